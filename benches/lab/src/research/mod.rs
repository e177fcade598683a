//! The integrators the lab compares: the engine's, which a game may choose, and the research
//! variants the lab keeps for its figures — the paper's equations as printed
//! (`harmonic-paper`), the closed form forced by the other forces frozen at the step's start
//! (`harmonic-forced`, and in Gauss–Seidel order `harmonic-forced-gs`), symmetric Gauss–Seidel
//! (`harmonic-sgs`) and classical fourth-order Runge–Kutta (`rk4`, the fine-step reference).
//! [`Method`] names either kind; [`Stepper`] steps the packed buffers with it.

pub mod paper;
mod solver;

use std::fmt;
use std::str::FromStr;

use harmonic::glam::DVec3;
use harmonic::internals::audit::DamperLaw;
use harmonic::internals::buffers::Packed;
use harmonic::internals::integrate::Solver;
use harmonic::internals::step_control::{self, Network, StepChoice, SAFETY, ZETAS};
use harmonic::{Integrator, SimError};

/// A research integrator, run by the lab only.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Research {
    /// The paper's equations as printed (`harmonic-paper`).
    Paper,
    /// Each spring's oscillator forced by the other forces, frozen at the start of the step.
    Forced,
    /// Forced, in Gauss–Seidel order.
    ForcedGs,
    /// Symmetric Gauss–Seidel: a forward then a backward colour sweep, each applying half of
    /// the closed-form impulse for the full step.
    Sgs,
    /// Classical fourth-order Runge–Kutta, the fine-step reference.
    Rk4,
}

/// Sweeps of `harmonic-sgs`, alternating direction, each applying 1/SGS_SWEEPS of the impulse.
pub const SGS_SWEEPS: usize = 2;

/// An integrator the lab runs: one of the engine's, or a research variant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Method {
    /// One the engine runs (and a game may choose).
    Engine(Integrator),
    /// One the lab keeps for comparison.
    Research(Research),
}

impl Method {
    /// Every method, in the order the lab lists them: the engine's, then the research ones.
    pub const ALL: [Method; 12] = [
        Method::Engine(Integrator::Harmonic),
        Method::Engine(Integrator::HarmonicGs),
        Method::Research(Research::Sgs),
        Method::Research(Research::Forced),
        Method::Research(Research::ForcedGs),
        Method::Research(Research::Paper),
        Method::Engine(Integrator::SymplecticEuler),
        Method::Engine(Integrator::ExplicitEuler),
        Method::Engine(Integrator::ImplicitEuler),
        Method::Engine(Integrator::Xpbd),
        Method::Engine(Integrator::ThetaMg),
        Method::Research(Research::Rk4),
    ];

    /// The research methods' shorthands.
    pub const HARMONIC_PAPER: Method = Method::Research(Research::Paper);
    /// `harmonic-forced`.
    pub const HARMONIC_FORCED: Method = Method::Research(Research::Forced);
    /// `harmonic-forced-gs`.
    pub const HARMONIC_FORCED_GS: Method = Method::Research(Research::ForcedGs);
    /// `harmonic-sgs`.
    pub const HARMONIC_SGS: Method = Method::Research(Research::Sgs);
    /// `rk4`.
    pub const RK4: Method = Method::Research(Research::Rk4);

    /// Its name on the command line, also its `Display`: the engine's name for the engine's.
    pub fn name(self) -> &'static str {
        match self {
            Method::Engine(i) => i.name(),
            Method::Research(Research::Paper) => "harmonic-paper",
            Method::Research(Research::Forced) => "harmonic-forced",
            Method::Research(Research::ForcedGs) => "harmonic-forced-gs",
            Method::Research(Research::Sgs) => "harmonic-sgs",
            Method::Research(Research::Rk4) => "rk4",
        }
    }

    /// The engine's integrator, if it is one.
    pub fn engine(self) -> Option<Integrator> {
        match self {
            Method::Engine(i) => Some(i),
            Method::Research(_) => None,
        }
    }

    /// Whether it steps cloth grids kept whole (only some of the engine's do).
    pub fn runs_on_grids(self, exact_displacement: bool) -> bool {
        self.engine()
            .is_some_and(|i| i.runs_on_grids(exact_displacement))
    }

    /// The law its dampers' work is booked by: the engine's for its integrators; the research
    /// closed forms' impulse is the whole step's (the mean rate), RK4's force is the start's.
    pub fn damper_law(self) -> DamperLaw {
        match self {
            Method::Engine(i) => DamperLaw::of(i),
            Method::Research(Research::Rk4) => DamperLaw::Start,
            Method::Research(_) => DamperLaw::Mid,
        }
    }

    /// Largest stable `ω_max h` at damping ratio `zeta`, or `None` without a limit: the
    /// engine's table for its integrators, the lab's for the research ones.
    pub fn stable_omega_h(self, zeta: f64) -> Option<f64> {
        match self {
            Method::Engine(i) => step_control::stable_omega_h(i, zeta),
            Method::Research(r) => Some(step_control::on_table(r.table(), zeta)),
        }
    }
}

impl From<Integrator> for Method {
    fn from(i: Integrator) -> Self {
        Method::Engine(i)
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                let known: Vec<_> = Method::ALL.iter().map(|m| m.name()).collect();
                format!("unknown integrator `{s}` (known: {})", known.join(", "))
            })
    }
}

