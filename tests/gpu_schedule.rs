//! The frame's schedule on the GPU (on an adapter; skipped only where none exists, failing
//! instead when `HARMONIC_REQUIRE_GPU` is set): the submits each frame makes, the device's share
//! of the frame, and the force stage on the device against gravity and against the CPU.
#![cfg(feature = "gpu")]

mod common;

use std::path::Path;
use std::sync::Arc;

use harmonic::internals::gpu::GpuContext;
use harmonic::prelude::*;
use harmonic::Backend;

fn context() -> Option<Arc<GpuContext>> {
    common::gpu_or_skip(GpuContext::shared(true))
}

/// Submits per frame, as the schedule asks: all of a frame's substeps in one where no stage
/// needs the host between them (the tethered cloth's clamp runs on the device too); one per
/// substep where the contacts run on the CPU (the cape's attachments, the flag's pole) or the
/// device's contacts push a dynamic body (the trampoline's ball). The windy flag's air runs on
/// the device.
#[test]
fn each_frame_submits_what_its_schedule_asks() {
    let Some(_ctx) = context() else { return };
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    // (scene, where its contacts run, one submit per substep)
    let cases = [
        ("hanging_cloth.ron", None, false),
        ("drape_sphere.ron", Some(Backend::Gpu), false),
        ("trampoline.ron", Some(Backend::Gpu), true),
        ("cape.ron", Some(Backend::Cpu), true),
        ("tethered_cloth.ron", None, false),
        ("windy_flag.ron", Some(Backend::Cpu), true),
    ];
    for (name, contacts_on, per_substep) in cases {
        let built = Scene::load(root.join(name))
            .unwrap_or_else(|e| panic!("{e}"))
            .build();
        let config = SimConfig {
            backend: Backend::Gpu,
            ..built.config
        };
        let mut sim = Simulation::with_props(built.world, config, built.props)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        for frame in 0..3 {
            let before = sim.gpu_solver().expect("on the GPU").submits();
            let substeps = sim
                .step()
                .unwrap_or_else(|e| panic!("{name}: {e}"))
                .substeps;
            let made = sim.gpu_solver().expect("on the GPU").submits() - before;
            // The host waited for the device's kernels: the device's share of the frame.
            assert!(!sim.stats().device.is_zero(), "{name}: {:?}", sim.stats());
            let want = if per_substep { u64::from(substeps) } else { 1 };
            assert_eq!(made, want, "{name} frame {frame}: {}", sim.schedule());
            let contacts = (sim.schedule().stages().iter())
                .find(|s| s.kind == StageKind::Contacts)
                .map(|s| s.on);
            assert_eq!(contacts, contacts_on, "{name}: {}", sim.schedule());
            // The air's passes run on the device with the springs, in the frame's first
            // submit.
            let windy = name == "windy_flag.ron";
            assert_eq!(sim.schedule().has(StageKind::Air), windy, "{name}");
            for s in sim.schedule().stages() {
                if s.kind == StageKind::Air {
                    assert_eq!(s.on, Backend::Gpu, "{name}: {}", sim.schedule());
                }
            }
        }
    }
}

/// A 16×16 cloth of 1 kg (masses 1/256 kg: `F/m` exact) with `gravity`, on `backend`.
fn forced_cloth(gravity: DVec3, integrator: Integrator, backend: Backend) -> Simulation {
    let mut scene = harmonic::internals::hanging_cloth(16);
    scene.gravity = gravity.to_array();
    scene.integrator = Some(integrator.name().to_string());
    scene.substeps = Some(4);
    scene.dt = 1e-3;
    let built = scene.build();
    let config = SimConfig {
        backend,
        ..built.config
    };
    Simulation::with_props(built.world, config, built.props).expect("builds")
}

/// The force stage on the device: forces of `m a` step as a gravity of `a` bit for bit (both
/// kernels), and a field that differs particle by particle steps as on the CPU, its work booked.
#[test]
fn forces_on_the_gpu_are_gravity_where_uniform_and_the_cpu_where_not() {
    let Some(_ctx) = context() else { return };
    let a = DVec3::new(0.5, -9.75, 1.25);
    let m = 1.0 / 256.0;
    for integrator in [Integrator::SymplecticEuler, Integrator::HarmonicGs] {
        let mut by_gravity = forced_cloth(a, integrator, Backend::Gpu);
        let mut by_forces = forced_cloth(DVec3::ZERO, integrator, Backend::Gpu);
        let n = by_forces.positions().len();
        by_forces
            .set_forces(&vec![m * a; n])
            .expect("one per particle");
        for _ in 0..10 {
            by_gravity.step().expect("steps");
            by_forces.step().expect("steps");
        }
        assert!(by_forces.schedule().has(StageKind::Forces));
        assert_eq!(
            by_gravity.positions(),
            by_forces.positions(),
            "{integrator}"
        );
        assert!(by_forces.diagnostics().audit.forces > 0.0);
    }
    let field: Vec<DVec3> = (0..256)
        .map(|i| m * 3.0 * DVec3::new((i as f64).sin(), (i as f64 * 0.7).cos(), 0.5))
        .collect();
    let g = DVec3::new(0.0, -9.81, 0.0);
    let mut cpu = forced_cloth(g, Integrator::SymplecticEuler, Backend::Cpu);
    let mut gpu = forced_cloth(g, Integrator::SymplecticEuler, Backend::Gpu);
    for sim in [&mut cpu, &mut gpu] {
        sim.set_forces(&field).expect("one per particle");
        for _ in 0..20 {
            sim.step().expect("steps");
        }
    }
    let worst = (cpu.positions().iter().zip(gpu.positions()))
        .map(|(c, g)| (*c - *g).length())
        .fold(0.0, f64::max);
    assert!(worst < 1e-5, "CPU and GPU {worst} m apart");
    let (wc, wg) = (
        cpu.diagnostics().audit.forces,
        gpu.diagnostics().audit.forces,
    );
    assert!(
        (wc - wg).abs() < 1e-3 * wc.abs(),
        "the forces' work: {wc} J on the CPU, {wg} J on the GPU"
    );
    // Cleared: the device drops the stage and steps with gravity alone again.
    gpu.clear_forces();
    gpu.step().expect("steps");
    assert!(!gpu.schedule().has(StageKind::Forces));
}

