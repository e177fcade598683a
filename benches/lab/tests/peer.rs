//! rapier's soft-body cloth, given our cloth, must be our model: the same statics and, as its
//! step shrinks, the same motion. Otherwise the bench's peer rows measure a different cloth.

use harmonic::glam::DVec3;
use harmonic::internals::buffers::Packed;
use harmonic_lab::accuracy::{rms, swinging_cloth};
use harmonic_lab::peer::{grid_strain, run_cloth};
use harmonic_lab::research::{Method, Stepper};

const G: DVec3 = DVec3::new(0.0, -9.81, 0.0);

#[test]
fn rapiers_cloth_hangs_where_ours_does() {
    let scene = swinging_cloth(8, 500.0, 0.0);
    let cloth = &scene.cloths[0];
    let packed = Packed::gather(&scene.build().world).unwrap();
    let ours = harmonic_lab::statics::relax(&packed, G, 1e-6, 2_000_000);
    let (ours_max, _) = grid_strain(cloth, &ours.positions);
    // ζ = 0.2 has settled by 5 s; rapier at its default substeps.
    let (theirs, _) = run_cloth(cloth, G, 5.0, 4, |_| ()).unwrap();
    let (their_max, _) = grid_strain(cloth, &theirs);
    let sag = rms(&ours.positions, &packed.x);
    let apart = rms(&theirs, &ours.positions);
    // The largest strain is at the pins, where rapier's edge sees the free particle's whole
    // mass: with the same frequency it would be twice as stiff there.
    assert!(
        (their_max / ours_max - 1.0).abs() < 0.08,
        "peak static strain: rapier {their_max:.4}, ours {ours_max:.4}"
    );
    assert!(
        apart < 0.1 * sag,
        "rapier hangs {apart:.2e} m from ours (sag {sag:.2e} m)"
    );
}

#[test]
fn rapiers_cloth_converges_to_our_motion() {
    let scene = swinging_cloth(8, 500.0, 2.0);
    let cloth = &scene.cloths[0];
    let packed = Packed::gather(&scene.build().world).unwrap();
    let t = 0.5;
    let steps = 4000;
    let h = t / steps as f64;
    let mut p = packed.clone();
    let mut solver = Stepper::new(Method::RK4, false, G);
    solver.prepare(&p, h).unwrap();
    for _ in 0..steps {
        solver.substep(&mut p, h).unwrap();
    }
    let moved = rms(&p.x, &packed.x);
    let error = |substeps| rms(&run_cloth(cloth, G, t, substeps, |_| ()).unwrap().0, &p.x);
    let (coarse, fine) = (error(8), error(64));
    assert!(
        fine < 0.5 * coarse,
        "8 substeps {coarse:.2e} m, 64 substeps {fine:.2e} m"
    );
    assert!(
        fine < 0.05 * moved,
        "64 substeps end {fine:.2e} m from ours (moved {moved:.2e} m)"
    );
}
