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

use glam::{DMat3, DVec3, Vec3};
use hecs::{Entity, World};
use rapier3d::parry::bounding_volume::BoundingVolume;
use rapier3d::parry::query::{PointQuery, Ray, RayCast};
use rapier3d::parry::shape::{Ball, Cuboid};
use rapier3d::prelude::{
    ColliderBuilder, ColliderHandle, ColliderSet, PhysicsWorld, Pose, RigidBody, RigidBodyBuilder,
    RigidBodyHandle, RigidBodySet, RigidBodyType, SharedShape,
};
use rayon::prelude::*;

use crate::buffers::Packed;
use crate::scene::props::{BodyDef, BodyKind, ContactDef, Keyframe, Shape};

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

/// The rigid side of a scene: rapier's world, the bodies driven along paths, and the contact
/// stage.
pub struct Props {
    pub physics: PhysicsWorld,
    /// Some body can move: rapier steps each substep.
    pub moving: bool,
    /// Some body is dynamic: impulses go back to bodies.
    pub dynamic: bool,
    /// Position-driven bodies following keyframed paths from the scene.
    paths: Vec<(RigidBodyHandle, Vec<Keyframe>)>,
    /// Position-driven bodies moved through the API this frame: (body, start, target).
    driven: Vec<(RigidBodyHandle, Pose, Pose)>,
    /// Simulated time of the paths (s).
    time: f64,
    /// Substep within the frame, and substeps per frame.
    substep: u32,
    substeps: u32,
    stage: ContactStage,
}

/// The contact stage's buffers and statistics: attachments, then particles against colliders.
/// It owns no rapier state, so it runs against the engine's sets or a caller's.
pub struct ContactStage {
    pub contact: ContactDef,
    /// Attached particles as packed indices, refreshed at gather.
    attached: Vec<(usize, Attachment)>,
    /// Per packed particle: attached (placed by its body, so no contacts).
    held: Vec<bool>,
    /// Positions at the start of the substep (for the swept test). The contact pass leaves
    /// each chunk's final positions here, so the next substep needs no copy.
    prev: Vec<DVec3>,
    /// `prev` holds the positions the last contact pass left, and nothing moved them since.
    prev_valid: bool,
    /// Colliders near the cloth this substep.
    candidates: Vec<Candidate>,
    /// Per (particle chunk, candidate): what the chunk did to the candidate's body.
    sums: Vec<Exchange>,
    /// Per chunk and candidate: whether the candidate's box meets the chunk's paths.
    near: Vec<bool>,
    pub stats: ContactStats,
}

/// A collider's shape, the common primitives by value.
enum Form {
    Ball(Ball),
    Cuboid(Cuboid),
    Other,
}

/// A collider near the cloth, with its pose and motion this substep.
struct Candidate {
    shape: SharedShape,
    form: Form,
    frame: Local,
    body: Option<RigidBodyHandle>,
    /// World pose (the device stage's upload), and its box grown by the thickness.
    #[cfg_attr(not(feature = "gpu"), allow(dead_code))]
    pose: Pose,
    lo: DVec3,
    hi: DVec3,
    /// Bounding sphere grown by the thickness: centre and radius.
    centre: DVec3,
    reach: f64,
    /// Rigid motion: velocity of the centre of mass, angular velocity, centre of mass.
    lin: DVec3,
    ang: DVec3,
    com: DVec3,
    dynamic: bool,
    /// The body's mass (dynamic bodies; 0 otherwise).
    mass: f64,
    mu_s: f64,
    mu_k: f64,
}

impl Candidate {
    fn velocity_at(&self, p: DVec3) -> DVec3 {
        self.lin + self.ang.cross(p - self.com)
    }
}

fn v3(v: [f64; 3]) -> Vec3 {
    DVec3::from(v).as_vec3()
}

/// A keyframe's pose.
fn pose_of(k: &Keyframe) -> Pose {
    Pose::new(v3(k.position), v3(k.rotation))
}

