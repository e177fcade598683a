//! The hard-case stability suite: stability thresholds against the numpy study, and bounded /
//! strain / energy figures for each integrator over the step ratios the paper tests.

use std::fmt::Write;

use harmonic::glam::DVec3;

use crate::research::{Method, Stepper};
use crate::statics;
use harmonic::internals::buffers::Packed;
use harmonic::internals::metrics;
use harmonic::scene::{Anchor, Cloth, ParticleDef, Plane, Rope, Scene, SpringDef, SpringSpec};
use harmonic::Integrator;

mod report;
pub use report::*;

/// The step ratios `h/h_c` of the hard-case suite.
pub const RATIOS: [f64; 8] = [0.25, 0.5, 1.0, 2.0, 2.0625, 4.0, 6.0625, 8.0625];

/// Integrators the suite compares (RK4 is the reference, not a contender).
pub const CONTENDERS: [Method; 11] = [
    Method::Engine(Integrator::SymplecticEuler),
    Method::Engine(Integrator::ExplicitEuler),
    Method::Engine(Integrator::Harmonic),
    Method::Engine(Integrator::HarmonicGs),
    Method::HARMONIC_FORCED,
    Method::HARMONIC_FORCED_GS,
    Method::HARMONIC_SGS,
    Method::Engine(Integrator::ImplicitEuler),
    Method::Engine(Integrator::ThetaMg),
    Method::Engine(Integrator::Xpbd),
    Method::HARMONIC_PAPER,
];

/// A run counts as blown up past this strain (1000 %).
pub const BLOWUP_STRAIN: f64 = 10.0;

pub struct Options {
    pub seconds: f64,
    pub full: bool,
}

/// How a hard case starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Start {
    /// From rest in the unloaded (or initially stretched) configuration.
    Rest,
    /// At its exact static (or steady spinning) equilibrium.
    Equilibrium,
}

fn spec(stiffness: f64, zeta: f64) -> SpringSpec {
    SpringSpec {
        stiffness: Some(stiffness),
        damping_ratio: Some(zeta),
        ..Default::default()
    }
}

fn base(dt: f64, gravity: [f64; 3]) -> Scene {
    Scene {
        substeps: Some(1),
        gravity,
        ..Scene::new(dt)
    }
}

/// Two free particles (masses 1 and `ratio`) joined by one spring, no gravity. Not spinning:
/// released from 10 % stretch (`Rest`) or at rest length (`Equilibrium`). Spinning about
/// their centre of mass at the rate whose steady stretch is 10 %: from rest length (`Rest`)
/// or on the steady circle (`Equilibrium`). Returns the scene and its reference strain (0.1).
pub fn pair(ratio: f64, zeta: f64, spinning: bool, start: Start) -> (Scene, f64) {
    let (l0, k) = (1.0, 100.0);
    let (ma, mb) = (1.0, ratio);
    let mu = ma * mb / (ma + mb);
    let mut s = base(1e-3, [0.0; 3]);
    let (len, omega) = match (spinning, start) {
        (false, Start::Rest) => (1.1 * l0, 0.0),
        (false, Start::Equilibrium) => (l0, 0.0),
        // κ(l − l0) = μ Ω² l with l = 1.1 l0  ⇒  Ω² = κ/(11 μ).
        (true, Start::Rest) => (l0, (k / (11.0 * mu)).sqrt()),
        (true, Start::Equilibrium) => (1.1 * l0, (k / (11.0 * mu)).sqrt()),
    };
    // Centre of mass at the origin; rotation about z.
    let (xa, xb) = (-len * mb / (ma + mb), len * ma / (ma + mb));
    s.particles = vec![
        ParticleDef {
            position: [xa, 0.0, 0.0],
            velocity: [0.0, omega * xa, 0.0],
            mass: ma,
            pinned: false,
        },
        ParticleDef {
            position: [xb, 0.0, 0.0],
            velocity: [0.0, omega * xb, 0.0],
            mass: mb,
            pinned: false,
        },
    ];
    s.springs = vec![SpringDef {
        a: 0,
        b: 1,
        stiffness: Some(k),
        damping: None,
        frequency: None,
        damping_ratio: Some(zeta),
        rest_length: Some(l0),
    }];
    (s, 0.1)
}

