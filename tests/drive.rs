//! Driven pins and motion constraints (`Simulation::drive`, `drive_within`,
//! `set_drive_targets`): checked against closed forms, Galilean invariance and the energy
//! audit's books.

use harmonic::prelude::*;
use harmonic::{SimError, StageKind};

mod common;

fn sim(text: &str) -> Simulation {
    Simulation::from_scene(&Scene::parse(text, "drive").expect("parses")).expect("builds")
}

const DT: f64 = 1.0 / 60.0;

/// A pin driven at constant speed `u` along a spring (κ, no damper) to a particle at rest:
/// `m ẍ = −κ (x − u t − L)`, so `x − L = u t − (u/ω) sin ωt`, and the pin's work is the
/// oscillator's energy, `m u² (1 − cos ωt)` (ω = 20 rad/s). Pins moved to the frame's end at once (teleported)
/// would lag the path by half a frame on average and miss it by about `u dt / 2` (4 mm here).
fn ramp(substeps: u32) -> (f64, harmonic::EnergyAudit, f64) {
    let (m, k, l, u): (f64, f64, f64, f64) = (0.5, 200.0, 1.0, 0.5);
    let w: f64 = (k / m).sqrt();
    let mut sim = sim(&format!(
        "Scene(dt: {DT:e}, substeps: {substeps}, gravity: (0.0, 0.0, 0.0), integrator: \"symplectic-euler\",
          particles: [(position: (0.0, 0.0, 0.0), mass: 1.0), (position: ({l:e}, 0.0, 0.0), mass: {m:e})],
          springs: [(a: 0, b: 1, stiffness: {k:e}, damping: 0.0, rest_length: {l:e})])"
    ));
    let pin = sim.drive(&[0]).expect("drives particle 0");
    assert!(sim.schedule().has(StageKind::Drive), "{}", sim.schedule());
    let frames = 90;
    let mut worst: f64 = 0.0;
    for f in 1..=frames {
        let t = f as f64 * DT;
        sim.set_drive_targets(pin, &[DVec3::new(u * t, 0.0, 0.0)])
            .expect("one target");
        sim.step().expect("steps");
        let exact = l + u * t - (u / w) * (w * t).sin();
        worst = worst.max((sim.positions()[1].x - exact).abs());
        assert_eq!(
            sim.positions()[0],
            DVec3::new(u * t, 0.0, 0.0),
            "the pin is on its target"
        );
    }
    let t = frames as f64 * DT;
    (
        worst,
        sim.diagnostics().audit,
        m * u * u * (1.0 - (w * t).cos()),
    )
}

/// The ramp's path to 1e-6 m, and its work booked: each substep's pin move is booked as the
/// mean of the change of `E` it would make at the substep's start and the one it makes at its
/// end (a trapezoid), so the books match the closed form's work to second order in the step
/// (the miss quarters when the step halves), and what is left in the residual is symplectic
/// Euler's own energy error, within `ω h` of the oscillation's energy.
#[test]
fn a_pin_driven_at_constant_speed_follows_the_closed_form() {
    let (coarse, a1, work) = ramp(100);
    let (fine, a2, _) = ramp(200);
    println!("worst miss {coarse:e} m (100 substeps), {fine:e} m (200)");
    assert!(
        coarse < 1e-6 && fine < 1e-6,
        "misses the closed form by {coarse:e} m"
    );
    let (w, u, h) = (20.0, 0.5, DT / 100.0);
    for (a, h) in [(a1, h), (a2, h / 2.0)] {
        println!(
            "h {h:e}: booked {:e} J, closed form {work:e} J, residual {:e} J",
            a.attachments, a.residual
        );
        // Symplectic Euler's energy wanders by about `ω h` of the oscillation's (2 m u²).
        let e = a.energy - a.start;
        assert!(
            (e - work).abs() < w * h * 2.0 * 0.5 * u * u,
            "E {e} J, not the oscillator's"
        );
        assert!(
            a.residual.abs() < w * h * 2.0 * 0.5 * u * u,
            "residual {:e} J",
            a.residual
        );
        assert!(
            (a.attachments - work).abs() < 1e-4 * work,
            "booked {} J",
            a.attachments
        );
    }
    let order = (a1.attachments - work) / (a2.attachments - work);
    println!("the books' miss falls {order:.2}× when the step halves");
    assert!(
        (3.5..4.5).contains(&order),
        "miss ratio {order} for h and h/2"
    );
}

