//! The GPU back end on an adapter: GPU and CPU kernels agreeing on random scenes and cloth
//! grids, device contacts matching the CPU stage, and every shipped scene finite on the GPU
//! (the shaders and layouts without an adapter: `gpu_shaders.rs`).
//!
//! GPU tests skip only when no adapter at all exists, and fail instead when
//! `HARMONIC_REQUIRE_GPU` is set (CI sets it: it has Mesa's lavapipe).
#![cfg(feature = "gpu")]

mod common;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use harmonic::internals::gpu::{GpuContext, Kernel};
use harmonic::prelude::*;
use harmonic::{Backend, GpuError, SimError};
use hecs::World;

fn context() -> Option<Arc<GpuContext>> {
    common::gpu_or_skip(GpuContext::shared(true))
}

/// A random blob of particles and springs: masses over three decades, about a tenth pinned,
/// each spring in one of the damping regimes (undamped, under-, critically, over-damped).
/// Returns the World and the largest `ω0` and `ζ` of any spring.
fn random_scene(rng: &mut fastrand::Rng, n: usize, regime: Option<usize>) -> (World, f64, f64) {
    let mut world = World::new();
    let mut ids = Vec::with_capacity(n);
    let mut masses = Vec::with_capacity(n);
    let mut xs = Vec::with_capacity(n);
    for i in 0..n {
        let x = DVec3::new(rng.f64(), rng.f64(), rng.f64()) * 2.0 + DVec3::Y * 1.5;
        let v = (DVec3::new(rng.f64(), rng.f64(), rng.f64()) - 0.5) * 0.4;
        let mass = 10f64.powf(rng.f64() * 3.0 - 1.5);
        let e = world.spawn((
            Particle {
                position: x,
                velocity: v,
                mass,
            },
            harmonic::SceneIndex(i as u32),
        ));
        if i > 0 && rng.f64() < 0.1 {
            world.insert_one(e, Pin).expect("spawned");
        }
        ids.push(e);
        masses.push(mass);
        xs.push(x);
    }
    let mut omega_max: f64 = 0.0;
    let mut zeta_max: f64 = 0.0;
    for a in 0..n {
        for _ in 0..3 {
            let b = rng.usize(0..n);
            if a == b {
                continue;
            }
            let len = (xs[b] - xs[a]).length();
            let rest = len * (0.8 + 0.4 * rng.f64());
            let stiffness = 10f64.powf(1.0 + 2.0 * rng.f64());
            let mu = masses[a] * masses[b] / (masses[a] + masses[b]);
            let zeta = match regime.unwrap_or_else(|| rng.usize(0..4)) {
                0 => 0.0,
                1 => 0.05 + 0.9 * rng.f64(),
                2 => 1.0,
                _ => 1.1 + 4.0 * rng.f64(),
            };
            omega_max = omega_max.max((stiffness / mu).sqrt());
            zeta_max = zeta_max.max(zeta);
            world.spawn((Spring {
                a: ids[a],
                b: ids[b],
                rest_length: rest,
                stiffness,
                damping: 2.0 * zeta * (stiffness * mu).sqrt(),
            },));
        }
    }
    (world, omega_max, zeta_max)
}

/// Runs `frames` frames of `substeps` each on both back ends; returns the largest position
/// difference seen at any frame end, the scene's extent, and the farthest any particle ended
/// from where it started (on the CPU).
fn cpu_against_gpu(
    world_cpu: World,
    world_gpu: World,
    config: SimConfig,
    frames: usize,
) -> Result<(f64, f64, f64), SimError> {
    let mut cpu = Simulation::new(
        world_cpu,
        SimConfig {
            backend: Backend::Cpu,
            ..config
        },
    )?;
    let mut gpu = Simulation::new(
        world_gpu,
        SimConfig {
            backend: Backend::Gpu,
            ..config
        },
    )?;
    assert_eq!(gpu.backend(), Backend::Gpu);
    gpu.gpu_solver().expect("on the GPU").poison();
    let start = cpu.positions().to_vec();
    let mut worst: f64 = 0.0;
    for _ in 0..frames {
        cpu.step()?;
        gpu.step()?;
        for (a, b) in cpu.positions().iter().zip(gpu.positions()) {
            worst = worst.max((*a - *b).length());
        }
    }
    let extent = cpu
        .positions()
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs().max_element()));
    let travel = cpu
        .positions()
        .iter()
        .zip(&start)
        .fold(0.0f64, |m, (x, x0)| m.max((*x - *x0).length()));
    Ok((worst, extent, travel))
}

