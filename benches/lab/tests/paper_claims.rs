//! The paper's printed equations, checked against the corrected closed form (MATH notes 1, 2,
//! 8): `harmonic-paper` is the lab's, so its claims are checked here.

use harmonic::glam::DVec3;
use harmonic::internals::buffers::Packed;
use harmonic::{Integrator, Scene};
use harmonic_lab::research::{Method, StepError, Stepper};

/// Two particles on one spring (k = 100 N/m, rest 1 m), centre of mass at rest at the origin:
/// stretched by `d0`, stretching at `v0`, damping ratio `zeta`, step `ratio · h_c`.
fn pair(ma: f64, mb: f64, zeta: f64, ratio: f64, d0: f64, v0: f64) -> (Packed, f64) {
    let k = 100.0;
    let mu = ma * mb / (ma + mb);
    let w0 = (k / mu).sqrt();
    let c = 2.0 * zeta * (k * mu).sqrt();
    let h = ratio * std::f64::consts::PI / w0;
    let (xa, xb) = (-(1.0 + d0) * mb / (ma + mb), (1.0 + d0) * ma / (ma + mb));
    let (va, vb) = (-v0 * mb / (ma + mb), v0 * ma / (ma + mb));
    let text = format!(
        "Scene(dt: {h:e}, substeps: 1, gravity: (0.0, 0.0, 0.0),
          particles: [(position: ({xa:e}, 0.0, 0.0), velocity: ({va:e}, 0.0, 0.0), mass: {ma:e}),
                      (position: ({xb:e}, 0.0, 0.0), velocity: ({vb:e}, 0.0, 0.0), mass: {mb:e})],
          springs: [(a: 0, b: 1, stiffness: {k:e}, damping: {c:e}, rest_length: 1.0)])"
    );
    let scene = Scene::parse(&text, "pair").unwrap();
    (Packed::gather(&scene.build().world).unwrap(), h)
}

const HARMONIC: Method = Method::Engine(Integrator::Harmonic);

/// Particle b's velocity change over one step of `method`.
fn change(method: Method, ma: f64, mb: f64, zeta: f64, ratio: f64, v0: f64) -> f64 {
    let (mut p, h) = pair(ma, mb, zeta, ratio, 0.05, v0);
    let before = p.v[1];
    let mut stepper = Stepper::new(method, false, DVec3::ZERO);
    stepper.substep(&mut p, h).unwrap();
    (p.v[1] - before).x
}

/// Eq. 14 as printed: the velocity change is μ/(2(m_i+m_j)) of the true one (1/8 at 1:1,
/// 1/2004 at 1:1000), here for a spring stretching (δ̇ ≥ 0, where eq. 12's phase is right).
#[test]
fn paper_velocity_change_is_too_small_by_the_printed_factor() {
    for (ma, mb, factor) in [
        (1.0, 1.0, 1.0 / 8.0),
        (1.0, 1000.0, 1000.0 / (2.0 * 1001.0 * 1001.0)),
    ] {
        let h = pair(ma, mb, 0.0, 0.3, 0.05, 0.2).1;
        // Algorithm 1 multiplies the change by h once more.
        let ratio = change(Method::HARMONIC_PAPER, ma, mb, 0.0, 0.3, 0.2)
            / h
            / change(HARMONIC, ma, mb, 0.0, 0.3, 0.2);
        assert!(
            (ratio / factor - 1.0).abs() < 1e-9,
            "{ma}:{mb}: ratio {ratio}, printed factor {factor}"
        );
    }
}

/// Eq. 12: with the spring contracting (δ̇ < 0) the printed phase has the wrong sign, so the
/// printed change is not the true one times the printed factor.
#[test]
fn paper_phase_loses_the_sign_of_the_stretch_rate() {
    let h = pair(1.0, 1.0, 0.0, 0.3, 0.05, -0.2).1;
    let ratio = change(Method::HARMONIC_PAPER, 1.0, 1.0, 0.0, 0.3, -0.2)
        / h
        / change(HARMONIC, 1.0, 1.0, 0.0, 0.3, -0.2);
    assert!(
        (ratio / 0.125 - 1.0).abs() > 0.1,
        "contracting spring gave the stretching ratio {ratio}"
    );
}

/// Eq. 27 as printed is NaN for ζ > 0.707: reported as an error, never a NaN step.
#[test]
fn paper_is_undefined_above_zeta_0_707_and_says_so() {
    let (mut p, h) = pair(1.0, 1.0, 0.6, 0.3, 0.05, 0.2);
    let mut stepper = Stepper::new(Method::HARMONIC_PAPER, false, DVec3::ZERO);
    stepper.substep(&mut p, h).unwrap();
    assert!(p.x.iter().all(|x| x.is_finite()));
    let (p, h) = pair(1.0, 1.0, 0.8, 0.3, 0.05, 0.2);
    let mut stepper = Stepper::new(Method::HARMONIC_PAPER, false, DVec3::ZERO);
    match stepper.prepare(&p, h) {
        Err(StepError::PaperUndefined { spring: 0, zeta }) => {
            assert!((zeta - 0.8).abs() < 1e-12)
        }
        Err(e) => panic!("wrong error {e}"),
        Ok(()) => panic!("ζ = 0.8 must be refused by harmonic-paper"),
    }
}

/// Eq. 22–23 as printed are inconsistent: the velocity change does not vanish as h → 0.
#[test]
fn paper_damped_change_does_not_vanish_as_h_shrinks() {
    // Per-step velocity change of particle b; for harmonic-paper Algorithm 1's extra factor h
    // is divided out, leaving the printed φ (times the mass split).
    let printed = |ratio: f64| {
        change(Method::HARMONIC_PAPER, 1.0, 1.0, 0.3, ratio, 0.2)
            / pair(1.0, 1.0, 0.3, ratio, 0.05, 0.2).1
    };
    let (big, small) = (printed(1e-2), printed(1e-4));
    assert!(
        (small / big - 1.0).abs() < 0.01,
        "printed φ should stay put as h shrinks 100×: {big} vs {small}"
    );
    let (big, small) = (
        change(HARMONIC, 1.0, 1.0, 0.3, 1e-2, 0.2),
        change(HARMONIC, 1.0, 1.0, 0.3, 1e-4, 0.2),
    );
    assert!(
        (small / big - 0.01).abs() < 0.001,
        "corrected φ must shrink with h: {big} vs {small}"
    );
}
