//! The memory budget of a cloth on the CPU back end, from building the scene through gathering
//! and stepping (the peak of live heap bytes, counted by a tracking global allocator;
//! `harmonic run`'s peak RSS in BENCHMARKS.md is the figure for the whole process):
//! - the grid: at most 150 bytes per particle with symplectic Euler and fixed substeps, its
//!   springs included, and 200 with the closed form (whose dampers the energy audit books after
//!   each substep from a copy of the state at its start, 48 B);
//! - the default path (no integrator named, automatic substeps, a motion check under way): the
//!   grid plus the accuracy controller's own state, at most 210 bytes per particle. That state
//!   is the motion check's second run between frames (its state in f32, 24 B, and the check
//!   frame's end, 12 B) and its solver's band scratch; a frame taken again starts from the
//!   World, which holds the frame's start, with no copy of it.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use harmonic::prelude::*;

mod common;

struct Tracking;
static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(bytes: usize) {
    let live = LIVE.fetch_add(bytes, Ordering::Relaxed) + bytes;
    PEAK.fetch_max(live, Ordering::Relaxed);
}

unsafe impl GlobalAlloc for Tracking {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        grew(layout.size());
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // Counted as both blocks at once, the worst case of a moving realloc.
        grew(new_size);
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        p
    }
}

#[global_allocator]
static GLOBAL: Tracking = Tracking;

/// Peak heap bytes per particle while `integrator` (None: the scene names none) builds,
/// gathers and steps an n×n cloth for `frames` frames, with fixed substeps or automatic ones.
fn peak_per_particle(n: u32, integrator: Option<Integrator>, auto: bool, frames: u32) -> f64 {
    let mut scene = harmonic::internals::hanging_cloth(n);
    scene.integrator = integrator.map(|i| i.name().into());
    if auto {
        scene.substeps = None;
    }
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..frames {
        sim.step().unwrap();
    }
    assert_eq!(sim.config().auto_substeps, auto);
    assert!(sim.positions().iter().all(|x| x.is_finite()));
    let particles = sim.positions().len();
    drop(sim);
    (PEAK.load(Ordering::Relaxed) - base) as f64 / particles as f64
}

#[test]
fn a_cloth_costs_at_most_150_bytes_per_particle() {
    // One test in this file: the counters see only it.
    let n = 512;
    let default = peak_per_particle(n, Some(Integrator::default()), false, 2);
    // The closed form keeps the cloth a grid too.
    let harmonic = peak_per_particle(n, Some(Integrator::Harmonic), false, 2);
    // An integrator that needs the springs one by one, for scale.
    let expanded = peak_per_particle(n, Some(Integrator::HarmonicGs), false, 2);
    // What a scene gets that names neither: the integrator chosen on the simulation's own
    // gather, the substeps by the accuracy controller, a motion check measured and the next
    // one under way.
    let path = peak_per_particle(n, None, true, 32);
    let controller = path - default;
    println!(
        "{n}×{n} cloth: {default:.1} B per particle (symplectic Euler, fixed substeps), \
         {harmonic:.1} B (harmonic), {expanded:.1} B (harmonic-gs); the default path \
         {path:.1} B, of which the accuracy controller's state {controller:.1} B"
    );
    assert!(
        path <= 210.0,
        "the default path peaks at {path:.1} B per particle"
    );
    // 24 + 12 B and a little scratch; nothing the size of a second cloth.
    assert!(
        controller <= 60.0,
        "the controller's state takes {controller:.1} B per particle"
    );
    assert!(
        default <= 150.0,
        "the default integrator peaks at {default:.1} B per particle"
    );
    assert!(
        harmonic <= 200.0,
        "harmonic peaks at {harmonic:.1} B per particle"
    );
    // Six springs per particle one by one cost several times more: the budget is the grid's.
    assert!(expanded > 3.0 * default, "{expanded:.1} vs {default:.1}");
    // A mesh cloth of the same grid (one diagonal a cell), built from its vertex and triangle
    // lists: its springs one by one, as `expanded`, and the mesh's own building on top.
    let mesh = mesh_peak_per_particle(128);
    println!("128×128 mesh: {mesh:.1} B per particle (symplectic Euler, fixed substeps)");
    // As much as the grid's springs one by one: the mesh's building (welding, its topology)
    // passes before the springs are packed, and adds nothing to the peak beyond that.
    assert!(
        mesh <= 1.1 * expanded,
        "a mesh peaks at {mesh:.1} B per particle, the grid's springs one by one {expanded:.1}"
    );
}

/// Peak heap bytes per particle while an n×n grid mesh builds, gathers and steps two frames
/// (its vertex and triangle lists made before the count starts, as a loaded scene's are).
fn mesh_peak_per_particle(n: u32) -> f64 {
    use harmonic::scene::mesh::{MeshCloth, MeshPin};
    let d = 1.0 / f64::from(n - 1);
    let vertices = (0..n)
        .flat_map(|r| (0..n).map(move |c| [f64::from(c) * d, 1.0 - f64::from(r) * d, 0.0]))
        .collect();
    let triangles = common::grid_triangles(n, n);
    let mut scene = Scene::new(1.0 / 60.0);
    scene.substeps = Some(4);
    scene.integrator = Some("symplectic-euler".into());
    let mesh: MeshCloth = ron::from_str(
        "(mass: Some(1.0), stretch: (frequency: Some(30.0), damping_ratio: Some(0.1)), bend: Some((frequency: Some(3.0))))",
    )
    .unwrap();
    scene.meshes.push(MeshCloth {
        vertices,
        triangles,
        pins: vec![MeshPin::Vertices(vec![0, n - 1])],
        ..mesh
    });
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..2 {
        sim.step().unwrap();
    }
    let particles = sim.positions().len();
    drop(sim);
    (PEAK.load(Ordering::Relaxed) - base) as f64 / particles as f64
}
