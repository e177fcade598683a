//! Stretch limits (`stretch_limit:` per cloth): springs held within `(1 + stretch)` of their
//! rest lengths, checked against a hanging mass's rest at its limit (a closed form), the
//! springs' lengths measured here, the momentum the projections must keep, and both back ends.

use harmonic::prelude::*;
use harmonic::{Particle, SceneIndex, StageKind};

mod common;

/// A 16×16 cloth of 1 m and 0.5 kg with springs of `hz`, hanging from its top corners, with
/// `extra` (RON) added to the cloth.
fn cloth(hz: f64, extra: &str, backend: &str) -> Scene {
    cloth_of(16, hz, extra, backend)
}

/// The cloth at `n`×`n` particles.
fn cloth_of(n: u32, hz: f64, extra: &str, backend: &str) -> Scene {
    Scene::parse(
        &format!(
            "Scene(dt: 0.016666666666666666, substeps: 8, integrator: \"symplectic-euler\", backend: \"{backend}\",
              cloths: [(origin: (-0.5, 1.0, 0.0), size: (1.0, 1.0), resolution: ({n}, {n}), mass: 0.5,
                structural: (frequency: {hz}, damping_ratio: 0.2), shear: Some((frequency: {hz}, damping_ratio: 0.2)),
                pins: [TopLeft, TopRight] {extra})])"
        ),
        "soft.ron",
    )
    .unwrap()
}

/// The worst stretch of the 16×16 cloth's structural springs (rest 1/15 m), a share of rest.
fn worst_stretch(x: &[DVec3]) -> f64 {
    let rest = 1.0 / 15.0;
    let mut worst: f64 = 0.0;
    for r in 0..16 {
        for c in 0..16 {
            let i = r * 16 + c;
            if c + 1 < 16 {
                worst = worst.max((x[i + 1] - x[i]).length() / rest - 1.0);
            }
            if r + 1 < 16 {
                worst = worst.max((x[i + 16] - x[i]).length() / rest - 1.0);
            }
        }
    }
    worst
}

/// The worst stretch over `frames` frames, and the run's audit.
fn run(scene: &Scene, frames: usize) -> (f64, harmonic::EnergyAudit, bool) {
    let mut sim = Simulation::from_scene(scene).unwrap();
    let mut worst: f64 = 0.0;
    for _ in 0..frames {
        sim.step().unwrap();
        worst = worst.max(worst_stretch(sim.positions()));
    }
    let failed = sim.diagnostics().failure.is_some();
    (worst, sim.diagnostics().audit, failed)
}

/// The soft cloth stretches its springs by more than half without a limit; with one of 10 %
/// the worst spring over 120 frames stays near 10 %, nearer with more passes, and the
/// projections only take energy out.
#[test]
fn a_stretch_limit_holds_a_soft_cloth_near_its_stretch() {
    let (free, _, _) = run(&cloth(6.0, "", "cpu"), 120);
    println!("no limit: the worst spring stretched {:.1} %", 100.0 * free);
    assert!(free > 0.5, "the soft cloth should stretch: {free}");
    let mut last = f64::INFINITY;
    for passes in [1, 4, 16, 64] {
        let limit = format!(", stretch_limit: Some((stretch: 0.1, passes: {passes}))");
        let (worst, audit, failed) = run(&cloth(6.0, &limit, "cpu"), 120);
        assert!(!failed, "{passes} passes");
        println!(
            "{passes} passes: the worst spring stretched {:.3} %; the limits took {:.4e} J, \
             residual {:+.3e} J of {:.3e} J",
            100.0 * worst,
            audit.limits,
            audit.residual,
            audit.scale
        );
        assert!(worst < free, "{passes} passes: {worst}");
        assert!(
            worst <= last + 1e-12,
            "more passes hold better: {worst} > {last}"
        );
        assert!(audit.limits > 0.0, "{passes} passes: {}", audit.limits);
        // Numerical damping only: symplectic Euler's step under gravity loses ½ m g² h² where
        // a limit holds a particle (see a_hanging_mass_rests_at_its_limit); nothing is made.
        assert!(
            audit.residual < 1e-6 * audit.scale && audit.residual > -0.05 * audit.scale,
            "{passes} passes: the books close: {audit:?}"
        );
        last = worst;
    }
    assert!(last < 0.11, "64 passes hold within 11 %: {last}");
}

