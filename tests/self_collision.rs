//! Self-collision and cloth–cloth collision (`self_collision:` per cloth), the particle layer:
//! checked against the thickness two stacked cloths must rest apart at, the momentum two
//! colliding cloths must keep, a cloth whose neighbours never come that close (unchanged bit
//! for bit), thread counts, and the scene checks.

use harmonic::prelude::*;
use harmonic::StageKind;

mod common;

/// A horizontal `n`×`n` cloth of 0.5 m at height `y`, centred on the y axis, with `extra`
/// (RON) added; every particle pinned where `pinned`.
fn sheet(n: u32, y: f64, pinned: bool, extra: &str) -> String {
    let pins: Vec<String> = (0..n)
        .flat_map(|r| (0..n).map(move |c| format!("Particle({c}, {r})")))
        .collect();
    let pins = if pinned {
        pins.join(", ")
    } else {
        String::new()
    };
    format!(
        "(origin: (-0.25, {y}, -0.25), size: (0.5, 0.5), resolution: ({n}, {n}), mass: 0.1,
          plane: Horizontal, structural: (frequency: 20.0, damping_ratio: 0.3),
          shear: Some((frequency: 20.0, damping_ratio: 0.3)), pins: [{pins}] {extra})"
    )
}

fn scene(cloths: &[String], gravity: f64) -> Scene {
    Scene::parse(
        &format!(
            "Scene(dt: 0.016666666666666666, substeps: 8, integrator: \"symplectic-euler\",
              gravity: (0.0, {gravity}, 0.0), cloths: [{}])",
            cloths.join(", ")
        ),
        "collide.ron",
    )
    .unwrap()
}

const LAYER: &str = ", self_collision: Some((thickness: 0.03, friction: 0.5))";

/// A 12×12 sheet (spacing 45 mm) dropped from 10 cm onto a pinned one of the same grid, both
/// 30 mm thick: without collision it falls through; with it, every particle comes to rest on
/// the one below at the thickness, within the sag one substep's gravity gives (`g h²`).
#[test]
fn a_sheet_rests_on_another_at_the_thickness() {
    let run = |extra: &str| {
        let cloths = [sheet(12, 0.0, true, extra), sheet(12, 0.1, false, extra)];
        let mut sim = Simulation::from_scene(&scene(&cloths, -9.81)).unwrap();
        for _ in 0..180 {
            sim.step().unwrap();
        }
        let y: Vec<f64> = sim.positions()[144..].iter().map(|p| p.y).collect();
        (sim, y)
    };
    let (free, y) = run("");
    assert!(!free.schedule().has(StageKind::SelfCollision));
    let lowest = y.iter().copied().fold(f64::MAX, f64::min);
    assert!(
        lowest < -0.5,
        "without collision it falls through: {lowest}"
    );
    let (sim, y) = run(LAYER);
    assert!(
        sim.schedule().has(StageKind::SelfCollision),
        "{}",
        sim.schedule()
    );
    let h = 1.0 / 480.0;
    let sag = 9.81 * h * h;
    let (lo, hi) = (
        y.iter().copied().fold(f64::MAX, f64::min),
        y.iter().copied().fold(f64::MIN, f64::max),
    );
    let a = sim.diagnostics().audit;
    println!(
        "resting {lo:.6} .. {hi:.6} m over the lower sheet (thickness 0.03, g h² {sag:.1e}); \
         {} pairs found {} times; contacts took {:.4e} J, residual {:.2e} J",
        sim.collision_pairs().0,
        sim.collision_pairs().1,
        a.contacts,
        a.residual
    );
    assert!(lo > 0.03 - 2.0 * sag && hi < 0.03 + 1e-4, "{lo} .. {hi}");
    let (pairs, found) = sim.collision_pairs();
    assert!(pairs >= 144, "{pairs}");
    // Found as it lands; once it rests they hold from frame to frame.
    assert!(
        (1..180).contains(&found),
        "found fewer times than once a frame: {found}"
    );
    assert!(
        a.contacts > 0.0,
        "the landing takes energy out: {}",
        a.contacts
    );
    assert!(sim.diagnostics().failure.is_none());
}

