//! `harmonic-lab bench`: speed against error. For each scene, integrator and step: wall time per
//! simulated second, RMS position error at t = 1 s against a converged RK4 reference, max strain
//! against the static strain, energy drift, and whether it stayed bounded.

// A harness over scenes it generates itself: a failure there is a bug in the harness.
#![allow(clippy::expect_used)]

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use harmonic::glam::DVec3;

use crate::research::{self, Method, Stepper};
use crate::{stability, statics};
use harmonic::internals::buffers::{GatherOptions, Packed};
use harmonic::internals::{metrics, step_control};
use harmonic::scene::{Anchor, Cloth, Plane, Rope, Scene, SpringSpec};
use harmonic::Integrator;

mod measure;
mod report;
pub use measure::*;
pub use report::*;

/// Simulated time of every run (s).
pub const T: f64 = 1.0;

/// A bench scene.
pub struct Case {
    pub name: &'static str,
    pub scene: Scene,
}

fn spec(stiffness: f64, zeta: f64) -> SpringSpec {
    SpringSpec {
        stiffness: Some(stiffness),
        damping_ratio: Some(zeta),
        ..Default::default()
    }
}

fn empty(gravity: [f64; 3]) -> Scene {
    Scene {
        substeps: Some(1),
        gravity,
        seconds: Some(T),
        ..Scene::new(T)
    }
}

/// A vertical `n`×`n` cloth, 1 m and 1 kg, pinned at its two top corners, released flat at
/// rest length with every free particle thrown sideways, in its plane, at `throw` m/s (a gust):
/// it swings sideways and sags, and stays in its plane. Without the throw the stiff cloth moves
/// under 1 cm by t = 1 s, so a run that never moved would pass a 1 cm error criterion. (A
/// cloth swinging out of its plane folds, and its state at t = 1 s is then chaotic: the
/// reference itself does not converge, which says nothing about the integrators.)
pub fn swinging_cloth(n: u32, stiffness: f64, throw: f64) -> Scene {
    let mut s = empty([0.0, -9.81, 0.0]);
    s.cloths = vec![Cloth {
        origin: [-0.5, 1.0, 0.0],
        size: (1.0, 1.0),
        resolution: (n, n),
        plane: Plane::Vertical,
        mass: 1.0,
        structural: spec(stiffness, 0.2),
        shear: Some(spec(stiffness, 0.2)),
        bend: Some(spec(stiffness / 4.0, 0.2)),
        pins: vec![Anchor::TopLeft, Anchor::TopRight],
        velocity: [throw, 0.0, 0.0],
        air: None,
        tethers: None,
        stretch_limit: None,
        tearing: None,
        self_collision: None,
    }];
    s
}

/// A 20-link chain released horizontally from a pin, ζ = 0.2.
pub fn swinging_chain() -> Scene {
    let mut s = empty([0.0, -9.81, 0.0]);
    s.ropes = vec![Rope {
        start: [0.0; 3],
        end: [1.0, 0.0, 0.0],
        particles: 21,
        mass: 0.5,
        spring: spec(2e4, 0.2),
        pin_start: true,
        pin_end: false,
        bend: None,
    }];
    s
}

/// A horizontal `n`×`n` cloth, 1 m and 1 kg, pinned at two corners of one edge and released
/// at rest: it falls and swings down like a dropped curtain, out of its plane. Run only when
/// named (`--scenes drop16,drop32`), for the stiffer-scenes study: a stiff cloth that still moves.
pub fn dropped_cloth(n: u32, stiffness: f64) -> Scene {
    let mut s = swinging_cloth(n, stiffness, 0.0);
    s.cloths[0].plane = Plane::Horizontal;
    s
}

/// Sideways throw of the bench cloths (m/s).
pub const THROW: f64 = 2.0;

/// Scenes the bench runs only when `--scenes` names them.
pub fn extra_cases() -> Vec<Case> {
    vec![
        Case {
            name: "drop16",
            scene: dropped_cloth(16, 500.0),
        },
        Case {
            name: "drop32",
            scene: dropped_cloth(32, 1000.0),
        },
    ]
}

pub fn cases(quick: bool) -> Vec<Case> {
    let mut v = vec![
        Case {
            name: "chain20",
            scene: swinging_chain(),
        },
        Case {
            name: "cloth16",
            scene: swinging_cloth(16, 500.0, THROW),
        },
    ];
    if !quick {
        v.push(Case {
            name: "cloth128",
            scene: swinging_cloth(128, 2000.0, THROW),
        });
    }
    v
}

