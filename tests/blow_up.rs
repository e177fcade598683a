//! A run that blows up while staying finite is a failure, not a success: the strain limit
//! reports it as a typed value in `StepStats` and `Diagnostics`, and `harmonic run` exits 2
//! naming the frame, the integrator and h/h_c.

use std::process::Command;

use harmonic::prelude::*;
use harmonic::Failure;

#[cfg(feature = "gpu")]
mod common;

/// A three-particle chain far too stiff for its step: k = 1e6 N/m, dt = 0.1 s, one substep;
/// the energy limit off, so the strain limit is what reports it (`tests/energy_audit.rs`
/// reports it by its energy).
fn stiff_chain(integrator: &str) -> String {
    format!(
        r#"Scene(dt: 0.1, substeps: 1, integrator: "{integrator}", seconds: 2.0, energy_limit: inf,
            ropes: [(start: (0.0, 0.0, 0.0), end: (1.0, 0.0, 0.0), particles: 3, mass: 0.3,
                     spring: (stiffness: 1e6))])"#
    )
}

#[test]
fn a_blow_up_is_reported_at_its_frame() {
    let scene = Scene::parse(&stiff_chain("explicit-euler"), "stiff.ron").unwrap();
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let mut first = None;
    for frame in 1..=20u64 {
        let stats = *sim.step().unwrap();
        if let (None, Some(f)) = (first, stats.failure) {
            first = Some((frame, f));
        }
    }
    let (frame, failure) = first.expect("the chain blows up within 20 frames");
    let Failure::Strain {
        frame: at,
        strain,
        limit,
        integrator,
        step_ratio,
        ..
    } = failure
    else {
        panic!("{failure:?}")
    };
    assert_eq!(at, frame);
    assert!(strain > limit && limit == harmonic::SimConfig::default().strain_limit);
    assert_eq!(integrator, Integrator::ExplicitEuler);
    // ω0 = √(k/μ) = √(1e6/0.05) ≈ 4472 rad/s, h_c = π/ω0 ≈ 7e-4 s: h = 0.1 s is ~142 h_c.
    assert!(
        (step_ratio - 0.1 * (1e6f64 / 0.05).sqrt() / std::f64::consts::PI).abs()
            < 1e-6 * step_ratio
    );
    // Diagnostics keeps the first failure.
    assert_eq!(sim.diagnostics().failure, Some(failure));
    // The same chain stepped safely fails nowhere.
    let mut safe = Scene::parse(&stiff_chain("explicit-euler"), "stiff.ron").unwrap();
    safe.substeps = None;
    safe.dt = 0.001;
    let mut sim = Simulation::from_scene(&safe).unwrap();
    for _ in 0..100 {
        assert_eq!(sim.step().unwrap().failure, None);
    }
    assert_eq!(sim.diagnostics().failure, None);
}

#[test]
fn the_limit_is_configurable_and_can_be_turned_off() {
    let mut scene = Scene::parse(&stiff_chain("explicit-euler"), "stiff.ron").unwrap();
    scene.strain_limit = Some(f64::INFINITY);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..5 {
        assert_eq!(sim.step().unwrap().failure, None);
    }
    let bad =
        stiff_chain("explicit-euler").replace("seconds: 2.0,", "seconds: 2.0, strain_limit: 0.0,");
    assert!(Scene::parse(&bad, "bad.ron").is_err());
    let config = SimConfig {
        strain_limit: f64::NAN,
        ..SimConfig::default()
    };
    assert!(Simulation::new(hecs::World::new(), config).is_err());
}

#[test]
fn stretch_is_tension_and_compression_is_apart() {
    // Two particles 1 m apart on a 2 m spring: compressed by half, not stretched at all.
    let text = r#"Scene(dt: 0.01, gravity: (0.0, 0.0, 0.0),
        particles: [(position: (0.0, 0.0, 0.0), mass: 1.0), (position: (1.0, 0.0, 0.0), mass: 1.0)],
        springs: [(a: 0, b: 1, stiffness: 1.0, rest_length: 2.0)])"#;
    let sim = Simulation::from_scene(&Scene::parse(text, "c.ron").unwrap()).unwrap();
    let d = sim.diagnostics();
    assert_eq!((d.max_strain, d.max_compression), (0.0, 0.5));
}

