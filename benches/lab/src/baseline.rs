//! A bit-for-bit record of what the engine computes, for a refactor that must change nothing
//! (the frame as a schedule): every scene of a folder and every hard case for [`FRAMES`] frames
//! with its own settings, each game integrator named on the chain and the hanging cloth, a run
//! against the caller's rapier sets (`step_with`) and, where an adapter exists, the GPU back end.
//! Per run it keeps the substeps of each frame, a hash of each frame's f64 state (positions,
//! velocities, the frame's energy books), how the run ended, and the run's energy audit.
//! `harmonic-lab baseline --write FILE` records it; `--check FILE` runs it again and names each
//! run's first difference. The record is of one machine: the grid pass picks its vector width
//! at run time, so record the baseline and check against it on the same kind of machine.

use std::collections::BTreeMap;
use std::path::Path;

use harmonic::{
    Backend, EnergyAudit, Integrator, Scene, SimConfig, SimError, Simulation, StepStats,
};

/// Frames each run takes: past the accuracy controller's first calm halving (120 frames).
pub const FRAMES: u64 = 150;

/// The integrators a game may pick, each named on the chain and the hanging cloth.
fn game_integrators() -> impl Iterator<Item = Integrator> {
    Integrator::ALL.into_iter()
}

/// FNV-1a, 64 bits: a stable hash of the bytes given (no seed, the same on every run).
#[derive(Clone, Copy)]
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn bytes(mut self, bytes: &[u8]) -> Self {
        for b in bytes {
            self.0 = (self.0 ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3);
        }
        self
    }
}

/// One run's record: `(key, value)` lines, keys `substeps`, `states`, `end`, `audit`.
fn record(
    sim: &mut Simulation,
    mut step: impl FnMut(&mut Simulation) -> Result<StepStats, SimError>,
) -> Vec<(&'static str, String)> {
    let (mut substeps, mut states) = (Vec::new(), Vec::new());
    let mut end = format!("ran {FRAMES} frames");
    for frame in 0..FRAMES {
        let stats = match step(sim) {
            Ok(s) => s,
            Err(e) => {
                end = format!("error at frame {frame}: {e}");
                break;
            }
        };
        substeps.push(stats.substeps.to_string());
        let mut h = Fnv::new();
        for (x, v) in sim.positions().iter().zip(sim.velocities()) {
            for c in x.to_array().into_iter().chain(v.to_array()) {
                h = h.bytes(&c.to_bits().to_le_bytes());
            }
        }
        h = h.bytes(books(&stats.audit).as_bytes());
        states.push(format!("{:016x}", h.0));
        if let Some(f) = stats.failure {
            end = format!("failure at frame {frame}: {f:?}");
            break;
        }
    }
    vec![
        ("substeps", substeps.join(",")),
        ("states", states.join(",")),
        ("end", end),
        ("audit", books(&sim.diagnostics().audit)),
    ]
}

/// The energy books bit for bit (f64's Debug is its shortest exact form), as the derived
/// Debug wrote them before the forces', limits' and torn lines: those are added only where they are
/// not zero, so a record made before them still holds.
fn books(a: &EnergyAudit) -> String {
    let forces = if a.forces != 0.0 {
        format!(", forces: {:?}", a.forces)
    } else {
        String::new()
    };
    let mut limits = String::new();
    if a.limits != 0.0 {
        limits += &format!(", limits: {:?}", a.limits);
    }
    if a.torn != 0.0 {
        limits += &format!(", torn: {:?}", a.torn);
    }
    format!(
        "EnergyAudit {{ start: {:?}, energy: {:?}, edits: {:?}, attachments: {:?}, damping: {:?}, \
         contacts: {:?}, friction: {:?}, quarantine: {:?}, residual: {:?}, peak_residual: {:?}, \
         scale: {:?}{forces}{limits} }}",
        a.start,
        a.energy,
        a.edits,
        a.attachments,
        a.damping,
        a.contacts,
        a.friction,
        a.quarantine,
        a.residual,
        a.peak_residual,
        a.scale
    )
}