/// Name of the rapier soft-body peer in reports.
pub const PEER: &str = "rapier-soft-body";
/// rapier substeps per 1/60 s step tried: its default (4), then finer, down to a step at which
/// it reaches 1 cm on the 128² cloth (128).
pub const RAPIER_SUBSTEPS: [usize; 6] = [4, 8, 16, 32, 64, 128];

pub const CONTENDERS: [Method; 9] = [
    Method::Engine(Integrator::Harmonic),
    Method::Engine(Integrator::HarmonicGs),
    Method::HARMONIC_SGS,
    Method::HARMONIC_FORCED,
    Method::HARMONIC_FORCED_GS,
    Method::Engine(Integrator::SymplecticEuler),
    Method::Engine(Integrator::ImplicitEuler),
    Method::Engine(Integrator::ThetaMg),
    Method::Engine(Integrator::Xpbd),
];

/// One measured run.
#[derive(Clone, Debug)]
pub struct Row {
    pub scene: &'static str,
    pub integrator: String,
    /// Steps per simulated second.
    pub steps: u64,
    /// `h/h_c` of the stiffest spring.
    pub step_ratio: f64,
    /// Median wall time per simulated second (s).
    pub wall: f64,
    pub rms_error: f64,
    pub max_strain: f64,
    pub static_strain: f64,
    pub energy_drift: f64,
    /// The energy audit's residual at the end and its peak, shares of the energy scale.
    pub residual: f64,
    pub peak_residual: f64,
    pub stable: bool,
    /// Found by bisecting toward the cheapest step within the default rule, not a ladder step.
    pub edge: bool,
}

/// What a run of [`simulate`] ends with: positions at `T`, max strain, energy drift, and the
/// energy audit's residual and peak residual (the drift and residuals as shares of `e_ref`).
pub type Outcome = (Vec<DVec3>, f64, f64, (f64, f64));

/// Positions at `T` after `steps` steps; `None` if it blew up. Also max strain, energy drift
/// and the energy audit's books (booked as the engine books them, every 8th step a "frame").
pub fn simulate(
    packed: &Packed,
    integrator: impl Into<Method>,
    g: DVec3,
    steps: u64,
    e_ref: f64,
) -> Option<Outcome> {
    let integrator = integrator.into();
    use harmonic::internals::audit::Auditor;
    let h = T / steps as f64;
    let mut p = packed.clone();
    let mut solver = Stepper::new(integrator, false, g);
    solver.prepare(&p, h).ok()?;
    let e0 = metrics::energy(&p, g);
    let mut books = Auditor::default();
    books.prepare(&p, solver.grid_audits());
    let law = integrator.damper_law();
    let start = books.energy(&p, g);
    books.begin_frame(start, e_ref);
    let mut max_strain = metrics::max_strain(&p);
    for step in 1..=steps {
        books.begin_substep(&p);
        solver.substep(&mut p, h).ok()?;
        books.damping(&p, law, h, solver.grid_damper_loss());
        // Strain every 8th step (and the last): a full pass costs as much as a step.
        if step % 8 == 0 || step == steps {
            let e = books.energy(&p, g);
            books.end_frame(e, false);
            books.begin_frame(e, e_ref);
            let strain = metrics::max_strain(&p);
            if strain.is_nan() || strain > stability::BLOWUP_STRAIN {
                return None;
            }
            max_strain = max_strain.max(strain);
        }
    }
    let run = books.run;
    metrics::first_non_finite(&p).is_none().then(|| {
        (
            p.x.clone(),
            max_strain,
            (metrics::energy(&p, g) - e0) / e_ref,
            (run.residual / e_ref, run.peak_residual / e_ref),
        )
    })
}

/// Median wall time of `repeats` bare runs (no diagnostics).
fn time_runs(packed: &Packed, integrator: Method, g: DVec3, steps: u64, repeats: u32) -> f64 {
    let h = T / steps as f64;
    let mut samples: Vec<f64> = (0..repeats.max(1))
        .map(|_| {
            let mut p = packed.clone();
            let mut solver = Stepper::new(integrator, false, g);
            let _ = solver.prepare(&p, h);
            let t = Instant::now();
            for _ in 0..steps {
                let _ = solver.substep(&mut p, h);
            }
            t.elapsed().as_secs_f64()
        })
        .collect();
    samples.sort_by(f64::total_cmp);
    samples[samples.len() / 2]
}