/// Ten substeps a frame, each a tenth of the network's `h_c` (at least `omega`'s), less with
/// damping ratio `zeta`: well inside every integrator's stable region (damping shrinks the
/// explicit ones'). Explicit Euler, unstable on undamped springs at any h, a tenth of that
/// again, so its growth over a run stays below 20 %.
fn parity_config(world: &World, omega: f64, zeta: f64, integrator: Integrator) -> SimConfig {
    let packed = harmonic::internals::buffers::Packed::gather(world).expect("valid");
    let omega = harmonic::internals::step_control::network_frequency(&packed, 200).max(omega);
    let mut h = 0.1 * std::f64::consts::PI / omega / (1.0 + zeta);
    if integrator == Integrator::ExplicitEuler {
        h /= 10.0;
    }
    SimConfig {
        dt: 10.0 * h,
        substeps: 10,
        auto_substeps: false,
        gravity: DVec3::new(0.0, -9.81, 0.0),
        integrator,
        exact_displacement: false,
        backend: Backend::Cpu,
        ..SimConfig::default()
    }
}

/// f32 against f64: each substep rounds positions to about ε₃₂·extent, and over a run those
/// errors add up at worst linearly, so the bound is `4 ε₃₂ · extent · substeps` (≈ 2e-4 m for
/// 300 substeps of a 3 m scene). Measured on lavapipe: ≤ 7e-6 m with damping, ≤ 6.6e-5 m
/// undamped (nothing damps the rounding there).
fn parity_tolerance(extent: f64, substeps: usize) -> f64 {
    4.0 * f32::EPSILON as f64 * extent * substeps as f64
}
/// The scenes start within 4 m of the origin; a state beyond this has blown up.
const BOUNDED: f64 = 10.0;

#[test]
fn gpu_matches_cpu_on_random_scenes() {
    let Some(_ctx) = context() else { return };
    let seed = common::seed();
    let mut rng = fastrand::Rng::with_seed(seed);
    let integrators = Kernel::supported().collect::<Vec<_>>();
    let mut report = Vec::new();
    for trial in 0..integrators.len() * 4 {
        let integrator = integrators[trial % integrators.len()];
        let regime = Some(trial / integrators.len());
        let n = 20 + rng.usize(0..60);
        let scene_seed = rng.u64(..);
        let (world_cpu, omega, zeta) =
            random_scene(&mut fastrand::Rng::with_seed(scene_seed), n, regime);
        let (world_gpu, ..) = random_scene(&mut fastrand::Rng::with_seed(scene_seed), n, regime);
        let config = parity_config(&world_cpu, omega, zeta, integrator);
        let (worst, extent, _) = cpu_against_gpu(world_cpu, world_gpu, config, 30)
            .unwrap_or_else(|e| panic!("seed {seed}, trial {trial} ({integrator}): {e}"));
        let tolerance = parity_tolerance(extent, 300);
        let ok = worst <= tolerance && extent < BOUNDED;
        report.push(format!(
            "{} trial {trial}: {integrator}, regime {regime:?}, {n} particles: max |Δx| {worst:.2e} m (tolerance {tolerance:.2e}), extent {extent:.2} m",
            if ok { "ok  " } else { "FAIL" }
        ));
    }
    let report = report.join("\n");
    assert!(
        !report.contains("FAIL"),
        "seed {seed} (HARMONIC_SEED={seed} replays it); bounded by {BOUNDED} m:\n{report}"
    );
    eprintln!("seed {seed}\n{report}");
}

