//! Automatic step control against the stability suite: the controller's step is stable (a
//! perturbation about rest does not grow) at damping ratios between and beyond the measured ones.

use harmonic::internals::Packed;
use harmonic::prelude::*;
use harmonic_lab::research::{self, Method};
use harmonic_lab::stability;

/// The controller's step at damping ratios between and beyond the measured ones: every
/// integrator with a limit, on the chain of 20 and the 8×8 cloth, must be stable there
/// (growth of a perturbation about rest, as the limits were measured). With the limits
/// measured at ζ = 0, 0.2, 1, 2 only and interpolated straight, symplectic Euler's default
/// blew up the cloth at ζ = 0.6, and every falling limit was held too high past ζ = 2.
#[test]
fn the_controllers_step_is_stable_at_any_damping() {
    let zero_g = |mut s: Scene| {
        s.gravity = [0.0; 3];
        s
    };
    let integrators = [
        Method::Engine(Integrator::SymplecticEuler),
        Method::Engine(Integrator::ExplicitEuler),
        Method::Engine(Integrator::Harmonic),
        Method::HARMONIC_FORCED,
        Method::Engine(Integrator::HarmonicGs),
        Method::HARMONIC_SGS,
        Method::HARMONIC_FORCED_GS,
        Method::RK4,
    ];
    let mut failures = Vec::new();
    for zeta in [0.05, 0.25, 0.45, 0.55, 0.6, 0.7, 0.9, 1.2, 1.8, 3.0, 5.0] {
        let systems = [
            (
                "chain of 20",
                zero_g(stability::chain(20, zeta, stability::Start::Rest).0),
            ),
            ("cloth 8×8", zero_g(stability::cloth(8, zeta))),
        ];
        for (name, scene) in &systems {
            let p = Packed::gather(&scene.build().world).unwrap();
            for integrator in integrators {
                let dt = 1.0 / 60.0;
                let choice = research::choose(&p, integrator, dt);
                let h = dt / f64::from(choice.substeps);
                let growth = stability::growth_rate(&p, integrator, false, h, 4000).unwrap();
                if growth > 1.0 + stability::GROWTH_TOL {
                    failures.push(format!(
                        "{name}, ζ = {zeta}, {integrator}: {} substeps, growth {growth:.5}",
                        choice.substeps
                    ));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
