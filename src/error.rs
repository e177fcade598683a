//! Errors at each boundary: scene files, the simulation step.

use std::fmt;
use std::path::PathBuf;

use hecs::Entity;

/// A vector in messages, each coordinate as `{:?}` prints it: exponents for very large or
/// small values instead of hundreds of digits.
pub(crate) struct V(pub glam::DVec3);

impl fmt::Display for V {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[{:?}, {:?}, {:?}]", self.0.x, self.0.y, self.0.z)
    }
}

/// One semantic problem in a scene, named by its entry (`springs[3].b`).
#[derive(Clone, Debug, PartialEq)]
pub struct Issue {
    /// Path of the entry at fault, e.g. `springs[3].b` (`scene` for the scene's size limits).
    pub location: String,
    /// What is wrong with it.
    pub message: String,
}

impl fmt::Display for Issue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.location, self.message)
    }
}

/// Why a scene could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// Scene file that could not be read.
        path: PathBuf,
        /// The I/O error reading it.
        #[source]
        source: std::io::Error,
    },
    /// Not a regular file: a directory, a device (`/dev/zero`), a FIFO or a socket.
    #[error("{path}: not a regular file but {kind}")]
    NotAFile {
        /// The path given.
        path: PathBuf,
        /// What it is instead.
        kind: &'static str,
    },
    /// Larger than [`crate::scene::MAX_FILE_BYTES`].
    #[error(
        "{path}: larger than {max} bytes (harmonic::scene::MAX_FILE_BYTES), too large for a scene"
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The most read.
        max: u64,
    },
    /// Syntax, unknown fields and wrong types, at ron's line and column (1-based).
    #[error("{path}:{line}:{column}: {message}")]
    Parse {
        /// Scene file the problem was found in (or the name the text was parsed under).
        path: PathBuf,
        /// Line of the problem, 1-based.
        line: usize,
        /// Column of the problem, 1-based.
        column: usize,
        /// ron's description of the problem.
        message: String,
    },
    /// Every semantic problem found, one per line.
    #[error("{}", format_issues(path, issues))]
    Invalid {
        /// Scene file the problems were found in (or the name the text was parsed under; for a
        /// part added at run time, the call, e.g. `add_cloth`).
        path: PathBuf,
        /// The problems, in file order.
        issues: Vec<Issue>,
    },
}

