//! Stepping: the stage order of a frame, gather and the frame's end.

use super::*;

impl Simulation {
    /// Advances one frame of `dt`. Stages, in order:
    /// 1. gather: World → buffers, only if the World may have changed (see [`Self::world_mut`]);
    /// 2. integrate: `substeps` substeps on the buffers (no allocation), each followed by the
    ///    contact stage when the scene has bodies;
    /// 3. scatter: buffers → World.
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

    /// The step order, the one place it is written (both [`Self::step`] and
    /// [`Self::step_with`] run it):
    /// 1. gather: World → packed buffers, only when the World changed (a pin set or freed
    ///    refreshes the mass split only, a pinned particle moved writes the state only);
    /// 2. per substep: the integrate kernel (CPU, or the device's, all substeps in one submit
    ///    when nothing on the CPU needs the state between them), then, with bodies, the contact
    ///    stage (rapier steps the bodies, attachments follow them, particles are pushed out of
    ///    colliders with friction, bodies get the opposite impulses), then the quarantine check;
    /// 3. scatter (`finish_frame`): buffers → World, this frame's quarantined particles pinned.
    pub(super) fn step_coupled(
        &mut self,
        user: Option<(&mut RigidBodySet, &ColliderSet)>,
    ) -> Result<&StepStats, SimError> {
        let t0 = Instant::now();
        let gathered = self.dirty;
        let edited = self.dirty || !self.pins.is_empty() || self.state_edited;
        self.contained.clear();
        self.sync()?;
        let t1 = Instant::now();
        self.open_books(edited);
        let mut audit_time = t1.elapsed();
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
        let mut contacts = Duration::ZERO;
        if let Some(c) = coupling.as_mut() {
            c.begin_frame(substeps);
        }
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &mut self.gpu {
            match coupling.as_mut() {
                // On the device the quarantine checks the state where it comes back: once per
                // frame when the substeps go in one submit.
                None => {
                    // Every substep in one submit; the state comes back once, for the scatter.
                    gpu.run(substeps)?;
                    gpu.read_back(&mut self.packed)?;
                    contain(&mut self.packed, &self.world, &mut self.contained);
                }
                Some(Coupling::Own(p)) if gpu.contacts().is_some() => {
                    device_frame(gpu, p, &mut self.device_scratch, substeps, h, &mut contacts)?;
                    gpu.read_back(&mut self.packed)?;
                    contain(&mut self.packed, &self.world, &mut self.contained);
                }
                Some(c) => {
                    // Contacts run on the CPU: the state goes back and forth every substep.
                    for k in 1..=substeps {
                        let t = Instant::now();
                        c.begin_substep(&self.packed);
                        contacts += t.elapsed();
                        gpu.run(1)?;
                        gpu.read_back(&mut self.packed)?;
                        let t = Instant::now();
                        c.substep(&mut self.packed, h, k);
                        contacts += t.elapsed();
                        if contain(&mut self.packed, &self.world, &mut self.contained) {
                            c.moved();
                        }
                        gpu.write_state(&self.packed);
                    }
                }
            }
            let projections = coupling.map(|mut c| c.stage().energy).unwrap_or_default();
            return self.finish_frame(
                t0,
                t1,
                gathered,
                (contacts, audit_time),
                None,
                (None, projections),
            );
        }
        // A frame the accuracy controller may take again: automatic substeps, no step budget
        // (the wall clock has the last word there), nothing outside the cloth (bodies) that a
        // retry would have to wind back.
        let retry =
            self.config.auto_substeps && !self.config.step_budget.is_finite() && coupling.is_none();
        if retry || probing {
            self.controller.keep_start(&self.packed);
        }
        let tol = self.config.tolerance * self.energy_scale;
        let mut substeps = substeps;
        let substeps_out = &mut substeps;
        let controller = &mut self.controller;
        let (solver, packed) = (&mut self.solver, &mut self.packed);
        let (world, found) = (&self.world, &mut self.contained);
        let auditor = &mut self.auditor;
        let law = crate::audit::DamperLaw::of(self.config.integrator);
        let coupling_ref = &mut coupling;
        let audit_out = &mut audit_time;
        let contacts_time = &mut contacts;
        // The strain check reads the frame's end state inside the same rayon job.
        let check = self.config.strain_limit.is_finite();
        let limit = self.config.strain_limit;
        let mut beyond = None;
        let beyond_out = &mut beyond;
        let gravity = self.config.gravity;
        let dt = self.config.dt;
        let mut end = None;
        let end_out = &mut end;
        let integrate = move || {
            let coupling = coupling_ref;
            let damping = auditor.frame.damping;
            let mut h = h;
            loop {
                (1..=*substeps_out).try_for_each(|k| {
                    if let Some(c) = coupling.as_mut() {
                        let t = Instant::now();
                        c.begin_substep(packed);
                        *contacts_time += t.elapsed();
                    }
                    let t = Instant::now();
                    auditor.begin_substep(packed);
                    let t = t.elapsed();
                    solver.substep(packed, h)?;
                    let u = Instant::now();
                    auditor.damping(packed, law, h, solver.grid_damper_loss());
                    *audit_out += t + u.elapsed();
                    if let Some(c) = coupling.as_mut() {
                        let t = Instant::now();
                        c.substep(packed, h, k);
                        *contacts_time += t.elapsed();
                    }
                    if contain(packed, world, found) {
                        if let Some(c) = coupling.as_mut() {
                            c.moved();
                        }
                    }
                    Ok::<(), SimError>(())
                })?;
                let t = Instant::now();
                let e = auditor.energy(packed, gravity);
                *end_out = Some(e);
                *audit_out += t.elapsed();
                if !retry || !found.is_empty() {
                    break;
                }
                let f = &auditor.frame;
                let before = auditor.run.residual;
                let after = before + (e - f.start - f.edits + f.damping);
                let Some(more) = controller.rejects(*substeps_out, before, after, tol) else {
                    break;
                };
                controller.restore_start(packed);
                auditor.frame.damping = damping;
                *substeps_out = more;
                h = dt / more as f64;
                solver.prepare(packed, h)?;
            }
            if check {
                *beyond_out = Some(crate::metrics::beyond(packed, limit));
            }
            Ok::<(), SimError>(())
        };
        if self.parallel {
            // One rayon job per frame: the passes inside run from a worker's own deque, so
            // the only allocation is the injector's queue block, recycled every 63 frames.
            rayon::scope(|_| integrate())?;
        } else {
            integrate()?;
        }
        self.config.substeps = substeps;
        let projections = coupling.map(|mut c| c.stage().energy).unwrap_or_default();
        self.finish_frame(
            t0,
            t1,
            gathered,
            (contacts, audit_time),
            beyond,
            (end, projections),
        )?;
        // The motion check: begun after its frame, its second run advanced a share after
        // each frame that follows.
        let t = Instant::now();
        let probed = self.advance_probe()?;
        if probing {
            self.begin_probe(substeps);
        }
        self.stats.integrate += t.elapsed();
        self.adapt(probed);
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
    /// [`contain`]), the energy books, then the scatter and the checks (`beyond`: the strain
    /// check's answer and `end` the energy, when the integrate stage already took them).
    pub(super) fn finish_frame(
        &mut self,
        t0: Instant,
        t1: Instant,
        gathered: bool,
        (contacts, audit_time): (Duration, Duration),
        beyond: Option<bool>,
        (end, projections): (Option<f64>, crate::audit::ProjectionLines),
    ) -> Result<&StepStats, SimError> {
        let t2 = Instant::now();
        self.quarantine();
        self.steps += 1;
        self.time += self.config.dt;
        let quarantined = std::mem::take(&mut self.newly_quarantined);
        let t = Instant::now();
        let end = end.unwrap_or_else(|| self.auditor.energy(&self.packed, self.config.gravity));
        let late = t.elapsed();
        self.auditor.end_frame(end, projections, quarantined > 0);
        self.packed.scatter(&mut self.world);
        let failure = self.check_strain(beyond).or_else(|| self.check_energy());
        self.failure = self.failure.or(failure);
        let t3 = Instant::now();
        self.stats = StepStats {
            gather: t1 - t0,
            integrate: (t2 - t1).saturating_sub(contacts + audit_time),
            contacts,
            audit_time: audit_time + late,
            scatter: (t3 - t2).saturating_sub(late),
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
    fn check_strain(&self, beyond: Option<bool>) -> Option<crate::Failure> {
        let limit = self.config.strain_limit;
        if !limit.is_finite() {
            return None;
        }
        if !beyond.unwrap_or_else(|| crate::metrics::beyond(&self.packed, limit)) {
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
            gpu.upload(&self.packed, lin, c.gravity, c.h(), c.integrator)?;
        }
        #[cfg(feature = "gpu")]
        self.device_contacts()?;
        self.dirty = false;
        Ok(())
    }
}
