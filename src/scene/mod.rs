//! RON scenes: the schema authors write, loading with located errors, and building a World.
//!
//! A scene lists explicit `particles` and `springs` (indices are positions in `particles`)
//! and any number of generated `cloths` and `ropes`, and cloths given as triangle `meshes`.
//! Particle order in the built scene, and so in trajectories: explicit particles, then each
//! cloth row-major (row 0 first, columns left to right), then each rope from `start` to `end`,
//! then each mesh's welded vertices in order of first appearance.
//!
//! # Stiffness by frequency
//! A spring takes either `stiffness` (κ, N/m) or `frequency` (f, Hz), and either `damping`
//! (c, N·s/m) or `damping_ratio` (ζ). With the reduced mass `μ = m_a m_b/(m_a+m_b)` of its two
//! end particles (as if both were free, so a pin does not change the material):
//! `μ δ̈ = −κ δ − c δ̇` has natural angular frequency `ω0 = √(κ/μ) = 2πf` and damping ratio
//! `ζ = c/(2√(κμ))`, hence `κ = μ (2πf)²` and `c = 2 ζ μ (2πf)`. With `stiffness` given,
//! `damping_ratio` means `c = 2 ζ √(κ μ)`.

mod behaviour;
mod build;
pub use build::{spawn_cloth, spawn_mesh};
pub mod mesh;
mod mesh_file;
pub mod props;
mod validate;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Issue, SceneError};

pub use build::BuiltScene;

/// A vector as `(x, y, z)`.
pub type V3 = [f64; 3];

fn yes() -> bool {
    true
}
fn default_gravity() -> V3 {
    [0.0, -9.81, 0.0]
}

/// How much a scene may ask for, checked on its description before anything is allocated, so
/// a generator asking for 10⁹ particles is a located error, not an out-of-memory abort.
/// The defaults suit a game (about 6 GB at the CPU back end's measured bytes per particle,
/// BENCHMARKS.md); raise them with [`Scene::parse_with`], [`Scene::load_with`] and
/// [`crate::Simulation::from_scene_with`], or `--max-particles` / `--max-springs`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Most particles a scene may build ([`Scene::particle_count`]).
    pub max_particles: u64,
    /// Most springs a scene may build ([`Scene::spring_count`]).
    pub max_springs: u64,
    /// Fixed substeps per frame (the automatic choice caps itself at the same default).
    pub max_substeps: u32,
    /// Frames one run may take (`seconds / dt`): a typo such as `dt: 1e-12` is refused
    /// instead of running for days.
    pub max_frames: u64,
    /// Substeps one run may take where they are fixed (frames × substeps per frame): each
    /// bound alone still admits a run of days.
    pub max_run_substeps: u64,
}

impl Limits {
    /// The defaults: 2²² particles, 2²⁵ springs, 100 000 fixed substeps per frame,
    /// 1 000 000 frames a run (4.6 hours at 60 Hz) and 10⁸ fixed substeps a run.
    pub const DEFAULT: Limits = Limits {
        max_particles: 1 << 22,
        max_springs: 1 << 25,
        max_substeps: crate::step_control::MAX_SUBSTEPS,
        max_frames: 1_000_000,
        max_run_substeps: 100_000_000,
    };

    /// The frames a run of `seconds` at `dt` takes, or why it is refused (an [`Issue`] at
    /// `seconds`): a time that is not finite and > 0, or more frames than
    /// [`Self::max_frames`].
    pub fn frames(&self, seconds: f64, dt: f64) -> Result<u64, Issue> {
        let issue = |message: String| Issue {
            location: "seconds".into(),
            message,
        };
        if !(seconds.is_finite() && seconds > 0.0) {
            return Err(issue(format!("must be finite and > 0, got {seconds:?}")));
        }
        if !(dt.is_finite() && dt > 0.0) {
            return Err(issue(format!(
                "needs a frame step dt finite and > 0, got {dt:?}"
            )));
        }
        // A hair under one frame is one frame (a duration written as a multiple of dt).
        if seconds / dt < 1.0 - 1e-9 {
            return Err(issue(format!(
                "{seconds:?} s is shorter than one frame (dt {dt:?} s): a run takes whole frames"
            )));
        }
        let frames = (seconds / dt).round();
        if frames.is_nan() || frames > self.max_frames as f64 {
            return Err(issue(format!(
                "{seconds:?} s at dt {dt:?} s is {frames:?} frames; the limit is {} \
                 (Limits::max_frames, --max-frames)",
                self.max_frames
            )));
        }
        Ok(frames as u64)
    }

