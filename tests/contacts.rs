//! Cloth against rapier bodies: no tunnelling, attachments that follow their body, momentum
//! exchanged exactly, particles kept outside colliders.

use harmonic::prelude::*;
use harmonic::Attachment;

fn load(name: &str) -> Simulation {
    Simulation::load(format!("{}/scenes/{name}", env!("CARGO_MANIFEST_DIR")))
        .unwrap_or_else(|e| panic!("{name}: {e}"))
}

#[test]
fn a_fast_cloth_does_not_tunnel_through_a_thin_wall() {
    // 40 m/s at about 2.7 cm per substep against a 1 cm wall at z = 0.495 … 0.505.
    let mut sim = load("projectile.ron");
    let h = sim.config().h();
    assert!(
        40.0 * h > 0.01,
        "the scene must step further than the wall is thick"
    );
    let mut swept = 0;
    for _ in 0..30 {
        sim.step().expect("finite");
        swept += sim.props().expect("props").stats().swept;
        for (i, x) in sim.positions().iter().enumerate() {
            assert!(
                x.z > -0.495,
                "particle {i} reached z = {} (through the wall)",
                x.z
            );
        }
    }
    assert!(
        sim.positions().iter().all(|x| x.z < -0.4),
        "the cloth reached the wall"
    );
    // The swept test, not the projection, caught them: they step over the shell.
    assert!(swept > 0, "no particle was caught by the swept test");
}

#[test]
fn attached_particles_follow_a_moving_kinematic_body() {
    let mut sim = load("cape.ron");
    for _ in 0..60 {
        sim.step().expect("finite");
        let props = sim.props().expect("props");
        let mut checked = 0;
        for (e, a) in sim.world().query::<(hecs::Entity, &Attachment)>().iter() {
            let body = &props.bodies()[a.body];
            let target = body.position().transform_point(a.local).as_dvec3();
            let i = sim.packed().index_of(e).expect("packed");
            let err = (sim.positions()[i] - target).length();
            assert!(err < 1e-4, "particle {i} is {err} m from its body point");
            checked += 1;
        }
        assert_eq!(checked, 24);
    }
    // The character walked 1.2 m/s × 1 s; the cape went with it.
    let z = sim.positions().iter().map(|x| x.z).sum::<f64>() / sim.positions().len() as f64;
    assert!(z > 0.8, "mean z of the cape {z}");
}

/// Free cloth (no gravity, no pins) thrown at a free dynamic ball: cloth + ball momentum.
#[test]
fn a_free_collision_conserves_linear_momentum() {
    let text = r#"Scene(
        dt: 0.004, gravity: (0.0, 0.0, 0.0),
        cloths: [(origin: (-0.3, 0.3, -1.0), size: (0.6, 0.6), resolution: (16, 16), plane: Vertical,
                  mass: 0.5, structural: (frequency: 60.0, damping_ratio: 0.2),
                  shear: Some((frequency: 60.0, damping_ratio: 0.2)), velocity: (0.0, 0.0, 3.0))],
        bodies: [(kind: Dynamic, shape: Ball(radius: 0.15), position: (0.0, 0.0, 0.0), mass: 0.4)],
        contact: (thickness: 0.01, friction: 0.5, kinetic_friction: 0.4),
    )"#;
    let scene = Scene::parse(text, "free_collision").expect("valid");
    let mut sim = Simulation::from_scene(&scene).expect("builds");
    let momentum = |sim: &Simulation| {
        let p = sim.packed();
        let cloth: DVec3 = (0..p.particle_count()).map(|i| p.v[i] * p.mass(i)).sum();
        let props = sim.props().expect("props");
        let (_, ball) = props.bodies().iter().next().expect("one body");
        (cloth, ball.linvel().as_dvec3() * ball.mass() as f64)
    };
    let (c0, b0) = momentum(&sim);
    let total0 = c0 + b0;
    let mut touched = false;
    for _ in 0..150 {
        sim.step().expect("finite");
        touched |= sim.props().expect("props").stats().contacts > 0;
    }
    let (c1, b1) = momentum(&sim);
    assert!(touched, "the cloth never reached the ball");
    assert!(b1.z > 0.2 * total0.z, "the ball was hardly pushed: {b1}");
    let err = (c1 + b1 - total0).length() / total0.length();
    assert!(
        err < 0.01,
        "momentum before {total0}, after {} (cloth {c1}, ball {b1}): {err:.2e}",
        c1 + b1
    );
}

