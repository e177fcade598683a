//! The game's per-particle forces: a force stage whose `F/m`, summed with gravity once a frame,
//! the integrate kernel reads where it reads gravity.

use super::*;

/// The forces the game set and the external acceleration they give.
#[derive(Debug, Default)]
pub(super) struct Forces {
    /// Newtons per particle, in scene (packed) order.
    pub(super) given: Vec<DVec3>,
    /// `g + F/m` per particle, made at each frame's start (pinned particles: `g`, unread).
    pub(super) accel: Vec<DVec3>,
}

impl Forces {
    /// The frame's external accelerations from `given`, `gravity` and the masses.
    pub(super) fn prepare(&mut self, packed: &Packed, gravity: DVec3) {
        self.accel.resize(self.given.len(), DVec3::ZERO);
        let inv = &packed.inv_mass;
        for ((a, f), &w) in self.accel.iter_mut().zip(&self.given).zip(inv) {
            *a = gravity + *f * w;
        }
    }
}

impl Simulation {
    /// Sets a force (N) on every particle, in scene order, held for every frame until it is
    /// set again or [`Self::clear_forces`] is called: a force stage adds `F/m` to gravity once
    /// a frame, and the integrators read that sum where they read gravity (no extra pass
    /// inside the substeps). The energy audit books the forces' work
    /// ([`crate::EnergyAudit::forces`]). Pinned particles ignore theirs. Allocates only the
    /// first time (and when the particle count grows); the forces are dropped when the
    /// particle count changes (a cloth added or removed, a World edited), so set them again
    /// then.
    ///
    /// Errors: [`SimError::ForceCount`] when `forces` does not have one force per particle,
    /// [`SimError::BadForce`] naming the first non-finite one; nothing is changed then.
    pub fn set_forces(&mut self, forces: &[DVec3]) -> Result<(), SimError> {
        // The World's count: an edit since the last step (a cloth added) is gathered next.
        let particles = if self.dirty {
            self.world.query::<&crate::Particle>().iter().count()
        } else {
            self.packed.particle_count()
        };
        if forces.len() != particles {
            return Err(SimError::ForceCount {
                given: forces.len(),
                particles,
            });
        }
        if let Some(index) = forces.iter().position(|f| !f.is_finite()) {
            return Err(SimError::BadForce {
                index,
                force: forces[index].to_array(),
            });
        }
        self.device_needs_forces(true);
        let f = self.forces.get_or_insert_with(Default::default);
        f.given.clear();
        f.given.extend_from_slice(forces);
        Ok(())
    }

    /// Removes the game's forces: the force stage leaves the schedule.
    pub fn clear_forces(&mut self) {
        self.device_needs_forces(false);
        self.forces = None;
    }

    /// The device's kernels are specialised to the force stage's presence: a change re-uploads
    /// at the next step.
    #[cfg_attr(not(feature = "gpu"), allow(unused_variables))]
    fn device_needs_forces(&mut self, listed: bool) {
        #[cfg(feature = "gpu")]
        if self.gpu.is_some() && self.forces.is_some() != listed {
            self.dirty = true;
        }
    }

    /// The forces set by [`Self::set_forces`] (N, scene order), if any.
    pub fn forces(&self) -> Option<&[DVec3]> {
        self.forces.as_ref().map(|f| &f.given[..])
    }

    /// Forces set for another particle count are dropped (see [`Self::set_forces`]).
    pub(super) fn drop_stale_forces(&mut self) {
        let n = self.packed.particle_count();
        if self.forces.as_ref().is_some_and(|f| f.given.len() != n) {
            self.forces = None;
        }
    }
}
