//! What each stage of a frame cost (the order itself is `Simulation::step_coupled`).

use std::time::Duration;

/// Wall time of each stage in the last frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepStats {
    /// Re-gathering the World into packed buffers (about zero when not `gathered`).
    pub gather: Duration,
    /// The substeps' integration, less the contact stage.
    pub integrate: Duration,
    /// The contact stage (zero without props).
    pub contacts: Duration,
    /// The quarantine and writing the state back into the World.
    pub scatter: Duration,
    /// Whether this frame re-gathered the World.
    pub gathered: bool,
    /// Substeps the frame took.
    pub substeps: u32,
    /// Particles this frame found non-finite and quarantined (frozen at their last finite
    /// position; [`crate::Simulation::quarantined`] lists them all).
    pub quarantined: usize,
}

impl StepStats {
    /// Sum of the four stages' times.
    pub fn total(&self) -> Duration {
        self.gather + self.integrate + self.contacts + self.scatter
    }
}
