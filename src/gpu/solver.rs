//! The GPU step: substeps encoded into one submit, the state read back on request.

use super::*;
use crate::schedule::StageKind;

/// The GPU step over one scene.
pub struct GpuSolver {
    pub(super) ctx: Arc<GpuContext>,
    pub(super) module: wgpu::ShaderModule,
    pub(super) layout: wgpu::BindGroupLayout,
    pub(super) pipeline_layout: wgpu::PipelineLayout,
    pub(super) pipelines: Option<Pipelines>,
    pub(super) buffers: Option<Buffers>,
    pub(super) kernel: Kernel,
    /// Whether to specialise the shader to the scene (off only to measure what it buys).
    pub specialise: bool,
    /// The host copy of the spring coefficients, in device order, for step changes.
    pub(super) host_coefs: Vec<Coef>,
    /// The grids step under the closed form (`grid::GridLaw::Harmonic`), not Euler.
    pub(super) harmonic_grids: bool,
    /// Host scratch for state uploads.
    pub(super) host_pos: Vec<Position>,
    pub(super) host_vel: Vec<[f32; 4]>,
    pub(super) h: f32,
    /// The contact stage on the device, when the scene's colliders allow it.
    pub(super) contacts: Option<contacts::DeviceContacts>,
    /// The tethers' clamp on the device, when the scene's cloths have tethers.
    pub(super) tethers: Option<tethers::DeviceTethers>,
    /// The air's passes on the device, when the scene's cloths feel air.
    pub(super) air: Option<air::DeviceAir>,
    /// Step submits so far ([`Self::submits`]).
    pub(super) submits: u64,
    /// Host scratch for the external accelerations ([`Self::set_accel`]).
    pub(super) host_accel: Vec<[f32; 4]>,
    /// The stage clock, where the device has timestamps inside passes.
    pub(super) clock: Option<clock::Clock>,
}