/// What one scene's runs share.
struct Runner<'a> {
    scene: &'static str,
    packed: &'a Packed,
    /// The form the simulation steps a cloth in, for the integrators with a grid pass.
    grid: &'a Packed,
    g: DVec3,
    /// Energy scale of the drift column.
    e_ref: f64,
    reference: &'a [DVec3],
    hc: f64,
    static_strain: f64,
}

impl Runner<'_> {
    /// The buffers `integrator` runs on.
    fn on(&self, integrator: Method) -> &Packed {
        if integrator.runs_on_grids(false) {
            self.grid
        } else {
            self.packed
        }
    }

    /// Times a stable run by `repeats` bare runs.
    fn time(&self, row: &mut Row, integrator: Method, repeats: u32) {
        row.wall = time_runs(self.on(integrator), integrator, self.g, row.steps, repeats);
    }

    /// One run at `steps` per simulated second; timed by `repeats` bare runs (none: untimed)
    /// when stable.
    fn run(&self, integrator: Method, steps: u64, repeats: u32) -> Row {
        let outcome = simulate(self.on(integrator), integrator, self.g, steps, self.e_ref);
        let (rms_error, max_strain, energy_drift, (residual, peak_residual), stable) = match outcome
        {
            Some((x, s, e, r)) => (rms(&x, self.reference), s, e, r, true),
            None => (f64::NAN, f64::NAN, f64::NAN, (f64::NAN, f64::NAN), false),
        };
        let mut row = Row {
            scene: self.scene,
            integrator: integrator.name().to_string(),
            steps,
            step_ratio: T / steps as f64 / self.hc,
            wall: f64::NAN,
            rms_error,
            max_strain,
            static_strain: self.static_strain,
            energy_drift,
            residual,
            peak_residual,
            stable,
            edge: false,
        };
        if repeats > 0 && stable {
            self.time(&mut row, integrator, repeats);
        }
        row
    }
}

pub use harmonic::internals::metrics::rms;

/// Step counts per simulated second tried for an integrator: its automatic choice ×{½, 1, 2, 4}
/// (½ probes the edge of its stability region), or a fixed ladder when it has no limit.
/// Scenes with more springs than this get a shorter ladder (each run is seconds long).
const LARGE: usize = 20_000;

fn ladder(packed: &Packed, integrator: Method) -> Vec<u64> {
    let c = research::choose(packed, integrator, T);
    let large = packed.spring_count() > LARGE;
    // An integrator without a stability limit (XPBD's bound is for accuracy) gets the wide
    // ladder, large steps included.
    let limit = c.limit.filter(|_| integrator.stable_omega_h(0.0).is_some());
    match (limit, large) {
        (Some(_), false) => {
            let n = c.substeps as u64;
            vec![(n / 2).max(1), n, 2 * n, 4 * n]
        }
        (Some(_), true) => {
            let n = c.substeps as u64;
            vec![(n / 2).max(1), n, 2 * n]
        }
        (None, false) => vec![30, 60, 120, 240, 480, 960, 1920, 3840],
        (None, true) if integrator == Method::Engine(Integrator::ImplicitEuler) => {
            vec![30, 60, 120, 240]
        }
        (None, true) if integrator == Method::Engine(Integrator::ThetaMg) => {
            vec![30, 60, 120, 240, 480, 960]
        }
        (None, true) => vec![60, 240, 960, 3840],
    }
}

/// The reference for a scene: RK4 at a quarter of its automatic step (an eighth on small scenes), and
/// the RMS change from the run at twice that step (a bound on the reference's own error,
/// about 1/15 of it for a fourth-order method).
/// Returns an error where the reference would blow up: it ran out of room in its step
/// choice (the scene too stiff for RK4 at [`step_control::MAX_SUBSTEPS`] a second).
pub fn reference(packed: &Packed, g: DVec3) -> Result<(Vec<DVec3>, u64, f64, f64), String> {
    let n = reference_steps(packed)?;
    let unstable = || "the RK4 reference blew up (a scene too stiff for its steps)".to_string();
    // `n` steps; the reference itself takes 2n.
    let a = simulate(packed, Method::RK4, g, n, 1.0)
        .ok_or_else(unstable)?
        .0;
    let (b, max_strain, _, _) =
        simulate(packed, Method::RK4, g, 2 * n, 1.0).ok_or_else(unstable)?;
    let change = rms(&a, &b);
    Ok((b, 2 * n, change, max_strain))
}