/// Two cloths kept whole as grids (symplectic and explicit Euler and the closed form step them
/// so on both back ends; the closed form's springs at pins and uneven masses go to the device
/// as extra springs, as the CPU pass corrects them one by one), one square, one not, with uneven masses, two pins each and a short rope of loose
/// springs hung from a cloth particle (so a grid particle also gathers springs from the CSR
/// list), every free particle started with its own velocity so the springs work from the
/// first substep: the GPU's `grid_pass` against the CPU grid pass, damped and undamped.
///
/// Positions are compensated pairs, so the f32 rounding is relative to the motion, not to the
/// coordinates: the bound is `4 ε₃₂ · substeps · travel` (travel: the farthest any particle
/// moves). Measured on lavapipe: 20–65× inside it; a 1 % error in the grid springs' force
/// is 80–130× outside it.
#[test]
fn cloth_grids_on_the_gpu_match_the_cpu_grid_pass() {
    let Some(_ctx) = context() else { return };
    let world = |damping: f64| {
        let mut scene = harmonic::internals::hanging_cloth(12);
        let mut second = scene.cloths[0].clone();
        second.origin = [1.0, 1.2, 0.3];
        second.resolution = (9, 7);
        scene.cloths.push(second);
        for c in &mut scene.cloths {
            for spec in [Some(&mut c.structural), c.shear.as_mut(), c.bend.as_mut()]
                .into_iter()
                .flatten()
            {
                spec.damping = Some(damping);
            }
        }
        let mut world = scene.build().world;
        let mut attach = None;
        let mut count = 0;
        let pinned: Vec<hecs::Entity> = world
            .query::<(hecs::Entity, &Pin)>()
            .iter()
            .map(|(e, _)| e)
            .collect();
        for (e, p, i) in world.query_mut::<(hecs::Entity, &mut Particle, &harmonic::SceneIndex)>() {
            p.mass *= 1.0 + f64::from(i.0 % 5) * 0.4;
            if !pinned.contains(&e) {
                let k = f64::from(i.0);
                p.velocity = 0.3 * DVec3::new((1.7 * k).sin(), (2.3 * k).cos(), (0.7 * k).sin());
            }
            count += 1;
            if i.0 == 12 * 11 + 5 {
                attach = Some((e, p.position));
            }
        }
        let (mut prev, at) = attach.expect("cloth particle");
        for k in 1..=3u32 {
            let e = world.spawn((
                Particle {
                    position: at - DVec3::Y * 0.05 * f64::from(k),
                    velocity: DVec3::ZERO,
                    mass: 0.01,
                },
                harmonic::SceneIndex(count + k - 1),
            ));
            world.spawn((Spring {
                a: prev,
                b: e,
                rest_length: 0.05,
                stiffness: 50.0,
                damping: damping * 0.1,
            },));
            prev = e;
        }
        world
    };
    let mut report = Vec::new();
    let integrators = [
        Integrator::SymplecticEuler,
        Integrator::ExplicitEuler,
        Integrator::Harmonic,
    ];
    for integrator in integrators {
        for damping in [0.0, 0.02] {
            let probe = world(damping);
            let config = parity_config(&probe, 0.0, 0.0, integrator);
            let frames = if integrator == Integrator::ExplicitEuler {
                10
            } else {
                30
            };
            let on_gpu = SimConfig {
                backend: Backend::Gpu,
                ..config
            };
            let mut gpu = Simulation::new(probe, on_gpu).expect("GPU simulation");
            gpu.step().expect("step");
            if integrator.runs_on_gpu_grids() {
                // The GPU really keeps the grids whole and specialises to them.
                assert_eq!(gpu.packed().topology.grids.len(), 2);
                assert_eq!(gpu.packed().springs.len(), 3, "only the rope one by one");
                let solver = gpu.gpu_solver().expect("on the GPU");
                assert!(solver.specialisation().expect("uploaded").grids);
                assert_eq!(
                    solver.specialisation().expect("uploaded").rate,
                    // The closed form responds to δ̇ even undamped.
                    damping != 0.0 || integrator == Integrator::Harmonic
                );
            } else {
                unreachable!("{integrator} steps cloth grids on both back ends");
            }
            let (worst, extent, travel) =
                cpu_against_gpu(world(damping), world(damping), config, frames).expect("steps");
            let tolerance = 4.0 * f32::EPSILON as f64 * (frames * 10) as f64 * travel;
            let ok = worst <= tolerance && extent < BOUNDED;
            report.push(format!(
                "{} {integrator}, damping {damping}: max |Δx| {worst:.2e} m (tolerance {tolerance:.2e}), extent {extent:.2} m",
                if ok { "ok  " } else { "FAIL" }
            ));
        }
    }
    let report = report.join("\n");
    assert!(!report.contains("FAIL"), "{report}");
    eprintln!("{report}");
}

