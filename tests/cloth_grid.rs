//! Cloth springs kept as one grid component: the grid pass (symplectic and explicit Euler,
//! and the closed form, no memory per spring) against the same springs spawned one by one,
//! and the errors a grid that no longer matches its particles gives.

mod common;

use std::collections::HashMap;

use harmonic::prelude::*;
use harmonic::{ClothGrid, ClothSprings, GridLink, SceneIndex, SimError};
use hecs::{Entity, World};

fn cloth((cols, rows): (u32, u32), integrator: Integrator) -> Scene {
    let mut scene = harmonic::internals::hanging_cloth(cols);
    scene.cloths[0].resolution = (cols, rows);
    scene.dt = 1e-3;
    scene.substeps = Some(4);
    scene.integrator = Some(integrator.name().into());
    // Damped, so the damping term of the pass is exercised too.
    for c in &mut scene.cloths {
        c.structural.damping = Some(0.05);
    }
    scene
}

/// The World with every `ClothSprings` replaced by one `Spring` entity per spring, made here
/// from the grid's definition (an independent expansion).
fn springs_one_by_one(mut world: World) -> World {
    let by_index: HashMap<u32, Entity> = world
        .query::<(Entity, &SceneIndex)>()
        .iter()
        .map(|(e, i)| (i.0, e))
        .collect();
    let grids: Vec<(Entity, ClothSprings)> = world
        .query::<(Entity, &ClothSprings)>()
        .iter()
        .map(|(e, c)| (e, c.clone()))
        .collect();
    for (e, cloth) in grids {
        world.despawn(e).unwrap();
        let g = cloth.grid;
        for r in 0..g.rows as i64 {
            for c in 0..g.cols as i64 {
                for l in &cloth.links {
                    let (c1, r1) = (c + l.offset.0 as i64, r + l.offset.1 as i64);
                    if c1 < 0 || r1 < 0 || c1 >= g.cols as i64 || r1 >= g.rows as i64 {
                        continue;
                    }
                    let at = |c: i64, r: i64| by_index[&(g.first + (r * g.cols as i64 + c) as u32)];
                    world.spawn((Spring {
                        a: at(c, r),
                        b: at(c1, r1),
                        rest_length: l.rest_length,
                        stiffness: l.stiffness,
                        damping: l.damping,
                    },));
                }
            }
        }
    }
    world
}

#[test]
fn the_grid_pass_matches_the_springs_one_by_one() {
    // 24×24 runs on the calling thread in one band; 72×72 in bands on rayon's pool; rows of 5
    // and 9 (shorter than the pass's chunks of 8, and one over) in bands too.
    for n in [(24, 24), (72, 72), (5, 900), (9, 500)] {
        for integrator in [
            Integrator::SymplecticEuler,
            Integrator::ExplicitEuler,
            Integrator::Harmonic,
        ] {
            let mut scene = cloth(n, integrator);
            // Explicit Euler grows every mode at any step (and the rounding difference with
            // it): small steps, few frames.
            // The closed form's Jacobi sum is stable to 0.73× symplectic Euler's step on a cloth
            // (STABILITY.md): 4× the substeps.
            let frames = match integrator {
                Integrator::ExplicitEuler => {
                    scene.substeps = Some(64);
                    8
                }
                Integrator::Harmonic => {
                    scene.substeps = Some(16);
                    30
                }
                _ => 60,
            };
            grid_against_single(&scene, frames, |w| w, &format!("{integrator} {n:?}"));
        }
    }
}

