//! The contact stage on the device (`shaders/contacts.wgsl`): which scenes it takes, the
//! colliders it is given each substep, and the partial sums it hands back.

use super::*;
use crate::gpu::contacts::{Collider, Partial, MAX_COLLIDERS};
use rapier3d::parry::shape::ShapeType;

impl Props {
    /// The device can run this scene's contacts: balls and cuboids only, at most
    /// [`MAX_COLLIDERS`], and no attachments. Otherwise the CPU runs them.
    pub fn device_ready(&self) -> bool {
        let colliders = &self.physics.colliders;
        colliders.len() <= MAX_COLLIDERS
            && self.stage.attached.is_empty()
            && colliders
                .iter()
                .all(|(_, c)| matches!(c.shape().shape_type(), ShapeType::Ball | ShapeType::Cuboid))
    }

    /// Per packed particle, the mass the device stage uses: 0 for pinned or attached.
    pub fn device_masses(&self, packed: &Packed) -> Vec<f32> {
        packed
            .inv_mass
            .iter()
            .enumerate()
            .map(|(i, &w)| {
                let m = packed.mass(i);
                let held = self.stage.held.get(i).copied().unwrap_or(false);
                if w == 0.0 || held {
                    0.0
                } else {
                    m as f32
                }
            })
            .collect()
    }

    /// The colliders as they stand (after `step_bodies`), in the CPU stage's order
    /// and with its motions and friction (`ContactStage::collect`); the stage keeps them to
    /// know which body each partial pushes.
    pub fn device_colliders(&mut self, out: &mut Vec<Collider>) {
        let (bodies, colliders) = (&self.physics.bodies, &self.physics.colliders);
        self.stage.collect(bodies, colliders, 0.0);
        out.clear();
        out.extend(self.stage.candidates.iter().map(|cand| {
            let (kind, dims) = match (cand.shape.as_ball(), cand.shape.as_cuboid()) {
                (Some(b), _) => (0, Vec3::new(b.radius, 0.0, 0.0)),
                (None, Some(b)) => (1, b.half_extents),
                (None, None) => (1, Vec3::ZERO),
            };
            let f = |v: DVec3, w: f64| v.as_vec3().extend(w as f32).to_array();
            let q = cand.pose.rotation;
            Collider {
                kind,
                dynamic: u32::from(cand.dynamic),
                translation: cand.pose.translation.extend(0.0).to_array(),
                rotation: [q.x, q.y, q.z, q.w],
                dims: dims.extend(0.0).to_array(),
                lin: f(cand.lin, cand.mu_s),
                ang: f(cand.ang, cand.mu_k),
                com: f(cand.com, cand.mass),
                sphere: f(cand.centre, cand.reach),
                ..Collider::default()
            }
        }));
    }

    /// One substep's partials (`[workgroup][collider]`), summed in workgroup order, into
    /// the statistics and onto the dynamic bodies.
    pub fn apply_device(&mut self, partials: &[Partial], groups: usize, colliders: usize) {
        let stage = &mut self.stage;
        for (ci, cand) in stage.candidates.iter().enumerate() {
            let mut total = Exchange::default();
            for g in 0..groups {
                let p = &partials[g * colliders + ci];
                let v = |a: [f32; 4]| DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64);
                total.add(&Exchange {
                    contacts: p.impulse[3] as usize,
                    swept: p.support_torque[3] as usize,
                    max_depth: p.torque[3] as f64,
                    impulse: v(p.impulse),
                    torque: v(p.torque),
                    supports: p.support[3] as usize,
                    support: v(p.support),
                    support_torque: v(p.support_torque),
                });
            }
            // The work the collider's motion did on the cloth, `−(J·v + L·ω)` with `J`, `L` the
            // impulse and angular impulse on the body about its centre of mass: what the books
            // can read of the device's contacts (their own dissipation is left in the residual,
            // where it is negative).
            let k = total.supports.max(1) as f64;
            let (j, l) = (
                total.impulse + total.support / k,
                total.torque + total.support_torque / k,
            );
            if total.contacts > 0 {
                stage.energy.contacts += j.dot(cand.lin) + l.dot(cand.ang);
            }
            let body = cand.body.filter(|_| cand.dynamic);
            apply(&mut stage.stats, &mut self.physics.bodies, body, &total);
        }
    }
}