/// A 2×2 cloth pinned along its top edge is two masses, each on one vertical spring: at rest
/// it stretches `m g / k` = 0.5 m; limited to 10 %, each mass rests at exactly 1.1 m below
/// its pin, and the books close.
#[test]
fn a_hanging_mass_rests_at_its_limit() {
    let scene = |limit: &str| {
        Scene::parse(
            &format!(
                "Scene(dt: 0.01, substeps: 20, seconds: 10.0, integrator: \"symplectic-euler\",
                  cloths: [(origin: (0.0, 0.0, 0.0), size: (1.0, 1.0), resolution: (2, 2), mass: 0.4,
                    structural: (stiffness: 1.962, damping: 0.3), pins: [TopEdge] {limit})])"
            ),
            "two.ron",
        )
        .unwrap()
    };
    let g = 9.81;
    for (limit, drop) in [
        ("", 1.0 + 0.1 * g / 1.962),
        (", stretch_limit: Some(())", 1.1),
    ] {
        let mut sim = Simulation::from_scene(&scene(limit)).unwrap();
        assert_eq!(
            sim.schedule().has(StageKind::StretchLimit),
            !limit.is_empty()
        );
        for _ in 0..1000 {
            sim.step().unwrap();
        }
        let x = sim.positions();
        for i in [2, 3] {
            let below = x[i - 2].y - x[i].y;
            println!("{limit:?}: mass {i} rests {below:.12} m below its pin");
            assert!(
                (below - drop).abs() < 1e-6,
                "{limit:?}: {below} against {drop}"
            );
        }
        let a = sim.diagnostics().audit;
        println!(
            "{limit:?}: dampers {:.6e} J, limits {:.6e} J, residual {:+.3e} J",
            a.damping, a.limits, a.residual
        );
        // Symplectic Euler's own error: a step under gravity alone loses ½ m g² h², which a
        // mass held by its limit meets every substep (the projection then takes out the rest
        // of the step's move, booked as limits).
        let (m, h) = (0.1, 0.01 / 20.0);
        let bound = 2.0 * 20_000.0 * 0.5 * m * g * g * h * h;
        assert!(a.residual <= 1e-9 && a.residual >= -bound, "{a:?}");
        // E at rest against the closed form: the masses' fall less their springs' energy.
        let k = 1.962;
        let lost = 2.0 * (m * g * (drop - 1.0) - 0.5 * k * (drop - 1.0).powi(2));
        println!("lost {:.9} J against {lost:.9} J", a.start - a.energy);
        assert!((a.start - a.energy - lost).abs() < 1e-6, "{a:?}");
        if limit.is_empty() {
            assert_eq!(a.limits, 0.0);
            assert!(a.residual.abs() < 1e-6 * a.scale, "{a:?}");
        } else {
            assert!(a.limits > 0.0);
        }
    }
}

/// The projections move each pair's ends in proportion to their inverse masses: a free cloth
/// without gravity, some particles pulled out, keeps its momentum to rounding.
#[test]
fn the_projections_keep_momentum() {
    let scene = Scene::parse(
        "Scene(dt: 0.01, substeps: 4, gravity: (0.0, 0.0, 0.0), integrator: \"symplectic-euler\",
          cloths: [(origin: (0.0, 0.0, 0.0), size: (1.0, 1.0), resolution: (8, 8), mass: 1.0,
            structural: (frequency: 2.0), shear: Some((frequency: 2.0)), velocity: (0.3, 0.0, 0.1),
            stretch_limit: Some((stretch: 0.05, passes: 8)))])",
        "free.ron",
    )
    .unwrap();
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for (p, i) in sim.world_mut().query_mut::<(&mut Particle, &SceneIndex)>() {
        if i.0 % 5 == 0 {
            p.position += DVec3::new(0.1, -0.2, 0.15) * f64::from(i.0 % 3);
            p.velocity += DVec3::new(-1.0, 0.5, 2.0) * f64::from(i.0 % 7) / 7.0;
        }
    }
    let momentum = |sim: &Simulation| -> DVec3 { sim.velocities().iter().sum::<DVec3>() / 64.0 };
    sim.step().unwrap();
    let p0 = momentum(&sim);
    let mut moved = 0.0;
    for _ in 0..60 {
        sim.step().unwrap();
        moved += sim.diagnostics().audit.limits;
    }
    let p1 = momentum(&sim);
    println!("momentum {p0:?} → {p1:?}; the limits took {moved:.3e} J");
    assert!(sim.diagnostics().audit.limits > 0.0);
    assert!((p1 - p0).length() < 1e-12, "{p0} → {p1}");
}

