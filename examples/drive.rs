//! An animated character's cape, driven by the game (`drive_within`, `set_drive_targets`): the
//! cape of `scenes/character_cape.ron` without its capsule, its collar following a "skinned
//! shoulder" the game moves each frame (a walk round a circle, bobbing with each step), and every
//! other vertex kept within a maximum distance of the pose the skin gives it, growing from 0 at
//! the collar to 0.45 m at the hem (a garment's motion constraint, as painted in a modeller).
//! One call a frame sets all the targets, without allocating; the drive stage moves the collar
//! there a share every substep, so the cape feels the walk.
//!
//! `cargo run --release --example drive`

use harmonic::prelude::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = format!("{}/scenes/character_cape.ron", env!("CARGO_MANIFEST_DIR"));
    let mut scene = Scene::load(&path)?;
    // The game animates the character itself: no capsule body, the collar's pins stay pins.
    scene.bodies.clear();
    scene.meshes[0].pinned_to = None;
    let particles: Vec<usize> = (scene.mesh_particles(0)?.into_iter())
        .flatten()
        .map(|i| i as usize)
        .collect();
    let mut sim = Simulation::from_scene(&scene)?;
    // The skin's rest pose: the cape as modelled (one particle per welded vertex).
    let rest: Vec<DVec3> = particles.iter().map(|&i| sim.positions()[i]).collect();
    let collar = rest.iter().map(|x| x.y).fold(f64::MIN, f64::max);
    let max_distance: Vec<f64> = rest
        .iter()
        .map(|x| (0.5 * (collar - x.y)).clamp(0.0, 0.45))
        .collect();
    let drive = sim.drive_within(&particles, &max_distance)?;
    println!("{path}: {} particles driven", particles.len());

    // The character walks a circle of 1.5 m at 1.2 m/s, facing along it, bobbing 3 cm a step.
    let (radius, speed) = (1.5, 1.2);
    let pose = |t: f64| {
        let a = speed * t / radius;
        let turn = glam::DQuat::from_rotation_y(-a);
        let at = DVec3::new(
            radius * a.sin(),
            0.03 * (2.0 * std::f64::consts::TAU * t).sin(),
            radius * (1.0 - a.cos()),
        );
        (turn, at)
    };
    let mut targets = rest.clone();
    let frames = (4.0 / sim.config().dt).round() as u64;
    let mut worst: f64 = 0.0;
    for frame in 1..=frames {
        let t = frame as f64 * sim.config().dt;
        let (turn, at) = pose(t);
        for (target, x) in targets.iter_mut().zip(&rest) {
            *target = turn * *x + at;
        }
        sim.set_drive_targets(drive, &targets)?;
        let stats = *sim.step()?;
        if frame == 1 {
            println!("schedule: {}", sim.schedule());
        }
        if let Some(f) = stats.failure {
            return Err(f.to_string().into());
        }
        // Every driven particle ends its frame within its maximum distance of its target.
        for ((&i, target), r) in particles.iter().zip(&targets).zip(&max_distance) {
            let beyond = (sim.positions()[i] - *target).length() - r;
            worst = worst.max(beyond);
        }
        if frame % 60 == 0 {
            let audit = sim.diagnostics().audit;
            let hem = particles
                .iter()
                .zip(&targets)
                .map(|(&i, x)| (sim.positions()[i] - *x).length())
                .fold(0.0, f64::max);
            println!(
                "t = {:.1} s: the hem swings up to {hem:.3} m from the skinned pose; the drive put in {:+.4e} J so far (the audit's attachments line)",
                sim.time(),
                audit.attachments
            );
        }
    }
    println!("the furthest any particle ended beyond its maximum distance: {worst:.1e} m");
    if worst > 1e-9 {
        return Err(format!("a particle ended {worst:e} m beyond its maximum distance").into());
    }
    Ok(())
}
