//! Air on cloth (`air:` per cloth, the scene's `wind`, `Simulation::set_wind`): checked
//! against the terminal velocity of its drag model, the energy audit's books, the back ends'
//! parity, and located errors.

use harmonic::prelude::*;
use harmonic::{SimError, Wind};

mod common;

/// A flat n×n mesh of `size` m at height `y`, horizontal (x–z), each cell split along one
/// diagonal, as RON.
fn flat_mesh(n: u32, size: f64, y: f64, rest: &str) -> String {
    let d = size / f64::from(n - 1);
    let mut v = Vec::new();
    for r in 0..n {
        for c in 0..n {
            v.push(format!("({}, {y}, {})", f64::from(c) * d, f64::from(r) * d));
        }
    }
    format!(
        "(vertices: [{}], triangles: [{}], {rest})",
        v.join(", "),
        common::ron_triangles(&common::grid_triangles(n, n))
    )
}

/// A flat horizontal cloth falling face-on in still air feels drag only, and with masses
/// lumped by area every particle feels the same force per mass, so it stays flat and reaches
/// the model's terminal velocity `√(2 m g / (ρ C_d A))` exactly: within 2 % after
/// `2.5 v_t / g`, and to 1e-6 once settled.
#[test]
fn a_falling_cloth_reaches_its_terminal_velocity() {
    let (m, g, rho, cd, size): (f64, f64, f64, f64, f64) = (0.05, 9.81, 1.225, 1.2, 1.0);
    let vt = (2.0 * m * g / (rho * cd * size * size)).sqrt();
    let mesh = flat_mesh(
        9,
        size,
        10.0,
        &format!(
            "mass: {m}, stretch: (frequency: 30.0, damping_ratio: 0.1), \
             air: Some((density: {rho}, drag: {cd}, lift: 0.8))"
        ),
    );
    let text = format!(
        "Scene(dt: 0.016666666666666666, substeps: 4, integrator: \"symplectic-euler\",
          gravity: (0.0, -{g}, 0.0), meshes: [{mesh}])"
    );
    let mut sim = Simulation::from_scene(&Scene::parse(&text, "fall.ron").unwrap()).unwrap();
    assert_eq!(
        sim.schedule().to_string(),
        "gravity → air → forces → integrate (symplectic-euler, 4 substeps) → quarantine"
    );
    let mean_vy = |sim: &Simulation| {
        let v = sim.velocities();
        v.iter().map(|v| v.y).sum::<f64>() / v.len() as f64
    };
    let settle = (2.5 * vt / g / sim.config().dt).ceil() as usize;
    for _ in 0..settle {
        sim.step().unwrap();
    }
    let at = -mean_vy(&sim);
    println!("v_t = {vt} m/s; after {settle} frames {at} m/s");
    assert!((at - vt).abs() < 0.02 * vt, "{at} m/s, not {vt}");
    for _ in 0..60 {
        sim.step().unwrap();
    }
    let at = -mean_vy(&sim);
    assert!((at - vt).abs() < 1e-6 * vt, "{at} m/s settled, not {vt}");
    // Flat: every particle at one height, moving as one.
    let ys = sim.positions().iter().map(|x| x.y);
    let (lo, hi) = ys.fold((f64::MAX, f64::MIN), |(a, b), y| (a.min(y), b.max(y)));
    assert!(hi - lo < 1e-9, "the cloth bends: {} m", hi - lo);
    // The air's work is booked with the forces': at terminal velocity it takes what gravity
    // gives, so the residual stays at the step's own error, under symplectic Euler's
    // `−½ m a² h²` a substep with `|a| ≤ g`.
    let a = sim.diagnostics().audit;
    let h = sim.config().h();
    let substeps = sim.steps() as f64 * f64::from(sim.config().substeps);
    let bound = 0.5 * m * g * g * h * h * substeps;
    println!("audit: {a:?}; the step's error at most {bound:e} J");
    assert!(a.forces < 0.0, "the air takes energy: {}", a.forces);
    let fall = a.energy - a.start;
    assert!(
        (fall - a.forces - a.residual).abs() < 1e-12,
        "the books balance"
    );
    assert!(
        a.residual <= 0.0 && -a.residual <= bound,
        "residual {} J against the air's {} J",
        a.residual,
        a.forces
    );
}

/// Cloths without `air:` feel none, and the schedule lists no air stage.
#[test]
fn no_air_no_stage() {
    let mesh = flat_mesh(3, 1.0, 1.0, "mass: 0.1, stretch: (frequency: 10.0)");
    let text = format!(
        "Scene(dt: 0.01, substeps: 2, wind: (velocity: (5.0, 0.0, 0.0)), meshes: [{mesh}])"
    );
    let mut sim = Simulation::from_scene(&Scene::parse(&text, "still.ron").unwrap()).unwrap();
    assert!(!sim.schedule().has(StageKind::Air), "{}", sim.schedule());
    sim.step().unwrap();
    assert!(sim.velocities().iter().all(|v| v.x == 0.0 && v.z == 0.0));
}