/// A chain of `n` particles hanging from a pinned top particle, 5 % strain at the top spring
/// at equilibrium. Returns the scene and its exact static max strain.
pub fn chain(n: u32, zeta: f64, start: Start) -> (Scene, f64) {
    let (m, l0, g) = (0.05, 0.05, 9.81);
    let top_load = (n - 1) as f64 * m * g;
    let k = top_load / (0.05 * l0);
    let mut s = base(1e-3, [0.0, -g, 0.0]);
    // Exact statics: spring i (from the top) carries the weight of the particles below it.
    let mut y = 0.0;
    let mut ys = vec![0.0];
    for i in 0..n - 1 {
        let stretch = if start == Start::Equilibrium {
            (n - 1 - i) as f64 * m * g / k
        } else {
            0.0
        };
        y -= l0 + stretch;
        ys.push(y);
    }
    s.particles = ys
        .iter()
        .enumerate()
        .map(|(i, &y)| ParticleDef {
            position: [0.0, y, 0.0],
            velocity: [0.0; 3],
            mass: m,
            pinned: i == 0,
        })
        .collect();
    s.springs = (0..n as usize - 1)
        .map(|i| SpringDef {
            a: i,
            b: i + 1,
            stiffness: Some(k),
            damping: None,
            frequency: None,
            damping_ratio: Some(zeta),
            rest_length: Some(l0),
        })
        .collect();
    (s, top_load / (k * l0))
}

/// An `n`×`n` cloth hanging from its two top corners; structural, shear and bend springs all
/// of one stiffness, as in the numpy study (a weaker bend family raises the thresholds 8–16 %).
pub fn cloth(n: u32, zeta: f64) -> Scene {
    let mut s = base(1e-3, [0.0, -9.81, 0.0]);
    let size = 0.5 * (n - 1) as f64 / 15.0;
    s.cloths = vec![Cloth {
        origin: [0.0, 0.0, 0.0],
        size: (size, size),
        resolution: (n, n),
        plane: Plane::Vertical,
        mass: 0.25 * (n * n) as f64 / 256.0,
        structural: spec(2000.0, zeta),
        shear: Some(spec(2000.0, zeta)),
        bend: Some(spec(2000.0, zeta)),
        pins: vec![Anchor::TopLeft, Anchor::TopRight],
        velocity: [0.0; 3],
        air: None,
        tethers: None,
        stretch_limit: None,
        tearing: None,
        self_collision: None,
    }];
    s
}

/// The paper's near-rigid system at 60 Hz: a 5-particle chain of 0.1 kg, 0.1 m links.
pub fn near_rigid(stiffness: f64, zeta: f64) -> Scene {
    let mut s = base(1.0 / 60.0, [0.0, -9.81, 0.0]);
    s.ropes = vec![Rope {
        start: [0.0, 0.0, 0.0],
        end: [0.4, 0.0, 0.0],
        particles: 5,
        mass: 0.5,
        spring: spec(stiffness, zeta),
        pin_start: true,
        pin_end: false,
        bend: None,
    }];
    s
}

#[allow(
    clippy::expect_used,
    reason = "the suite builds its own scenes, never user input"
)]
fn pack(scene: &Scene) -> Packed {
    Packed::gather(&scene.build().world).expect("generated scenes are consistent")
}

/// `h_c = π/ω0` of the stiffest spring.
pub fn h_crit(packed: &Packed) -> f64 {
    let w = packed
        .springs
        .iter()
        .map(|s| s.omega0_sq())
        .fold(0.0, f64::max)
        .sqrt();
    std::f64::consts::PI / w
}

/// Outcome of one hard-case run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// Bounded for the whole run.
    Bounded { max_strain: f64, energy_drift: f64 },
    /// Blew up (non-finite or past [`BLOWUP_STRAIN`]) at this time (s).
    BlownUp { time: f64 },
    /// The integrator has no value for this case (harmonic-paper at ζ > 0.707).
    Undefined,
}