/// The pose on a keyframed path at time `t`: linear in position, spherical in rotation, held
/// before the first and after the last keyframe.
pub fn path_pose(path: &[Keyframe], t: f64) -> Pose {
    let next = path.partition_point(|k| k.time <= t);
    match (next.checked_sub(1).map(|i| &path[i]), path.get(next)) {
        (Some(a), Some(b)) => {
            let s = ((t - a.time) / (b.time - a.time)) as f32;
            pose_of(a).lerp(&pose_of(b), s)
        }
        (Some(a), None) => pose_of(a),
        (None, Some(b)) => pose_of(b),
        (None, None) => Pose::IDENTITY,
    }
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
        let mut props = Props {
            physics,
            moving: false,
            dynamic: false,
            paths: Vec::new(),
            driven: Vec::new(),
            time: 0.0,
            substep: 0,
            substeps: 1,
            stage: ContactStage::new(contact),
        };
        let mut handles = Vec::with_capacity(bodies.len());
        for (i, b) in bodies.iter().enumerate() {
            let prop = props
                .add_body(b, world)
                .map_err(|e| format!("bodies[{i}].{e}"))?;
            handles.push(prop.body);
        }
        Ok((props, handles))
    }

    /// Adds a body (validated like a scene's) to the rapier world and spawns its
    /// [`RigidProp`] entity into `world`.
    pub fn add_body(&mut self, b: &BodyDef, world: &mut World) -> Result<RigidProp, String> {
        let physics = &mut self.physics;
        let (position, rotation) = match b.path.first() {
            Some(k) => (k.position, k.rotation),
            None => (b.position, b.rotation),
        };
        let builder = match b.kind {
            BodyKind::Fixed => RigidBodyBuilder::fixed(),
            BodyKind::Dynamic => RigidBodyBuilder::dynamic(),
            BodyKind::Kinematic => RigidBodyBuilder::kinematic_velocity_based(),
            BodyKind::KinematicPosition => RigidBodyBuilder::kinematic_position_based(),
        }
        .translation(v3(position))
        .rotation(v3(rotation))
        .linvel(v3(b.velocity))
        .angvel(v3(b.angular_velocity))
        .linear_damping(b.linear_damping as f32)
        .angular_damping(b.angular_damping as f32);
        let mut co = collider_of(&b.shape)
            .map_err(|e| format!("shape: {e}"))?
            .friction(b.friction as f32)
            .restitution(b.restitution as f32);
        co = match (b.mass, b.density) {
            (Some(m), _) => co.mass(m as f32),
            (None, Some(d)) => co.density(d as f32),
            (None, None) => co.density(1000.0),
        };
        let body = physics.bodies.insert(builder);
        let collider = physics
            .colliders
            .insert_with_parent(co, body, &mut physics.bodies);
        let prop = RigidProp { body, collider };
        world.spawn((prop,));
        if !b.path.is_empty() {
            self.paths.push((body, b.path.clone()));
        }
        self.moving |= b.kind != BodyKind::Fixed;
        self.dynamic |= b.kind == BodyKind::Dynamic;
        Ok(prop)
    }

    /// Removes a body, its collider, its [`RigidProp`] entity and the attachments of particles
    /// to it (those particles go free). False when the body is not in this world.
    pub fn remove_body(&mut self, body: RigidBodyHandle, world: &mut World) -> bool {
        if self.physics.remove_body(body).is_none() {
            return false;
        }
        self.paths.retain(|(h, _)| *h != body);
        // The body's own entity, and the particles attached to it.
        let mine: Vec<(Entity, bool)> = world
            .query::<(Entity, Option<&RigidProp>, Option<&Attachment>)>()
            .iter()
            .filter_map(|(e, p, a)| match (p, a) {
                (Some(p), _) if p.body == body => Some((e, true)),
                (_, Some(a)) if a.body == body => Some((e, false)),
                _ => None,
            })
            .collect();
        for (e, is_body) in mine {
            if is_body {
                let _ = world.despawn(e);
            } else {
                let _ = world.remove_one::<Attachment>(e);
            }
        }
        let bodies = &self.physics.bodies;
        self.moving = bodies.iter().any(|(_, b)| !b.is_fixed());
        self.dynamic = bodies.iter().any(|(_, b)| b.is_dynamic());
        true
    }

    /// After a gather: the attached particles' packed indices.
    pub fn gather(&mut self, world: &World, packed: &Packed) {
        self.stage.gather(world, packed);
    }

    /// Entities of attached particles whose body no longer exists.
    pub fn dangling(&self, world: &World) -> Option<Entity> {
        self.stage.dangling(world, &self.physics.bodies)
    }

    /// The contact stage (the simulation's substep loop drives it directly).
    pub(crate) fn stage_mut(&mut self) -> &mut ContactStage {
        &mut self.stage
    }

    /// The frame's statistics start again; position-driven bodies given a target through the
    /// API (`set_next_kinematic_position`) reach it at the frame's end, in even substeps.
    pub fn begin_frame(&mut self, substeps: u32) {
        self.stage.begin_frame();
        (self.substep, self.substeps) = (0, substeps.max(1));
        self.driven.clear();
        for (handle, b) in self.physics.bodies.iter() {
            let by_path = self.paths.iter().any(|(p, _)| *p == handle);
            if b.body_type() == RigidBodyType::KinematicPositionBased && !by_path {
                self.driven
                    .push((handle, *b.position(), *b.next_position()));
            }
        }
    }

    /// Steps 1–3 of the module docs, after the integrate stage of one substep.
    pub fn substep(&mut self, packed: &mut Packed, h: f64) {
        self.step_bodies(h);
        let (bodies, colliders) = (&mut self.physics.bodies, &self.physics.colliders);
        self.stage.substep(packed, bodies, colliders, 0.0, h);
    }

    /// Step 1: the bodies move by one substep (paths, API targets, then rapier).
    pub fn step_bodies(&mut self, h: f64) {
        self.substep += 1;
        self.time += h;
        if self.moving {
            let bodies = &mut self.physics.bodies;
            for (handle, path) in &self.paths {
                if let Some(b) = bodies.get_mut(*handle) {
                    b.set_next_kinematic_position(path_pose(path, self.time));
                }
            }
            let s = self.substep as f32 / self.substeps as f32;
            for (handle, start, target) in &self.driven {
                if let Some(b) = bodies.get_mut(*handle) {
                    b.set_next_kinematic_position(start.lerp(target, s.min(1.0)));
                }
            }
            self.physics.integration_parameters.dt = h as f32;
            self.physics.step();
        }
    }

    pub fn stats(&self) -> &ContactStats {
        &self.stage.stats
    }

    pub fn contact(&self) -> &ContactDef {
        &self.stage.contact
    }

    pub fn bodies(&self) -> &RigidBodySet {
        &self.physics.bodies
    }

    pub fn colliders(&self) -> &ColliderSet {
        &self.physics.colliders
    }
}

