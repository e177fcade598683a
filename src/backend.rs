//! Which machine runs the integrate stage.

use std::fmt;
use std::str::FromStr;

use crate::error::SimError;

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
    pub const ALL: [Backend; 3] = [Backend::Cpu, Backend::Gpu, Backend::Auto];

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