#[test]
fn harmonic_run_exits_2_on_a_blow_up() {
    let dir = std::env::temp_dir().join(format!("harmonic-blow-up-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let chain = dir.join("stiff_chain.ron");
    std::fs::write(&chain, stiff_chain("explicit-euler")).unwrap();
    // A 16×16 cloth with k = 1e5 N/m at dt = 0.05 s on one substep of the closed form.
    let cloth = dir.join("stiff_cloth.ron");
    std::fs::write(
        &cloth,
        r#"Scene(dt: 0.05, substeps: 1, integrator: "harmonic", seconds: 2.0,
            cloths: [(origin: (-0.5, 1.0, 0.0), size: (1.0, 1.0), resolution: (16, 16),
                      plane: Vertical, mass: 1.0, structural: (stiffness: 1e5),
                      shear: Some((stiffness: 1e5)), pins: [TopLeft, TopRight])])"#,
    )
    .unwrap();
    for (path, integrator) in [(&chain, "explicit-euler"), (&cloth, "harmonic")] {
        let out = Command::new(env!("CARGO_BIN_EXE_harmonic"))
            .args(["run", path.to_str().unwrap()])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{}: {stderr}", path.display());
        // The cloth is caught by the energy it makes, before any spring passes the strain limit.
        let limit = if path == &cloth {
            "energy limit"
        } else {
            "strain limit"
        };
        for needle in [
            "run failed at frame",
            limit,
            integrator,
            "h/h_c",
            "lower dt",
        ] {
            assert!(
                stderr.contains(needle),
                "{}: lacks {needle:?}: {stderr}",
                path.display()
            );
        }
    }
}

#[test]
fn xpbds_automatic_substeps_resolve_a_stiff_damped_chain() {
    // 20 links, 0.5 kg, 20 kN/m with dampers, released horizontally at 60 Hz. With one
    // substep (no stability limit to go by) XPBD stretched it 462 % and ended 252 J above
    // its start; a damped swing can only lose energy.
    let text = r#"Scene(dt: 0.016666666666666666, integrator: "xpbd",
        ropes: [(start: (0.0, 0.0, 0.0), end: (1.0, 0.0, 0.0), particles: 21, mass: 0.5,
                 spring: (stiffness: 20000.0, damping: 0.5), pin_start: true)])"#;
    let mut sim = Simulation::from_scene(&Scene::parse(text, "xpbd.ron").unwrap()).unwrap();
    assert!(sim.config().substeps > 1, "{:?}", sim.step_choice());
    let start = sim.diagnostics().energy;
    let mut stretch: f64 = 0.0;
    for _ in 0..600 {
        sim.step().unwrap();
        stretch = stretch.max(sim.diagnostics().max_strain);
    }
    let end = sim.diagnostics().energy;
    assert!(stretch < 0.1, "stretched {:.1} %", 100.0 * stretch);
    assert!(end < start, "energy {start} J → {end} J");
}

/// On the device the state comes back every frame; the strain check reads it there.
#[cfg(feature = "gpu")]
#[test]
fn a_blow_up_on_the_gpu_is_reported_too() {
    use harmonic::internals::gpu::GpuContext;
    if common::gpu_or_skip(GpuContext::shared(true)).is_none() {
        return;
    }
    let mut scene = Scene::parse(&stiff_chain("explicit-euler"), "stiff.ron").unwrap();
    scene.backend = Some("gpu".into());
    let mut sim = Simulation::from_scene(&scene).unwrap();
    assert_eq!(sim.backend(), harmonic::Backend::Gpu);
    let failed = (0..20).find_map(|_| sim.step().unwrap().failure);
    assert!(
        matches!(
            failed,
            Some(Failure::Strain {
                integrator: Integrator::ExplicitEuler,
                ..
            })
        ),
        "{failed:?}"
    );
}

