//! Self-collision's pass on the device (`shaders/collide_pass.wgsl`), the twin of the CPU's
//! pass over the particle-against-triangle candidates in colour order (`project` in
//! `src/collide/mod.rs` with its colours, `src/collide/colours.rs`): a dispatch per colour,
//! one after another in one compute pass over the springs' position and velocity buffers, or
//! one workgroup taking them all where every colour fits it, so the result is the same on
//! every run (and the same in either form). The host uploads the candidates at each find and the substep's
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
    pub particles: u32,
    pub one: f32,
    pub colours: u32,
    pub settles: u32,
}

/// `Span` in shaders/collide_pass.wgsl: a colour's contacts, `first..end`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Span {
    pub first: u32,
    pub end: u32,
    pub _pad0: u32,
    pub _pad1: u32,
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

/// The buffers that grow with the candidates: the contacts, what each pushed, the spans (at
/// the dynamic offsets' stride, and packed).
struct Lists {
    contacts: wgpu::Buffer,
    active: wgpu::Buffer,
    spans: wgpu::Buffer,
    packed: wgpu::Buffer,
}

/// The pass of one gather over the springs' buffers.
pub struct DevicePass {
    ctx: Arc<GpuContext>,
    layout: wgpu::BindGroupLayout,
    /// `push_colour`, `settle_colour`, `keep_start`, `one_group`.
    pipelines: [wgpu::ComputePipeline; 4],
    bind_group: wgpu::BindGroup,
    step: wgpu::Buffer,
    pos: wgpu::Buffer,
    vel: wgpu::Buffer,
    start: wgpu::Buffer,
    lists: Lists,
    staging: wgpu::Buffer,
    particles: u32,
    settles: u32,
    /// Each colour's contacts, as uploaded; the spans' dynamic-offset stride.
    colours: Vec<Span>,
    stride: u32,
    uniform: PassStep,
    /// One workgroup for every colour (`Some(true)`), a dispatch per colour, or (`None`) the
    /// first where every colour fits a workgroup.
    form: Option<bool>,
    /// Contacts and colours the lists have room for.
    room: (u32, u32),
}

impl std::fmt::Debug for DevicePass {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DevicePass")
            .field("particles", &self.particles)
            .field("colours", &self.colours.len())
            .finish()
    }
}