/// The stage runs in a fixed order, its blocks side by side (a 96×96 cloth: three blocks of
/// particles and the springs between them): 1 and 2 threads give the same bits.
#[test]
fn a_stretch_limit_is_the_same_on_1_and_2_threads() {
    let limit = ", stretch_limit: Some((stretch: 0.05, passes: 4))";
    let scene = cloth_of(96, 60.0, limit, "cpu");
    let runs: Vec<(Vec<DVec3>, Vec<DVec3>, f64)> = [1, 2]
        .map(|threads| {
            common::on_threads(threads, || {
                let mut sim = Simulation::from_scene(&scene).unwrap();
                for _ in 0..10 {
                    sim.step().unwrap();
                }
                let a = sim.diagnostics().audit;
                (
                    sim.positions().to_vec(),
                    sim.velocities().to_vec(),
                    a.limits,
                )
            })
        })
        .into();
    assert!(runs[0].2 > 0.0, "the limit works: {}", runs[0].2);
    assert!(runs[0] == runs[1]);
}

/// On the GPU the stage runs on the host between the device's substeps: the same cloth as the
/// CPU's to the device's f32.
#[test]
fn a_stretch_limit_runs_beside_the_gpu_springs() {
    if common::gpu_or_skip(harmonic::internals::gpu::GpuContext::shared(true)).is_none() {
        return;
    }
    let limit = ", stretch_limit: Some((stretch: 0.1, passes: 4))";
    let mut cpu = Simulation::from_scene(&cloth(6.0, limit, "cpu")).unwrap();
    let mut gpu = Simulation::from_scene(&cloth(6.0, limit, "gpu")).unwrap();
    assert!(
        gpu.schedule().has(StageKind::StretchLimit),
        "{}",
        gpu.schedule()
    );
    let mut apart: f64 = 0.0;
    for _ in 0..60 {
        cpu.step().unwrap();
        gpu.step().unwrap();
        let d = (cpu.positions().iter().zip(gpu.positions()))
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0, f64::max);
        apart = apart.max(d);
    }
    let (c, g) = (
        worst_stretch(cpu.positions()),
        worst_stretch(gpu.positions()),
    );
    println!("CPU and GPU up to {apart:.3e} m apart; worst stretch {c:.5} and {g:.5}");
    assert!(apart < 1e-4, "{apart}");
    assert!(gpu.diagnostics().audit.limits > 0.0);
}

/// A limit the springs never reach changes nothing, bit for bit.
#[test]
fn a_slack_limit_changes_nothing() {
    let mut free = Simulation::from_scene(&cloth(30.0, "", "cpu")).unwrap();
    let limit = ", stretch_limit: Some((stretch: 1.0, passes: 2))";
    let mut slack = Simulation::from_scene(&cloth(30.0, limit, "cpu")).unwrap();
    for _ in 0..60 {
        free.step().unwrap();
        slack.step().unwrap();
    }
    assert!(worst_stretch(free.positions()) < 1.0);
    assert!(slack.schedule().has(StageKind::StretchLimit));
    assert_eq!(free.positions(), slack.positions());
    assert_eq!(free.velocities(), slack.velocities());
    assert_eq!(slack.diagnostics().audit.limits, 0.0);
}

#[test]
fn bad_stretch_limits_are_refused_by_name() {
    for (limit, message) in [
        (
            "(stretch: -0.1)",
            "cloths[0].stretch_limit: stretch must be finite and ≥ 0, got -0.1",
        ),
        (
            "(passes: 0)",
            "cloths[0].stretch_limit: passes must be 1 to 64, got 0",
        ),
        (
            "(passes: 65)",
            "cloths[0].stretch_limit: passes must be 1 to 64, got 65",
        ),
    ] {
        let text = format!(
            "Scene(dt: 0.01, cloths: [(origin: (0.0, 0.0, 0.0), size: (1.0, 1.0),
              resolution: (4, 4), mass: 1.0, structural: (frequency: 5.0),
              stretch_limit: Some({limit}))])"
        );
        let e = Scene::parse(&text, "bad.ron").unwrap_err().to_string();
        assert!(e.contains(message), "{e}");
    }
}