impl ContactStage {
    pub fn new(contact: ContactDef) -> Self {
        Self {
            contact,
            attached: Vec::new(),
            held: Vec::new(),
            prev: Vec::new(),
            prev_valid: false,
            candidates: Vec::new(),
            sums: Vec::new(),
            near: Vec::new(),
            stats: ContactStats::default(),
        }
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
        self.held.clear();
        self.held.resize(packed.x.len(), false);
        for &(i, _) in &self.attached {
            self.held[i] = true;
        }
    }

    /// An attached particle whose body is not in `bodies`.
    pub fn dangling(&self, world: &World, bodies: &RigidBodySet) -> Option<Entity> {
        world
            .query::<(Entity, &Attachment)>()
            .iter()
            .find(|(_, a)| !bodies.contains(a.body))
            .map(|(e, _)| e)
    }

    /// Before a substep's integrate: where the particles start (the last contact pass left it,
    /// unless something else moved them since).
    pub fn begin_substep(&mut self, packed: &Packed) {
        if !self.prev_valid || self.prev.len() != packed.x.len() {
            self.prev.clear();
            self.prev.extend_from_slice(&packed.x);
        }
        self.prev_valid = false;
    }

    /// Particles moved between substeps by something other than this stage.
    pub fn moved(&mut self) {
        self.prev_valid = false;
    }