/// Two free 10×10 sheets (spacing 55.6 mm) thrown at each other without gravity for 30
/// frames, one offset by about half a cell, with `extra` (RON) on both: the upper sheet's mean
/// height over the lower's at the end, the drift of their total momentum, the most triangle
/// pairs crossing at a frame's end (the exact test of `common::crossing`, not the stage's
/// query) and the books.
fn thrown(extra: &str) -> (f64, f64, usize, harmonic::EnergyAudit) {
    let a = sheet(
        10,
        0.0,
        false,
        &format!("{extra}, velocity: (0.3, 1.0, 0.0)"),
    );
    let b = sheet(
        10,
        0.1,
        false,
        &format!("{extra}, velocity: (0.0, -1.0, 0.1)"),
    );
    let b = b.replace("origin: (-0.25, 0.1, -0.25)", "origin: (-0.22, 0.1, -0.22)");
    let mut sim = Simulation::from_scene(&scene(&[a, b], 0.0)).unwrap();
    let momentum =
        |sim: &Simulation| -> DVec3 { sim.velocities().iter().map(|v| *v * (0.1 / 100.0)).sum() };
    let p0 = momentum(&sim);
    let triangles = sim.triangles().to_vec();
    let mut most = 0;
    for _ in 0..30 {
        sim.step().unwrap();
        most = most.max(common::crossing::crossing_pairs(
            sim.positions(),
            &triangles,
        ));
    }
    let x = sim.positions();
    let mean = |r: std::ops::Range<usize>| x[r].iter().map(|p| p.y).sum::<f64>() / 100.0;
    (
        mean(100..200) - mean(0..100),
        (momentum(&sim) - p0).length(),
        most,
        sim.diagnostics().audit,
    )
}

/// The sheets 45 mm thick: over the half diagonal (39.3 mm), so no particle fits through a
/// cell of the other. They do not pass through (without collision they do), and the pushes and
/// friction keep the total momentum (each contact's moves go by inverse mass).
#[test]
fn colliding_sheets_keep_their_momentum_and_their_order() {
    let (through, _, _, _) = thrown("");
    assert!(through < 0.0, "without collision they pass: {through}");
    let (apart, drift, _, a) = thrown(", self_collision: Some((thickness: 0.045, friction: 0.5))");
    println!(
        "apart {apart:.4} m; momentum drift {drift:.2e} kg m/s; contacts {:.3e} J",
        a.contacts
    );
    assert!(apart > 0.0, "the upper sheet stays above: {apart}");
    assert!(drift < 1e-12, "momentum kept: {drift}");
    assert!(a.contacts > 0.0);
}

/// The sheets at 20 mm: under a cell's half diagonal, so a particle of one fits through a
/// cell of the other, which particles alone would let pass. The triangles hold it: no two
/// triangles cross at the end of any frame, and the momentum is kept.
#[test]
fn thin_sheets_thrown_at_each_other_never_cross() {
    let (through, _, _, _) = thrown("");
    let (apart, drift, most, _) =
        thrown(", self_collision: Some((thickness: 0.02, friction: 0.5))");
    println!("apart {apart:.4} m ({through:.4} without collision); crossing pairs at a frame's end {most}; momentum drift {drift:.2e}");
    assert!(through < 0.0, "without collision they pass: {through}");
    assert!(apart > 0.0, "the upper sheet stays above: {apart}");
    assert_eq!(most, 0, "no triangles cross");
    assert!(drift < 1e-12, "momentum kept: {drift}");
}

/// A 6×6 sheet thrown down at 15 m/s onto a pinned 12×12 one, 10 mm thick: it moves 31 mm a
/// substep, three thicknesses, so a test of where it ends would find it past the pinned sheet;
/// the swept test sends it back to the side it came from. Every particle stays above the
/// pinned sheet at every frame's end, no triangles cross, and it comes to rest at the
/// thickness; without collision it passes through.
#[test]
fn a_fast_sheet_is_stopped_along_its_path() {
    let run = |extra: &str| {
        let low = sheet(12, 0.0, true, extra);
        let high = sheet(
            6,
            0.2,
            false,
            &format!("{extra}, velocity: (0.0, -15.0, 0.0)"),
        )
        .replace(
            "origin: (-0.25, 0.2, -0.25), size: (0.5, 0.5)",
            "origin: (-0.13, 0.2, -0.11), size: (0.3, 0.3)",
        );
        let mut sim = Simulation::from_scene(&scene(&[low, high], -9.81)).unwrap();
        let triangles = sim.triangles().to_vec();
        let (mut lowest, mut most) = (f64::MAX, 0);
        for _ in 0..60 {
            sim.step().unwrap();
            let y = sim.positions()[144..].iter().map(|p| p.y);
            lowest = y.fold(lowest, f64::min);
            most = most.max(common::crossing::crossing_pairs(
                sim.positions(),
                &triangles,
            ));
        }
        let y = sim.positions()[144..].iter().map(|p| p.y);
        let (lo, hi) = y.fold((f64::MAX, f64::MIN), |(lo, hi), y| (lo.min(y), hi.max(y)));
        (lowest, most, lo, hi)
    };
    let (through, _, _, _) = run("");
    assert!(through < -0.1, "without collision it passes: {through}");
    let (lowest, most, lo, hi) = run(", self_collision: Some((thickness: 0.01))");
    println!("lowest at a frame's end {lowest:.5} m; crossing pairs {most}; at rest {lo:.6} .. {hi:.6} m");
    assert!(lowest > 0.0, "stays above: {lowest}");
    assert_eq!(most, 0);
    let sag = 9.81 / (480.0 * 480.0);
    assert!(lo > 0.01 - 2.0 * sag && hi < 0.01 + 1e-4, "{lo} .. {hi}");
}

