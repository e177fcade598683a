//! The stages of a step, in their fixed order, and what each cost.

use std::time::Duration;

/// The stages a frame runs, in this order. A stage a scene does not need is not in its
/// schedule: without colliders there is no contact stage (there are no colliders yet).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// World → packed buffers; runs only when the World changed since the last gather.
    Gather,
    /// `substeps` steps of the integrator on the packed buffers.
    Integrate,
    /// Packed buffers → World (positions and velocities), once per frame.
    Scatter,
}

impl Stage {
    pub const ORDER: [Stage; 3] = [Stage::Gather, Stage::Integrate, Stage::Scatter];
}

/// Wall time of each stage in the last frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepStats {
    pub gather: Duration,
    pub integrate: Duration,
    pub scatter: Duration,
    /// Whether this frame re-gathered the World.
    pub gathered: bool,
    pub substeps: u32,
}

impl StepStats {
    pub fn total(&self) -> Duration {
        self.gather + self.integrate + self.scatter
    }
}
