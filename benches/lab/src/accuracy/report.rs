//! The report: CSV, the markdown tables with the frontier, and the charts.

use super::*;

pub fn csv(rows: &[Row]) -> String {
    let mut out = String::from("scene,integrator,steps_per_s,h_over_hc,wall_s_per_sim_s,rms_error_m,max_strain,static_strain,energy_drift,stable,edge,residual,peak_residual\n");
    for r in rows {
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{},{}",
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
            r.edge,
            r.residual,
            r.peak_residual
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
        let _ = writeln!(out, "| integrator | steps/s | h/h_c | wall s per sim. s | RMS error (m) | max strain | static strain | energy drift | residual (peak) | stable |");
        let _ = writeln!(out, "|---|---|---|---|---|---|---|---|---|---|");
        for r in rows.iter().filter(|r| r.scene == scene) {
            if r.stable {
                let _ = writeln!(
                    out,
                    "| {} | {} | {:.3} | {:.4} | {:.3e} | {:.4} | {:.4} | {:+.2e} | {:+.2e} ({:.2e}) | yes |",
                    r.integrator,
                    steps_cell(r),
                    r.step_ratio,
                    r.wall,
                    r.rms_error,
                    r.max_strain,
                    r.static_strain,
                    r.energy_drift,
                    r.residual,
                    r.peak_residual
                );
            } else {
                let _ = writeln!(
                    out,
                    "| {} | {} | {:.3} | - | - | - | {:.4} | - | - | no |",
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
pub(super) fn integrators_in<'a>(rows: impl Iterator<Item = &'a Row>) -> Vec<&'a str> {
    let mut names: Vec<&str> = Vec::new();
    for r in rows {
        if !names.contains(&r.integrator.as_str()) {
            names.push(&r.integrator);
        }
    }
    names
}

/// A ladder step as is; a bisected one marked.
pub(super) fn steps_cell(r: &Row) -> String {
    if r.edge {
        format!("{} (edge)", r.steps)
    } else {
        r.steps.to_string()
    }
}

/// Each integrator's cheapest run within the default rule, and its wall time over symplectic
/// Euler's: a speed ratio between runs inside the same error bounds.
pub(super) fn frontier(out: &mut String, rows: &[Row], scene: &str, reference_strain: f64) {
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
