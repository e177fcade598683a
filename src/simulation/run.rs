//! The one loop that runs a frame's schedule ([`Schedule`]) on either back end, and the
//! stages matched in one place.
//!
//! Substeps go in batches: one substep at a time on the CPU; on the device all of a frame's
//! substeps in one submit unless a stage needs the host between them
//! ([`Schedule::substeps_per_submit`]). Each batch runs every stage's `begin` (work before the
//! springs move: the contact stage keeps the start positions, or poses the device's colliders
//! for the batch's slots), then every stage in order. The state comes back from the device
//! when a host stage needs it, and at the frame's end.

use super::*;
use crate::audit::{Auditor, DamperLaw, Line};
use crate::schedule::{Schedule, Stage, StageKind, StageTimes};

/// What the stages of one frame work on: borrowed from the [`Simulation`], so the frame can
/// run as one rayon job.
pub(super) struct Run<'a> {
    pub(super) schedule: &'a Schedule,
    /// The game's forces and the frame's external accelerations, when the force stage is
    /// listed.
    pub(super) forces: Option<&'a mut super::forces::Forces>,
    /// The drives, when the drive stage is listed.
    pub(super) drives: Option<&'a mut super::drive::Drives>,
    /// The tethers, when their stage is listed.
    pub(super) tethers: Option<&'a mut crate::tether::TetherStage>,
    /// The stretch limits, when their stage is listed.
    pub(super) stretch: Option<&'a mut crate::stretch::StretchStage>,
    /// Self-collision, when its stage is listed.
    pub(super) collide: Option<&'a mut crate::collide::CollideStage>,
    /// The tearing stage, when listed (it runs at the frame's end, in the frame's job).
    pub(super) tear: Option<&'a mut crate::tear::TearStage>,
    pub(super) gravity: DVec3,
    /// The frame's substeps (a retry's, once it runs).
    pub(super) frame_substeps: u32,
    pub(super) packed: &'a mut Packed,
    pub(super) solver: &'a mut Solver,
    pub(super) auditor: &'a mut Auditor,
    pub(super) world: &'a World,
    /// Particles the quarantine found this frame.
    pub(super) found: &'a mut Vec<usize>,
    pub(super) coupling: Option<Coupling<'a>>,
    #[cfg(feature = "gpu")]
    pub(super) device: Option<Device<'a>>,
    pub(super) law: DamperLaw,
    pub(super) times: StageTimes,
    /// The audit's share of the substeps (the dampers' pass).
    pub(super) audit_time: Duration,
    /// The host's waits for the device's work (the state or the contacts' partials back).
    pub(super) device_time: Duration,
    /// The device's kernel time per stage, from its stage clock.
    pub(super) device_stages: Option<StageTimes>,
    /// The last lap of the stage clock.
    pub(super) lap: Instant,
    /// Whether the stages are timed ([`Simulation::set_timers`]): off, no clock is read.
    pub(super) timed: bool,
}

/// The device's side of a frame.
#[cfg(feature = "gpu")]
pub(super) struct Device<'a> {
    pub(super) gpu: &'a mut crate::gpu::GpuSolver,
    /// Host scratch for the device contact stage's colliders.
    pub(super) scratch: &'a mut Vec<crate::gpu::contacts::Collider>,
    /// A host stage moved particles since the state last went to the device.
    pub(super) host_newer: bool,
    /// The device stepped since the state last came back.
    pub(super) device_newer: bool,
}

