//! The speed-against-error report's scenes must move further by t = 1 s than its error
//! criterion, or a run that never moved, or one that only settled, would pass it.

use glam::DVec3;
use harmonic::accuracy::{self, rms, RULE_ERROR};
use harmonic::buffers::Packed;
use harmonic::integrate::{Integrator, Solver};

#[test]
fn bench_cloth_moves_well_past_the_error_criterion() {
    let scene = accuracy::swinging_cloth(16, 500.0, accuracy::THROW);
    let g = DVec3::from(scene.gravity);
    let start = Packed::gather(&scene.build().world).unwrap();
    // Symplectic Euler at a quarter of its automatic step: an independent fine run.
    let steps = 4 * harmonic::step_control::choose(&start, Integrator::SymplecticEuler, 1.0)
        .substeps as u64;
    let h = accuracy::T / steps as f64;
    let mut p = start.clone();
    let mut solver = Solver::new(Integrator::SymplecticEuler, false, g);
    for _ in 0..steps {
        solver.substep(&mut p, h).unwrap();
    }
    let settled = harmonic::statics::relax(&start, g, 1e-4, 400_000).positions;
    let (still, rest) = (rms(&start.x, &p.x), rms(&settled, &p.x));
    println!("never moving: {still:.3e} m, static equilibrium: {rest:.3e} m");
    assert!(still > 3.0 * RULE_ERROR, "never moving scores {still} m");
    assert!(
        rest > 3.0 * RULE_ERROR,
        "the static equilibrium scores {rest} m"
    );

    // Dropped from rest instead, the same cloth fails the check: the test can fail.
    let mut dropped = accuracy::swinging_cloth(16, 500.0, 0.0);
    dropped.gravity = scene.gravity;
    let start = Packed::gather(&dropped.build().world).unwrap();
    let mut p = start.clone();
    let mut solver = Solver::new(Integrator::SymplecticEuler, false, g);
    for _ in 0..steps {
        solver.substep(&mut p, h).unwrap();
    }
    assert!(rms(&start.x, &p.x) < 3.0 * RULE_ERROR);
}
