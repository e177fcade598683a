//! Non-finite state during a run: a NaN velocity set from outside, a spring that degenerates
//! (both ends at one point), a stiffness beyond f32. The step quarantines the particles it
//! touches (frozen at their last finite position, reported) and the rest keeps simulating;
//! nothing spreads NaN. Misuse of the World through the API is a typed error.

mod common;

use glam::DVec3;
use harmonic::prelude::*;
use harmonic::{Quarantined, SimError};

const J: usize = 5 * 16 + 5;
const K: usize = J + 1; // its structural neighbour along the row

fn cloth(integrator: Integrator) -> Simulation {
    let mut scene = harmonic::internals::hanging_cloth(16);
    scene.dt = 1e-3;
    scene.substeps = Some(4);
    scene.integrator = Some(integrator.name().into());
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..20 {
        sim.step().unwrap();
    }
    sim
}

fn particle(sim: &mut Simulation, i: usize) -> hecs::RefMut<'_, Particle> {
    let e = sim.particle_entity(i).unwrap();
    sim.world_mut().get::<&mut Particle>(e).unwrap()
}

fn run(sim: &mut Simulation, frames: usize) -> usize {
    (0..frames).map(|_| sim.step().unwrap().quarantined).sum()
}

fn indices(sim: &Simulation) -> Vec<usize> {
    sim.quarantined().into_iter().map(|(i, _)| i).collect()
}

const EVERY: [Integrator; 6] = [
    Integrator::SymplecticEuler,
    Integrator::Harmonic,
    Integrator::HarmonicGs,
    Integrator::ImplicitEuler,
    Integrator::ThetaMg,
    Integrator::Xpbd,
];

#[test]
fn a_nan_velocity_freezes_that_particle_only() {
    for integrator in EVERY {
        let mut sim = cloth(integrator);
        particle(&mut sim, J).velocity = DVec3::new(f64::NAN, 0.0, 0.0);
        assert_eq!(sim.step().unwrap().quarantined, 1, "{integrator}");
        assert_eq!(run(&mut sim, 49), 0, "{integrator}");
        assert_eq!(
            sim.quarantined(),
            vec![(
                J,
                Quarantined {
                    step: 20,
                    was_pinned: false
                }
            )]
        );
        assert_eq!(sim.diagnostics().non_finite, 0);
        // The same as pinning it where it was: the rest of the cloth is untouched by it.
        let mut pinned = cloth(integrator);
        pinned.pin(J).unwrap();
        run(&mut pinned, 50);
        assert_eq!(sim.positions(), pinned.positions(), "{integrator}");
    }
}

#[test]
fn a_degenerate_spring_quarantines_its_ends_and_the_rest_moves_on() {
    for integrator in EVERY {
        let mut sim = cloth(integrator);
        let at = sim.positions()[J];
        particle(&mut sim, K).position = at;
        let before = sim.positions().to_vec();
        let found = run(&mut sim, 50);
        let q = indices(&sim);
        assert_eq!(found, q.len());
        let p = sim.positions();
        assert!(p.iter().all(|x| x.is_finite()));
        if integrator == Integrator::Xpbd {
            // XPBD drifts before it projects, so the two ends have parted by the time the
            // spring is read: nothing degenerates.
            assert!(q.is_empty(), "{q:?}");
        } else {
            // Only the two ends: the guard drops what reaches a neighbour in a sweep or a
            // solve, and the quarantine restores them before the next substep.
            assert_eq!(q, vec![J, K], "{integrator}");
            assert_eq!(p[J], at);
            assert_eq!(p[K], at);
        }
        // Everything else kept falling and swinging.
        let moved = (0..p.len())
            .filter(|i| !q.contains(i) && (p[*i] - before[*i]).length() > 1e-4)
            .count();
        assert!(moved > 200, "{integrator}: only {moved} particles moved");
        assert!(sim.diagnostics().energy.is_finite());
    }
}

#[test]
fn a_stiffness_beyond_f32_quarantines_its_ends() {
    for integrator in [Integrator::SymplecticEuler, Integrator::HarmonicGs] {
        let mut sim = cloth(integrator);
        let (a, b) = (
            sim.particle_entity(J).unwrap(),
            sim.particle_entity(K).unwrap(),
        );
        let rest = (sim.positions()[K] - sim.positions()[J]).length();
        sim.world_mut().spawn((Spring {
            a,
            b,
            rest_length: rest,
            stiffness: 1e39,
            damping: 0.0,
        },));
        assert_eq!(sim.step().unwrap().quarantined, 2, "{integrator}");
        assert_eq!(indices(&sim), vec![J, K]);
        run(&mut sim, 30);
        // As if the two were pinned and the spring never existed.
        let mut pinned = cloth(integrator);
        pinned.pin(J).unwrap();
        pinned.pin(K).unwrap();
        run(&mut pinned, 31);
        assert_eq!(sim.positions(), pinned.positions(), "{integrator}");
    }
}

#[test]
fn a_released_particle_moves_again() {
    let mut sim = cloth(Integrator::SymplecticEuler);
    particle(&mut sim, J).velocity = DVec3::splat(f64::INFINITY);
    run(&mut sim, 1);
    let held = sim.positions()[J];
    run(&mut sim, 5);
    assert_eq!(sim.positions()[J], held);
    sim.release_quarantine(J).unwrap();
    assert_eq!(
        sim.release_quarantine(J),
        Err(SimError::NotQuarantined { index: J })
    );
    run(&mut sim, 5);
    assert!(sim.quarantined().is_empty());
    assert_ne!(sim.positions()[J], held);
}