impl Run<'_> {
    /// The wall time since the last lap goes to `kind`.
    fn charge(&mut self, kind: StageKind) {
        if self.timed {
            let now = Instant::now();
            self.times[kind] += now - self.lap;
            self.lap = now;
        }
    }

    /// The wall time since the last lap goes to the device's share.
    #[cfg(feature = "gpu")]
    fn charge_device(&mut self) {
        if self.timed {
            let now = Instant::now();
            self.device_time += now - self.lap;
            self.lap = now;
        }
    }

    /// The wall time since the last lap goes to the audit.
    fn charge_audit(&mut self) {
        if self.timed {
            let now = Instant::now();
            self.audit_time += now - self.lap;
            self.lap = now;
        }
    }

    /// Substeps `1..=substeps` of `h`: the schedule's stages, batch by batch; then, on the
    /// device, the state back for the frame's end and the quarantine's check of it.
    pub(super) fn substeps(&mut self, substeps: u32, h: f64) -> Result<(), SimError> {
        let schedule = self.schedule;
        let per_submit = schedule.substeps_per_submit(substeps);
        self.frame_substeps = substeps;
        if self.timed {
            self.lap = Instant::now();
        }
        #[cfg(feature = "gpu")]
        if let Some(d) = self.device.as_mut() {
            d.gpu.set_clock(self.timed);
        }
        let mut k = 0;
        while k < substeps {
            let n = per_submit.min(substeps - k);
            for &s in schedule.stages() {
                self.begin(s, k, n, h)?;
            }
            #[cfg(feature = "gpu")]
            if let Some(d) = self.device.as_mut().filter(|d| d.host_newer) {
                d.gpu.write_state(self.packed);
                d.host_newer = false;
            }
            for &s in schedule.stages() {
                self.run(s, k, n, h)?;
            }
            #[cfg(feature = "gpu")]
            if let Some(d) = self.device.as_mut().filter(|d| d.host_newer) {
                d.gpu.write_state(self.packed);
                d.host_newer = false;
            }
            k += n;
        }
        #[cfg(feature = "gpu")]
        if self.device.as_ref().is_some_and(|d| d.device_newer) {
            self.state_to_host()?;
            self.quarantine();
        }
        #[cfg(feature = "gpu")]
        if let Some(d) = self.device.as_mut() {
            self.device_stages = d.gpu.take_clock();
        }
        Ok(())
    }

    /// The stages' `prepare(h)`: what each caches for a substep of `h` (the integrate stage's
    /// coefficients), when the frame changes its step (a retry at more substeps).
    pub(super) fn prepare(&mut self, h: f64) -> Result<(), SimError> {
        for s in self.schedule.stages() {
            if s.kind == StageKind::Integrate && s.on == Backend::Cpu {
                self.solver.prepare(self.packed, h)?;
            }
        }
        Ok(())
    }

    /// The stages' frame end: the contact stage books its projections on the frame's lines.
    pub(super) fn book_frame(&mut self) {
        if let Some(d) = &self.drives {
            self.auditor.book(Line::Attachments, d.energy);
        }
        if let Some(t) = &self.tethers {
            self.auditor.book(Line::Limits, -t.energy);
        }
        if let Some(s) = &self.stretch {
            self.auditor.book(Line::Limits, -s.energy);
        }
        if let Some(c) = &self.collide {
            self.auditor.book(Line::Contacts, -c.energy);
        }
        if let Some(t) = &self.tear {
            self.auditor.book(Line::Torn, t.energy);
        }
        if let Some(c) = self.coupling.as_mut() {
            for (line, joules) in c.stage().energy.lines() {
                self.auditor.book(line, joules);
            }
        }
    }

    /// A stage's work before the batch's springs move (substeps `k + 1..=k + n`).
    #[cfg_attr(not(feature = "gpu"), allow(unused_variables))]
    fn begin(&mut self, stage: Stage, k: u32, n: u32, h: f64) -> Result<(), SimError> {
        if let (StageKind::Tethers, 0, Some(t)) = (stage.kind, k, self.tethers.as_mut()) {
            t.energy = 0.0;
            #[cfg(feature = "gpu")]
            if let Some(d) = self.device.as_mut() {
                d.gpu.set_tether_slots(self.frame_substeps - 1);
            }
        }
        if let (StageKind::StretchLimit, 0, Some(s)) = (stage.kind, k, self.stretch.as_mut()) {
            s.energy = 0.0;
        }
        if let (StageKind::SelfCollision, 0) = (stage.kind, k) {
            // The candidates from the frame's start state (on the host at a frame's start).
            if let Some(c) = self.collide.as_mut() {
                c.begin_frame(self.packed)?;
            }
            self.charge(StageKind::SelfCollision);
        }
        if stage.kind == StageKind::Drive {
            if let Some(d) = self.drives.as_mut() {
                if k == 0 {
                    d.begin_frame(self.packed, self.frame_substeps, h);
                }
                d.begin_substep(self.packed, k + 1, self.gravity);
                if k == 0 {
                    self.host_moved();
                }
            }
            self.charge(StageKind::Drive);
        }
        if stage.kind != StageKind::Contacts {
            return Ok(());
        }
        match (stage.on, self.coupling.as_mut()) {
            (Backend::Cpu, Some(c)) => c.begin_substep(self.packed),
            #[cfg(feature = "gpu")]
            (Backend::Gpu, Some(Coupling::Own(p))) => {
                let Some(d) = self.device.as_mut() else {
                    return Ok(());
                };
                // The bodies move first: nothing they do within the batch depends on the cloth.
                for slot in k..k + n {
                    p.step_bodies(h);
                    p.device_colliders(d.scratch);
                    if let Some(dc) = d.gpu.contacts() {
                        dc.set_colliders(slot, d.scratch);
                    }
                }
            }
            _ => {}
        }
        self.charge(StageKind::Contacts);
        Ok(())
    }

    /// A stage's work over the batch (substeps `k + 1..=k + n`): the one match of the kinds.
    fn run(&mut self, stage: Stage, k: u32, n: u32, h: f64) -> Result<(), SimError> {
        match (stage.kind, stage.on) {
            // Fused: the integrate kernel reads them as its external acceleration (the force
            // stage's frame-start work is done before the substeps).
            (StageKind::Gravity | StageKind::Air | StageKind::Forces, _) => {}
            // At the frame's end, in the frame's job after the last substep.
            (StageKind::Tearing, _) => {}
            (StageKind::Integrate, Backend::Gpu) => self.integrate_on_device(k, n)?,
            (StageKind::Integrate, _) => {
                self.auditor.begin_substep(self.packed);
                self.charge_audit();
                let accel = self.forces.as_deref().map(|f| &f.accel[..]);
                self.solver.substep_with(self.packed, h, accel)?;
                self.charge(StageKind::Integrate);
                let loss = self.solver.grid_damper_loss();
                self.auditor.damping(self.packed, self.law, h, loss);
                if let Some(f) = self.forces.as_deref() {
                    self.auditor.force_work(self.packed, &f.total);
                }
                self.charge_audit();
            }
            (StageKind::Drive, _) => {
                self.state_to_host()?;
                if let Some(d) = self.drives.as_mut() {
                    d.substep(self.packed, k + 1, self.gravity);
                }
                self.host_moved();
                self.charge(StageKind::Drive);
            }
            // The device clamps each substep; the frame's last placing runs here.
            (StageKind::Tethers, Backend::Gpu) => {
                if k + n == self.frame_substeps {
                    self.device_tethers_end(h)?;
                }
            }
            (StageKind::Tethers, _) => {
                self.state_to_host()?;
                if let Some(t) = self.tethers.as_mut() {
                    if t.project(self.packed, self.gravity, h, k + n == self.frame_substeps) {
                        t.energy += self.auditor.spring_change(self.packed, t.moves());
                    }
                }
                self.host_moved();
                self.charge(StageKind::Tethers);
            }
            (StageKind::StretchLimit, _) => {
                self.state_to_host()?;
                if let Some(s) = self.stretch.as_mut() {
                    if s.project(self.packed, self.gravity) {
                        s.energy += self.auditor.spring_change(self.packed, s.moves());
                    }
                }
                self.host_moved();
                self.charge(StageKind::StretchLimit);
            }
            (StageKind::SelfCollision, Backend::Gpu) => {
                // The places after the springs, for the host's check whether to find again;
                // the pass then moves the device's state, newer than the host's once more.
                self.state_to_host()?;
                #[cfg(feature = "gpu")]
                if let (Some(c), Some(d)) = (self.collide.as_mut(), self.device.as_mut()) {
                    c.project_on_device(self.packed)?;
                    d.device_newer = true;
                }
                self.charge(StageKind::SelfCollision);
            }
            (StageKind::SelfCollision, _) => {
                self.state_to_host()?;
                // What the host's contact pass touched (none where the contacts run on the
                // device, whose pass the host does not see).
                let host_contacts = (self.schedule.stages())
                    .iter()
                    .any(|s| s.kind == StageKind::Contacts && s.on == Backend::Cpu);
                if let Some(c) = self.collide.as_mut() {
                    match self.coupling.as_mut() {
                        Some(p) if host_contacts => c.ground(p.stage().touched()),
                        _ => c.ground(&[]),
                    }
                }
                if let Some(c) = self.collide.as_mut() {
                    if c.project(self.packed, self.gravity)? {
                        c.energy += self.auditor.spring_change(self.packed, c.moves());
                    }
                }
                self.host_moved();
                self.charge(StageKind::SelfCollision);
            }
            (StageKind::Contacts, Backend::Gpu) => self.device_contacts(k, n)?,
            (StageKind::Contacts, _) => {
                self.state_to_host()?;
                if let Some(c) = self.coupling.as_mut() {
                    c.substep(self.packed, h, k + 1);
                }
                self.host_moved();
                self.charge(StageKind::Contacts);
            }
            // Where the state is on the host; on the device it waits for the frame's end.
            (StageKind::Quarantine, _) => {
                if !self.state_on_device() {
                    self.quarantine();
                }
            }
        }
        Ok(())
    }

    /// The quarantine's check of the host's state ([`contain`]); the stages hear of particles
    /// it moved.
    fn quarantine(&mut self) {
        if contain(self.packed, self.world, self.found) {
            if let Some(c) = self.coupling.as_mut() {
                c.moved();
            }
            self.host_moved();
        }
        self.charge(StageKind::Quarantine);
    }

    /// Whether the device holds a state newer than the host's.
    fn state_on_device(&self) -> bool {
        #[cfg(feature = "gpu")]
        if let Some(d) = &self.device {
            return d.device_newer;
        }
        false
    }

    /// A host stage moved particles: the device needs the state before it steps again.
    fn host_moved(&mut self) {
        #[cfg(feature = "gpu")]
        if let Some(d) = &mut self.device {
            d.host_newer = true;
        }
    }

    /// Brings the device's state to the host when it is newer (the wait is the device's
    /// share: its kernels run while the host waits here).
    fn state_to_host(&mut self) -> Result<(), SimError> {
        #[cfg(feature = "gpu")]
        if let Some(d) = self.device.as_mut().filter(|d| d.device_newer) {
            d.gpu.read_back(self.packed)?;
            d.device_newer = false;
            // The frame's air, made on the device, came back with the state: its work is
            // booked from here as the CPU's air is.
            if let Some(f) = self.forces.as_deref_mut() {
                if d.gpu.take_air_forces(&mut f.air)? {
                    f.prepare(self.packed, self.gravity);
                }
            }
            self.charge_device();
            if let Some(f) = self.forces.as_deref() {
                self.auditor.force_work(self.packed, &f.total);
                self.charge_audit();
            }
        }
        Ok(())
    }

    #[cfg(feature = "gpu")]
    fn integrate_on_device(&mut self, k: u32, n: u32) -> Result<(), SimError> {
        if let Some(d) = self.device.as_mut() {
            if self.forces.is_some() && !d.device_newer {
                // The start of the moves whose work the forces book when the state comes back.
                self.auditor.begin_substep(self.packed);
            }
            d.gpu.run_slots(k, n)?;
            d.device_newer = true;
        }
        self.charge(StageKind::Integrate);
        Ok(())
    }

    #[cfg(not(feature = "gpu"))]
    fn integrate_on_device(&mut self, _: u32, _: u32) -> Result<(), SimError> {
        Ok(())
    }

    /// The device's contact stage: its partial impulses for the batch's slots come back and
    /// push the bodies.
    #[cfg(feature = "gpu")]
    fn device_contacts(&mut self, k: u32, n: u32) -> Result<(), SimError> {
        let (Some(Coupling::Own(p)), Some(d)) = (self.coupling.as_mut(), self.device.as_mut())
        else {
            return Ok(());
        };
        let Some(dc) = d.gpu.contacts() else {
            return Ok(());
        };
        let (groups, nc) = dc.shape();
        let partials = d.gpu.read_partials(k, n)?;
        if self.timed {
            let now = Instant::now();
            self.device_time += now - self.lap;
            self.lap = now;
        }
        for slot in partials.chunks(groups * nc) {
            p.apply_device(slot, groups, nc);
        }
        self.charge(StageKind::Contacts);
        Ok(())
    }

    #[cfg(not(feature = "gpu"))]
    fn device_contacts(&mut self, _: u32, _: u32) -> Result<(), SimError> {
        Ok(())
    }

    /// The frame's last substep of the device's tethers: the state and the device clamps'
    /// change of energy come back, and the substep's placing and clamp run here, as on the CPU
    /// (the state then goes back: the clamp changed velocities).
    #[cfg(feature = "gpu")]
    fn device_tethers_end(&mut self, h: f64) -> Result<(), SimError> {
        self.state_to_host()?;
        let change = match self.device.as_mut() {
            Some(d) => d.gpu.take_tether_change()?,
            None => 0.0,
        };
        self.charge_device();
        if let Some(t) = self.tethers.as_mut() {
            if t.finish_device(self.packed, self.gravity, h, change) {
                t.energy += self.auditor.spring_change(self.packed, t.moves());
            }
        }
        self.host_moved();
        self.charge(StageKind::Tethers);
        Ok(())
    }

    #[cfg(not(feature = "gpu"))]
    fn device_tethers_end(&mut self, _: f64) -> Result<(), SimError> {
        Ok(())
    }
}