#[test]
fn particles_stay_outside_colliders() {
    // The whole run of each scene.
    for name in ["trampoline.ron", "drape_sphere.ron"] {
        let path = format!("{}/scenes/{name}", env!("CARGO_MANIFEST_DIR"));
        let seconds = Scene::load(&path).expect("valid").seconds.expect("seconds");
        let mut sim = load(name);
        let frames = (seconds / sim.config().dt).round() as usize;
        let thickness = sim.props().expect("props").contact().thickness;
        let mut contacts = 0;
        for _ in 0..frames {
            sim.step().expect("finite");
            let s = sim.props().expect("props").stats();
            contacts += s.contacts;
            assert!(
                s.max_depth < thickness,
                "{name}: a particle got {} m inside (thickness {thickness})",
                s.max_depth
            );
        }
        assert!(contacts > 0, "{name}: no contact at all");
    }
}

/// A ball resting on a cloth pinned at its edges: averaged over the last second, the cloth's
/// push on the ball is the ball's weight (the ball's momentum balance).
#[test]
fn a_trampoline_carries_the_weight_of_the_ball_at_rest() {
    let mut sim = load("trampoline.ron");
    let dt = sim.config().dt;
    let frames = (6.0 / dt).round() as usize;
    let last = (1.0 / dt).round() as usize;
    let mut impulse = DVec3::ZERO;
    let (mut low, mut high) = (f32::MAX, f32::MIN);
    for f in 0..frames {
        sim.step().expect("finite");
        if f >= frames - last {
            let props = sim.props().expect("props");
            impulse += props.stats().impulse_on_bodies;
            let y = props
                .bodies()
                .iter()
                .next()
                .expect("the ball")
                .1
                .translation()
                .y;
            (low, high) = (low.min(y), high.max(y));
        }
    }
    let props = sim.props().expect("props");
    let (_, ball) = props.bodies().iter().next().expect("the ball");
    let weight = ball.mass() as f64 * 9.81;
    let carried = impulse.y / (last as f64 * dt);
    eprintln!("carried {carried:.4} N of {weight:.4} N; y in [{low}, {high}]");
    assert!(
        high - low < 0.005,
        "the ball has not settled: y in [{low}, {high}]"
    );
    assert!(
        (carried / weight - 1.0).abs() < 0.02,
        "the cloth carries {carried:.4} N of a {weight:.4} N ball"
    );
    assert!(
        impulse.x.abs().max(impulse.z.abs()) < 0.02 * impulse.y,
        "sideways push {impulse}"
    );
    // And the cloth sags under it: the ball rests below the pinned edges.
    assert!(high < 0.5 + 0.15, "ball at {high}");
}

/// The hand of the tablecloth is position-driven along a keyframed path: it is where the path
/// says each frame, the cloth edge attached to it follows, and the pull leaves the boxes.
#[test]
fn a_position_driven_body_follows_its_path_and_drags_the_cloth() {
    use harmonic::internals::contacts::path_pose;
    let scene = Scene::load(format!(
        "{}/scenes/tablecloth.ron",
        env!("CARGO_MANIFEST_DIR")
    ))
    .expect("valid");
    let path = scene.bodies[4].path.clone();
    let mut sim = Simulation::from_scene(&scene).expect("builds");
    let frames = (scene.seconds.expect("seconds") / sim.config().dt).round() as usize;
    for f in 1..=frames {
        sim.step().expect("finite");
        let props = sim.props().expect("props");
        let hand = props.bodies().iter().nth(4).expect("the hand").1;
        let want = path_pose(&path, f as f64 * sim.config().dt);
        let off = (hand.translation() - want.translation).length();
        assert!(off < 1e-5, "frame {f}: hand {off} m off its path");
        for (e, a) in sim.world().query::<(hecs::Entity, &Attachment)>().iter() {
            let body = &props.bodies()[a.body];
            let target = body.position().transform_point(a.local).as_dvec3();
            let i = sim.packed().index_of(e).expect("packed");
            let err = (sim.positions()[i] - target).length();
            assert!(
                err < 1e-4,
                "frame {f}: particle {i} is {err} m from the hand"
            );
        }
    }
    // The cloth went with the hand, past the table's near edge.
    let props = sim.props().expect("props");
    let z = sim.positions().iter().map(|x| x.z).fold(f64::MIN, f64::max);
    assert!(
        z < -0.6,
        "the cloth's far edge is still on the table at z = {z}"
    );
    // The boxes stayed on the table.
    for (k, (_, b)) in props.bodies().iter().enumerate().skip(1).take(3) {
        let p = b.translation();
        assert!(
            p.y > 0.8 && p.z.abs() < 0.6,
            "box {k} left the table: {p:?}"
        );
    }
}

