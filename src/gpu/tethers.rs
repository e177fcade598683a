//! The tethers' velocity clamp on the device (`shaders/tethers.wgsl`), the twin of the CPU's
//! clamp of one link (`tether/lanes.rs`, `clamp_one`): run after each substep's integrate
//! passes over the particles' resident state, so a tethered cloth's frame is one submit. Each tethered particle
//! keeps the kinetic energy its clamps changed in its own element; the host reads them back
//! once a frame and sums them in order. The frame's last placing stays on the host, where the
//! state comes back at a frame's end.

use bytemuck::{Pod, Zeroable};
use glam::DVec3;

use super::GpuContext;
use crate::error::GpuError;

/// The WGSL source of the tethers' pass: the prelude ([`super::PRELUDE`]), then
/// `shaders/tethers.wgsl`.
pub const SHADER: &str = concat!(
    include_str!("../../shaders/prelude.wgsl"),
    include_str!("../../shaders/tethers.wgsl")
);

/// `TetherStep` in shaders/tethers.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TetherStep {
    pub gravity: [f32; 3],
    pub h: f32,
    pub parts: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

/// `Part` in shaders/tethers.wgsl: a tethered particle, its links `first..first + count`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Part {
    pub particle: u32,
    pub first: u32,
    pub count: u32,
    pub _pad: u32,
}

/// `Link` in shaders/tethers.wgsl: the anchor's particle and the limit (m).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Link {
    pub anchor: u32,
    pub limit: f32,
}

/// What the tethers' pass needs of a gather (particles in packed order).
pub struct TetherSetup<'a> {
    pub parts: &'a [Part],
    pub links: &'a [Link],
    pub gravity: DVec3,
    pub h: f64,
}

/// The device tethers of one gather: pipeline, buffers.
pub struct DeviceTethers {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    step: wgpu::Buffer,
    change: wgpu::Buffer,
    staging: wgpu::Buffer,
    params: TetherStep,
    /// The pass follows the springs of slots `0..slots` (the host clamps after the frame's
    /// last placing, as the CPU does).
    pub(super) slots: u32,
}

impl DeviceTethers {
    pub(super) fn new(
        ctx: &GpuContext,
        pos: &wgpu::Buffer,
        vel: &wgpu::Buffer,
        setup: &TetherSetup<'_>,
    ) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let params = TetherStep {
            gravity: setup.gravity.as_vec3().to_array(),
            h: setup.h as f32,
            parts: setup.parts.len() as u32,
            ..Default::default()
        };
        // No binding may be empty: one unread element where there is nothing.
        let (no_part, no_link) = ([Part::default()], [Link::default()]);
        let parts: &[u8] = bytemuck::cast_slice(match setup.parts {
            [] => &no_part,
            p => p,
        });
        let links: &[u8] = bytemuck::cast_slice(match setup.links {
            [] => &no_link,
            l => l,
        });
        let change_bytes = (setup.parts.len().max(1) * 4) as u64;
        ctx.scoped("tether stage", || {
            use super::Slot::{Storage, Uniform};
            use wgpu::BufferUsages as U;
            let (layout, pipeline) = super::stage_pipeline(
                device,
                "tethers",
                SHADER,
                "tether_pass",
                &[
                    Uniform { dynamic: false },
                    Storage { read_only: true },
                    Storage { read_only: false },
                    Storage { read_only: true },
                    Storage { read_only: true },
                    Storage { read_only: false },
                ],
            );
            let init = |label, bytes: &[u8], usage| super::init_buffer(device, label, bytes, usage);
            let step = init(
                "tether step",
                bytemuck::bytes_of(&params),
                U::UNIFORM | U::COPY_DST,
            );
            let parts = init("tethered particles", parts, U::STORAGE);
            let links = init("tethers", links, U::STORAGE);
            let change = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("tethers' change of energy"),
                size: change_bytes,
                usage: U::STORAGE | U::COPY_SRC | U::COPY_DST,
                mapped_at_creation: false,
            });
            let staging = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("tethers' change staging"),
                size: change_bytes,
                usage: U::MAP_READ | U::COPY_DST,
                mapped_at_creation: false,
            });
            let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("tethers"),
                layout: &layout,
                entries: &[
                    super::entry(0, &step),
                    super::entry(1, pos),
                    super::entry(2, vel),
                    super::entry(3, &parts),
                    super::entry(4, &links),
                    super::entry(5, &change),
                ],
            });
            Self {
                pipeline,
                bind_group,
                step,
                change,
                staging,
                params,
                slots: u32::MAX,
            }
        })
    }

    /// A new substep length.
    pub(super) fn set_h(&mut self, queue: &wgpu::Queue, h: f64) {
        self.params.h = h as f32;
        queue.write_buffer(&self.step, 0, bytemuck::bytes_of(&self.params));
    }

    /// Encodes one substep's pass.
    pub(super) fn encode(&self, pass: &mut wgpu::ComputePass<'_>) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        super::dispatch(pass, self.params.parts);
    }

    /// Waits for the queued work; the change of energy the clamps made since the last call,
    /// summed in particle order (J), the device's sums then cleared.
    pub(super) fn take_change(&mut self, ctx: &GpuContext) -> Result<f64, GpuError> {
        if self.params.parts == 0 {
            return Ok(0.0);
        }
        let bytes = u64::from(self.params.parts) * 4;
        let mut sum = 0.0;
        super::read_staging(
            ctx,
            "read tethers",
            &self.staging,
            bytes,
            |encoder| {
                encoder.copy_buffer_to_buffer(&self.change, 0, &self.staging, 0, bytes);
                encoder.clear_buffer(&self.change, 0, None);
            },
            |view| {
                let change: &[f32] = bytemuck::cast_slice(view);
                sum = change.iter().map(|&e| f64::from(e)).sum();
            },
        )?;
        Ok(sum)
    }
}
