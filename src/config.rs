//! What a simulation is configured with: the integrator, the back end and the step. The bottom
//! layer: every other module may import it, it imports only the errors.

use std::fmt;
use std::str::FromStr;

use glam::DVec3;

use crate::error::SimError;

/// The integrators a game may choose, all over the same packed buffers. The research variants
/// (the paper's printed step, the forced and symmetric closed forms, the RK4 reference) live in
/// the lab crate (`benches/lab`, [`RESEARCH_INTEGRATORS`]), which runs them for its figures.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Integrator {
    /// The corrected closed-form spring step, summed per particle (Jacobi).
    Harmonic,
    /// `v += a h; x += v h`. The default: fastest at ≤ 1 cm error on the 128×128 cloth
    /// (`harmonic-lab bench`, benches/lab/BENCHMARKS.md).
    #[default]
    SymplecticEuler,
    /// `x += v h; v += a h`.
    ExplicitEuler,
    /// The closed form applied spring by spring in Gauss–Seidel order over a colouring.
    HarmonicGs,
    /// Baraff–Witkin implicit Euler: one Newton step, conjugate gradients.
    ImplicitEuler,
    /// Small-step XPBD, one iteration per substep.
    Xpbd,
    /// A θ-step (θ = 0.6) solved by one multigrid V-cycle: stable at any step, for steps far
    /// past the explicit integrators' limits.
    ThetaMg,
}

/// The research integrators' names, which the lab runs and the engine refuses with
/// [`SimError::ResearchIntegrator`].
pub const RESEARCH_INTEGRATORS: [&str; 5] = [
    "harmonic-sgs",
    "harmonic-forced",
    "harmonic-forced-gs",
    "harmonic-paper",
    "rk4",
];

impl Integrator {
    /// Every integrator, in the order messages list their names.
    pub const ALL: [Integrator; 7] = [
        Integrator::Harmonic,
        Integrator::HarmonicGs,
        Integrator::SymplecticEuler,
        Integrator::ExplicitEuler,
        Integrator::ImplicitEuler,
        Integrator::Xpbd,
        Integrator::ThetaMg,
    ];

    /// Whether it steps cloth grids ([`crate::buffers::PackedGrid`]) as they are on the CPU,
    /// with no memory per spring (`harmonic` only without exact displacement); the others get
    /// the cloths' springs expanded one by one.
    pub fn runs_on_grids(self, exact_displacement: bool) -> bool {
        match self {
            Integrator::SymplecticEuler | Integrator::ExplicitEuler => true,
            Integrator::Harmonic => !exact_displacement,
            _ => false,
        }
    }

    /// Whether the GPU's `grid_pass` steps its cloth grids whole: the Euler integrators, and
    /// the closed form (its device kernel has no exact displacement).
    pub fn runs_on_gpu_grids(self) -> bool {
        matches!(
            self,
            Integrator::SymplecticEuler | Integrator::ExplicitEuler | Integrator::Harmonic
        )
    }

    /// Whether its spring step is the closed-form oscillator (the harmonic family), whose
    /// impulse vanishes or reverses at whole multiples of a spring's `h_c`.
    pub fn uses_closed_form(self) -> bool {
        matches!(self, Integrator::Harmonic | Integrator::HarmonicGs)
    }

    /// Whether it applies the closed form spring by spring in colour order (Gauss–Seidel).
    pub(crate) fn sweeps(self) -> bool {
        self == Integrator::HarmonicGs
    }

    /// Whether it needs the springs' colouring (the Gauss–Seidel sweeps and XPBD).
    pub fn needs_colouring(self) -> bool {
        self.sweeps() || self == Integrator::Xpbd
    }

    /// Its name in scene files and on the command line (`symplectic-euler`), also its `Display`.
    pub fn name(self) -> &'static str {
        match self {
            Integrator::Harmonic => "harmonic",
            Integrator::SymplecticEuler => "symplectic-euler",
            Integrator::ExplicitEuler => "explicit-euler",
            Integrator::HarmonicGs => "harmonic-gs",
            Integrator::ImplicitEuler => "implicit-euler",
            Integrator::Xpbd => "xpbd",
            Integrator::ThetaMg => "theta-mg",
        }
    }
}

impl fmt::Display for Integrator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Integrator {
    type Err = SimError;
    fn from_str(s: &str) -> Result<Self, SimError> {
        Integrator::ALL
            .into_iter()
            .find(|i| i.name() == s)
            .ok_or_else(|| {
                if RESEARCH_INTEGRATORS.contains(&s) {
                    SimError::ResearchIntegrator(s.to_string())
                } else {
                    SimError::UnknownIntegrator(s.to_string())
                }
            })
    }
}

/// Where the step runs. The default is the CPU: it is what every machine has, and a software
/// GPU adapter (lavapipe, llvmpipe) is slower than the CPU kernel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Backend {
    /// The rayon kernel on f64 state.
    #[default]
    Cpu,
    /// The WGSL kernel through wgpu on f32 state; an error when no adapter exists (a software
    /// adapter is accepted) or the integrator has no GPU kernel.
    Gpu,
    /// A hardware GPU when one is present and the integrator has a GPU kernel, else the CPU.
    /// Never picks a software adapter.
    Auto,
}

impl Backend {
    /// Every back end.
    pub const ALL: [Backend; 3] = [Backend::Cpu, Backend::Gpu, Backend::Auto];

