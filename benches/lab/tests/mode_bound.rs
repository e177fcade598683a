//! The network stability limits of the one-pass integrators as a closed form.
//!
//! On a network whose springs share ω0 and ζ (the chain and the cloth of the threshold
//! table), the damping matrix is (2ζ/ω0) K, so M⁻¹K and the damping share eigenvectors: each
//! mode, with eigenvalue k ω0² of M⁻¹K, evolves alone. A one-pass integrator gives every spring
//! the velocity change `p δ + q δ̇`, so the mode's step is
//! `v' = (1 + q k) v + p k x, x' = x + h v'`: det = 1 + q k, trace = 2 + q k + h p k. It is
//! stable while −q k ≤ 2 and k (−2q − h p) ≤ 4 (Jury), at the highest mode k_max. The test
//! holds the measured thresholds to that, with p and q written out here from the oscillator's
//! closed form (MATH.md) and from symplectic Euler, independent of the engine's coefficients:
//! stable at 0.99 of the predicted limit, unstable at 1.01.

use harmonic::internals::buffers::Packed;
use harmonic::internals::step_control;
use harmonic::Integrator;
use harmonic_lab::stability::{self, GROWTH_TOL};

/// `(p, q)` of one spring for step `h` (ω0 = 1, so h = θ), under-damped.
fn coefficients(integrator: Integrator, zeta: f64, h: f64) -> (f64, f64) {
    match integrator {
        Integrator::SymplecticEuler => (-h, -2.0 * zeta * h),
        Integrator::Harmonic => {
            let beta = (1.0 - zeta * zeta).sqrt();
            let (c, s) = ((beta * h).cos(), (beta * h).sin() / beta);
            let e = (-zeta * h).exp();
            (-e * s, e * (c - zeta * s) - 1.0)
        }
        other => panic!("no closed form for {other:?}"),
    }
}

/// Largest h/h_c at which the mode of eigenvalue `k_max` (in units of ω0²) stays stable.
fn predicted(integrator: Integrator, zeta: f64, k_max: f64) -> f64 {
    let stable = |r: f64| {
        let h = r * std::f64::consts::PI;
        let (p, q) = coefficients(integrator, zeta, h);
        -q * k_max <= 2.0 && k_max * (-2.0 * q - h * p) <= 4.0
    };
    let mut r = 0.001;
    while stable(r) {
        r += 0.001;
    }
    let (mut lo, mut hi) = (r - 0.001, r);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if stable(mid) {
            lo = mid
        } else {
            hi = mid
        }
    }
    lo
}

#[test]
fn one_pass_thresholds_follow_the_mode_closed_form() {
    let mut checked = 0;
    for study in stability::threshold_systems() {
        let p = Packed::gather(&study.scene.build().world).unwrap();
        if p.springs.len() < 2 {
            continue; // a single spring is not a network
        }
        let stiffest = p
            .springs
            .iter()
            .max_by(|a, b| a.omega0_sq().total_cmp(&b.omega0_sq()))
            .unwrap();
        let (w0, zeta) = (stiffest.omega0_sq().sqrt(), stiffest.zeta());
        let k_max = (step_control::network_frequency(&p, 3000) / w0).powi(2);
        let hc = stability::h_crit(&p);
        for integrator in [Integrator::SymplecticEuler, Integrator::Harmonic] {
            let r = predicted(integrator, zeta, k_max);
            let growth =
                |f: f64| stability::growth_rate(&p, integrator, false, f * r * hc, 4000).unwrap();
            let (below, above) = (growth(0.99), growth(1.01));
            println!(
                "{}, {}: k_max {k_max:.4}, predicted {r:.4} h/h_c; growth {below:.6} at 0.99×, {above:.6} at 1.01×",
                study.name,
                integrator.name()
            );
            assert!(below <= 1.0 + GROWTH_TOL, "{}: {below}", study.name);
            assert!(above > 1.0 + GROWTH_TOL, "{}: {above}", study.name);
            checked += 1;
        }
    }
    assert_eq!(
        checked, 8,
        "the chain and the cloth, ζ = 0 and 0.2, two integrators"
    );
}

