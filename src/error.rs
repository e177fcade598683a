//! Errors at each boundary: scene files, the simulation step.

use std::fmt;
use std::path::PathBuf;

use hecs::Entity;

/// One semantic problem in a scene, named by its entry (`springs[3].b`).
#[derive(Clone, Debug, PartialEq)]
pub struct Issue {
    pub location: String,
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
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Syntax, unknown fields and wrong types, at ron's line and column (1-based).
    #[error("{path}:{line}:{column}: {message}")]
    Parse {
        path: PathBuf,
        line: usize,
        column: usize,
        message: String,
    },
    /// Every semantic problem found, one per line.
    #[error("{}", format_issues(path, issues))]
    Invalid { path: PathBuf, issues: Vec<Issue> },
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
    #[error("unknown integrator `{0}` (known: {known})", known = known_integrators())]
    UnknownIntegrator(String),
    #[error("unknown backend `{0}` (known: cpu, gpu, auto)")]
    UnknownBackend(String),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("this simulation's scene has bodies of its own; step it with `step`, not `step_with`")]
    OwnBodies,
    #[error("particle {particle:?} is attached to a body that no longer exists")]
    DanglingAttachment { particle: Entity },
    #[error("time step must be finite and > 0, got {0}")]
    BadStep(f64),
    #[error("frame time must be finite and ≥ 0, got {0}")]
    BadFrameTime(f64),
    #[error("substeps must be ≥ 1")]
    NoSubsteps,
    #[error("no such cloth in this simulation (removed already?)")]
    UnknownCloth,
    #[error("no such body in this simulation (removed already?)")]
    UnknownBody,
    #[error("body: {0}")]
    BadBody(String),
    #[error("no particle {index} (scene order) in this simulation")]
    NoParticle { index: usize },
    #[error("particle {index} (scene order) is not in quarantine")]
    NotQuarantined { index: usize },
    #[error("position must be finite, got {0}")]
    BadPosition(glam::DVec3),
    #[error("invalid scene: {}", join_issues(.0))]
    InvalidScene(Vec<Issue>),
    #[error("particle {particle:?}: {what}")]
    BadParticle { particle: Entity, what: String },
    #[error("spring {spring:?}: {what}")]
    BadSpring { spring: Entity, what: String },
    #[error("spring {spring:?} refers to {end:?}, which is not a particle")]
    DanglingSpring { spring: Entity, end: Entity },
    #[error("cloth springs {cloth:?}: {what}")]
    BadCloth { cloth: Entity, what: String },
    #[error(
        "cloth springs {cloth:?} reach scene index {index}, which no particle has (or more than one has)"
    )]
    BrokenCloth { cloth: Entity, index: u32 },
    #[error("{0} does not step cloth grids kept whole (gather with them expanded)")]
    GridsUnsupported(crate::integrate::Integrator),
    #[error(
        "harmonic-paper is undefined for spring {spring}: eq. 27 as printed takes √(1 − 2ζ²) with ζ = {zeta:.3} > 0.707"
    )]
    PaperUndefined { spring: usize, zeta: f64 },
}

/// Why the GPU back end could not run.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum GpuError {
    #[error(
        "no GPU adapter (Vulkan or GL) found; install a driver, or Mesa's lavapipe for a software one (apt-get install mesa-vulkan-drivers libvulkan1)"
    )]
    NoAdapter,
    #[error("only software GPU adapters found ({found}); `--backend auto` does not use them, `--backend gpu` does")]
    OnlySoftware { found: String },
    #[error("GPU adapter {adapter}: {what}")]
    Device { adapter: String, what: String },
    #[error("reading the GPU state back failed: {0}")]
    Readback(String),
    #[error("integrator {integrator} has no GPU kernel (GPU kernels: {supported}){extra}")]
    NoKernel {
        integrator: crate::Integrator,
        supported: String,
        extra: &'static str,
    },
    #[error("this build has no GPU back end (built without the `gpu` feature)")]
    NotBuilt,
}

/// Any error of the crate's API.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Scene(#[from] SceneError),
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