/// Runs `scene` with its cloth kept as a grid and with its springs one by one, each World
/// first changed by `edit`, and asserts they agree to rounding.
fn grid_against_single(scene: &Scene, frames: usize, edit: impl Fn(World) -> World, what: &str) {
    let built = scene.build();
    let mut grid = Simulation::with_props(edit(built.world), built.config, None).unwrap();
    assert_eq!(grid.packed().topology.grids.len(), 1);
    assert!(grid.packed().springs.is_empty());
    let built = scene.build();
    let world = springs_one_by_one(edit(built.world));
    let mut single = Simulation::with_props(world, built.config, None).unwrap();
    assert!(single.packed().topology.grids.is_empty());
    assert_eq!(grid.packed().spring_count(), single.packed().spring_count());
    let start = grid.positions().to_vec();
    let (a, b) = (
        common::run_state(&mut grid, frames),
        common::run_state(&mut single, frames),
    );
    // Only the order of each particle's sum differs: agreement to rounding.
    let worst = a
        .iter()
        .zip(&b)
        .map(|(p, q)| (*p - *q).length())
        .fold(0.0, f64::max);
    let moved = start
        .iter()
        .zip(&a)
        .map(|(p, q)| (*p - *q).length())
        .fold(0.0, f64::max);
    assert!(a.iter().all(|x| x.is_finite()));
    assert!(moved > 1e-4, "{what}: the cloth must move ({moved:e})");
    assert!(
        worst < 1e-10,
        "{what}: grid and single springs differ by {worst:e}"
    );
    // The grid pass books its dampers' work in the pass, per particle; the single springs
    // are booked spring by spring after each substep: the same discrete work.
    let (dg, ds) = (grid.diagnostics().audit, single.diagnostics().audit);
    assert!(ds.damping > 0.0, "{what}: {ds:?}");
    assert!(
        (dg.damping - ds.damping).abs() < 1e-9 * ds.damping,
        "{what}: dampers booked {:e} on the grid, {:e} spring by spring",
        dg.damping,
        ds.damping
    );
    assert!(
        (dg.residual - ds.residual).abs() < 1e-9 * ds.scale,
        "{what}: {dg:?} {ds:?}"
    );
}

#[test]
fn the_closed_form_on_a_grid_handles_any_masses() {
    // The grid pass holds the closed form for one mass (the centre particle's); springs at a
    // pin or at a particle of another mass are corrected one by one. Here: heavier particles
    // along a row and a column, one lighter particle, and the centre itself changed, so the
    // nominal mass is not the common one.
    for n in [(24, 24), (72, 72)] {
        let mut scene = cloth(n, Integrator::Harmonic);
        scene.substeps = Some(16);
        let cols = n.0;
        let edit = |mut world: World| {
            for (i, p) in world.query_mut::<(&SceneIndex, &mut Particle)>() {
                let (c, r) = (i.0 % cols, i.0 / cols);
                if r == 5 || c == 7 {
                    p.mass *= 3.0;
                }
                if (c, r) == (2, 11) {
                    p.mass *= 0.5;
                }
                if (c, r) == (cols / 2, n.1 / 2) {
                    p.mass *= 1.7;
                }
            }
            world
        };
        grid_against_single(&scene, 30, edit, &format!("harmonic {n:?}, uneven masses"));
    }
}

#[test]
fn exact_displacement_gets_the_grid_expanded() {
    let mut sim = Simulation::from_scene(&cloth((16, 16), Integrator::Harmonic)).unwrap();
    assert_eq!(sim.packed().topology.grids.len(), 1);
    let mut c = *sim.config();
    c.exact_displacement = true;
    sim.set_config(c).unwrap();
    assert!(sim.packed().topology.grids.is_empty());
    sim.step().unwrap();
    assert!(sim.positions().iter().all(|x| x.is_finite()));
}

