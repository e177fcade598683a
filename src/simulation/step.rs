//! Stepping: a frame's start (gather, the schedule, the books), its stages' run and its end.

use super::*;
use crate::schedule::{StageKind, StageTimes};

impl Simulation {
    /// Advances one frame of `dt` by running the scene's stages ([`Self::schedule`]):
    /// 1. frame start: gather (World → buffers, only if the World may have changed, see
    ///    [`Self::world_mut`]), the schedule rebuilt, the energy books opened, the force stage's
    ///    accelerations when forces are set ([`Self::set_forces`]);
    /// 2. `substeps` substeps on the buffers (no allocation): integrate, then the contact stage
    ///    when the scene has bodies, then the quarantine's check;
    /// 3. frame end: the books closed, buffers → World (scatter), the strain and energy checks.
    ///
    /// A scene without colliders has no contact stage. The state the World gets is always
    /// finite: a particle gone non-finite is quarantined ([`Self::quarantined`]).
    pub fn step(&mut self) -> Result<&StepStats, SimError> {
        self.step_coupled(None)
    }

    /// As [`Self::step`], with the caller's own rapier sets as the rigid side, the way rapier's
    /// own step takes them: particles collide with `colliders` and push the dynamic bodies of
    /// `bodies`; particles with an [`crate::contacts::Attachment`] follow their body.
    ///
    /// The engine does not step these sets: the caller's loop steps rapier once per frame,
    /// before or after this call. Within the frame a moving body is taken at its current
    /// velocity (its pose `k·h` ahead at substep `k`), which is what rapier's step will do.
    /// A simulation whose scene has bodies of its own refuses this (use [`Self::step`]).
    pub fn step_with(
        &mut self,
        bodies: &mut RigidBodySet,
        colliders: &ColliderSet,
    ) -> Result<&StepStats, SimError> {
        if self.props.is_some() {
            return Err(SimError::OwnBodies);
        }
        self.sync()?;
        let stage = self.user_stage.get_or_insert_with(|| {
            let mut s = ContactStage::new(self.contact);
            s.gather(&self.world, &self.packed);
            s.gravity = self.config.gravity;
            s
        });
        if let Some(particle) = stage.dangling(&self.world, bodies) {
            return Err(SimError::DanglingAttachment { particle });
        }
        self.step_coupled(Some((bodies, colliders)))
    }

