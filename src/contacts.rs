//! Rigid props: the rapier world a scene's bodies live in, the contact stage that keeps
//! particles outside colliders, and attachments of particles to bodies.
//!
//! Per substep, after the integrate stage:
//! 1. rapier steps the bodies by `h` (only when some body can move);
//! 2. attachments put their particles at their body points, at the body's point velocity;
//! 3. contacts: each particle within `thickness` of a collider (or whose path this substep
//!    crossed one) goes back to the surface plus `thickness`; its normal velocity into the
//!    collider is removed (restitution `e` keeps `e` of it) and its tangential velocity obeys
//!    Coulomb friction, static then kinetic.
//!
//! Steps 2 and 3 change particle momenta by `J`; a dynamic body receives `−J` at the contact
//! point, so cloth and bodies exchange momentum exactly (two-way coupling). Candidate colliders
//! come from a broad phase on bounding boxes (the cloth's box against each collider's, then each
//! particle against its candidates'); the contact itself is parry's shape projection, and a ray
//! cast along the particle's path catches particles that would tunnel through thin shapes.

use glam::{DVec3, Vec3};
use hecs::{Entity, World};
use rapier3d::parry::bounding_volume::BoundingVolume;
use rapier3d::parry::query::Ray;
use rapier3d::prelude::{
    Collider, ColliderBuilder, ColliderHandle, PhysicsWorld, RigidBodyBuilder, RigidBodyHandle,
    RigidBodySet,
};
use rayon::prelude::*;

use crate::buffers::Packed;
use crate::scene::props::{BodyDef, BodyKind, ContactDef, Shape};

/// A body of the scene, as an ECS component on its own entity (the rapier handles stay opaque:
/// the sets live in [`Props`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RigidProp {
    pub body: RigidBodyHandle,
    pub collider: ColliderHandle,
}

/// On a particle: it is held at `local` (body frame) of `body`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Attachment {
    pub body: RigidBodyHandle,
    pub local: Vec3,
}

/// What the contact stage did in the last frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactStats {
    /// Particle–collider contacts resolved, summed over substeps.
    pub contacts: usize,
    /// Deepest any particle got inside a collider before being pushed out (m).
    pub max_depth: f64,
    /// Particles caught by the swept test (their path crossed a collider's surface).
    pub swept: usize,
    /// Total impulse given to dynamic bodies by contacts and attachments (N·s).
    pub impulse_on_bodies: DVec3,
}

/// The rigid side of a scene: rapier's world and the cloth's contact material.
pub struct Props {
    pub physics: PhysicsWorld,
    pub contact: ContactDef,
    /// Some body can move: rapier steps each substep.
    pub moving: bool,
    /// Some body is dynamic: impulses go back to bodies.
    pub dynamic: bool,
    /// Attached particles as packed indices, refreshed at gather.
    attached: Vec<(usize, Attachment)>,
    /// Positions at the start of the substep (for the swept test).
    prev: Vec<DVec3>,
    /// Colliders near the cloth this substep, with their boxes grown by the thickness.
    candidates: Vec<(ColliderHandle, DVec3, DVec3)>,
    pub stats: ContactStats,
}

fn v3(v: [f64; 3]) -> Vec3 {
    DVec3::from(v).as_vec3()
}

/// The rapier collider of a shape, or why the shape is unusable.
pub fn collider_of(shape: &Shape) -> Result<ColliderBuilder, String> {
    Ok(match shape {
        Shape::Ball { radius } => ColliderBuilder::ball(*radius as f32),
        Shape::Cuboid { half_extents: h } => {
            ColliderBuilder::cuboid(h[0] as f32, h[1] as f32, h[2] as f32)
        }
        Shape::Capsule {
            half_height,
            radius,
        } => ColliderBuilder::capsule_y(*half_height as f32, *radius as f32),
        Shape::Cylinder {
            half_height,
            radius,
        } => ColliderBuilder::cylinder(*half_height as f32, *radius as f32),
        Shape::ConvexHull { points } => {
            let pts: Vec<Vec3> = points.iter().map(|p| v3(*p)).collect();
            ColliderBuilder::convex_hull(&pts).ok_or("the points span no volume")?
        }
        Shape::TriMesh { vertices, indices } => {
            ColliderBuilder::trimesh(vertices.iter().map(|p| v3(*p)).collect(), indices.clone())
                .map_err(|e| e.to_string())?
        }
        Shape::HeightField { heights, scale } => {
            let rows = heights.len();
            let cols = heights.first().map_or(0, Vec::len);
            // parry's Array2 is column-major.
            let mut data = Vec::with_capacity(rows * cols);
            for c in 0..cols {
                for row in heights {
                    data.push(row[c] as f32);
                }
            }
            ColliderBuilder::heightfield(
                rapier3d::parry::utils::Array2::new(rows, cols, data),
                v3(*scale),
            )
        }
    })
}