/// Runs `packed` with `integrator` at step `h` for `seconds`. Energy drift is relative to
/// `energy_ref` (J).
pub fn run(
    packed: &Packed,
    integrator: impl Into<Method>,
    gravity: DVec3,
    h: f64,
    seconds: f64,
    energy_ref: f64,
) -> Outcome {
    let mut p = packed.clone();
    let mut solver = Stepper::new(integrator.into(), false, gravity);
    if solver.prepare(&p, h).is_err() {
        return Outcome::Undefined;
    }
    let e0 = metrics::energy(&p, gravity);
    let steps = (seconds / h).ceil() as u64;
    let mut max_strain = metrics::max_strain(&p);
    for step in 1..=steps {
        if solver.substep(&mut p, h).is_err() {
            return Outcome::Undefined;
        }
        let strain = metrics::max_strain(&p);
        if !strain.is_finite() || strain > BLOWUP_STRAIN || metrics::first_non_finite(&p).is_some()
        {
            return Outcome::BlownUp {
                time: step as f64 * h,
            };
        }
        max_strain = max_strain.max(strain);
    }
    Outcome::Bounded {
        max_strain,
        energy_drift: (metrics::energy(&p, gravity) - e0) / energy_ref,
    }
}

/// Energy scale for drift: total free mass × |g| × system size, or the initial energy
/// (kinetic + spring) without gravity.
fn energy_scale(packed: &Packed, gravity: DVec3) -> f64 {
    let free: f64 = (0..packed.particle_count())
        .filter(|&i| packed.inv_mass[i] != 0.0)
        .map(|i| packed.mass(i))
        .sum();
    let (lo, hi) = packed
        .x
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(*x), hi.max(*x))
        });
    let by_gravity = free * gravity.length() * (hi - lo).length();
    if by_gravity > 0.0 {
        by_gravity
    } else {
        metrics::energy(packed, gravity)
            .abs()
            .max(f64::MIN_POSITIVE)
    }
}

// --- thresholds --------------------------------------------------------------------------

