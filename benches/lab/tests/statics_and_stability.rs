//! The statics relaxation against a closed form, and the stability measure against the
//! single-oscillator stability bounds that are known exactly.

use harmonic::glam::DVec3;
use harmonic::internals::buffers::Packed;
use harmonic::Integrator;
use harmonic_lab::research::Method;
use harmonic_lab::stability::{self, Start};
use harmonic_lab::statics;

fn pack(scene: &harmonic::Scene) -> Packed {
    Packed::gather(&scene.build().world).unwrap()
}

#[test]
fn relaxation_finds_the_hanging_chain_closed_form() {
    let (from_rest, strain) = stability::chain(20, 0.0, Start::Rest);
    let (exact, _) = stability::chain(20, 0.0, Start::Equilibrium);
    let p = pack(&from_rest);
    let relaxed = statics::relax(&p, DVec3::from(from_rest.gravity), 1e-10, 2_000_000);
    let q = pack(&exact);
    let err = relaxed
        .positions
        .iter()
        .zip(&q.x)
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0, f64::max);
    println!(
        "relaxed in {} iterations, max |Δx| {err:.2e} m",
        relaxed.iterations
    );
    assert!(err < 1e-8, "relaxed chain is {err} m from the closed form");
    assert!((statics::static_strain(&p, &relaxed) - strain).abs() < 1e-6);
}

#[test]
fn equilibrium_start_stays_put_with_rk4() {
    // The closed-form equilibrium is a fixed point of the dynamics.
    let (scene, strain) = stability::chain(20, 0.0, Start::Equilibrium);
    let p = pack(&scene);
    let hc = stability::h_crit(&p);
    let o = stability::run(
        &p,
        Method::RK4,
        DVec3::from(scene.gravity),
        0.2 * hc,
        1.0,
        1.0,
    );
    match o {
        stability::Outcome::Bounded { max_strain, .. } => assert!(
            (max_strain / strain - 1.0).abs() < 1e-6,
            "{max_strain} vs {strain}"
        ),
        other => panic!("{other:?}"),
    }
}

#[test]
fn single_spring_thresholds_match_the_oscillator_bounds() {
    // Symplectic Euler on an undamped oscillator is stable iff ω h ≤ 2: h/h_c ≤ 2/π.
    let p = pack(&stability::pair(1.0, 0.0, false, Start::Equilibrium).0);
    let se = stability::threshold(&p, Method::Engine(Integrator::SymplecticEuler), false, 2.0)
        .expect("bounded");
    println!(
        "symplectic Euler: {se:.4} (exact {:.4})",
        2.0 / std::f64::consts::PI
    );
    assert!((se - 2.0 / std::f64::consts::PI).abs() < 0.01, "{se}");
    // Harmonic with exact displacement integrates an isolated spring exactly: never unstable.
    assert_eq!(
        stability::threshold(&p, Method::Engine(Integrator::Harmonic), true, 10.0),
        None
    );
    // Over-damped: the closed form is stable at any step (MATH: ∞), symplectic Euler is not.
    let p2 = pack(&stability::pair(1.0, 2.0, false, Start::Equilibrium).0);
    assert_eq!(
        stability::threshold(&p2, Method::Engine(Integrator::Harmonic), false, 10.0),
        None
    );
    let se2 = stability::threshold(&p2, Method::Engine(Integrator::SymplecticEuler), false, 2.0)
        .expect("bounded");
    println!("symplectic Euler at ζ = 2: {se2:.4}");
    // Exact bound: ωh < 2(√(ζ²+1) − ζ), i.e. h/h_c < 0.1502 at ζ = 2.
    let exact = 2.0 * (5.0f64.sqrt() - 2.0) / std::f64::consts::PI;
    assert!((se2 - exact).abs() < 0.01 * exact, "{se2} vs {exact}");
}

#[test]
fn harmonic_single_spring_thresholds_match_their_closed_forms() {
    use std::f64::consts::PI;
    // Undamped, θ = ωh: the closed form gives p h = −θ sin θ, q = cos θ − 1, and with
    // x += h v_new the one-spring map has det 1 + q, trace 2 + p h + q.
    // - One impulse (Jacobi, Gauss–Seidel, forced: alone, a spring has no other force): Jury's
    //   |trace| ≤ 1 + det is 2 cos(θ/2) ≥ θ sin(θ/2), i.e. (θ/2) tan(θ/2) ≤ 1.
    // - Two half impulses (symmetric sweeps): p and q scale by 1 + q/4, det = cos⁴(θ/2) and
    //   trace − (1 + det) = −θ sin θ (3 + cos θ)/4: stable exactly while sin θ ≥ 0, i.e. h ≤ h_c.
    let (mut lo, mut hi) = (0.0, PI / 2.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if mid * mid.tan() < 1.0 {
            lo = mid
        } else {
            hi = mid
        }
    }
    let one_impulse = 2.0 * lo / PI; // 0.5477
    let p = pack(&stability::pair(1.0, 0.0, false, Start::Equilibrium).0);
    for (integrator, exact) in [
        (Method::Engine(Integrator::Harmonic), one_impulse),
        (Method::Engine(Integrator::HarmonicGs), one_impulse),
        (Method::HARMONIC_FORCED, one_impulse),
        (Method::HARMONIC_FORCED_GS, one_impulse),
        (Method::HARMONIC_SGS, 1.0),
    ] {
        let t = stability::threshold(&p, integrator, false, 2.0).expect("bounded");
        println!("{integrator}: {t:.4} (exact {exact:.4})");
        assert!(
            (t - exact).abs() < 0.01 * exact,
            "{integrator}: {t} vs {exact}"
        );
    }
}

