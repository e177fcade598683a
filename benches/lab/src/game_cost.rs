//! `harmonic-lab game-cost`: a stiff cloth's look at a game's cost. The 128×128 cloth of 1 m and
//! 1 kg hanging from its two top corners, stiff (k = 1e4 N/m, the peers' benchmark cloth) at its
//! own automatic substeps and converged (twice them), against the shipped soft springs (200 Hz)
//! held by tethers, with and without a stretch limit: wall time per 60 Hz frame, peak
//! structural strain, and the RMS distance from the converged stiff cloth at t = 1 s, all from
//! one run; and what the tethers, the stretch limit and air cost beside the spring stage. With
//! more than one round, every cloth but the converged one runs once a round, the rounds one
//! after the other, and each time is the median over the rounds.

use std::time::{Duration, Instant};

use harmonic::internals::hanging_cloth;
use harmonic::scene::SpringSpec;
use harmonic::{Aero, Scene, Simulation, StageKind, StretchLimit, TetherSpec};

const N: usize = 128;

/// One cloth's run: its mean wall time per frame, its peak structural strain, its positions
/// at the end, its substeps at the end, and its stages' times summed.
struct Run {
    frame: f64,
    peak: f64,
    end: Vec<harmonic::glam::DVec3>,
    substeps: u32,
    integrate: Duration,
    tethers: Duration,
    stretch: Duration,
    air: Duration,
    /// The audit's, the gather's and the scatter's time summed.
    audit: Duration,
    gather: Duration,
    scatter: Duration,
}

/// The worst stretch of the cloth's structural springs (rest 1/127 m), a share of rest.
fn peak_strain(x: &[harmonic::glam::DVec3]) -> f64 {
    let rest = 1.0 / (N - 1) as f64;
    let mut worst: f64 = 0.0;
    for r in 0..N {
        for c in 0..N {
            let i = r * N + c;
            if c + 1 < N {
                worst = worst.max((x[i + 1] - x[i]).length() / rest - 1.0);
            }
            if r + 1 < N {
                worst = worst.max((x[i + N] - x[i]).length() / rest - 1.0);
            }
        }
    }
    worst
}

fn run(scene: &Scene, frames: u32) -> Result<Run, String> {
    let mut sim = Simulation::from_scene(scene).map_err(|e| e.to_string())?;
    let mut r = Run {
        frame: 0.0,
        peak: 0.0,
        end: Vec::new(),
        substeps: 0,
        integrate: Duration::ZERO,
        tethers: Duration::ZERO,
        stretch: Duration::ZERO,
        air: Duration::ZERO,
        audit: Duration::ZERO,
        gather: Duration::ZERO,
        scatter: Duration::ZERO,
    };
    let mut wall = Duration::ZERO;
    for _ in 0..frames {
        let t = Instant::now();
        let s = *sim.step().map_err(|e| e.to_string())?;
        wall += t.elapsed();
        r.integrate += s.stages[StageKind::Integrate];
        r.tethers += s.stages[StageKind::Tethers];
        r.stretch += s.stages[StageKind::StretchLimit];
        r.air += s.stages[StageKind::Air] + s.stages[StageKind::Forces];
        r.audit += s.audit_time;
        r.gather += s.gather;
        r.scatter += s.scatter;
        r.peak = r.peak.max(peak_strain(sim.positions()));
    }
    if let Some(f) = sim.diagnostics().failure {
        return Err(format!("{}: {f:?}", scene.name.as_deref().unwrap_or("?")));
    }
    r.frame = wall.as_secs_f64() / f64::from(frames);
    r.end = sim.positions().to_vec();
    r.substeps = sim.config().substeps;
    Ok(r)
}

fn rms(a: &[harmonic::glam::DVec3], b: &[harmonic::glam::DVec3]) -> f64 {
    let sum: f64 = a
        .iter()
        .zip(b)
        .map(|(p, q)| (*p - *q).length_squared())
        .sum();
    (sum / a.len() as f64).sqrt()
}

/// The cloth: stiff (k = 1e4 N/m) or the shipped soft springs, at automatic or fixed substeps.
fn cloth(stiff: bool, substeps: Option<u32>) -> Scene {
    let mut s = hanging_cloth(N as u32);
    s.dt = 1.0 / 60.0;
    s.substeps = substeps;
    s.integrator = Some("symplectic-euler".into());
    let c = &mut s.cloths[0];
    let spec = |k: f64| SpringSpec {
        stiffness: Some(k),
        damping: Some(0.01),
        ..Default::default()
    };
    let hz = |f: f64| SpringSpec {
        frequency: Some(f),
        damping_ratio: Some(0.05),
        ..Default::default()
    };
    if stiff {
        c.structural = spec(1e4);
        c.shear = Some(spec(1e4));
        c.bend = Some(spec(1e3));
    } else {
        c.structural = hz(200.0);
        c.shear = Some(hz(200.0));
        c.bend = Some(hz(60.0));
    }
    s
}

/// The run of median frame time among `runs` (one a round).
fn median(mut runs: Vec<Run>) -> Run {
    runs.sort_by(|a, b| a.frame.total_cmp(&b.frame));
    let k = runs.len() / 2;
    runs.swap_remove(k)
}

