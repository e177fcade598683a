//! The measurement: every contender on every case at a ladder of steps, timed beside its error.

use super::*;

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
    let plan: Vec<(usize, Method, u64)> = cases
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
        let (reference, steps, change, max_strain) = match reference(&packed, g) {
            Ok(r) => r,
            Err(why) => {
                // Refused up front by `Selection::validate`; a case past it is left out.
                eprintln!("{}: {why}; left out", case.name);
                continue;
            }
        };
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
                        residual: f64::NAN,
                        peak_residual: f64::NAN,
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
