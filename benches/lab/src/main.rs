//! `harmonic-lab`: the measuring apparatus of harmonic, headless: speed against error, the
//! hard-case stability suite, step throughput, the drape beside rapier's cloth, the GPU bench.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::{Parser, Subcommand};
use harmonic::{Integrator, Scene, Simulation};
use harmonic_lab::research::Method;
use harmonic_lab::{stability, throughput};

#[derive(Parser)]
#[command(
    name = "harmonic-lab",
    version,
    about = "Measures harmonic: speed against error, stability, throughput, peers"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the hard-case stability suite and print Markdown tables.
    Stability {
        /// Simulated seconds per hard case.
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
        /// Also run the 128×128 cloth (minutes).
        #[arg(long)]
        full: bool,
        /// Write the report here as well as to stdout.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Instead of running the suite, write its cases as scene files into this folder.
        #[arg(long)]
        write_scenes: Option<PathBuf>,
    },
    /// Speed against error: every integrator at several steps on the bench scenes, against an
    /// RK4 reference. Writes CSV, Markdown and log-log charts (SVG, PNG) into --out.
    Bench {
        /// Skip the 128×128 cloth.
        #[arg(long)]
        quick: bool,
        /// Timed repeats per run; the median is reported.
        #[arg(long, default_value_t = 3)]
        repeats: u32,
        #[arg(long, default_value = "bench-out")]
        out: PathBuf,
        /// Only these scenes (chain20, cloth16, cloth128; drop16 and drop32 by name only; default: the first three).
        #[arg(long, value_delimiter = ',')]
        scenes: Vec<String>,
        /// Only these integrators (default: every contender and rapier's cloth).
        #[arg(long, value_delimiter = ',')]
        integrators: Vec<String>,
        /// These steps per simulated second instead of each integrator's ladder.
        #[arg(long, value_delimiter = ',')]
        steps: Vec<u64>,
        /// Every spring's stiffness times this factor (damping ratios kept).
        #[arg(long)]
        stiffen: Option<f64>,
        /// `gpu`: instead, GPU substeps/s against cloth size beside the CPU kernel, against the
        /// memory-bound floor, and what each shader specialisation buys (writes gpu.md).
        #[arg(long, default_value = "cpu")]
        backend: String,
        /// Cloth sizes N (N×N) for `--backend gpu`.
        #[arg(long, value_delimiter = ',', default_value = "64,128,256,512,1024")]
        sizes: Vec<u32>,
        /// Largest N the CPU kernel also runs for `--backend gpu`.
        #[arg(long, default_value_t = 1024)]
        cpu_max: u32,
        /// Integrator for `--backend gpu`.
        #[arg(long, default_value = "symplectic-euler")]
        integrator: String,
    },
    /// Spring-substeps per second of each integrator on an N×N hanging cloth, side by side.
    Throughput {
        /// Cloth resolution N (N×N particles).
        #[arg(long, default_value_t = 128)]
        size: u32,
        /// Cloths of that size side by side (each a grid of its own).
        #[arg(long, default_value_t = 1)]
        cloths: u32,
        /// Substeps timed per integrator and repeat.
        #[arg(long, default_value_t = 200)]
        substeps: u32,
        /// Repeats; the median is reported.
        #[arg(long, default_value_t = 5)]
        repeats: u32,
        /// Integrators to compare (default: all but the RK4 reference).
        #[arg(long, value_delimiter = ',')]
        integrators: Vec<String>,
    },
    /// A bit-for-bit record of what the engine computes (every scene of --scenes and hard case
    /// for 150 frames, each game integrator on the chain and the hanging cloth, `step_with`, the
    /// GPU): write it before a refactor that must change nothing, check against it after.
    Baseline {
        /// Record the runs into this file.
        #[arg(long, conflicts_with = "check", required_unless_present = "check")]
        write: Option<PathBuf>,
        /// Run again and compare with this file; exit 2 naming each run's first difference.
        #[arg(long)]
        check: Option<PathBuf>,
        /// The folder of shipped scenes.
        #[arg(long, default_value = "scenes")]
        scenes: PathBuf,
        /// Only the runs whose name contains this (`hard/…` for the hard cases).
        #[arg(long)]
        only: Option<String>,
    },
    /// Mean wall time per frame at fixed substeps, one line per timed run: for comparing two
    /// builds side by side (alternate their binaries; set RAYON_NUM_THREADS).
    FrameTime {
        /// chain, cloth16, stiff128 or cloth1024.
        #[arg(long)]
        case: String,
        /// Timed runs after one untimed run.
        #[arg(long, default_value_t = 1)]
        repeats: u32,
    },
    /// A cloth scene draped on one fixed ball, run by this engine (CPU) and by rapier 0.36's own
    /// soft-body cloth on the same ball, side by side: wall time, strain, penetration.
    DrapePeer {
        #[arg(default_value = "scenes/drape_sphere.ron")]
        scene: PathBuf,
    },
    /// A stiff cloth's look at a game's cost: the 128×128 two-corner cloth stiff (k = 1e4 N/m)
    /// at its automatic substeps and converged, against soft springs held by tethers and a
    /// stretch limit: ms per frame, peak strain, RMS from the converged stiff cloth.
    GameCost {
        /// Frames of 1/60 s.
        #[arg(long, default_value_t = 60)]
        frames: u32,
        /// Rounds of every cloth but the converged one, one after the other: each time is the
        /// median over the rounds (the machine's noise moves single runs).
        #[arg(long, default_value_t = 1)]
        rounds: u32,
    },
    /// Cloth through cloth: a scene run with and without its self-collision, the triangle
    /// pairs crossing at each frame's end counted (exact test), beside the stage's cost.
    Crossings {
        scene: PathBuf,
        /// Frames to run (default: the scene's seconds).
        #[arg(long)]
        frames: Option<u32>,
    },
}