    /// The state may have been edited between frames: the first substep copies it.
    pub fn begin_frame(&mut self) {
        self.stats = ContactStats::default();
        self.prev_valid = false;
    }

    /// Attachments then contacts of a substep of `h` against `bodies` and `colliders`, posed
    /// `ahead` seconds after their stored poses at their current velocities (0 when rapier
    /// already stepped them).
    pub fn substep(
        &mut self,
        packed: &mut Packed,
        bodies: &mut RigidBodySet,
        colliders: &ColliderSet,
        ahead: f64,
        h: f64,
    ) {
        self.attach(packed, bodies, ahead);
        self.contacts(packed, bodies, colliders, ahead, h);
    }

    fn attach(&mut self, packed: &mut Packed, bodies: &mut RigidBodySet, ahead: f64) {
        for &(i, a) in &self.attached {
            let Some(body) = bodies.get_mut(a.body) else {
                continue;
            };
            let pose = posed(body, ahead);
            let target = pose.transform_point(a.local);
            let com = pose.transform_point(body.local_center_of_mass()).as_dvec3();
            let vb =
                body.linvel().as_dvec3() + body.angvel().as_dvec3().cross(target.as_dvec3() - com);
            let m = packed.mass(i);
            if m.is_finite() && body.is_dynamic() {
                let j = m * (vb - packed.v[i]);
                body.apply_impulse_at_point(-j.as_vec3(), target, true);
                self.stats.impulse_on_bodies -= j;
            }
            packed.x[i] = target.as_dvec3();
            packed.v[i] = vb;
        }
    }

    /// The colliders as they stand `ahead` seconds on into `candidates`: fixed and kinematic first, so a particle
    /// they touch is supported when a dynamic body then presses on it.
    fn collect(&mut self, bodies: &RigidBodySet, colliders: &ColliderSet, ahead: f64) {
        let c = &self.contact;
        self.candidates.clear();
        for (_, co) in colliders.iter() {
            if !co.is_enabled() {
                continue;
            }
            let body = co.parent().and_then(|p| bodies.get(p).map(|b| (p, b)));
            let pose = match (body, co.position_wrt_parent()) {
                (Some((_, b)), Some(rel)) if ahead > 0.0 && b.is_moving() => posed(b, ahead) * rel,
                _ => *co.position(),
            };
            let aabb = co.shape().compute_aabb(&pose).loosened(c.thickness as f32);
            let (lin, ang, com, dynamic, mass) = body.map_or(
                (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO, false, 0.0),
                |(_, b)| {
                    let com = posed(b, ahead).transform_point(b.local_center_of_mass());
                    (
                        b.linvel().as_dvec3(),
                        b.angvel().as_dvec3(),
                        com.as_dvec3(),
                        b.is_dynamic(),
                        b.mass() as f64,
                    )
                },
            );
            let mu_s = 0.5 * (c.friction + co.friction() as f64);
            let sphere = co.shape().compute_bounding_sphere(&pose);
            let shape = co.shape();
            let form = match (shape.as_ball(), shape.as_cuboid()) {
                (Some(b), _) => Form::Ball(*b),
                (_, Some(b)) => Form::Cuboid(*b),
                _ => Form::Other,
            };
            self.candidates.push(Candidate {
                shape: co.shared_shape().clone(),
                frame: Local::of(&pose, matches!(form, Form::Ball(_))),
                form,
                centre: sphere.center.as_dvec3(),
                reach: sphere.radius as f64 + c.thickness,
                body: body.map(|(p, _)| p),
                pose,
                lo: aabb.mins.as_dvec3(),
                hi: aabb.maxs.as_dvec3(),
                lin,
                ang,
                com,
                dynamic,
                mass,
                mu_s,
                mu_k: (0.5 * (c.kinetic_friction + co.friction() as f64)).min(mu_s),
            });
        }
        self.candidates.sort_by_key(|c| c.dynamic);
    }

