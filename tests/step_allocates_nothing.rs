//! The step allocates nothing once the scene is gathered. On the parallel path the frame is
//! one rayon job; rayon's injector queue recycles a block every 63 jobs, the only allocation.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use harmonic::prelude::*;

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations_per_frame(n: u32, integrator: Integrator, exact: bool) -> f64 {
    let mut scene = harmonic::internals::hanging_cloth(n);
    scene.integrator = Some(integrator.name().to_string());
    scene.exact_displacement = exact;
    scene.substeps = Some(4);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..5 {
        sim.step().unwrap();
    }
    let frames = 630;
    let before = ALLOCS.load(Ordering::Relaxed);
    for _ in 0..frames {
        sim.step().unwrap();
    }
    (ALLOCS.load(Ordering::Relaxed) - before) as f64 / frames as f64
}

#[test]
fn stepping_allocates_nothing() {
    // One test thread: the counter sees only this test. rayon's workers allocate as they
    // start; every one has started once each has run a job.
    rayon::broadcast(|_| ());
    for (integrator, exact) in [
        (Integrator::Harmonic, false),
        (Integrator::Harmonic, true),
        (Integrator::SymplecticEuler, false),
        (Integrator::ExplicitEuler, false),
    ] {
        // 24×24 (3,218 springs): every pass on the calling thread.
        let serial = allocations_per_frame(24, integrator, exact);
        // 72×72 = 5184 particles: passes on rayon's pool.
        let parallel = allocations_per_frame(72, integrator, exact);
        println!("{integrator} (exact {exact}): {serial} allocations per frame serial, {parallel} parallel");
        assert_eq!(serial, 0.0, "{integrator} allocates in the step");
        assert!(
            parallel <= 1.0 / 63.0 + 1e-9,
            "{integrator} allocates {parallel} times per frame"
        );
    }
    // The game-loop path: advance (fixed steps from frame times) and render (interpolated
    // positions, normals, triangles).
    let mut sim = Simulation::from_scene(&harmonic::internals::hanging_cloth(24)).unwrap();
    for _ in 0..5 {
        let a = sim.advance(1.0 / 60.0).unwrap();
        sim.render(a.alpha);
    }
    let before = ALLOCS.load(Ordering::Relaxed);
    for i in 0..120 {
        let a = sim.advance(if i % 2 == 0 { 0.01 } else { 0.02 }).unwrap();
        let view = sim.render(a.alpha);
        assert_eq!(view.positions.len(), view.normals.len());
    }
    let game_loop = ALLOCS.load(Ordering::Relaxed) - before;
    assert_eq!(
        game_loop, 0,
        "advance + render allocated {game_loop} times in 120 frames"
    );
    // The game's forces, set anew every frame: the force stage and its books allocate nothing.
    let mut forces = vec![DVec3::ZERO; sim.positions().len()];
    sim.set_forces(&forces).unwrap();
    sim.step().unwrap();
    let before = ALLOCS.load(Ordering::Relaxed);
    for i in 0..120 {
        for (k, f) in forces.iter_mut().enumerate() {
            *f = DVec3::new(1e-3 * (i + k % 7) as f64, 0.0, 0.0);
        }
        sim.set_forces(&forces).unwrap();
        sim.step().unwrap();
    }
    let forced = ALLOCS.load(Ordering::Relaxed) - before;
    assert_eq!(
        forced, 0,
        "set_forces + step allocated {forced} times in 120 frames"
    );
    // Driven pins and motion constraints, their targets set anew every frame.
    sim.clear_forces();
    let n = sim.positions().len();
    let pins = sim.drive(&[0, 23]).unwrap();
    let free: Vec<usize> = (24..n).step_by(5).collect();
    let within = sim.drive_within(&free, &vec![0.05; free.len()]).unwrap();
    let mut pose = free.iter().map(|&i| sim.positions()[i]).collect::<Vec<_>>();
    let mut ends = [sim.positions()[0], sim.positions()[23]];
    sim.step().unwrap();
    let before = ALLOCS.load(Ordering::Relaxed);
    for _ in 0..120 {
        let step = DVec3::new(1e-3, 0.0, 0.0);
        ends.iter_mut().for_each(|x| *x += step);
        pose.iter_mut().for_each(|x| *x += step);
        sim.set_drive_targets(pins, &ends).unwrap();
        sim.set_drive_targets(within, &pose).unwrap();
        sim.step().unwrap();
    }
    let driven = ALLOCS.load(Ordering::Relaxed) - before;
    assert_eq!(
        driven, 0,
        "set_drive_targets + step allocated {driven} times in 120 frames"
    );
    // Air in a gusting wind: the air stage writes its forces in place.
    let mut scene = harmonic::internals::hanging_cloth(24);
    scene.cloths[0].air = Some(harmonic::Aero::default());
    scene.wind = harmonic::Wind {
        velocity: [6.0, 0.0, 1.0],
        gust: Some(harmonic::Gust {
            strength: 2.0,
            length: 3.0,
            period: 1.0,
            seed: 1,
        }),
    };
    scene.substeps = Some(4);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    assert!(sim.schedule().has(StageKind::Air));
    sim.step().unwrap();
    let before = ALLOCS.load(Ordering::Relaxed);
    for _ in 0..120 {
        sim.step().unwrap();
    }
    let blown = ALLOCS.load(Ordering::Relaxed) - before;
    assert_eq!(
        blown, 0,
        "the air stage allocated {blown} times in 120 frames"
    );
}
