//! Tethers (`tethers:` per cloth): each free particle held within `(1 + slack)` of its rest
//! distance to its nearest anchors, checked against that distance measured here from the
//! cloth's start, on both back ends.

use harmonic::prelude::*;
use harmonic::StageKind;

mod common;

/// A soft 16×16 cloth of 1 m hanging from its top corners, with `tethers` (RON) if given.
fn soft_cloth(tethers: &str, backend: &str) -> Scene {
    cloth(6.0, tethers, backend)
}

/// The 16×16 cloth with springs of `hz`.
fn cloth(hz: f64, tethers: &str, backend: &str) -> Scene {
    Scene::parse(
        &format!(
            "Scene(dt: 0.016666666666666666, substeps: 8, integrator: \"symplectic-euler\", backend: \"{backend}\",
              cloths: [(origin: (-0.5, 1.0, 0.0), size: (1.0, 1.0), resolution: (16, 16), mass: 0.5,
                structural: (frequency: {hz}, damping_ratio: 0.2), shear: Some((frequency: {hz}, damping_ratio: 0.2)),
                pins: [TopLeft, TopRight] {tethers})])"
        ),
        "soft.ron",
    )
    .unwrap()
}

/// The worst ratio, over the free particles, of the distance to the nearer pin over its rest
/// distance, for particles at `x` that started at `start` (pins 0 and 15).
fn worst_ratio(start: &[DVec3], x: &[DVec3]) -> f64 {
    let pins = [0, 15];
    (0..x.len())
        .filter(|i| !pins.contains(i))
        .map(|i| {
            let p = pins
                .iter()
                .copied()
                .min_by(|&a, &b| {
                    let (da, db) = (
                        (start[i] - start[a]).length(),
                        (start[i] - start[b]).length(),
                    );
                    da.total_cmp(&db).then(a.cmp(&b))
                })
                .unwrap();
            (x[i] - x[p]).length() / (start[i] - start[p]).length()
        })
        .fold(0.0, f64::max)
}

/// Without tethers the soft cloth stretches to 18× its rest distances from the pins; with
/// them (slack 0.1, the nearest pin) no particle ends a frame further than 1.1× from it, on
/// either back end, and the projections only take energy out (booked as limits).
#[test]
fn tethers_hold_a_soft_cloth_to_its_slack() {
    let mut free = Simulation::from_scene(&soft_cloth("", "cpu")).unwrap();
    assert!(!free.schedule().has(StageKind::Tethers));
    let start = free.positions().to_vec();
    let mut loose: f64 = 0.0;
    for _ in 0..120 {
        free.step().unwrap();
        loose = loose.max(worst_ratio(&start, free.positions()));
    }
    println!("untethered: up to {loose:.3}× the rest distance from the nearer pin");
    assert!(loose > 1.5, "the soft cloth should stretch: {loose}");
    for backend in ["cpu", "gpu"] {
        if backend == "gpu"
            && common::gpu_or_skip(harmonic::internals::gpu::GpuContext::shared(true)).is_none()
        {
            continue;
        }
        let scene = soft_cloth(", tethers: Some((slack: 0.1, anchors: 1))", backend);
        let mut sim = Simulation::from_scene(&scene).unwrap();
        assert!(sim.schedule().has(StageKind::Tethers), "{}", sim.schedule());
        let mut worst: f64 = 0.0;
        for _ in 0..120 {
            sim.step().unwrap();
            worst = worst.max(worst_ratio(&start, sim.positions()));
        }
        let a = sim.diagnostics().audit;
        println!(
            "{backend}: tethered up to {worst:.6}×; the tethers took {:.4e} J",
            a.limits
        );
        let tol = if backend == "gpu" { 1e-5 } else { 1e-12 };
        assert!(worst <= 1.1 + tol, "{backend}: {worst}× the rest distance");
        assert!(
            worst > 1.09,
            "{backend}: the tethers hold at their slack, {worst}"
        );
        assert!(a.limits > 0.0, "{backend}: projections take energy out");
        assert_eq!(a.contacts, 0.0, "{backend}: no contacts");
        assert!(sim.diagnostics().failure.is_none());
    }
}

/// Tethers that never reach their limit change nothing: the same trajectory, bit for bit.
#[test]
fn slack_tethers_change_nothing() {
    let mut free = Simulation::from_scene(&cloth(30.0, "", "cpu")).unwrap();
    let tethers = ", tethers: Some((slack: 2.0, anchors: 2))";
    let mut slack = Simulation::from_scene(&cloth(30.0, tethers, "cpu")).unwrap();
    let start = free.positions().to_vec();
    let mut loose: f64 = 0.0;
    for _ in 0..60 {
        free.step().unwrap();
        slack.step().unwrap();
        loose = loose.max(worst_ratio(&start, free.positions()));
    }
    assert!(
        loose < 3.0,
        "the stiffer cloth stays within the slack: {loose}"
    );
    assert!(slack.schedule().has(StageKind::Tethers));
    assert_eq!(free.positions(), slack.positions());
    assert_eq!(free.velocities(), slack.velocities());
}