    /// A frame, for both [`Self::step`] and [`Self::step_with`]:
    /// 1. frame start: gather (World → packed buffers, only when the World changed: a pin set
    ///    or freed refreshes the mass split only, a pinned particle moved writes the state
    ///    only), the schedule rebuilt in place, the energy books opened, the stages' frame
    ///    start;
    /// 2. the schedule's stages ([`Self::schedule`]), substep by substep, by the one loop of
    ///    `run.rs`; on the CPU the accuracy controller may reject the frame and run it again
    ///    from its start with more substeps;
    /// 3. frame end (`finish_frame`): the quarantine's pins, the energy books closed, the
    ///    scatter (buffers → World), the strain and energy checks; then the motion check's
    ///    share and the next frame's substeps.
    pub(super) fn step_coupled(
        &mut self,
        user: Option<(&mut RigidBodySet, &ColliderSet)>,
    ) -> Result<&StepStats, SimError> {
        let t0 = Instant::now();
        let gathered = self.dirty;
        let edited = self.dirty || !self.pins.is_empty() || self.state_edited;
        self.contained.clear();
        self.sync()?;
        self.build_schedule(user.is_some());
        let t1 = Instant::now();
        self.open_books(edited);
        // The air stage, once a frame, at the frame's start state (before the coupling borrows
        // the bodies).
        let t = (self.timers && !self.air.is_empty()).then(Instant::now);
        self.blow();
        let air_time = t.map(|t| t.elapsed());
        let open_time = if self.timers {
            t1.elapsed()
        } else {
            Duration::ZERO
        };
        // The accuracy controller's first hook: this frame is probed (run again on a copy,
        // over the next frames).
        let probing = self.checks_motion();
        let h = self.config.h();
        let substeps = self.config.substeps;
        let mut coupling = match (user, self.props.as_mut(), self.user_stage.as_mut()) {
            (Some((bodies, colliders)), _, Some(stage)) => Some(Coupling::User {
                stage,
                bodies,
                colliders,
            }),
            (None, Some(p), _) => Some(Coupling::Own(p)),
            _ => None,
        };
        if let Some(c) = coupling.as_mut() {
            c.begin_frame(substeps);
        }
        // The force stage, once a frame: gravity and `F/m` summed into one acceleration.
        let t = (self.timers && self.forces.is_some()).then(Instant::now);
        if let Some(f) = self.forces.as_mut() {
            f.prepare(&self.packed, self.config.gravity);
        }
        let forces = self.forces.as_mut();
        #[cfg(feature = "gpu")]
        if let (Some(gpu), Some(f)) = (self.gpu.as_mut(), forces.as_deref()) {
            gpu.set_accel(&f.accel)?;
        }
        let n = self.packed.particle_count();
        self.auditor.set_forced(forces.is_some(), n);
        let mut times = crate::schedule::StageTimes::default();
        if let Some(t) = t {
            times[StageKind::Forces] = t.elapsed();
        }
        if let Some(t) = air_time {
            times[StageKind::Air] = t;
        }
        #[cfg(feature = "gpu")]
        let device = self.gpu.as_mut().map(|gpu| run::Device {
            gpu,
            scratch: &mut self.device_scratch,
            host_newer: false,
            device_newer: false,
        });
        #[cfg(feature = "gpu")]
        let on_device = device.is_some();
        #[cfg(not(feature = "gpu"))]
        let on_device = false;
        // The accuracy controller's second hook: a frame it may reject and run again from its
        // start (automatic substeps, no step budget: the wall clock has the last word there;
        // the CPU; nothing outside the cloth, such as bodies, that a retry would wind back).
        let retry = self.config.auto_substeps
            && !self.config.step_budget.is_finite()
            && coupling.is_none()
            && !on_device;
        // A frame taken again starts from the World, which holds the frame's start until its
        // end's scatter; the motion check keeps its own start, in f32.
        if probing {
            self.controller.probe.keep_start(&self.packed);
        }
        let mut run = run::Run {
            schedule: &self.schedule,
            forces,
            drives: (!self.drives.is_empty()).then_some(&mut self.drives),
            tethers: (!self.tethers.is_empty()).then_some(&mut self.tethers),
            stretch: (!self.stretch.is_empty()).then_some(&mut self.stretch),
            collide: (!self.collide.is_empty()).then_some(&mut self.collide),
            tear: (!self.tear.is_empty()).then_some(&mut self.tear),
            gravity: self.config.gravity,
            frame_substeps: 0,
            packed: &mut self.packed,
            solver: &mut self.solver,
            auditor: &mut self.auditor,
            world: &self.world,
            found: &mut self.contained,
            coupling,
            #[cfg(feature = "gpu")]
            device,
            law: crate::audit::DamperLaw::of(self.config.integrator),
            times,
            audit_time: open_time,
            device_time: Duration::ZERO,
            device_stages: None,
            lap: t1,
            timed: self.timers,
        };
        let tol = self.config.tolerance * self.energy_scale;
        let controller = &mut self.controller;
        let (gravity, dt) = (self.config.gravity, self.config.dt);
        let limit = self.config.strain_limit;
        let mut substeps = substeps;
        let run_ref = &mut run;
        let substeps_out = &mut substeps;
        let frame = move || {
            let run = run_ref;
            let (damping, work) = (run.auditor.frame.damping, run.auditor.frame.forces);
            let mut h = h;
            let mut end = loop {
                run.substeps(*substeps_out, h)?;
                let t = run.timed.then(Instant::now);
                let e = run.auditor.energy(run.packed, gravity);
                if let Some(t) = t {
                    run.audit_time += t.elapsed();
                }
                if !retry || !run.found.is_empty() {
                    break e;
                }
                let f = &run.auditor.frame;
                let before = run.auditor.run.residual;
                // The drive stage's moves are booked at the frame's end (`book_frame`).
                let driven = run.drives.as_ref().map_or(0.0, |d| d.energy);
                let tied = run.tethers.as_ref().map_or(0.0, |t| t.energy)
                    + run.stretch.as_ref().map_or(0.0, |s| s.energy)
                    + run.collide.as_ref().map_or(0.0, |c| c.energy);
                let after = before + (e - f.start - f.edits - f.forces - driven - tied + f.damping);
                let Some(more) = controller.rejects(*substeps_out, before, after, tol) else {
                    break e;
                };
                run.packed.reload_state(run.world);
                run.auditor.frame.damping = damping;
                run.auditor.frame.forces = work;
                *substeps_out = more;
                h = dt / more as f64;
                run.prepare(h)?;
            };
            // The tearing stage, at the frame's end: the springs it breaks leave `E` (and the
            // buffers, for the strain check below).
            if let Some(t) = run.tear.as_mut() {
                t.find(run.packed);
                end -= t.energy;
            }
            run.book_frame();
            // The strain check reads the frame's end state inside the same job.
            let beyond = limit.is_finite() && crate::metrics::beyond(run.packed, limit);
            Ok::<_, SimError>((end, beyond))
        };
        let (end, beyond) = if self.parallel {
            // One rayon job per frame: the passes inside run from a worker's own deque, so
            // the only allocation is the injector's queue block, recycled every 63 frames.
            rayon::scope(|_| frame())?
        } else {
            frame()?
        };
        let (times, audit_time) = (run.times, run.audit_time);
        let device_time = (run.device_time, run.device_stages);
        self.drives.end_frame();
        self.config.substeps = substeps;
        self.finish_frame(
            t0,
            t1,
            gathered,
            (times, audit_time, device_time),
            beyond,
            end,
        )?;
        // The accuracy controller runs on the CPU: on the device the substeps stay at the
        // stability floor's (the device's contact slots are sized for them).
        if !on_device {
            // The motion check: begun after its frame, its second run advanced a share after
            // each frame that follows.
            let t = self.timers.then(Instant::now);
            let probed = self.advance_probe()?;
            if probing {
                self.begin_probe(substeps);
            }
            if let Some(t) = t {
                self.stats.stages[StageKind::Integrate] += t.elapsed();
            }
            // The accuracy controller's third hook: the next frame's substeps.
            self.adapt(probed);
            self.schedule.set_substeps(self.config.substeps);
        }
        self.gather_opened();
        Ok(&self.stats)
    }