    fn contacts(
        &mut self,
        packed: &mut Packed,
        bodies: &mut RigidBodySet,
        colliders: &ColliderSet,
        ahead: f64,
        h: f64,
    ) {
        let c = self.contact;
        self.collect(bodies, colliders, ahead);
        let nc = self.candidates.len();
        if nc == 0 || packed.x.is_empty() {
            return;
        }
        let chunks = packed.x.len().div_ceil(CHUNK);
        self.sums.clear();
        self.sums.resize(chunks * nc, Exchange::default());
        self.near.clear();
        self.near.resize(chunks * nc, false);
        let (candidates, held) = (&self.candidates, &self.held);
        let Packed { x, v, inv_mass, .. } = packed;
        let inv_mass = &inv_mass[..];
        // One pass over particles in fixed chunks; each chunk sums its impulses per collider,
        // then the sums are added in chunk order: the same result whatever the thread count.
        // Below the parallel threshold the chunks are not split: rayon's fork costs more than
        // the pass (small cloths), and the chunk order, hence the sums, stay the same.
        let min_len = if x.len() < crate::integrate::par::PAR_MIN {
            usize::MAX
        } else {
            1
        };
        x.par_chunks_mut(CHUNK)
            .zip(v.par_chunks_mut(CHUNK))
            .zip(self.prev.par_chunks_mut(CHUNK))
            .zip(self.sums.par_chunks_mut(nc))
            .zip(self.near.par_chunks_mut(nc))
            .enumerate()
            .with_min_len(min_len)
            .for_each(|(k, ((((xs, vs), prev), sums), near))| {
                // Broad phase, coarse: the colliders whose box meets the box of this chunk's
                // paths (computed here, while the chunk is in cache).
                let base = k * CHUNK;
                let free = |j: usize| inv_mass[base + j] != 0.0 && !held[base + j];
                let mut lo = DVec3::splat(f64::INFINITY);
                let mut hi = DVec3::splat(f64::NEG_INFINITY);
                for (j, xi) in xs.iter().enumerate() {
                    if free(j) {
                        let x0 = prev[j];
                        lo = lo.min(x0.min(*xi));
                        hi = hi.max(x0.max(*xi));
                    }
                }
                let mut any = false;
                for (cand, n) in candidates.iter().zip(near.iter_mut()) {
                    *n = lo.cmple(cand.hi).all() && hi.cmpge(cand.lo).all();
                    any |= *n;
                }
                if !any {
                    prev.copy_from_slice(xs);
                    return;
                }
                for (j, (xi, vi)) in xs.iter_mut().zip(vs.iter_mut()).enumerate() {
                    let i = base + j;
                    if !free(j) {
                        continue;
                    }
                    let mut supported = false;
                    for (ci, cand) in candidates.iter().enumerate() {
                        if !near[ci] {
                            continue;
                        }
                        let sum = &mut sums[ci];
                        let (x0, x1) = (prev[j], *xi);
                        // Broad phase, fine: this particle's path against this collider's box.
                        if x0.min(x1).cmpgt(cand.hi).any() || x0.max(x1).cmplt(cand.lo).any() {
                            continue;
                        }
                        // And against its bounding sphere: no point of the path comes closer
                        // to the centre than |x1 − c| − |x1 − x0|, and the L1 length bounds
                        // |x1 − x0| without a square root.
                        let d = x1 - x0;
                        let step = d.abs().element_sum();
                        if x1.distance_squared(cand.centre) > (cand.reach + step).powi(2) {
                            continue;
                        }
                        let fast = d.length_squared() > c.thickness * c.thickness;
                        let (frame, t) = (&cand.frame, c.thickness);
                        // The common primitives statically dispatched: parry's queries inline.
                        let hit = match &cand.form {
                            Form::Ball(b) => surface(b, frame, x0, x1, fast, t),
                            Form::Cuboid(b) => surface(b, frame, x0, x1, fast, t),
                            Form::Other => surface(cand.shape.as_ref(), frame, x0, x1, fast, t),
                        };
                        let Some(hit) = hit else {
                            continue;
                        };
                        sum.contacts += 1;
                        sum.max_depth = sum.max_depth.max(hit.depth);
                        sum.swept += usize::from(hit.swept);
                        if cand.dynamic && supported {
                            support(&hit, x1, *vi, &c, cand, h, sum);
                            continue;
                        }
                        supported |= !cand.dynamic;
                        *xi = hit.point + hit.normal * c.thickness;
                        let vb = cand.velocity_at(hit.point);
                        let old = *vi;
                        let Some(new) = respond(old - vb, hit.normal, &c, cand) else {
                            continue;
                        };
                        *vi = vb + new;
                        if cand.dynamic {
                            // The body gets −J at the contact point: force and torque.
                            let j = (*vi - old) / inv_mass[i];
                            sum.impulse -= j;
                            sum.torque -= (hit.point - cand.com).cross(j);
                        }
                    }
                }
                prev.copy_from_slice(xs);
            });
        self.prev_valid = true;
        for (ci, cand) in self.candidates.iter().enumerate() {
            let mut total = Exchange::default();
            for s in self.sums.iter().skip(ci).step_by(nc) {
                total.add(s);
            }
            let body = cand.body.filter(|_| cand.dynamic);
            apply(&mut self.stats, bodies, body, &total);
        }
    }
}

