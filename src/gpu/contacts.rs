//! The contact stage on the device (`shaders/contacts.wgsl`): balls and cuboids, up to
//! [`MAX_COLLIDERS`] of them, against the particles' resident state. The host uploads the
//! colliders' poses and motions per substep slot and reads back only the per-workgroup partial
//! sums of what the particles did to each body (a few hundred bytes), never the state.

use bytemuck::{Pod, Zeroable};

use super::{GpuContext, WORKGROUP};
use crate::error::GpuError;

/// The WGSL source of the contact stage: the prelude ([`super::PRELUDE`]), then
/// `shaders/contacts.wgsl`.
pub const SHADER: &str = concat!(
    include_str!("../../shaders/prelude.wgsl"),
    include_str!("../../shaders/contacts.wgsl")
);

/// Colliders one device pass can take (the shader's `MAX_COLLIDERS`).
pub const MAX_COLLIDERS: usize = 8;

/// `Step` in shaders/contacts.wgsl: one per substep slot, at a dynamic offset.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Step {
    pub h: f32,
    pub thickness: f32,
    pub restitution: f32,
    pub particles: u32,
    pub colliders: u32,
    pub slot: u32,
    pub groups: u32,
    pub _pad: u32,
}

/// `Collider` in shaders/contacts.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Collider {
    /// 0: ball, 1: cuboid.
    pub kind: u32,
    pub dynamic: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub translation: [f32; 4],
    /// Unit quaternion (x, y, z, w).
    pub rotation: [f32; 4],
    /// Ball: x = radius. Cuboid: half extents.
    pub dims: [f32; 4],
    /// Velocity of the centre of mass; w = static friction.
    pub lin: [f32; 4],
    /// Angular velocity; w = kinetic friction.
    pub ang: [f32; 4],
    /// Centre of mass; w = the body's mass.
    pub com: [f32; 4],
    /// Bounding sphere centre; w = its radius plus the thickness.
    pub sphere: [f32; 4],
}

/// `Partial` in shaders/contacts.wgsl: one workgroup's sums for one collider.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Partial {
    /// Impulse on the body; w = contacts.
    pub impulse: [f32; 4],
    /// Angular impulse about the centre of mass; w = deepest penetration.
    pub torque: [f32; 4],
    /// Supported contacts' impulse sum; w = their count.
    pub support: [f32; 4],
    /// Their angular impulse sum; w = contacts found by the swept test.
    pub support_torque: [f32; 4],
}

/// The device contact stage of one gather: pipeline, buffers, host scratch.
pub struct DeviceContacts {
    pipeline: wgpu::ComputePipeline,
    pub(super) bind_group: wgpu::BindGroup,
    /// The per-slot step uniforms (read through the bind group).
    _step: wgpu::Buffer,
    colliders: wgpu::Buffer,
    partials: wgpu::Buffer,
    staging: wgpu::Buffer,
    /// Dynamic-offset stride of the step uniform.
    pub(super) stride: u32,
    slots: u32,
    colliders_per_slot: u32,
    groups: u32,
    particles: u32,
    host_colliders: Vec<Collider>,
    host_partials: Vec<Partial>,
}

/// What the contact stage needs of a gather.
pub struct ContactSetup<'a> {
    /// Per particle: its mass, 0 for particles the stage skips (pinned, attached).
    pub masses: &'a [f32],
    /// Colliders per slot.
    pub colliders: usize,
    /// Substep slots per frame.
    pub slots: u32,
    pub h: f64,
    pub thickness: f64,
    pub restitution: f64,
}

