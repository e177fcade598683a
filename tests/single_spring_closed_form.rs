//! One spring moving along its own axis, exact displacement on: the harmonic step reproduces
//! the closed-form motion in every damping regime, at large steps and at mass ratio 1:1000.

mod common;
use common::*;

#[test]
fn harmonic_with_exact_displacement_tracks_the_closed_form() {
    for (ma, mb) in [(1.0, 1.0), (1.0, 1000.0)] {
        for zeta in [0.0, 0.2, 1.0, 2.0] {
            for ratio in [0.5, 2.0, 8.0625] {
                let (d0, v0) = (0.1, 0.3);
                let (mut sim, w0, alpha) = pair(ma, mb, zeta, ratio, d0, v0, true, "harmonic");
                let h = sim.config().dt;
                let mut worst: f64 = 0.0;
                for k in 1..=1000u32 {
                    sim.step().unwrap();
                    let (d, v) = stretch(&sim);
                    let (dr, vr) = textbook(w0 * w0, alpha, k as f64 * h, d0, v0);
                    // 1e-5 relative, with a floor at the round-off of positions near 1 m.
                    let (tol_d, tol_v) = (1e-5 * dr.abs() + 1e-12, 1e-5 * vr.abs() + 1e-12 * w0);
                    assert!(
                        (d - dr).abs() <= tol_d && (v - vr).abs() <= tol_v,
                        "masses {ma}:{mb} ζ {zeta} h/h_c {ratio} step {k}: δ {d} vs {dr}, δ̇ {v} vs {vr}"
                    );
                    worst = worst.max((d - dr).abs() / (dr.abs() + 1e-12));
                }
                println!(
                    "masses {ma}:{mb} ζ {zeta} h/h_c {ratio}: worst relative δ error {worst:.2e}"
                );
            }
        }
    }
}

#[test]
fn isolated_undamped_spring_never_gains_energy() {
    for ratio in [0.5, 2.0625, 8.0625] {
        let (mut sim, _, _) = pair(1.0, 3.0, 0.0, ratio, 0.1, 0.3, true, "harmonic");
        let e0 = sim.diagnostics().energy;
        let mut max_e = e0;
        for _ in 0..100_000 {
            sim.step().unwrap();
            max_e = max_e.max(sim.diagnostics().energy);
        }
        println!("h/h_c {ratio}: E0 {e0:.12e}, max E {max_e:.12e}");
        assert!(
            max_e <= e0 * (1.0 + 1e-9),
            "h/h_c {ratio}: energy grew from {e0} to {max_e}"
        );
    }
}