/// One collider's totals for a substep: into the statistics, and (dynamic body) onto the body.
/// Supported contacts each ask for the impulse that would stop the body alone: the body gets
/// their mean (one body, many contacts, one answer).
fn apply(
    stats: &mut ContactStats,
    bodies: &mut RigidBodySet,
    dynamic: Option<RigidBodyHandle>,
    total: &Exchange,
) {
    stats.contacts += total.contacts;
    stats.swept += total.swept;
    stats.max_depth = stats.max_depth.max(total.max_depth);
    let Some(handle) = dynamic else {
        return;
    };
    if total.contacts == 0 {
        return;
    }
    let k = total.supports.max(1) as f64;
    let impulse = total.impulse + total.support / k;
    let torque = total.torque + total.support_torque / k;
    if let Some(b) = bodies.get_mut(handle) {
        b.apply_impulse(impulse.as_vec3(), true);
        b.apply_torque_impulse(torque.as_vec3(), true);
    }
    stats.impulse_on_bodies += impulse;
}

impl Exchange {
    fn add(&mut self, s: &Exchange) {
        self.contacts += s.contacts;
        self.swept += s.swept;
        self.max_depth = self.max_depth.max(s.max_depth);
        self.impulse += s.impulse;
        self.torque += s.torque;
        self.support += s.support;
        self.support_torque += s.support_torque;
        self.supports += s.supports;
    }
}

/// The contact stage on the device (`shaders/contacts.wgsl`): which scenes it takes, the
/// colliders it is given each substep, and the partial sums it hands back.
#[cfg(feature = "gpu")]
mod device {
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
                && colliders.iter().all(|(_, c)| {
                    matches!(c.shape().shape_type(), ShapeType::Ball | ShapeType::Cuboid)
                })
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

        /// The colliders as they stand (after [`Self::step_bodies`]), in the CPU stage's order
        /// and with its motions and friction ([`ContactStage::collect`]); the stage keeps them to
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
                let body = cand.body.filter(|_| cand.dynamic);
                apply(&mut stage.stats, &mut self.physics.bodies, body, &total);
            }
        }
    }
}

