//! Contact queries in each collider's local frame (f64): surface point, normal, support, response.

use super::*;

/// A dynamic body pressing on a particle that a fixed or kinematic collider holds up (a box on
/// a tablecloth on a table): the particle cannot give way, so the body is stopped instead. The
/// impulse asked for ends the body's approach, closes a fifth of the shell's overlap per
/// substep, and carries Coulomb friction against the particle's sliding; the particle keeps
/// its state (its reaction goes into the collider holding it).
pub(super) fn support(
    hit: &Hit,
    x: DVec3,
    v: DVec3,
    c: &ContactMaterial,
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
pub(super) fn posed(body: &RigidBody, ahead: f64) -> Pose {
    if ahead > 0.0 && body.is_moving() {
        body.predict_position_using_velocity(ahead as f32)
    } else {
        *body.position()
    }
}

/// The velocity relative to the collider after the contact: the approach along `normal`
/// reversed by the restitution, the tangential part held by static friction or slowed by
/// kinetic friction. None when the particle is already leaving.
pub(super) fn respond(
    rel: DVec3,
    normal: DVec3,
    c: &ContactMaterial,
    cand: &Candidate,
) -> Option<DVec3> {
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

/// A collider's rigid frame in f64: particles go into it for parry's local queries (one
/// transform in, one out, and parry's f32 sees only coordinates near the shape).
#[derive(Clone, Copy)]
pub(super) struct Local {
    pub(super) origin: DVec3,
    /// Rotation and its transpose; None when the frame is not rotated, or the shape (a ball) is
    /// the same whatever its rotation.
    pub(super) rotation: Option<(DMat3, DMat3)>,
}

impl Local {
    pub(super) fn of(pose: &Pose, symmetric: bool) -> Self {
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

    pub(super) fn point_in(&self, p: DVec3) -> DVec3 {
        let d = p - self.origin;
        self.rotation.map_or(d, |(_, t)| t * d)
    }

    pub(super) fn vector_out(&self, v: DVec3) -> DVec3 {
        self.rotation.map_or(v, |(m, _)| m * v)
    }
}

/// The contact of a particle that moved from `x0` to `x1`: its path crossed the surface (ray
/// cast, when `fast`: it moved further than `thickness`), or it ends within `thickness` of it
/// or inside (projection).
pub(super) fn surface<S: PointQuery + RayCast + ?Sized>(
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
pub(super) fn local_surface<S: PointQuery + RayCast + ?Sized>(
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