impl Props {
    /// The rapier world of `bodies`, each also spawned into `world` as a [`RigidProp`] entity.
    /// Shapes must have passed scene validation.
    pub fn build(
        bodies: &[BodyDef],
        contact: ContactDef,
        gravity: DVec3,
        world: &mut World,
    ) -> Result<(Props, Vec<RigidBodyHandle>), String> {
        let mut physics = PhysicsWorld::new();
        physics.gravity = gravity.as_vec3();
        let mut handles = Vec::with_capacity(bodies.len());
        for (i, b) in bodies.iter().enumerate() {
            let builder = match b.kind {
                BodyKind::Fixed => RigidBodyBuilder::fixed(),
                BodyKind::Dynamic => RigidBodyBuilder::dynamic(),
                BodyKind::Kinematic => RigidBodyBuilder::kinematic_velocity_based(),
            }
            .translation(v3(b.position))
            .rotation(v3(b.rotation))
            .linvel(v3(b.velocity))
            .angvel(v3(b.angular_velocity));
            let body = physics.bodies.insert(builder);
            let mut co = collider_of(&b.shape)
                .map_err(|e| format!("bodies[{i}].shape: {e}"))?
                .friction(b.friction as f32)
                .restitution(b.restitution as f32);
            co = match (b.mass, b.density) {
                (Some(m), _) => co.mass(m as f32),
                (None, Some(d)) => co.density(d as f32),
                (None, None) => co.density(1000.0),
            };
            let collider = physics
                .colliders
                .insert_with_parent(co, body, &mut physics.bodies);
            world.spawn((RigidProp { body, collider },));
            handles.push(body);
        }
        let moving = bodies.iter().any(|b| b.kind != BodyKind::Fixed);
        let dynamic = bodies.iter().any(|b| b.kind == BodyKind::Dynamic);
        Ok((
            Props {
                physics,
                contact,
                moving,
                dynamic,
                attached: Vec::new(),
                prev: Vec::new(),
                candidates: Vec::new(),
                stats: ContactStats::default(),
            },
            handles,
        ))
    }

    /// After a gather: the attached particles' packed indices.
    pub fn gather(&mut self, world: &World, packed: &Packed) {
        self.attached.clear();
        for (e, a) in world.query::<(Entity, &Attachment)>().iter() {
            if let Some(i) = packed.index_of(e) {
                self.attached.push((i, *a));
            }
        }
        self.attached.sort_by_key(|(i, _)| *i);
    }

    /// Entities of attached particles whose body no longer exists.
    pub fn dangling(&self, world: &World) -> Option<Entity> {
        world
            .query::<(Entity, &Attachment)>()
            .iter()
            .find(|(_, a)| !self.physics.bodies.contains(a.body))
            .map(|(e, _)| e)
    }

    /// Call before each substep's integrate: remembers where particles start.
    pub fn begin_substep(&mut self, packed: &Packed) {
        self.prev.clear();
        self.prev.extend_from_slice(&packed.x);
    }

    /// The frame's statistics start again.
    pub fn begin_frame(&mut self) {
        self.stats = ContactStats::default();
    }

    /// Steps 1–3 of the module docs, after the integrate stage of one substep.
    pub fn substep(&mut self, packed: &mut Packed, h: f64) {
        if self.moving {
            self.physics.integration_parameters.dt = h as f32;
            self.physics.step();
        }
        self.attach(packed);
        self.contacts(packed);
    }