/// The caller's own rapier world as the rigid side (`step_with`): the cloth pushes the caller's
/// ball and momentum is conserved; the caller steps rapier once per frame.
#[test]
fn a_cloth_couples_with_the_callers_own_rapier_sets() {
    use rapier3d::prelude::*;
    let text = r#"Scene(
        dt: 0.004, gravity: (0.0, 0.0, 0.0),
        cloths: [(origin: (-0.3, 0.3, -1.0), size: (0.6, 0.6), resolution: (16, 16), plane: Vertical,
                  mass: 0.5, structural: (frequency: 60.0, damping_ratio: 0.2),
                  shear: Some((frequency: 60.0, damping_ratio: 0.2)), velocity: (0.0, 0.0, 3.0))],
    )"#;
    let scene = Scene::parse(text, "callers_world").expect("valid");
    let mut sim = Simulation::from_scene(&scene).expect("builds");
    let mut world = PhysicsWorld::new();
    world.gravity = Vector::ZERO;
    world.integration_parameters.dt = sim.config().dt as f32;
    let (ball, _) = world.insert(
        RigidBodyBuilder::dynamic(),
        ColliderBuilder::ball(0.15).mass(0.4),
    );
    let momentum = |sim: &Simulation, world: &PhysicsWorld| {
        let p = sim.packed();
        let cloth: DVec3 = (0..p.particle_count()).map(|i| p.v[i] * p.mass(i)).sum();
        let b = &world.bodies[ball];
        cloth + b.linvel().as_dvec3() * b.mass() as f64
    };
    let p0 = momentum(&sim, &world);
    let mut touched = 0;
    for _ in 0..150 {
        sim.step_with(&mut world.bodies, &world.colliders)
            .expect("finite");
        touched += sim.contact_stats().expect("coupled").contacts;
        world.step();
    }
    let p1 = momentum(&sim, &world);
    assert!(touched > 0, "the cloth never reached the ball");
    let pushed = world.bodies[ball].linvel().z as f64 * 0.4;
    assert!(pushed > 0.2 * p0.z, "the ball was hardly pushed: {pushed}");
    let err = (p1 - p0).length() / p0.length();
    assert!(err < 0.01, "momentum before {p0}, after {p1}: {err:.2e}");
    // A scene with bodies of its own refuses the caller's sets.
    let mut own = load("trampoline.ron");
    assert!(matches!(
        own.step_with(&mut world.bodies, &world.colliders),
        Err(harmonic::SimError::OwnBodies)
    ));
}

/// Particles attached to the caller's kinematic body follow it through the caller's steps.
#[test]
fn attachments_follow_a_body_of_the_callers_world() {
    use rapier3d::prelude::*;
    let text = r#"Scene(
        dt: 0.01,
        cloths: [(origin: (-0.2, 1.0, 0.0), size: (0.4, 0.4), resolution: (8, 8), plane: Vertical,
                  mass: 0.1, structural: (frequency: 40.0, damping_ratio: 0.2))],
    )"#;
    let scene = Scene::parse(text, "attached_to_callers_body").expect("valid");
    let mut sim = Simulation::from_scene(&scene).expect("builds");
    let mut world = PhysicsWorld::new();
    world.integration_parameters.dt = sim.config().dt as f32;
    let (body, _) = world.insert(
        RigidBodyBuilder::kinematic_velocity_based()
            .translation(Vector::new(0.0, 1.0, 0.0))
            .linvel(Vector::new(0.8, 0.0, 0.0))
            .angvel(Vector::new(0.0, 1.5, 0.0)),
        ColliderBuilder::cuboid(0.25, 0.02, 0.05),
    );
    // The top row hangs from the body.
    let top: Vec<hecs::Entity> = sim
        .world()
        .query::<(hecs::Entity, &Particle)>()
        .iter()
        .filter(|(_, p)| (p.position.y - 1.0).abs() < 1e-9)
        .map(|(e, _)| e)
        .collect();
    assert_eq!(top.len(), 8);
    for &e in &top {
        let x = sim.world().get::<&Particle>(e).expect("particle").position;
        let local = world.bodies[body]
            .position()
            .inverse_transform_point(x.as_vec3());
        sim.world_mut()
            .insert_one(e, Attachment { body, local })
            .expect("alive");
    }
    for f in 0..50 {
        sim.step_with(&mut world.bodies, &world.colliders)
            .expect("finite");
        world.step();
        let b = &world.bodies[body];
        for &e in &top {
            let a = *sim.world().get::<&Attachment>(e).expect("attached");
            let target = b.position().transform_point(a.local).as_dvec3();
            let i = sim.packed().index_of(e).expect("packed");
            let err = (sim.positions()[i] - target).length();
            assert!(
                err < 1e-4,
                "frame {f}: particle {i} is {err} m from the body point"
            );
        }
    }
    // Removing the body from the caller's set is reported, not ignored.
    world.remove_body(body);
    assert!(matches!(
        sim.step_with(&mut world.bodies, &world.colliders),
        Err(harmonic::SimError::DanglingAttachment { .. })
    ));
}
