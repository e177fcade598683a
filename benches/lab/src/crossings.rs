//! Cloth passing through cloth, counted: a scene run as it is and with every cloth's
//! self-collision taken out, the triangle pairs that cross at the end of each frame counted by
//! the exact test the engine's tests use (`tests/common/crossing.rs`, not the stage's own
//! query), beside the self-collision and integrate stages' times.

use std::time::Duration;

use harmonic::{Scene, Simulation, StageKind};

#[path = "../../../tests/common/crossing.rs"]
#[allow(dead_code)]
mod crossing;

/// One run's counts and times.
struct Run {
    /// Crossing pairs at the end of each frame: all, and those apart along the cloth.
    counts: Vec<usize>,
    apart: Vec<usize>,
    collide: Duration,
    integrate: Duration,
    /// Candidates tested in the last substep.
    pairs: usize,
}

/// `apart`: twice the thickness, the rest distance within which a cloth's triangles are
/// neighbours the stage leaves to the springs.
fn run(scene: &Scene, frames: u32, apart: f64) -> Result<Run, String> {
    let mut sim = Simulation::from_scene(scene).map_err(|e| e.to_string())?;
    let triangles = sim.triangles().to_vec();
    let rest = sim.positions().to_vec();
    let mut out = Run {
        counts: Vec::new(),
        apart: Vec::new(),
        collide: Duration::ZERO,
        integrate: Duration::ZERO,
        pairs: 0,
    };
    for _ in 0..frames {
        sim.step().map_err(|e| e.to_string())?;
        let t = sim.stats().stages;
        out.collide += t[StageKind::SelfCollision];
        out.integrate += t[StageKind::Integrate];
        let list = crossing::crossing_list(sim.positions(), &triangles);
        let far = (list.iter())
            .filter(|&&(a, b)| crossing::apart_at_rest(&rest, triangles[a], triangles[b], apart))
            .count();
        out.counts.push(list.len());
        out.apart.push(far);
    }
    out.pairs = sim.collision_pairs().0;
    Ok(out)
}

/// The report for `path` over `frames` frames (the scene's own length where `None`).
pub fn report(path: &std::path::Path, frames: Option<u32>) -> Result<String, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let scene = Scene::parse(&text, path.display().to_string()).map_err(|e| e.to_string())?;
    let frames = frames.unwrap_or_else(|| (scene.seconds.unwrap_or(1.0) / scene.dt).round() as u32);
    let mut bare = scene.clone();
    for c in &mut bare.cloths {
        c.self_collision = None;
    }
    for m in &mut bare.meshes {
        m.self_collision = None;
    }
    let thickest = (scene.cloths.iter().map(|c| c.self_collision))
        .chain(scene.meshes.iter().map(|m| m.self_collision))
        .flatten()
        .map(|c| c.thickness)
        .fold(0.0, f64::max);
    let apart = 2.0 * thickest;
    let (with, without) = (run(&scene, frames, apart)?, run(&bare, frames, apart)?);
    let mut out = format!(
        "{}: {frames} frames; triangle pairs sharing no corner that cross at a frame's end \
         (exact test), and those of them apart at rest by twice the thickness ({apart} m)\n\n\
         | run | most | frames with any | last frame | most apart at rest | self-collision | integrate | candidates at the end |\n\
         |---|---|---|---|---|---|---|---|\n",
        path.display()
    );
    for (name, r) in [("with self-collision", &with), ("without", &without)] {
        let most = r.counts.iter().copied().max().unwrap_or(0);
        let any = r.counts.iter().filter(|&&c| c > 0).count();
        out += &format!(
            "| {name} | {most} | {any} | {} | {} | {:.2} s | {:.2} s | {} |\n",
            r.counts.last().copied().unwrap_or(0),
            r.apart.iter().copied().max().unwrap_or(0),
            r.collide.as_secs_f64(),
            r.integrate.as_secs_f64(),
            r.pairs
        );
    }
    let worst = (with.counts.iter().zip(&without.counts))
        .map(|(&w, &o)| w as f64 / o.max(1) as f64)
        .fold(0.0, f64::max);
    out += &format!(
        "\nworst frame: {:.2} % of the pairs crossing there without self-collision\n",
        100.0 * worst
    );
    Ok(out)
}
