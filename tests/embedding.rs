//! The game-loop API: the fixed-step accumulator keeps simulated time equal to the clock (less
//! what the cap drops), interpolation lands between the last two states, and the render
//! normals are the surface's.

use harmonic::prelude::*;

fn cloth(substeps: &str) -> Simulation {
    let text = format!(
        r#"Scene(dt: 0.01, {substeps}
            cloths: [(origin: (-0.5, 1.0, -0.5), size: (1.0, 1.0), resolution: (12, 12),
                      plane: Horizontal, mass: 0.2, structural: (frequency: 30.0, damping_ratio: 0.1),
                      pins: [TopLeft, TopRight])])"#
    );
    Simulation::from_scene(&Scene::parse(&text, "embedding").expect("valid")).expect("builds")
}

#[test]
fn advance_keeps_simulated_time_with_the_clock() {
    let mut sim = cloth("");
    let mut rng = fastrand::Rng::with_seed(5);
    let (mut clock, mut dropped, mut steps) = (0.0, 0.0, 0u64);
    for _ in 0..500 {
        let dt = 0.002 + 0.03 * rng.f64();
        clock += dt;
        let a = sim.advance(dt).expect("finite");
        steps += a.steps as u64;
        dropped += a.dropped;
        assert!(
            (0.0..1.0).contains(&a.alpha) || a.alpha == 1.0,
            "alpha {}",
            a.alpha
        );
        // What is owed is alpha of a step: simulated + owed + dropped = clock.
        let owed = a.alpha * 0.01;
        assert!(
            (sim.time() + owed + dropped - clock).abs() < 1e-9,
            "simulated {} + owed {owed} + dropped {dropped} vs clock {clock}",
            sim.time()
        );
    }
    assert_eq!(sim.steps(), steps);
    assert_eq!(dropped, 0.0, "no frame here needs more than the cap");
}

#[test]
fn a_long_frame_is_capped_not_spiralled() {
    let mut sim = cloth("");
    sim.set_max_steps_per_advance(4);
    let a = sim.advance(1.0).expect("finite");
    assert_eq!(a.steps, 4);
    // Four steps taken, at most one step owed, the rest dropped.
    assert!(
        (a.dropped - (1.0 - 0.04 - a.alpha * 0.01)).abs() < 1e-9,
        "{a:?}"
    );
    assert!(a.alpha <= 1.0);
    for bad in [f64::NAN, -0.01, f64::INFINITY] {
        assert!(matches!(
            sim.advance(bad),
            Err(harmonic::SimError::BadFrameTime(_))
        ));
    }
}

#[test]
fn render_interpolates_between_the_last_two_states() {
    let mut sim = cloth("");
    sim.advance(0.05).expect("finite");
    let before: Vec<DVec3> = sim.positions().to_vec();
    let a = sim.advance(0.01).expect("finite");
    assert_eq!(a.steps, 1);
    let now: Vec<DVec3> = sim.positions().to_vec();
    for alpha in [0.0, 0.3, 1.0] {
        let view = sim.render(alpha);
        for (i, p) in view.positions.iter().enumerate() {
            let want = before[i].lerp(now[i], alpha).as_vec3();
            assert!((*p - want).length() < 1e-6, "alpha {alpha}, particle {i}");
        }
    }
}

#[test]
fn render_normals_are_the_surface_normals() {
    let mut sim = cloth("substeps: Some(1),");
    // Flat and horizontal at the start: every normal is +y, unit length.
    let view = sim.render(0.0);
    assert_eq!(view.triangles.len(), 2 * 11 * 11);
    for n in view.normals {
        assert!((*n - glam::Vec3::Y).length() < 1e-6, "{n}");
    }
    // Tilt it by moving the particles: z ↦ z, y ↦ y + z (a 45° slope): n ∝ (0, 1, −1).
    let tilted: Vec<DVec3> = sim
        .positions()
        .iter()
        .map(|x| DVec3::new(x.x, x.y + x.z, x.z))
        .collect();
    for (e, p) in sim
        .world_mut()
        .query_mut::<(&harmonic::SceneIndex, &mut Particle)>()
    {
        p.position = tilted[e.0 as usize];
    }
    sim.step().expect("finite"); // gathers the moved particles
    let want = glam::Vec3::new(0.0, 1.0, -1.0).normalize();
    let view = sim.render(1.0);
    for n in view.normals {
        assert!((*n - want).length() < 0.05, "{n}");
    }
}