impl GpuSolver {
    pub fn new(ctx: Arc<GpuContext>, kernel: Kernel) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let (module, layout, pipeline_layout) = ctx.scoped("shader module", || {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("integrate.wgsl"),
                source: wgpu::ShaderSource::Wgsl(SHADER.into()),
            });
            let storage = |binding, read_only| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            };
            let uniform = |binding, dynamic| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: dynamic,
                    min_binding_size: None,
                },
                count: None,
            };
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("integrate"),
                entries: &[
                    uniform(0, false),
                    storage(1, false),
                    storage(2, false),
                    storage(3, true),
                    storage(4, true),
                    storage(5, false),
                    storage(6, true),
                    storage(7, true),
                    uniform(8, true),
                    storage(9, true),
                ],
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("integrate"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            (module, layout, pipeline_layout)
        })?;
        let clock = clock::Clock::new(&ctx);
        Ok(Self {
            ctx,
            module,
            layout,
            pipeline_layout,
            pipelines: None,
            buffers: None,
            kernel,
            specialise: true,
            host_coefs: Vec::new(),
            harmonic_grids: false,
            host_pos: Vec::new(),
            host_vel: Vec::new(),
            h: f32::NAN,
            contacts: None,
            tethers: None,
            air: None,
            submits: 0,
            host_accel: Vec::new(),
            clock,
        })
    }

    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// The context, shared (for a stage that keeps its own device work).
    pub fn shared_context(&self) -> Arc<GpuContext> {
        self.ctx.clone()
    }

    pub fn kernel(&self) -> Kernel {
        self.kernel
    }

    /// The specialisation the pipelines were built for (after an upload).
    pub fn specialisation(&self) -> Option<Specialisation> {
        self.pipelines.as_ref().map(|p| p.spec)
    }

    /// A new step `h` with its coefficients: rewrites `h` and the springs' coefficients only.
    pub fn set_step(&mut self, packed: &Packed, lin: &[Linear], h: f64) -> Result<(), GpuError> {
        let Some(b) = &self.buffers else {
            return Ok(());
        };
        if self.h == h as f32 {
            return Ok(());
        }
        let springs = packed.colouring.springs.len();
        for (c, &k) in self.host_coefs.iter_mut().zip(&packed.colouring.springs) {
            c.p = lin[k as usize].p as f32;
            c.q = lin[k as usize].q as f32;
        }
        self.host_coefs.truncate(springs);
        self.host_coefs
            .extend(grid_device(packed, h, self.harmonic_grids).1);
        let q = &self.ctx.queue;
        q.write_buffer(&b.coefs, 0, bytemuck::cast_slice(&self.host_coefs));
        // h is the 4th f32 of Params.
        q.write_buffer(&b.params, 12, bytemuck::bytes_of(&(h as f32)));
        if let Some(t) = &mut self.tethers {
            t.set_h(q, h);
        }
        self.h = h as f32;
        Ok(())
    }

    /// Puts the contact stage on the device over the state uploaded last (call after each
    /// upload and step change); every substep then ends with the contact pass.
    pub fn enable_contacts(&mut self, setup: &contacts::ContactSetup<'_>) -> Result<(), GpuError> {
        let Some(b) = &self.buffers else {
            return Ok(());
        };
        self.contacts = Some(contacts::DeviceContacts::new(
            &self.ctx, &b.pos, &b.vel, setup,
        )?);
        Ok(())
    }

    /// Puts the tethers' clamp on the device over the state uploaded last (call after each
    /// upload): every substep's springs are then followed by the tethers' pass.
    pub fn enable_tethers(&mut self, setup: &tethers::TetherSetup<'_>) -> Result<(), GpuError> {
        let Some(b) = &self.buffers else {
            return Ok(());
        };
        self.tethers = Some(tethers::DeviceTethers::new(
            &self.ctx, &b.pos, &b.vel, setup,
        )?);
        Ok(())
    }

    /// The device clamps after the springs of a frame's slots `0..slots` only (the host takes
    /// the last: it places the particles past their limits first).
    pub fn set_tether_slots(&mut self, slots: u32) {
        if let Some(t) = &mut self.tethers {
            t.slots = slots;
        }
    }

    /// Puts the air on the device over the state uploaded last (call after each upload, for a
    /// solver uploaded with forces): each frame's first submit then starts with its passes
    /// ([`Self::begin_air`]), and their forces come back with the state
    /// ([`Self::take_air_forces`]).
    pub fn enable_air(&mut self, setup: &air::AirSetup) -> Result<(), GpuError> {
        let Some(b) = &self.buffers else {
            return Ok(());
        };
        if !self.pipelines.as_ref().is_some_and(|p| p.spec.forces) {
            return Err(GpuError::Device {
                adapter: self.ctx.describe(),
                what: "air for a solver uploaded without forces".into(),
            });
        }
        let buffers = [&b.pos, &b.vel, &b.accel];
        self.air = Some(air::DeviceAir::new(&self.ctx, buffers, setup)?);
        Ok(())
    }

    /// Whether the air runs on the device.
    pub fn has_air(&self) -> bool {
        self.air.is_some()
    }

    /// The frame's wind for the air's passes, which the frame's first submit starts with.
    pub(crate) fn begin_air(&mut self, field: &crate::air::Field) {
        if let Some(a) = &mut self.air {
            a.begin(&self.ctx.queue, field);
        }
    }

    /// The air's forces of the frame (N, packed order) written over `out`, once the state has
    /// come back after them ([`Self::read_back`] copies them); false where none were waiting.
    pub fn take_air_forces(&mut self, out: &mut [DVec3]) -> Result<bool, GpuError> {
        match &mut self.air {
            Some(a) => a.take(&self.ctx, out),
            None => Ok(false),
        }
    }

    /// Whether the tethers' clamp runs on the device.
    pub fn has_tethers(&self) -> bool {
        self.tethers.is_some()
    }

    /// Waits for the queued work; the change of energy the device's tether clamps made since
    /// the last call (J; 0 without them).
    pub fn take_tether_change(&mut self) -> Result<f64, GpuError> {
        match &mut self.tethers {
            Some(t) => t.take_change(&self.ctx),
            None => Ok(0.0),
        }
    }

    /// The frame's external accelerations (packed order, gravity included; without the air's
    /// where it runs on the device) for a solver uploaded with forces; a device whose buffers
    /// have no room for them refuses them.
    pub fn set_accel(&mut self, accel: &[DVec3]) -> Result<(), GpuError> {
        let Some(b) = &self.buffers else {
            return Ok(());
        };
        if !self.pipelines.as_ref().is_some_and(|p| p.spec.forces)
            || accel.len() != b.particles as usize
        {
            return Err(GpuError::Device {
                adapter: self.ctx.describe(),
                what: "external accelerations for a solver uploaded without forces".into(),
            });
        }
        self.host_accel.clear();
        self.host_accel
            .extend(accel.iter().map(|a| a.as_vec3().extend(0.0).to_array()));
        // With the air on the device, its passes add their share on top.
        match &self.air {
            Some(air) => air.set_base(&self.ctx.queue, &self.host_accel),
            None => {
                self.ctx
                    .queue
                    .write_buffer(&b.accel, 0, bytemuck::cast_slice(&self.host_accel))
            }
        }
        Ok(())
    }

    /// Whether the contact stage runs on the device.
    pub fn has_contacts(&self) -> bool {
        self.contacts.is_some()
    }

    /// The contact stage on the device, when enabled.
    /// Self-collision's pass over the state's buffers (none before the first upload).
    pub fn collide_pass(
        &self,
        particles: u32,
        settles: u32,
    ) -> Result<Option<super::collide_pass::DevicePass>, GpuError> {
        let Some(b) = &self.buffers else {
            return Ok(None);
        };
        let pass = super::collide_pass::DevicePass::new(
            self.ctx.clone(),
            &b.pos,
            &b.vel,
            particles,
            settles,
        )?;
        Ok(Some(pass))
    }

    pub fn contacts(&mut self) -> Option<&mut contacts::DeviceContacts> {
        self.contacts.as_mut()
    }

    /// Waits for the queued work; the contact partials of slots `first..first + count`.
    pub fn read_partials(
        &mut self,
        first: u32,
        count: u32,
    ) -> Result<&[contacts::Partial], GpuError> {
        match &mut self.contacts {
            Some(c) => c.read(&self.ctx, first, count),
            None => Ok(&[]),
        }
    }

    /// How many step submits ([`Self::run_slots`]) the solver has made: a frame's count is
    /// what its schedule asks (one for all its substeps unless a stage needs the host between
    /// them).
    pub fn submits(&self) -> u64 {
        self.submits
    }

    /// Whether the device has the stage clock (timestamps inside passes: [`clock::FEATURES`]).
    pub fn has_clock(&self) -> bool {
        self.clock.is_some()
    }

    /// Turns the stage clock's timestamps on or off (off by default; a simulation turns it on
    /// with its timers, [`crate::Simulation::set_timers`]).
    pub fn set_clock(&mut self, on: bool) {
        if let Some(c) = &mut self.clock {
            c.on = on;
        }
    }

    /// Each stage's kernel time since the last call, as the timestamps read back with the
    /// state measured it; `None` without the clock, with it off, or when a submit found no
    /// room for its timestamps ([`clock::CAPACITY`]).
    pub fn take_clock(&mut self) -> Option<crate::schedule::StageTimes> {
        self.clock.as_mut().and_then(|c| c.take())
    }

    /// Encodes `substeps` substeps into one submit. Nothing is read back.
    pub fn run(&mut self, substeps: u32) -> Result<(), GpuError> {
        self.run_slots(0, substeps)
    }

    /// As [`Self::run`], the substeps using contact slots `first..first + substeps`.
    pub fn run_slots(&mut self, first: u32, substeps: u32) -> Result<(), GpuError> {
        let (Some(b), Some(p)) = (&self.buffers, &self.pipelines) else {
            return Ok(());
        };
        self.submits += 1;
        let contacts = self.contacts.as_ref();
        if let Some(c) = contacts {
            c.flush(&self.ctx.queue);
        }
        let tethers = self.tethers.as_ref();
        let air = self.air.as_mut();
        let kernel = self.kernel;
        let ctx = &self.ctx;
        // A submit's start, the air's end, then the end of each stage of each substep.
        let per_substep = 1 + u32::from(contacts.is_some()) + u32::from(tethers.is_some());

        let mut clock = self.clock.as_mut();
        if !clock
            .as_deref_mut()
            .is_some_and(|c| c.admits(2 + substeps * per_substep))
        {
            clock = None;
        }
        ctx.scoped("step", || {
            let mut encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("step"),
                });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("substeps"),
                    timestamp_writes: None,
                });
                if let Some(c) = clock.as_deref_mut() {
                    c.mark(&mut pass, None);
                }
                // The frame's air, before its first substep.
                if air.is_some_and(|a| a.encode(&mut pass)) {
                    if let Some(c) = clock.as_deref_mut() {
                        c.mark(&mut pass, Some(StageKind::Air));
                    }
                }
                for s in 0..substeps {
                    pass.set_bind_group(0, &b.bind_group, &[0]);
                    match kernel {
                        Kernel::Jacobi => {
                            pass.set_pipeline(&p.spring_pass);
                            dispatch(&mut pass, b.springs_len);
                            if !b.grids.is_empty() {
                                pass.set_pipeline(&p.grid_pass);
                                for (g, &(_, count)) in b.grids.iter().enumerate() {
                                    let at = (b.colours.len() + g) as u32 * b.colour_stride;
                                    pass.set_bind_group(0, &b.bind_group, &[at]);
                                    dispatch(&mut pass, count);
                                }
                                pass.set_bind_group(0, &b.bind_group, &[0]);
                            }
                            pass.set_pipeline(&p.particle_pass);
                            dispatch(&mut pass, b.particles);
                        }
                        Kernel::GaussSeidel => {
                            pass.set_pipeline(&p.add_gravity);
                            dispatch(&mut pass, b.particles);
                            pass.set_pipeline(&p.sweep_colour);
                            for (c, &(_, count)) in b.colours.iter().enumerate() {
                                let offset = c as u32 * b.colour_stride;
                                pass.set_bind_group(0, &b.bind_group, &[offset]);
                                dispatch(&mut pass, count);
                            }
                            pass.set_bind_group(0, &b.bind_group, &[0]);
                            pass.set_pipeline(&p.drift);
                            dispatch(&mut pass, b.particles);
                        }
                    }
                    if let Some(c) = clock.as_deref_mut() {
                        c.mark(&mut pass, Some(StageKind::Integrate));
                    }
                    if let Some(t) = tethers.filter(|t| first + s < t.slots) {
                        t.encode(&mut pass);
                        if let Some(c) = clock.as_deref_mut() {
                            c.mark(&mut pass, Some(StageKind::Tethers));
                        }
                    }
                    if let Some(c) = contacts {
                        c.encode(&mut pass, first + s);
                        if let Some(c) = clock.as_deref_mut() {
                            c.mark(&mut pass, Some(StageKind::Contacts));
                        }
                    }
                }
            }
            ctx.queue.submit([encoder.finish()]);
        })
    }

    /// Waits for the queued work and copies positions and velocities into `packed`
    /// (pinned particles included: the kernels never write them); the air's forces, when the
    /// frame's are waiting, are copied for [`Self::take_air_forces`].
    pub fn read_back(&mut self, packed: &mut Packed) -> Result<(), GpuError> {
        let Some(b) = &self.buffers else {
            return Ok(());
        };
        let n = b.particles as usize;
        let pos_bytes = (n * std::mem::size_of::<Position>()) as u64;
        let vel_bytes = (n * 16) as u64;
        if n == 0 {
            return Ok(());
        }
        let total = pos_bytes + vel_bytes;
        let clock = self.clock.as_ref();
        let air = self.air.as_ref();
        read_staging(
            &self.ctx,
            "read back",
            &b.staging,
            total,
            |encoder| {
                encoder.copy_buffer_to_buffer(&b.pos, 0, &b.staging, 0, pos_bytes);
                encoder.copy_buffer_to_buffer(&b.vel, 0, &b.staging, pos_bytes, vel_bytes);
                if let Some(a) = air {
                    a.copy_out(encoder);
                }
                if let Some(c) = clock {
                    c.resolve(encoder);
                }
            },
            |bytes| {
                let pos: &[Position] = bytemuck::cast_slice(&bytes[..pos_bytes as usize]);
                let vel: &[[f32; 4]] = bytemuck::cast_slice(&bytes[pos_bytes as usize..]);
                for (x, p) in packed.x.iter_mut().zip(pos) {
                    *x = p.to_f64();
                }
                for (v, w) in packed.v.iter_mut().zip(vel) {
                    *v = DVec3::new(w[0].into(), w[1].into(), w[2].into());
                }
            },
        )?;
        match &mut self.clock {
            Some(c) => c.collect(&self.ctx),
            None => Ok(()),
        }
    }

    /// Uploads positions and velocities from `packed` (after the CPU changed them: contacts),
    /// through host scratch sized at gather.
    pub fn write_state(&mut self, packed: &Packed) {
        if let Some(b) = &self.buffers {
            fill_state(packed, &mut self.host_pos, &mut self.host_vel);
            let q = &self.ctx.queue;
            q.write_buffer(&b.pos, 0, bytemuck::cast_slice(&self.host_pos));
            q.write_buffer(&b.vel, 0, bytemuck::cast_slice(&self.host_vel));
        }
    }

    /// Blocks until the queued substeps have run.
    pub fn finish(&self) -> Result<(), GpuError> {
        self.ctx
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Readback(e.to_string()))
    }

    /// Overwrites the per-spring output buffer with NaN, so an element a pass fails to write
    /// shows up as a non-finite state (the parity tests call this before each run).
    pub fn poison(&mut self) {
        if let Some(b) = &self.buffers {
            let bytes = poison(b.springs_len as usize * 16);
            self.ctx.queue.write_buffer(&b.sdv, 0, &bytes);
            // And the grid particles' sums (the other particles' stay zero: no pass writes them).
            for &(first, count) in &b.grids {
                let at = (u64::from(b.springs_len) + u64::from(first)) * 16;
                let bytes = poison(count as usize * 16);
                self.ctx.queue.write_buffer(&b.sdv, at, &bytes);
            }
        }
    }

    /// Bytes the kernels move per substep at best (each element read or written once),
    /// for the memory-bound floor: see BENCHMARKS.md.
    pub fn bytes_per_substep(&self) -> u64 {
        let Some(b) = &self.buffers else { return 0 };
        let (n, m) = (b.particles as u64, b.springs_len as u64);
        let spec = self.specialisation();
        let rate = spec.is_none_or(|s| s.rate);
        let pos = std::mem::size_of::<Position>() as u64;
        match self.kernel {
            Kernel::Jacobi => {
                // Spring pass: spring, two positions (and velocities), one sdv write.
                // Particle pass: offsets, entries, sdv reads, position and velocity in and out.
                let spring_pass = m * (8 + 16 + 16) + n * (pos + if rate { 16 } else { 0 });
                let particle_pass = n * (4 + 2 * pos + 2 * 16) + 2 * m * (8 + 16);
                // Grid pass: each grid particle's position and velocity read (its neighbours'
                // from cache), its sum written, then read by the particle pass.
                let g: u64 = b.grids.iter().map(|&(_, c)| u64::from(c)).sum();
                let grid_pass = g * (pos + 16 + 16 + 16);
                spring_pass + grid_pass + particle_pass
            }
            Kernel::GaussSeidel => {
                let sweep = m * (8 + 16) + n * (pos + 2 * 16);
                n * 2 * 16 + sweep + n * (2 * pos + 16)
            }
        }
    }
}

/// `len` bytes of f32 NaN.
pub(super) fn poison(len: usize) -> Vec<u8> {
    f32::NAN
        .to_le_bytes()
        .iter()
        .copied()
        .cycle()
        .take(len)
        .collect()
}
