//! The contact stage: the broad phase, push-out with friction, and the impulses on bodies.

use super::*;

/// The contact stage's buffers and statistics: attachments, then particles against colliders.
/// It owns no rapier state, so it runs against the engine's sets or a caller's.
pub struct ContactStage {
    pub contact: ContactMaterial,
    /// Attached particles as packed indices, refreshed at gather.
    pub(super) attached: Vec<(usize, Attachment)>,
    /// Per packed particle: attached (placed by its body, so no contacts).
    pub(super) held: Vec<bool>,
    /// Positions at the start of the substep (for the swept test). The contact pass leaves
    /// each chunk's final positions here, so the next substep needs no copy.
    pub(super) prev: Vec<DVec3>,
    /// `prev` holds the positions the last contact pass left, and nothing moved them since.
    pub(super) prev_valid: bool,
    /// Colliders near the cloth this substep.
    pub(super) candidates: Vec<Candidate>,
    /// Per (particle chunk, candidate): what the chunk did to the candidate's body.
    pub(super) sums: Vec<Exchange>,
    /// Per chunk and candidate: whether the candidate's box meets the chunk's paths.
    pub(super) near: Vec<bool>,
    pub stats: ContactStats,
    /// Gravity, for the energy the stage's projections change.
    pub(crate) gravity: DVec3,
    /// The positions before this substep's contact pass (the energy audit's spring terms).
    pub(super) pre: Vec<DVec3>,
    /// Per particle: the contact pass moved it this substep.
    pub(super) touched: Vec<bool>,
    /// Per chunk: the energy its contacts and friction removed from the particles themselves,
    /// and whether it pushed any (then, after the pass, its springs' change).
    pub(super) removed: Vec<[f64; 3]>,
    /// What the projections did to the cloth's energy this frame.
    pub(crate) energy: ProjectionLines,
}

/// A collider's shape, the common primitives by value.
pub(super) enum Form {
    Ball(Ball),
    Cuboid(Cuboid),
    Other,
}

/// A collider near the cloth, with its pose and motion this substep.
pub(super) struct Candidate {
    pub(super) shape: SharedShape,
    pub(super) form: Form,
    pub(super) frame: Local,
    pub(super) body: Option<RigidBodyHandle>,
    /// World pose (the device stage's upload), and its box grown by the thickness.
    #[cfg_attr(not(feature = "gpu"), allow(dead_code))]
    pub(super) pose: Pose,
    pub(super) lo: DVec3,
    pub(super) hi: DVec3,
    /// Bounding sphere grown by the thickness: centre and radius.
    pub(super) centre: DVec3,
    pub(super) reach: f64,
    /// Rigid motion: velocity of the centre of mass, angular velocity, centre of mass.
    pub(super) lin: DVec3,
    pub(super) ang: DVec3,
    pub(super) com: DVec3,
    pub(super) dynamic: bool,
    /// The body's mass (dynamic bodies; 0 otherwise).
    pub(super) mass: f64,
    pub(super) mu_s: f64,
    pub(super) mu_k: f64,
}

impl Candidate {
    pub(super) fn velocity_at(&self, p: DVec3) -> DVec3 {
        self.lin + self.ang.cross(p - self.com)
    }
}