    /// Opens the frame's energy books: `E` after the edits (`edited`: the World, pins or the
    /// state changed since the last frame; otherwise the last frame's end stands).
    fn open_books(&mut self, edited: bool) {
        let start = match self.auditor.end {
            Some(e) if !edited => e,
            _ => self.auditor.energy(&self.packed, self.config.gravity),
        };
        self.auditor.begin_frame(start, self.energy_scale);
    }

    /// The end of a frame: the quarantine (the state is finite: every substep ended with
    /// [`contain`]), the energy books closed at `end` (taken in the frame's job), then the
    /// scatter and the checks (`beyond`: a spring is past the strain limit, as the job found).
    pub(super) fn finish_frame(
        &mut self,
        t0: Instant,
        t1: Instant,
        gathered: bool,
        (times, audit_time, (device, device_stages)): (
            StageTimes,
            Duration,
            (Duration, Option<StageTimes>),
        ),
        beyond: bool,
        end: f64,
    ) -> Result<&StepStats, SimError> {
        let t2 = Instant::now();
        self.quarantine();
        self.steps += 1;
        self.time += self.config.dt;
        let quarantined = std::mem::take(&mut self.newly_quarantined);
        self.auditor.end_frame(end, quarantined > 0);
        self.packed.scatter(&mut self.world);
        self.tear_apart();
        let failure = self.check_strain(beyond).or_else(|| self.check_energy());
        self.failure = self.failure.or(failure);
        let t3 = Instant::now();
        self.stats = StepStats {
            gather: t1 - t0,
            stages: times,
            device,
            device_stages,
            audit_time,
            scatter: t3 - t2,
            gathered,
            substeps: self.config.substeps,
            quarantined,
            failure,
            audit: self.auditor.frame,
            budget_limited: false,
        };
        Ok(&self.stats)
    }