    /// Whether `frames` frames at `substeps` fixed substeps each fit
    /// [`Self::max_run_substeps`]; the error says how many that is.
    pub fn run_substeps(&self, frames: u64, substeps: u32) -> Result<(), String> {
        let total = frames.saturating_mul(u64::from(substeps));
        if total > self.max_run_substeps {
            return Err(format!(
                "{frames} frame(s) × {substeps} substep(s) is {:.3e} substeps; the limit is \
                 {:.3e} (Limits::max_run_substeps, --max-run-substeps)",
                total as f64, self.max_run_substeps as f64
            ));
        }
        Ok(())
    }
}

/// The world's bound (m): every position a scene gives (particles, cloth and rope ends,
/// bodies, keyframes, shape points) lies within ±1e5 m of the origin on each axis, and every
/// size within 1e5 m. Bodies run in rapier's f32, which resolves 8 mm there; a game whose
/// world is larger moves its origin with the player.
pub const WORLD_BOUND: f64 = 1e5;

/// The speed bound: every velocity a scene gives (m/s, and body spins in rad/s) lies within
/// ±1e4 on each axis, faster than any projectile a cloth meets.
pub const SPEED_BOUND: f64 = 1e4;

/// The largest file [`Scene::load`] reads (256 MiB): a scene is text, and a device or a pipe
/// that never ends (`/dev/zero`) is refused by name instead of read until memory runs out.
pub const MAX_FILE_BYTES: u64 = 256 << 20;

/// A file's text, refused before it is opened unless it is a regular file (opening a FIFO
/// would block until a writer came) and read to at most [`MAX_FILE_BYTES`].
pub(crate) fn read_text(path: &Path) -> Result<String, SceneError> {
    use std::io::Read;
    let io = |source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    };
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        let kind = if meta.is_dir() {
            "a directory"
        } else {
            "a device, pipe or socket"
        };
        return Err(SceneError::NotAFile {
            path: path.to_path_buf(),
            kind,
        });
    }
    let too_large = || SceneError::TooLarge {
        path: path.to_path_buf(),
        max: MAX_FILE_BYTES,
    };
    if meta.len() > MAX_FILE_BYTES {
        return Err(too_large());
    }
    let mut text = String::new();
    // The file may grow after its size was read.
    (std::fs::File::open(path).map_err(io)?)
        .take(MAX_FILE_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(io)?;
    if text.len() as u64 > MAX_FILE_BYTES {
        return Err(too_large());
    }
    Ok(text)
}

impl Default for Limits {
    fn default() -> Self {
        Limits::DEFAULT
    }
}

/// A scene file.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, rename = "Scene")]
pub struct Scene {
    /// A label for the scene; the simulation does not read it.
    #[serde(default)]
    pub name: Option<String>,
    /// Frame step (s): one `Simulation::step` advances this much, in `substeps` substeps.
    pub dt: f64,
    /// Substeps per frame; absent: chosen automatically to keep the integrator stable.
    #[serde(default)]
    pub substeps: Option<u32>,
    /// Gravitational acceleration (m/s²); `(0, −9.81, 0)` when absent.
    #[serde(default = "default_gravity")]
    pub gravity: V3,
    /// The wind the cloths with `air` feel; still when absent.
    #[serde(default)]
    pub wind: crate::Wind,
    /// Integrator name; when absent the engine chooses by rule, the cheaper within the
    /// tolerance of `symplectic-euler` and `harmonic` ([`crate::SimConfig::auto_integrator`]).
    #[serde(default)]
    pub integrator: Option<String>,
    /// Back end: `"cpu"` (the default), `"gpu"` or `"auto"`; the CLI's `--backend` overrides it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backend: Option<String>,
    /// Harmonic only: move positions by each spring's exact displacement too.
    #[serde(default)]
    pub exact_displacement: bool,
    /// Default run length for `harmonic run` (s).
    #[serde(default)]
    pub seconds: Option<f64>,
    /// [`crate::SimConfig::strain_limit`] (absent: its default; `inf`: not checked).
    #[serde(default)]
    pub strain_limit: Option<f64>,
    /// [`crate::SimConfig::tolerance`] (absent: 1 % of the energy scale).
    #[serde(default)]
    pub tolerance: Option<f64>,
    /// [`crate::SimConfig::energy_limit`] (absent: 10 %; `inf`: not checked).
    #[serde(default)]
    pub energy_limit: Option<f64>,
    /// Explicit particles: scene indices 0, 1, … in this order.
    #[serde(default)]
    pub particles: Vec<ParticleDef>,
    /// Springs between explicit particles.
    #[serde(default)]
    pub springs: Vec<SpringDef>,
    /// Generated cloth grids.
    #[serde(default)]
    pub cloths: Vec<Cloth>,
    /// Generated ropes and chains.
    #[serde(default)]
    pub ropes: Vec<Rope>,
    /// Cloths given as triangle meshes.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub meshes: Vec<mesh::MeshCloth>,
    /// Rigid props (rapier bodies, one collider each). None: no contact stage, no rapier world.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub bodies: Vec<props::BodyDef>,
    /// The cloth's contact material (thickness, friction, restitution).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact: Option<props::ContactMaterial>,
    /// Particles held at points of bodies.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub attachments: Vec<props::AttachmentDef>,
}

