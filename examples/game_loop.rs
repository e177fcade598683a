//! A plain game loop around the engine, no window: uneven frame times go into the fixed-step
//! accumulator (`advance`), and each frame reads the buffers a renderer would upload
//! (`render`: interpolated positions, normals, triangles), with no allocation per frame.
//!
//! `cargo run --release --example game_loop [SCENE]` (default: scenes/hanging_cloth.ron)

use harmonic::prelude::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| format!("{}/scenes/hanging_cloth.ron", env!("CARGO_MANIFEST_DIR")));
    let mut sim = Simulation::load(&path)?;
    println!(
        "{path}: {} particles, {} triangles, dt {} s",
        sim.positions().len(),
        sim.triangles().len(),
        sim.config().dt
    );
    // Frame times as a game sees them: 60 Hz, every third frame at 144 Hz, one 250 ms hitch.
    let frame_time = |i: usize| match i {
        100 => 0.25,
        i if i % 3 == 0 => 1.0 / 144.0,
        _ => 1.0 / 60.0,
    };
    // Interleaved position + normal, as a vertex buffer would take them.
    let mut vertices: Vec<[f32; 6]> = Vec::new();
    let mut clock = 0.0;
    for i in 0..240 {
        let dt = frame_time(i);
        clock += dt;
        let a = sim.advance(dt)?;
        let view = sim.render(a.alpha);
        vertices.clear();
        vertices.extend(
            view.positions
                .iter()
                .zip(view.normals)
                .map(|(p, n)| [p.x, p.y, p.z, n.x, n.y, n.z]),
        );
        if a.dropped > 0.0 {
            println!(
                "frame {i}: a {dt} s frame took {} steps (the cap) and dropped {:.3} s",
                a.steps, a.dropped
            );
        }
        if i % 60 == 0 {
            let d = sim.diagnostics();
            let s = sim.stats();
            println!(
                "frame {i:3}: wall clock {clock:.3} s, simulated {:.3} s, alpha {:.2}, energy {:.4e} J, max strain {:.2} %, h/h_c {:.3}, last step {:.2} ms",
                sim.time(),
                a.alpha,
                d.energy,
                100.0 * d.max_strain,
                d.step_ratio,
                1e3 * s.total().as_secs_f64()
            );
        }
    }
    println!(
        "{} vertices per frame; simulated {:.3} s for a wall clock of {clock:.3} s",
        vertices.len(),
        sim.time()
    );
    Ok(())
}
