//! Conservation laws: momentum to round-off without gravity or pins, for every integrator,
//! on random networks with springs in all three damping regimes (implicit Euler: to its
//! conjugate-gradient tolerance, since an inexact solve moves momentum by its residual).

mod common;
use common::*;
use harmonic::prelude::*;

fn random_network(rng: &mut Rng, integrator: Integrator) -> Simulation {
    let n = 24;
    let mut particles = String::new();
    for _ in 0..n {
        particles += &format!(
            "(position: ({}, {}, {}), velocity: ({}, {}, {}), mass: {}),",
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(0.1, 10.0)
        );
    }
    let mut springs = String::new();
    for k in 0..60 {
        let a = k % n;
        let b = (a + 1 + (rng.next_f64() * (n - 1) as f64) as usize) % n;
        // ζ in the under-damped, near-critical and over-damped regimes.
        let zeta = [0.1, 1.0, 3.0][k % 3];
        springs += &format!(
            "(a: {a}, b: {b}, frequency: {}, damping_ratio: {zeta}),",
            rng.range(0.5, 3.0)
        );
    }
    let text = format!(
        "Scene(dt: 0.002, substeps: 1, gravity: (0.0, 0.0, 0.0), integrator: \"{integrator}\", particles: [{particles}], springs: [{springs}])"
    );
    Simulation::from_scene(&Scene::parse(&text, "random").unwrap()).unwrap()
}

fn momentum(sim: &Simulation) -> (DVec3, f64) {
    let p = sim.packed();
    let total = harmonic::internals::metrics::momentum(p);
    let scale = (0..p.particle_count())
        .map(|i| p.mass(i) * p.v[i].length())
        .sum();
    (total, scale)
}

#[test]
fn momentum_is_conserved_to_round_off() {
    let mut rng = Rng(seed());
    for integrator in Integrator::ALL {
        let mut sim = random_network(&mut rng, integrator);
        let (p0, scale) = momentum(&sim);
        for _ in 0..300 {
            sim.step().unwrap();
        }
        let (p1, _) = momentum(&sim);
        let drift = (p1 - p0).length() / scale;
        println!("{integrator}: momentum drift {drift:.2e} of Σ m|v|");
        let tol = if integrator == Integrator::ImplicitEuler {
            10.0 * harmonic::internals::integrate::implicit::CG_TOLERANCE
        } else {
            1e-12
        };
        assert!(drift < tol, "{integrator}: momentum drifted by {drift:e}");
    }
}