/// A damped chain moving at `u` with its pinned end driven at `u` moves as one body, to
/// rounding: the pin moves a share every substep with the path's velocity, so no spring
/// stretches and no damper drags. A pin teleported at the frame's end, or one whose velocity
/// the dampers do not see, stretches the first link.
#[test]
fn a_chain_driven_with_its_own_velocity_translates_rigidly() {
    let u = DVec3::new(0.7, -0.2, 0.3);
    let particles: Vec<String> = (0..8)
        .map(|i| {
            format!(
                "(position: ({}, 0.0, 0.0), velocity: ({:e}, {:e}, {:e}), mass: 0.05)",
                i as f64 * 0.1,
                u.x,
                u.y,
                u.z
            )
        })
        .collect();
    let springs: Vec<String> = (0..7)
        .map(|i| {
            format!(
                "(a: {i}, b: {}, stiffness: 500.0, damping: 0.8, rest_length: 0.1)",
                i + 1
            )
        })
        .collect();
    for backend in ["cpu", "gpu"] {
        if backend == "gpu"
            && common::gpu_or_skip(harmonic::internals::gpu::GpuContext::shared(true)).is_none()
        {
            continue;
        }
        let mut sim = sim(&format!(
            "Scene(dt: {DT:e}, substeps: 16, gravity: (0.0, 0.0, 0.0), backend: \"{backend}\",
              integrator: \"symplectic-euler\", particles: [{}], springs: [{}])",
            particles.join(", "),
            springs.join(", ")
        ));
        let on = if backend == "gpu" {
            Backend::Gpu
        } else {
            Backend::Cpu
        };
        assert_eq!(sim.backend(), on);
        let start = sim.positions().to_vec();
        let pin = sim.drive(&[0]).expect("drives");
        for f in 1..=60 {
            let t = f as f64 * DT;
            sim.set_drive_targets(pin, &[start[0] + u * t]).unwrap();
            sim.step().unwrap();
        }
        let t = 60.0 * DT;
        let tol = if backend == "gpu" { 1e-5 } else { 1e-12 };
        for (i, (x, x0)) in sim.positions().iter().zip(&start).enumerate() {
            let miss = (*x - (*x0 + u * t)).length();
            assert!(
                miss < tol,
                "{backend}: particle {i} is {miss:e} m off the rigid path"
            );
        }
    }
}

/// A particle falling from its target's place is caught at the maximum distance below it and
/// rests there; the audit books the projections' loss on the attachments line, so the energy
/// left is the potential `−m g r` and the residual stays at the step's own error.
#[test]
fn a_maximum_distance_catches_a_falling_particle() {
    let (m, g, r) = (0.2, 9.81, 0.3);
    let mut sim = sim(&format!(
        "Scene(dt: {DT:e}, substeps: 8, gravity: (0.0, -{g:e}, 0.0), integrator: \"symplectic-euler\",
          particles: [(position: (0.0, 1.0, 0.0), mass: {m:e})])"
    ));
    let id = sim
        .drive_within(&[0], &[r])
        .expect("a free particle within r");
    assert_eq!(sim.drive_targets(id).unwrap(), &[DVec3::new(0.0, 1.0, 0.0)]);
    for _ in 0..120 {
        sim.step().unwrap();
    }
    let x = sim.positions()[0];
    assert!(
        (x - DVec3::new(0.0, 1.0 - r, 0.0)).length() < 1e-12,
        "rests at {x}"
    );
    assert!(sim.velocities()[0].length() < g * DT / 8.0 + 1e-12);
    let a = sim.diagnostics().audit;
    let fall = -m * g * r;
    assert!(
        (a.energy - a.start - fall).abs() < 1e-9,
        "E fell {} J",
        a.energy - a.start
    );
    // Resting at the distance, each substep's fall and the projection that undoes it leave
    // the step's own error, `−½ m g² h²` a substep (as on a collider: `EnergyAudit`).
    let h = DT / 8.0;
    let resting = -0.5 * m * g * g * h * h * (120.0 * 8.0);
    println!("residual {:e} J, at most {resting:e} J", a.residual);
    assert!(
        a.residual <= 0.0 && a.residual >= resting * (1.0 + 1e-9),
        "residual {} J (attachments {} J)",
        a.residual,
        a.attachments
    );
}

/// A pose moving at `u` drags a free particle that started on it: it trails at the maximum
/// distance, on the line of motion, at the pose's speed.
#[test]
fn a_moving_pose_drags_its_particle_at_the_maximum_distance() {
    let (u, r) = (DVec3::new(1.5, 0.0, 0.0), 0.25);
    let mut sim = sim(&format!(
        "Scene(dt: {DT:e}, substeps: 4, gravity: (0.0, 0.0, 0.0), integrator: \"symplectic-euler\",
          particles: [(position: (0.0, 0.0, 0.0), mass: 1.0)])"
    ));
    let id = sim.drive_within(&[0], &[r]).unwrap();
    let mut pose = DVec3::ZERO;
    for _ in 0..60 {
        pose += u * DT;
        sim.set_drive_targets(id, &[pose]).unwrap();
        sim.step().unwrap();
    }
    let x = sim.positions()[0];
    assert!(
        (x - (pose - DVec3::X * r)).length() < 1e-12,
        "{x} behind {pose}"
    );
    assert!((sim.velocities()[0] - u).length() < 1e-12);
}