/// The compensated position: a particle falling from 100 m at h = 5e-5 s moves less than half an
/// f32 ulp of 100 (3.8e-6 m) per step for its first 155 steps; plain f32 positions would not
/// move then and would round every later step.
#[test]
fn a_small_step_at_height_still_moves_the_particle() {
    let Some(_ctx) = context() else { return };
    let mut world = World::new();
    world.spawn((Particle {
        position: DVec3::new(0.0, 100.0, 0.0),
        velocity: DVec3::ZERO,
        mass: 1.0,
    },));
    let h = 5e-5;
    let substeps = 100u32;
    let config = SimConfig {
        dt: h * substeps as f64,
        substeps,
        auto_substeps: false,
        backend: Backend::Gpu,
        ..SimConfig::default()
    };
    let mut sim = Simulation::new(world, config).expect("GPU simulation");
    for _ in 0..10 {
        sim.step().expect("finite");
    }
    // Symplectic Euler from rest: y_n = y0 − g h² n(n+1)/2.
    let n = 1000.0;
    let expected = 100.0 - 9.81 * h * h * n * (n + 1.0) / 2.0;
    let y = sim.positions()[0].y;
    assert!(
        (y - expected).abs() < 1e-6,
        "y = {y}, expected {expected} (drop {:e})",
        100.0 - expected
    );
}

fn scene_files() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let mut files = Vec::new();
    for dir in [root.clone(), root.join("hard")] {
        for e in std::fs::read_dir(&dir).expect("scenes/ exists") {
            let p = e.expect("entry").path();
            if p.extension().is_some_and(|e| e == "ron") {
                files.push(p);
            }
        }
    }
    files.sort();
    files
}

#[test]
fn every_shipped_scene_runs_finite_on_the_gpu() {
    let Some(_ctx) = context() else { return };
    let files = scene_files();
    assert!(files.len() > 60, "found {} scenes", files.len());
    for path in files {
        let scene = Scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
        let built = scene.build();
        let config = SimConfig {
            backend: Backend::Gpu,
            ..built.config
        };
        let mut sim = Simulation::with_props(built.world, config, built.props)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        // Half a simulated second (at least one frame) of every scene.
        let frames = (0.5 / config.dt).ceil().max(1.0) as usize;
        for _ in 0..frames {
            sim.step()
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        }
        assert!(sim.positions().iter().all(|x| x.is_finite()));
    }
}

#[test]
fn integrators_without_a_gpu_kernel_are_a_clear_error() {
    let Some(_ctx) = context() else { return };
    for integrator in Integrator::ALL {
        let (world, ..) = random_scene(&mut fastrand::Rng::with_seed(7), 10, Some(1));
        let config = SimConfig {
            integrator,
            backend: Backend::Gpu,
            auto_substeps: false,
            ..SimConfig::default()
        };
        match (
            Kernel::of(integrator, false),
            Simulation::new(world, config),
        ) {
            (Some(_), Ok(sim)) => assert_eq!(sim.backend(), Backend::Gpu),
            (None, Err(SimError::Gpu(GpuError::NoKernel { integrator: i, .. }))) => {
                assert_eq!(i, integrator)
            }
            (k, r) => panic!("{integrator}: kernel {k:?}, got {:?}", r.err()),
        }
    }
    // Auto falls back to the CPU for them instead.
    let (world, ..) = random_scene(&mut fastrand::Rng::with_seed(7), 10, Some(1));
    let config = SimConfig {
        integrator: Integrator::ImplicitEuler,
        backend: Backend::Auto,
        ..SimConfig::default()
    };
    assert_eq!(
        Simulation::new(world, config)
            .expect("CPU fallback")
            .backend(),
        Backend::Cpu
    );
}

#[test]
fn auto_uses_only_a_hardware_gpu() {
    let (world, ..) = random_scene(&mut fastrand::Rng::with_seed(3), 10, Some(0));
    let config = SimConfig {
        backend: Backend::Auto,
        ..SimConfig::default()
    };
    let sim = Simulation::new(world, config).expect("auto never fails for a lack of GPU");
    let hardware = GpuContext::shared(false).is_ok();
    let expected = if hardware { Backend::Gpu } else { Backend::Cpu };
    assert_eq!(sim.backend(), expected);
    if let Some(adapter) = sim.gpu_adapter() {
        assert!(!adapter.contains("llvmpipe"), "{adapter}");
    }
}

