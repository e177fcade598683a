#![allow(dead_code)]
//! Helpers shared by the integration tests.

use harmonic::prelude::*;

pub mod crossing;

/// The triangles of a grid of `cols × rows` vertices numbered row by row, each cell split
/// along the diagonal from its first vertex.
pub fn grid_triangles(cols: u32, rows: u32) -> Vec<[u32; 3]> {
    let mut t = Vec::new();
    for r in 0..rows - 1 {
        for c in 0..cols - 1 {
            let i = r * cols + c;
            t.push([i, i + 1, i + cols + 1]);
            t.push([i, i + cols + 1, i + cols]);
        }
    }
    t
}

/// Triangles as the items of a RON list: `(a, b, c), …`.
pub fn ron_triangles(triangles: &[[u32; 3]]) -> String {
    let t: Vec<String> = (triangles.iter())
        .map(|t| format!("({}, {}, {})", t[0], t[1], t[2]))
        .collect();
    t.join(", ")
}

/// Two particles on the x axis joined by one spring (κ, ζ) with masses `ma`, `mb`, no gravity,
/// stretched by `d0` and stretching at `v0`; stepped at `h = ratio · h_c`.
#[allow(clippy::too_many_arguments)]
pub fn pair(
    ma: f64,
    mb: f64,
    zeta: f64,
    ratio: f64,
    d0: f64,
    v0: f64,
    exact: bool,
    integrator: &str,
) -> (Simulation, f64, f64) {
    let k = 100.0;
    let mu = ma * mb / (ma + mb);
    let w0 = (k / mu).sqrt();
    let c = 2.0 * zeta * (k * mu).sqrt();
    let h = ratio * std::f64::consts::PI / w0;
    let l0 = 1.0;
    // Centre of mass at rest at the origin.
    let (xa, xb) = (-(l0 + d0) * mb / (ma + mb), (l0 + d0) * ma / (ma + mb));
    let (va, vb) = (-v0 * mb / (ma + mb), v0 * ma / (ma + mb));
    let text = format!(
        "Scene(dt: {h:e}, substeps: 1, gravity: (0.0, 0.0, 0.0), integrator: \"{integrator}\", exact_displacement: {exact},
          particles: [(position: ({xa:e}, 0.0, 0.0), velocity: ({va:e}, 0.0, 0.0), mass: {ma:e}),
                      (position: ({xb:e}, 0.0, 0.0), velocity: ({vb:e}, 0.0, 0.0), mass: {mb:e})],
          springs: [(a: 0, b: 1, stiffness: {k:e}, damping: {c:e}, rest_length: {l0:e})])"
    );
    let scene = Scene::parse(&text, "pair").expect("valid pair scene");
    (
        Simulation::from_scene(&scene).expect("builds"),
        w0,
        zeta * w0,
    )
}

/// `(δ, δ̇)` of a spring in a simulation of two particles.
pub fn stretch(sim: &Simulation) -> (f64, f64) {
    let (x, v) = (sim.positions(), sim.velocities());
    let d = x[1] - x[0];
    let n = d.normalize();
    (
        d.length() - sim.packed().springs[0].rest,
        n.dot(v[1] - v[0]),
    )
}

/// Textbook solution of `δ̈ + 2αδ̇ + ω0²δ = 0`, written directly in each regime.
pub fn textbook(w2: f64, a: f64, t: f64, d0: f64, v0: f64) -> (f64, f64) {
    let b2 = w2 - a * a;
    let e = (-a * t).exp();
    if b2.abs() < 1e-12 * w2 {
        (
            e * (d0 + (v0 + a * d0) * t),
            e * (v0 - (w2 * d0 + a * v0) * t),
        )
    } else if b2 > 0.0 {
        let b = b2.sqrt();
        let (c, s) = ((b * t).cos(), (b * t).sin() / b);
        (
            e * (d0 * c + (v0 + a * d0) * s),
            e * (v0 * c - (w2 * d0 + a * v0) * s),
        )
    } else {
        // e^{−αt}cosh(γt) and e^{−αt}sinh(γt)/γ as sums of decaying exponentials.
        let g = (-b2).sqrt();
        let (e1, e2) = ((-(a - g) * t).exp(), (-(a + g) * t).exp());
        let (c, s) = (0.5 * (e1 + e2), 0.5 * (e1 - e2) / g);
        (d0 * c + (v0 + a * d0) * s, v0 * c - (w2 * d0 + a * v0) * s)
    }
}

/// A small splitmix64 generator: seeded, printable, no dependency on global state.
pub struct Rng(pub u64);
impl Rng {
    pub fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }
}

/// Seed from the clock unless `HARMONIC_SEED` is set; printed so a failure can be replayed.
/// The GPU tests' skip rule: `Ok(v)` is `Some(v)`; an error skips the test (`None`) only when
/// no adapter exists at all and `HARMONIC_REQUIRE_GPU` is not set (CI sets it).
pub fn gpu_or_skip<T>(r: Result<T, harmonic::GpuError>) -> Option<T> {
    match r {
        Ok(v) => Some(v),
        Err(e) => {
            assert!(
                std::env::var_os("HARMONIC_REQUIRE_GPU").is_none(),
                "HARMONIC_REQUIRE_GPU is set but no adapter: {e}"
            );
            assert_eq!(
                e,
                harmonic::GpuError::NoAdapter,
                "only a missing adapter may skip"
            );
            eprintln!("skipped: {e}");
            None
        }
    }
}

pub fn seed() -> u64 {
    let seed = std::env::var("HARMONIC_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(1, |d| d.as_nanos() as u64)
        });
    eprintln!("seed: {seed} (replay with HARMONIC_SEED={seed})");
    seed
}

/// `frames` steps, then the state: positions followed by velocities.
pub fn run_state(sim: &mut Simulation, frames: usize) -> Vec<DVec3> {
    for _ in 0..frames {
        sim.step().unwrap();
    }
    sim.positions()
        .iter()
        .chain(sim.velocities())
        .copied()
        .collect()
}

/// Every `scenes/hard/` case (64 files), sorted, with its largest strain over its full run
/// under `integrator` (`None`: the scene's own settings) and the substeps it ran with.
pub fn hard_cases_max_strain(integrator: Option<&str>) -> Vec<(std::path::PathBuf, f64, u32)> {
    let mut files: Vec<_> = std::fs::read_dir(repo_root().join("scenes/hard"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert_eq!(files.len(), 64);
    files
        .into_iter()
        .map(|path| {
            let mut scene = Scene::load(&path).unwrap();
            if let Some(name) = integrator {
                scene.integrator = Some(name.into());
            }
            let mut sim = Simulation::from_scene(&scene).unwrap();
            let substeps = sim.config().substeps;
            let frames = (scene.seconds.unwrap() / scene.dt).ceil() as usize;
            let mut max_strain: f64 = 0.0;
            for _ in 0..frames {
                sim.step()
                    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                max_strain = max_strain.max(sim.diagnostics().max_strain);
            }
            (path, max_strain, substeps)
        })
        .collect()
}

/// The repository's root (where `scenes/` is), from the engine's tests and the lab's alike.
pub fn repo_root() -> std::path::PathBuf {
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    here.ancestors()
        .find(|d| d.join("scenes").is_dir())
        .unwrap_or(here)
        .to_path_buf()
}

/// `f` run on a rayon pool of `threads` threads.
pub fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool")
        .install(f)
}
