//! The suite's report: threshold tables against the numpy study, and outcome tables.

use super::*;

pub(super) fn fmt_threshold(t: Option<f64>, max: f64) -> String {
    match t {
        Some(t) => format!("{t:.3}"),
        None => format!("> {max}"),
    }
}

pub(super) fn fmt_paper(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2}")
    } else {
        "∞".into()
    }
}

pub(super) fn outcome_cell(o: Outcome, reference: f64) -> String {
    match o {
        Outcome::Bounded {
            max_strain,
            energy_drift,
        } => {
            format!(
                "{:.2} / {:+.1}%",
                max_strain / reference,
                100.0 * energy_drift
            )
        }
        Outcome::BlownUp { time } => format!("✗ {time:.2} s"),
        Outcome::Undefined => "undef.".into(),
    }
}

/// The whole report as Markdown.
pub fn report(opts: &Options) -> String {
    let mut out = String::new();
    let max = 10.0;
    let _ = writeln!(
        out,
        "## Largest stable h/h_c (growth rate of a perturbation about rest ≤ 1 + {GROWTH_TOL})\n"
    );
    let _ = writeln!(
        out,
        "h_c = π/ω0 of the stiffest single spring. Scanned in steps of 0.01 up to {max}, then bisected.\n"
    );
    let _ = writeln!(
        out,
        "Each cell: ours (numpy study's figure from MATH.md).\n"
    );
    let engine = Method::Engine;
    let columns: [(&str, Method, bool); 11] = [
        (
            "symplectic Euler",
            engine(Integrator::SymplecticEuler),
            false,
        ),
        ("harmonic (Jacobi)", engine(Integrator::Harmonic), false),
        ("harmonic-forced", Method::HARMONIC_FORCED, false),
        ("harmonic-gs", engine(Integrator::HarmonicGs), false),
        ("harmonic-forced-gs", Method::HARMONIC_FORCED_GS, false),
        ("harmonic-sgs", Method::HARMONIC_SGS, false),
        (
            "harmonic, exact displacement",
            engine(Integrator::Harmonic),
            true,
        ),
        ("explicit Euler", engine(Integrator::ExplicitEuler), false),
        ("implicit-euler", engine(Integrator::ImplicitEuler), false),
        ("theta-mg", engine(Integrator::ThetaMg), false),
        ("xpbd", engine(Integrator::Xpbd), false),
    ];
    let names: Vec<&str> = columns.iter().map(|c| c.0).collect();
    let _ = writeln!(out, "| system | {} |", names.join(" | "));
    let _ = writeln!(out, "|---|{}", "---|".repeat(columns.len()));
    for study in threshold_systems() {
        let p = pack(&study.scene);
        let cells: Vec<String> = columns
            .iter()
            .map(|&(_, integrator, exact)| {
                let ours = fmt_threshold(threshold(&p, integrator, exact, max), max);
                let theirs = match (integrator, exact) {
                    (Method::Engine(Integrator::SymplecticEuler), _) => study.symplectic_euler,
                    (Method::Engine(Integrator::Harmonic), false) => study.harmonic,
                    (Method::HARMONIC_FORCED, _) => study.forced,
                    (Method::Engine(Integrator::HarmonicGs), _) => study.gauss_seidel,
                    _ => f64::NAN,
                };
                if theirs.is_nan() {
                    ours
                } else {
                    format!("{ours} ({})", fmt_paper(theirs))
                }
            })
            .collect();
        let _ = writeln!(out, "| {} | {} |", study.name, cells.join(" | "));
    }
    // Stable windows of the undamped single spring above the first threshold.
    let p = pack(&pair(1.0, 0.0, false, Start::Equilibrium).0);
    let hc = h_crit(&p);
    let _ = writeln!(out, "\nUndamped single spring, harmonic (Jacobi, x += h v_new), growth rate at the paper's step ratios:\n");
    let _ = writeln!(out, "| h/h_c | growth rate per step | stable |");
    let _ = writeln!(out, "|---|---|---|");
    for r in [1.0, 2.0, 2.0625, 3.0, 4.0, 6.0, 6.0625, 8.0, 8.0625] {
        let g =
            growth_rate(&p, Integrator::Harmonic, false, r * hc, GROWTH_STEPS).unwrap_or(f64::NAN);
        let _ = writeln!(
            out,
            "| {r} | {g:.4} | {} |",
            if g <= 1.0 + GROWTH_TOL { "yes" } else { "no" }
        );
    }

    let _ = writeln!(out, "\n## Hard cases, {} s each\n", opts.seconds);
    let _ = writeln!(
        out,
        "Cell: max strain over the run ÷ reference strain (the exact static strain; 10 % for the pairs) / energy \
         drift over the run relative to m·|g|·size (initial energy without gravity). ✗ t: blew up (non-finite or \
         strain > {:.0} %) at time t. undef.: the printed equations have no value (ζ > 0.707).\n",
        100.0 * BLOWUP_STRAIN
    );
    type Case = (String, Box<dyn Fn(f64, Start) -> (Scene, f64)>);
    let mut cases: Vec<Case> = vec![
        ("pair 1:1".into(), Box::new(|z, s| pair(1.0, z, false, s))),
        (
            "pair 1:1000".into(),
            Box::new(|z, s| pair(1000.0, z, false, s)),
        ),
        (
            "pair 1:1, spinning".into(),
            Box::new(|z, s| pair(1.0, z, true, s)),
        ),
        (
            "pair 1:1000, spinning".into(),
            Box::new(|z, s| pair(1000.0, z, true, s)),
        ),
        (
            "chain of 20 pinned at the top".into(),
            Box::new(|z, s| chain(20, z, s)),
        ),
        (
            "cloth 16×16 pinned at two corners".into(),
            Box::new(|z, s| cloth_case(16, z, s)),
        ),
    ];
    if opts.full {
        cases.push((
            "cloth 128×128 pinned at two corners".into(),
            Box::new(|z, s| cloth_case(128, z, s)),
        ));
    }
    for (name, make) in &cases {
        let _ = writeln!(out, "### {name}\n");
        let header: Vec<String> = RATIOS.iter().map(|r| format!("{r}")).collect();
        let _ = writeln!(out, "| ζ | start | integrator | {} |", header.join(" | "));
        let _ = writeln!(out, "|---|---|---|{}", "---|".repeat(RATIOS.len()));
        for zeta in [0.0, 0.2] {
            for start in [Start::Rest, Start::Equilibrium] {
                let (scene, reference) = make(zeta, start);
                let p = pack(&scene);
                let g = DVec3::from(scene.gravity);
                let hc = h_crit(&p);
                let e_ref = energy_scale(&p, g);
                for integrator in CONTENDERS {
                    let cells: Vec<String> = RATIOS
                        .iter()
                        .map(|r| {
                            outcome_cell(
                                run(&p, integrator, g, r * hc, opts.seconds, e_ref),
                                reference,
                            )
                        })
                        .collect();
                    let _ = writeln!(
                        out,
                        "| {zeta} | {start:?} | {integrator} | {} |",
                        cells.join(" | ")
                    );
                }
            }
        }
        let _ = writeln!(out);
    }

    let _ = writeln!(
        out,
        "### Near-rigid 5-particle chain at 60 Hz (h = 1/60 s), released from rest\n"
    );
    let _ = writeln!(out, "| κ (N/m) | ζ | h/h_c | integrator | outcome |");
    let _ = writeln!(out, "|---|---|---|---|---|");
    for k in [1e4, 1e5, 1e6, 1e7] {
        for zeta in [0.0, 0.2] {
            let scene = near_rigid(k, zeta);
            let p = pack(&scene);
            let g = DVec3::from(scene.gravity);
            let h = scene.dt;
            let ratio = h / h_crit(&p);
            let reference = static_strain_of(&p, g);
            let e_ref = energy_scale(&p, g);
            for integrator in CONTENDERS {
                let o = run(&p, integrator, g, h, opts.seconds, e_ref);
                let _ = writeln!(
                    out,
                    "| {k:e} | {zeta} | {ratio:.2} | {integrator} | {} |",
                    outcome_cell(o, reference)
                );
            }
        }
    }
    out
}