#[test]
fn implicit_euler_is_stable_at_every_step_on_the_threshold_systems() {
    // MATH.md's study: ∞ on every system (implicit Euler is A-stable on a linear network).
    for study in stability::threshold_systems() {
        let p = pack(&study.scene);
        let hc = stability::h_crit(&p);
        for ratio in [0.5, 1.0, 2.0, 4.0, 8.0625] {
            let g = stability::growth_rate(
                &p,
                Method::Engine(Integrator::ImplicitEuler),
                false,
                ratio * hc,
                2000,
            )
            .expect("runs");
            assert!(
                g <= 1.0 + stability::GROWTH_TOL,
                "{} at {ratio} h_c: growth {g}",
                study.name
            );
        }
    }
}

#[test]
fn relaxed_cloth_is_a_fixed_point() {
    // The relaxed 16×16 cloth barely moves under the RK4 reference (an independent integrator).
    let (scene, strain) = stability::cloth_case(16, 0.0, Start::Equilibrium);
    assert!(strain > 0.0 && strain < 0.5, "static strain {strain}");
    let p = pack(&scene);
    let hc = stability::h_crit(&p);
    match stability::run(
        &p,
        Method::RK4,
        DVec3::from(scene.gravity),
        0.2 * hc,
        0.2,
        1.0,
    ) {
        stability::Outcome::Bounded { max_strain, .. } => {
            println!("static strain {strain:.5}, max under RK4 {max_strain:.5}");
            assert!(
                (max_strain / strain - 1.0).abs() < 1e-3,
                "{max_strain} vs {strain}"
            );
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn forced_harmonic_keeps_statics_exact() {
    // Started at the exact equilibrium, the forced oscillator step does not move the chain at
    // a large stable step; the unforced step sags (a loaded spring's impulse is κδ·sin(ωh)/ω).
    let (scene, strain) = stability::chain(20, 0.2, Start::Equilibrium);
    let p = pack(&scene);
    let g = DVec3::from(scene.gravity);
    let h = 0.3 * stability::h_crit(&p);
    let ratio = |integrator| match stability::run(&p, integrator, g, h, 2.0, 1.0) {
        stability::Outcome::Bounded { max_strain, .. } => max_strain / strain,
        other => panic!("{integrator}: {other:?}"),
    };
    let (forced, plain) = (
        ratio(Method::HARMONIC_FORCED),
        ratio(Method::Engine(Integrator::Harmonic)),
    );
    println!("max strain / static strain at 0.3 h_c: forced {forced:.12}, harmonic {plain:.6}");
    assert!(
        (forced - 1.0).abs() < 1e-9,
        "forced step moved the static chain: {forced}"
    );
    assert!(
        plain - 1.0 > 1e-3,
        "unforced step should overshoot statics: {plain}"
    );
}

#[test]
fn implicit_euler_stays_bounded_at_large_steps() {
    // Unconditionally stable: the hanging chain and cloth at h/h_c = 8.0625 stay bounded, and
    // from rest the chain settles near its static strain.
    let (scene, strain) = stability::chain(20, 0.0, Start::Rest);
    let p = pack(&scene);
    let h = 8.0625 * stability::h_crit(&p);
    match stability::run(
        &p,
        Method::Engine(Integrator::ImplicitEuler),
        DVec3::from(scene.gravity),
        h,
        10.0,
        1.0,
    ) {
        stability::Outcome::Bounded { max_strain, .. } => {
            println!("chain: max strain {max_strain:.4} vs static {strain:.4}");
            assert!(max_strain < 2.5 * strain, "{max_strain}");
        }
        other => panic!("chain: {other:?}"),
    }
    let (cloth, _) = stability::cloth_case(16, 0.2, Start::Rest);
    let p = pack(&cloth);
    let h = 8.0625 * stability::h_crit(&p);
    assert!(matches!(
        stability::run(
            &p,
            Method::Engine(Integrator::ImplicitEuler),
            DVec3::from(cloth.gravity),
            h,
            2.0,
            1.0
        ),
        stability::Outcome::Bounded { .. }
    ));
}
