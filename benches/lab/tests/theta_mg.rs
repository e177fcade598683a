//! `theta-mg` (a θ-step solved by one multigrid V-cycle): stable at every step on the
//! threshold systems and bounded on the hard cases, convergent to the fine-step reference,
//! and less damped than implicit Euler.

#[path = "../../../tests/common/mod.rs"]
mod common;

use harmonic::glam::DVec3;
use harmonic::internals::buffers::Packed;
use harmonic::prelude::*;
use harmonic_lab::accuracy;
use harmonic_lab::stability::{self, Start, GROWTH_TOL};

#[test]
fn stable_at_every_hard_case_ratio_on_the_threshold_systems() {
    for study in stability::threshold_systems() {
        let p = Packed::gather(&study.scene.build().world).unwrap();
        let hc = stability::h_crit(&p);
        for r in stability::RATIOS {
            let g = stability::growth_rate(&p, Integrator::ThetaMg, false, r * hc, 2000)
                .expect("theta-mg prepares on every threshold system");
            assert!(
                g <= 1.0 + GROWTH_TOL,
                "{}: growth {g} per step at {r} h_c",
                study.name
            );
        }
    }
}

#[test]
fn every_hard_case_stays_bounded_in_one_step_per_frame() {
    let mut worst: f64 = 0.0;
    for (path, max_strain, substeps) in common::hard_cases_max_strain(Some("theta-mg")) {
        assert_eq!(substeps, 1, "{}", path.display());
        assert!(
            max_strain.is_finite() && max_strain < stability::BLOWUP_STRAIN,
            "{}: max strain {max_strain}",
            path.display()
        );
        worst = worst.max(max_strain);
    }
    println!("largest max strain over the hard cases: {worst:.3}");
}

/// The damped chain of 20 from rest, its gravity, h_c and its RK4 positions at t = 1 s.
struct Chain {
    packed: Packed,
    g: DVec3,
    hc: f64,
    reference: Vec<DVec3>,
}

impl Chain {
    fn new() -> Chain {
        let (scene, _) = stability::chain(20, 0.2, Start::Rest);
        let packed = Packed::gather(&scene.build().world).unwrap();
        let g = DVec3::from(scene.gravity);
        Chain {
            hc: stability::h_crit(&packed),
            reference: accuracy::reference(&packed, g).unwrap().0,
            packed,
            g,
        }
    }

    /// RMS error at t = 1 s against the reference, at `steps` per second.
    fn error(&self, integrator: Integrator, steps: u64) -> f64 {
        let (x, ..) = accuracy::simulate(&self.packed, integrator, self.g, steps, 1.0)
            .unwrap_or_else(|| panic!("{integrator} at {steps} steps/s"));
        accuracy::rms(&x, &self.reference)
    }
}

#[test]
fn converges_to_the_fine_step_reference() {
    // A fixed Jacobi weight of 1/2 leaves half of each sweep's correction undone even as
    // h → 0, and stalled at 3 cm here; the l1 sweeps are exact in that limit.
    let chain = Chain::new();
    let steps = [480, 960, 1920, 3840];
    let e: Vec<f64> = steps
        .iter()
        .map(|&n| chain.error(Integrator::ThetaMg, n))
        .collect();
    println!("theta-mg errors at {steps:?} steps/s: {e:?}");
    assert!(e.windows(2).all(|w| w[1] < w[0]), "{e:?}");
    assert!(e[3] < 0.25 * e[0], "{e:?}");
}

#[test]
fn more_accurate_than_implicit_euler_up_to_h_c_on_the_damped_chain() {
    // θ = 0.6 damps less than implicit Euler (θ = 1). Past h_c this chain turns: at 2 and 4 h_c
    // implicit Euler is 1.6× closer (STABILITY.md), so the claim stops at h_c.
    let chain = Chain::new();
    for ratio in [0.5, 1.0] {
        let n = (1.0 / (ratio * chain.hc)).round() as u64;
        let mg = chain.error(Integrator::ThetaMg, n);
        let ie = chain.error(Integrator::ImplicitEuler, n);
        println!("{ratio} h_c ({n} steps/s): theta-mg {mg:.3e} m, implicit Euler {ie:.3e} m");
        assert!(
            mg < 0.5 * ie,
            "at {ratio} h_c: theta-mg {mg} against implicit Euler {ie}"
        );
    }
}
