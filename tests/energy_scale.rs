//! The energy scale energy changes are measured against, against hand-computed values:
//! `max(E_kin + E_spring, M |g| H)`, `H` the diagonal of the particles' bounding box.

use harmonic::prelude::*;

fn sim(text: &str) -> Simulation {
    Simulation::from_scene(&Scene::parse(text, "scale.ron").unwrap()).unwrap()
}

#[test]
fn a_chain_is_measured_by_its_weight_times_its_reach() {
    // Pinned at y = 2, free particles of 0.25 kg each at y = 1.5, 1, 0.5 (0.75 kg), at rest and
    // unstretched: M |g| H = 0.75 · 9.81 · 1.5.
    let d = sim(r#"Scene(dt: 0.01,
        ropes: [(start: (0.0, 2.0, 0.0), end: (0.0, 0.5, 0.0), particles: 4, mass: 1.0,
                 spring: (stiffness: 100.0))])"#)
    .diagnostics();
    let expected = 0.75 * 9.81 * 1.5;
    assert!(
        (d.energy_scale - expected).abs() < 1e-12 * expected,
        "{}",
        d.energy_scale
    );
    // Released horizontally it can swing down its length: the same scale, though no particle
    // starts above another.
    let d = sim(r#"Scene(dt: 0.01,
        ropes: [(start: (0.0, 0.0, 0.0), end: (1.5, 0.0, 0.0), particles: 4, mass: 1.0,
                 spring: (stiffness: 100.0))])"#)
    .diagnostics();
    assert!(
        (d.energy_scale - expected).abs() < 1e-12 * expected,
        "{}",
        d.energy_scale
    );
}

#[test]
fn without_gravity_it_is_the_motion_and_the_stretch() {
    // Two 1 kg particles 2 m apart on a 1 m spring of 10 N/m, one moving at 3 m/s:
    // ½ κ δ² + ½ m v² = 5 + 4.5.
    let d = sim(r#"Scene(dt: 0.01, gravity: (0.0, 0.0, 0.0),
        particles: [(position: (0.0, 0.0, 0.0), mass: 1.0),
                    (position: (2.0, 0.0, 0.0), velocity: (0.0, 3.0, 0.0), mass: 1.0)],
        springs: [(a: 0, b: 1, stiffness: 10.0, rest_length: 1.0)])"#)
    .diagnostics();
    assert!((d.energy_scale - 9.5).abs() < 1e-12, "{}", d.energy_scale);
    // At rest, unstretched and weightless there is nothing to measure against.
    let still = sim(r#"Scene(dt: 0.01, gravity: (0.0, 0.0, 0.0),
        particles: [(position: (0.0, 0.0, 0.0), mass: 1.0), (position: (1.0, 0.0, 0.0), mass: 1.0)],
        springs: [(a: 0, b: 1, stiffness: 10.0)])"#);
    assert_eq!(still.diagnostics().energy_scale, 0.0);
}