#[test]
fn specialisation_follows_the_scene() {
    let Some(_ctx) = context() else { return };
    // Undamped symplectic Euler without pins: no rate term, no pin test.
    let text = |integrator: &str, damping: f64, pinned: bool| {
        format!(
            "Scene(dt: 0.001, substeps: 1, integrator: \"{integrator}\", backend: \"gpu\",
              particles: [(position: (0.0, 0.0, 0.0), mass: 1.0, pinned: {pinned}),
                          (position: (1.0, 0.0, 0.0), mass: 1.0)],
              springs: [(a: 0, b: 1, stiffness: 100.0, damping: {damping})])"
        )
    };
    let spec = |t: String| {
        let scene = Scene::parse(&t, "inline").expect("valid");
        let mut sim = Simulation::from_scene(&scene).expect("GPU");
        sim.gpu_solver()
            .expect("on the GPU")
            .specialisation()
            .expect("uploaded")
    };
    let s = spec(text("symplectic-euler", 0.0, false));
    assert!(!s.rate && !s.pins && !s.grids, "{s:?}");
    let s = spec(text("symplectic-euler", 1.0, true));
    assert!(s.rate && s.pins, "{s:?}");
    // The harmonic step responds to δ̇ even undamped (q = cos ωh − 1).
    let s = spec(text("harmonic", 0.0, false));
    assert!(s.rate && !s.pins, "{s:?}");
    let s = spec(text("explicit-euler", 0.0, false));
    assert_eq!(s.update, 1);
    // A cloth under symplectic Euler stays a grid on the device; under harmonic-gs it does not.
    let cloth = |integrator: &str| {
        let mut scene = harmonic::internals::hanging_cloth(8);
        scene.integrator = Some(integrator.into());
        scene.backend = Some("gpu".into());
        let mut sim = Simulation::from_scene(&scene).expect("GPU");
        let grids = sim.packed().topology.grids.len();
        let spec = sim.gpu_solver().expect("on the GPU").specialisation();
        (grids, spec.expect("uploaded").grids)
    };
    assert_eq!(cloth("symplectic-euler"), (1, true));
    assert_eq!(cloth("harmonic-gs"), (0, false));
    // The closed form keeps it a grid too (its pins' springs as extra device springs).
    assert_eq!(cloth("harmonic"), (1, true));
}