#[test]
fn misuse_of_the_world_is_a_typed_error_and_recoverable() {
    let mut sim = cloth(Integrator::SymplecticEuler);
    let (a, b) = (
        sim.particle_entity(J).unwrap(),
        sim.particle_entity(K).unwrap(),
    );
    // A spring from a particle to itself.
    let s = sim.world_mut().spawn((Spring {
        a,
        b: a,
        rest_length: 0.1,
        stiffness: 1.0,
        damping: 0.0,
    },));
    assert!(matches!(sim.step(), Err(SimError::BadSpring { spring, .. }) if spring == s));
    sim.world_mut().despawn(s).unwrap();
    // A zero rest length, a negative stiffness.
    for (rest, k) in [(0.0, 1.0), (0.1, -1.0), (f64::NAN, 1.0)] {
        let s = sim.world_mut().spawn((Spring {
            a,
            b,
            rest_length: rest,
            stiffness: k,
            damping: 0.0,
        },));
        let e = sim.step().unwrap_err();
        assert!(matches!(e, SimError::BadSpring { .. }), "{e}");
        sim.world_mut().despawn(s).unwrap();
    }
    // A negative mass, a NaN position.
    particle(&mut sim, J).mass = -1.0;
    let e = sim.step().unwrap_err();
    assert!(
        e.to_string()
            .contains("mass must be finite and > 0, got -1"),
        "{e}"
    );
    particle(&mut sim, J).mass = 1.0 / 256.0;
    let keep = particle(&mut sim, J).position;
    particle(&mut sim, J).position.y = f64::NAN;
    assert!(matches!(sim.step(), Err(SimError::BadParticle { particle, .. }) if particle == a));
    particle(&mut sim, J).position = keep;
    // A spring to a despawned particle, and despawning a particle springs still use.
    let ghost = sim.world_mut().spawn((Particle {
        position: DVec3::ZERO,
        velocity: DVec3::ZERO,
        mass: 1.0,
    },));
    sim.world_mut().despawn(ghost).unwrap();
    let s = sim.world_mut().spawn((Spring {
        a,
        b: ghost,
        rest_length: 1.0,
        stiffness: 1.0,
        damping: 0.0,
    },));
    assert!(matches!(
        sim.step(),
        Err(SimError::DanglingSpring { spring, end }) if spring == s && end == ghost
    ));
    sim.world_mut().despawn(s).unwrap();
    // Steps with dt ≤ 0 or NaN are refused and leave the config as it was.
    for dt in [0.0, -1e-3, f64::NAN, f64::INFINITY] {
        let mut c = *sim.config();
        c.dt = dt;
        assert!(matches!(sim.set_config(c), Err(SimError::BadStep(_))));
    }
    assert!(sim.advance(f64::NAN).is_err());
    // After each fix the simulation steps on, finite.
    run(&mut sim, 10);
    assert_eq!(sim.diagnostics().non_finite, 0);
    assert!(sim.quarantined().is_empty());
}

#[test]
fn the_gpu_back_end_quarantines_too() {
    let mut scene = harmonic::internals::hanging_cloth(16);
    scene.dt = 1e-3;
    scene.substeps = Some(4);
    scene.backend = Some("gpu".into());
    let Some(mut sim) = common::gpu_or_skip(Simulation::from_scene(&scene).map_err(|e| match e {
        SimError::Gpu(g) => g,
        e => panic!("{e}"),
    })) else {
        return;
    };
    scene.backend = None;
    let mut cpu = Simulation::from_scene(&scene).unwrap();
    let mut frozen = Vec::new();
    for sim in [&mut sim, &mut cpu] {
        run(sim, 5);
        particle(sim, J).velocity = DVec3::new(0.0, f64::NAN, 0.0);
        assert_eq!(sim.step().unwrap().quarantined, 1);
        run(sim, 20);
        assert_eq!(indices(sim), vec![J]);
        assert_eq!(sim.diagnostics().non_finite, 0);
        frozen.push(sim.positions().to_vec());
        // A spring degenerating on the device: its ends only, though the frame's four
        // substeps run in one submit before the state comes back (the kernel's guard drops
        // the rest).
        let at = sim.positions()[J + 16];
        particle(sim, J + 17).position = at;
        run(sim, 20);
        let q = indices(sim);
        assert!(q.contains(&(J + 16)) && q.contains(&(J + 17)), "{q:?}");
        assert_eq!(q, vec![J, J + 16, J + 17]);
        assert!(sim.positions().iter().all(|x| x.is_finite()));
    }
    // Both back ends quarantine the same particles. After the NaN velocity (caught at gather
    // on both) the cloths agree to f32's rounding: 4 ε₃₂ · 1 m · 104 substeps (tests/gpu.rs).
    // After the collapse they need not: the CPU puts the two ends back after every substep,
    // the device only once the frame's substeps come back, dropping their springs meanwhile.
    assert_eq!(sim.quarantined(), cpu.quarantined());
    let worst = frozen[0]
        .iter()
        .zip(&frozen[1])
        .map(|(g, c)| (*g - *c).length())
        .fold(0.0, f64::max);
    assert!(
        worst < 4.0 * f32::EPSILON as f64 * 104.0,
        "GPU and CPU differ by {worst} m"
    );
}
