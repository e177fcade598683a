//! Cloth against rapier bodies: no tunnelling, attachments that follow their body, momentum
//! exchanged exactly, particles kept outside colliders.

use harmonic::contacts::Attachment;
use harmonic::prelude::*;

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
    for _ in 0..30 {
        sim.step().expect("finite");
        for (i, x) in sim.positions().iter().enumerate() {
            assert!(
                x.z < 0.495,
                "particle {i} reached z = {} (through the wall)",
                x.z
            );
        }
    }
    let swept = sim.props().expect("props").stats;
    assert!(
        sim.positions().iter().all(|x| x.z > 0.4),
        "the cloth reached the wall"
    );
    let _ = swept;
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
        let cloth: DVec3 = p.v.iter().zip(&p.mass).map(|(v, m)| *v * *m).sum();
        let props = sim.props().expect("props");
        let (_, ball) = props.bodies().iter().next().expect("one body");
        (cloth, ball.linvel().as_dvec3() * ball.mass() as f64)
    };
    let (c0, b0) = momentum(&sim);
    let total0 = c0 + b0;
    let mut touched = false;
    for _ in 0..150 {
        sim.step().expect("finite");
        touched |= sim.props().expect("props").stats.contacts > 0;
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
    for (name, frames) in [("trampoline.ron", 120), ("drape_sphere.ron", 60)] {
        let mut sim = load(name);
        let thickness = sim.props().expect("props").contact.thickness;
        let mut contacts = 0;
        for _ in 0..frames {
            sim.step().expect("finite");
            let s = sim.props().expect("props").stats;
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