/// A cloth whose particles never come within the thickness of each other steps as if it had
/// no collision, bit for bit: the stage only acts on contact.
#[test]
fn a_layer_out_of_contact_changes_nothing() {
    let hang = |extra: &str| {
        let cloth = sheet(12, 0.0, false, extra).replace(
            "plane: Horizontal,",
            "plane: Vertical, pins: [TopLeft, TopRight],",
        );
        let cloth = cloth.replace(", pins: [] ", " ");
        let mut sim = Simulation::from_scene(&scene(&[cloth], -9.81)).unwrap();
        for _ in 0..60 {
            sim.step().unwrap();
        }
        let on = sim.schedule().has(StageKind::SelfCollision);
        (sim.positions().to_vec(), on)
    };
    let thin = ", self_collision: Some((thickness: 0.005))";
    let (a, _) = hang("");
    let (b, on) = hang(thin);
    assert!(on);
    assert!(a == b);
}

/// The stage runs in one fixed order: 1 and 2 threads give the same bits.
#[test]
fn self_collision_is_the_same_on_1_and_2_threads() {
    let cloths = [sheet(12, 0.0, true, LAYER), sheet(12, 0.1, false, LAYER)];
    let scene = scene(&cloths, -9.81);
    let runs: Vec<(Vec<DVec3>, f64)> = [1, 2]
        .map(|threads| {
            common::on_threads(threads, || {
                let mut sim = Simulation::from_scene(&scene).unwrap();
                for _ in 0..40 {
                    sim.step().unwrap();
                }
                (sim.positions().to_vec(), sim.diagnostics().audit.contacts)
            })
        })
        .into();
    assert!(runs[0].1 > 0.0);
    assert!(runs[0] == runs[1]);
}

/// A thickness at or over the particle spacing, or a bad coefficient, is refused where it is.
#[test]
fn bad_self_collision_is_refused_by_name() {
    for (layer, want) in [
        ("(thickness: 0.05)", "particle spacing"),
        ("(thickness: 0.0)", "thickness must be finite and > 0"),
        ("(thickness: 0.01, friction: -1.0)", "friction must be"),
        (
            "(thickness: 0.01, kinetic_friction: inf)",
            "kinetic_friction must be",
        ),
        (
            "(thickness: 0.01, friction: 0.2, kinetic_friction: 0.3)",
            "must be at most friction",
        ),
    ] {
        let cloth = sheet(12, 0.0, false, &format!(", self_collision: Some({layer})"));
        let text = format!("Scene(dt: 0.016666666666666666, substeps: 8, cloths: [{cloth}])");
        let msg = Scene::parse(&text, "bad.ron").unwrap_err().to_string();
        assert!(
            msg.contains("cloths[0].self_collision") && msg.contains(want),
            "{layer}: {msg}"
        );
    }
}

/// With the springs on the GPU the candidates are found there and the pass runs on the host
/// between the device's substeps: the sheet rests on the other at the thickness there too (to
/// the device's f32), and a second run on the device ends with the same bits.
#[test]
fn a_sheet_rests_at_the_thickness_beside_the_gpu_springs() {
    if common::gpu_or_skip(harmonic::internals::gpu::GpuContext::shared(true)).is_none() {
        return;
    }
    let cloths = [sheet(12, 0.0, true, LAYER), sheet(12, 0.1, false, LAYER)];
    let mut s = scene(&cloths, -9.81);
    s.backend = Some("gpu".into());
    let run = || {
        let mut sim = Simulation::from_scene(&s).unwrap();
        let config = SimConfig {
            device_collide_pass: true,
            ..*sim.config()
        };
        sim.set_config(config).unwrap();
        sim.step().unwrap();
        let schedule = sim.schedule().to_string();
        assert!(
            schedule.contains("self-collision (on the GPU)"),
            "{schedule}"
        );
        for _ in 0..180 {
            sim.step().unwrap();
        }
        sim
    };
    let (sim, again) = (run(), run());
    let bits = |sim: &Simulation| -> Vec<[u64; 3]> {
        (sim.positions().iter())
            .map(|p| p.to_array().map(f64::to_bits))
            .collect()
    };
    assert!(bits(&sim) == bits(&again), "two runs on the device differ");
    let y = sim.positions()[144..].iter().map(|p| p.y);
    let (lo, hi) = y.fold((f64::MAX, f64::MIN), |(lo, hi), y| (lo.min(y), hi.max(y)));
    println!("gpu: resting {lo:.6} .. {hi:.6} m");
    assert!(lo > 0.0299 && hi < 0.0301, "{lo} .. {hi}");
}