/// A flag in a steady wind streams downwind on both back ends, and the device (its springs in
/// f32, the air the host's) stays within f32's reach of the CPU.
#[test]
fn a_flag_streams_downwind_on_both_back_ends() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut scene = Scene::load(root.join("scenes/flag.ron")).unwrap();
    scene.wind = Wind::steady(DVec3::new(8.0, 0.0, 0.0));
    scene.cloths[0].air = Some(harmonic::Aero::default());
    scene.substeps = Some(30);
    scene.integrator = Some("symplectic-euler".into());
    let run = |backend: Backend| {
        let built = scene.build();
        let config = SimConfig {
            backend,
            ..built.config
        };
        let mut sim = Simulation::new(built.world, config).unwrap();
        assert_eq!(sim.backend(), backend);
        let start = sim.positions().to_vec();
        for _ in 0..30 {
            sim.step().unwrap();
        }
        (start, sim.positions().to_vec())
    };
    let (start, cpu) = run(Backend::Cpu);
    let mean_x = |x: &[DVec3]| x.iter().map(|p| p.x).sum::<f64>() / x.len() as f64;
    println!("mean x {} → {}", mean_x(&start), mean_x(&cpu));
    assert!(
        mean_x(&cpu) > mean_x(&start) + 0.05,
        "the flag streams downwind"
    );
    if common::gpu_or_skip(harmonic::internals::gpu::GpuContext::shared(true)).is_none() {
        return;
    }
    let (_, gpu) = run(Backend::Gpu);
    let apart = (cpu.iter().zip(&gpu))
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0, f64::max);
    println!("GPU against CPU after 0.5 s in the wind: {apart:e} m");
    assert!(apart < 1e-3, "{apart} m apart");
}

#[test]
fn bad_air_and_wind_are_refused_by_name() {
    let mesh = |air: &str| {
        flat_mesh(
            3,
            1.0,
            1.0,
            &format!("mass: 0.1, stretch: (frequency: 10.0), air: Some({air})"),
        )
    };
    let bad = |text: String| Scene::parse(&text, "air.ron").unwrap_err().to_string();
    let e = bad(format!(
        "Scene(dt: 0.01, meshes: [{}])",
        mesh("(density: -1.0)")
    ));
    assert!(
        e.contains("meshes[0].air: density must be finite and ≥ 0, got -1.0"),
        "{e}"
    );
    let e = bad(format!(
        "Scene(dt: 0.01, wind: (velocity: (1.0, 0.0, 0.0), gust: Some((strength: 2.0, length: 0.0, period: 1.0))), meshes: [{}])",
        mesh("()")
    ));
    assert!(
        e.contains("wind: gust.length must be finite and > 0, got 0.0"),
        "{e}"
    );
    let text = format!("Scene(dt: 0.01, meshes: [{}])", mesh("(lift: 0.5)"));
    let mut sim = Simulation::from_scene(&Scene::parse(&text, "air.ron").unwrap()).unwrap();
    let e = sim
        .set_wind(Wind::steady(DVec3::new(f64::NAN, 0.0, 0.0)))
        .unwrap_err();
    assert!(matches!(e, SimError::BadWind(_)), "{e}");
    assert!(
        e.to_string().starts_with("wind: velocity must be finite"),
        "{e}"
    );
    assert!(sim.config().wind.is_still(), "nothing changed");
    // Edge-on to the horizontal cloth a wind does nothing; one through it pushes it along.
    sim.set_wind(Wind::steady(DVec3::new(3.0, 0.0, 0.0)))
        .unwrap();
    sim.step().unwrap();
    assert!(sim.velocities().iter().all(|v| v.x == 0.0), "edge-on");
    sim.set_wind(Wind::steady(DVec3::new(3.0, 2.0, 0.0)))
        .unwrap();
    sim.step().unwrap();
    assert!(
        sim.velocities().iter().all(|v| v.x > 0.0),
        "the new wind blows"
    );
}

/// The windy flag in a steady 6 m/s wind (its gusts taken off) streams downwind and flutters:
/// the fly end's free corner swings across the wind at a steady frequency, reported.
#[test]
fn a_flag_in_a_steady_wind_streams_and_flutters() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut scene = Scene::load(root.join("scenes/windy_flag.ron")).unwrap();
    scene.wind.gust = None;
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let (cols, rows) = (32, 20);
    let corner = (rows - 1) * cols + cols - 1;
    let dt = scene.dt;
    for _ in 0..60 {
        sim.step().unwrap();
    }
    let mut z = Vec::new();
    let mut x = 0.0;
    let frames = 240;
    for _ in 0..frames {
        sim.step().unwrap();
        let p = sim.positions()[corner];
        z.push(p.z);
        x += p.x / frames as f64;
    }
    let mean = z.iter().sum::<f64>() / z.len() as f64;
    let swing = (z.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / z.len() as f64).sqrt();
    let crossings = z
        .windows(2)
        .filter(|w| (w[0] - mean).signum() != (w[1] - mean).signum())
        .count();
    let frequency = crossings as f64 / 2.0 / (frames as f64 * dt);
    let tail = &z[z.len() - 60..];
    let late = (tail.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 60.0).sqrt();
    println!(
        "fly corner: mean x {x:.3} m, swing {swing:.4} m rms across the wind ({late:.4} m in the last second), flutter {frequency:.2} Hz"
    );
    assert!(
        late > 0.3 * swing,
        "the flutter dies away: {late} m rms at the end"
    );
    assert!(x > 0.7, "the flag streams downwind: the corner at x = {x}");
    assert!(swing > 0.005, "it flutters: {swing} m rms");
    assert!((0.5..15.0).contains(&frequency), "{frequency} Hz");
}