/// The longest hard case `stability --seconds` runs (an hour simulated: hours of wall time).
const MAX_SECONDS: f64 = 3600.0;

fn main() -> ExitCode {
    // Before any thread starts: no Wayland probe's error on a headless machine.
    harmonic::internals::quiet_headless_adapters();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Stability {
            write_scenes: Some(dir),
            ..
        } => stability::write_hard_scenes(&dir)
            .map(|n| println!("wrote {n} scenes to {}", dir.display()))
            .map_err(|e| format!("{}: {e}", dir.display())),
        Command::Stability { seconds, .. } if !(seconds > 0.0 && seconds <= MAX_SECONDS) => {
            Err(format!(
                "--seconds {seconds}: expected simulated seconds per case, > 0 and at most \
                 {MAX_SECONDS}"
            ))
        }
        Command::Stability {
            seconds, full, out, ..
        } => {
            let report = stability::report(&stability::Options { seconds, full });
            print!("{report}");
            match out {
                Some(path) => {
                    std::fs::write(&path, &report).map_err(|e| format!("{}: {e}", path.display()))
                }
                None => Ok(()),
            }
        }
        Command::Bench { repeats: 0, .. } => Err("--repeats 0: run at least once".into()),
        Command::Bench {
            quick,
            repeats,
            out,
            scenes,
            integrators,
            steps,
            stiffen,
            backend,
            sizes,
            cpu_max,
            integrator,
        } => match backend.as_str() {
            "cpu" => {
                let chosen = if integrators.is_empty() {
                    Ok(Vec::new())
                } else {
                    parse_integrators(&integrators)
                };
                chosen.and_then(|integrators| {
                    let selection = harmonic_lab::accuracy::Selection {
                        scenes,
                        integrators,
                        steps,
                        stiffen,
                    };
                    selection.validate(quick)?;
                    bench_report(quick, repeats, &selection, &out)
                })
            }
            "gpu" => gpu_bench(&sizes, &integrator, repeats, cpu_max, &out),
            other => Err(format!("--backend {other}: the bench runs `cpu` or `gpu`")),
        },
        Command::Throughput {
            size,
            cloths,
            substeps,
            repeats,
            integrators,
        } => check_throughput(size, cloths, substeps, repeats)
            .and_then(|()| parse_integrators(&integrators))
            .map(|list| {
                print!(
                    "{}",
                    throughput::report(size, cloths, substeps, repeats, &list)
                );
            }),
        Command::DrapePeer { scene } => drape_peer(&scene),
        Command::GameCost { frames: 0, .. } => Err("--frames 0: run at least one frame".into()),
        Command::GameCost { rounds: 0, .. } => Err("--rounds 0: run at least one round".into()),
        Command::GameCost { rounds: 101.., .. } => {
            Err("--rounds: at most 100 (each round takes about half a minute)".into())
        }
        Command::Crossings {
            frames: Some(0), ..
        } => Err("--frames 0: run at least one frame".into()),
        Command::Crossings { scene, frames } => {
            harmonic_lab::crossings::report(&scene, frames).map(|r| print!("{r}"))
        }
        Command::GameCost { frames, rounds } => {
            harmonic_lab::game_cost::report(frames, rounds).map(|r| print!("{r}"))
        }
        Command::FrameTime { case, repeats } => harmonic_lab::frame_time::measure(&case, repeats)
            .map(|runs| {
                for t in runs {
                    println!("{case}\t{:.6e}", t);
                }
            }),
        Command::Baseline {
            write,
            check,
            scenes,
            only,
        } => baseline(write.as_deref(), check.as_deref(), &scenes, only.as_deref()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(msg) => {
            eprintln!("error: {msg}");
            ExitCode::from(2)
        }
    }
}

