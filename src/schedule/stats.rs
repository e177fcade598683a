//! What a frame did and cost, and why a finite frame may still be wrong.

use super::StageTimes;
use crate::error::Readable;
use std::time::Duration;

/// What the last frame did, and the wall time of each stage of its schedule and of the work
/// around them (gather, audit, scatter).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepStats {
    /// Re-gathering the World into packed buffers (about zero when not `gathered`).
    pub gather: Duration,
    /// Each stage kind's time on the host (zero for a kind not in the schedule). On the GPU a
    /// stage's time is its encoding and its host side; the device's kernels are in
    /// [`Self::device`].
    pub stages: StageTimes,
    /// On the GPU, the host's waits for the device: the kernels of every stage on the device,
    /// which run while the host waits for the state (or the contacts' impulses) to come back.
    /// Zero on the CPU.
    pub device: Duration,
    /// On the GPU, each stage's kernel time on the device, from timestamps written between
    /// the stages' kernels. `None` where not measured: on the CPU, with the timers off, on an
    /// adapter without timestamps inside compute passes, or in a frame with more than
    /// `gpu::clock::CAPACITY` of them.
    pub device_stages: Option<StageTimes>,
    /// The energy audit: the dampers' pass after each substep (damped scenes only) and the
    /// energy at the frame's ends.
    pub audit_time: Duration,
    /// The quarantine and writing the state back into the World.
    pub scatter: Duration,
    /// Whether this frame re-gathered the World.
    pub gathered: bool,
    /// Substeps the frame took.
    pub substeps: u32,
    /// Particles this frame found non-finite and quarantined (frozen at their last finite
    /// position; [`crate::Simulation::quarantined`] lists them all).
    pub quarantined: usize,
    /// Why this frame's state, though finite, is not to be trusted (None: nothing found).
    pub failure: Option<Failure>,
    /// The frame's energy books ([`crate::EnergyAudit`]).
    pub audit: crate::EnergyAudit,
    /// [`crate::SimConfig::step_budget`] kept the next step's substeps under what the
    /// tolerance asked (or this step was over the budget at the stability floor).
    pub budget_limited: bool,
}

/// A frame whose state is finite but wrong: the engine reports it, never as success.
/// [`crate::Diagnostics::failure`] keeps the first one of a run.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum Failure {
    /// A spring stretched past [`crate::SimConfig::strain_limit`]: the step is too large for
    /// the springs (the state is blowing up), or the scene (or a particle grabbed and dragged
    /// away) stretches it further than the limit.
    Strain {
        /// The frame (1 for the first step).
        frame: u64,
        /// The ends of the spring stretched most (particles in scene order).
        particles: (usize, usize),
        /// Its extension `δ/l0`.
        strain: f64,
        /// The limit it passed.
        limit: f64,
        /// The integrator that stepped it.
        integrator: crate::Integrator,
        /// That spring's `h/h_c` (`h_c = π/ω0`).
        step_ratio: f64,
        /// Substeps of the frame.
        substeps: u32,
    },
    /// The steps made energy: the run's peak residual ([`crate::EnergyAudit::peak_residual`])
    /// passed [`crate::SimConfig::energy_limit`] of the energy scale. Energy created beyond
    /// what went in, though every spring is within the strain limit.
    Energy {
        /// The frame (1 for the first step).
        frame: u64,
        /// The peak residual (J).
        created: f64,
        /// The energy scale (J).
        scale: f64,
        /// The limit it passed, a share of the scale.
        limit: f64,
        /// The integrator that stepped it.
        integrator: crate::Integrator,
        /// The stiffest spring's `h/h_c` (`h_c = π/ω0`).
        step_ratio: f64,
        /// The ends of the spring stretched most (particles in scene order).
        particles: (usize, usize),
        /// That spring's extension `δ/l0`.
        strain: f64,
        /// Substeps of the frame.
        substeps: u32,
    },
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Failure::Strain {
                frame,
                particles: (a, b),
                strain,
                limit,
                integrator,
                step_ratio,
                substeps,
            } => write!(
                f,
                "frame {frame}: the spring from particle {a} to {b} is stretched {:.4e} % past its rest length, beyond \
                 the strain limit of {:.4e} % ({integrator}, {substeps} substep(s), h/h_c = {} \
                 for that spring). A blow-up: lower dt, raise the substeps or leave them automatic, \
                 or choose a more stable integrator; if the scene (or a drag) means to stretch this \
                 far, raise `strain_limit`",
                100.0 * strain,
                100.0 * limit,
                Readable::new(step_ratio, 4)
            ),
            Failure::Energy {
                frame,
                created,
                scale,
                limit,
                integrator,
                step_ratio,
                particles: (a, b),
                strain,
                substeps,
            } => write!(
                f,
                "frame {frame}: the steps made {created:.4e} J of energy beyond what went in, \
                 {} % of the energy scale ({scale:.4e} J), past the energy limit of {} % \
                 ({integrator}, {substeps} substep(s), h/h_c = {} for the stiffest \
                 spring; the spring stretched most joins particles {a} and {b}, at {} %). The \
                 step is too large for the accuracy asked: lower dt, raise the substeps or leave \
                 them automatic, or choose another integrator; raise `energy_limit` to accept it",
                Readable::new(100.0 * created / scale, 4),
                Readable::new(100.0 * limit, 4),
                Readable::new(step_ratio, 4),
                Readable::new(100.0 * strain, 4)
            ),
        }
    }
}

impl StepStats {
    /// The frame's wall time: the stages, the device, the gather, the audit and the scatter.
    pub fn total(&self) -> Duration {
        self.gather + self.stages.total() + self.device + self.audit_time + self.scatter
    }
}
