//! Every integrator, the engine's and the lab's research variants, converges to a fine-step
//! RK4 reference at its order as h shrinks (and the paper's printed step does not converge at
//! all).

use harmonic::internals::buffers::Packed;
use harmonic::internals::metrics::rms;
use harmonic::prelude::*;
use harmonic_lab::research::{Method, Stepper};

const T: f64 = 0.25;

/// A 6-particle chain pinned at one end, released horizontally: large, nonlinear swinging.
fn chain() -> Scene {
    Scene::parse(
        "Scene(dt: 0.001, gravity: (0.0, -9.81, 0.0),
           ropes: [(start: (0.0, 0.0, 0.0), end: (0.5, 0.0, 0.0), particles: 6, mass: 0.3,
                    spring: (stiffness: 300.0, damping_ratio: 0.2))])",
        "chain",
    )
    .unwrap()
}

fn positions_at_t(method: Method, exact: bool, steps: u32) -> Vec<DVec3> {
    let scene = chain();
    let mut p = Packed::gather(&scene.build().world).unwrap();
    let mut stepper = Stepper::new(method, exact, DVec3::from(scene.gravity));
    let h = T / steps as f64;
    for _ in 0..steps {
        stepper.substep(&mut p, h).unwrap();
    }
    p.x
}

fn sci(v: &[f64]) -> String {
    v.iter()
        .map(|e| format!("{e:.3e}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Errors at N, 2N, 4N steps and the observed order log2(e(h)/e(h/2)) of the last halving.
fn order(integrator: Method, exact: bool, n: u32, reference: &[DVec3]) -> (Vec<f64>, f64) {
    let errors: Vec<f64> = [n, 2 * n, 4 * n]
        .iter()
        .map(|&k| rms(&positions_at_t(integrator, exact, k), reference))
        .collect();
    let p = (errors[1] / errors[2]).log2();
    (errors, p)
}

#[test]
fn integrators_converge_at_their_order() {
    let p = Packed::gather(&chain().build().world).unwrap();
    let hc = std::f64::consts::PI
        / p.springs
            .iter()
            .map(|s| s.omega0_sq())
            .fold(0.0, f64::max)
            .sqrt();
    // Steps for h = 0.1 h_c (first-order methods) and 0.4 h_c (RK4).
    let n_small = (T / (0.1 * hc)).ceil() as u32;
    let n_rk = (T / (0.4 * hc)).ceil() as u32;
    let reference = positions_at_t(Method::RK4, false, 64 * n_small);
    let finer = positions_at_t(Method::RK4, false, 128 * n_small);
    let ref_err = rms(&reference, &finer);
    println!(
        "reference: RK4 at h = {:.3e} s; halving it moves it by {ref_err:.2e} m",
        T / (64 * n_small) as f64
    );

    let cases = [
        (
            Method::Engine(Integrator::ExplicitEuler),
            false,
            n_small,
            1.0,
        ),
        (
            Method::Engine(Integrator::SymplecticEuler),
            false,
            n_small,
            1.0,
        ),
        (Method::Engine(Integrator::Harmonic), false, n_small, 1.0),
        (Method::Engine(Integrator::Harmonic), true, n_small, 1.0),
        (Method::Engine(Integrator::HarmonicGs), false, n_small, 1.0),
        (Method::HARMONIC_SGS, false, n_small, 1.0),
        (Method::HARMONIC_FORCED, false, n_small, 1.0),
        (Method::HARMONIC_FORCED_GS, false, n_small, 1.0),
        (
            Method::Engine(Integrator::ImplicitEuler),
            false,
            n_small,
            1.0,
        ),
        (Method::Engine(Integrator::Xpbd), false, n_small, 1.0),
        (Method::RK4, false, n_rk, 4.0),
    ];
    for (integrator, exact, n, expected) in cases {
        let (errors, p) = order(integrator, exact, n, &reference);
        println!(
            "{integrator}{}: RMS errors {}, observed order {p:.2} (expected {expected})",
            if exact { " (exact displacement)" } else { "" },
            sci(&errors)
        );
        assert!(
            errors[2] > 100.0 * ref_err,
            "{integrator}: reference not converged enough to judge"
        );
        assert!(
            (p - expected).abs() < 0.3 * expected,
            "{integrator}: observed order {p:.2}, expected {expected}"
        );
    }

    // The printed paper step is inconsistent: halving h does not reduce its error.
    let (errors, p) = order(Method::HARMONIC_PAPER, false, n_small, &reference);
    println!(
        "harmonic-paper: RMS errors {}, observed order {p:.2} (inconsistent: expected ≈ 0)",
        sci(&errors)
    );
    assert!(
        p.abs() < 0.3 && errors[2] > 1e-2,
        "harmonic-paper unexpectedly converges: {errors:?}"
    );
}