#[test]
fn bad_tethers_are_refused_by_name() {
    for (t, want) in [
        (
            "(slack: -0.1)",
            "cloths[0].tethers: slack must be finite and ≥ 0, got -0.1",
        ),
        (
            "(anchors: 5)",
            "cloths[0].tethers: anchors must be 1 to 4, got 5",
        ),
    ] {
        let text = format!(
            "Scene(dt: 0.01, cloths: [(origin: (0.0, 1.0, 0.0), size: (1.0, 1.0), resolution: (4, 4),
              mass: 0.1, structural: (frequency: 5.0), pins: [TopLeft], tethers: Some({t}))])"
        );
        let e = Scene::parse(&text, "t.ron").unwrap_err().to_string();
        assert!(e.contains(want), "{e}");
    }
}

/// A mesh's tethers tie it to its pins, or to the body its pins hang on: the character's cape
/// keeps every particle within its slack of the nearest collar particle while it walks.
#[test]
fn a_mesh_hung_on_a_body_is_tethered_to_it() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut scene = Scene::load(root.join("scenes/character_cape.ron")).unwrap();
    scene.meshes[0].tethers = Some(harmonic::TetherSpec {
        slack: 0.05,
        anchors: 2,
    });
    let built = scene.build();
    let tethers: usize = built
        .world
        .query::<&harmonic::Tethers>()
        .iter()
        .map(|t| t.links.len())
        .sum();
    let particles = built.world.query::<&Particle>().iter().count();
    // Two anchors for every particle off the collar's row of 21.
    assert_eq!(tethers, 2 * (particles - 21));
    let mut sim = Simulation::from_scene(&scene).unwrap();
    assert!(sim.schedule().has(StageKind::Tethers), "{}", sim.schedule());
    for _ in 0..90 {
        sim.step().unwrap();
    }
    assert!(sim.diagnostics().failure.is_none());
}

/// The tethers' pass runs block by block on rayon's pool for a large cloth, its blocks' sums in
/// block order: 1 and 2 threads give the same bits and the same books.
#[test]
fn tethers_are_the_same_on_1_and_2_threads() {
    let scene = Scene::parse(
        "Scene(dt: 0.016666666666666666, substeps: 8, integrator: \"symplectic-euler\",
          cloths: [(origin: (-0.5, 1.0, 0.0), size: (1.0, 1.0), resolution: (80, 80), mass: 0.5,
            structural: (frequency: 20.0, damping_ratio: 0.2), shear: Some((frequency: 20.0)),
            pins: [TopLeft, TopRight], tethers: Some((slack: 0.05, anchors: 2)))])",
        "big.ron",
    )
    .unwrap();
    let runs: Vec<(Vec<DVec3>, Vec<DVec3>, harmonic::EnergyAudit)> = [1, 2]
        .map(|threads| {
            common::on_threads(threads, || {
                let mut sim = Simulation::from_scene(&scene).unwrap();
                for _ in 0..20 {
                    sim.step().unwrap();
                }
                let a = sim.diagnostics().audit;
                (sim.positions().to_vec(), sim.velocities().to_vec(), a)
            })
        })
        .into();
    assert!(runs[0].2.limits > 0.0, "{:?}", runs[0].2);
    assert!(runs[0] == runs[1]);
}

/// The books of a grid cloth's projections (its springs by grid rows) agree with those of the
/// same cloth built spring by spring (a tearable cloth, its threshold never reached): the
/// springs' change is evaluated only where a particle moved, in both.
#[test]
fn a_grid_books_its_tethers_as_its_springs_one_by_one() {
    let tethers = ", tethers: Some((slack: 0.05, anchors: 2))";
    let run = |extra: &str| {
        let mut sim = Simulation::from_scene(&soft_cloth(extra, "cpu")).unwrap();
        for _ in 0..20 {
            sim.step().unwrap();
        }
        (sim.diagnostics().audit, sim.positions().to_vec())
    };
    let (grid, xg) = run(tethers);
    let (loose, xl) = run(&format!("{tethers}, tearing: Some((stretch: 100.0))"));
    let apart = xg
        .iter()
        .zip(&xl)
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0, f64::max);
    println!(
        "limits: grid {:.12e} J, one by one {:.12e} J; residuals {:.3e}, {:.3e} J; states {apart:.1e} m apart",
        grid.limits, loose.limits, grid.residual, loose.residual
    );
    assert!(apart < 1e-9, "the two builds step alike: {apart} m");
    assert!(grid.limits > 1e-3, "the tethers work: {}", grid.limits);
    let rel = (grid.limits - loose.limits).abs() / grid.limits;
    assert!(rel < 1e-9, "{} against {}", grid.limits, loose.limits);
    assert!((grid.residual - loose.residual).abs() < 1e-9 * grid.limits);
}

