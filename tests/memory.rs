//! The memory budget of a cloth on the CPU back end: at most 150 bytes of heap per particle with
//! the default integrator, its springs included, and 200 with the closed form (whose dampers
//! the energy audit books after each substep from a copy of the state at its start, 48 B), from building the scene through gathering and stepping (the peak of
//! live heap bytes, counted by a tracking global allocator; `harmonic run`'s peak RSS in
//! BENCHMARKS.md is the figure for the whole process).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use harmonic::prelude::*;

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

/// Peak heap bytes per particle while `integrator` builds, gathers and steps an n×n cloth.
fn peak_per_particle(n: u32, integrator: Integrator) -> f64 {
    let mut scene = harmonic::internals::hanging_cloth(n);
    scene.integrator = Some(integrator.name().into());
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..2 {
        sim.step().unwrap();
    }
    assert!(sim.positions().iter().all(|x| x.is_finite()));
    let particles = sim.positions().len();
    drop(sim);
    (PEAK.load(Ordering::Relaxed) - base) as f64 / particles as f64
}

#[test]
fn a_cloth_costs_at_most_150_bytes_per_particle() {
    // One test in this file: the counters see only it.
    let n = 512;
    let default = peak_per_particle(n, Integrator::default());
    // The closed form keeps the cloth a grid too.
    let harmonic = peak_per_particle(n, Integrator::Harmonic);
    // An integrator that needs the springs one by one, for scale.
    let expanded = peak_per_particle(n, Integrator::HarmonicGs);
    println!(
        "{n}×{n} cloth: {default:.1} B per particle (default), {harmonic:.1} B (harmonic), {expanded:.1} B (harmonic-gs)"
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
}