use super::collide::buffer;
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
        // Dynamic offsets are multiples of the alignment, each holding a Span.
        let stride = ctx.limits.min_uniform_buffer_offset_alignment.max(16);
        ctx.scoped("self-collision pass", move || {
            use super::Slot::{Storage, Uniform};
            let (write, read) = (Storage { read_only: false }, Storage { read_only: true });
            let (layout, pipelines) = super::stage_pipelines(
                &ctx2.device,
                "self-collision pass",
                SHADER,
                ["push_colour", "settle_colour", "keep_start", "one_group"],
                &[
                    Uniform { dynamic: false },
                    write,
                    write,
                    write,
                    read,
                    write,
                    Uniform { dynamic: true },
                    read,
                ],
            );
            let uniform = PassStep {
                particles,
                one: 1.0,
                colours: 0,
                settles,
            };
            let step = super::init_buffer(
                &ctx2.device,
                "pass step",
                bytemuck::bytes_of(&uniform),
                U::UNIFORM | U::COPY_DST,
            );
            let bytes = u64::from(particles) * 16;
            let start = buffer(
                &ctx2,
                "pass start",
                bytes,
                U::STORAGE | U::COPY_DST | U::COPY_SRC,
            );
            let staging = buffer(&ctx2, "pass staging", bytes, U::MAP_READ | U::COPY_DST);
            let lists = Self::lists(&ctx2, (0, 0), stride);
            Self {
                ctx: ctx2.clone(),
                bind_group: Self::bind(&ctx2, &layout, [&step, &pos, &vel, &start], &lists),
                layout,
                pipelines,
                step,
                pos,
                vel,
                start,
                lists,
                staging,
                particles,
                settles,
                colours: Vec::new(),
                stride,
                uniform,
                form: None,
                room: (0, 0),
            }
        })
    }

    /// Room for `n` contacts in `c` colours.
    fn lists(ctx: &GpuContext, (n, c): (u32, u32), stride: u32) -> Lists {
        let n = u64::from(n.max(1));
        let spans = u64::from(c.max(1)) * u64::from(stride);
        let storage = U::STORAGE | U::COPY_DST;
        Lists {
            contacts: buffer(ctx, "pass contacts", n * 32, U::STORAGE | U::COPY_DST),
            active: buffer(ctx, "pass active", n * 32, U::STORAGE),
            spans: buffer(ctx, "pass spans", spans, U::UNIFORM | U::COPY_DST),
            packed: buffer(ctx, "pass spans, packed", u64::from(c.max(1)) * 16, storage),
        }
    }

    fn bind(
        ctx: &GpuContext,
        layout: &wgpu::BindGroupLayout,
        state: [&wgpu::Buffer; 4],
        lists: &Lists,
    ) -> wgpu::BindGroup {
        let mut entries: Vec<_> = (0u32..)
            .zip(state.into_iter().chain([&lists.contacts, &lists.active]))
            .map(|(i, b)| super::entry(i, b))
            .collect();
        // The span at a dynamic offset: one Span's bytes bound.
        entries.push(wgpu::BindGroupEntry {
            binding: 6,
            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &lists.spans,
                offset: 0,
                size: wgpu::BufferSize::new(std::mem::size_of::<Span>() as u64),
            }),
        });
        entries.push(super::entry(7, &lists.packed));
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
        let n = contacts.len() as u32;
        let c = colour_at.len().saturating_sub(1) as u32;
        if n > self.room.0 || c > self.room.1 {
            let ctx = self.ctx.clone();
            let room = (n.next_power_of_two(), c.next_power_of_two());
            let stride = self.stride;
            let lists = ctx.scoped("self-collision pass", || Self::lists(&ctx, room, stride))?;
            let state = [&self.step, &self.pos, &self.vel, &self.start];
            self.bind_group = Self::bind(&ctx, &self.layout, state, &lists);
            (self.lists, self.room) = (lists, room);
        }
        self.colours.clear();
        (self.colours).extend(colour_at.windows(2).map(|w| Span {
            first: w[0],
            end: w[1],
            ..Span::default()
        }));
        let stride = self.stride as usize;
        let mut spans = vec![0u8; self.colours.len() * stride];
        for (k, span) in self.colours.iter().enumerate() {
            spans[k * stride..k * stride + 16].copy_from_slice(bytemuck::bytes_of(span));
        }
        let q = &self.ctx.queue;
        if n > 0 {
            q.write_buffer(&self.lists.contacts, 0, bytemuck::cast_slice(contacts));
            q.write_buffer(&self.lists.spans, 0, &spans);
            q.write_buffer(&self.lists.packed, 0, bytemuck::cast_slice(&self.colours));
        }
        self.uniform.colours = self.colours.len() as u32;
        q.write_buffer(&self.step, 0, bytemuck::bytes_of(&self.uniform));
        Ok(())
    }

    /// One workgroup for every colour (`Some(true)`), a dispatch per colour (`Some(false)`),
    /// or the first where every colour fits a workgroup (`None`, the default). Both give the
    /// same bits; the tests hold them together.
    pub fn set_form(&mut self, one_group: Option<bool>) {
        self.form = one_group;
    }

    /// Each particle's place at the substep's start (xyz).
    pub fn set_start(&self, start: &[[f32; 4]]) {
        let q = &self.ctx.queue;
        q.write_buffer(&self.start, 0, bytemuck::cast_slice(start));
    }

    /// One pass, in its own submit: each colour's contacts pushed, colour after colour, then
    /// their velocities settled the same way, then the places kept (in one workgroup, or a
    /// dispatch per colour: [`Self::set_form`]).
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
                let [push, settle, keep, one] = &self.pipelines;
                let fits = (self.colours.iter()).all(|s| s.end - s.first <= super::WORKGROUP);
                if self.form.unwrap_or(fits) {
                    pass.set_pipeline(one);
                    pass.set_bind_group(0, &self.bind_group, &[0]);
                    pass.dispatch_workgroups(1, 1, 1);
                } else {
                    for round in 0..=self.settles {
                        pass.set_pipeline(if round == 0 { push } else { settle });
                        for (k, span) in self.colours.iter().enumerate() {
                            pass.set_bind_group(0, &self.bind_group, &[k as u32 * self.stride]);
                            super::dispatch(&mut pass, span.end - span.first);
                        }
                    }
                    pass.set_pipeline(keep);
                    pass.set_bind_group(0, &self.bind_group, &[0]);
                    super::dispatch(&mut pass, self.particles);
                }
            }
            self.ctx.queue.submit([encoder.finish()]);
        })
    }

    /// The places the last pass kept as the next substep's start, into `out`.
    pub fn read_start(&self, out: &mut Vec<[f32; 4]>) -> Result<(), GpuError> {
        let bytes = u64::from(self.particles) * 16;
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