/// Growth rate per step of a tiny perturbation about the rest state (no gravity): an estimate
/// of the step map's spectral radius. Polynomial growth of neutral modes (drift, rotation)
/// gives values within about `ln 2 / steps` of 1.
pub fn growth_rate(
    packed: &Packed,
    integrator: impl Into<Method>,
    exact: bool,
    h: f64,
    steps: usize,
) -> Option<f64> {
    let mut solver = Stepper::new(integrator.into(), exact, DVec3::ZERO);
    solver.prepare(packed, h).ok()?;
    let w = h_crit(packed).recip() * std::f64::consts::PI;
    let eps = 1e-7
        * packed
            .springs
            .iter()
            .map(|s| s.rest)
            .fold(f64::INFINITY, f64::min);
    let x_eq = packed.x.clone();
    let mut p = packed.clone();
    // Deterministic pseudo-random perturbation (splitmix64).
    let mut seed = 0x9E37_79B9_7F4A_7C15u64;
    let mut rnd = || {
        seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = seed;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    for i in 0..p.particle_count() {
        if p.inv_mass[i] != 0.0 {
            p.x[i] += eps * DVec3::new(rnd(), rnd(), rnd());
            p.v[i] = eps * w * DVec3::new(rnd(), rnd(), rnd());
        }
    }
    let norm = |p: &Packed| {
        p.x.iter()
            .zip(&x_eq)
            .zip(&p.v)
            .map(|((x, e), v)| (w * (*x - *e)).length_squared() + v.length_squared())
            .sum::<f64>()
            .sqrt()
    };
    let n0 = norm(&p);
    let chunk = 10;
    let mut log_growth = 0.0;
    let mut log_at_half = 0.0;
    for c in 0..steps / chunk {
        for _ in 0..chunk {
            solver.substep(&mut p, h).ok()?;
        }
        let n = norm(&p);
        if !n.is_finite() || n > 1e6 * n0 {
            return Some(f64::INFINITY);
        }
        // Renormalise to stay linear.
        let scale = n0 / n;
        for (x, e) in p.x.iter_mut().zip(&x_eq) {
            *x = *e + scale * (*x - *e);
        }
        p.v.iter_mut().for_each(|v| *v *= scale);
        log_growth += (n / n0).ln();
        if c + 1 == steps / chunk / 2 {
            log_at_half = log_growth;
        }
    }
    let counted = (steps / chunk - steps / chunk / 2) * chunk;
    Some(((log_growth - log_at_half) / counted as f64).exp())
}

/// Stable when the growth rate stays within this of 1.
pub const GROWTH_TOL: f64 = 1e-3;
const GROWTH_STEPS: usize = 4000;

/// Largest `h/h_c` below which every tested ratio is stable (scan in steps of 0.01 up to
/// `max`, then bisect to 0.002), or `None` if stable up to `max`.
pub fn threshold(
    packed: &Packed,
    integrator: impl Into<Method>,
    exact: bool,
    max: f64,
) -> Option<f64> {
    let integrator = integrator.into();
    let hc = h_crit(packed);
    let stable = |r: f64| {
        growth_rate(packed, integrator, exact, r * hc, GROWTH_STEPS)
            .is_some_and(|g| g <= 1.0 + GROWTH_TOL)
    };
    let mut r = 0.01;
    while r <= max {
        if !stable(r) {
            let (mut lo, mut hi) = (r - 0.01, r);
            while hi - lo > 0.002 {
                let mid = 0.5 * (lo + hi);
                if stable(mid) {
                    lo = mid
                } else {
                    hi = mid
                }
            }
            return Some(lo);
        }
        r += 0.01;
    }
    None
}

/// Figures of the numpy study (MATH.md) for one system: symplectic Euler, harmonic Jacobi,
/// harmonic forced, harmonic Gauss–Seidel (`INFINITY` for "∞", `NAN` where it gives none).
pub struct Study {
    pub name: &'static str,
    pub scene: Scene,
    pub symplectic_euler: f64,
    pub harmonic: f64,
    pub forced: f64,
    pub gauss_seidel: f64,
}

/// The systems of the numpy study's threshold table, with its figures.
pub fn threshold_systems() -> Vec<Study> {
    let zero_g = |mut s: Scene| {
        s.gravity = [0.0; 3];
        s
    };
    let inf = f64::INFINITY;
    let row = |name, scene, se, h, f, gs| Study {
        name,
        scene,
        symplectic_euler: se,
        harmonic: h,
        forced: f,
        gauss_seidel: gs,
    };
    vec![
        row(
            "1 spring, ζ = 0",
            pair(1.0, 0.0, false, Start::Equilibrium).0,
            0.64,
            0.55,
            0.55,
            0.55,
        ),
        row(
            "1 spring, ζ = 2",
            pair(1.0, 2.0, false, Start::Equilibrium).0,
            0.2,
            inf,
            inf,
            inf,
        ),
        row(
            "chain of 20, ζ = 0",
            zero_g(chain(20, 0.0, Start::Rest).0),
            0.45,
            0.34,
            0.37,
            0.56,
        ),
        row(
            "chain of 20, ζ = 0.2",
            zero_g(chain(20, 0.2, Start::Rest).0),
            0.34,
            0.31,
            0.48,
            0.65,
        ),
        row(
            "cloth 8×8, ζ = 0",
            zero_g(cloth(8, 0.0)),
            0.30,
            0.22,
            0.24,
            0.46,
        ),
        row(
            "cloth 8×8, ζ = 0.2",
            zero_g(cloth(8, 0.2)),
            0.19,
            0.17,
            0.24,
            0.97,
        ),
    ]
}

/// A cloth case: from rest in its flat layout, or at the relaxed static equilibrium.
pub fn cloth_case(n: u32, zeta: f64, start: Start) -> (Scene, f64) {
    let scene = cloth(n, zeta);
    let p = pack(&scene);
    let g = DVec3::from(scene.gravity);
    let relaxed = statics::relax(&p, g, 1e-9, 2_000_000);
    let strain = statics::static_strain(&p, &relaxed);
    match start {
        Start::Rest => (scene, strain),
        Start::Equilibrium => {
            // Explicit form of the same cloth at its equilibrium positions.
            let mut s = base(scene.dt, scene.gravity);
            s.particles = (0..p.particle_count())
                .map(|i| ParticleDef {
                    position: relaxed.positions[i].to_array(),
                    velocity: [0.0; 3],
                    mass: if p.inv_mass[i] == 0.0 {
                        scene.cloths[0].mass / (n * n) as f64
                    } else {
                        p.mass(i)
                    },
                    pinned: p.inv_mass[i] == 0.0,
                })
                .collect();
            s.springs = p
                .springs
                .iter()
                .map(|sp| SpringDef {
                    a: sp.a as usize,
                    b: sp.b as usize,
                    stiffness: Some(sp.stiffness),
                    damping: Some(sp.damping),
                    frequency: None,
                    damping_ratio: None,
                    rest_length: Some(sp.rest),
                })
                .collect();
            (s, strain)
        }
    }
}

fn static_strain_of(p: &Packed, g: DVec3) -> f64 {
    statics::static_strain(p, &statics::relax(p, g, 1e-9, 2_000_000))
}

/// The hard-case suite as scene files: every case × ζ ∈ {0, 0.2, 1, 2} × start, with
/// `dt = 8.0625 h_c` and no fixed substeps (so step control decides), plus the near-rigid
/// chains at 60 Hz. Names are `<case>_z<ζ>_<start>.ron`.
pub fn hard_scenes() -> Vec<(String, Scene)> {
    type Make = fn(f64, Start) -> (Scene, f64);
    let cases: [(&str, Make); 6] = [
        ("pair_1to1", |z, s| pair(1.0, z, false, s)),
        ("pair_1to1000", |z, s| pair(1000.0, z, false, s)),
        ("pair_1to1_spinning", |z, s| pair(1.0, z, true, s)),
        ("pair_1to1000_spinning", |z, s| pair(1000.0, z, true, s)),
        ("chain20", |z, s| chain(20, z, s)),
        ("cloth16", |z, s| cloth_case(16, z, s)),
    ];
    let mut out = Vec::new();
    for (name, make) in cases {
        for zeta in [0.0, 0.2, 1.0, 2.0] {
            for start in [Start::Rest, Start::Equilibrium] {
                let (mut scene, _) = make(zeta, start);
                let hc = h_crit(&pack(&scene));
                scene.dt = 8.0625 * hc;
                scene.substeps = None;
                scene.seconds = Some(10.0);
                let tag = if start == Start::Rest {
                    "rest"
                } else {
                    "equilibrium"
                };
                scene.name = Some(format!("{name}, ζ = {zeta}, from {tag}, dt = 8.0625 h_c"));
                out.push((format!("{name}_z{zeta}_{tag}.ron"), scene));
            }
        }
    }
    for k in [1e4, 1e5, 1e6, 1e7] {
        for zeta in [0.0, 0.2, 1.0, 2.0] {
            let mut scene = near_rigid(k, zeta);
            scene.substeps = None;
            scene.seconds = Some(10.0);
            scene.name = Some(format!(
                "near-rigid chain, κ = {k:e} N/m, ζ = {zeta}, dt = 1/60 s"
            ));
            out.push((format!("near_rigid_k{k:e}_z{zeta}.ron"), scene));
        }
    }
    out
}

/// Writes [`hard_scenes`] into `dir`.
pub fn write_hard_scenes(dir: &std::path::Path) -> std::io::Result<usize> {
    std::fs::create_dir_all(dir)?;
    let config = ron::ser::PrettyConfig::new()
        .struct_names(true)
        .depth_limit(2);
    let scenes = hard_scenes();
    for (file, scene) in &scenes {
        let text =
            ron::ser::to_string_pretty(scene, config.clone()).map_err(std::io::Error::other)?;
        let header = "// Generated by `harmonic-lab stability --write-scenes scenes/hard`: one case of the hard-case suite.\n";
        std::fs::write(dir.join(file), format!("{header}{text}\n"))?;
    }
    Ok(scenes.len())
}