/// The reference's coarser run's steps per simulated second; an error when RK4's stability
/// floor alone passes [`step_control::MAX_SUBSTEPS`].
pub fn reference_steps(packed: &Packed) -> Result<u64, String> {
    let factor = if packed.spring_count() > LARGE { 2 } else { 4 };
    let c = research::choose(packed, Method::RK4, T);
    if c.capped {
        return Err(format!(
            "the RK4 reference would need more than {} steps per simulated second \
             (ω_max = {:.3e} rad/s); lower --stiffen",
            step_control::MAX_SUBSTEPS,
            c.omega_max
        ));
    }
    Ok(factor * c.substeps as u64)
}

/// A scene's reference run: steps per second, RMS change when its step is halved, max strain.
#[derive(Clone, Debug)]
pub struct Reference {
    pub scene: &'static str,
    /// The stiffness factor of [`Selection::stiffen`] (1: the scene as it is).
    pub stiffen: f64,
    pub steps: u64,
    pub change: f64,
    pub max_strain: f64,
    /// RMS error of a run that never moves (the start state against the reference).
    pub still: f64,
    /// RMS error of the static equilibrium against the reference.
    pub settled: f64,
}

/// What a bench run covers; the default is everything.
#[derive(Clone, Debug, Default)]
pub struct Selection {
    /// Scene names (empty: all of [`cases`]; [`extra_cases`] run only when named).
    pub scenes: Vec<String>,
    /// Integrators (empty: all of [`CONTENDERS`], and rapier's cloth when built in).
    pub integrators: Vec<Method>,
    /// Step counts per simulated second instead of each integrator's ladder (empty: ladders).
    pub steps: Vec<u64>,
    /// Every spring's stiffness times this, damping ratios kept (None: the scenes as they are):
    /// where a stiffer scene moves the balance between small and large steps.
    pub stiffen: Option<f64>,
}

impl Selection {
    /// Checks the scene names against the cases the bench knows.
    pub fn validate(&self, quick: bool) -> Result<(), String> {
        let known: Vec<&str> = cases(quick).iter().map(|c| c.name).collect();
        let extra: Vec<&str> = extra_cases().iter().map(|c| c.name).collect();
        for s in &self.scenes {
            if !known.contains(&s.as_str()) && !extra.contains(&s.as_str()) {
                let note = if quick {
                    " (--quick leaves out cloth128)"
                } else {
                    ""
                };
                return Err(format!(
                    "--scenes {s}: the bench's scenes are {}{note}, and by name only {}",
                    known.join(", "),
                    extra.join(", ")
                ));
            }
        }
        if self.steps.contains(&0) {
            return Err("--steps: step counts must be ≥ 1".into());
        }
        let Some(f) = self.stiffen else {
            return Ok(());
        };
        if !(f.is_finite() && f > 0.0) {
            return Err(format!("--stiffen {f:?}: expected a finite factor > 0"));
        }
        // Every stiffened scene must still be a scene, and its RK4 reference within reach.
        let named = |c: &Case| self.scenes.is_empty() || self.scenes.iter().any(|s| s == c.name);
        let chosen = cases(quick).into_iter().filter(named);
        for case in chosen.chain(
            extra_cases()
                .into_iter()
                .filter(|c| !self.scenes.is_empty() && named(c)),
        ) {
            let scene = stiffened(case.scene, f);
            if let Some(issue) = scene.validate().first() {
                return Err(format!("--stiffen {f:?}: {}: {issue}", case.name));
            }
            let packed = Packed::gather(&scene.build().world).map_err(|e| e.to_string())?;
            reference_steps(&packed)
                .map_err(|steps| format!("--stiffen {f:?}: {}: {steps}", case.name))?;
        }
        Ok(())
    }

    fn integrators(&self) -> Vec<Method> {
        if self.integrators.is_empty() {
            CONTENDERS.to_vec()
        } else {
            self.integrators.clone()
        }
    }
}

