//! Coupling with rigid bodies: the scene's own rapier world or the caller's sets, on the CPU or the device.

use super::*;

/// The rigid side a frame couples with: the scene's own rapier world, or the caller's sets.
pub(super) enum Coupling<'a> {
    Own(&'a mut Props),
    User {
        stage: &'a mut ContactStage,
        bodies: &'a mut RigidBodySet,
        colliders: &'a ColliderSet,
    },
}

impl Coupling<'_> {
    pub(super) fn begin_frame(&mut self, substeps: u32) {
        match self {
            Coupling::Own(p) => p.begin_frame(substeps),
            Coupling::User { stage, .. } => stage.begin_frame(),
        }
    }

    pub(super) fn begin_substep(&mut self, packed: &Packed) {
        self.stage().begin_substep(packed);
    }

    /// Particles were moved outside the stages (the quarantine restored some).
    pub(super) fn moved(&mut self) {
        self.stage().moved();
    }

    pub(super) fn stage(&mut self) -> &mut ContactStage {
        match self {
            Coupling::Own(p) => p.stage_mut(),
            Coupling::User { stage, .. } => stage,
        }
    }

    /// After the integrate stage of substep `k` (1-based).
    pub(super) fn substep(&mut self, packed: &mut Packed, h: f64, k: u32) {
        match self {
            Coupling::Own(p) => p.substep(packed, h),
            Coupling::User {
                stage,
                bodies,
                colliders,
            } => stage.substep(packed, bodies, colliders, k as f64 * h, h),
        }
    }
}

impl Simulation {
    /// With the springs on the GPU and colliders the device stage takes (balls and cuboids,
    /// no attachments), contacts run there too; otherwise on the CPU, with the state read back
    /// every substep.
    #[cfg(feature = "gpu")]
    pub(super) fn device_contacts(&mut self) -> Result<(), SimError> {
        let (Some(gpu), Some(p)) = (&mut self.gpu, &self.props) else {
            return Ok(());
        };
        if !p.device_ready() {
            return Ok(());
        }
        let masses = p.device_masses(&self.packed);
        let c = p.contact();
        gpu.enable_contacts(&crate::gpu::contacts::ContactSetup {
            masses: &masses,
            colliders: p.colliders().len(),
            slots: self.config.substeps,
            h: self.config.h(),
            thickness: c.thickness,
            restitution: c.restitution,
        })?;
        Ok(())
    }

    /// With the springs on the GPU, the tethers' clamp runs there too (their frame-end
    /// placing on the host, where the state comes back).
    #[cfg(feature = "gpu")]
    pub(super) fn device_tethers(&mut self) -> Result<(), SimError> {
        use crate::gpu::tethers::{Link, Part, TetherSetup};
        let Some(gpu) = &mut self.gpu else {
            return Ok(());
        };
        if self.tethers.is_empty() {
            return Ok(());
        }
        let (mut parts, mut links) = (Vec::<Part>::new(), Vec::new());
        for (i, anchor, limit) in self.tethers.links() {
            match parts.last_mut() {
                Some(p) if p.particle == i => p.count += 1,
                _ => parts.push(Part {
                    particle: i,
                    first: links.len() as u32,
                    count: 1,
                    _pad: 0,
                }),
            }
            links.push(Link {
                anchor,
                limit: limit as f32,
            });
        }
        gpu.enable_tethers(&TetherSetup {
            parts: &parts,
            links: &links,
            gravity: self.config.gravity,
            h: self.config.h(),
        })?;
        Ok(())
    }

    /// Whether the contact stage runs on the GPU.
    pub fn contacts_on_gpu(&mut self) -> bool {
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &mut self.gpu {
            return gpu.contacts().is_some();
        }
        false
    }

    /// What the contact stage did in the last frame (None when the simulation has never
    /// coupled with bodies).
    pub fn contact_stats(&self) -> Option<&ContactStats> {
        match (&self.props, &self.user_stage) {
            (Some(p), _) => Some(p.stats()),
            (None, Some(s)) => Some(&s.stats),
            (None, None) => None,
        }
    }

    /// The cloth's contact material against the caller's sets ([`Self::step_with`]); a scene's
    /// own bodies use the scene's `contact`.
    pub fn set_contact_material(&mut self, contact: ContactMaterial) {
        self.contact = contact;
        if let Some(s) = &mut self.user_stage {
            s.contact = contact;
        }
    }
}
