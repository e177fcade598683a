//! `harmonic`: run, check and render scenes, headless. The measuring apparatus (speed against
//! error, the stability suite, throughput, the rapier peer, the GPU bench) is `harmonic-lab`.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::{Parser, Subcommand};

mod progress;
mod summary;
mod trajectory;
use harmonic::internals::Readable;
use harmonic::scene::Limits;
use harmonic::{Backend, Scene, SimError, Simulation, StageKind};
use progress::Progress;

/// Standard output closed by its reader (`harmonic run … | head -1`): the run stops quietly,
/// as `ls | head` does, with the shell's status for a broken pipe.
const CLOSED: &str = "standard output closed";
const CLOSED_STATUS: u8 = 141;

/// One line to standard output: a closed pipe is [`CLOSED`], any other failure (a full disk)
/// an error that says so.
fn out(args: std::fmt::Arguments) -> Result<(), String> {
    let mut stdout = std::io::stdout().lock();
    match writeln!(stdout, "{args}").and_then(|()| stdout.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Err(CLOSED.into()),
        Err(e) => Err(format!("writing to standard output: {e}")),
    }
}

/// `println!` that returns [`out`]'s error from the enclosing function.
macro_rules! say {
    ($($t:tt)*) => {
        out(format_args!($($t)*))?
    };
}

// After `say!`, which it uses.
mod render;

#[derive(Parser)]
#[command(
    name = "harmonic",
    version,
    about = "Mass-spring simulation with a closed-form spring step"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene headless and print a summary.
    Run(RunArgs),
    /// Load and validate scenes, and build each as `run` would (without stepping): print every
    /// problem with its location.
    Check {
        #[arg(required = true)]
        scenes: Vec<PathBuf>,
        #[command(flatten)]
        limits: LimitArgs,
    },
    /// Render a scene headless to PNG with wgpu offscreen (a software adapter such as Mesa's
    /// lavapipe works): shaded cloth, rigid bodies, a floor grid.
    Render(RenderArgs),
}

/// How much a scene may ask for (`harmonic::scene::Limits`), checked before building it.
#[derive(clap::Args)]
struct LimitArgs {
    /// Refuse scenes with more particles than this.
    #[arg(long, default_value_t = Limits::DEFAULT.max_particles)]
    max_particles: u64,
    /// Refuse scenes with more springs than this.
    #[arg(long, default_value_t = Limits::DEFAULT.max_springs)]
    max_springs: u64,
    /// Refuse scenes, and --substeps, fixing more substeps per frame than this.
    #[arg(long, default_value_t = Limits::DEFAULT.max_substeps)]
    max_substeps: u32,
    /// Refuse runs of more frames than this (seconds / dt, or --steps).
    #[arg(long, default_value_t = Limits::DEFAULT.max_frames)]
    max_frames: u64,
    /// Refuse runs of more substeps than this where they are fixed (frames × substeps).
    #[arg(long, default_value_t = Limits::DEFAULT.max_run_substeps)]
    max_run_substeps: u64,
}

impl LimitArgs {
    fn limits(&self) -> Limits {
        Limits {
            max_particles: self.max_particles,
            max_springs: self.max_springs,
            max_substeps: self.max_substeps,
            max_frames: self.max_frames,
            max_run_substeps: self.max_run_substeps,
        }
    }
}

