//! One contact's response: a particle pushed out from a point of others (a particle, or a
//! point of a triangle by its barycentric weights) to the thickness, by inverse mass, its
//! approach removed and its sliding slowed by Coulomb friction; and the particle–triangle
//! test, swept along the substep.

use glam::DVec3;

use super::edges::{coplanar_times, line_parameters, segment_weights};
use super::search::{closest_on_triangle, plane_weights};
use crate::audit::Moves;

/// The state a pass moves, and its record of what moved.
pub(super) struct Touch<'a> {
    pub(super) x: &'a mut [DVec3],
    pub(super) v: &'a mut [DVec3],
    pub(super) inv: &'a [f64],
    pub(super) moves: &'a mut Moves,
    pub(super) before_v: &'a mut [DVec3],
    /// The contacts pushed this pass, for the passes over their velocities after.
    pub(super) active: &'a mut Vec<Active>,
    /// Each particle's path (its moves less the members' mean move each substep), onto which
    /// every push adds its length ([`Tested`]; `collide/pass.rs`).
    pub(super) odometer: &'a mut [f64],
}

/// What a contact's test did: whether it moved any particle, and, where it found the two
/// sides apart, by how much past the thickness at least (else 0). While the two sides'
/// paths since, summed, stay under that, the test would find them apart again, crossed or
/// not: a crossing over a substep puts the two sides' points, interpolated, on each other
/// at some moment, and each point is no further from where it was than its particles' paths.
#[derive(Clone, Copy, Debug)]
pub(super) struct Tested {
    pub(super) moved: bool,
    pub(super) apart: f64,
}

impl Tested {
    const AGAIN: Tested = Tested {
        moved: false,
        apart: 0.0,
    };

    /// `dist` apart against thickness `t`, near `at`: less a hair for the rounding of the
    /// distance (relative to the thickness and to the coordinates' size).
    fn apart(dist: f64, t: f64, at: DVec3) -> Tested {
        let apart = dist - t - 1e-9 * t - 1e-12 * at.abs().max_element();
        Tested {
            moved: false,
            apart: if apart > 0.0 { apart } else { 0.0 },
        }
    }

    fn pushed(moved: bool) -> Tested {
        Tested { moved, apart: 0.0 }
    }
}

/// A contact the pass pushed: its two sides' particles and weights (a particle: one, weight 1;
/// an edge's point: two; a triangle's: three; the rest unused), the normal, `W`, and the
/// normal impulse (per unit of `W`) it has given so far.
#[derive(Clone, Copy, Debug)]
pub(super) struct Active {
    ours: [(usize, f64); 2],
    ours_count: usize,
    others: [(usize, f64); 3],
    count: usize,
    n: DVec3,
    w: f64,
    impulse: f64,
}

/// The velocity of a side's point: its particles' by their weights.
fn velocity(v: &[DVec3], side: &[(usize, f64)]) -> DVec3 {
    side.iter().map(|&(i, c)| v[i] * c).sum()
}

/// A contact's friction: kinetic, then static.
pub(super) type Friction = (f64, f64);