/// An explicit particle of a scene.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ParticleDef {
    /// Start position (m).
    pub position: V3,
    /// Start velocity (m/s); zero when absent.
    #[serde(default)]
    pub velocity: V3,
    /// kg, > 0 (also for pinned particles, whose mass sets frequency-given springs).
    pub mass: f64,
    /// Held where it is (a [`crate::Pin`]).
    #[serde(default)]
    pub pinned: bool,
}

/// A spring between two explicit particles, with its material.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpringDef {
    /// One end: an index into `particles`.
    pub a: usize,
    /// The other end: an index into `particles`.
    pub b: usize,
    /// κ (N/m); give this or `frequency`.
    #[serde(default)]
    pub stiffness: Option<f64>,
    /// c (N·s/m); give this or `damping_ratio` (no damping without either).
    #[serde(default)]
    pub damping: Option<f64>,
    /// Natural frequency f (Hz), giving `κ = μ (2πf)²`; give this or `stiffness`.
    #[serde(default)]
    pub frequency: Option<f64>,
    /// Damping ratio ζ, giving `c = 2 ζ √(κ μ)`; give this or `damping`.
    #[serde(default)]
    pub damping_ratio: Option<f64>,
    /// Defaults to the initial distance of the two ends.
    #[serde(default)]
    pub rest_length: Option<f64>,
}

impl SpringDef {
    /// Its material: the stiffness and damping fields as a [`SpringSpec`].
    pub fn spec(&self) -> SpringSpec {
        SpringSpec {
            stiffness: self.stiffness,
            damping: self.damping,
            frequency: self.frequency,
            damping_ratio: self.damping_ratio,
        }
    }
}

/// Spring material: `stiffness` or `frequency`, plus optionally `damping` or `damping_ratio`.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpringSpec {
    /// κ (N/m); give this or `frequency`.
    #[serde(default)]
    pub stiffness: Option<f64>,
    /// c (N·s/m); give this or `damping_ratio` (no damping without either).
    #[serde(default)]
    pub damping: Option<f64>,
    /// Natural frequency f (Hz), giving `κ = μ (2πf)²`; give this or `stiffness`.
    #[serde(default)]
    pub frequency: Option<f64>,
    /// Damping ratio ζ, giving `c = 2 ζ √(κ μ)`; give this or `damping`.
    #[serde(default)]
    pub damping_ratio: Option<f64>,
}

/// Which plane a cloth is laid out in.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
pub enum Plane {
    /// Hanging: columns along +x, rows downward along −y from `origin`.
    #[default]
    Vertical,
    /// Lying: columns along +x, rows along +z from `origin`.
    Horizontal,
}

/// A pinned part of a cloth. Row 0 is the "top" (the row at `origin`).
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
pub enum Anchor {
    /// The particle at column 0 of row 0.
    TopLeft,
    /// The particle at the last column of row 0.
    TopRight,
    /// The particle at column 0 of the last row.
    BottomLeft,
    /// The particle at the last column of the last row.
    BottomRight,
    /// Every particle of row 0.
    TopEdge,
    /// Every particle of the last row.
    BottomEdge,
    /// Every particle of column 0.
    LeftEdge,
    /// Every particle of the last column.
    RightEdge,
    /// `(column, row)`.
    Particle(u32, u32),
}