    /// Its name in scene files and on the command line (`cpu`, `gpu`, `auto`), also its `Display`.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Cpu => "cpu",
            Backend::Gpu => "gpu",
            Backend::Auto => "auto",
        }
    }
}

impl fmt::Display for Backend {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Backend {
    type Err = SimError;
    fn from_str(s: &str) -> Result<Self, SimError> {
        Backend::ALL
            .into_iter()
            .find(|b| b.name() == s)
            .ok_or_else(|| SimError::UnknownBackend(s.to_string()))
    }
}

/// How a simulation steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimConfig {
    /// Frame step (s).
    pub dt: f64,
    /// Substeps per frame; the integrator's step is `h = dt / substeps`. With
    /// `auto_substeps` this is chosen at every gather, pin refresh and
    /// [`crate::Simulation::set_config`].
    pub substeps: u32,
    /// Choose `substeps` from the network's highest frequency and the integrator's measured
    /// stability region (the engine's step control; `step_control.rs`).
    pub auto_substeps: bool,
    /// Gravitational acceleration (m/s²).
    pub gravity: DVec3,
    /// The wind the cloths with air feel ([`crate::Aero`]); still by default.
    pub wind: crate::Wind,
    /// The integrator every substep uses.
    pub integrator: Integrator,
    /// Choose `integrator` from the springs at load (a scene that names none): the cheaper
    /// within the tolerance of symplectic Euler and the closed form by their stability floors
    /// at the scene's damping (`step_control::choose_integrator`);
    /// [`crate::Simulation::integrator_choice`] says why.
    pub auto_integrator: bool,
    /// Harmonic only: move positions by each spring's closed-form displacement too.
    pub exact_displacement: bool,
    /// Where the integrate stage runs.
    pub backend: Backend,
    /// The largest extension `δ/l0` any spring may reach before a frame is reported as a
    /// [`crate::Failure`] (10: a spring eleven times its rest length); infinite to not check.
    /// Checked once per frame, one read of the springs.
    pub strain_limit: f64,
    /// The energy the steps may make, as a share of the energy scale: the automatic substeps
    /// keep the run's peak residual ([`crate::EnergyAudit::peak_residual`]) within it (1 %).
    pub tolerance: f64,
    /// Wall time one step may take (s; infinite: no budget). With automatic substeps the
    /// controller then halves the substeps of a step over it (never under the stability floor)
    /// and raises them for accuracy only while twice the step fits; a step the budget kept
    /// under what the tolerance asked says so ([`crate::StepStats::budget_limited`]), and the
    /// audit's peak residual how far it went. It reads the wall clock, so a budgeted run is
    /// not deterministic.
    pub step_budget: f64,
    /// The peak residual, as a share of the energy scale, past which a frame is reported as a
    /// [`crate::Failure::Energy`] (10 × the default tolerance); infinite to not check.
    pub energy_limit: f64,
    /// With the springs on the GPU, self-collision's pass over its candidates runs there too,
    /// where every candidate is a particle against a triangle and the contacts do not run on
    /// the host (taken at each gather and [`crate::Simulation::set_config`]). Deterministic and
    /// held to the CPU's pass over the same colours, but off by default: on the adapters
    /// measured it is slower than the host's pass (`benches/lab/NOTES.md`, "Self-collision").
    pub device_collide_pass: bool,
}

/// [`SimConfig::tolerance`]'s default: 1 % of the energy scale.
pub const DEFAULT_TOLERANCE: f64 = 0.01;
/// [`SimConfig::energy_limit`]'s default: ten times the default tolerance.
pub const DEFAULT_ENERGY_LIMIT: f64 = 0.1;

/// [`SimConfig::strain_limit`]'s default: far past any cloth that is only stretching (the
/// 128×128 cloth on 200 Hz springs pinned at two corners reaches 8.6), caught within frames
/// when a step blows up.
pub const DEFAULT_STRAIN_LIMIT: f64 = 10.0;

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            dt: 1.0 / 60.0,
            substeps: 1,
            auto_substeps: true,
            gravity: DVec3::new(0.0, -9.81, 0.0),
            wind: crate::Wind::default(),
            integrator: Integrator::default(),
            auto_integrator: false,
            exact_displacement: false,
            backend: Backend::Cpu,
            strain_limit: DEFAULT_STRAIN_LIMIT,
            tolerance: DEFAULT_TOLERANCE,
            step_budget: f64::INFINITY,
            energy_limit: DEFAULT_ENERGY_LIMIT,
            device_collide_pass: false,
        }
    }
}

impl SimConfig {
    /// The integrator's step `h = dt / substeps` (s).
    pub fn h(&self) -> f64 {
        self.dt / self.substeps as f64
    }
    pub(crate) fn check(&self) -> Result<(), SimError> {
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(SimError::BadStep(self.dt));
        }
        if self.substeps == 0 {
            return Err(SimError::NoSubsteps);
        }
        self.wind.check().map_err(SimError::BadWind)?;
        if self.strain_limit.is_nan() || self.strain_limit <= 0.0 {
            return Err(SimError::BadStrainLimit(self.strain_limit));
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(SimError::BadTolerance(self.tolerance));
        }
        if self.step_budget.is_nan() || self.step_budget <= 0.0 {
            return Err(SimError::BadStepBudget(self.step_budget));
        }
        if self.energy_limit.is_nan() || self.energy_limit <= 0.0 {
            return Err(SimError::BadEnergyLimit(self.energy_limit));
        }
        Ok(())
    }
}