    /// The energy limit, checked on the run's books at the frame's end: reported at the frame
    /// the peak residual passes it (the peak never falls, so once).
    fn check_energy(&self) -> Option<crate::Failure> {
        let run = &self.auditor.run;
        let limit = self.config.energy_limit * run.scale;
        // No scale (a scene at rest with nothing to fall): nothing to measure against.
        if run.scale <= 0.0 || run.peak_residual <= limit || self.auditor.peak_before > limit {
            return None;
        }
        let limit = self.config.energy_limit;
        let h = self.config.h();
        let worst = crate::metrics::most_stretched(&self.packed, h);
        Some(crate::Failure::Energy {
            frame: self.steps,
            created: run.peak_residual,
            scale: run.scale,
            limit,
            integrator: self.config.integrator,
            step_ratio: crate::metrics::worst_step_ratio(&self.packed, h).map_or(0.0, |r| r.0),
            particles: worst.map_or((0, 0), |w| w.ends),
            strain: worst.map_or(0.0, |w| w.strain),
            substeps: self.config.substeps,
        })
    }

    /// The strain limit, checked on the frame's end state: one read of the springs, and the
    /// worst spring looked up only when the limit is passed.
    fn check_strain(&self, beyond: bool) -> Option<crate::Failure> {
        let limit = self.config.strain_limit;
        if !beyond {
            return None;
        }
        let worst = crate::metrics::most_stretched(&self.packed, self.config.h())?;
        if worst.strain <= limit {
            // Within rounding of the limit: the squared comparison and δ/l0 disagree there.
            return None;
        }
        Some(crate::Failure::Strain {
            frame: self.steps,
            particles: worst.ends,
            strain: worst.strain,
            limit,
            integrator: self.config.integrator,
            step_ratio: worst.step_ratio,
            substeps: self.config.substeps,
        })
    }

    /// What the step needs packed: cloth grids kept whole for an integrator with a grid pass
    /// (on either back end), the colouring only for the sweeping integrators and the GPU.
    pub(super) fn gather_options(&self) -> GatherOptions {
        #[cfg(feature = "gpu")]
        let gpu = self.gpu.is_some();
        #[cfg(not(feature = "gpu"))]
        let gpu = false;
        let i = self.config.integrator;
        let keep_grids = if gpu {
            i.runs_on_gpu_grids()
        } else {
            i.runs_on_grids(self.config.exact_displacement)
        };
        GatherOptions {
            keep_grids,
            colouring: gpu || self.config.integrator.needs_colouring(),
        }
    }

    /// Brings the packed buffers up to date with the edits since the last step: a World change
    /// re-gathers everything, pins set or freed refresh the mass split, pinned particles moved
    /// go to the device.
    pub(super) fn sync(&mut self) -> Result<(), SimError> {
        if self.dirty {
            return self.gather();
        }
        if !self.pins.is_empty() {
            // A freed particle takes its mass from the World, which holds it.
            let (world, entities) = (&self.world, &self.packed.topology.entities);
            // The last edit of each particle is what the World holds.
            let mut edits: Vec<(usize, usize, bool)> = (self.pins.drain(..).enumerate())
                .map(|(k, (i, pinned))| (i, k, pinned))
                .collect();
            edits.sort_unstable_by_key(|&(i, k, _)| (i, k));
            let last = (0..edits.len())
                .filter(|&k| edits.get(k + 1).is_none_or(|next| next.0 != edits[k].0))
                .map(|k| (edits[k].0, edits[k].2));
            let pins: Vec<(usize, Option<f64>)> = last
                .map(|(i, pinned)| {
                    let mass = || {
                        let p = entities.get(i).map(|&e| world.get::<&crate::Particle>(e));
                        p.and_then(Result::ok).map_or(f64::NAN, |p| p.mass)
                    };
                    (i, (!pinned).then(mass))
                })
                .collect();
            if let Err(e) = self.packed.repin(&pins) {
                // The World holds the edit: the next step gathers it and reports it again.
                self.dirty = true;
                return Err(e);
            }
            self.state_edited = false;
            // As after a failed gather: the next step starts again from the World.
            return self.refresh().inspect_err(|_| self.dirty = true);
        }
        #[cfg(feature = "gpu")]
        if self.state_edited {
            if let Some(gpu) = &mut self.gpu {
                gpu.write_state(&self.packed);
            }
        }
        self.state_edited = false;
        Ok(())
    }

