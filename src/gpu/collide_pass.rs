//! Self-collision's pass on the device (`shaders/collide_pass.wgsl`), the twin of the CPU's
//! pass over the particle-against-triangle candidates in colour order (`project` in
//! `src/collide/mod.rs` with its colours, `src/collide/colours.rs`): one workgroup runs the
//! colours one after another over the springs' position and velocity buffers, so the result
//! is the same on every run. The host uploads the candidates at each find and the substep's
//! start places at a frame's start; the shader keeps those after each pass.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::GpuContext;
use crate::error::GpuError;

/// The WGSL source of the pass: the prelude ([`super::PRELUDE`]), the triangle queries, then
/// `shaders/collide_pass.wgsl`.
pub const SHADER: &str = concat!(
    include_str!("../../shaders/prelude.wgsl"),
    include_str!("../../shaders/triangle.wgsl"),
    include_str!("../../shaders/collide_pass.wgsl")
);

/// `PassStep` in shaders/collide_pass.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PassStep {
    pub colours: u32,
    pub particles: u32,
    pub settles: u32,
    pub one: f32,
}

/// `Contact` in shaders/collide_pass.wgsl: particle `p` against the triangle `a`, `b`, `c`
/// (packed indices), the pair's thickness and friction (kinetic, static).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Contact {
    pub p: u32,
    pub a: u32,
    pub b: u32,
    pub c: u32,
    pub thickness: f32,
    pub mu: f32,
    pub mu_s: f32,
    pub _pad: f32,
}

/// `Active` in shaders/collide_pass.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Active {
    pub n: [f32; 4],
    pub weights: [f32; 4],
}

/// The pass of one gather over the springs' buffers.
pub struct DevicePass {
    ctx: Arc<GpuContext>,
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    step: wgpu::Buffer,
    pos: wgpu::Buffer,
    vel: wgpu::Buffer,
    start: wgpu::Buffer,
    contacts: wgpu::Buffer,
    colour_at: wgpu::Buffer,
    active: wgpu::Buffer,
    staging: wgpu::Buffer,
    uniform: PassStep,
    /// Contacts and colours the buffers have room for.
    room: (u32, u32),
}

impl std::fmt::Debug for DevicePass {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DevicePass")
            .field("step", &self.uniform)
            .finish()
    }
}

fn buffer(ctx: &GpuContext, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage,
        mapped_at_creation: false,
    })
}

use wgpu::BufferUsages as U;

impl DevicePass {
    /// The pass over `pos` (`Position`s) and `vel` (velocity, inverse mass) of `particles`,
    /// with `settles` passes over the velocities after the first.
    pub fn new(
        ctx: Arc<GpuContext>,
        pos: &wgpu::Buffer,
        vel: &wgpu::Buffer,
        particles: u32,
        settles: u32,
    ) -> Result<Self, GpuError> {
        let ctx2 = ctx.clone();
        let (pos, vel) = (pos.clone(), vel.clone());
        ctx.scoped("self-collision pass", move || {
            use super::Slot::{Storage, Uniform};
            let (write, read) = (Storage { read_only: false }, Storage { read_only: true });
            let (layout, pipeline) = super::stage_pipeline(
                &ctx2.device,
                "self-collision pass",
                SHADER,
                "collide_pass",
                &[
                    Uniform { dynamic: false },
                    write,
                    write,
                    write,
                    read,
                    read,
                    write,
                ],
            );
            let step = buffer(&ctx2, "pass step", 16, U::UNIFORM | U::COPY_DST);
            let start = buffer(
                &ctx2,
                "pass start",
                u64::from(particles) * 16,
                U::STORAGE | U::COPY_DST | U::COPY_SRC,
            );
            let staging = buffer(
                &ctx2,
                "pass staging",
                u64::from(particles) * 16,
                U::MAP_READ | U::COPY_DST,
            );
            let (contacts, colour_at, active) = Self::lists(&ctx2, (0, 0));
            let uniform = PassStep {
                colours: 0,
                particles,
                settles,
                one: 1.0,
            };
            Self {
                ctx: ctx2.clone(),
                bind_group: Self::bind(
                    &ctx2,
                    &layout,
                    [&step, &pos, &vel, &start, &contacts, &colour_at, &active],
                ),
                layout,
                pipeline,
                step,
                pos,
                vel,
                start,
                contacts,
                colour_at,
                active,
                staging,
                uniform,
                room: (0, 0),
            }
        })
    }

