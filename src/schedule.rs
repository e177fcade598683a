//! The stages of a step, in their fixed order, and what each cost.

use std::time::Duration;

/// The stages a frame runs, in this order. A stage a scene does not need is not in its
/// schedule: without bodies there is no contact stage and no rapier world.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// World → packed buffers; runs only when the World changed since the last gather.
    Gather,
    /// `substeps` steps of the integrator on the packed buffers; with props, each substep is
    /// followed by the contact stage.
    Integrate,
    /// Per substep: rapier steps the bodies, attachments follow them, particles are pushed out
    /// of colliders with friction, and dynamic bodies get the opposite impulses.
    Contacts,
    /// Packed buffers → World (positions and velocities), once per frame.
    Scatter,
}

impl Stage {
    pub const ORDER: [Stage; 4] = [
        Stage::Gather,
        Stage::Integrate,
        Stage::Contacts,
        Stage::Scatter,
    ];
}

/// Wall time of each stage in the last frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepStats {
    pub gather: Duration,
    pub integrate: Duration,
    /// The contact stage (zero without props).
    pub contacts: Duration,
    pub scatter: Duration,
    /// Whether this frame re-gathered the World.
    pub gathered: bool,
    pub substeps: u32,
    /// Particles this frame found non-finite and quarantined (frozen at their last finite
    /// position; [`crate::Simulation::quarantined`] lists them all).
    pub quarantined: usize,
}

impl StepStats {
    pub fn total(&self) -> Duration {
        self.gather + self.integrate + self.contacts + self.scatter
    }
}