/// A rectangular cloth grid.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Cloth {
    /// Position of particle (column 0, row 0).
    pub origin: V3,
    /// `(width, height)` in metres.
    pub size: (f64, f64),
    /// `(columns, rows)` of particles, each ≥ 2.
    pub resolution: (u32, u32),
    /// The plane the grid is laid out in.
    #[serde(default)]
    pub plane: Plane,
    /// Total mass (kg), spread evenly over the particles.
    pub mass: f64,
    /// Springs to the right and lower neighbours.
    pub structural: SpringSpec,
    /// Springs along both diagonals of each cell.
    #[serde(default)]
    pub shear: Option<SpringSpec>,
    /// Springs to the second neighbour along rows and columns.
    #[serde(default)]
    pub bend: Option<SpringSpec>,
    /// The parts held in place.
    #[serde(default)]
    pub pins: Vec<Anchor>,
    /// Start velocity of every particle (m/s).
    #[serde(default)]
    pub velocity: V3,
    /// Its aerodynamics (`(density, drag, lift)`); none: it feels no air.
    #[serde(default)]
    pub air: Option<crate::Aero>,
    /// Tethers from its pinned particles (`(slack, anchors)`); none: no tethers.
    #[serde(default)]
    pub tethers: Option<crate::TetherSpec>,
    /// Its springs held within `(1 + stretch)` of their rest lengths (`(stretch, passes)`);
    /// none: no limit.
    #[serde(default)]
    pub stretch_limit: Option<crate::StretchLimit>,
    /// Its springs break past a stretch (`(stretch)`); none: it does not tear. A tearable
    /// cloth keeps its springs one by one (built as a mesh of its grid).
    #[serde(default)]
    pub tearing: Option<crate::Tearing>,
    /// Collision of its particles with each other and other colliding cloths' (`(thickness,
    /// friction)`); none: it passes through itself.
    #[serde(default)]
    pub self_collision: Option<crate::SelfCollision>,
}

/// A rope or chain of equal particles from `start` to `end`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Rope {
    /// Position of the first particle (m).
    pub start: V3,
    /// Position of the last particle (m).
    pub end: V3,
    /// Number of particles, ≥ 2.
    pub particles: u32,
    /// Total mass (kg).
    pub mass: f64,
    /// Material of the springs between neighbours.
    pub spring: SpringSpec,
    /// Pin the first particle (`true` when absent).
    #[serde(default = "yes")]
    pub pin_start: bool,
    /// Pin the last particle.
    #[serde(default)]
    pub pin_end: bool,
    /// Springs to the second neighbour (stiff chains resist folding).
    #[serde(default)]
    pub bend: Option<SpringSpec>,
}

impl Scene {
    /// An empty scene stepping `dt` with the schema's defaults (automatic substeps, standard
    /// gravity, default integrator and back end); tools fill in the rest.
    pub fn new(dt: f64) -> Scene {
        Scene {
            name: None,
            dt,
            substeps: None,
            gravity: default_gravity(),
            wind: crate::Wind::default(),
            integrator: None,
            backend: None,
            exact_displacement: false,
            seconds: None,
            strain_limit: None,
            tolerance: None,
            energy_limit: None,
            particles: vec![],
            springs: vec![],
            cloths: vec![],
            ropes: vec![],
            meshes: vec![],
            bodies: vec![],
            contact: None,
            attachments: vec![],
        }
    }

    /// Reads, parses and validates a scene file within the default [`Limits`].
    pub fn load(path: impl AsRef<Path>) -> Result<Scene, SceneError> {
        Scene::load_with(path, &Limits::DEFAULT)
    }

    /// Reads, parses and validates a scene file within `limits`.
    pub fn load_with(path: impl AsRef<Path>, limits: &Limits) -> Result<Scene, SceneError> {
        let path = path.as_ref();
        Scene::parse_with(&read_text(path)?, path, limits)
    }

    /// Parses and validates scene text within the default [`Limits`]; `path` only names the
    /// source in errors.
    pub fn parse(text: &str, path: impl AsRef<Path>) -> Result<Scene, SceneError> {
        Scene::parse_with(text, path, &Limits::DEFAULT)
    }