/// The device's clamp is the CPU's (`shaders/tethers.wgsl`, the twin of `clamp_one`):
/// the soft cloth, held by two anchors against its slack every substep, steps alike on both
/// back ends, each frame one submit with the tethers on the device; the same cloth on the
/// device without them ends far from both.
#[cfg(feature = "gpu")]
#[test]
fn the_device_clamps_as_the_cpu_does() {
    if common::gpu_or_skip(harmonic::internals::gpu::GpuContext::shared(true)).is_none() {
        return;
    }
    let tethers = ", tethers: Some((slack: 0.05, anchors: 2))";
    let mut cpu = Simulation::from_scene(&soft_cloth(tethers, "cpu")).unwrap();
    let mut gpu = Simulation::from_scene(&soft_cloth(tethers, "gpu")).unwrap();
    let mut free = Simulation::from_scene(&soft_cloth("", "gpu")).unwrap();
    let on = (gpu.schedule().stages().iter())
        .find(|s| s.kind == StageKind::Tethers)
        .map(|s| s.on);
    assert_eq!(on, Some(harmonic::Backend::Gpu), "{}", gpu.schedule());
    let mut apart: f64 = 0.0;
    for frame in 0..60 {
        cpu.step().unwrap();
        let before = gpu.gpu_solver().unwrap().submits();
        gpu.step().unwrap();
        let made = gpu.gpu_solver().unwrap().submits() - before;
        assert_eq!(made, 1, "frame {frame}: {}", gpu.schedule());
        free.step().unwrap();
        let d = (cpu.positions().iter().zip(gpu.positions()))
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0, f64::max);
        apart = apart.max(d);
    }
    let untethered = (cpu.positions().iter().zip(free.positions()))
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0, f64::max);
    let (c, g) = (cpu.diagnostics().audit, gpu.diagnostics().audit);
    println!(
        "CPU and device {apart:.2e} m apart at most; untethered {untethered:.2e} m; \
         limits {:.6e} J on the CPU, {:.6e} J on the device",
        c.limits, g.limits
    );
    assert!(untethered > 0.1, "the tethers hold the cloth: {untethered}");
    assert!(apart < 3e-5, "{apart} m");
    assert!((c.limits - g.limits).abs() < 1e-4 * c.limits);
}

/// A sheet made rolled into a half cylinder (radius 0.3 m, 30 rows round it) and pinned along
/// its top edge hangs out straight under gravity: its tethers' rest distances run along it
/// (to the far edge, 30 chords of the circle, 0.9420 m), not straight across (0.6 m, where
/// the tethers would hold its far edge within 0.63 m of the pins, two thirds of its length).
/// Measured: the far edge 0.900 m below the pins after 4 s (its bend springs keep the top
/// rows' turn round); with the straight line's rest distances, 0.598 m.
#[test]
fn a_sheet_made_rolled_hangs_to_its_length_along_it() {
    let (r, cols, rows, width) = (0.3, 9u32, 31u32, 0.4);
    let mut v = Vec::new();
    for k in 0..rows {
        let theta = std::f64::consts::PI * f64::from(k) / f64::from(rows - 1);
        for c in 0..cols {
            let x = width * f64::from(c) / f64::from(cols - 1);
            v.push(format!(
                "({x}, {}, {})",
                2.0 + r * theta.cos(),
                r * theta.sin()
            ));
        }
    }
    let top: Vec<String> = (0..cols).map(|c| c.to_string()).collect();
    let text = format!(
        "Scene(dt: 0.016666666666666666, substeps: 16, integrator: \"symplectic-euler\",
          meshes: [(vertices: [{}], triangles: [{}], mass: 0.2,
            stretch: (frequency: 12.0, damping_ratio: 0.3), bend: Some((frequency: 1.0, damping_ratio: 0.3)),
            pins: [Vertices([{}])], tethers: Some((slack: 0.05, anchors: 1)))])",
        v.join(", "),
        common::ron_triangles(&common::grid_triangles(cols, rows)),
        top.join(", ")
    );
    let scene = Scene::parse(&text, "rolled.ron").unwrap();
    let built = scene.build();
    let along = 30.0 * 2.0 * r * (0.5 * std::f64::consts::PI / 30.0).sin();
    // The far edge's tethers: its rest distance along the sheet.
    let far: Vec<f64> = (built.world.query::<&harmonic::Tethers>().iter())
        .flat_map(|t| t.links.clone())
        .filter(|l| l.0 >= (rows - 1) * cols)
        .map(|l| l.2 / 1.05)
        .collect();
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..240 {
        sim.step().unwrap();
    }
    let x = sim.positions();
    let drop = (0..cols as usize)
        .map(|c| x[c].y - x[((rows - 1) * cols) as usize + c].y)
        .fold(f64::MAX, f64::min);
    println!(
        "far edge {drop} m below the pins; along the sheet {along} m, across {} m",
        2.0 * r
    );
    assert_eq!(far.len(), cols as usize);
    for d in &far {
        assert!((d - along).abs() < 1e-9 * along, "{d} m, not {along} m");
    }
    assert!(drop > 0.9 * along, "{drop} m");
    assert!(drop <= 1.05 * along + 1e-9, "{drop} m");
}
