//! Run-time pins and grabs leave the topology alone: moving a pinned particle writes the state,
//! pinning or freeing one refreshes the springs touching it, and neither re-gathers the World.
//! The reference is the full gather: the same edits made through `world_mut` (which re-gathers
//! everything) must give the same state, bit for bit, on every integrator, with fixed and with
//! automatic substeps (a pin changes the step choice, and the refresh chooses again as a gather
//! does; moving a pinned particle does not, as no other frame does).

use harmonic::prelude::*;
use harmonic::SimError;

#[cfg(feature = "gpu")]
mod common;

fn scene(integrator: &str, substeps: &str) -> Simulation {
    let text = format!(
        r#"Scene(dt: 0.01, integrator: "{integrator}", {substeps}
            cloths: [(origin: (-0.5, 1.0, 0.0), size: (1.0, 1.0), resolution: (12, 12),
                      plane: Vertical, mass: 0.2,
                      structural: (frequency: 30.0, damping_ratio: 0.1),
                      shear: Some((frequency: 20.0, damping_ratio: 0.1)),
                      bend: Some((frequency: 5.0)), pins: [TopLeft, TopRight])],
            ropes: [(start: (1.0, 1.0, 0.0), end: (1.0, 0.2, 0.0), particles: 8, mass: 0.1,
                     spring: (frequency: 20.0, damping_ratio: 0.05))])"#
    );
    Simulation::from_scene(&Scene::parse(&text, "edits").expect("valid")).expect("builds")
}

/// An edit, made either through the API or as a World change.
#[derive(Clone, Copy, Debug)]
enum Edit {
    Grab(usize, DVec3),
    Release(usize),
    Pin(usize),
    Unpin(usize),
}

fn by_api(sim: &mut Simulation, edit: Edit) {
    match edit {
        Edit::Grab(i, at) => sim.grab(i, at),
        Edit::Release(i) => sim.release(i),
        Edit::Pin(i) => sim.pin(i),
        Edit::Unpin(i) => sim.unpin(i),
    }
    .unwrap();
}

/// The same edit as the World would take it from a game writing components: a Pin inserted
/// or removed, the particle placed (grab) or left at rest (freed), then a full gather.
fn by_world(sim: &mut Simulation, edit: Edit) {
    let e = sim.particle_entity(match edit {
        Edit::Grab(i, _) | Edit::Release(i) | Edit::Pin(i) | Edit::Unpin(i) => i,
    });
    let e = e.unwrap();
    let world = sim.world_mut();
    match edit {
        Edit::Grab(_, at) => {
            let _ = world.insert_one(e, Pin);
            let mut p = world.get::<&mut Particle>(e).unwrap();
            p.position = at;
            p.velocity = DVec3::ZERO;
        }
        Edit::Pin(_) => {
            let _ = world.insert_one(e, Pin);
        }
        Edit::Release(_) | Edit::Unpin(_) => {
            let _ = world.remove_one::<Pin>(e);
            world.get::<&mut Particle>(e).unwrap().velocity = DVec3::ZERO;
        }
    }
}

/// The edits of frame `f`: a free particle grabbed and dragged for 16 frames, a scene pin
/// taken off, a free particle pinned and freed again, a rope particle pinned.
fn edits(f: usize) -> Vec<Edit> {
    let drag = |f: usize| DVec3::new(0.1 + 0.02 * f as f64, 0.7, 0.05);
    match f {
        3 => vec![Edit::Grab(70, drag(f)), Edit::Pin(150)],
        4..=18 => {
            let mut e = vec![Edit::Grab(70, drag(f))];
            if f == 8 {
                e.push(Edit::Unpin(0));
                e.push(Edit::Pin(30));
            }
            e
        }
        19 => vec![Edit::Release(70)],
        24 => vec![Edit::Unpin(30), Edit::Unpin(150)],
        _ => vec![],
    }
}

fn state(sim: &Simulation) -> Vec<DVec3> {
    sim.positions()
        .iter()
        .chain(sim.velocities())
        .copied()
        .collect()
}