/// The device's stage clock: where the adapter has timestamps inside compute passes, every
/// frame on the device gives its integrate kernels' time, and its contact kernels' where the
/// contacts run there; each stage's kernels fit in the frame's wall time. With the timers off,
/// nothing is measured.
#[test]
fn the_device_times_each_stage_where_it_has_timestamps() {
    let Some(ctx) = context() else { return };
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    // (scene, contacts on the device, tethers on the device)
    for (name, device_contacts, device_tethers) in [
        ("hanging_cloth.ron", false, false),
        ("drape_sphere.ron", true, false),
        ("trampoline.ron", true, false),
        ("cape.ron", false, false),
        ("tethered_cloth.ron", false, true),
        ("windy_flag.ron", false, false),
    ] {
        let built = Scene::load(root.join(name)).unwrap().build();
        let config = SimConfig {
            backend: Backend::Gpu,
            ..built.config
        };
        let mut sim = Simulation::with_props(built.world, config, built.props).unwrap();
        let clock = sim.gpu_solver().expect("on the GPU").has_clock();
        println!("{}: stage clock {clock}", ctx.describe());
        for _ in 0..3 {
            let stats = *sim.step().unwrap();
            let Some(kernels) = stats.device_stages else {
                assert!(!clock, "{name}: the clock measured nothing: {stats:?}");
                continue;
            };
            assert!(clock);
            let integrate = kernels[StageKind::Integrate];
            let contacts = kernels[StageKind::Contacts];
            let tethers = kernels[StageKind::Tethers];
            let air = kernels[StageKind::Air];
            println!(
                "{name}: integrate {integrate:?}, contacts {contacts:?}, tethers {tethers:?} of {:?}",
                stats.total()
            );
            assert!(!integrate.is_zero(), "{name}: {kernels:?}");
            assert_eq!(!contacts.is_zero(), device_contacts, "{name}: {kernels:?}");
            assert_eq!(!tethers.is_zero(), device_tethers, "{name}: {kernels:?}");
            assert_eq!(
                !air.is_zero(),
                name == "windy_flag.ron",
                "{name}: {kernels:?}"
            );
            assert!(
                kernels.total() <= stats.total(),
                "{name}: {kernels:?} in {stats:?}"
            );
        }
        sim.set_timers(false);
        assert_eq!(sim.step().unwrap().device_stages, None, "{name}");
    }
}

/// The device's contacts book the work their colliders' motion does on the cloth: the ball
/// dropped on the trampoline puts energy in on both back ends (a negative contacts line), and
/// the device's run is not mistaken for a step making energy (the residual the books leave is
/// the contacts' own dissipation, negative).
#[test]
fn device_contacts_book_the_work_of_moving_bodies() {
    let Some(_ctx) = context() else {
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let scene = Scene::load(root.join("scenes/trampoline.ron")).unwrap();
    let run = |backend: Backend| {
        let built = scene.build();
        let config = SimConfig {
            backend,
            ..built.config
        };
        let mut sim = Simulation::with_props(built.world, config, built.props).unwrap();
        for _ in 0..60 {
            sim.step().unwrap();
        }
        (sim.contacts_on_gpu(), sim.diagnostics())
    };
    let (on_gpu, gpu) = run(Backend::Gpu);
    let (_, cpu) = run(Backend::Cpu);
    println!("CPU: {:?}\nGPU: {:?}", cpu.audit, gpu.audit);
    assert!(on_gpu, "the trampoline's contacts run on the device");
    assert!(cpu.audit.contacts < 0.0 && gpu.audit.contacts < 0.0);
    assert!(gpu.failure.is_none(), "{:?}", gpu.failure);
    assert!(
        gpu.audit.relative_peak() < 0.01,
        "peak {}",
        gpu.audit.relative_peak()
    );
}