/// The hard cases' names begin so.
const HARD: &str = "hard/";

/// Whether `--only` keeps the run `name`: its name contains it, and a hard case only where it
/// begins `hard/` (the hard cases are not made otherwise).
fn wanted(name: &str, only: Option<&str>) -> bool {
    only.is_none_or(|o| name.contains(o) && (!name.starts_with(HARD) || o.starts_with(HARD)))
}

/// The runs, by name: each builds its simulation and records it. `only` keeps the runs whose
/// name contains it (the hard cases only where it begins `hard/`).
pub fn runs(scenes: &Path, only: Option<&str>) -> Result<Vec<(String, String, String)>, String> {
    let wanted = |name: &str| wanted(name, only);
    let mut out = Vec::new();
    let mut push = |name: String, lines: Vec<(&'static str, String)>| {
        for (k, v) in lines {
            out.push((name.clone(), k.to_string(), v));
        }
    };
    let load = |file: &str| {
        let path = scenes.join(file);
        Scene::load(&path).map_err(|e| e.to_string())
    };
    let mut files: Vec<_> = std::fs::read_dir(scenes)
        .map_err(|e| format!("{}: {e}", scenes.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "ron"))
        .collect();
    files.sort();
    for path in files {
        let name = format!(
            "scenes/{}",
            path.file_name().unwrap_or_default().to_string_lossy()
        );
        if wanted(&name) {
            let scene = Scene::load(&path).map_err(|e| e.to_string())?;
            push(name, built(&scene, |_| {}));
        }
    }
    // Their equilibrium starts take minutes to find: made only where they may be wanted.
    let hard = only.is_none_or(|o| o.starts_with(HARD));
    for (file, scene) in hard.then(crate::stability::hard_scenes).unwrap_or_default() {
        let name = format!("{HARD}{file}");
        if wanted(&name) {
            push(name, built(&scene, |_| {}));
        }
    }
    for file in ["chain.ron", "hanging_cloth.ron"] {
        for integrator in game_integrators() {
            let name = format!("{file} --integrator {integrator}");
            if wanted(&name) {
                let scene = load(file)?;
                push(
                    name,
                    built(&scene, |c| {
                        c.integrator = integrator;
                        c.auto_integrator = false;
                    }),
                );
            }
        }
    }
    let name = "step_with: a cloth thrown at the caller's dynamic ball".to_string();
    if wanted(&name) {
        push(name, callers_sets(Backend::Cpu));
    }
    // The device's frames: all substeps in one submit (the hanging cloth; the drape, with
    // the device's contacts against a fixed ball), one submit per substep (the trampoline's
    // dynamic ball on the device's contacts), and the state back every substep for the CPU's
    // contacts (the cape's attachments, the caller's sets); the tethers' clamp and the air
    // on the device (the tethered cloth, the windy flag in its gusts).
    for file in [
        "hanging_cloth.ron",
        "drape_sphere.ron",
        "trampoline.ron",
        "cape.ron",
        "tethered_cloth.ron",
        "windy_flag.ron",
    ] {
        let name = format!("{file} --backend gpu");
        if wanted(&name) {
            let scene = load(file)?;
            push(name, built(&scene, |c| c.backend = Backend::Gpu));
        }
    }
    let name = "step_with --backend gpu".to_string();
    if wanted(&name) {
        push(name, callers_sets(Backend::Gpu));
    }
    Ok(out)
}

/// A scene's run with its own settings, `edit`ed; a simulation that does not build is
/// recorded as such (the GPU without an adapter).
fn built(scene: &Scene, edit: impl FnOnce(&mut SimConfig)) -> Vec<(&'static str, String)> {
    let b = scene.build();
    let mut config = b.config;
    edit(&mut config);
    match Simulation::with_props(b.world, config, b.props) {
        Ok(mut sim) => record(&mut sim, |s| s.step().copied()),
        Err(e) => vec![("end", format!("not built: {e}"))],
    }
}

