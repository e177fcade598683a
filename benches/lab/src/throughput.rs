//! `harmonic-lab bench`: spring-substeps per second of each integrator on one cloth, side by side.

// A harness over scenes it generates itself: a failure there is a bug in the harness.
#![allow(clippy::expect_used)]

use std::fmt::Write;
use std::time::Instant;

use harmonic::glam::DVec3;

use crate::research::{Method, Stepper};
use harmonic::internals::buffers::{GatherOptions, Packed};
use harmonic::internals::hanging_cloths;
use harmonic::Integrator;

/// One row of the bench.
pub struct Row {
    pub integrator: Method,
    /// The cloth's springs expanded one by one, for an integrator that runs on the grid as
    /// the simulation does (a comparison row).
    pub one_by_one: bool,
    /// Median spring-substeps per second.
    pub rate: f64,
}

/// Times `substeps` substeps of each integrator on the buffers the simulation gives it,
/// `repeats` times round-robin, and reports medians. An integrator with a grid pass is timed
/// on the springs one by one too.
pub fn measure(
    n: u32,
    cloths: u32,
    substeps: u32,
    repeats: u32,
    integrators: &[Method],
) -> (usize, Vec<Row>) {
    let scene = hanging_cloths(n, cloths);
    let world = scene.build().world;
    let gather = |keep_grids| {
        let options = GatherOptions {
            keep_grids,
            colouring: !keep_grids,
        };
        Packed::gather_with(&world, options).expect("generated scene is consistent")
    };
    let (packed, grid) = (gather(false), gather(true));
    let h = scene.dt;
    let g = DVec3::from(scene.gravity);
    let m = packed.spring_count();
    let cases: Vec<(Method, bool)> = integrators
        .iter()
        .flat_map(|&i| {
            let one_by_one = i.runs_on_grids(false).then_some((i, true));
            [(i, false)].into_iter().chain(one_by_one)
        })
        .collect();
    let mut samples = vec![Vec::new(); cases.len()];
    let mut runs: Vec<(Packed, Stepper)> = cases
        .iter()
        .map(|&(i, one_by_one)| {
            let mut s = Stepper::new(i, false, g);
            let mut p = if i.runs_on_grids(false) && !one_by_one {
                grid.clone()
            } else {
                packed.clone()
            };
            s.prepare(&p, h).expect("bench cloth is under-damped");
            for _ in 0..10 {
                s.substep(&mut p, h).expect("prepared");
            }
            (p, s)
        })
        .collect();
    for _ in 0..repeats {
        for (k, (p, s)) in runs.iter_mut().enumerate() {
            let t = Instant::now();
            for _ in 0..substeps {
                s.substep(p, h).expect("prepared");
            }
            samples[k].push(m as f64 * substeps as f64 / t.elapsed().as_secs_f64());
        }
    }
    let rows = cases
        .iter()
        .zip(samples)
        .map(|(&(integrator, one_by_one), mut v)| {
            v.sort_by(f64::total_cmp);
            Row {
                integrator,
                one_by_one,
                rate: v[v.len() / 2],
            }
        })
        .collect();
    (m, rows)
}

/// The bench as a Markdown table.
pub fn report(n: u32, cloths: u32, substeps: u32, repeats: u32, integrators: &[Method]) -> String {
    let (m, rows) = measure(n, cloths, substeps, repeats, integrators);
    let threads = rayon::current_num_threads();
    let reference = rows
        .iter()
        .find(|r| r.integrator == Method::Engine(Integrator::SymplecticEuler) && !r.one_by_one)
        .map(|r| r.rate);
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{cloths} cloth(s) {n}×{n}: {} particles, {m} springs; {substeps} substeps × {repeats} repeats (median), {threads} threads\n",
        cloths * n * n
    );
    let _ = writeln!(
        out,
        "| integrator | M spring-substeps/s | ns per spring-substep | vs symplectic Euler |"
    );
    let _ = writeln!(out, "|---|---|---|---|");
    for r in &rows {
        let ratio = reference.map_or("-".to_string(), |s| format!("{:.2}×", r.rate / s));
        let _ = writeln!(
            out,
            "| {}{} | {:.1} | {:.2} | {ratio} |",
            r.integrator,
            if r.one_by_one {
                " (springs one by one)"
            } else {
                ""
            },
            r.rate / 1e6,
            1e9 / r.rate
        );
    }
    out
}