fn format_issues(path: &std::path::Path, issues: &[Issue]) -> String {
    issues
        .iter()
        .map(|i| format!("{}: {i}", path.display()))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Why a step could not be taken.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SimError {
    /// An integrator name matches none of [`crate::Integrator::ALL`].
    #[error("unknown integrator `{0}` (known: {known})", known = known_integrators())]
    UnknownIntegrator(String),
    /// An integrator name is one of the research variants ([`crate::RESEARCH_INTEGRATORS`]),
    /// which the lab runs and a game does not.
    #[error(
        "integrator `{0}` is a research variant: it moved to the lab crate, where \
         `harmonic-lab bench --integrators {0}` and `harmonic-lab stability` run it (a scene \
         names one of: {known})",
        known = known_integrators()
    )]
    ResearchIntegrator(String),
    /// A back-end name is not `cpu`, `gpu` or `auto`.
    #[error("unknown backend `{0}` (known: cpu, gpu, auto)")]
    UnknownBackend(String),
    /// The GPU back end could not be set up or run.
    #[error(transparent)]
    Gpu(#[from] GpuError),
    /// [`crate::Simulation::step_with`] was called on a simulation whose scene has bodies.
    #[error("this simulation's scene has bodies of its own; step it with `step`, not `step_with`")]
    OwnBodies,
    /// A particle's [`crate::Attachment`] names a body that is no longer in the rigid-body set.
    #[error("particle {particle:?} is attached to a body that no longer exists")]
    DanglingAttachment {
        /// The attached particle.
        particle: Entity,
    },
    /// A config's frame step `dt` is not finite and > 0.
    #[error("time step must be finite and > 0, got {0:?}")]
    BadStep(f64),
    /// [`crate::Simulation::advance`] was given a frame time that is not finite and ≥ 0.
    #[error("frame time must be finite and ≥ 0, got {0:?}")]
    BadFrameTime(f64),
    /// [`crate::Simulation::set_forces`] was not given one force per particle.
    #[error("set_forces: {given} force(s) for {particles} particle(s); give one per particle, in scene order")]
    ForceCount {
        /// Forces given.
        given: usize,
        /// Particles in the simulation.
        particles: usize,
    },
    /// [`crate::Simulation::set_forces`] was given a force that is not finite.
    #[error("set_forces: the force on particle {index} is not finite: {force:?} N")]
    BadForce {
        /// The particle (scene order).
        index: usize,
        /// The force given (N).
        force: [f64; 3],
    },
    /// `SimConfig::strain_limit` is not > 0.
    #[error("strain limit must be > 0 (infinite: not checked), got {0:?}")]
    BadStrainLimit(f64),
    /// `SimConfig::tolerance` is not finite and > 0.
    #[error("energy tolerance must be finite and > 0 (a share of the energy scale), got {0:?}")]
    BadTolerance(f64),
    /// `SimConfig::step_budget` is not > 0.
    #[error("step budget must be > 0 s (infinite: none), got {0:?}")]
    BadStepBudget(f64),
    /// `SimConfig::energy_limit` is not > 0.
    #[error(
        "energy limit must be > 0 (a share of the energy scale; infinite: not checked), got {0:?}"
    )]
    BadEnergyLimit(f64),
    /// A config asks for 0 substeps per frame.
    #[error("substeps must be ≥ 1")]
    NoSubsteps,
    /// The [`crate::ClothId`] names no cloth of this simulation (removed, or its
    /// [`crate::ClothSprings`] despawned).
    #[error("no such cloth in this simulation (removed already?)")]
    UnknownCloth,
    /// A wind ([`crate::SimConfig::wind`], [`crate::Simulation::set_wind`]) that is not finite,
    /// or gusts without a length or period: the field is named.
    #[error("wind: {0}")]
    BadWind(String),
    /// The [`crate::DriveId`] names no drive of this simulation (removed already).
    #[error("no such drive in this simulation (removed already?)")]
    UnknownDrive,
    /// A drive's particles, targets or maximum distances are wrong ([`crate::Simulation::drive`],
    /// [`crate::Simulation::set_drive_targets`]): the call and the element are named.
    #[error("{call}: {what}")]
    BadDrive {
        /// The call that refused it.
        call: &'static str,
        /// What is wrong, naming the element.
        what: String,
    },
    /// The body is not in this simulation's rigid-body set (or the simulation has none).
    #[error("no such body in this simulation (removed already?)")]
    UnknownBody,
    /// A body given to [`crate::Simulation::add_body`] could not be built; the message says why.
    #[error("body: {0}")]
    BadBody(String),
    /// No particle of this simulation has the scene index given.
    #[error("no particle {index} (scene order) in this simulation")]
    NoParticle {
        /// The scene index asked for.
        index: usize,
    },
    /// [`crate::Simulation::release_quarantine`] was given a particle that is not in quarantine.
    #[error("particle {index} (scene order) is not in quarantine")]
    NotQuarantined {
        /// The particle's scene index.
        index: usize,
    },
    /// A target position given to [`crate::Simulation::grab`] is not finite.
    #[error("position must be finite, got {}", V(*.0))]
    BadPosition(glam::DVec3),
    /// A scene given to [`crate::Simulation::from_scene`] fails validation: every problem.
    #[error("invalid scene: {}", join_issues(.0))]
    InvalidScene(Vec<Issue>),
    /// A [`crate::Particle`] in the World has a non-finite position, or is unpinned with a mass
    /// that is not finite and > 0.
    #[error("particle {particle:?}: {what}")]
    BadParticle {
        /// The particle's entity.
        particle: Entity,
        /// What is wrong with it.
        what: String,
    },
    /// A [`crate::Spring`] in the World joins a particle to itself, or has a rest length that is
    /// not finite and > 0, or a stiffness or damping that is not finite and ≥ 0.
    #[error("spring {spring:?}: {what}")]
    BadSpring {
        /// The spring's entity.
        spring: Entity,
        /// What is wrong with it.
        what: String,
    },
    /// An end of a [`crate::Spring`] in the World is not a particle entity.
    #[error("spring {spring:?} refers to {end:?}, which is not a particle")]
    DanglingSpring {
        /// The spring's entity.
        spring: Entity,
        /// The end that is not a particle.
        end: Entity,
    },
    /// A [`crate::ClothSprings`] in the World is malformed: an empty grid, scene indices past
    /// `u32` or overlapping another cloth's, or a link with a bad offset, rest length, stiffness
    /// or damping.
    #[error("cloth springs {cloth:?}: {what}")]
    BadCloth {
        /// The entity holding the [`crate::ClothSprings`].
        cloth: Entity,
        /// What is wrong with it.
        what: String,
    },
    /// A cloth's grid reaches scene indices that are not held by exactly one particle each.
    #[error(
        "cloth springs {cloth:?} reach scene index {index}, which no particle has (or more than one has)"
    )]
    BrokenCloth {
        /// The entity holding the [`crate::ClothSprings`].
        cloth: Entity,
        /// Where the grid's run of scene indices first breaks (a missing or repeated index).
        index: u32,
    },
    /// The integrator cannot step cloth grids kept whole
    /// ([`crate::Integrator::runs_on_grids`]); the packed buffers must have them expanded.
    #[error("{0} does not step cloth grids kept whole (gather with them expanded)")]
    GridsUnsupported(crate::config::Integrator),
}