/// Runs the edit script on `make()` through the API and, on a twin, as World changes,
/// comparing the state after every frame; `auto`: the scene chooses its substeps.
fn compare(make: impl Fn() -> Simulation, auto: bool, name: &str) {
    let (mut api, mut world) = (make(), make());
    for f in 0..30 {
        for &e in &edits(f) {
            // With automatic substeps a World change also chooses the substeps again, at the
            // moved geometry; a drag (a pinned particle moved) does not.
            let drag = match e {
                Edit::Grab(i, _) => {
                    let p = world.particle_entity(i).unwrap();
                    world.world().get::<&Pin>(p).is_ok()
                }
                _ => false,
            };
            by_api(&mut api, e);
            if drag && auto {
                by_api(&mut world, e);
            } else {
                by_world(&mut world, e);
            }
        }
        let stats = *api.step().unwrap();
        let reference = *world.step().unwrap();
        assert!(f == 0 || !stats.gathered, "{name} frame {f}: re-gathered");
        assert_eq!(stats.substeps, reference.substeps, "{name} frame {f}");
        assert!(
            state(&api) == state(&world),
            "{name} frame {f}: the state differs from a full gather's"
        );
    }
    // The edits did something: the unpinned corner fell.
    let x = api.positions();
    assert!(
        x[0].y < 1.0 - 0.01,
        "{name}: the freed corner fell: {}",
        x[0]
    );
}

#[test]
fn pins_and_grabs_give_a_full_gathers_state_without_one() {
    for integrator in Integrator::ALL {
        for (substeps, auto) in [("substeps: 4,", false), ("", true)] {
            let name = integrator.name();
            compare(
                || scene(name, substeps),
                auto,
                &format!("{name} {substeps}"),
            );
        }
    }
}

/// On the device a drag writes the state, a pin refresh uploads the springs again: the same
/// state as a full gather's upload, bit for bit.
#[cfg(feature = "gpu")]
#[test]
fn on_the_gpu_pins_and_grabs_give_a_full_gathers_state_without_one() {
    use harmonic::internals::gpu::{GpuContext, Kernel};
    if common::gpu_or_skip(GpuContext::shared(true)).is_none() {
        return;
    }
    for integrator in Kernel::supported() {
        let name = integrator.name();
        let make = || {
            let mut sim = scene(name, "substeps: 4,");
            let config = SimConfig {
                backend: Backend::Gpu,
                ..*sim.config()
            };
            sim.set_config(config).unwrap();
            assert_eq!(sim.backend(), Backend::Gpu);
            sim
        };
        compare(make, false, &format!("{name} on the GPU"));
    }
}

#[test]
fn a_dragged_pin_is_where_it_was_put_each_frame() {
    let mut sim = scene("symplectic-euler", "");
    for f in 0..10 {
        let at = DVec3::new(0.3 * f as f64, 1.2, 0.0);
        sim.grab(11, at).unwrap();
        let stats = *sim.step().unwrap();
        assert!(f == 0 || !stats.gathered);
        assert_eq!(sim.positions()[11], at);
        assert_eq!(sim.velocities()[11], DVec3::ZERO);
    }
}

#[test]
fn freeing_a_particle_without_a_valid_mass_is_a_located_error() {
    // A pinned particle may hold any mass; freed, it is refused by name on the next step, and
    // again on every step until the World is fixed.
    let mut world = hecs::World::new();
    let a = world.spawn((
        Particle {
            position: DVec3::ZERO,
            velocity: DVec3::ZERO,
            mass: 0.0,
        },
        Pin,
    ));
    let b = world.spawn((Particle {
        position: DVec3::new(0.0, -1.0, 0.0),
        velocity: DVec3::ZERO,
        mass: 1.0,
    },));
    world.spawn((Spring {
        a,
        b,
        rest_length: 1.0,
        stiffness: 10.0,
        damping: 0.0,
    },));
    let mut sim = Simulation::new(world, SimConfig::default()).unwrap();
    sim.step().unwrap();
    let i = (0..2)
        .find(|&i| sim.particle_entity(i).unwrap() == a)
        .unwrap();
    // Freed and pinned again before a step: the World holds it pinned, and so does the step.
    sim.unpin(i).unwrap();
    sim.pin(i).unwrap();
    sim.step().unwrap();
    sim.unpin(i).unwrap();
    for _ in 0..2 {
        match sim.step() {
            Err(SimError::BadParticle { particle, what }) => {
                assert_eq!(particle, a);
                assert!(what.contains("mass"), "{what}");
            }
            other => panic!("expected BadParticle, got {other:?}"),
        }
    }
    sim.world_mut().get::<&mut Particle>(a).unwrap().mass = 2.0;
    sim.step().unwrap();
    assert!(sim.positions()[i].y < 0.0, "freed, it falls");
}
