//! Loads a scene, runs it, and prints what the engine reports along the way: energy, strain,
//! contacts and the cost of each stage.
//!
//! `cargo run --release --example drape [SCENE] [SECONDS]` (default: scenes/drape_sphere.ron,
//! the scene's own `seconds`)

use harmonic::prelude::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .unwrap_or_else(|| format!("{}/scenes/drape_sphere.ron", env!("CARGO_MANIFEST_DIR")));
    let scene = Scene::load(&path)?;
    let seconds: f64 = match args.next() {
        Some(s) => s.parse()?,
        None => scene.seconds.unwrap_or(1.0),
    };
    let mut sim = Simulation::from_scene(&scene)?;
    if let Some(choice) = sim.step_choice() {
        println!(
            "substeps per frame: {} (chosen automatically)",
            choice.substeps
        );
    }
    let frames = (seconds / sim.config().dt).round() as u64;
    let report_every = ((0.5 / sim.config().dt).round() as u64).max(1);
    let (mut integrate, mut contacts) = (0.0, 0.0);
    for f in 1..=frames {
        let s = *sim.step()?;
        integrate += s.stages[StageKind::Integrate].as_secs_f64();
        contacts += s.stages[StageKind::Contacts].as_secs_f64();
        if f % report_every == 0 || f == frames {
            let d = sim.diagnostics();
            let touching = sim.contact_stats().map_or(0, |c| c.contacts);
            println!(
                "t = {:.2} s: energy {:.4e} J, max strain {:.2} %, contacts this frame {touching}",
                sim.time(),
                d.energy,
                100.0 * d.max_strain
            );
        }
    }
    println!("stage time: integrate {integrate:.3} s, contacts {contacts:.3} s");
    Ok(())
}