fn baseline(
    write: Option<&std::path::Path>,
    check: Option<&std::path::Path>,
    scenes: &std::path::Path,
    only: Option<&str>,
) -> Result<(), String> {
    use harmonic_lab::baseline;
    let recorded = match check {
        Some(path) => {
            Some(std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?)
        }
        None => None,
    };
    let runs = baseline::runs(scenes, only)?;
    let count = runs.iter().filter(|r| r.1 == "end").count();
    if let Some(path) = write {
        std::fs::write(path, baseline::write(&runs))
            .map_err(|e| format!("{}: {e}", path.display()))?;
        println!("wrote {count} runs to {}", path.display());
    }
    if let (Some(text), Some(path)) = (recorded, check) {
        let differences = baseline::differences(&text, &runs, only);
        for d in &differences {
            println!("{d}");
        }
        if !differences.is_empty() {
            return Err(format!(
                "{} difference(s) from {} ({count} runs)",
                differences.len(),
                path.display()
            ));
        }
        println!("{count} runs, the same bits as {}", path.display());
    }
    Ok(())
}

/// The throughput flags, refused before anything is built: a cloth of at least 2×2, at most
/// the engine's default particle limit in all, and at least one substep and one repeat.
fn check_throughput(size: u32, cloths: u32, substeps: u32, repeats: u32) -> Result<(), String> {
    let max = harmonic::scene::Limits::DEFAULT.max_particles;
    let particles = u64::from(size)
        .checked_mul(u64::from(size))
        .and_then(|p| p.checked_mul(u64::from(cloths)))
        .unwrap_or(u64::MAX);
    if size < 2 {
        return Err(format!(
            "--size {size}: a cloth needs at least 2×2 particles"
        ));
    }
    if cloths == 0 || particles > max {
        return Err(format!(
            "--size {size} --cloths {cloths}: {particles} particles; expected 1 to {max} \
             (the engine's default particle limit)"
        ));
    }
    if substeps == 0 {
        return Err("--substeps 0: time at least one substep".into());
    }
    if repeats == 0 {
        return Err("--repeats 0: run at least once".into());
    }
    Ok(())
}

#[cfg(feature = "gpu")]
fn gpu_bench(
    sizes: &[u32],
    integrator: &str,
    repeats: u32,
    cpu_max: u32,
    out: &std::path::Path,
) -> Result<(), String> {
    let integrator: Integrator = integrator
        .parse()
        .map_err(|e: harmonic::SimError| e.to_string())?;
    if sizes.is_empty() || sizes.contains(&0) {
        return Err("--sizes: give one or more sizes ≥ 1".into());
    }
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let md = harmonic_lab::gpu_bench::report(sizes, integrator, repeats, cpu_max, |what| {
        eprintln!("bench: {what}")
    })
    .map_err(|e| e.to_string())?;
    let path = out.join("gpu.md");
    std::fs::write(&path, &md).map_err(|e| format!("{}: {e}", path.display()))?;
    print!("{md}");
    println!("wrote {}", path.display());
    Ok(())
}

#[cfg(not(feature = "gpu"))]
fn gpu_bench(_: &[u32], _: &str, _: u32, _: u32, _: &std::path::Path) -> Result<(), String> {
    Err(harmonic::GpuError::NotBuilt.to_string())
}

/// A progress bar on stderr when it is a terminal; None otherwise (callers print plain lines).
fn progress_bar(total: u64) -> Option<indicatif::ProgressBar> {
    use std::io::IsTerminal;
    std::io::stderr().is_terminal().then(|| {
        let bar = indicatif::ProgressBar::new(total);
        bar.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} {elapsed_precise} {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    })
}

