//! Scenes a hostile user would write: each gets a located error or a documented behaviour.

use harmonic::prelude::*;
use harmonic::SceneError;

fn issues(text: &str) -> Vec<String> {
    match Scene::parse(text, "hostile.ron") {
        Err(SceneError::Invalid { issues, .. }) => issues.iter().map(|i| i.to_string()).collect(),
        other => panic!("expected the scene refused, got {other:?}"),
    }
}

fn has(issues: &[String], location: &str, needle: &str) {
    assert!(
        issues
            .iter()
            .any(|i| i.starts_with(location) && i.contains(needle)),
        "no `{location}: …{needle}…` among {issues:#?}"
    );
}

const BALL: &str = "(kind: Fixed, shape: Ball(radius: 0.3))";

fn with_bodies(bodies: &str, attachments: &str) -> String {
    format!(
        r#"Scene(dt: 0.01,
            particles: [(position: (0.0, 1.0, 0.0), mass: 0.1), (position: (0.0, 0.5, 0.0), mass: 0.1)],
            springs: [(a: 0, b: 1, stiffness: 10.0)],
            bodies: [{bodies}], attachments: [{attachments}])"#
    )
}

#[test]
fn a_byte_order_mark_is_not_a_syntax_error() {
    let text = "\u{feff}Scene(dt: 0.01, particles: [(position: (0.0, 0.0, 0.0), mass: 1.0)])";
    let scene = Scene::parse(text, "bom.ron").expect("a BOM is skipped");
    assert_eq!(scene.particle_count(), 1);
}

#[test]
fn huge_values_are_printed_with_an_exponent() {
    let i = issues("Scene(dt: -1e300, particles: [(position: (0.0, 0.0, 0.0), mass: -1e-300)])");
    has(&i, "dt", "got -1e300");
    has(&i, "particles[0].mass", "got -1e-300");
    assert!(i.iter().all(|m| m.len() < 120), "{i:#?}");
}

#[test]
fn springs_beyond_f32s_range_are_refused_where_they_are_written() {
    let i = issues(
        "Scene(dt: 0.01, particles: [(position: (0.0, 0.0, 0.0), mass: 1.0),
                                     (position: (1.0, 0.0, 0.0), mass: 1.0)],
               springs: [(a: 0, b: 1, stiffness: 1e39), (a: 0, b: 1, stiffness: 1.0, damping: 1e39)])",
    );
    has(&i, "springs[0]", "stiffness of 1e39, beyond f32's range");
    has(&i, "springs[1]", "damping of 1e39");
    // Through the frequency form too: 1e20 Hz on a 1 kg cloth's particles.
    let i = issues(
        "Scene(dt: 0.01, cloths: [(origin: (0.0, 0.0, 0.0), size: (1.0, 1.0), resolution: (4, 4),
               plane: Horizontal, mass: 1.0, structural: (frequency: 1e20))])",
    );
    has(&i, "cloths[0].structural", "beyond f32's range");
    // Within range it runs.
    Scene::parse(
        "Scene(dt: 0.01, particles: [(position: (0.0, 0.0, 0.0), mass: 1.0),
                                     (position: (1.0, 0.0, 0.0), mass: 1.0)],
               springs: [(a: 0, b: 1, stiffness: 1e30)])",
        "ok.ron",
    )
    .unwrap();
}

#[test]
fn a_dynamic_body_without_volume_needs_a_mass() {
    let flat = "(kind: Dynamic, shape: TriMesh(vertices: [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)], indices: [(0, 1, 2)]))";
    let i = issues(&with_bodies(flat, ""));
    has(&i, "bodies[0].shape", "encloses no volume");
    let coplanar = "(kind: Dynamic, shape: ConvexHull(points: [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 1.0)]))";
    let i = issues(&with_bodies(coplanar, ""));
    has(&i, "bodies[0].shape", "");
    // Given a mass, or fixed, the flat mesh is fine.
    let massive = flat.replace("(kind: Dynamic,", "(kind: Dynamic, mass: 2.0,");
    Scene::parse(&with_bodies(&massive, ""), "m.ron").unwrap();
    let fixed = flat.replace("Dynamic", "Fixed");
    Scene::parse(&with_bodies(&fixed, ""), "f.ron").unwrap();
}

#[test]
fn restitution_above_one_is_refused() {
    let bouncy = "(kind: Fixed, shape: Ball(radius: 0.3), restitution: 2.0)";
    has(
        &issues(&with_bodies(bouncy, "")),
        "bodies[0].restitution",
        "[0, 1], got 2.0",
    );
}