impl ContactStage {
    pub fn new(contact: ContactMaterial) -> Self {
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
            gravity: DVec3::ZERO,
            pre: Vec::new(),
            touched: Vec::new(),
            removed: Vec::new(),
            energy: ProjectionLines::default(),
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

    /// Per particle: the last contact pass on the host moved it (empty before one ran).
    pub(crate) fn touched(&self) -> &[bool] {
        &self.touched
    }

    /// The state may have been edited between frames: the first substep copies it.
    pub fn begin_frame(&mut self) {
        self.stats = ContactStats::default();
        self.energy = ProjectionLines::default();
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

    pub(super) fn attach(&mut self, packed: &mut Packed, bodies: &mut RigidBodySet, ahead: f64) {
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
            let before = audit::local_energy(packed, i, self.gravity);
            packed.x[i] = target.as_dvec3();
            packed.v[i] = vb;
            self.energy.attachments += audit::local_energy(packed, i, self.gravity) - before;
        }
    }

    /// The colliders as they stand `ahead` seconds on into `candidates`: fixed and kinematic first, so a particle
    /// they touch is supported when a dynamic body then presses on it.
    pub(super) fn collect(&mut self, bodies: &RigidBodySet, colliders: &ColliderSet, ahead: f64) {
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

    pub(super) fn contacts(
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
        self.removed.clear();
        self.removed.resize(chunks, [0.0; 3]);
        self.touched.clear();
        self.touched.resize(packed.x.len(), false);
        self.pre.clear();
        self.pre.extend_from_slice(&packed.x);
        let g = self.gravity;
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
            .zip(self.removed.par_iter_mut())
            .zip(self.touched.par_chunks_mut(CHUNK))
            .enumerate()
            .with_min_len(min_len)
            .for_each(
                |(k, ((((((xs, vs), prev), sums), near), removed), touched))| {
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
                            let (x_old, old) = (*xi, *vi);
                            *xi = hit.point + hit.normal * c.thickness;
                            touched[j] = true;
                            removed[2] = 1.0;
                            let m = 1.0 / inv_mass[i];
                            // The push-out's change of the particle's own energy (its springs' are
                            // booked after the pass).
                            removed[0] += m * g.dot(*xi - x_old);
                            let vb = cand.velocity_at(hit.point);
                            let Some(new) = respond(old - vb, hit.normal, &c, cand) else {
                                continue;
                            };
                            *vi = vb + new;
                            let n = hit.normal;
                            let (u, u1) = (old - vb, new);
                            let (ut, ut1) = (u - u.dot(n) * n, u1 - u1.dot(n) * n);
                            let friction = 0.5 * m * (ut.length_squared() - ut1.length_squared());
                            removed[0] +=
                                0.5 * m * (old.length_squared() - vi.length_squared()) - friction;
                            removed[1] += friction;
                            if cand.dynamic {
                                // The body gets −J at the contact point: force and torque.
                                let j = (*vi - old) / inv_mass[i];
                                sum.impulse -= j;
                                sum.torque -= (hit.point - cand.com).cross(j);
                            }
                        }
                    }
                    prev.copy_from_slice(xs);
                },
            );
        self.prev_valid = true;
        self.book(packed);
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

impl ContactStage {
    /// Books the contact pass's energy: the change it made, each chunk's to its particles,
    /// then the change of the springs at the particles it moved, each spring once (in chunk
    /// order).
    fn book(&mut self, packed: &Packed) {
        let (x, pre, moved) = (&packed.x[..], &self.pre[..], &self.touched[..]);
        let chunk = |k: usize| {
            let mut springs = 0.0;
            for i in (k * CHUNK..((k + 1) * CHUNK).min(x.len())).filter(|&i| moved[i]) {
                audit::springs_at(packed, i, |l| {
                    let other = if l.a == i { l.b } else { l.a };
                    if moved[other] && other < i {
                        return;
                    }
                    springs += audit::spring_energy(x, l) - audit::spring_energy(pre, l);
                });
            }
            springs
        };
        // Each chunk's springs on its own thread (the state is only read), summed in order.
        let min_len = if x.len() < crate::integrate::par::PAR_MIN {
            usize::MAX
        } else {
            1
        };
        self.removed
            .par_iter_mut()
            .enumerate()
            .with_min_len(min_len)
            .filter(|(_, r)| r[2] != 0.0)
            .for_each(|(k, r)| r[2] = chunk(k));
        for r in self
            .removed
            .iter()
            .filter(|r| r[2] != 0.0 || r[0] != 0.0 || r[1] != 0.0)
        {
            self.energy.contacts += r[0] - r[2];
            self.energy.friction += r[1];
        }
    }
}

/// One collider's totals for a substep: into the statistics, and (dynamic body) onto the body.
/// Supported contacts each ask for the impulse that would stop the body alone: the body gets
/// their mean (one body, many contacts, one answer).
pub(super) fn apply(
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
    pub(super) fn add(&mut self, s: &Exchange) {
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

/// Particles per parallel task of the contact stage.
pub(super) const CHUNK: usize = 512;

/// What one chunk of particles did against one collider.
#[derive(Clone, Copy, Default)]
pub(super) struct Exchange {
    pub(super) contacts: usize,
    pub(super) swept: usize,
    pub(super) max_depth: f64,
    /// Impulse and angular impulse (about the centre of mass) on the body.
    pub(super) impulse: DVec3,
    pub(super) torque: DVec3,
    /// Supported contacts: their count and the sums of the impulses each asks for.
    pub(super) supports: usize,
    pub(super) support: DVec3,
    pub(super) support_torque: DVec3,
}

/// Where a particle meets a collider this substep.
pub(super) struct Hit {
    /// The surface point.
    pub(super) point: DVec3,
    /// Outward unit normal there.
    pub(super) normal: DVec3,
    /// How far inside the collider the particle was (0 if outside).
    pub(super) depth: f64,
    /// Found by the swept test.
    pub(super) swept: bool,
}
