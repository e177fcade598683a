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

const TWO_CLOTHS: &str = r#"Scene(dt: 0.01, substeps: 4, cloths: [
    (origin: (-2.0, 1.0, -0.5), size: (1.0, 1.0), resolution: (10, 10), plane: Horizontal,
     mass: 0.2, structural: (frequency: 30.0, damping_ratio: 0.1), pins: [TopLeft, TopRight]),
    (origin: (1.0, 1.0, -0.5), size: (1.0, 1.0), resolution: (8, 8), plane: Horizontal,
     mass: 0.2, structural: (frequency: 30.0, damping_ratio: 0.1), pins: [TopLeft]),
])"#;

/// Removing one of two independent cloths mid-run leaves the other moving exactly as it would
/// have alone; adding it back later gives it the scene's particles and triangles again.
#[test]
fn cloths_are_added_and_removed_as_units() {
    let scene = Scene::parse(TWO_CLOTHS, "two").unwrap();
    let mut both = Simulation::from_scene(&scene).unwrap();
    let mut alone_scene = scene.clone();
    let first = alone_scene.cloths.remove(0);
    let mut alone = Simulation::from_scene(&alone_scene).unwrap();
    let ids: Vec<_> = both.cloths().collect();
    assert_eq!(ids.len(), 2);
    assert_eq!((ids[0].1.clone(), ids[1].1.clone()), (0..100, 100..164));
    for _ in 0..10 {
        both.step().unwrap();
    }
    both.remove_cloth(ids[0].0).unwrap();
    assert!(both.remove_cloth(ids[0].0).is_err(), "removed twice");
    // The first cloth's 10 steps happened before the removal; the second cloth never saw it.
    for _ in 0..10 {
        alone.step().unwrap();
    }
    for _ in 0..20 {
        both.step().unwrap();
        alone.step().unwrap();
    }
    assert_eq!(both.positions().len(), 64);
    assert_eq!(both.triangles(), alone.triangles());
    let worst = both
        .positions()
        .iter()
        .zip(alone.positions())
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-12,
        "the remaining cloth moved differently: {worst:e} m"
    );

    // Back again: after the 64 particles, with its own triangles over them.
    let id = both.add_cloth(&first).unwrap();
    both.step().unwrap();
    assert_eq!(both.positions().len(), 164);
    let range = both.cloths().find(|c| c.0 == id).unwrap().1;
    assert_eq!(range, 64..164);
    assert_eq!(both.triangles().len(), 2 * 81 + 2 * 49);
    assert!(both
        .triangles()
        .iter()
        .skip(2 * 49)
        .all(|t| t.iter().all(|&i| (64..164).contains(&(i as usize)))));
    // Its pinned corner stays where the scene put it.
    let corner = both.positions()[64];
    assert!(
        (corner - DVec3::new(-2.0, 1.0, -0.5)).length() < 1e-12,
        "{corner}"
    );
}

/// The same with a second cloth that has tethers, self-collision and a stretch limit, all
/// kept per cloth from its first particle: removing the cloth before it leaves it moving as
/// it would alone (its tethers and layer follow its particles up the scene order).
#[test]
fn a_removed_cloth_leaves_the_later_cloths_tethers_and_layers_whole() {
    let scene = Scene::parse(
        r#"Scene(dt: 0.01, substeps: 8, cloths: [
    (origin: (-2.0, 1.0, -0.5), size: (1.0, 1.0), resolution: (10, 10), plane: Horizontal,
     mass: 0.2, structural: (frequency: 30.0, damping_ratio: 0.1), pins: [TopLeft, TopRight]),
    (origin: (1.0, 1.0, -0.5), size: (1.0, 1.0), resolution: (8, 8), plane: Horizontal,
     mass: 0.2, structural: (frequency: 5.0, damping_ratio: 0.1), pins: [TopLeft],
     tethers: Some((slack: 0.02, anchors: 1)), stretch_limit: Some((stretch: 0.3)),
     self_collision: Some((thickness: 0.05))),
])"#,
        "two",
    )
    .unwrap();
    let mut both = Simulation::from_scene(&scene).unwrap();
    let mut alone_scene = scene.clone();
    alone_scene.cloths.remove(0);
    let mut alone = Simulation::from_scene(&alone_scene).unwrap();
    let mut loose_scene = alone_scene.clone();
    loose_scene.cloths[0].tethers = None;
    let mut loose = Simulation::from_scene(&loose_scene).unwrap();
    let id = both.cloths().next().unwrap().0;
    both.step().unwrap();
    both.remove_cloth(id).unwrap();
    alone.step().unwrap();
    loose.step().unwrap();
    for _ in 0..60 {
        both.step().unwrap();
        alone.step().unwrap();
        loose.step().unwrap();
    }
    let apart = |a: &Simulation, b: &Simulation| {
        (a.positions().iter().zip(b.positions()))
            .map(|(p, q)| p.distance(*q))
            .fold(0.0, f64::max)
    };
    // The tethers act: without them the cloth hangs elsewhere.
    assert!(apart(&alone, &loose) > 0.05, "{}", apart(&alone, &loose));
    let worst = apart(&both, &alone);
    assert!(
        worst < 1e-12,
        "the remaining cloth moved differently: {worst:e} m"
    );
    assert_eq!(both.collision_pairs().0, alone.collision_pairs().0);
}