/// A quad 40 cm × 10 cm standing in the plane `z = 0` dropped (at `vy`) across the top edge
/// of a pinned one standing in `x = 0`, both with `layer` (RON) added:
/// no corner ever comes near the other's face (they are 20 cm off it), so only their edges
/// meet. Returns, over 90 frames, the most triangle pairs crossing at a frame's end (the exact
/// test), the nearest any of the falling quad's edges came to the pinned quad's top edge at a
/// frame's end once it had landed (sampled along the edge, not the stage's query), and the
/// frames of the first 20 that ended with it below that edge, across it (where the falling
/// quad meets the pinned one's plane, all of it under the edge; later, tipped off the edge to
/// one side, it falls past as it may).
fn across(vy: f64, layer: &str) -> (usize, f64, usize) {
    let quad = |v: &str, extra: &str| {
        format!(
            "(vertices: [{v}], triangles: [(0, 1, 2), (0, 2, 3)], mass: 0.1,
              stretch: (frequency: 30.0, damping_ratio: 0.3), bend: Some((frequency: 30.0)) {extra} {layer})"
        )
    };
    let pinned = quad(
        "(0.0, -0.1, -0.2), (0.0, 0.0, -0.2), (0.0, 0.0, 0.2), (0.0, -0.1, 0.2)",
        ", pins: [Vertices([0, 1, 2, 3])]",
    );
    let falling = quad(
        "(-0.2, 0.03, 0.0), (0.2, 0.03, 0.0), (0.2, 0.13, 0.0), (-0.2, 0.13, 0.0)",
        &format!(", velocity: (0.0, {vy}, 0.0)"),
    );
    let text = format!(
        "Scene(dt: 0.016666666666666666, substeps: 8, integrator: \"symplectic-euler\",
          meshes: [{pinned}, {falling}])"
    );
    let mut sim = Simulation::from_scene(&Scene::parse(&text, "across.ron").unwrap()).unwrap();
    let triangles = sim.triangles().to_vec();
    let (mut most, mut nearest, mut under) = (0, f64::MAX, 0);
    for frame in 0..90 {
        sim.step().unwrap();
        let x = sim.positions();
        most = most.max(common::crossing::crossing_pairs(x, &triangles));
        let meets: Vec<f64> = [(4, 5), (5, 6), (6, 7), (7, 4)]
            .into_iter()
            .filter(|&(i, j)| x[i].x * x[j].x < 0.0)
            .map(|(i, j)| x[i].y + (x[j].y - x[i].y) * x[i].x / (x[i].x - x[j].x))
            .collect();
        if frame < 20 && !meets.is_empty() && meets.iter().all(|&y| y < 0.0) {
            under += 1;
        }
        if frame >= 10 {
            let (a, b) = (x[1], x[2]);
            for (i, j) in [(4, 5), (5, 6), (6, 7), (7, 4), (4, 6)] {
                for k in 0..=2000 {
                    let p = a + (b - a) * (k as f64 / 2000.0);
                    let d = common::crossing::to_segment(p, x[i], x[j]);
                    nearest = nearest.min(d);
                }
            }
        }
    }
    assert!(sim.diagnostics().failure.is_none());
    (most, nearest, under)
}

/// Edge against edge: the falling quad rests across the pinned one's top edge at the
/// thickness (less the sag one substep's gravity gives, `g h²`, and the sampling's 0.1 mm);
/// without collision, or with its particles against triangles only, it falls through. Dropped from 30 mm, the edges close to the thickness
/// and are pushed apart; thrown at 15 m/s (31 mm a substep, more than the thickness) they
/// cross within a substep and the swept test sends the quad back to its side.
#[test]
fn edges_that_meet_with_no_corner_near_are_kept_apart() {
    for layer in ["", ", self_collision: Some((thickness: 0.02))"] {
        let (through, _, under) = across(0.0, layer);
        assert!(
            through > 0 && under > 0,
            "{layer}: falls through: {through}, {under}"
        );
    }
    let sag = 9.81 / (480.0 * 480.0);
    for vy in [0.0, -15.0] {
        let (most, nearest, under) =
            across(vy, ", self_collision: Some((thickness: 0.02, edges: true))");
        println!("thrown at {vy} m/s: crossing pairs {most}, nearest {nearest:.6} m, frames under {under}");
        assert_eq!((most, under), (0, 0), "at {vy} m/s");
        assert!(
            nearest > 0.02 - 2.0 * sag - 1e-4 && nearest < 0.02 + 1e-4,
            "at {vy} m/s: {nearest}"
        );
    }
}