/// A dynamic body pressing on a particle that a fixed or kinematic collider holds up (a box on
/// a tablecloth on a table): the particle cannot give way, so the body is stopped instead. The
/// impulse asked for ends the body's approach, closes a fifth of the shell's overlap per
/// substep, and carries Coulomb friction against the particle's sliding; the particle keeps
/// its state (its reaction goes into the collider holding it).
fn support(
    hit: &Hit,
    x: DVec3,
    v: DVec3,
    c: &ContactDef,
    cand: &Candidate,
    h: f64,
    sum: &mut Exchange,
) {
    let n = hit.normal;
    let rel = v - cand.velocity_at(hit.point);
    let vn = rel.dot(n);
    let overlap = (c.thickness - (x - hit.point).dot(n)).max(0.0);
    let approach = -vn + 0.2 * overlap / h;
    if approach <= 0.0 {
        return;
    }
    let jn = cand.mass * approach;
    let vt = rel - vn * n;
    let speed = vt.length();
    let jt = if cand.mass * speed <= cand.mu_s * jn {
        cand.mass * vt
    } else {
        vt * (cand.mu_k * jn / speed)
    };
    let j = -jn * n + jt;
    sum.supports += 1;
    sum.support += j;
    sum.support_torque += (hit.point - cand.com).cross(j);
}

/// A body's pose `ahead` seconds on at its current velocity (its pose when `ahead` is 0).
fn posed(body: &RigidBody, ahead: f64) -> Pose {
    if ahead > 0.0 && body.is_moving() {
        body.predict_position_using_velocity(ahead as f32)
    } else {
        *body.position()
    }
}

/// The velocity relative to the collider after the contact: the approach along `normal`
/// reversed by the restitution, the tangential part held by static friction or slowed by
/// kinetic friction. None when the particle is already leaving.
fn respond(rel: DVec3, normal: DVec3, c: &ContactDef, cand: &Candidate) -> Option<DVec3> {
    let vn = rel.dot(normal);
    if vn >= 0.0 {
        return None;
    }
    let dvn = -(1.0 + c.restitution) * vn;
    let vt = rel - vn * normal;
    // Static friction compares squares: the common resting case takes no square root.
    let speed2 = vt.length_squared();
    let vt = if speed2 <= (cand.mu_s * dvn).powi(2) {
        DVec3::ZERO
    } else {
        vt * (1.0 - cand.mu_k * dvn / speed2.sqrt()).max(0.0)
    };
    Some((vn + dvn) * normal + vt)
}

/// Particles per parallel task of the contact stage.
const CHUNK: usize = 512;

/// What one chunk of particles did against one collider.
#[derive(Clone, Copy, Default)]
struct Exchange {
    contacts: usize,
    swept: usize,
    max_depth: f64,
    /// Impulse and angular impulse (about the centre of mass) on the body.
    impulse: DVec3,
    torque: DVec3,
    /// Supported contacts: their count and the sums of the impulses each asks for.
    supports: usize,
    support: DVec3,
    support_torque: DVec3,
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

/// A collider's rigid frame in f64: particles go into it for parry's local queries (one
/// transform in, one out, and parry's f32 sees only coordinates near the shape).
#[derive(Clone, Copy)]
struct Local {
    origin: DVec3,
    /// Rotation and its transpose; None when the frame is not rotated, or the shape (a ball) is
    /// the same whatever its rotation.
    rotation: Option<(DMat3, DMat3)>,
}

impl Local {
    fn of(pose: &Pose, symmetric: bool) -> Self {
        let q = pose.rotation.as_dquat();
        let rotation = (!symmetric && q.xyz() != DVec3::ZERO).then(|| {
            let m = DMat3::from_quat(q.normalize());
            (m, m.transpose())
        });
        Self {
            origin: pose.translation.as_dvec3(),
            rotation,
        }
    }

    fn point_in(&self, p: DVec3) -> DVec3 {
        let d = p - self.origin;
        self.rotation.map_or(d, |(_, t)| t * d)
    }