/// The coupling with the caller's own rapier sets, as `tests/contacts.rs` runs it, on `backend`.
fn callers_sets(backend: Backend) -> Vec<(&'static str, String)> {
    use harmonic::rapier3d::prelude::*;
    let text = r#"Scene(
        dt: 0.004, gravity: (0.0, 0.0, 0.0),
        cloths: [(origin: (-0.3, 0.3, -1.0), size: (0.6, 0.6), resolution: (16, 16), plane: Vertical,
                  mass: 0.5, structural: (frequency: 60.0, damping_ratio: 0.2),
                  shear: Some((frequency: 60.0, damping_ratio: 0.2)), velocity: (0.0, 0.0, 3.0))],
    )"#;
    let scene = Scene::parse(text, "callers_sets").expect("a sound scene");
    let mut sim = Simulation::from_scene(&scene).expect("builds");
    if backend == Backend::Gpu {
        let config = SimConfig {
            backend,
            ..*sim.config()
        };
        if let Err(e) = sim.set_config(config) {
            return vec![("end", format!("not built: {e}"))];
        }
    }
    let mut world = PhysicsWorld::new();
    world.gravity = Vector::ZERO;
    world.integration_parameters.dt = sim.config().dt as f32;
    world.insert(
        RigidBodyBuilder::dynamic(),
        ColliderBuilder::ball(0.15).mass(0.4),
    );
    record(&mut sim, |s| {
        let stats = *s.step_with(&mut world.bodies, &world.colliders)?;
        world.step();
        Ok(stats)
    })
}

/// The record as text: a header, then `name<TAB>key<TAB>value` lines.
pub fn write(runs: &[(String, String, String)]) -> String {
    let mut text = format!(
        "# harmonic-lab baseline: {} runs of up to {FRAMES} frames; check it on the kind of \
         machine that wrote it\n",
        runs.iter().filter(|r| r.1 == "end").count(),
    );
    for (name, key, value) in runs {
        text.push_str(&format!("{name}\t{key}\t{value}\n"));
    }
    text
}

/// Every difference between a recorded baseline and this run, one line each (empty: the
/// same bits): a run missing or new, or the first frame whose substeps or state differ. With
/// `only`, the recorded runs it would not keep are passed over.
pub fn differences(
    recorded: &str,
    runs: &[(String, String, String)],
    only: Option<&str>,
) -> Vec<String> {
    let parse = |text: &str| -> BTreeMap<(String, String), String> {
        text.lines()
            .filter(|l| !l.starts_with('#') && !l.is_empty())
            .filter(|l| wanted(l.split('\t').next().unwrap_or(""), only))
            .filter_map(|l| {
                let mut parts = l.splitn(3, '\t');
                let (name, key) = (parts.next()?, parts.next()?);
                Some(((name.into(), key.into()), parts.next().unwrap_or("").into()))
            })
            .collect()
    };
    let was = parse(recorded);
    let now: BTreeMap<_, _> = runs
        .iter()
        .map(|(n, k, v)| ((n.clone(), k.clone()), v.clone()))
        .collect();
    let mut out = Vec::new();
    for ((name, key), old) in &was {
        match now.get(&(name.clone(), key.clone())) {
            None => out.push(format!("{name}: {key} not run now")),
            Some(new) if new == old => {}
            Some(new) if key == "substeps" || key == "states" => {
                let (a, b): (Vec<_>, Vec<_>) = (old.split(',').collect(), new.split(',').collect());
                let first = (0..a.len().max(b.len())).find(|&i| a.get(i) != b.get(i));
                out.push(format!(
                    "{name}: {key} differ first at frame {} ({} frames recorded, {} now)",
                    first.unwrap_or(0),
                    a.len(),
                    b.len()
                ));
            }
            Some(new) => out.push(format!("{name}: {key} was `{old}`, now `{new}`")),
        }
    }
    for (name, key) in now.keys() {
        if !was.contains_key(&(name.clone(), key.clone())) {
            out.push(format!("{name}: {key} not in the baseline"));
        }
    }
    out
}