impl Touch<'_> {
    fn touch(&mut self, i: usize) {
        if !self.moves.moved[i] {
            self.before_v[i] = self.v[i];
        }
        Moves::mark(
            &mut self.moves.moved[i],
            &mut self.moves.before[i],
            self.x[i],
        );
    }

    /// The point `p = Σ cᵢ x[i]` of `ours` against the point `q = Σ wᵢ x[i]` of `others`
    /// (each side's weights summing to 1), `over` (m) closer along the normal `n` (from `q`
    /// towards `p`) than the thickness: the gap opened by a move along `n` of generalised
    /// inverse mass `W = Σ cᵢ² wᵢ + Σ wᵢ² wᵢ` (`λ = over / W`, each of ours by `λ cᵢ wᵢ`,
    /// each other by `−λ wᵢ wᵢ`), then the approach and the sliding removed the same way, so
    /// the momentum is kept. Returns whether it moved (nothing does where every mass is held).
    pub(super) fn push(
        &mut self,
        ours: &[(usize, f64)],
        others: &[(usize, f64)],
        n: DVec3,
        over: f64,
        (mu, mu_s): Friction,
    ) -> bool {
        let inv = self.inv;
        let mass = |side: &[(usize, f64)]| side.iter().map(|&(i, c)| c * c * inv[i]).sum::<f64>();
        let w = mass(ours) + mass(others);
        if w.is_nan() || w <= 0.0 {
            return false;
        }
        // A point near a held corner of a triangle whose other corners are free, against a
        // held particle, would throw the free corner by `over / bᵢ`: at most 4 `over` (the
        // point then moves less than `over`; its neighbours' contacts take the rest).
        let widest = (ours.iter().chain(others))
            .map(|&(i, c)| c * inv[i])
            .fold(0.0, f64::max);
        let w = w.max(0.25 * widest);
        for &(i, _) in ours.iter().chain(others) {
            self.touch(i);
        }
        let lambda = over / w;
        let length = n.length();
        for &(i, c) in ours {
            self.x[i] += n * (lambda * c * inv[i]);
            self.odometer[i] += (lambda * c * inv[i]).abs() * length;
        }
        for &(i, c) in others {
            self.x[i] -= n * (lambda * c * inv[i]);
            self.odometer[i] += (lambda * c * inv[i]).abs() * length;
        }
        let vr = velocity(self.v, ours) - velocity(self.v, others);
        let vn = vr.dot(n);
        let mut active = Active {
            ours: [(0, 0.0); 2],
            ours_count: ours.len(),
            others: [(0, 0.0); 3],
            count: others.len(),
            n,
            w,
            impulse: (-vn).max(0.0) / w,
        };
        active.ours[..ours.len()].copy_from_slice(ours);
        active.others[..others.len()].copy_from_slice(others);
        self.active.push(active);
        if vn < 0.0 {
            let j = -vn / w;
            for &(i, c) in ours {
                self.v[i] += n * (j * c * inv[i]);
            }
            for &(i, c) in others {
                self.v[i] -= n * (j * c * inv[i]);
            }
            let vt = vr - n * vn;
            let slide = vt.length();
            let stop = if slide <= mu_s * -vn {
                1.0
            } else {
                (mu * -vn / slide).min(1.0)
            };
            if slide > 0.0 {
                let k = stop / w;
                for &(i, c) in ours {
                    self.v[i] -= vt * (k * c * inv[i]);
                }
                for &(i, c) in others {
                    self.v[i] += vt * (k * c * inv[i]);
                }
            }
        }
        true
    }

    /// One more pass over the pushed contacts' velocities (projected Gauss–Seidel): each one's
    /// approach removed again, or an impulse it gave that the others have made more than
    /// needed taken back, never past none. The first pass's impulses remove each contact's
    /// approach with the others as they were; where one point of a triangle stops and its
    /// corners move unlike, that can throw a corner off; these passes settle it.
    pub(super) fn settle(&mut self) {
        let inv = self.inv;
        for c in self.active.iter_mut() {
            let (ours, others) = (&c.ours[..c.ours_count], &c.others[..c.count]);
            let vn = (velocity(self.v, ours) - velocity(self.v, others)).dot(c.n);
            let impulse = (c.impulse - vn / c.w).max(0.0);
            let j = impulse - c.impulse;
            if j == 0.0 {
                continue;
            }
            c.impulse = impulse;
            for &(i, k) in ours {
                self.v[i] += c.n * (j * k * inv[i]);
            }
            for &(i, k) in others {
                self.v[i] -= c.n * (j * k * inv[i]);
            }
        }
    }

    /// Particles `a`, `b` closer than `t`: apart along the line between them (two on one
    /// point: apart upwards).
    pub(super) fn points(&mut self, a: usize, b: usize, t: f64, friction: Friction) -> Tested {
        let d = self.x[b] - self.x[a];
        let dist2 = d.length_squared();
        if !dist2.is_finite() {
            return Tested::AGAIN;
        }
        let dist = dist2.sqrt();
        if dist2 >= t * t {
            return Tested::apart(dist, t, self.x[a]);
        }
        let n = if dist > 1e-9 * t { d / dist } else { DVec3::Y };
        Tested::pushed(self.push(&[(b, 1.0)], &[(a, 1.0)], n, t - dist, friction))
    }

    /// Particle `p` against triangle `tri`, both at `start` at the substep's start. If `p`
    /// crossed the triangle's plane inside the triangle over the substep (the signed distances
    /// to the plane at the start and now, interpolated linearly, cross zero where the
    /// interpolated point projects inside the interpolated triangle), it goes back to the side
    /// it started on, at the thickness `t`; otherwise, closer than `t` to the triangle, it
    /// goes out from its closest point.
    pub(super) fn face(
        &mut self,
        p: usize,
        tri: [u32; 3],
        start: &[DVec3],
        t: f64,
        friction: Friction,
    ) -> Tested {
        let [ia, ib, ic] = tri.map(|i| i as usize);
        let x = &*self.x;
        let (xp, a, b, c) = (x[p], x[ia], x[ib], x[ic]);
        let (p0, a0, b0, c0) = (start[p], start[ia], start[ib], start[ic]);
        let (n0, n1) = ((b0 - a0).cross(c0 - a0), (b - a).cross(c - a));
        let (d0, d1) = (n0.dot(p0 - a0), n1.dot(xp - a));
        if d0 * d1 < 0.0 {
            let (e0, e1) = (d0 / n0.length(), d1 / n1.length());
            let tau = e0 / (e0 - e1);
            let at = |s: DVec3, e: DVec3| s + (e - s) * tau;
            let crossed = plane_weights(at(p0, xp), at(a0, a), at(b0, b), at(c0, c))
                .filter(|w| w.iter().all(|&w| w >= 0.0));
            if let Some(w) = crossed {
                let n = n1 * (d0.signum() / n1.length());
                let q = a * w[0] + b * w[1] + c * w[2];
                let over = t - n.dot(xp - q);
                let others = [(ia, w[0]), (ib, w[1]), (ic, w[2])];
                return Tested::pushed(self.push(&[(p, 1.0)], &others, n, over, friction));
            }
        }
        // Past the thickness from the plane, on the side it started on: not in contact, and at
        // least as far from the triangle. Where that is little past the thickness (a particle
        // lying on a sheet, against the sheet's triangles beside the one under it), the
        // distance to the triangle itself, so the test waits longer before it runs again.
        let plane = (d1 * d1 >= t * t * n1.length_squared() && d0 * d1 >= 0.0)
            .then(|| d1.abs() / n1.length());
        if plane.is_some_and(|d| !d.is_finite()) {
            // A triangle without area: never in contact, but no distance to wait on.
            return Tested::AGAIN;
        }
        if let Some(plane) = plane.filter(|&d| d >= 1.5 * t) {
            return Tested::apart(plane, t, xp);
        }
        let w = closest_on_triangle(xp, a, b, c);
        if let Some(plane) = plane {
            let dist = (xp - (a * w[0] + b * w[1] + c * w[2])).length();
            return Tested::apart(dist.max(plane), t, xp);
        }
        let d = xp - (a * w[0] + b * w[1] + c * w[2]);
        let dist2 = d.length_squared();
        if !dist2.is_finite() {
            return Tested::AGAIN;
        }
        let dist = dist2.sqrt();
        if dist2 >= t * t {
            return Tested::apart(dist, t, xp);
        }
        let n = if dist > 1e-9 * t {
            d / dist
        } else {
            // On the triangle: out on the side it started on.
            let side = if d0 < 0.0 { -1.0 } else { 1.0 };
            (n1 * side).try_normalize().unwrap_or(DVec3::Y)
        };
        let others = [(ia, w[0]), (ib, w[1]), (ic, w[2])];
        Tested::pushed(self.push(&[(p, 1.0)], &others, n, t - dist, friction))
    }

    /// Edge `e` against edge `f`, both at `start` at the substep's start. If they crossed
    /// over the substep (at the first time their lines, each corner moving linearly, met
    /// within both edges), `e` goes back to the side of `f` it was on just before, along their
    /// common normal then, at the thickness `t`, from the points where they met; otherwise,
    /// closer than `t`, they go apart at their closest points.
    pub(super) fn edges(
        &mut self,
        [ia, ib]: [usize; 2],
        [ic, id]: [usize; 2],
        start: &[DVec3],
        t: f64,
        friction: Friction,
    ) -> Tested {
        let x = &*self.x;
        let (a, b, c, d) = (x[ia], x[ib], x[ic], x[id]);
        let p0 = [ia, ib, ic, id].map(|i| start[i]);
        // No point of either edge moved further than its ends did: edges further apart at the
        // start than the two ends' largest moves together cannot have met.
        let (s0, u0) = segment_weights(p0[0], p0[1], p0[2], p0[3]);
        let gap0 = (p0[0] + (p0[1] - p0[0]) * s0) - (p0[2] + (p0[3] - p0[2]) * u0);
        let moved = |i: usize, e: DVec3| (e - p0[i]).length();
        let reach = moved(0, a).max(moved(1, b)) + moved(2, c).max(moved(3, d));
        let (roots, count) = if gap0.length() > reach {
            ([0.0; 3], 0)
        } else {
            coplanar_times(p0, [a, b, c, d])
        };
        for &tau in &roots[..count] {
            let q = [0, 1, 2, 3].map(|i| p0[i] + ([a, b, c, d][i] - p0[i]) * tau);
            let Some((s, u)) = line_parameters(q[0], q[1], q[2], q[3]) else {
                continue;
            };
            // Coplanar and not parallel, the lines meet: within both edges, they met (the
            // quarter thickness allows for the time's rounding).
            let apart = (q[0] + (q[1] - q[0]) * s) - (q[2] + (q[3] - q[2]) * u);
            if !((0.0..=1.0).contains(&s)
                && (0.0..=1.0).contains(&u)
                && apart.length_squared() < 0.0625 * t * t)
            {
                continue;
            }
            // Just before, `e`'s point was on the side of `f`'s that its move relative to it,
            // along their normal then, leaves behind.
            let m = (q[1] - q[0]).cross(q[3] - q[2]);
            let vp = (b - p0[1]) * s + (a - p0[0]) * (1.0 - s);
            let vq = (d - p0[3]) * u + (c - p0[2]) * (1.0 - u);
            let closing = (vp - vq).dot(m);
            let Some(n) = (m * -closing.signum()).try_normalize() else {
                break;
            };
            let (p, q) = (a + (b - a) * s, c + (d - c) * u);
            let over = t - n.dot(p - q);
            if over <= 0.0 {
                break;
            }
            let (ours, others) = ([(ia, 1.0 - s), (ib, s)], [(ic, 1.0 - u), (id, u)]);
            return Tested::pushed(self.push(&ours, &others, n, over, friction));
        }
        let (s, u) = segment_weights(a, b, c, d);
        let (p, q) = (a + (b - a) * s, c + (d - c) * u);
        let dist2 = (p - q).length_squared();
        if !dist2.is_finite() {
            return Tested::AGAIN;
        }
        let dist = dist2.sqrt();
        if dist2 >= t * t {
            return Tested::apart(dist, t, a);
        }
        let n = if dist > 1e-9 * t {
            (p - q) / dist
        } else {
            // On each other: apart on the side `e` started on.
            let m = (b - a).cross(d - c);
            let side = -m.dot(p0[2] - p0[0]).signum();
            (m * side).try_normalize().unwrap_or(DVec3::Y)
        };
        let (ours, others) = ([(ia, 1.0 - s), (ib, s)], [(ic, 1.0 - u), (id, u)]);
        Tested::pushed(self.push(&ours, &others, n, t - dist, friction))
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use crate::buffers::Packed;
    use crate::collide::search::tests::{bits, crumpled};
    use crate::collide::CollideStage;

    /// A folded sheet and a sheet sinking through it at 0.5 m/s, every particle shaken by up
    /// to 0.3 mm a substep, 150 substeps: the pass that lets a contact found apart wait gives
    /// the bits of the pass that tests every candidate every substep, and most tests wait.
    #[test]
    fn a_contact_found_apart_waits_and_the_pass_is_the_same() {
        let run = |wait: bool| -> (Vec<[u64; 6]>, u64, usize) {
            let (mut stage, mut packed): (CollideStage, Packed) = crumpled();
            let n = packed.x.len();
            let sinking = |i: usize| stage.members[i].1 == 1;
            packed.v = (0..n)
                .map(|i| DVec3::new(0.0, if sinking(i) { -0.5 } else { 0.0 }, 0.0))
                .collect();
            stage.moves.reset(n);
            stage.before_v.resize(n, DVec3::ZERO);
            stage.start = packed.x.clone();
            stage.begin_frame(&packed).unwrap();
            let mut r = super::super::uniform(7);
            let (h, gravity) = (1.0 / 600.0, DVec3::ZERO);
            let mut candidates = 0;
            for _ in 0..150 {
                for i in 0..n {
                    let shake = DVec3::new(r(), r(), r()) * 3e-4;
                    packed.x[i] += packed.v[i] * h + shake;
                }
                if !wait {
                    stage.due.iter_mut().for_each(|d| d.1 = f64::NEG_INFINITY);
                }
                stage.project(&mut packed, gravity).unwrap();
                candidates += stage.due.len();
            }
            let bits = bits(&packed);
            (bits, stage.waited, candidates)
        };
        let (every, none, _) = run(false);
        let (waits, waited, candidates) = run(true);
        println!("{waited} of {candidates} tests waited");
        assert!(none == 0);
        assert!(every == waits);
        assert!(waited * 2 > candidates as u64, "{waited} of {candidates}");
    }
}