    pub(super) fn gather(&mut self) -> Result<(), SimError> {
        self.pins.clear();
        self.state_edited = false;
        let options = self.gather_options();
        // In place: the old buffers go before the new ones are made (never two copies), and
        // only once the World is known to be sound (an error leaves them as they were).
        self.packed.regather(&self.world, options)?;
        self.drop_stale_forces();
        self.gather_air();
        let parts = crate::metrics::energy_parts(&self.packed, self.config.gravity);
        self.energy_scale = parts.scale();
        self.energy_in_motion = parts.internal();
        self.refresh()
    }

    /// Everything after the buffers changed: the checks, the step choice, the solver's
    /// coefficients, the contact stages and the device's copy.
    fn refresh(&mut self) -> Result<(), SimError> {
        let options = self.gather_options();
        // Frozen before anything reads them: particles with a velocity set non-finite from
        // outside, and the free ends of springs beyond f32's range (the device's precision,
        // where they turn non-finite at once; the CPU does the same so the back ends agree).
        let over = |v: f64| v > f32::MAX as f64;
        let p = &self.packed;
        self.contained.extend(
            p.all_springs()
                .filter(|s| over(s.stiffness) || over(s.damping))
                .flat_map(|s| [s.a as usize, s.b as usize])
                .filter(|&i| p.inv_mass[i] != 0.0),
        );
        contain(&mut self.packed, &self.world, &mut self.contained);
        if !self.contained.is_empty() {
            self.quarantine();
            self.packed.regather(&self.world, options)?;
        }
        self.drives.refresh(&self.packed);
        self.tethers.gather(&self.world, &self.packed);
        self.stretch.gather(&self.world, &self.packed);
        // The device's pass kept the places the game's edits are swept from.
        #[cfg(feature = "gpu")]
        self.collide.start_from_device()?;
        self.collide.gather(&self.world, &self.packed);
        self.tear.gather(&self.world, &self.packed);
        self.solver.invalidate();
        self.parallel = crate::integrate::runs_parallel(&self.packed);
        self.estimate_network();
        self.choose_substeps();
        self.solver.prepare(&self.packed, self.config.h())?;
        self.auditor
            .prepare(&self.packed, self.solver.grid_audits());
        if let Some(p) = &mut self.props {
            if let Some(particle) = p.dangling(&self.world) {
                return Err(SimError::DanglingAttachment { particle });
            }
            p.gather(&self.world, &self.packed);
            p.stage_mut().gravity = self.config.gravity;
        }
        if let Some(s) = &mut self.user_stage {
            s.gather(&self.world, &self.packed);
            s.gravity = self.config.gravity;
        }
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &mut self.gpu {
            let c = &self.config;
            let lin = self.solver.coefficients();
            let forces = self.forces.is_some();
            gpu.upload(&self.packed, lin, (c.gravity, forces), c.h(), c.integrator)?;
        }
        #[cfg(feature = "gpu")]
        self.device_contacts()?;
        #[cfg(feature = "gpu")]
        self.device_tethers()?;
        #[cfg(feature = "gpu")]
        self.device_air()?;
        #[cfg(feature = "gpu")]
        self.device_collide()?;
        self.build_schedule(self.user_stage.is_some());
        self.dirty = false;
        Ok(())
    }
}