    fn attach(&mut self, packed: &mut Packed) {
        let bodies = &mut self.physics.bodies;
        for &(i, a) in &self.attached {
            let Some(body) = bodies.get_mut(a.body) else {
                continue;
            };
            let target = body.position().transform_point(a.local);
            let vb = body.velocity_at_point(target).as_dvec3();
            let m = packed.mass[i];
            if m.is_finite() && body.is_dynamic() {
                let j = m * (vb - packed.v[i]);
                body.apply_impulse_at_point(-j.as_vec3(), target, true);
                self.stats.impulse_on_bodies -= j;
            }
            packed.x[i] = target.as_dvec3();
            packed.v[i] = vb;
        }
    }

    fn contacts(&mut self, packed: &mut Packed) {
        let c = self.contact;
        let margin = c.thickness as f32;
        // Broad phase, coarse: colliders whose box meets the box of every particle path.
        let Some(cloth_box) = bounds(&packed.x, &self.prev) else {
            return;
        };
        self.candidates.clear();
        for (handle, co) in self.physics.colliders.iter() {
            let b = co.compute_aabb().loosened(margin);
            if b.mins.cmple(cloth_box.1).all() && b.maxs.cmpge(cloth_box.0).all() {
                self.candidates
                    .push((handle, b.mins.as_dvec3(), b.maxs.as_dvec3()));
            }
        }
        if self.candidates.is_empty() {
            return;
        }
        let (colliders, bodies) = (&self.physics.colliders, &mut self.physics.bodies);
        for &(handle, lo, hi) in &self.candidates {
            let co = &colliders[handle];
            let mu_s = 0.5 * (c.friction + co.friction() as f64);
            let mu_k = (0.5 * (c.kinetic_friction + co.friction() as f64)).min(mu_s);
            let body = co.parent().and_then(|p| bodies.get(p));
            let dynamic = body.is_some_and(|b| b.is_dynamic());
            let com = body.map_or(Vec3::ZERO, |b| b.center_of_mass()).as_dvec3();
            let prev = &self.prev;
            let Packed {
                x,
                v,
                inv_mass,
                mass,
                ..
            } = packed;
            let (inv_mass, mass) = (&inv_mass[..], &mass[..]);
            // Particles in fixed chunks, each summing its impulses on the body, then the sums in
            // chunk order: the same result whatever the thread count.
            let sums: Vec<Exchange> = x
                .par_chunks_mut(CHUNK)
                .zip(v.par_chunks_mut(CHUNK))
                .enumerate()
                .map(|(k, (xs, vs))| {
                    let mut sum = Exchange::default();
                    for (j, (xi, vi)) in xs.iter_mut().zip(vs.iter_mut()).enumerate() {
                        let i = k * CHUNK + j;
                        if inv_mass[i] == 0.0 {
                            continue;
                        }
                        let (x0, x1) = (prev[i], *xi);
                        // Broad phase, fine: this particle's path against this collider's box.
                        if x0.min(x1).cmpgt(hi).any() || x0.max(x1).cmplt(lo).any() {
                            continue;
                        }
                        let Some(hit) = surface(co, x0, x1, c.thickness) else {
                            continue;
                        };
                        sum.contacts += 1;
                        sum.max_depth = sum.max_depth.max(hit.depth);
                        sum.swept += usize::from(hit.swept);
                        *xi = hit.point + hit.normal * c.thickness;
                        let vb = body.map_or(DVec3::ZERO, |b| {
                            b.velocity_at_point(hit.point.as_vec3()).as_dvec3()
                        });
                        let old = *vi;
                        let rel = old - vb;
                        let vn = rel.dot(hit.normal);
                        if vn >= 0.0 {
                            continue;
                        }
                        let dvn = -(1.0 + c.restitution) * vn;
                        let vt = rel - vn * hit.normal;
                        let speed = vt.length();
                        let vt = if speed <= mu_s * dvn {
                            DVec3::ZERO
                        } else {
                            vt * (1.0 - mu_k * dvn / speed).max(0.0)
                        };
                        *vi = vb + (vn + dvn) * hit.normal + vt;
                        if dynamic {
                            // The body gets −J at the contact point: force and torque.
                            let j = mass[i] * (*vi - old);
                            sum.impulse -= j;
                            sum.torque -= (hit.point - com).cross(j);
                        }
                    }
                    sum
                })
                .collect();
            let mut total = Exchange::default();
            for s in &sums {
                total.contacts += s.contacts;
                total.swept += s.swept;
                total.max_depth = total.max_depth.max(s.max_depth);
                total.impulse += s.impulse;
                total.torque += s.torque;
            }
            self.stats.contacts += total.contacts;
            self.stats.swept += total.swept;
            self.stats.max_depth = self.stats.max_depth.max(total.max_depth);
            if dynamic && total.contacts > 0 {
                if let Some(b) = co.parent().and_then(|p| bodies.get_mut(p)) {
                    b.apply_impulse(total.impulse.as_vec3(), true);
                    b.apply_torque_impulse(total.torque.as_vec3(), true);
                }
                self.stats.impulse_on_bodies += total.impulse;
            }
        }
    }