impl Research {
    /// Its measured stable `ω_max h` at each damping ratio of [`ZETAS`] (the least of one
    /// spring, the chain of 20 and the 8×8 cloth; rounded down; `harmonic-lab stability`).
    pub fn table(self) -> &'static [f64; ZETAS.len()] {
        match self {
            Research::Paper => &step_control::TABLE_H,
            Research::Forced => &TABLE_HF,
            Research::ForcedGs => &TABLE_FGS,
            Research::Sgs => &TABLE_SGS,
            Research::Rk4 => &TABLE_RK4,
        }
    }
}

/// `harmonic-forced`'s measured stable `ω_max h` at each of [`ZETAS`].
pub const TABLE_HF: [f64; 11] = [
    1.616, 1.798, 1.616, 1.32, 1.1, 0.939, 0.812, 0.634, 0.516, 0.355, 0.262,
];
/// Symmetric sweeps: the single spring caps it at h = h_c (ω h = π) when lightly damped.
pub const TABLE_SGS: [f64; 11] = [
    std::f64::consts::PI,
    3.157,
    3.208,
    3.294,
    3.428,
    3.632,
    3.934,
    5.27,
    8.884,
    20.0,
    20.0,
];
/// `harmonic-forced-gs`'s measured stable `ω_max h` at each of [`ZETAS`].
pub const TABLE_FGS: [f64; 11] = [
    1.72, 1.798, 1.616, 1.32, 1.1, 0.939, 0.812, 0.634, 0.516, 0.355, 0.262,
];
/// RK4's measured stable `ω_max h` at each of [`ZETAS`].
pub const TABLE_RK4: [f64; 11] = [
    2.826, 2.927, 2.665, 2.648, 2.618, 1.878, 1.311, 0.888, 0.685, 0.44, 0.321,
];

/// Substeps for a frame of `dt` with `method` on `packed`, as the engine's step control
/// chooses them (the research methods by their tables, with the engine's safety factor).
pub fn choose(packed: &Packed, method: Method, dt: f64) -> StepChoice {
    match method {
        Method::Engine(i) => step_control::choose(packed, i, dt),
        Method::Research(r) => {
            let network = Network::of(packed);
            let (lo, hi) = network.zeta_range;
            let limit =
                step_control::on_table(r.table(), lo).min(step_control::on_table(r.table(), hi));
            network.choose_within(Some(SAFETY * limit), dt)
        }
    }
}

/// Why a step could not be taken.
#[derive(Debug)]
pub enum StepError {
    /// The engine's solver refused.
    Engine(SimError),
    /// The research steps take springs one by one: the packed buffers need grids expanded.
    Grids(Research),
    /// `harmonic-paper` has no value for a spring with ζ > 1/√2 (eq. 27 as printed).
    PaperUndefined {
        /// The spring's index among the packed springs.
        spring: usize,
        /// The spring's true damping ratio ζ.
        zeta: f64,
    },
}

impl fmt::Display for StepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StepError::Engine(e) => e.fmt(f),
            StepError::Grids(r) => write!(
                f,
                "{} does not step cloth grids kept whole (gather with them expanded)",
                Method::Research(*r)
            ),
            StepError::PaperUndefined { spring, zeta } => write!(
                f,
                "harmonic-paper is undefined for spring {spring}: eq. 27 as printed takes \
                 √(1 − 2ζ²) with ζ = {zeta:.3} > 0.707"
            ),
        }
    }
}

impl std::error::Error for StepError {}

impl From<SimError> for StepError {
    fn from(e: SimError) -> Self {
        StepError::Engine(e)
    }
}

/// Steps packed buffers with a [`Method`]: the engine's [`Solver`] or the lab's own.
#[derive(Clone, Debug)]
// One per run, made once: the two solvers' sizes do not matter.
#[allow(clippy::large_enum_variant)]
pub enum Stepper {
    /// An engine integrator.
    Engine(Solver),
    /// A research integrator.
    Research(solver::Solver),
}

impl Stepper {
    /// A stepper for `method` under `gravity` (`exact_displacement`: the engine's closed form
    /// only).
    pub fn new(method: Method, exact_displacement: bool, gravity: DVec3) -> Self {
        match method {
            Method::Engine(i) => Stepper::Engine(Solver::new(i, exact_displacement, gravity)),
            Method::Research(r) => Stepper::Research(solver::Solver::new(r, gravity)),
        }
    }

    /// Sizes scratch and computes step coefficients for `h`.
    pub fn prepare(&mut self, packed: &Packed, h: f64) -> Result<(), StepError> {
        match self {
            Stepper::Engine(s) => Ok(s.prepare(packed, h)?),
            Stepper::Research(s) => s.prepare(packed, h),
        }
    }

    /// Whether the engine's grid pass books its dampers' loss itself.
    pub fn grid_audits(&self) -> bool {
        matches!(self, Stepper::Engine(s) if s.grid_audits())
    }

    /// What the cloth grids' dampers dissipated in the last substep, when the grid pass books it.
    pub fn grid_damper_loss(&self) -> f64 {
        match self {
            Stepper::Engine(s) => s.grid_damper_loss(),
            Stepper::Research(_) => 0.0,
        }
    }

    /// Advances the packed state by one substep `h`.
    pub fn substep(&mut self, packed: &mut Packed, h: f64) -> Result<(), StepError> {
        match self {
            Stepper::Engine(s) => Ok(s.substep(packed, h)?),
            Stepper::Research(s) => s.substep(packed, h),
        }
    }
}