#[test]
fn a_grid_that_no_longer_matches_its_particles_is_a_located_error() {
    let mut sim = Simulation::from_scene(&cloth((8, 8), Integrator::SymplecticEuler)).unwrap();
    sim.step().unwrap();
    let grid = sim.packed().topology.grids[0].entity;
    // A particle of the cloth despawned: its scene index is missing.
    let gone = sim.particle_entity(19).unwrap();
    let particle = *sim.world().get::<&Particle>(gone).unwrap();
    sim.world_mut().despawn(gone).unwrap();
    let e = sim.step().unwrap_err();
    assert!(
        matches!(e, SimError::BrokenCloth { cloth, index: 19 } if cloth == grid),
        "{e}"
    );
    // Back, then a second particle claiming the same scene index.
    sim.world_mut().spawn((particle, SceneIndex(19)));
    sim.step().unwrap();
    let twin = sim.world_mut().spawn((particle, SceneIndex(63)));
    let e = sim.step().unwrap_err();
    assert!(matches!(e, SimError::BrokenCloth { index: 63, .. }), "{e}");
    sim.world_mut().despawn(twin).unwrap();
    sim.step().unwrap();
    // A second grid over some of the same particles, and bad links.
    let link = GridLink {
        offset: (1, 0),
        rest_length: 0.1,
        stiffness: 1.0,
        damping: 0.0,
    };
    let bad_grids = [
        (
            ClothSprings {
                grid: ClothGrid {
                    first: 60,
                    cols: 2,
                    rows: 2,
                },
                links: vec![link],
            },
            "overlap",
        ),
        (
            ClothSprings {
                grid: ClothGrid {
                    first: 0,
                    cols: 0,
                    rows: 8,
                },
                links: vec![],
            },
            "at least 1 × 1",
        ),
    ];
    for (g, what) in bad_grids {
        let extra = sim.world_mut().spawn((g,));
        let e = sim.step().unwrap_err();
        assert!(e.to_string().contains(what), "{e}");
        sim.world_mut().despawn(extra).unwrap();
    }
    for (l, what) in [
        (
            GridLink {
                offset: (0, 0),
                ..link
            },
            "offset",
        ),
        (
            GridLink {
                stiffness: f64::NAN,
                ..link
            },
            "stiffness",
        ),
        (
            GridLink {
                rest_length: 0.0,
                ..link
            },
            "rest length",
        ),
    ] {
        let keep = {
            let mut c = sim.world_mut().get::<&mut ClothSprings>(grid).unwrap();
            let keep = c.links[0];
            c.links[0] = l;
            keep
        };
        let e = sim.step().unwrap_err();
        assert!(
            matches!(&e, SimError::BadCloth { cloth, what: w } if *cloth == grid && w.contains(what)),
            "{e}"
        );
        sim.world_mut()
            .get::<&mut ClothSprings>(grid)
            .unwrap()
            .links[0] = keep;
    }
    // Every error left the state as it was, and the repaired scene steps on.
    let before = sim.positions().to_vec();
    assert_eq!(before.len(), 64);
    sim.step().unwrap();
    assert!(sim.positions().iter().all(|x| x.is_finite()));
    assert_ne!(sim.positions(), &before[..]);
}

#[test]
fn other_integrators_get_the_grid_expanded() {
    let mut sim = Simulation::from_scene(&cloth((16, 16), Integrator::SymplecticEuler)).unwrap();
    let springs = sim.packed().spring_count();
    assert!(sim.packed().springs.is_empty());
    let mut c = *sim.config();
    c.integrator = Integrator::HarmonicGs;
    sim.set_config(c).unwrap();
    assert!(sim.packed().topology.grids.is_empty());
    assert_eq!(sim.packed().springs.len(), springs);
    assert!(sim.packed().colouring.colours() > 0);
    sim.step().unwrap();
    c.integrator = Integrator::SymplecticEuler;
    sim.set_config(c).unwrap();
    assert_eq!(sim.packed().topology.grids.len(), 1);
    sim.step().unwrap();
    assert!(sim.positions().iter().all(|x| x.is_finite()));
}

#[test]
fn a_link_offset_that_cannot_be_reversed_is_refused() {
    let mut sim = Simulation::from_scene(&cloth((4, 4), Integrator::SymplecticEuler)).unwrap();
    let grid = sim.packed().topology.grids[0].entity;
    sim.world_mut()
        .get::<&mut ClothSprings>(grid)
        .unwrap()
        .links[0]
        .offset = (i32::MIN, 1);
    let e = sim.step().unwrap_err();
    assert!(
        matches!(&e, SimError::BadCloth { what, .. } if what.contains("offset")),
        "{e}"
    );
}