    /// Parses and validates scene text within `limits`.
    pub fn parse_with(
        text: &str,
        path: impl AsRef<Path>,
        limits: &Limits,
    ) -> Result<Scene, SceneError> {
        let path: PathBuf = path.as_ref().to_path_buf();
        // A byte-order mark some editors write is not part of the scene.
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let options = ron::Options::default()
            .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME);
        let mut scene: Scene = options.from_str(text).map_err(|e| SceneError::Parse {
            path: path.clone(),
            line: e.span.start.line,
            column: e.span.start.col,
            message: e.code.to_string(),
        })?;
        // Mesh files beside the scene, read before anything is checked.
        let dir = path.parent().unwrap_or(Path::new(""));
        let issues: Vec<Issue> = (scene.meshes.iter_mut().enumerate())
            .filter_map(|(i, m)| m.read_file(dir, &format!("meshes[{i}]")).err())
            .collect();
        if !issues.is_empty() {
            return Err(SceneError::Invalid { path, issues });
        }
        let issues = scene.validate_with(limits);
        if issues.is_empty() {
            Ok(scene)
        } else {
            Err(SceneError::Invalid { path, issues })
        }
    }

    /// Number of particles the scene builds (saturating, so huge generators can be refused);
    /// a mesh counts its vertices before welding, at most what it builds.
    pub fn particle_count(&self) -> u64 {
        let cloth = self
            .cloths
            .iter()
            .map(|c| c.resolution.0 as u64 * c.resolution.1 as u64);
        let rope = self.ropes.iter().map(|r| r.particles as u64);
        // A mesh by its vertices before welding: at most what it builds.
        let mesh = self.meshes.iter().map(|m| m.vertices.len() as u64);
        cloth
            .chain(rope)
            .chain(mesh)
            .fold(self.particles.len() as u64, u64::saturating_add)
    }

    /// Number of springs the scene builds (saturating), counted from its description; a mesh
    /// counts at most what it builds.
    pub fn spring_count(&self) -> u64 {
        let cloth = self.cloths.iter().map(|c| {
            let (x, y) = (c.resolution.0 as u64, c.resolution.1 as u64);
            let lines = |k: u64| {
                x.saturating_sub(k)
                    .saturating_mul(y)
                    .saturating_add(y.saturating_sub(k).saturating_mul(x))
            };
            let shear = 2 * x.saturating_sub(1).saturating_mul(y.saturating_sub(1));
            lines(1)
                .saturating_add(if c.shear.is_some() { shear } else { 0 })
                .saturating_add(if c.bend.is_some() { lines(2) } else { 0 })
        });
        let rope = self.ropes.iter().map(|r| {
            let p = r.particles as u64;
            p.saturating_sub(1)
                + if r.bend.is_some() {
                    p.saturating_sub(2)
                } else {
                    0
                }
        });
        // A mesh at most: three edges per triangle, and a bend across each (shared) edge.
        let mesh = self.meshes.iter().map(|m| {
            let t = m.triangles.len() as u64;
            t.saturating_mul(if m.bend.is_some() { 6 } else { 3 })
        });
        cloth
            .chain(rope)
            .chain(mesh)
            .fold(self.springs.len() as u64, u64::saturating_add)
    }
}

/// The body of the scene fuzz target (`tests/fuzz`) and of its regression tests: untrusted
/// bytes are parsed within small limits and, when they make a sound scene, built and stepped
/// a few frames on the CPU. An error is a fine answer; a panic, a hang, a runaway allocation
/// or a non-finite state in an `Ok` is a bug.
#[doc(hidden)]
pub fn exercise(data: &[u8]) -> Result<crate::Diagnostics, crate::Error> {
    const LIMITS: Limits = Limits {
        max_particles: 4096,
        max_springs: 32_768,
        max_substeps: 64,
        ..Limits::DEFAULT
    };
    let text = String::from_utf8_lossy(data);
    let scene = Scene::parse_with(&text, "fuzz.ron", &LIMITS)?;
    let mut sim = crate::Simulation::from_scene_with(&scene, &LIMITS)?;
    let mut config = *sim.config();
    config.backend = crate::Backend::Cpu;
    config.substeps = config.substeps.min(LIMITS.max_substeps);
    config.auto_substeps = false;
    sim.set_config(config)?;
    for _ in 0..3 {
        sim.step()?;
    }
    Ok(sim.diagnostics())
}
