//! The game's per-particle forces (`Simulation::set_forces`): a force stage whose `F/m` the
//! integrators read where they read gravity, its work booked in the energy audit.

use harmonic::prelude::*;
use harmonic::{SimError, StageKind};

/// A 16×16 cloth of 1 kg (masses 1/256 kg, a power of two: `F/m` is exact), hanging from two
/// corners, with `gravity` and a fixed integrator.
fn cloth(gravity: DVec3, integrator: Integrator) -> Simulation {
    let mut scene = harmonic::internals::hanging_cloth(16);
    scene.gravity = gravity.to_array();
    scene.integrator = Some(integrator.name().to_string());
    scene.substeps = Some(4);
    scene.dt = 1e-3;
    Simulation::from_scene(&scene).expect("builds")
}

const GAME_INTEGRATORS: [Integrator; 7] = [
    Integrator::SymplecticEuler,
    Integrator::Harmonic,
    Integrator::HarmonicGs,
    Integrator::ExplicitEuler,
    Integrator::ImplicitEuler,
    Integrator::ThetaMg,
    Integrator::Xpbd,
];

/// Forces of `m a` on every particle step exactly as a gravity of `a`: every integrator reads
/// the force stage's acceleration where it reads gravity.
#[test]
fn mass_proportional_forces_are_gravity_bit_for_bit() {
    let a = DVec3::new(0.5, -9.75, 1.25);
    for integrator in GAME_INTEGRATORS {
        let mut by_gravity = cloth(a, integrator);
        let mut by_forces = cloth(DVec3::ZERO, integrator);
        let m = 1.0 / 256.0;
        let forces = vec![m * a; by_forces.positions().len()];
        by_forces.set_forces(&forces).expect("one per particle");
        for _ in 0..20 {
            by_gravity.step().expect("steps");
            by_forces.step().expect("steps");
        }
        assert_eq!(
            by_gravity.positions(),
            by_forces.positions(),
            "{integrator}: forces of m a do not step as gravity a"
        );
        assert_eq!(by_gravity.velocities(), by_forces.velocities());
        // The audit books the forces' work where gravity's is potential energy: the same
        // residual to rounding, and the forces' line equals the gravity run's potential change.
        let (g, f) = (
            by_gravity.diagnostics().audit,
            by_forces.diagnostics().audit,
        );
        assert_eq!(g.forces, 0.0);
        let fall = -(g.energy - g.start - f.energy + f.start);
        assert!(
            (f.forces - fall).abs() <= 1e-9 * fall.abs().max(1e-12) + 1e-15,
            "{integrator}: the forces did {} J, gravity's potential fell {fall} J",
            f.forces
        );
        assert!(
            (f.residual - g.residual).abs() <= 1e-9 * g.scale,
            "{integrator}: residual {} with forces, {} with gravity",
            f.residual,
            g.residual
        );
    }
}

/// A particle falling against a drag the game applies each frame (`F = −c v`) reaches the
/// terminal velocity `m g / c`.
#[test]
fn a_drag_set_each_frame_gives_the_terminal_velocity() {
    let (m, c, g) = (0.25, 0.5, 9.81);
    let text = format!(
        "Scene(dt: 0.01, substeps: 4, gravity: (0.0, -{g}, 0.0), particles: [(position: (0.0, 0.0, 0.0), mass: {m})])"
    );
    let scene = Scene::parse(&text, "drag").expect("parses");
    let mut sim = Simulation::from_scene(&scene).expect("builds");
    // τ = m / c = 0.5 s: 20 s is 40 time constants.
    for _ in 0..2000 {
        let v = sim.velocities()[0];
        sim.set_forces(&[-c * v]).expect("one force");
        sim.step().expect("steps");
    }
    let terminal = m * g / c;
    let v = sim.velocities()[0];
    assert!(
        (-v.y - terminal).abs() < 1e-9 * terminal && v.x == 0.0 && v.z == 0.0,
        "v = {v}, terminal {terminal} m/s"
    );
}

#[test]
fn the_schedule_lists_the_force_stage_while_forces_are_set() {
    let mut sim = cloth(DVec3::new(0.0, -9.81, 0.0), Integrator::SymplecticEuler);
    let n = sim.positions().len();
    sim.set_forces(&vec![DVec3::X; n])
        .expect("one per particle");
    sim.step().expect("steps");
    assert!(sim.schedule().has(StageKind::Forces), "{}", sim.schedule());
    assert!(sim
        .schedule()
        .to_string()
        .starts_with("gravity → forces → integrate"));
    sim.clear_forces();
    sim.step().expect("steps");
    assert!(!sim.schedule().has(StageKind::Forces), "{}", sim.schedule());
    assert_eq!(sim.stats().audit.forces, 0.0);
}

#[test]
fn bad_forces_are_refused_by_name() {
    let mut sim = cloth(DVec3::ZERO, Integrator::SymplecticEuler);
    let n = sim.positions().len();
    match sim.set_forces(&vec![DVec3::ZERO; n - 1]) {
        Err(e @ SimError::ForceCount { given, particles }) => {
            assert_eq!((given, particles), (n - 1, n));
            assert!(e.to_string().contains("one per particle"), "{e}");
        }
        other => panic!("{other:?}"),
    }
    let mut forces = vec![DVec3::ZERO; n];
    forces[17].y = f64::NAN;
    match sim.set_forces(&forces) {
        Err(e @ SimError::BadForce { index: 17, .. }) => {
            assert!(e.to_string().contains("particle 17"), "{e}")
        }
        other => panic!("{other:?}"),
    }
    assert!(sim.forces().is_none(), "a refused call changes nothing");
    // Forces for another particle count are dropped when a cloth is added; forces for the
    // new count, set before the step that gathers it, are kept.
    sim.set_forces(&vec![DVec3::Y; n])
        .expect("one per particle");
    let cloth = harmonic::internals::hanging_cloth(4).cloths[0].clone();
    sim.add_cloth(&cloth).expect("adds");
    sim.step().expect("steps");
    assert!(sim.forces().is_none());
    assert!(!sim.schedule().has(StageKind::Forces));
    sim.add_cloth(&cloth).expect("adds");
    sim.set_forces(&vec![DVec3::Y; n + 32])
        .expect("one per particle of the World as it is now");
    sim.step().expect("steps");
    assert_eq!(sim.forces().map(<[DVec3]>::len), Some(n + 32));
}
