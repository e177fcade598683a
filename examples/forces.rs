//! The game's own forces on the cloth (`set_forces`): a crude breeze on the flag, a drag toward
//! the wind's velocity `F = c (w − v)` on every particle, set anew each frame from the
//! particles' velocities. The force stage joins the schedule, its work is booked in the energy
//! audit, and the flag streams downwind (+x) instead of hanging from its pole.
//!
//! `cargo run --release --example forces [SCENE]` (default: scenes/flag.ron)

use harmonic::prelude::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| format!("{}/scenes/flag.ron", env!("CARGO_MANIFEST_DIR")));
    let mut sim = Simulation::load(&path)?;
    let n = sim.positions().len();
    // The wind (m/s) and each particle's drag coefficient (N·s/m): the cloth's 0.2 kg relaxes
    // toward the wind's speed in about a second, pushed at up to 10 m/s² against gravity's 9.81.
    let wind = DVec3::new(10.0, 0.0, 0.0);
    let c = 0.2 / n as f64;
    let mut forces = vec![DVec3::ZERO; n];
    let mean_x = |sim: &Simulation| sim.positions().iter().map(|x| x.x).sum::<f64>() / n as f64;
    println!(
        "{path}: {n} particles, the flag's mean x {:.3} m",
        mean_x(&sim)
    );
    let frames = (3.0 / sim.config().dt).round() as u64;
    for frame in 1..=frames {
        for (f, v) in forces.iter_mut().zip(sim.velocities()) {
            *f = c * (wind - *v);
        }
        sim.set_forces(&forces)?;
        let stats = *sim.step()?;
        if frame == 1 {
            println!("schedule: {}", sim.schedule());
        }
        if let Some(f) = stats.failure {
            return Err(f.to_string().into());
        }
        if frame % 60 == 0 {
            let audit = sim.diagnostics().audit;
            println!(
                "t = {:.2} s: the flag's mean x {:.3} m; the forces' work so far {:+.4e} J (the audit's `forces` line)",
                sim.time(),
                mean_x(&sim),
                audit.forces
            );
        }
    }
    Ok(())
}