    fn lists(ctx: &GpuContext, (n, c): (u32, u32)) -> (wgpu::Buffer, wgpu::Buffer, wgpu::Buffer) {
        let storage = U::STORAGE | U::COPY_DST;
        (
            buffer(ctx, "pass contacts", u64::from(n.max(1)) * 32, storage),
            buffer(ctx, "pass colours", u64::from(c + 1) * 4, storage),
            buffer(ctx, "pass active", u64::from(n.max(1)) * 32, U::STORAGE),
        )
    }

    fn bind(
        ctx: &GpuContext,
        layout: &wgpu::BindGroupLayout,
        buffers: [&wgpu::Buffer; 7],
    ) -> wgpu::BindGroup {
        let entries: Vec<_> = (0u32..)
            .zip(buffers)
            .map(|(i, b)| super::entry(i, b))
            .collect();
        ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("self-collision pass"),
            layout,
            entries: &entries,
        })
    }

    /// The candidates in colour order: colour `c`'s are `contacts[colour_at[c] ..
    /// colour_at[c + 1]]`.
    pub fn set_contacts(
        &mut self,
        contacts: &[Contact],
        colour_at: &[u32],
    ) -> Result<(), GpuError> {
        let (n, c) = (
            contacts.len() as u32,
            colour_at.len().saturating_sub(1) as u32,
        );
        if n > self.room.0 || c > self.room.1 {
            let ctx = self.ctx.clone();
            let room = (n.next_power_of_two(), c.next_power_of_two());
            let (contacts, colour_at, active) =
                ctx.scoped("self-collision pass", || Self::lists(&ctx, room))?;
            self.bind_group = Self::bind(
                &ctx,
                &self.layout,
                [
                    &self.step,
                    &self.pos,
                    &self.vel,
                    &self.start,
                    &contacts,
                    &colour_at,
                    &active,
                ],
            );
            (self.contacts, self.colour_at, self.active, self.room) =
                (contacts, colour_at, active, room);
        }
        let q = &self.ctx.queue;
        if n > 0 {
            q.write_buffer(&self.contacts, 0, bytemuck::cast_slice(contacts));
        }
        q.write_buffer(&self.colour_at, 0, bytemuck::cast_slice(colour_at));
        self.uniform.colours = c;
        q.write_buffer(&self.step, 0, bytemuck::bytes_of(&self.uniform));
        Ok(())
    }

    /// Each particle's place at the substep's start (xyz).
    pub fn set_start(&self, start: &[[f32; 4]]) {
        let q = &self.ctx.queue;
        q.write_buffer(&self.start, 0, bytemuck::cast_slice(start));
    }

    /// One pass, in its own submit.
    pub fn run(&self) -> Result<(), GpuError> {
        self.ctx.scoped("self-collision pass", || {
            let mut encoder =
                (self.ctx.device).create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("pass"),
                });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("self-collision pass"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &self.bind_group, &[]);
                pass.dispatch_workgroups(1, 1, 1);
            }
            self.ctx.queue.submit([encoder.finish()]);
        })
    }

    /// The places the last pass kept as the next substep's start, into `out`.
    pub fn read_start(&self, out: &mut Vec<[f32; 4]>) -> Result<(), GpuError> {
        let bytes = u64::from(self.uniform.particles) * 16;
        super::read_staging(
            &self.ctx,
            "self-collision start",
            &self.staging,
            bytes,
            |encoder| encoder.copy_buffer_to_buffer(&self.start, 0, &self.staging, 0, bytes),
            |b| {
                out.clear();
                out.extend_from_slice(bytemuck::cast_slice(b));
            },
        )
    }
}
