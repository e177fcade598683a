//! The game's per-particle forces and the air's: force stages whose `F/m`, summed with gravity
//! once a frame, the integrate kernel reads where it reads gravity.

use super::*;

/// The external forces of a frame: the game's, the air's, and the acceleration they give.
#[derive(Debug, Default)]
pub(super) struct Forces {
    /// The game's forces (N, scene order); empty while it has set none.
    pub(super) given: Vec<DVec3>,
    /// The air's, made at each frame's start; empty without air.
    pub(super) air: Vec<DVec3>,
    /// What acts over the frame, `given + air`: what the audit books the work of.
    pub(super) total: Vec<DVec3>,
    /// `g + F/m` per particle, made at each frame's start (pinned particles: `g`, unread).
    pub(super) accel: Vec<DVec3>,
}

impl Forces {
    /// The frame's total forces and external accelerations from `given`, `air`, `gravity` and
    /// the masses.
    pub(super) fn prepare(&mut self, packed: &Packed, gravity: DVec3) {
        let n = packed.particle_count();
        self.total.clear();
        self.total.resize(n, DVec3::ZERO);
        for part in [&self.given, &self.air] {
            for (t, f) in self.total.iter_mut().zip(part) {
                *t += *f;
            }
        }
        self.accel.resize(n, DVec3::ZERO);
        let inv = &packed.inv_mass;
        for ((a, f), &w) in self.accel.iter_mut().zip(&self.total).zip(inv) {
            *a = gravity + *f * w;
        }
    }

    /// Whether the game set forces.
    pub(super) fn game(&self) -> bool {
        !self.given.is_empty()
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

    /// Removes the game's forces: the force stage leaves the schedule (the air stays).
    pub fn clear_forces(&mut self) {
        let air = !self.air.is_empty();
        self.device_needs_forces(air);
        match (&mut self.forces, air) {
            (Some(f), true) => f.given.clear(),
            _ => self.forces = None,
        }
    }

    /// Sets the wind the cloths with air feel from the next frame on ([`crate::Wind`]; the
    /// scene's `wind`). Errors: [`SimError::BadWind`] naming the field, nothing changed.
    pub fn set_wind(&mut self, wind: crate::Wind) -> Result<(), SimError> {
        wind.check().map_err(SimError::BadWind)?;
        self.config.wind = wind;
        Ok(())
    }

    /// The cloths' air and the force stage it needs, after a gather: each cloth with an
    /// [`crate::Aero`] adds its triangles (scene order).
    pub(super) fn gather_air(&mut self) {
        let mut cloths: Vec<(u32, Vec<[u32; 3]>, crate::Aero)> = Vec::new();
        for (grid, aero) in self
            .world
            .query::<(&crate::ClothSprings, &crate::Aero)>()
            .iter()
        {
            let mut t = Vec::new();
            grid.grid.triangles(&mut t);
            cloths.push((grid.grid.first, t, *aero));
        }
        for (e, (surface, aero)) in self
            .world
            .query::<(hecs::Entity, (&crate::MeshSurface, &crate::Aero))>()
            .iter()
        {
            let mut t = Vec::new();
            crate::MeshSurface::all_of(&self.world, e, &mut t);
            cloths.push((surface.first, t, *aero));
        }
        cloths.sort_unstable_by_key(|c| c.0);
        self.air = crate::air::AirSurfaces::default();
        for (_, t, aero) in cloths {
            self.air.push(t, aero);
        }
        let n = self.packed.particle_count();
        if self.air.is_empty() {
            if let Some(f) = &mut self.forces {
                f.air.clear();
            }
            if self.forces.as_ref().is_some_and(|f| !f.game()) {
                self.forces = None;
            }
        } else {
            let f = self.forces.get_or_insert_with(Default::default);
            f.air.resize(n, DVec3::ZERO);
        }
    }

    /// The air stage, once a frame: the air's forces at the frame's start state. On the
    /// device when the springs run there: its passes start the frame's first submit and add
    /// their share to the accelerations there; their forces come back with the state (until
    /// then the frame's books hold none, and no force's work is booked before the state comes
    /// back).
    pub(super) fn blow(&mut self) {
        if let Some(f) = self.forces.as_mut().filter(|_| !self.air.is_empty()) {
            #[cfg(feature = "gpu")]
            if let Some(gpu) = self.gpu.as_mut().filter(|g| g.has_air()) {
                f.air.fill(DVec3::ZERO);
                gpu.begin_air(&self.config.wind.field(self.time));
                return;
            }
            let p = &self.packed;
            self.air
                .forces(&p.x, &p.v, &self.config.wind, self.time, &mut f.air);
        }
    }

    /// With the springs on the GPU, the air's passes run there too.
    #[cfg(feature = "gpu")]
    pub(super) fn device_air(&mut self) -> Result<(), SimError> {
        let Some(gpu) = &mut self.gpu else {
            return Ok(());
        };
        if self.air.is_empty() {
            return Ok(());
        }
        let (triangles, cloths) = self.air.parts();
        let n = self.packed.particle_count();
        gpu.enable_air(&crate::gpu::air::AirSetup::new(triangles, cloths, n))?;
        Ok(())
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
        self.forces
            .as_ref()
            .filter(|f| f.game())
            .map(|f| &f.given[..])
    }

    /// Forces set for another particle count are dropped (see [`Self::set_forces`]).
    pub(super) fn drop_stale_forces(&mut self) {
        let n = self.packed.particle_count();
        if let Some(f) = &mut self.forces {
            if f.given.len() != n {
                f.given.clear();
            }
            if !f.game() && f.air.is_empty() {
                self.forces = None;
            }
        }
    }
}