#[test]
fn a_spring_between_two_pins_is_not_the_cloths_stretch() {
    // Pinned 20 m apart on a 1 m spring: the game's doing, not a blow-up.
    let text = r#"Scene(dt: 0.01,
        particles: [(position: (0.0, 0.0, 0.0), mass: 1.0, pinned: true),
                    (position: (20.0, 0.0, 0.0), mass: 1.0, pinned: true),
                    (position: (20.0, -1.0, 0.0), mass: 1.0)],
        springs: [(a: 0, b: 1, stiffness: 10.0, rest_length: 1.0), (a: 1, b: 2, stiffness: 10.0)])"#;
    let mut sim = Simulation::from_scene(&Scene::parse(text, "pins.ron").unwrap()).unwrap();
    for _ in 0..10 {
        assert_eq!(sim.step().unwrap().failure, None);
    }
    assert!(sim.diagnostics().max_strain < 1.0);
    assert!(harmonic::scene::Limits::DEFAULT
        .frames(1.0, f64::NAN)
        .is_err());
    assert!(harmonic::scene::Limits::DEFAULT.frames(1.0, -1.0).is_err());
    assert_eq!(harmonic::scene::Limits::DEFAULT.frames(1.0, 0.01), Ok(100));
}

#[test]
fn the_strain_check_reads_every_spring_of_a_grid() {
    use harmonic::internals::metrics::stretch;
    // A stretched, folded cloth with a rope, kept as a grid (symplectic Euler) and expanded
    // (harmonic-gs): the check's walk over the grid's links finds what the springs one by one
    // give, large and parallel or small and serial.
    for (n, integrator) in [
        (6, "symplectic-euler"),
        (6, "harmonic-gs"),
        (80, "symplectic-euler"),
    ] {
        let text = format!(
            r#"Scene(dt: 0.01, integrator: "{integrator}", substeps: 4,
                cloths: [(origin: (-0.5, 1.0, 0.0), size: (1.0, 1.0), resolution: ({n}, {n}),
                          plane: Vertical, mass: 0.2, structural: (frequency: 5.0),
                          shear: Some((frequency: 5.0)), bend: Some((frequency: 2.0)),
                          pins: [TopLeft, TopRight])],
                ropes: [(start: (1.0, 1.0, 0.0), end: (1.0, 0.2, 0.0), particles: 6, mass: 0.1,
                         spring: (frequency: 5.0))])"#
        );
        let mut sim = Simulation::from_scene(&Scene::parse(&text, "s.ron").unwrap()).unwrap();
        for _ in 0..30 {
            sim.step().unwrap();
        }
        let p = sim.packed();
        let (mut t, mut c) = (0.0f64, 0.0f64);
        for s in p.all_springs().filter(|s| s.mu.is_finite()) {
            let e = p.stretch(&s) / s.rest;
            t = t.max(e);
            c = c.max(-e);
        }
        let got = stretch(p);
        assert!(t > 0.0 && c > 0.0, "{integrator} {n}: {t} {c}");
        assert_eq!((got.tension, got.compression), (t, c), "{integrator} {n}");
        // The worst spring is one of those at that stretch, the smallest pair among them.
        let worst = harmonic::internals::metrics::most_stretched(p, 0.0025).unwrap();
        let at_max: Vec<(usize, usize)> = p
            .all_springs()
            .filter(|s| s.mu.is_finite() && p.stretch(s) / s.rest == t)
            .map(|s| (s.a as usize, s.b as usize))
            .collect();
        assert_eq!(worst.strain, t, "{integrator} {n}");
        assert_eq!(Some(&worst.ends), at_max.iter().min(), "{integrator} {n}");
    }
}

#[test]
fn the_per_frame_check_agrees_with_the_stretch() {
    use harmonic::internals::metrics::{beyond, stretch};
    // A cloth hanging under its own weight on soft springs, kept as a grid and expanded:
    // `beyond` answers exactly whether the stretch passes the limit, on either side of it.
    for integrator in ["symplectic-euler", "harmonic-gs"] {
        let text = format!(
            r#"Scene(dt: 0.01, integrator: "{integrator}", substeps: 8,
                cloths: [(origin: (-0.5, 1.0, 0.0), size: (1.0, 1.0), resolution: (70, 70),
                          plane: Vertical, mass: 0.2, structural: (frequency: 3.0),
                          shear: Some((frequency: 3.0)), pins: [TopLeft, TopRight])])"#
        );
        let mut sim = Simulation::from_scene(&Scene::parse(&text, "s.ron").unwrap()).unwrap();
        for _ in 0..40 {
            sim.step().unwrap();
        }
        let t = stretch(sim.packed()).tension;
        assert!(t > 0.01, "{integrator}: {t}");
        assert!(beyond(sim.packed(), 0.99 * t), "{integrator}");
        assert!(!beyond(sim.packed(), 1.01 * t), "{integrator}");
    }
}
