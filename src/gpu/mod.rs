//! The GPU back end: `shaders/integrate.wgsl` through wgpu, state resident on the device.
//!
//! - [`GpuContext`]: adapter (Vulkan or GL), device and queue.
//! - [`GpuSolver`]: pipelines (one per entry point, specialised to the scene), buffers uploaded
//!   at gather, substeps encoded into one submit, and a staging buffer read only on request.
//! - The device stages beside the springs ([`contacts`], [`tethers`], [`air`]), each the twin
//!   of its CPU module; what they share (a stage's pipelines, a dispatch over a 2-D grid of
//!   workgroups, every read-back through a staging buffer) is defined once here.
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

pub mod air;
pub mod collide;
pub mod collide_pass;
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

/// A binding of a stage's layout: a uniform (`dynamic`: at a dynamic offset) or a storage
/// buffer (`read_only`).
#[derive(Clone, Copy)]
pub(crate) enum Slot {
    Uniform { dynamic: bool },
    Storage { read_only: bool },
}

/// A device stage's shader module, bind group layout (bindings 0, 1, … as `slots` list them)
/// and its one compute pipeline, at `entry` with the `WORKGROUP` override: what the contact,
/// tether and air stages share.
pub(crate) fn stage_pipeline(
    device: &wgpu::Device,
    name: &str,
    shader: &str,
    entry: &str,
    slots: &[Slot],
) -> (wgpu::BindGroupLayout, wgpu::ComputePipeline) {
    let (layout, [pipeline]) = stage_pipelines(device, name, shader, [entry], slots);
    (layout, pipeline)
}

/// As [`stage_pipeline`], one pipeline per entry point over the one layout.
pub(crate) fn stage_pipelines<const N: usize>(
    device: &wgpu::Device,
    name: &str,
    shader: &str,
    entries: [&str; N],
    slots: &[Slot],
) -> (wgpu::BindGroupLayout, [wgpu::ComputePipeline; N]) {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(name),
        source: wgpu::ShaderSource::Wgsl(shader.into()),
    });
    let bindings: Vec<_> = (slots.iter().enumerate())
        .map(|(binding, slot)| {
            let (ty, has_dynamic_offset) = match *slot {
                Slot::Uniform { dynamic } => (wgpu::BufferBindingType::Uniform, dynamic),
                Slot::Storage { read_only } => {
                    (wgpu::BufferBindingType::Storage { read_only }, false)
                }
            };
            wgpu::BindGroupLayoutEntry {
                binding: binding as u32,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty,
                    has_dynamic_offset,
                    min_binding_size: None,
                },
                count: None,
            }
        })
        .collect();
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(name),
        entries: &bindings,
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(name),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipelines = entries.map(|entry| {
        device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: &[("WORKGROUP", WORKGROUP as f64)],
                zero_initialize_workgroup_memory: false,
            },
            cache: None,
        })
    });
    (layout, pipelines)
}

/// A buffer created holding `bytes`.
pub(crate) fn init_buffer(
    device: &wgpu::Device,
    label: &str,
    bytes: &[u8],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: bytes,
        usage,
    })
}

/// Encodes `copy` into `staging`, submits it, waits, and hands the first `bytes` of `staging`
/// to `read`: every read-back from the device goes through here.
pub(crate) fn read_staging(
    ctx: &GpuContext,
    what: &str,
    staging: &wgpu::Buffer,
    bytes: u64,
    copy: impl FnOnce(&mut wgpu::CommandEncoder),
    read: impl FnOnce(&[u8]),
) -> Result<(), GpuError> {
    ctx.scoped(what, || {
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(what) });
        copy(&mut encoder);
        ctx.queue.submit([encoder.finish()]);
    })?;
    map_read(ctx, staging, bytes, read)
}

/// Waits for the queued work and reads the first `bytes` of a mappable `staging` buffer.
pub(crate) fn map_read(
    ctx: &GpuContext,
    staging: &wgpu::Buffer,
    bytes: u64,
    read: impl FnOnce(&[u8]),
) -> Result<(), GpuError> {
    let failed = |e: &dyn std::fmt::Display| GpuError::Readback(e.to_string());
    let (tx, rx) = std::sync::mpsc::channel();
    staging
        .slice(..bytes)
        .map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
    ctx.device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| failed(&e))?;
    match rx.recv() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => return Err(failed(&e)),
        Err(e) => return Err(failed(&e)),
    }
    {
        let view = staging.get_mapped_range(..bytes).map_err(|e| failed(&e))?;
        read(&view);
    }
    staging.unmap();
    Ok(())
}

/// One invocation per element, over a 2-D grid of workgroups when one dimension is not enough.
pub(crate) fn dispatch(pass: &mut wgpu::ComputePass<'_>, count: u32) {
    if count == 0 {
        return;
    }
    let groups = count.div_ceil(WORKGROUP);
    let x = groups.min(MAX_GROUPS);
    pass.dispatch_workgroups(x, groups.div_ceil(x), 1);
}