/// The device contact stage against the CPU's (parry's projections and ray casts): random
/// particles around a ball, a tilted cuboid and a free dynamic ball, slow and fast (the swept
/// test), one substep without springs or gravity. Particles within 1 mm of a decision boundary
/// (the thickness shell, a surface) are not generated: f32 and f64 may decide them apart.
#[test]
fn device_contacts_match_the_cpu_stage() {
    let Some(_ctx) = context() else { return };
    let seed = common::seed();
    let mut rng = fastrand::Rng::with_seed(seed);
    let thickness = 0.01;
    let h = 1.0 / 600.0;
    let bodies = r#"
        (kind: Fixed, shape: Ball(radius: 0.3), position: (0.0, 0.0, 0.0), friction: 0.4),
        (kind: Fixed, shape: Cuboid(half_extents: (0.3, 0.05, 0.2)), position: (1.0, 0.0, 0.0),
         rotation: (0.3, 0.2, 0.5)),
        (kind: Dynamic, shape: Ball(radius: 0.2), position: (-1.0, 0.0, 0.0), mass: 0.5,
         velocity: (0.3, -0.2, 0.1), angular_velocity: (1.0, 2.0, -1.0)),"#;
    // Shapes as parry sees them, to keep generated particles off the boundaries.
    let probe = Scene::parse(
        &format!("Scene(dt: {h}, substeps: Some(1), gravity: (0.0, 0.0, 0.0), bodies: [{bodies}])"),
        "probe",
    )
    .expect("valid");
    let probe = Simulation::from_scene(&probe).expect("builds");
    let colliders: Vec<_> = probe
        .props()
        .expect("props")
        .colliders()
        .iter()
        .map(|(_, c)| (c.shape().clone_dyn(), *c.position()))
        .collect();
    let near_boundary = |x: DVec3| {
        colliders.iter().any(|(shape, pose)| {
            let p = shape.project_point(pose, x.as_vec3(), false);
            let d = (x.as_vec3() - p.point).length() as f64;
            d < 1e-3 || (d - thickness).abs() < 1e-3
        })
    };
    // Distance outside the nearest collider (0 inside).
    let gap = |x: DVec3| {
        colliders
            .iter()
            .map(|(shape, pose)| {
                let p = shape.project_point(pose, x.as_vec3(), false);
                if p.is_inside {
                    0.0
                } else {
                    (x.as_vec3() - p.point).length() as f64
                }
            })
            .fold(f64::MAX, f64::min)
    };
    let centres = [
        DVec3::ZERO,
        DVec3::new(1.0, 0.0, 0.0),
        DVec3::new(-1.0, 0.0, 0.0),
    ];
    let mut particles = String::new();
    let mut count = 0;
    while count < 800 {
        let c = centres[rng.usize(..3)];
        let x = c + DVec3::new(rng.f64() - 0.5, rng.f64() - 0.5, rng.f64() - 0.5) * 0.9;
        let fast = rng.f64() < 0.2;
        let speed = if fast { 30.0 } else { 2.0 };
        let v = DVec3::new(rng.f64() - 0.5, rng.f64() - 0.5, rng.f64() - 0.5) * 2.0 * speed;
        let x1 = x + h * v;
        if near_boundary(x) || near_boundary(x1) || gap(x).min(gap(x1)) > 0.03 {
            continue;
        }
        particles += &format!(
            "(position: ({}, {}, {}), velocity: ({}, {}, {}), mass: {}),",
            x.x,
            x.y,
            x.z,
            v.x,
            v.y,
            v.z,
            0.001 + rng.f64() * 0.01
        );
        count += 1;
    }
    let text = format!(
        "Scene(dt: {h}, substeps: Some(1), gravity: (0.0, 0.0, 0.0), integrator: Some(\"symplectic-euler\"),
               particles: [{particles}], bodies: [{bodies}],
               contact: (thickness: {thickness}, friction: 0.5, kinetic_friction: 0.3, restitution: 0.2))"
    );
    let scene = Scene::parse(&text, "contact_parity").expect("valid");
    let run = |backend| {
        let built = scene.build();
        let config = SimConfig {
            backend,
            ..built.config
        };
        let mut sim = Simulation::with_props(built.world, config, built.props).expect("builds");
        sim.step().expect("finite");
        sim
    };
    let mut cpu = run(Backend::Cpu);
    let mut gpu = run(Backend::Gpu);
    assert!(gpu.contacts_on_gpu(), "balls and cuboids run on the device");
    assert!(!cpu.contacts_on_gpu());
    let (sc, sg) = (
        *cpu.props().expect("props").stats(),
        *gpu.props().expect("props").stats(),
    );
    assert!(sc.contacts > 50 && sc.swept > 5, "too few cases: {sc:?}");
    assert_eq!(
        (sc.contacts, sc.swept),
        (sg.contacts, sg.swept),
        "seed {seed}"
    );
    let mut worst: (f64, usize) = (0.0, 0);
    for i in 0..cpu.positions().len() {
        let dx = (cpu.positions()[i] - gpu.positions()[i]).length();
        let dv = (cpu.velocities()[i] - gpu.velocities()[i]).length() * h;
        if dx.max(dv) > worst.0 {
            worst = (dx.max(dv), i);
        }
    }
    assert!(
        worst.0 < 5e-5,
        "seed {seed}: particle {} differs by {:.3e} m",
        worst.1,
        worst.0
    );
    let (jc, jg) = (sc.impulse_on_bodies, sg.impulse_on_bodies);
    assert!(jc.length() > 0.0, "the dynamic ball was not pushed");
    assert!(
        (jc - jg).length() < 1e-4 * jc.length().max(1e-3),
        "seed {seed}: impulse on bodies CPU {jc}, GPU {jg}"
    );
    let body = |sim: &Simulation| {
        let b = sim
            .props()
            .expect("props")
            .bodies()
            .iter()
            .nth(2)
            .expect("ball")
            .1;
        (b.linvel().as_dvec3(), b.angvel().as_dvec3())
    };
    let ((lc, ac), (lg, ag)) = (body(&cpu), body(&gpu));
    assert!(
        (lc - lg).length() < 1e-4 && (ac - ag).length() < 1e-3,
        "seed {seed}: ball CPU {lc} {ac}, GPU {lg} {ag}"
    );
    eprintln!("seed {seed}: {sc:?}; worst particle {:.3e} m", worst.0);
}