/// The frames of a run: `--steps`, else `seconds` (the flag's, the scene's, else 1 s) at the
/// config's `dt`; refused, naming the flag, when not a time of at least one frame, over
/// `--max-frames`, or (with fixed substeps) over `--max-run-substeps` in all.
fn frames(
    steps: Option<u64>,
    flag: Option<f64>,
    scene: Option<f64>,
    config: &harmonic::SimConfig,
    limits: &Limits,
) -> Result<u64, String> {
    let (what, frames) = match (steps, flag, scene) {
        (Some(n), ..) if n == 0 || n > limits.max_frames => {
            return Err(format!(
                "--steps {n}: expected 1 to {} frames (--max-frames)",
                limits.max_frames
            ))
        }
        (Some(n), ..) => ("--steps", n),
        (None, flag, scene) => {
            let (what, seconds) = match (flag, scene) {
                (Some(t), _) => ("--seconds", t),
                (None, Some(t)) => ("the scene's seconds", t),
                (None, None) => ("the default 1 s", 1.0),
            };
            let frames = limits
                .frames(seconds, config.dt)
                .map_err(|e| format!("{what}: {}", e.message))?;
            (what, frames)
        }
    };
    if !config.auto_substeps {
        limits
            .run_substeps(frames, config.substeps)
            .map_err(|e| format!("{what} with fixed substeps: {e}"))?;
    }
    Ok(frames)
}

#[derive(clap::Args)]
struct RenderArgs {
    scene: PathBuf,
    #[command(flatten)]
    limits: LimitArgs,
    /// Folder for the pictures (`<scene>_<k>.png`, and `<scene>_sheet.png` with --sheet).
    #[arg(long, default_value = "render-out")]
    out: PathBuf,
    /// Pictures, evenly spaced over the run; the last shows its end.
    #[arg(long, default_value_t = 1)]
    frames: u32,
    /// Picture size, WIDTHxHEIGHT.
    #[arg(long, default_value = "800x600")]
    size: String,
    /// Simulated seconds (default: the scene's `seconds`, else 1).
    #[arg(long)]
    seconds: Option<f64>,
    /// Colour the cloth by strain (blue 0 to red at --strain-scale).
    #[arg(long)]
    strain: bool,
    /// Strain drawn fully red.
    #[arg(long, default_value_t = 0.1)]
    strain_scale: f64,
    /// Draw the cloth's triangle edges.
    #[arg(long)]
    wireframe: bool,
    /// Also tile the pictures into one contact sheet.
    #[arg(long)]
    sheet: bool,
}

#[derive(clap::Args)]
struct RunArgs {
    scene: PathBuf,
    #[command(flatten)]
    limits: LimitArgs,
    /// Simulated seconds (default: the scene's `seconds`, else 1).
    #[arg(long, conflicts_with = "steps")]
    seconds: Option<f64>,
    /// Frames to step.
    #[arg(long)]
    steps: Option<u64>,
    /// Override the scene's frame step (s).
    #[arg(long)]
    dt: Option<f64>,
    /// Fix the substeps per frame (default: the scene's, else automatic).
    #[arg(long)]
    substeps: Option<u32>,
    /// Override the scene's integrator.
    #[arg(long)]
    integrator: Option<String>,
    /// Harmonic: move positions by each spring's exact displacement too.
    #[arg(long)]
    exact_displacement: bool,
    /// Where the step runs: cpu, gpu (any adapter, software included) or auto (a hardware GPU
    /// if present, else the CPU). Default: the scene's, else cpu.
    #[arg(long)]
    backend: Option<String>,
    /// Write `step,time,particle,x,y,z,vx,vy,vz` rows (scene order) to this CSV file.
    #[arg(long)]
    trajectory: Option<PathBuf>,
    /// Override the scene's strain limit: the largest stretch δ/l0 before the run fails as a
    /// blow-up (default 10; `inf`: not checked).
    #[arg(long)]
    strain_limit: Option<f64>,
    /// Override the scene's energy limit: the peak energy residual, a share of the energy
    /// scale, before the run fails (default 0.1; `inf`: not checked).
    #[arg(long)]
    energy_limit: Option<f64>,
    /// Record every M-th frame in the trajectory (step 0 always).
    #[arg(long, default_value_t = 1)]
    every: u64,
}

fn main() -> ExitCode {
    // Before any thread starts.
    harmonic::internals::quiet_headless_adapters();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run(args) => run(args),
        Command::Check { scenes, limits } => check(&scenes, &limits.limits()),
        Command::Render(args) => render::render(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(msg) if msg == CLOSED => ExitCode::from(CLOSED_STATUS),
        Err(msg) => {
            eprintln!("error: {msg}");
            ExitCode::from(2)
        }
    }
}

