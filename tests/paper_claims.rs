//! The paper's claims and printed errors, checked (MATH notes 1, 2, 8).

mod common;
use common::*;
use harmonic::{SimError, Simulation};

/// Fig. 3: at h = n·h_c an isolated undamped spring's impulse is μ δ̇0 (1 − (−1)ⁿ): zero at
/// even n (the pair drifts on), a reversal of the stretch rate at odd n.
#[test]
fn integer_multiples_of_h_c_give_zero_or_reversing_impulse() {
    for n in 1..=6u32 {
        let (mut sim, _, _) = pair(2.0, 2.0, 0.0, n as f64, 0.0, 1.0, false, "harmonic");
        let (_, v0) = stretch(&sim);
        sim.step().unwrap();
        // Relative velocity along the axis after one step (direction may not flip: δ stays small).
        let v = sim.velocities();
        let rel = (v[1] - v[0]).x;
        let expected = if n % 2 == 0 { v0 } else { -v0 };
        assert!(
            (rel - expected).abs() < 1e-9,
            "n = {n}: relative velocity {rel}, expected {expected}"
        );
    }
}

/// Eq. 14 as printed: the velocity change is μ/(2(m_i+m_j)) of the true one (1/8 at 1:1,
/// 1/2004 at 1:1000), here for a spring stretching (δ̇ ≥ 0, where eq. 12's phase is right).
#[test]
fn paper_velocity_change_is_too_small_by_the_printed_factor() {
    for (ma, mb, factor) in [
        (1.0, 1.0, 1.0 / 8.0),
        (1.0, 1000.0, 1000.0 / (2.0 * 1001.0 * 1001.0)),
    ] {
        let change = |integrator: &str| {
            let (mut sim, _, _) = pair(ma, mb, 0.0, 0.3, 0.05, 0.2, false, integrator);
            let before = sim.velocities().to_vec();
            sim.step().unwrap();
            // Velocity change of particle b beyond nothing (no gravity).
            (sim.velocities()[1] - before[1]).x
        };
        let h = pair(ma, mb, 0.0, 0.3, 0.05, 0.2, false, "harmonic")
            .0
            .config()
            .dt;
        // Algorithm 1 multiplies the change by h once more.
        let ratio = change("harmonic-paper") / h / change("harmonic");
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
    let change = |integrator: &str| {
        let (mut sim, _, _) = pair(1.0, 1.0, 0.0, 0.3, 0.05, -0.2, false, integrator);
        let before = sim.velocities()[1];
        sim.step().unwrap();
        (sim.velocities()[1] - before).x
    };
    let h = pair(1.0, 1.0, 0.0, 0.3, 0.05, -0.2, false, "harmonic")
        .0
        .config()
        .dt;
    let ratio = change("harmonic-paper") / h / change("harmonic");
    assert!(
        (ratio / 0.125 - 1.0).abs() > 0.1,
        "contracting spring gave the stretching ratio {ratio}"
    );
}

/// Eq. 27 as printed is NaN for ζ > 0.707: reported as an error, never a NaN step.
#[test]
fn paper_is_undefined_above_zeta_0_707_and_says_so() {
    let (sim, _, _) = pair(1.0, 1.0, 0.6, 0.3, 0.05, 0.2, false, "harmonic-paper");
    assert!(sim.positions().iter().all(|x| x.is_finite()));
    let text = "Scene(dt: 0.01, gravity: (0.0, 0.0, 0.0), integrator: \"harmonic-paper\",
        particles: [(position: (0.0, 0.0, 0.0), mass: 1.0), (position: (1.0, 0.0, 0.0), mass: 1.0)],
        springs: [(a: 0, b: 1, stiffness: 100.0, damping_ratio: 0.8)])";
    let scene = harmonic::Scene::parse(text, "zeta.ron").unwrap();
    match Simulation::from_scene(&scene) {
        Err(SimError::PaperUndefined { spring: 0, zeta }) => assert!((zeta - 0.8).abs() < 1e-12),
        Err(e) => panic!("wrong error {e}"),
        Ok(_) => panic!("ζ = 0.8 must be refused by harmonic-paper"),
    }
}

/// Eq. 22–23 as printed are inconsistent: the velocity change does not vanish as h → 0.
#[test]
fn paper_damped_change_does_not_vanish_as_h_shrinks() {
    // Per-step velocity change of particle b; for harmonic-paper Algorithm 1's extra factor h
    // is divided out, leaving the printed φ (times the mass split).
    let change = |ratio: f64, integrator: &str| {
        let (mut sim, _, _) = pair(1.0, 1.0, 0.3, ratio, 0.05, 0.2, false, integrator);
        let before = sim.velocities()[1];
        sim.step().unwrap();
        let dv = (sim.velocities()[1] - before).x;
        if integrator == "harmonic-paper" {
            dv / sim.config().dt
        } else {
            dv
        }
    };
    let (big, small) = (
        change(1e-2, "harmonic-paper"),
        change(1e-4, "harmonic-paper"),
    );
    assert!(
        (small / big - 1.0).abs() < 0.01,
        "printed φ should stay put as h shrinks 100×: {big} vs {small}"
    );
    let (big, small) = (change(1e-2, "harmonic"), change(1e-4, "harmonic"));
    assert!(
        (small / big - 0.01).abs() < 0.001,
        "corrected φ must shrink with h: {big} vs {small}"
    );
}
