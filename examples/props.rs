//! Cloth and rigid bodies built from code, not RON: a cloth pinned at its four edges (a
//! trampoline) described with the scene types, and a ball living in *your own* rapier world,
//! which the cloth pushes and which you step yourself (`Simulation::step_with`).
//!
//! `cargo run --release --example props`

use harmonic::prelude::*;
use harmonic::scene::{Anchor, Cloth, Plane, SpringSpec};
use rapier3d::prelude::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // The cloth: 1.5 m square, 32×32 particles, 0.5 kg, pinned along its edges at y = 0.5.
    let mut scene = Scene::new(1.0 / 60.0);
    let spring = |frequency: f64| SpringSpec {
        frequency: Some(frequency),
        damping_ratio: Some(0.5),
        ..SpringSpec::default()
    };
    scene.cloths.push(Cloth {
        origin: [-0.75, 0.5, -0.75],
        size: (1.5, 1.5),
        resolution: (32, 32),
        plane: Plane::Horizontal,
        mass: 0.5,
        structural: spring(120.0),
        shear: Some(spring(80.0)),
        bend: None,
        pins: vec![
            Anchor::TopEdge,
            Anchor::BottomEdge,
            Anchor::LeftEdge,
            Anchor::RightEdge,
        ],
        velocity: [0.0; 3],
        air: None,
        tethers: None,
        stretch_limit: None,
        tearing: None,
        self_collision: None,
    });
    // Validation reports every problem with its location, as for a RON file.
    if let Some(issue) = scene.validate().first() {
        return Err(format!("{issue}").into());
    }
    let mut sim = Simulation::from_scene(&scene)?;

    // Your rapier world, stepped by you once per frame.
    let mut world = PhysicsWorld::new();
    world.integration_parameters.dt = sim.config().dt as f32;
    let (ball, _) = world.insert(
        RigidBodyBuilder::dynamic()
            .translation(Vector::new(0.0, 1.2, 0.0))
            .linear_damping(3.0),
        ColliderBuilder::ball(0.15).mass(0.3),
    );

    for frame in 1..=360 {
        sim.step_with(&mut world.bodies, &world.colliders)?;
        world.step();
        if frame % 60 == 0 {
            let b = &world.bodies[ball];
            let contacts = sim.contact_stats().map_or(0, |c| c.contacts);
            println!(
                "t = {:.1} s: ball at y = {:.3} m, {contacts} cloth contacts this frame",
                sim.time(),
                b.translation().y,
            );
        }
    }
    let sag = 0.5 - sim.positions().iter().map(|x| x.y).fold(f64::MAX, f64::min);
    println!("the cloth sags {sag:.3} m under the ball");
    Ok(())
}
