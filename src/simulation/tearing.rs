//! The tearing stage's frame end on the World ([`crate::tear`]): the broken springs and their
//! triangles gone, the game's events, the next frame's gather.

use super::*;

impl Simulation {
    /// After the frame's scatter: the breaks the tearing stage found, into the World.
    pub(super) fn tear_apart(&mut self) {
        self.torn.clear();
        if self.tear.broken.is_empty() {
            return;
        }
        let mut breaks = Vec::with_capacity(self.tear.broken.len());
        let openings = self.tear.apply(&mut self.world, &self.packed, &mut breaks);
        // The particles the game holds (grabbed, or pinned by a drive): their copies go free.
        let held: Vec<Entity> = (self.grabbed.iter().copied())
            .chain(self.drives.pinned_here())
            .collect();
        // Last cloth first: each one's new particles go after its own, moving the later ones.
        for o in openings.into_iter().rev() {
            let (end, added) = (o.first + o.count, o.added());
            if added > 0 {
                self.opened = true;
                self.renumber(end, added as i64);
                for b in &mut breaks {
                    if b.1 >= end {
                        (b.1, b.2) = (b.1 + added, b.2 + added);
                    }
                }
            }
            o.carry_out(&mut self.world, &self.packed.topology.entities, &held);
        }
        let step = self.steps - 1;
        for (e, a, b) in breaks {
            if let Some(&(cloth, _)) = self.cloths.iter().find(|c| c.1 == e) {
                let (a, b) = (a as usize, b as usize);
                self.torn.push(crate::Tear { cloth, a, b, step });
            }
        }
        self.tear.broken.clear();
        // The next step gathers the new topology; the surfaces' triangles are made again.
        self.dirty = true;
        self.frame.triangles.take();
        if self.opened {
            // The last positions no longer line up with the particles.
            self.frame.prev.clear();
        }
    }

    /// After a frame whose tear added particles: the buffers gathered at once, so what the
    /// game reads before the next step (positions, triangles) agrees; the next frame's books
    /// take `E` afresh, the change booked as edits. A failed gather is left to the next step.
    pub(super) fn gather_opened(&mut self) {
        if std::mem::take(&mut self.opened) {
            match self.gather() {
                Ok(()) => self.state_edited = true,
                Err(_) => self.dirty = true,
            }
        }
    }

    /// The springs that broke in the last frame ([`crate::Tearing`]), in the springs' order:
    /// each one's cloth and ends. Empty after a frame without a break. A frame that tears
    /// may add particles where the surface opens (see [`crate::Tearing`]): they come
    /// after their cloth's particles, later particles move up in scene order, and
    /// [`Self::positions`] and [`Self::triangles`] have them when the step returns.
    pub fn torn(&self) -> &[crate::Tear] {
        &self.torn
    }

    /// Self-collision's candidates ([`crate::SelfCollision`]): the candidate pairs of the
    /// last substep, and the times the candidates were found since the scene was last gathered (at
    /// the first frame, and again where particles near each other moved apart past the
    /// margin, at a frame's start or within it; 0 without a colliding cloth).
    pub fn collision_pairs(&self) -> (usize, u64) {
        self.collide.pair_count()
    }

    /// With the springs on the GPU, self-collision's candidates against triangles are found
    /// there.
    #[cfg(feature = "gpu")]
    pub(super) fn device_collide(&mut self) -> Result<(), SimError> {
        let Some(gpu) = &self.gpu else {
            return Ok(());
        };
        if self.collide.is_empty() {
            return Ok(());
        }
        self.collide.enable_device(gpu.shared_context())?;
        // The pass too where asked, unless the host's contact stage runs (its touches weigh
        // the pushes).
        let host_contacts = match &self.props {
            Some(_) => !gpu.has_contacts(),
            None => self.user_stage.is_some(),
        };
        if self.config.device_collide_pass && self.collide.pass_fits_device() && !host_contacts {
            let settles = crate::collide::VELOCITY_PASSES as u32 - 1;
            let n = self.packed.particle_count() as u32;
            if let Some(pass) = gpu.collide_pass(n, settles)? {
                self.collide.enable_device_pass(pass);
            }
        }
        Ok(())
    }
}