impl DeviceContacts {
    pub(super) fn new(
        ctx: &GpuContext,
        pos: &wgpu::Buffer,
        vel: &wgpu::Buffer,
        setup: &ContactSetup<'_>,
    ) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let n = setup.masses.len() as u32;
        let nc = setup.colliders.clamp(1, MAX_COLLIDERS) as u32;
        let slots = setup.slots.max(1);
        let groups = n.div_ceil(WORKGROUP).max(1);
        let stride = ctx.limits.min_uniform_buffer_offset_alignment.max(32);
        let mut step_bytes = vec![0u8; (slots * stride) as usize];
        for slot in 0..slots {
            let s = Step {
                h: setup.h as f32,
                thickness: setup.thickness as f32,
                restitution: setup.restitution as f32,
                particles: n,
                colliders: nc,
                slot,
                groups,
                _pad: 0,
            };
            let at = (slot * stride) as usize;
            step_bytes[at..at + 32].copy_from_slice(bytemuck::bytes_of(&s));
        }
        let host_colliders = vec![Collider::default(); (slots * nc) as usize];
        let host_partials = vec![Partial::default(); (slots * groups * nc) as usize];
        let partial_bytes = std::mem::size_of_val(host_partials.as_slice()) as u64;
        ctx.scoped("contact stage", || {
            use super::Slot::{Storage, Uniform};
            use wgpu::BufferUsages as U;
            let (layout, pipeline) = super::stage_pipeline(
                device,
                "contacts",
                SHADER,
                "contact_pass",
                &[
                    Uniform { dynamic: true },
                    Storage { read_only: false },
                    Storage { read_only: false },
                    Storage { read_only: true },
                    Storage { read_only: false },
                    Storage { read_only: true },
                ],
            );
            let init = |label, bytes: &[u8], usage| super::init_buffer(device, label, bytes, usage);
            let step = init("contact steps", &step_bytes, U::UNIFORM);
            let colliders = init(
                "colliders",
                bytemuck::cast_slice(&host_colliders),
                U::STORAGE | U::COPY_DST,
            );
            let partials = init(
                "partials",
                bytemuck::cast_slice(&host_partials),
                U::STORAGE | U::COPY_SRC,
            );
            let masses: &[u8] = if n == 0 {
                &[0u8; 16]
            } else {
                bytemuck::cast_slice(setup.masses)
            };
            let masses = init("masses", masses, U::STORAGE);
            let staging = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("partials staging"),
                size: partial_bytes,
                usage: U::MAP_READ | U::COPY_DST,
                mapped_at_creation: false,
            });
            let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("contacts"),
                layout: &layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &step,
                            offset: 0,
                            size: wgpu::BufferSize::new(32),
                        }),
                    },
                    super::entry(1, pos),
                    super::entry(2, vel),
                    super::entry(3, &colliders),
                    super::entry(4, &partials),
                    super::entry(5, &masses),
                ],
            });
            Self {
                pipeline,
                bind_group,
                _step: step,
                colliders,
                partials,
                staging,
                stride,
                slots,
                colliders_per_slot: nc,
                groups,
                particles: n,
                host_colliders,
                host_partials,
            }
        })
    }

    pub fn slots(&self) -> u32 {
        self.slots
    }

    /// Sets slot `slot`'s colliders (host side; [`Self::flush`] uploads them).
    pub fn set_colliders(&mut self, slot: u32, colliders: &[Collider]) {
        let nc = self.colliders_per_slot as usize;
        let at = slot as usize * nc;
        let dst = &mut self.host_colliders[at..at + nc];
        dst.fill(Collider::default());
        for (d, c) in dst.iter_mut().zip(colliders) {
            *d = *c;
        }
    }

    pub(super) fn flush(&self, queue: &wgpu::Queue) {
        queue.write_buffer(
            &self.colliders,
            0,
            bytemuck::cast_slice(&self.host_colliders),
        );
    }

    /// Encodes the contact pass of `slot`.
    pub(super) fn encode(&self, pass: &mut wgpu::ComputePass<'_>, slot: u32) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[slot * self.stride]);
        super::dispatch(pass, self.particles);
    }

    /// Waits for the queued work and returns the partials of slots `first..first + count`:
    /// `[slot][workgroup][collider]`.
    pub(super) fn read(
        &mut self,
        ctx: &GpuContext,
        first: u32,
        count: u32,
    ) -> Result<&[Partial], GpuError> {
        let per_slot = (self.groups * self.colliders_per_slot) as usize;
        let size = std::mem::size_of::<Partial>();
        let (from, len) = (first as usize * per_slot, count as usize * per_slot);
        let bytes = (len * size) as u64;
        let host = &mut self.host_partials[..len];
        super::read_staging(
            ctx,
            "read partials",
            &self.staging,
            bytes,
            |encoder| {
                encoder.copy_buffer_to_buffer(
                    &self.partials,
                    (from * size) as u64,
                    &self.staging,
                    0,
                    bytes,
                );
            },
            |view| host.copy_from_slice(bytemuck::cast_slice(view)),
        )?;
        Ok(&self.host_partials[..len])
    }

    /// Workgroups per slot and colliders per slot: the shape of [`Self::read`]'s answer.
    pub fn shape(&self) -> (usize, usize) {
        (self.groups as usize, self.colliders_per_slot as usize)
    }
}
