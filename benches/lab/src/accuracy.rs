//! `harmonic-lab bench`: speed against error. For each scene, integrator and step: wall time per
//! simulated second, RMS position error at t = 1 s against a converged RK4 reference, max strain
//! against the static strain, energy drift, and whether it stayed bounded.

// A harness over scenes it generates itself: a failure there is a bug in the harness.
#![allow(clippy::expect_used)]

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use harmonic::glam::DVec3;

use crate::{stability, statics};
use harmonic::internals::buffers::{GatherOptions, Packed};
use harmonic::internals::integrate::{Integrator, Solver};
use harmonic::internals::{metrics, step_control};
use harmonic::scene::{Anchor, Cloth, Plane, Rope, Scene, SpringSpec};

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

pub const CONTENDERS: [Integrator; 9] = [
    Integrator::Harmonic,
    Integrator::HarmonicGs,
    Integrator::HarmonicSgs,
    Integrator::HarmonicForced,
    Integrator::HarmonicForcedGs,
    Integrator::SymplecticEuler,
    Integrator::ImplicitEuler,
    Integrator::ThetaMg,
    Integrator::Xpbd,
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
    pub stable: bool,
    /// Found by bisecting toward the cheapest step within the default rule, not a ladder step.
    pub edge: bool,
}

/// Positions at `T` after `steps` steps; `None` if it blew up. Also max strain and energy drift.
pub fn simulate(
    packed: &Packed,
    integrator: Integrator,
    g: DVec3,
    steps: u64,
    e_ref: f64,
) -> Option<(Vec<DVec3>, f64, f64)> {
    let h = T / steps as f64;
    let mut p = packed.clone();
    let mut solver = Solver::new(integrator, false, g);
    solver.prepare(&p, h).ok()?;
    let e0 = metrics::energy(&p, g);
    let mut max_strain = metrics::max_strain(&p);
    for step in 1..=steps {
        solver.substep(&mut p, h).ok()?;
        // Strain every 8th step (and the last): a full pass costs as much as a step.
        if step % 8 == 0 || step == steps {
            let strain = metrics::max_strain(&p);
            if strain.is_nan() || strain > stability::BLOWUP_STRAIN {
                return None;
            }
            max_strain = max_strain.max(strain);
        }
    }
    metrics::first_non_finite(&p).is_none().then(|| {
        (
            p.x.clone(),
            max_strain,
            (metrics::energy(&p, g) - e0) / e_ref,
        )
    })
}

