//! The speed-against-error report's scenes must move further by t = 1 s than its error
//! criterion, or a run that never moved, or one that only settled, would pass it.

use harmonic::glam::DVec3;
use harmonic::internals::buffers::Packed;
use harmonic::internals::integrate::{Integrator, Solver};
use harmonic::scene::Scene;
use harmonic_lab::accuracy::{self, rms, RULE_ERROR};

/// The start state and the state at t = 1 s by symplectic Euler at a quarter of its automatic
/// step: an independent fine run.
fn fine_run(scene: &Scene) -> (Packed, Packed) {
    let g = DVec3::from(scene.gravity);
    let start = Packed::gather(&scene.build().world).unwrap();
    let steps =
        4 * harmonic::internals::step_control::choose(&start, Integrator::SymplecticEuler, 1.0)
            .substeps as u64;
    let h = accuracy::T / steps as f64;
    let mut p = start.clone();
    let mut solver = Solver::new(Integrator::SymplecticEuler, false, g);
    for _ in 0..steps {
        solver.substep(&mut p, h).unwrap();
    }
    (start, p)
}

#[test]
fn bench_cloth_moves_well_past_the_error_criterion() {
    let scene = accuracy::swinging_cloth(16, 500.0, accuracy::THROW);
    let g = DVec3::from(scene.gravity);
    let (start, end) = fine_run(&scene);
    let settled = harmonic_lab::statics::relax(&start, g, 1e-4, 400_000).positions;
    let (still, rest) = (rms(&start.x, &end.x), rms(&settled, &end.x));
    println!("never moving: {still:.3e} m, static equilibrium: {rest:.3e} m");
    assert!(still > 3.0 * RULE_ERROR, "never moving scores {still} m");
    assert!(
        rest > 3.0 * RULE_ERROR,
        "the static equilibrium scores {rest} m"
    );

    // Dropped from rest instead, the same cloth fails the check: the test can fail.
    let (start, end) = fine_run(&accuracy::swinging_cloth(16, 500.0, 0.0));
    assert!(rms(&start.x, &end.x) < 3.0 * RULE_ERROR);
}