/// A cloth whose springs component was despawned by hand is no longer a cloth: it leaves the
/// cloth list and the triangles, removing it is an error, and its particles still step.
#[test]
fn a_cloth_without_its_springs_is_not_a_cloth() {
    let mut sim = Simulation::from_scene(&Scene::parse(TWO_CLOTHS, "two").unwrap()).unwrap();
    let ids: Vec<_> = sim.cloths().collect();
    assert_eq!(sim.triangles().len(), 2 * 81 + 2 * 49);
    let springs: Vec<hecs::Entity> = sim
        .world_mut()
        .query_mut::<(hecs::Entity, &harmonic::ClothSprings)>()
        .into_iter()
        .filter(|(_, c)| c.grid.first == 0)
        .map(|(e, _)| e)
        .collect();
    assert_eq!(springs.len(), 1);
    sim.world_mut().despawn(springs[0]).unwrap();
    assert_eq!(
        sim.cloths().map(|c| c.1).collect::<Vec<_>>(),
        vec![100..164]
    );
    assert!(matches!(
        sim.remove_cloth(ids[0].0),
        Err(harmonic::SimError::UnknownCloth)
    ));
    sim.step().unwrap();
    assert_eq!(sim.positions().len(), 164);
    assert_eq!(sim.triangles().len(), 2 * 49);
    assert!(sim.positions().iter().all(|p| p.is_finite()));
}

#[test]
fn a_bad_cloth_or_body_added_at_run_time_is_a_located_error() {
    let mut sim = cloth("");
    let mut c = Scene::parse(TWO_CLOTHS, "two").unwrap().cloths[0].clone();
    c.resolution = (1, 5);
    let e = sim.add_cloth(&c).unwrap_err().to_string();
    assert!(e.contains("cloths[0].resolution"), "{e}");
    let body = Scene::parse(
        "Scene(dt: 0.01, bodies: [(kind: Fixed, shape: Ball(radius: -1.0))])",
        "b",
    );
    assert!(body.is_err(), "a negative radius must not parse");
    let bad = Body::new(BodyKind::Fixed, Shape::Ball { radius: 0.2 }).with_mass(-2.0);
    let e = sim.add_body(&bad).unwrap_err().to_string();
    assert!(e.contains("add_body: mass"), "{e}");
    let e = sim
        .add_body(&Body::new(BodyKind::Fixed, Shape::Ball { radius: 0.2 }).at(DVec3::NAN))
        .unwrap_err()
        .to_string();
    assert!(e.contains("add_body: position"), "{e}");
    // Nothing was added.
    assert_eq!(sim.positions().len(), 144);
    assert!(sim.props().is_none());
}

/// A ball put under a falling cloth at run time catches it (the contact stage starts with the
/// first body); removing the ball lets it fall on.
#[test]
fn a_body_added_at_run_time_catches_the_cloth_and_its_removal_frees_it() {
    let text = r#"Scene(dt: 0.01, substeps: 8, cloths: [
        (origin: (-0.5, 1.0, -0.5), size: (1.0, 1.0), resolution: (16, 16), plane: Horizontal,
         mass: 0.2, structural: (frequency: 30.0, damping_ratio: 0.1),
         shear: Some((frequency: 30.0, damping_ratio: 0.1)))])"#;
    let mut sim = Simulation::from_scene(&Scene::parse(text, "fall").unwrap()).unwrap();
    assert!(sim.props().is_none(), "no bodies, no rapier world");
    let ball =
        Body::new(BodyKind::Fixed, Shape::Ball { radius: 0.3 }).at(DVec3::new(0.0, 0.3, 0.0));
    let prop = sim.add_body(&ball).unwrap();
    let thickness = sim.props().unwrap().contact().thickness;
    for _ in 0..150 {
        sim.step().unwrap();
        let deepest = sim
            .positions()
            .iter()
            .map(|x| 0.3 - x.distance(DVec3::new(0.0, 0.3, 0.0)))
            .fold(f64::MIN, f64::max);
        assert!(
            deepest < thickness,
            "a particle is {deepest} m inside the ball"
        );
    }
    let centre = |sim: &Simulation| sim.positions()[8 * 16 + 8].y;
    assert!(
        centre(&sim) > 0.6,
        "the cloth's middle rests on the ball top: {}",
        centre(&sim)
    );
    sim.remove_body(prop).unwrap();
    assert!(sim.remove_body(prop).is_err(), "removed twice");
    for _ in 0..40 {
        sim.step().unwrap();
    }
    assert!(centre(&sim) < 0.3, "the cloth fell on: {}", centre(&sim));
}

#[test]
fn grab_holds_a_particle_and_release_lets_it_go() {
    let mut sim = cloth("substeps: 4,");
    let target = DVec3::new(0.2, 1.5, 0.1);
    sim.grab(70, target).unwrap();
    for _ in 0..20 {
        sim.step().unwrap();
        assert_eq!(sim.positions()[70], target);
    }
    assert!(sim.grab(10_000, target).is_err());
    assert!(sim.grab(70, DVec3::NAN).is_err());
    sim.release(70).unwrap();
    for _ in 0..20 {
        sim.step().unwrap();
    }
    assert!(sim.positions()[70].y < 1.5 - 0.01, "released, it falls");
    // A scene pin survives a grab and release.
    sim.grab(0, DVec3::new(-0.5, 1.0, -0.5)).unwrap();
    sim.release(0).unwrap();
    for _ in 0..5 {
        sim.step().unwrap();
    }
    assert_eq!(sim.positions()[0], DVec3::new(-0.5, 1.0, -0.5));
}
