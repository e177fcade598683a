//! The same scene gives bit-identical states on one thread and on two: the parallel passes
//! split work into fixed chunks and add partial sums in chunk order.

mod common;

use harmonic::prelude::*;

/// The state after `frames` frames of `scene`, stepped on a pool of `threads` threads.
fn state_on(threads: usize, scene: &Scene, frames: usize) -> Vec<DVec3> {
    common::on_threads(threads, || {
        let mut sim = Simulation::from_scene(scene).unwrap();
        common::run_state(&mut sim, frames)
    })
}

fn run(path: &str, integrator: Option<&str>, threads: usize, frames: usize) -> Vec<DVec3> {
    let mut scene = Scene::load(path).unwrap();
    if let Some(name) = integrator {
        scene.integrator = Some(name.to_string());
    }
    state_on(threads, &scene, frames)
}

fn same_bits(a: &[DVec3], b: &[DVec3]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(p, q)| {
            p.to_array()
                .iter()
                .zip(q.to_array())
                .all(|(x, y)| x.to_bits() == y.to_bits())
        })
}

#[test]
fn one_thread_and_two_give_the_same_bits() {
    let root = env!("CARGO_MANIFEST_DIR");
    for (scene, integrator, frames) in [
        // 500 frames (14,500 substeps) of the 64×64 cloth: long enough for any order
        // dependence to grow into visible bits.
        ("scenes/hanging_cloth.ron", None, 500),
        ("scenes/hanging_cloth.ron", Some("harmonic-gs"), 10),
        ("scenes/hanging_cloth.ron", Some("implicit-euler"), 5),
        ("scenes/drape_sphere.ron", None, 40),
        ("scenes/trampoline.ron", None, 60),
    ] {
        let path = format!("{root}/{scene}");
        let one = run(&path, integrator, 1, frames);
        let two = run(&path, integrator, 2, frames);
        assert!(one.iter().all(|x| x.is_finite()));
        assert!(
            same_bits(&one, &two),
            "{scene} ({integrator:?}) differs between 1 and 2 threads"
        );
    }
}

/// Many small cloths run side by side on the grid pass: on one thread or two, each cloth ends
/// bit-identical to the same cloth stepped alone (cloths do not interact).
#[test]
fn cloths_side_by_side_match_each_cloth_alone() {
    let frames = 200;
    let on = |threads: usize, scene: &Scene| state_on(threads, scene, frames);
    // 9 cloths of 24×24: 5,184 particles, enough for the pass to split them over threads.
    let (n, k) = (24, 9);
    let all = harmonic::internals::hanging_cloths(n, k);
    let grids = Simulation::from_scene(&all)
        .unwrap()
        .packed()
        .topology
        .grids
        .len();
    assert_eq!(grids, k as usize, "each cloth on the grid pass");
    let (one, two) = (on(1, &all), on(2, &all));
    assert!(one.iter().all(|x| x.is_finite()));
    assert!(same_bits(&one, &two), "1 and 2 threads differ");
    // States are all positions, then all velocities.
    let (per, total) = ((n * n) as usize, (k * n * n) as usize);
    for (i, cloth) in all.cloths.iter().enumerate() {
        let alone = Scene {
            cloths: vec![cloth.clone()],
            ..all.clone()
        };
        let state = on(2, &alone);
        let (x, v) = (
            i * per..(i + 1) * per,
            total + i * per..total + (i + 1) * per,
        );
        assert!(
            same_bits(&state[..per], &two[x]) && same_bits(&state[per..], &two[v]),
            "cloth {i} differs from itself alone"
        );
    }
    // The cloths moved: the check is not of states at rest.
    let start = Simulation::from_scene(&all).unwrap().positions().to_vec();
    let moved = start
        .iter()
        .zip(&one)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0, f64::max);
    assert!(moved > 1e-3, "moved {moved}");
}