    fn vector_out(&self, v: DVec3) -> DVec3 {
        self.rotation.map_or(v, |(m, _)| m * v)
    }
}

/// The contact of a particle that moved from `x0` to `x1`: its path crossed the surface (ray
/// cast, when `fast`: it moved further than `thickness`), or it ends within `thickness` of it
/// or inside (projection).
fn surface<S: PointQuery + RayCast + ?Sized>(
    shape: &S,
    frame: &Local,
    x0: DVec3,
    x1: DVec3,
    fast: bool,
    thickness: f64,
) -> Option<Hit> {
    let (l0, l1) = (frame.point_in(x0), frame.point_in(x1));
    let hit = local_surface(shape, l0, l1, fast, thickness)?;
    Some(Hit {
        point: frame.origin + frame.vector_out(hit.point),
        normal: frame.vector_out(hit.normal),
        ..hit
    })
}

/// [`surface`] in the shape's frame.
fn local_surface<S: PointQuery + RayCast + ?Sized>(
    shape: &S,
    x0: DVec3,
    x1: DVec3,
    fast: bool,
    thickness: f64,
) -> Option<Hit> {
    let d = x1 - x0;
    if fast {
        // Fast enough to skip a shell: cast the path, from outside only.
        let start = shape.project_local_point(x0.as_vec3(), false);
        if !start.is_inside {
            let ray = Ray::new(x0.as_vec3(), d.as_vec3());
            if let Some(r) = shape.cast_local_ray_and_get_normal(&ray, 1.0, false) {
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
    let p = shape.project_local_point(x1.as_vec3(), false);
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

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;
    use rapier3d::parry::shape::{Capsule, Shape as ParryShape};

    /// The f64 local frame against parry's own posed queries, for rotated shapes: the same
    /// surface point and normal within f32 rounding, inside and outside, and along a cast path.
    #[test]
    fn local_frame_queries_match_posed_queries() {
        let pose = Pose::from_parts(
            Vec3::new(0.3, -1.2, 2.0),
            Quat::from_euler(glam::EulerRot::XYZ, 0.7, -0.4, 1.1),
        );
        let cuboid = Cuboid::new(Vec3::new(0.5, 0.2, 0.8));
        let capsule = Capsule::new_y(0.6, 0.25);
        let ball = Ball::new(0.4);
        let points = [
            DVec3::new(0.9, -0.9, 2.4),
            DVec3::new(0.35, -1.15, 2.05),
            DVec3::new(-0.2, -1.6, 1.5),
            DVec3::new(0.3, -0.6, 2.3),
        ];
        let check = |shape: &dyn ParryShape, symmetric: bool| {
            let frame = Local::of(&pose, symmetric);
            for &x in &points {
                let posed = shape.project_point(&pose, x.as_vec3(), false);
                let hit = surface(shape, &frame, x, x, false, 10.0).unwrap();
                assert!((hit.point - posed.point.as_dvec3()).length() < 1e-5, "{x}");
                let dist = (x - hit.point).length();
                assert!((hit.depth > 0.0) == posed.is_inside && dist > 1e-3);
                let outward = if posed.is_inside {
                    hit.point - x
                } else {
                    x - hit.point
                };
                assert!((hit.normal - outward / dist).length() < 1e-5);
            }
            // A path from far outside through the shape's centre: the swept test meets the
            // surface where parry's posed ray cast does.
            let (x0, x1) = (DVec3::new(3.0, 1.0, 4.0), pose.translation.as_dvec3());
            let hit = surface(shape, &frame, x0, x1, true, 1e-3).unwrap();
            let ray = Ray::new(x0.as_vec3(), (x1 - x0).as_vec3());
            let r = shape
                .cast_ray_and_get_normal(&pose, &ray, 1.0, false)
                .unwrap();
            assert!(hit.swept);
            let at = x0 + (x1 - x0) * r.time_of_impact as f64;
            assert!((hit.point - at).length() < 1e-5);
            assert!((hit.normal - r.normal.as_dvec3()).length() < 1e-5);
        };
        check(&cuboid, false);
        check(&capsule, false);
        check(&ball, true);
        check(&ball, false);
    }
}
