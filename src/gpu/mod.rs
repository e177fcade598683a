//! The GPU back end: `shaders/integrate.wgsl` through wgpu, state resident on the device.
//!
//! - [`GpuContext`]: adapter (Vulkan or GL), device and queue.
//! - [`GpuSolver`]: pipelines (one per entry point, specialised to the scene), buffers uploaded
//!   at gather, substeps encoded into one submit, and a staging buffer read only on request.
//!
//! The springs go to the device in colour order, so a Gauss–Seidel colour is a contiguous range
//! and the Jacobi passes index the same array. Cloth grids kept whole (symplectic and explicit
//! Euler, `harmonic`) go as their links only: `grid_pass` finds each particle's neighbours from
//! its grid position, as the CPU grid pass does, with no memory per spring. Under `harmonic`
//! the links hold the closed form for one mass, and each spring the CPU pass corrects
//! (`grid::Fix`) goes as two extra device springs, its own closed form and the nominal force
//! taken back. Coefficients (`p`, `q`) come
//! from the CPU ([`crate::integrate::harmonic`]), once per `h`: one definition of the spring
//! math.

// Not API: reachable from outside only through the hidden `internals` module.
#![allow(missing_docs)]

use std::sync::{Arc, Mutex, OnceLock};

use bytemuck::{Pod, Zeroable};
use glam::DVec3;
use wgpu::util::DeviceExt;

use crate::buffers::Packed;
use crate::error::GpuError;
use crate::integrate::harmonic::Linear;
use crate::integrate::{grid, Integrator};

pub mod clock;
mod context;
mod layout;
mod pipelines;
mod solver;
mod upload;

pub use context::*;
pub use layout::*;
pub use pipelines::*;
pub use solver::*;
use upload::*;

pub mod contacts;
pub mod tethers;

/// What the step's shaders share (`WORKGROUP`, `Position`, `linear`), joined before each.
pub const PRELUDE: &str = include_str!("../../shaders/prelude.wgsl");
/// The WGSL source of the integrate kernels: the prelude, then `shaders/integrate.wgsl`.
pub const SHADER: &str = concat!(
    include_str!("../../shaders/prelude.wgsl"),
    include_str!("../../shaders/integrate.wgsl")
);
/// Invocations per workgroup (the shader's `WORKGROUP` override).
pub const WORKGROUP: u32 = 256;
/// Workgroups per dispatch dimension (WebGPU's minimum limit).
const MAX_GROUPS: u32 = 65_535;