/// Why the GPU back end could not run.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum GpuError {
    /// No GPU adapter (Vulkan or GL) was found.
    #[error(
        "no GPU adapter (Vulkan or GL) found; install a driver, or Mesa's lavapipe for a software one (apt-get install mesa-vulkan-drivers libvulkan1)"
    )]
    NoAdapter,
    /// Only software adapters were found where a hardware one is required.
    #[error("only software GPU adapters found ({found}); `--backend auto` does not use them, `--backend gpu` does")]
    OnlySoftware {
        /// The adapters found, each as `name (backend, device type)`, joined by `; `.
        found: String,
    },
    /// The adapter lacks what the engine needs, or a device operation failed (validation, out
    /// of memory, a refused request); also an offscreen render target of an unsupported size.
    #[error("GPU adapter {adapter}: {what}")]
    Device {
        /// The adapter, as `name (backend, device type)` (`offscreen` for the size check).
        adapter: String,
        /// What failed.
        what: String,
    },
    /// Waiting for the device or mapping its results back to the CPU failed; wgpu's message.
    #[error("reading the GPU state back failed: {0}")]
    Readback(String),
    /// The GPU back end was asked for with an integrator that has no GPU kernel.
    #[error("integrator {integrator} has no GPU kernel (GPU kernels: {supported}){extra}")]
    NoKernel {
        /// The integrator asked for.
        integrator: crate::Integrator,
        /// Names of the integrators with a GPU kernel, comma-separated.
        supported: String,
        /// A note appended to the message: for `harmonic`, that it runs on the GPU without exact
        /// displacement; otherwise empty.
        extra: &'static str,
    },
    /// The GPU back end was asked for in a build without the `gpu` feature.
    #[error("this build has no GPU back end (built without the `gpu` feature)")]
    NotBuilt,
}

/// Any error of the crate's API.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A scene could not be loaded.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// A simulation could not be built, edited or stepped.
    #[error(transparent)]
    Sim(#[from] SimError),
}

fn join_issues(issues: &[Issue]) -> String {
    issues
        .iter()
        .map(|i| i.to_string())
        .collect::<Vec<_>>()
        .join("; ")
}

fn known_integrators() -> String {
    crate::Integrator::ALL
        .iter()
        .map(|i| i.name())
        .collect::<Vec<_>>()
        .join(", ")
}

/// A number for a message: fixed with `digits` decimals where that reads well (0, and
/// magnitudes from 10⁻³ to under 10⁶), scientific otherwise, so a blown-up energy prints as
/// `+8.972e302`, not three hundred digits. `signed` writes a `+` on positive values.
#[derive(Clone, Copy, Debug)]
pub struct Readable {
    /// The value.
    pub value: f64,
    /// Decimals (of the mantissa, in scientific form).
    pub digits: usize,
    /// Whether a positive value gets its `+`.
    pub signed: bool,
}

impl Readable {
    /// `value` with `digits` decimals.
    pub fn new(value: f64, digits: usize) -> Self {
        Self {
            value,
            digits,
            signed: false,
        }
    }

    /// `value` with `digits` decimals and its sign always written.
    pub fn signed(value: f64, digits: usize) -> Self {
        Self {
            value,
            digits,
            signed: true,
        }
    }
}

impl fmt::Display for Readable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (v, d) = (self.value, self.digits);
        let fixed = v == 0.0 || !v.is_finite() || (1e-3..1e6).contains(&v.abs());
        match (fixed, self.signed) {
            (true, true) => write!(f, "{v:+.d$}"),
            (true, false) => write!(f, "{v:.d$}"),
            (false, true) => write!(f, "{v:+.d$e}"),
            (false, false) => write!(f, "{v:.d$e}"),
        }
    }
}