/// Median wall time of `repeats` bare runs (no diagnostics).
fn time_runs(packed: &Packed, integrator: Integrator, g: DVec3, steps: u64, repeats: u32) -> f64 {
    let h = T / steps as f64;
    let mut samples: Vec<f64> = (0..repeats.max(1))
        .map(|_| {
            let mut p = packed.clone();
            let mut solver = Solver::new(integrator, false, g);
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
    fn on(&self, integrator: Integrator) -> &Packed {
        if integrator.runs_on_grids(false) {
            self.grid
        } else {
            self.packed
        }
    }

    /// Times a stable run by `repeats` bare runs.
    fn time(&self, row: &mut Row, integrator: Integrator, repeats: u32) {
        row.wall = time_runs(self.on(integrator), integrator, self.g, row.steps, repeats);
    }

    /// One run at `steps` per simulated second; timed by `repeats` bare runs (none: untimed)
    /// when stable.
    fn run(&self, integrator: Integrator, steps: u64, repeats: u32) -> Row {
        let outcome = simulate(self.on(integrator), integrator, self.g, steps, self.e_ref);
        let (rms_error, max_strain, energy_drift, stable) = match outcome {
            Some((x, s, e)) => (rms(&x, self.reference), s, e, true),
            None => (f64::NAN, f64::NAN, f64::NAN, false),
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

fn ladder(packed: &Packed, integrator: Integrator) -> Vec<u64> {
    let c = step_control::choose(packed, integrator, T);
    let large = packed.spring_count() > LARGE;
    match (c.limit, large) {
        (Some(_), false) => {
            let n = c.substeps as u64;
            vec![(n / 2).max(1), n, 2 * n, 4 * n]
        }
        (Some(_), true) => {
            let n = c.substeps as u64;
            vec![(n / 2).max(1), n, 2 * n]
        }
        (None, false) => vec![30, 60, 120, 240, 480, 960, 1920, 3840],
        (None, true) if integrator == Integrator::ImplicitEuler => vec![30, 60, 120, 240],
        (None, true) if integrator == Integrator::ThetaMg => vec![30, 60, 120, 240, 480, 960],
        (None, true) => vec![60, 240, 960, 3840],
    }
}

/// The reference for a scene: RK4 at a quarter of its automatic step (an eighth on small scenes), and
/// the RMS change from the run at twice that step (a bound on the reference's own error,
/// about 1/15 of it for a fourth-order method).
pub fn reference(packed: &Packed, g: DVec3) -> (Vec<DVec3>, u64, f64, f64) {
    let factor = if packed.spring_count() > LARGE { 2 } else { 4 };
    let n = factor * step_control::choose(packed, Integrator::Rk4, T).substeps as u64;
    // `n` steps; the reference itself takes 2n.
    let a = simulate(packed, Integrator::Rk4, g, n, 1.0)
        .expect("RK4 reference is stable")
        .0;
    let (b, max_strain, _) =
        simulate(packed, Integrator::Rk4, g, 2 * n, 1.0).expect("RK4 reference is stable");
    let change = rms(&a, &b);
    (b, 2 * n, change, max_strain)
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
    pub integrators: Vec<Integrator>,
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
        match self.stiffen {
            Some(f) if !(f.is_finite() && f > 0.0) => {
                Err(format!("--stiffen {f}: expected a finite factor > 0"))
            }
            _ => Ok(()),
        }
    }

    fn integrators(&self) -> Vec<Integrator> {
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

/// Runs every selected case; `progress` is told after each run (done, total, label).
pub fn measure(
    quick: bool,
    repeats: u32,
    selection: &Selection,
    mut progress: impl FnMut(usize, usize, &str),
) -> (Vec<Row>, Vec<Reference>) {
    let named = |c: &Case| selection.scenes.iter().any(|s| s == c.name);
    let cases: Vec<Case> = cases(quick)
        .into_iter()
        .filter(|c| selection.scenes.is_empty() || named(c))
        .chain(extra_cases().into_iter().filter(named))
        .map(|c| Case {
            name: c.name,
            scene: stiffened(c.scene, selection.stiffen.unwrap_or(1.0)),
        })
        .collect();
    let contenders = selection.integrators();
    let plan: Vec<(usize, Integrator, u64)> = cases
        .iter()
        .enumerate()
        .flat_map(|(ci, case)| {
            let p = Packed::gather(&case.scene.build().world).expect("bench scenes are consistent");
            contenders
                .iter()
                .flat_map(|&i| {
                    let steps = if selection.steps.is_empty() {
                        ladder(&p, i)
                    } else {
                        selection.steps.clone()
                    };
                    steps.into_iter().map(move |n| (ci, i, n))
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let with_peer = cfg!(feature = "rapier") && selection.integrators.is_empty();
    let peer_runs = if with_peer {
        cases.iter().filter(|c| !c.scene.cloths.is_empty()).count() * RAPIER_SUBSTEPS.len()
    } else {
        0
    };
    let mut total = plan.len() + cases.len() + peer_runs;
    let mut done = 0;
    let mut rows = Vec::new();
    let mut refs = Vec::new();
    for (ci, case) in cases.iter().enumerate() {
        let world = case.scene.build().world;
        let packed = Packed::gather(&world).expect("bench scenes are consistent");
        // The form the simulation steps a cloth in, for the integrators with a grid pass.
        let grid = Packed::gather_with(
            &world,
            GatherOptions {
                keep_grids: true,
                colouring: false,
            },
        )
        .expect("bench scenes are consistent");
        let g = DVec3::from(case.scene.gravity);
        progress(done, total, &format!("{}: RK4 reference", case.name));
        let (reference, steps, change, max_strain) = reference(&packed, g);
        done += 1;
        progress(done, total, &format!("{}: static equilibrium", case.name));
        // Net acceleration below 1e-5 g: well under the strain digits reported.
        let relaxed = statics::relax(&packed, g, 1e-5 * g.length(), 400_000);
        let static_strain = statics::static_strain(&packed, &relaxed);
        refs.push(Reference {
            scene: case.name,
            stiffen: selection.stiffen.unwrap_or(1.0),
            steps,
            change,
            max_strain,
            still: rms(&packed.x, &reference),
            settled: rms(&relaxed.positions, &reference),
        });
        let e_ref = (0..packed.particle_count())
            .map(|i| packed.mass(i))
            .filter(|m| m.is_finite())
            .sum::<f64>()
            * g.length()
            * 1.0;
        let hc = stability::h_crit(&packed);
        let runner = Runner {
            scene: case.name,
            packed: &packed,
            grid: &grid,
            g,
            e_ref,
            reference: &reference,
            hc,
            static_strain,
        };
        // A large scene's ladder is timed once (each run is seconds long); the edges, which
        // the headline ratios compare, get every repeat.
        let ladder_repeats = if packed.spring_count() > LARGE {
            1
        } else {
            repeats.max(1)
        };
        for &(_, integrator, steps) in plan.iter().filter(|r| r.0 == ci) {
            progress(
                done,
                total,
                &format!("{}: {integrator} at {steps} steps/s", case.name),
            );
            rows.push(runner.run(integrator, steps, ladder_repeats));
            done += 1;
        }
        for &integrator in &contenders {
            let ladder: Vec<&Row> = rows
                .iter()
                .filter(|r| r.scene == case.name && r.integrator == integrator.name())
                .collect();
            let Some((mut lo, mut hi)) = edge_bracket(&ladder, max_strain) else {
                continue;
            };
            let bisections = bisections_to_resolve(lo, hi);
            total += bisections + 1;
            let mut best: Option<Row> = None;
            for k in 0..bisections {
                if hi - lo < 2 {
                    // No step count left between them: count the probes not run.
                    done += bisections - k;
                    break;
                }
                let mid = ((lo as f64 * hi as f64).sqrt().round() as u64).clamp(lo + 1, hi - 1);
                progress(
                    done,
                    total,
                    &format!("{}: {integrator} edge, {mid} steps/s", case.name),
                );
                done += 1;
                let probe = runner.run(integrator, mid, 0);
                if within_rule(&probe, max_strain) {
                    hi = mid;
                    best = Some(probe);
                } else {
                    lo = mid;
                }
            }
            if let Some(mut row) = best {
                progress(
                    done,
                    total,
                    &format!("{}: {integrator} edge, timing", case.name),
                );
                runner.time(&mut row, integrator, repeats.max(1));
                row.edge = true;
                rows.push(row);
            }
            done += 1;
        }
        // Each edge row next to its integrator's ladder, in step order.
        let first = rows
            .iter()
            .position(|r| r.scene == case.name)
            .unwrap_or(rows.len());
        rows[first..].sort_by_key(|r| {
            let k = contenders.iter().position(|i| i.name() == r.integrator);
            (k, r.steps)
        });
        #[cfg(feature = "rapier")]
        if let (true, Some(cloth)) = (with_peer, case.scene.cloths.first()) {
            for substeps in RAPIER_SUBSTEPS {
                progress(
                    done,
                    total,
                    &format!("{}: rapier soft body, {substeps} substeps", case.name),
                );
                done += 1;
                let mut walls = Vec::new();
                let mut last = None;
                let reps = if packed.spring_count() > LARGE {
                    1
                } else {
                    repeats.max(1)
                };
                // The peak strain over the run, sampled after every 1/60 s step (as ours is
                // every 8th substep), measured on our springs.
                let mut frame = packed.clone();
                let mut strain = 0.0f64;
                for _ in 0..reps {
                    strain = 0.0;
                    let observe = |x: &[DVec3]| {
                        frame.x.copy_from_slice(x);
                        strain = strain.max(metrics::max_strain(&frame));
                    };
                    match crate::peer::run_cloth(cloth, g, T, substeps, observe) {
                        Ok((x, wall)) => {
                            walls.push(wall);
                            last = Some(x);
                        }
                        Err(_) => break,
                    }
                }
                walls.sort_by(f64::total_cmp);
                if let Some(x) = last {
                    let stable =
                        x.iter().all(|p| p.is_finite()) && strain <= stability::BLOWUP_STRAIN;
                    rows.push(Row {
                        scene: case.name,
                        integrator: PEER.to_string(),
                        steps: 60 * substeps as u64,
                        step_ratio: T / (60 * substeps) as f64 / hc,
                        wall: walls[walls.len() / 2],
                        rms_error: if stable {
                            rms(&x, &reference)
                        } else {
                            f64::NAN
                        },
                        max_strain: strain,
                        static_strain,
                        energy_drift: f64::NAN,
                        stable,
                        edge: false,
                    });
                }
            }
        }
    }
    progress(done, total, "done");
    (rows, refs)
}

pub fn csv(rows: &[Row]) -> String {
    let mut out = String::from("scene,integrator,steps_per_s,h_over_hc,wall_s_per_sim_s,rms_error_m,max_strain,static_strain,energy_drift,stable,edge\n");
    for r in rows {
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{}",
            r.scene,
            r.integrator,
            r.steps,
            r.step_ratio,
            r.wall,
            r.rms_error,
            r.max_strain,
            r.static_strain,
            r.energy_drift,
            r.stable,
            r.edge
        );
    }
    out
}

/// Whether a run is inside the default rule: stable, within [`RULE_ERROR`] RMS and within
/// [`RULE_STRAIN`] of the reference's max strain.
pub fn within_rule(r: &Row, reference_strain: f64) -> bool {
    r.stable && r.rms_error <= RULE_ERROR && (r.max_strain - reference_strain).abs() <= RULE_STRAIN
}

/// The fastest of some rows inside the default rule.
pub fn fastest_within<'a>(
    rows: impl IntoIterator<Item = &'a Row>,
    reference_strain: f64,
) -> Option<&'a Row> {
    rows.into_iter()
        .filter(|r| within_rule(r, reference_strain))
        .min_by(|a, b| a.wall.total_cmp(&b.wall))
}

/// How close the bisection places an integrator's edge of the rule: within a factor of
/// 2^(1/16), 4.4 % (four bisections of the ladder's factor of 2).
pub const EDGE_RESOLUTION: f64 = 1.044_273_782_427_413_8;

/// Geometric bisections that narrow `hi / lo` to [`EDGE_RESOLUTION`].
pub fn bisections_to_resolve(lo: u64, hi: u64) -> usize {
    let halvings = ((hi as f64 / lo as f64).ln() / EDGE_RESOLUTION.ln()).log2();
    // The tolerance keeps an exact factor of 2 at four bisections despite rounding.
    (halvings - 1e-9).ceil().max(0.0) as usize
}

/// The steps per second that bracket an integrator's edge of the default rule on its ladder:
/// the most steps that fell outside and the fewest that fell inside, when both were tried and
/// the outside run is the cheaper one.
pub fn edge_bracket(ladder: &[&Row], reference_strain: f64) -> Option<(u64, u64)> {
    let inside = |r: &Row| within_rule(r, reference_strain);
    let hi = ladder.iter().filter(|r| inside(r)).map(|r| r.steps).min()?;
    let lo = ladder
        .iter()
        .filter(|r| !inside(r) && r.steps < hi)
        .map(|r| r.steps)
        .max()?;
    (hi - lo >= 2).then_some((lo, hi))
}

/// The default-integrator rule: error ≤ 1 cm RMS and max strain within 1 percentage point.
pub const RULE_ERROR: f64 = 0.01;
pub const RULE_STRAIN: f64 = 0.01;

pub fn markdown(rows: &[Row], refs: &[Reference]) -> String {
    let mut out = String::new();
    for reference in refs {
        let scene = reference.scene;
        let smallest = rows
            .iter()
            .filter(|r| r.scene == scene && r.stable)
            .map(|r| r.rms_error)
            .fold(f64::INFINITY, f64::min);
        if reference.stiffen == 1.0 {
            let _ = writeln!(out, "### {scene}\n");
        } else {
            let _ = writeln!(out, "### {scene}, every stiffness ×{}\n", reference.stiffen);
        }
        let _ = writeln!(
            out,
            "Reference: RK4 at {} steps/s, max strain {:.4}; halving its step moves it by {:.2e} m RMS, {:.2}% of the smallest error below.\n",
            reference.steps,
            reference.max_strain,
            reference.change,
            100.0 * reference.change / smallest
        );
        // The error criterion tells integrators apart only below what doing nothing scores.
        let _ = writeln!(
            out,
            "Baselines: never moving scores {:.3e} m RMS, the static equilibrium {:.3e} m.\n",
            reference.still, reference.settled
        );
        if reference.still <= RULE_ERROR {
            let _ = writeln!(
                out,
                "**Never moving is within 1 cm here: the rule cannot tell a run from one that stood still, and this scene's ratios say nothing.**\n"
            );
        }
        match fastest_within(
            rows.iter().filter(|r| r.scene == scene),
            reference.max_strain,
        ) {
            Some(r) => {
                let _ = writeln!(
                    out,
                    "Fastest within 1 cm RMS and 1 percentage point of strain: **{}** at {} steps/s, {:.3} s per simulated second.\n",
                    r.integrator, r.steps, r.wall
                );
            }
            None => {
                let _ = writeln!(
                    out,
                    "No run is within 1 cm RMS and 1 percentage point of strain.\n"
                );
            }
        }
        frontier(&mut out, rows, scene, reference.max_strain);
        let _ = writeln!(out, "| integrator | steps/s | h/h_c | wall s per sim. s | RMS error (m) | max strain | static strain | energy drift | stable |");
        let _ = writeln!(out, "|---|---|---|---|---|---|---|---|---|");
        for r in rows.iter().filter(|r| r.scene == scene) {
            if r.stable {
                let _ = writeln!(
                    out,
                    "| {} | {} | {:.3} | {:.4} | {:.3e} | {:.4} | {:.4} | {:+.2e} | yes |",
                    r.integrator,
                    steps_cell(r),
                    r.step_ratio,
                    r.wall,
                    r.rms_error,
                    r.max_strain,
                    r.static_strain,
                    r.energy_drift
                );
            } else {
                let _ = writeln!(
                    out,
                    "| {} | {} | {:.3} | - | - | - | {:.4} | - | no |",
                    r.integrator,
                    steps_cell(r),
                    r.step_ratio,
                    r.static_strain
                );
            }
        }
        let _ = writeln!(out);
    }
    out
}

/// The integrators of some rows, each once, in order of first appearance.
fn integrators_in<'a>(rows: impl Iterator<Item = &'a Row>) -> Vec<&'a str> {
    let mut names: Vec<&str> = Vec::new();
    for r in rows {
        if !names.contains(&r.integrator.as_str()) {
            names.push(&r.integrator);
        }
    }
    names
}

/// A ladder step as is; a bisected one marked.
fn steps_cell(r: &Row) -> String {
    if r.edge {
        format!("{} (edge)", r.steps)
    } else {
        r.steps.to_string()
    }
}

/// Each integrator's cheapest run within the default rule, and its wall time over symplectic
/// Euler's: a speed ratio between runs inside the same error bounds.
fn frontier(out: &mut String, rows: &[Row], scene: &str, reference_strain: f64) {
    let names = integrators_in(rows.iter().filter(|r| r.scene == scene));
    let best = |name: &str| {
        let runs = rows
            .iter()
            .filter(|r| r.scene == scene && r.integrator == name);
        fastest_within(runs, reference_strain)
    };
    let euler = best(Integrator::SymplecticEuler.name());
    let _ = writeln!(
        out,
        "Each integrator's cheapest run within the rule (an edge row is bisected between the ladder's steps to within {:.1} %, taking a finer step to stay inside):\n",
        100.0 * (EDGE_RESOLUTION - 1.0)
    );
    let _ = writeln!(
        out,
        "| integrator | steps/s | h/h_c | wall s per sim. s | RMS error (m) | max strain | time ÷ symplectic Euler's |"
    );
    let _ = writeln!(out, "|---|---|---|---|---|---|---|");
    for name in names {
        match best(name) {
            Some(r) => {
                let ratio = euler.map_or("-".to_string(), |e| format!("{:.2}", r.wall / e.wall));
                let _ = writeln!(
                    out,
                    "| {name} | {} | {:.3} | {:.4} | {:.3e} | {:.4} | {ratio} |",
                    steps_cell(r),
                    r.step_ratio,
                    r.wall,
                    r.rms_error,
                    r.max_strain
                );
            }
            None => {
                let _ = writeln!(out, "| {name} | none within the rule | - | - | - | - | - |");
            }
        }
    }
    let _ = writeln!(out);
}

/// Log-log chart of wall time per simulated second against RMS error, one series per integrator,
/// with the 1 cm rule and what never moving scores drawn as vertical lines.
pub fn chart(rows: &[Row], reference: &Reference, svg: &Path, png: &Path) -> Result<(), String> {
    let scene = reference.scene;
    use plotters::prelude::*;
    // PNG text needs a font; the embedded one avoids depending on system fonts.
    let _ =
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    let pts: Vec<&Row> = rows
        .iter()
        .filter(|r| r.scene == scene && r.stable && r.rms_error > 0.0)
        .collect();
    if pts.is_empty() {
        return Ok(());
    }
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64);
    for r in &pts {
        x0 = x0.min(r.rms_error);
        x1 = x1.max(r.rms_error);
        y0 = y0.min(r.wall);
        y1 = y1.max(r.wall);
    }
    let marks = [(RULE_ERROR, "1 cm rule"), (reference.still, "never moving")];
    for (x, _) in marks {
        x0 = x0.min(x);
        x1 = x1.max(x);
    }
    let (x0, x1, y0, y1) = (x0 / 2.0, x1 * 2.0, y0 / 2.0, y1 * 2.0);
    fn draw<DB: DrawingBackend>(
        root: DrawingArea<DB, plotters::coord::Shift>,
        scene: &str,
        pts: &[&Row],
        marks: &[(f64, &str)],
        range: (f64, f64, f64, f64),
    ) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let (x0, x1, y0, y1) = range;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("{scene}: speed against error (t = 1 s)"),
                ("sans-serif", 22),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("RMS position error against the RK4 reference (m)")
            .y_desc("wall time per simulated second (s)")
            .x_label_formatter(&|v| format!("{v:.0e}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()
            .map_err(|e| e.to_string())?;
        for &(x, label) in marks {
            let grey = RGBColor(110, 110, 110);
            chart
                .draw_series(LineSeries::new(
                    vec![(x, y0), (x, y1)],
                    grey.stroke_width(1),
                ))
                .map_err(|e| e.to_string())?;
            chart
                .draw_series(std::iter::once(Text::new(
                    label.to_string(),
                    (x * 1.08, y0 * 1.15),
                    ("sans-serif", 13).into_font().color(&grey),
                )))
                .map_err(|e| e.to_string())?;
        }
        let names = integrators_in(pts.iter().copied());
        for (k, name) in names.iter().enumerate() {
            let colour = Palette99::pick(k).to_rgba();
            let mut runs: Vec<&&Row> = pts.iter().filter(|r| r.integrator == *name).collect();
            runs.sort_by_key(|r| r.steps);
            let series: Vec<(f64, f64)> = runs.iter().map(|r| (r.rms_error, r.wall)).collect();
            chart
                .draw_series(LineSeries::new(series.clone(), colour.stroke_width(2)))
                .map_err(|e| e.to_string())?
                .label(*name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                });
            chart
                .draw_series(series.iter().map(|&p| Circle::new(p, 4, colour.filled())))
                .map_err(|e| e.to_string())?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())
    }
    let range = (x0, x1, y0, y1);
    draw(
        SVGBackend::new(svg, (900, 600)).into_drawing_area(),
        scene,
        &pts,
        &marks,
        range,
    )?;
    draw(
        BitMapBackend::new(png, (900, 600)).into_drawing_area(),
        scene,
        &pts,
        &marks,
        range,
    )?;
    Ok(())
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