/// The slowest mode of a free chain follows the same per-mode map: a free line of N equal
/// masses has mode shapes cos(jπ(i + ½)/N) with k_j = 2 sin²(jπ/(2N)) (in units of ω0²), and
/// moving along its own line the chain is exactly linear. Started in mode 1, the engine's
/// chain must track `M(k_1)ⁿ` of the 2×2 map; there the closed form over-damps the mode by
/// q/(−2ζθ) (STABILITY.md, "The slow modes"), while symplectic Euler's rate is the true one.
#[test]
fn the_slowest_mode_follows_the_mode_map() {
    let (n, kappa, m, zeta) = (12usize, 400.0f64, 0.5f64, 0.2f64);
    let mu = 0.5 * m;
    let w0 = (kappa / mu).sqrt();
    let c = 2.0 * zeta * (kappa * mu).sqrt();
    let k1 = 2.0 * (std::f64::consts::PI / (2.0 * n as f64)).sin().powi(2);
    let shape: Vec<f64> = (0..n)
        .map(|i| (std::f64::consts::PI * (i as f64 + 0.5) / n as f64).cos())
        .collect();
    let y0 = 0.01;
    for integrator in [Integrator::Harmonic, Integrator::SymplecticEuler] {
        let r = 0.2;
        let h = r * std::f64::consts::PI / w0;
        let particles: String = (0..n)
            .map(|i| {
                format!(
                    "(position: ({:e}, 0.0, 0.0), mass: {m}),",
                    i as f64 + y0 * shape[i]
                )
            })
            .collect();
        let springs: String = (0..n - 1)
            .map(|i| {
                format!(
                    "(a: {i}, b: {}, stiffness: {kappa}, damping: {c:e}, rest_length: 1.0),",
                    i + 1
                )
            })
            .collect();
        let text = format!(
            "Scene(dt: {h:e}, substeps: 1, gravity: (0.0, 0.0, 0.0), integrator: \"{}\",
              particles: [{particles}], springs: [{springs}])",
            integrator.name()
        );
        let scene = harmonic::Scene::parse(&text, "line").unwrap();
        let mut sim = harmonic::Simulation::from_scene(&scene).unwrap();
        // The map in units ω0 = 1 (θ = ω0 h), mode coordinate y and its rate y' = dy/dt / ω0.
        let (p, q) = coefficients(integrator, zeta, r * std::f64::consts::PI);
        let theta = r * std::f64::consts::PI;
        let (mut y, mut yd) = (y0, 0.0);
        let norm: f64 = shape.iter().map(|u| u * u).sum();
        let mut worst: f64 = 0.0;
        let steps = 200;
        for _ in 0..steps {
            sim.step().unwrap();
            yd += p * k1 * y + q * k1 * yd;
            y += theta * yd;
            let measured = sim
                .positions()
                .iter()
                .zip(&shape)
                .enumerate()
                .map(|(i, (x, u))| (x.x - i as f64) * u)
                .sum::<f64>()
                / norm;
            worst = worst.max((measured - y).abs());
        }
        // The mode's damping per step, against the exact e^(−2ζθ k) of its determinant.
        let rate = (1.0 + q * k1).ln() / (-2.0 * zeta * theta * k1);
        println!(
            "{}: mode 1 (k = {k1:.4}) after {steps} steps at {r} h_c: |y − map| ≤ {worst:.2e} (y0 {y0}); damping {rate:.3}× the true rate",
            integrator.name()
        );
        assert!(worst < 1e-9, "{}: {worst:e}", integrator.name());
        match integrator {
            Integrator::SymplecticEuler => assert!((rate - 1.0).abs() < 0.01, "{rate}"),
            _ => assert!(
                rate > 1.3,
                "the closed form over-damps the slow mode: {rate}"
            ),
        }
    }
}