#[test]
fn bad_drives_are_refused_by_name() {
    let mut sim = sim(
        "Scene(dt: 0.01, substeps: 2, particles: [(position: (0.0, 0.0, 0.0), mass: 1.0),
          (position: (1.0, 0.0, 0.0), mass: 1.0)], springs: [(a: 0, b: 1, stiffness: 10.0, damping: 0.0)])",
    );
    assert_eq!(
        sim.drive(&[5]).unwrap_err(),
        SimError::NoParticle { index: 5 }
    );
    let e = sim.drive(&[]).unwrap_err().to_string();
    assert!(e.contains("drive: no particles"), "{e}");
    let e = sim.drive_within(&[0, 1], &[0.1]).unwrap_err().to_string();
    assert!(e.contains("2 particle(s) and 1 maximum distance"), "{e}");
    let e = sim.drive_within(&[1], &[f64::NAN]).unwrap_err().to_string();
    assert!(e.contains("max_distance[0] = NaN"), "{e}");
    let e = sim.drive_within(&[1], &[-1.0]).unwrap_err().to_string();
    assert!(e.contains("max_distance[0] = -1.0"), "{e}");
    assert!(!sim.schedule().has(StageKind::Drive), "no drive, no stage");
    let id = sim.drive(&[0]).unwrap();
    let e = sim.set_drive_targets(id, &[]).unwrap_err().to_string();
    assert!(e.contains("0 target(s) for a drive of 1"), "{e}");
    let e = (sim.set_drive_targets(id, &[DVec3::new(0.0, f64::INFINITY, 0.0)]))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("set_drive_targets: targets[0] is not finite"),
        "{e}"
    );
    sim.remove_drive(id).unwrap();
    assert_eq!(
        sim.set_drive_targets(id, &[DVec3::ZERO]),
        Err(SimError::UnknownDrive)
    );
    assert_eq!(sim.remove_drive(id), Err(SimError::UnknownDrive));
}

/// Removing a drive frees the particles it pinned (they fall), and leaves the scene's own
/// pins pinned.
#[test]
fn removing_a_drive_frees_what_it_pinned() {
    let mut sim = sim(
        "Scene(dt: 0.01, substeps: 2, gravity: (0.0, -9.81, 0.0), particles: [(position: (0.0, 0.0, 0.0), mass: 1.0, pinned: true),
          (position: (1.0, 0.0, 0.0), mass: 1.0)], springs: [(a: 0, b: 1, stiffness: 1000.0, damping: 1.0)])",
    );
    let id = sim.drive(&[0, 1]).unwrap();
    for _ in 0..10 {
        sim.step().unwrap();
    }
    assert_eq!(
        sim.positions()[1],
        DVec3::new(1.0, 0.0, 0.0),
        "held by the drive"
    );
    sim.remove_drive(id).unwrap();
    assert!(!sim.schedule().has(StageKind::Drive));
    for _ in 0..10 {
        sim.step().unwrap();
    }
    assert_eq!(sim.positions()[0], DVec3::ZERO, "the scene's pin stays");
    assert!(
        sim.positions()[1].y < -0.01,
        "freed, it falls: {}",
        sim.positions()[1]
    );
}

/// Under automatic substeps the accuracy controller reads the drive's moves as work put in,
/// not as the step's error: a chain whose pin the game swings round a circle keeps the
/// substeps its springs need (it would otherwise take ever more, to no end).
#[test]
fn automatic_substeps_count_the_drive_as_work() {
    let mut scene =
        Scene::load(format!("{}/scenes/chain.ron", env!("CARGO_MANIFEST_DIR"))).unwrap();
    scene.substeps = None;
    let mut sim = Simulation::from_scene(&scene).unwrap();
    assert!(sim.config().auto_substeps);
    let first = sim.config().substeps;
    let pin = sim.drive(&[0]).unwrap();
    let mut most = first;
    for f in 1..=300 {
        let a = std::f64::consts::TAU * f as f64 * scene.dt;
        sim.set_drive_targets(pin, &[0.2 * DVec3::new(a.cos() - 1.0, a.sin(), 0.0)])
            .unwrap();
        sim.step().unwrap();
        most = most.max(sim.config().substeps);
    }
    let a = sim.diagnostics().audit;
    println!(
        "substeps {first} at the start, at most {most}; attachments {:e} J, peak residual {:e}",
        a.attachments,
        a.relative_peak()
    );
    assert!(most <= 4 * first, "{most} substeps (from {first})");
    assert!(a.attachments > 0.0, "the swing puts energy in");
}
