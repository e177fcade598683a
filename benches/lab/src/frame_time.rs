//! `harmonic-lab frame-time`: the wall time of whole frames (`Simulation::step`) at fixed
//! substeps, for comparing two builds of the engine side by side (the frame as a schedule must
//! not cost more than the hand-written order did). Run it from a script that alternates the
//! two builds' binaries, at `RAYON_NUM_THREADS=1` and `2`, and compare the medians.

use std::time::Instant;

use harmonic::internals::hanging_cloth;
use harmonic::scene::{Rope, SpringSpec};
use harmonic::{Scene, Simulation};

/// The cases: what each measures.
pub const CASES: [(&str, &str); 4] = [
    (
        "chain",
        "the 20-link chain of scenes/chain.ron at 1 substep of 0.25 ms: the per-frame overhead",
    ),
    (
        "cloth16",
        "a 16×16 hanging cloth at 1 substep: the per-frame overhead of a small cloth",
    ),
    (
        "stiff128",
        "a 128×128 cloth of 1 m and 1 kg, k = 1e4 N/m, two corners pinned, 400 substeps",
    ),
    (
        "cloth1024",
        "a 1024×1024 hanging cloth, 1 kg over 1 m², 8 substeps",
    ),
];

/// The scene, fixed substeps and frames per timed run of a case.
fn case(name: &str) -> Option<(Scene, u32, u32)> {
    let spec = |k: f64| SpringSpec {
        stiffness: Some(k),
        damping: Some(0.01),
        ..Default::default()
    };
    match name {
        "chain" => {
            let mut s = Scene::new(2.5e-4);
            s.gravity = [0.0, -9.81, 0.0];
            s.ropes.push(Rope {
                start: [0.0; 3],
                end: [1.0, 0.0, 0.0],
                particles: 21,
                mass: 0.5,
                spring: SpringSpec {
                    stiffness: Some(2e4),
                    damping: Some(0.5),
                    ..Default::default()
                },
                pin_start: true,
                pin_end: false,
                bend: None,
            });
            Some((s, 1, 200_000))
        }
        "cloth16" => {
            let mut s = hanging_cloth(16);
            s.dt = 1e-3;
            Some((s, 1, 20_000))
        }
        "stiff128" => {
            let mut s = hanging_cloth(128);
            s.dt = 1.0 / 60.0;
            let c = &mut s.cloths[0];
            c.structural = spec(1e4);
            c.shear = Some(spec(1e4));
            c.bend = Some(spec(1e3));
            Some((s, 400, 4))
        }
        "cloth1024" => {
            let mut s = hanging_cloth(1024);
            s.dt = 1.0 / 60.0;
            Some((s, 8, 3))
        }
        _ => None,
    }
}

/// Runs `case` `repeats` times (after one untimed run) and returns each run's mean frame time
/// in seconds.
pub fn measure(name: &str, repeats: u32) -> Result<Vec<f64>, String> {
    let (mut scene, substeps, frames) = case(name).ok_or_else(|| {
        let names: Vec<_> = CASES.iter().map(|c| c.0).collect();
        format!("--case {name}: expected one of {}", names.join(", "))
    })?;
    scene.substeps = Some(substeps);
    let mut sim = Simulation::from_scene(&scene).map_err(|e| e.to_string())?;
    let mut out = Vec::new();
    for run in 0..=repeats {
        let t = Instant::now();
        for _ in 0..frames {
            sim.step().map_err(|e| e.to_string())?;
        }
        if run > 0 {
            out.push(t.elapsed().as_secs_f64() / f64::from(frames));
        }
    }
    Ok(out)
}