fn bench_report(
    quick: bool,
    repeats: u32,
    selection: &harmonic_lab::accuracy::Selection,
    out: &std::path::Path,
) -> Result<(), String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let bar = progress_bar(1);
    let (rows, refs) = harmonic_lab::accuracy::measure(
        quick,
        repeats,
        selection,
        |done, total, label| match &bar {
            Some(b) => {
                b.set_length(total as u64);
                b.set_position(done as u64);
                b.set_message(label.to_string());
            }
            None => eprintln!("[{done}/{total}] {label}"),
        },
    );
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let md = harmonic_lab::accuracy::markdown(&rows, &refs);
    let write = |name: &str, text: &str| {
        std::fs::write(out.join(name), text)
            .map_err(|e| format!("{}: {e}", out.join(name).display()))
    };
    write("bench.csv", &harmonic_lab::accuracy::csv(&rows))?;
    write("bench.md", &md)?;
    for r in &refs {
        let scene = r.scene;
        harmonic_lab::accuracy::chart(
            &rows,
            r,
            &out.join(format!("{scene}.svg")),
            &out.join(format!("{scene}.png")),
        )?;
    }
    print!("{md}");
    println!(
        "wrote {}/bench.csv, bench.md and a chart per scene (SVG, PNG)",
        out.display()
    );
    Ok(())
}

fn parse_integrators(names: &[String]) -> Result<Vec<Method>, String> {
    if names.is_empty() {
        return Ok(Method::ALL
            .into_iter()
            .filter(|&m| m != Method::RK4)
            .collect());
    }
    names.iter().map(|n| n.parse::<Method>()).collect()
}

/// `harmonic-lab drape-peer`: the scene's first cloth on its ball, ours against rapier's.
fn drape_peer(path: &PathBuf) -> Result<(), String> {
    use harmonic::scene::props::Shape;
    use harmonic_lab::peer;
    let scene = Scene::load(path).map_err(|e| e.to_string())?;
    let cloth = scene.cloths.first().ok_or("the scene has no cloth")?;
    let (centre, radius) = scene
        .bodies
        .iter()
        .find_map(|b| match b.shape {
            Shape::Ball { radius } => Some((harmonic::glam::DVec3::from(b.position), radius)),
            _ => None,
        })
        .ok_or("the scene has no ball")?;
    let contact = scene.contact.unwrap_or_default();
    let seconds = scene.seconds.unwrap_or(3.0);
    let gravity = harmonic::glam::DVec3::from(scene.gravity);
    let figures = |x: &[harmonic::glam::DVec3]| {
        let (max, mean) = peer::grid_strain(cloth, x);
        // How far the deepest particle is inside the ball, and inside the contact shell.
        let gap = x
            .iter()
            .map(|p| (*p - centre).length() - radius)
            .fold(f64::MAX, f64::min);
        (
            max,
            mean,
            (-gap).max(0.0),
            (contact.thickness - gap).max(0.0),
        )
    };
    let mut sim = Simulation::from_scene(&scene).map_err(|e| e.to_string())?;
    let frames = (seconds / sim.config().dt).round() as u64;
    let t = Instant::now();
    for _ in 0..frames {
        sim.step().map_err(|e| e.to_string())?;
    }
    let ours = t.elapsed().as_secs_f64();
    // Scene order: the scene's loose particles, then the first cloth's.
    let first = scene.particles.len();
    let n = (cloth.resolution.0 * cloth.resolution.1) as usize;
    let a = figures(&sim.positions()[first..first + n]);
    let (y, theirs) = peer::drape_on_ball(
        cloth,
        gravity,
        centre,
        radius,
        contact.thickness,
        contact.friction,
        seconds,
    )?;
    let b = figures(&y);
    println!(
        "{n} particles on a ball of radius {radius} m, {seconds} s simulated, contact thickness {} m",
        contact.thickness
    );
    println!();
    println!("| engine | wall (s) | wall / simulated | max strain | mean strain | deepest inside the ball (m) | deepest inside the shell (m) |");
    println!("|---|---|---|---|---|---|---|");
    let sub = sim.config().substeps;
    for (name, wall, f) in [
        (
            format!(
                "harmonic ({}, {sub} substeps/frame, CPU)",
                sim.config().integrator.name()
            ),
            ours,
            a,
        ),
        (
            "rapier 0.36 soft-body cloth (defaults)".to_string(),
            theirs,
            b,
        ),
    ] {
        println!(
            "| {name} | {wall:.3} | {:.3} | {:.2} % | {:.3} % | {:.2e} | {:.2e} |",
            wall / seconds,
            100.0 * f.0,
            100.0 * f.1,
            f.2,
            f.3
        );
    }
    Ok(())
}
