//! The numpy study's stability thresholds (MATH.md), reproduced within 10 % per integrator on
//! the chain of 20 and the 8×8 cloth: stable at 0.9× and 0.5× the study's figure, unstable at 1.1×.

use harmonic::internals::buffers::Packed;
use harmonic::Integrator;
use harmonic_lab::research::Method;
use harmonic_lab::stability::{self, GROWTH_TOL};

fn stable(p: &Packed, integrator: Method, ratio: f64) -> bool {
    let h = ratio * stability::h_crit(p);
    stability::growth_rate(p, integrator, false, h, 4000).is_some_and(|g| g <= 1.0 + GROWTH_TOL)
}

#[test]
fn thresholds_match_the_numpy_study_within_ten_percent() {
    for study in stability::threshold_systems()
        .into_iter()
        .filter(|s| !s.name.starts_with("1 spring"))
    {
        let p = Packed::gather(&study.scene.build().world).unwrap();
        for (integrator, figure) in [
            (
                Method::Engine(Integrator::SymplecticEuler),
                study.symplectic_euler,
            ),
            (Method::Engine(Integrator::Harmonic), study.harmonic),
            (Method::HARMONIC_FORCED, study.forced),
            (Method::Engine(Integrator::HarmonicGs), study.gauss_seidel),
        ] {
            for (factor, expect) in [(0.5, true), (0.9, true), (1.1, false)] {
                assert_eq!(
                    stable(&p, integrator, factor * figure),
                    expect,
                    "{}, {integrator}: at {factor} × {figure} h_c expected {}",
                    study.name,
                    if expect { "stable" } else { "unstable" }
                );
            }
        }
    }
}