#[test]
fn a_huge_rotation_is_refused_and_a_large_one_taken_modulo_a_turn() {
    let spun =
        "(kind: Fixed, shape: Cuboid(half_extents: (0.5, 0.1, 0.5)), rotation: (3e19, 0.0, 0.0))";
    has(
        &issues(&with_bodies(spun, "")),
        "bodies[0].rotation",
        "at most 1e15",
    );
    // 1e6 rad about y is the same box as 1e6 mod 4π.
    let pose = |angle: f64| {
        let body = format!("(kind: Fixed, shape: Cuboid(half_extents: (0.5, 0.1, 0.2)), rotation: (0.0, {angle:?}, 0.0))");
        let scene = Scene::parse(&with_bodies(&body, ""), "r.ron").unwrap();
        let sim = Simulation::from_scene(&scene).unwrap();
        let props = sim.props().unwrap();
        let (_, c) = props.colliders().iter().next().unwrap();
        let aabb = c.compute_aabb();
        (aabb.mins, aabb.maxs)
    };
    let reduced = 1e6f64.rem_euclid(4.0 * std::f64::consts::PI);
    let (a, b) = (pose(1e6), pose(reduced));
    assert!(a.0.is_finite() && a.1.is_finite(), "{a:?}");
    assert!(
        (a.0 - b.0).abs().max_element() < 1e-4 && (a.1 - b.1).abs().max_element() < 1e-4,
        "{a:?} vs {b:?}"
    );
}

#[test]
fn a_particle_follows_one_body() {
    let twice = "(particle: Particle(1), body: 0), (particle: Particle(1), body: 1)";
    let i = issues(&with_bodies(&format!("{BALL}, {BALL}"), twice));
    has(
        &i,
        "attachments[1].particle",
        "already attached by attachments[0]",
    );
}

#[test]
fn bodies_and_particles_stay_within_the_worlds_bound() {
    // Bodies run in rapier's f32: poses, speeds and sizes past the documented bounds are
    // refused where they are written, not met later as "a step too large".
    let kinematic = "(kind: KinematicPosition, shape: Ball(radius: 0.3), \
                     path: [(time: 0.0, position: (0.0, 0.0, 0.0)), (time: 1.0, position: (1e300, 0.0, 0.0))])";
    let i = issues(&with_bodies(kinematic, "(particle: Particle(1), body: 0)"));
    has(&i, "bodies[0].path[1].position", "beyond the world's bound");
    let fast = "(kind: Kinematic, shape: Ball(radius: 0.3), velocity: (1e20, 0.0, 0.0))";
    let i = issues(&with_bodies(fast, "(particle: Particle(1), body: 0)"));
    has(&i, "bodies[0].velocity", "beyond the world's bound of ±1e4");
    let far = "(kind: Fixed, position: (0.0, 1e300, 0.0), shape: Ball(radius: 0.3))";
    has(
        &issues(&with_bodies(far, "")),
        "bodies[0].position",
        "±1e5 m",
    );
    let huge = "(kind: Fixed, shape: Ball(radius: 1e300))";
    has(
        &issues(&with_bodies(huge, "")),
        "bodies[0].shape.radius",
        "1e5 m",
    );
    // Not "encloses no volume": too large, and said so.
    let i = issues(&with_bodies(
        "(kind: Dynamic, shape: Ball(radius: 1e30))",
        "",
    ));
    has(&i, "bodies[0].shape.radius", "beyond the world's bound");
    assert!(i.iter().all(|m| !m.contains("no volume")), "{i:#?}");
    // Within the bound, but its mass and inertia (m r²) past f32's range.
    let dense = "(kind: Dynamic, density: 1e15, shape: Ball(radius: 1e5))";
    has(
        &issues(&with_bodies(dense, "")),
        "bodies[0]",
        "beyond f32's range",
    );
    // The largest sound ball still builds.
    let sound = "(kind: Dynamic, shape: Ball(radius: 1e5))";
    Scene::parse(&with_bodies(sound, ""), "big.ron").expect("within every bound");
    // Particles: named by their entry, never by an internal spring id.
    let i = issues(
        "Scene(dt: 0.01, particles: [(position: (-1e308, 0.0, 0.0), mass: 1.0), \
         (position: (1e308, 0.0, 0.0), mass: 1.0)], springs: [(a: 0, b: 1, stiffness: 1.0)])",
    );
    has(&i, "particles[0].position", "beyond the world's bound");
    has(&i, "particles[1].position", "beyond the world's bound");
}