/// The report: one table, every figure from this run (`rounds` of it, medians).
pub fn report(frames: u32, rounds: u32) -> Result<String, String> {
    let seconds = f64::from(frames) / 60.0;
    let first = run(&cloth(true, None), frames)?;
    let converged = run(&cloth(true, Some(2 * first.substeps)), frames)?;
    let tethers = TetherSpec {
        slack: 0.05,
        anchors: 2,
    };
    let mut tethered = cloth(false, None);
    tethered.cloths[0].tethers = Some(tethers);
    // The slack is at most 5 %: a tighter one holds the shape closer, at more clamps.
    let mut tight = tethered.clone();
    tight.cloths[0].tethers = Some(TetherSpec {
        slack: 0.02,
        ..tethers
    });
    let mut limited = tethered.clone();
    limited.cloths[0].stretch_limit = Some(StretchLimit {
        stretch: 0.07,
        passes: 4,
    });
    // The limit's projections leave the springs a residual the accuracy controller answers
    // with more substeps: the same cloth held at the soft springs' own.
    let mut held = limited.clone();
    held.substeps = Some(30);
    let mut aired = cloth(false, None);
    aired.cloths[0].air = Some(Aero {
        density: 1.225,
        drag: 1.0,
        lift: 0.5,
    });
    let scenes = [
        cloth(true, None),
        cloth(false, None),
        tethered,
        tight,
        limited,
        held,
        aired,
    ];
    let mut runs: Vec<Vec<Run>> = scenes.iter().map(|_| Vec::new()).collect();
    runs[0].push(first);
    for round in 0..rounds {
        for (scene, runs) in scenes.iter().zip(&mut runs) {
            if runs.len() <= round as usize {
                runs.push(run(scene, frames)?);
            }
        }
    }
    // Stiff over tethered (slack 0.05, 0.02), round by round.
    let by_round: Vec<String> = (0..rounds as usize)
        .map(|k| {
            let stiff = runs[0][k].frame;
            format!(
                "{:.1}× and {:.1}×",
                stiff / runs[2][k].frame,
                stiff / runs[3][k].frame
            )
        })
        .collect();
    let [stiff, soft, t, t2, l, h, a] = runs
        .into_iter()
        .map(median)
        .collect::<Vec<_>>()
        .try_into()
        .map_err(|_| "seven cloths".to_string())?;
    let mut out = format!(
        "128×128 cloth, 1 m, 1 kg, two top corners pinned, {frames} frames of 1/60 s \
         ({seconds:.2} s), symplectic Euler, {} thread(s), {rounds} round(s) (medians)\n\
         | cloth | substeps at the end | ms per frame | stiff's time over this | peak structural strain | RMS from the converged stiff cloth at {seconds:.2} s |\n\
         |---|---|---|---|---|---|\n",
        rayon::current_num_threads()
    );
    let row = |name: &str, r: &Run| {
        format!(
            "| {name} | {} | {:.2} | {:.1}× | {:.2} % | {:.2} cm |\n",
            r.substeps,
            1e3 * r.frame,
            stiff.frame / r.frame,
            100.0 * r.peak,
            100.0 * rms(&r.end, &converged.end)
        )
    };
    out += &row("stiff, k = 1e4 N/m, automatic substeps", &stiff);
    out += &row("stiff, twice those (converged)", &converged);
    out += &row("soft (200 Hz)", &soft);
    out += &row("soft + tethers (slack 0.05, 2 anchors)", &t);
    out += &row("soft + tethers (slack 0.02, 2 anchors)", &t2);
    out += &row("soft + tethers + stretch limit (0.07, 4 passes)", &l);
    out += &row("the same at 30 substeps (fixed)", &h);
    out += &row("soft + air (still air)", &a);
    let share = |d: Duration, r: &Run| 100.0 * d.as_secs_f64() / r.integrate.as_secs_f64();
    out += &format!(
        "tethers: {:.1} % of the spring stage's time ({:.1} % at slack 0.02); stretch limit: \
         {:.1} %; air: {:.1} %\n",
        share(t.tethers, &t),
        share(t2.tethers, &t2),
        share(l.stretch, &l),
        share(a.air, &a)
    );
    if rounds > 1 {
        out += &format!(
            "stiff's time over the tethered cloth's (slack 0.05 and 0.02), round by round: {}\n",
            by_round.join("; ")
        );
    }
    out += "where a frame's time goes (ms per frame)\n\
            | cloth | integrate | tethers | stretch limit | air | audit | gather + scatter | other |\n\
            |---|---|---|---|---|---|---|---|\n";
    let ms = |d: Duration| 1e3 * d.as_secs_f64() / f64::from(frames);
    let split = |name: &str, r: &Run| {
        let known = r.integrate + r.tethers + r.stretch + r.air + r.audit + r.gather + r.scatter;
        format!(
            "| {name} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |\n",
            ms(r.integrate),
            ms(r.tethers),
            ms(r.stretch),
            ms(r.air),
            ms(r.audit),
            ms(r.gather + r.scatter),
            (1e3 * r.frame - ms(known)).max(0.0)
        )
    };
    out += &split("stiff, automatic substeps", &stiff);
    out += &split("soft", &soft);
    out += &split("soft + tethers", &t);
    out += &split("soft + tethers, slack 0.02", &t2);
    out += &split("soft + tethers + stretch limit", &l);
    out += &split("the same at 30 substeps (fixed)", &h);
    out += &split("soft + air", &a);
    Ok(out)
}