fn check(paths: &[PathBuf], limits: &Limits) -> Result<(), String> {
    let mut bad = 0;
    for path in paths {
        match checked(path, limits) {
            Ok((particles, frames)) => say!(
                "{}: ok ({particles} particles, {frames} frame(s) for `run`)",
                path.display()
            ),
            Err(e) => {
                eprintln!("{e}");
                bad += 1;
            }
        }
    }
    if bad == 0 {
        Ok(())
    } else {
        Err(format!("{bad} of {} scene(s) invalid", paths.len()))
    }
}

/// What `run` does before its first frame, on one scene: load and validate it, build the
/// simulation, and take the run's length; its particles and frames, or the first problem.
fn checked(path: &std::path::Path, limits: &Limits) -> Result<(usize, u64), String> {
    let scene = Scene::load_with(path, limits).map_err(|e| e.to_string())?;
    for w in scene.warnings() {
        eprintln!("warning: {}: {w}", path.display());
    }
    let at = |e: String| format!("{}: {e}", path.display());
    let sim = Simulation::from_scene_with(&scene, limits).map_err(|e| at(e.to_string()))?;
    let frames = frames(None, None, scene.seconds, sim.config(), limits).map_err(at)?;
    Ok((sim.positions().len(), frames))
}

fn run(args: RunArgs) -> Result<(), String> {
    let limits = args.limits.limits();
    if let Some(k) = args.substeps {
        if k == 0 || k > limits.max_substeps {
            return Err(format!(
                "--substeps {k}: expected 1 to {} per frame (--max-substeps)",
                limits.max_substeps
            ));
        }
    }
    if let Some(path) = &args.trajectory {
        // The scene file by identity: a hard link or a symlink to the scene is the scene (its
        // mesh files are checked once it is read).
        if trajectory::same_file(path, &args.scene) {
            return Err(format!(
                "--trajectory {}: that is the scene being run (the same file); name another file",
                path.display()
            ));
        }
    }
    let scene = Scene::load_with(&args.scene, &limits).map_err(|e| e.to_string())?;
    for w in scene.warnings() {
        eprintln!("warning: {}: {w}", args.scene.display());
    }
    if let Some(path) = &args.trajectory {
        // The mesh files it read are the scene's too.
        let dir = args.scene.parent().unwrap_or(std::path::Path::new(""));
        let read = scene.meshes.iter().filter_map(|m| m.file_path(dir));
        if let Some(file) = read.into_iter().find(|f| trajectory::same_file(path, f)) {
            return Err(format!(
                "--trajectory {}: that is {}, a mesh file the scene reads; name another file",
                path.display(),
                file.display()
            ));
        }
    }
    let built = scene.build();
    let mut config = built.config;
    if let Some(dt) = args.dt {
        config.dt = dt;
    }
    if let Some(k) = args.substeps {
        config.substeps = k;
        config.auto_substeps = false;
    }
    if let Some(name) = &args.integrator {
        config.integrator = name.parse().map_err(|e: SimError| e.to_string())?;
        config.auto_integrator = false;
    }
    if let Some(name) = &args.backend {
        config.backend = name.parse().map_err(|e: SimError| e.to_string())?;
    }
    config.exact_displacement |= args.exact_displacement;
    if let Some(l) = args.strain_limit {
        config.strain_limit = l;
    }
    if let Some(l) = args.energy_limit {
        config.energy_limit = l;
    }
    let sim =
        Simulation::with_props(built.world, config, built.props).map_err(|e| e.to_string())?;
    let mut sim = sim;
    let config = *sim.config();
    if args.every == 0 {
        return Err("--every must be ≥ 1".into());
    }
    let steps = frames(args.steps, args.seconds, scene.seconds, &config, &limits)?;

    let mut traj = match &args.trajectory {
        Some(path) => Some(trajectory::create(path, &sim)?),
        None => None,
    };

    let packed = sim.packed();
    let (n, m) = (packed.particle_count(), packed.spring_count());
    let start = sim.diagnostics();
    let ratio = harmonic::internals::metrics::worst_step_ratio(packed, config.h());
    say!(
        "scene: {} ({n} particles, {m} springs)",
        args.scene.display()
    );
    say!(
        "integrator: {}{}, dt {} s, {} substep(s), h = {:.4e} s",
        config.integrator,
        if config.exact_displacement {
            " (exact displacement)"
        } else {
            ""
        },
        config.dt,
        config.substeps,
        config.h()
    );
    if let Some(why) = sim.integrator_choice() {
        say!("integrator chosen: {why} (the scene names none)");
    }
    if let Some(c) = sim.step_choice() {
        let limit = c.limit.map_or("no stability limit".to_string(), |l| {
            let why = if config.integrator == harmonic::Integrator::Xpbd {
                " (an accuracy bound: xpbd has no stability limit)"
            } else {
                ""
            };
            format!("ω_max h ≤ {l:.3}{why}")
        });
        say!(
            "substeps: automatic, {} ({limit} for ζ in [{:.3}, {:.3}], ω_max = {:.4e} rad/s){}",
            c.substeps,
            c.zeta_range.0,
            c.zeta_range.1,
            c.omega_max,
            if c.capped {
                if config.integrator == harmonic::Integrator::Xpbd {
                    " — capped: the scene needs more, expect inaccuracy"
                } else {
                    " — capped: the scene needs more, expect instability"
                }
            } else {
                ""
            }
        );
    }
    match sim.gpu_adapter() {
        Some(adapter) => say!("backend: gpu, adapter {adapter}"),
        None => say!("backend: cpu ({} thread(s))", rayon::current_num_threads()),
    }
    say!("schedule: {}", sim.schedule());
    match ratio {
        Some((r, k)) => say!(
            "h/h_c of the stiffest spring: {} (spring {k}, h_c = π/ω0)",
            Readable::new(r, 4)
        ),
        None => say!("h/h_c of the stiffest spring: no springs"),
    }
    // Only the closed form aliases; the other integrators have nothing special at n h_c.
    let aliased = config
        .integrator
        .uses_closed_form()
        .then(|| harmonic::internals::step_control::aliasing(packed, config.h(), 0.02))
        .flatten();
    if let Some((k, r)) = aliased {
        say!(
            "warning: spring {k} is stepped at h/h_c = {r:.4}, within 2 % of a whole multiple of h_c: \
             its closed-form impulse vanishes (even) or reverses its stretch rate (odd) there"
        );
    }

    let on_gpu = sim.contacts_on_gpu();
    if let Some(p) = sim.props() {
        let stage = match (on_gpu, sim.backend()) {
            (true, _) => "on the GPU (balls and cuboids)",
            (false, Backend::Gpu) => "on the CPU, the state read back every substep (shapes other than balls and cuboids, or attachments)",
            (false, _) => "on the CPU",
        };
        say!(
            "props: {} bod(ies), contact thickness {} m, friction {} static / {} kinetic; rapier steps {}; contacts {stage}",
            p.bodies().len(),
            p.contact().thickness,
            p.contact().friction,
            p.contact().kinetic_friction,
            if p.moving() { "every substep" } else { "never (all bodies fixed)" }
        );
    }
    let (mut max_strain, mut max_compression) = (start.max_strain, start.max_compression);
    let (mut contacts, mut max_depth, mut swept) = (0usize, 0.0f64, 0usize);
    let mut times = summary::Times::default();
    let mut substeps_run = 0u64;
    let mut bar = Progress::new(steps);
    let t0 = Instant::now();
    let mut failure = None;
    let mut first_quarantine = None;
    let (mut tears, particles, triangles) = (0usize, sim.positions().len(), sim.triangles().len());
    for step in 1..=steps {
        match sim.step() {
            Err(e) => {
                failure = Some(e);
                break;
            }
            Ok(s) if s.quarantined > 0 && first_quarantine.is_none() => {
                first_quarantine = Some(step)
            }
            Ok(_) => {}
        }
        bar.set(step, sim.time());
        tears += sim.torn().len();
        times.add(sim.stats());
        substeps_run += sim.stats().substeps as u64;
        if let Some(p) = sim.props() {
            contacts += p.stats().contacts;
            max_depth = max_depth.max(p.stats().max_depth);
            swept += p.stats().swept;
        }
        let stretch = harmonic::internals::metrics::stretch(sim.packed());
        max_strain = max_strain.max(stretch.tension);
        max_compression = max_compression.max(stretch.compression);
        if let Some(w) = traj.as_mut() {
            if step % args.every == 0 {
                trajectory::write_rows(w, &sim, step).map_err(|e| e.to_string())?;
            }
        }
        if sim.stats().failure.is_some() {
            break;
        }
    }
    let wall = t0.elapsed().as_secs_f64();
    bar.finish();
    if let Some(w) = traj.as_mut() {
        w.flush().map_err(|e| e.to_string())?;
    }
    let done = sim.steps();
    let end = sim.diagnostics();
    let substeps = substeps_run;
    say!(
        "steps: {done} frame(s), {substeps} substep(s), {:.4} s simulated in {wall:.3} s wall ({:.0} steps/s, {:.1} M spring-substeps/s)",
        sim.time(),
        done as f64 / wall,
        (m as f64 * substeps as f64) / wall / 1e6
    );
    say!("{}", times.shares());
    if sim.schedule().has(StageKind::SelfCollision) {
        let (pairs, found) = sim.collision_pairs();
        say!(
            "self-collision: {pairs} candidate pairs at the end; candidates found {found} times in {done} frame(s)"
        );
    }
    if sim.schedule().has(StageKind::Tearing) {
        say!(
            "tearing: {tears} spring(s) broke; the surface opened at {} new particle(s), {} of {triangles} triangle(s) left",
            sim.positions().len() - particles,
            sim.triangles().len()
        );
    }
    if sim.props().is_some() {
        say!(
            "contacts: {contacts} particle-collider contacts ({swept} by the swept test), deepest {max_depth:.3e} m inside"
        );
    }
    say!(
        "max strain: {} % (the largest stretch δ/l0 over the run; compression apart: {} %)",
        Readable::new(100.0 * max_strain, 4),
        Readable::new(100.0 * max_compression, 4)
    );
    say!("{}", summary::energy(&start, &end));
    say!(
        "{}",
        summary::audit(&end.audit, times.audit, times.stage(StageKind::Integrate))
    );
    if let (Some(c), (changes, motion)) = (sim.step_choice(), sim.accuracy()) {
        say!(
            "{}",
            summary::accuracy(c.substeps, sim.config().substeps, changes, motion)
        );
    }
    if let Some(bytes) = summary::peak_rss() {
        say!(
            "memory: peak RSS {:.1} MiB for {n} particles and {m} springs (the process's whole footprint)",
            bytes as f64 / (1 << 20) as f64,
        );
    }
    let quarantined = sim.quarantined();
    if let Some(f) = sim.diagnostics().failure {
        return Err(format!("run failed at {f}"));
    }
    match (failure, first_quarantine) {
        (Some(e), _) => Err(format!("run stopped: {e}")),
        (None, Some(step)) => {
            let list: Vec<String> = quarantined
                .iter()
                .take(8)
                .map(|(i, _)| i.to_string())
                .collect();
            say!(
                "non-finite: {} particle(s) quarantined (frozen at their last finite position), first at step {step}: {}{}",
                quarantined.len(),
                list.join(", "),
                if quarantined.len() > list.len() { ", …" } else { "" }
            );
            Err(format!(
                "run degraded: {} particle(s) went non-finite and were quarantined, the first at step {step} \
                 (a step too large for the scene, or a spring that degenerated to a point)",
                quarantined.len()
            ))
        }
        (None, None) => {
            say!("non-finite: none");
            Ok(())
        }
    }
}