/// `scene` with every spring's stiffness times `factor` (damping ratios, and so ζ, kept).
pub fn stiffened(mut scene: Scene, factor: f64) -> Scene {
    let mut scale = |spec: &mut SpringSpec| {
        if let Some(k) = spec.stiffness.as_mut() {
            *k *= factor;
        }
    };
    for c in &mut scene.cloths {
        scale(&mut c.structural);
        c.shear.iter_mut().for_each(&mut scale);
        c.bend.iter_mut().for_each(&mut scale);
    }
    for r in &mut scene.ropes {
        scale(&mut r.spring);
        r.bend.iter_mut().for_each(&mut scale);
    }
    scene
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(steps: u64, stable: bool, rms_error: f64, max_strain: f64) -> Row {
        Row {
            scene: "s",
            integrator: "i".into(),
            steps,
            step_ratio: 1.0,
            wall: 1.0 / steps as f64,
            rms_error,
            max_strain,
            static_strain: 0.0,
            energy_drift: 0.0,
            residual: 0.0,
            peak_residual: 0.0,
            stable,
            edge: false,
        }
    }

    #[test]
    fn the_edge_is_bracketed_by_the_cheapest_run_inside_and_the_next_cheaper_one() {
        let ladder = [
            row(100, false, f64::NAN, f64::NAN),
            row(200, true, 0.02, 0.5),
            row(400, true, 0.005, 0.5),
            row(800, true, 0.001, 0.5),
        ];
        let refs: Vec<&Row> = ladder.iter().collect();
        assert_eq!(edge_bracket(&refs, 0.5), Some((200, 400)));
        // A reference strain 2 points away puts every run outside.
        assert_eq!(edge_bracket(&refs, 0.52), None);
        // Everything inside from the cheapest rung: nothing to bisect.
        assert_eq!(edge_bracket(&refs[2..], 0.5), None);
        // Neighbouring step counts leave no step between them.
        let close = [row(10, false, f64::NAN, f64::NAN), row(11, true, 0.0, 0.5)];
        let refs: Vec<&Row> = close.iter().collect();
        assert_eq!(edge_bracket(&refs, 0.5), None);
    }

    #[test]
    fn the_report_says_when_standing_still_passes_the_rule() {
        let reference = |still: f64| Reference {
            scene: "s",
            stiffen: 1.0,
            steps: 1000,
            change: 1e-9,
            max_strain: 0.5,
            still,
            settled: still,
        };
        let rows = [row(100, true, 0.001, 0.5)];
        let warning = "rule cannot tell a run from one that stood still";
        assert!(markdown(&rows, &[reference(0.005)]).contains(warning));
        assert!(!markdown(&rows, &[reference(0.05)]).contains(warning));
    }

    #[test]
    fn stiffening_scales_every_spring_and_keeps_its_damping_ratio() {
        for scene in [swinging_cloth(4, 500.0, THROW), swinging_chain()] {
            let packed = |s: Scene| Packed::gather(&s.build().world).expect("bench scene");
            let base = packed(scene.clone());
            let stiff = packed(stiffened(scene, 100.0));
            assert_eq!(base.springs.len(), stiff.springs.len());
            for (a, b) in base.springs.iter().zip(&stiff.springs) {
                assert!(
                    (b.stiffness / a.stiffness - 100.0).abs() < 1e-9,
                    "{a:?} {b:?}"
                );
                assert!((b.zeta() - a.zeta()).abs() < 1e-12, "{a:?} {b:?}");
            }
            // h_c = π/ω0 with ω0 ∝ √κ.
            let ratio = stability::h_crit(&base) / stability::h_crit(&stiff);
            assert!((ratio - 10.0).abs() < 1e-9, "{ratio}");
        }
    }

    #[test]
    fn a_scene_run_only_by_name_is_accepted_by_name() {
        let named = |name: &str| Selection {
            scenes: vec![name.into()],
            ..Default::default()
        };
        assert!(named("drop16").validate(true).is_ok());
        let err = named("drop17").validate(true).unwrap_err();
        assert!(err.contains("by name only drop16"), "{err}");
        // The default report leaves it out.
        assert!(cases(false).iter().all(|c| c.name != "drop16"));
    }

    #[test]
    fn bisections_narrow_a_bracket_to_the_resolution() {
        assert_eq!(bisections_to_resolve(200, 400), 4);
        assert_eq!(bisections_to_resolve(60, 240), 5);
        for (lo, hi) in [(200u64, 400u64), (60, 240), (7646, 15292), (10, 11)] {
            let n = bisections_to_resolve(lo, hi) as i32;
            let left = (hi as f64 / lo as f64).powf(0.5f64.powi(n));
            assert!(
                left <= EDGE_RESOLUTION * (1.0 + 1e-12),
                "{lo}..{hi}: {left}"
            );
        }
    }
}