    pub fn bodies(&self) -> &RigidBodySet {
        &self.physics.bodies
    }
}

/// Particles per parallel task of the contact stage.
const CHUNK: usize = 1024;

/// What one chunk of particles did against one collider.
#[derive(Clone, Copy, Default)]
struct Exchange {
    contacts: usize,
    swept: usize,
    max_depth: f64,
    /// Impulse and angular impulse (about the centre of mass) on the body.
    impulse: DVec3,
    torque: DVec3,
}

/// Where a particle meets a collider this substep.
struct Hit {
    /// The surface point.
    point: DVec3,
    /// Outward unit normal there.
    normal: DVec3,
    /// How far inside the collider the particle was (0 if outside).
    depth: f64,
    /// Found by the swept test.
    swept: bool,
}

/// The contact of a particle that moved from `x0` to `x1`: its path crossed the surface (ray
/// cast), or it ends within `thickness` of it or inside (projection).
fn surface(co: &Collider, x0: DVec3, x1: DVec3, thickness: f64) -> Option<Hit> {
    let (shape, pose) = (co.shape(), co.position());
    let d = x1 - x0;
    if d.length() > thickness {
        // Fast enough to skip a shell: cast the path, from outside only.
        let start = shape.project_point(pose, x0.as_vec3(), false);
        if !start.is_inside {
            let ray = Ray::new(x0.as_vec3(), d.as_vec3());
            if let Some(r) = shape.cast_ray_and_get_normal(pose, &ray, 1.0, false) {
                let point = x0 + d * r.time_of_impact as f64;
                let normal = r.normal.as_dvec3().normalize_or(DVec3::Y);
                // A path grazing a thin shape from its far side has the normal along it.
                let normal = if normal.dot(d) > 0.0 { -normal } else { normal };
                let depth = (x1 - point).dot(-normal).max(0.0);
                return Some(Hit {
                    point,
                    normal,
                    depth,
                    swept: true,
                });
            }
        }
    }
    let p = shape.project_point(pose, x1.as_vec3(), false);
    let point = p.point.as_dvec3();
    let diff = x1 - point;
    let dist = diff.length();
    if !p.is_inside && dist >= thickness {
        return None;
    }
    let normal = if dist > 1e-9 {
        if p.is_inside {
            -diff / dist
        } else {
            diff / dist
        }
    } else {
        // On the surface: the side the particle came from.
        (x0 - point).normalize_or(DVec3::Y)
    };
    Some(Hit {
        point,
        normal,
        depth: if p.is_inside { dist } else { 0.0 },
        swept: false,
    })
}

/// The box around two position sets (f32), or None when empty.
fn bounds(a: &[DVec3], b: &[DVec3]) -> Option<(Vec3, Vec3)> {
    let mut it = a.iter().chain(b);
    let first = *it.next()?;
    let (lo, hi) = it.fold((first, first), |(lo, hi), x| (lo.min(*x), hi.max(*x)));
    Some((lo.as_vec3(), hi.as_vec3()))
}
