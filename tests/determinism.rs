//! The same scene gives bit-identical states on one thread and on two: the parallel passes
//! split work into fixed chunks and add partial sums in chunk order.

mod common;

use harmonic::prelude::*;

fn run(path: &str, integrator: Option<&str>, threads: usize, frames: usize) -> Vec<DVec3> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut scene = Scene::load(path).unwrap();
        if let Some(name) = integrator {
            scene.integrator = Some(name.to_string());
        }
        let mut sim = Simulation::from_scene(&scene).unwrap();
        common::run_state(&mut sim, frames)
    })
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
