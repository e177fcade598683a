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

use harmonic::buffers::Packed;
use harmonic::stability::{self, GROWTH_TOL};
use harmonic::{step_control, Integrator};

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
