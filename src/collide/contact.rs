//! One contact's response: a particle pushed out from a point of others (a particle, or a
//! point of a triangle by its barycentric weights) to the thickness, by inverse mass, its
//! approach removed and its sliding slowed by Coulomb friction; and the particle–triangle
//! test, swept along the substep.

use glam::DVec3;

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
}

/// A contact the pass pushed: the particle, the point's corners and weights (a particle
/// against a particle has one, weight 1, and two unused), the normal, `W`, and the normal
/// impulse (per unit of `W`) it has given so far.
#[derive(Clone, Copy, Debug)]
pub(super) struct Active {
    p: usize,
    others: [(usize, f64); 3],
    count: usize,
    n: DVec3,
    w: f64,
    impulse: f64,
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

    /// Particle `p` against the point `q = Σ wᵢ x[i]` of `others` (weights summing to 1),
    /// `over` (m) closer along the normal `n` (from `q` towards `p`) than the thickness: the
    /// gap opened by a move along `n` of generalised inverse mass `W = w_p + Σ wᵢ² wᵢ`
    /// (`λ = over / W`, `p` by `λ w_p`, each other by `−λ wᵢ w_i`), then the approach and
    /// the sliding removed the same way, so the momentum is kept. Returns whether it moved
    /// (nothing does where every mass is held).
    pub(super) fn push(
        &mut self,
        p: usize,
        others: &[(usize, f64)],
        n: DVec3,
        over: f64,
        (mu, mu_s): Friction,
    ) -> bool {
        let inv = self.inv;
        let wp = inv[p];
        let w = wp + others.iter().map(|&(i, w)| w * w * inv[i]).sum::<f64>();
        if w.is_nan() || w <= 0.0 {
            return false;
        }
        // A point near a held corner of a triangle whose other corners are free, against a
        // held particle, would throw the free corner by `over / bᵢ`: at most 4 `over` (the
        // point then moves less than `over`; its neighbours' contacts take the rest).
        let widest = others.iter().map(|&(i, c)| c * inv[i]).fold(wp, f64::max);
        let w = w.max(0.25 * widest);
        self.touch(p);
        for &(i, _) in others {
            self.touch(i);
        }
        let lambda = over / w;
        self.x[p] += n * (lambda * wp);
        for &(i, c) in others {
            self.x[i] -= n * (lambda * c * inv[i]);
        }
        let vq: DVec3 = others.iter().map(|&(i, c)| self.v[i] * c).sum();
        let vr = self.v[p] - vq;
        let vn = vr.dot(n);
        let mut padded = [(p, 0.0); 3];
        padded[..others.len()].copy_from_slice(others);
        self.active.push(Active {
            p,
            others: padded,
            count: others.len(),
            n,
            w,
            impulse: (-vn).max(0.0) / w,
        });
        if vn < 0.0 {
            let j = -vn / w;
            self.v[p] += n * (j * wp);
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
                self.v[p] -= vt * (k * wp);
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
            let others = &c.others[..c.count];
            let vq: DVec3 = others.iter().map(|&(i, k)| self.v[i] * k).sum();
            let vn = (self.v[c.p] - vq).dot(c.n);
            let impulse = (c.impulse - vn / c.w).max(0.0);
            let j = impulse - c.impulse;
            if j == 0.0 {
                continue;
            }
            c.impulse = impulse;
            self.v[c.p] += c.n * (j * inv[c.p]);
            for &(i, k) in others {
                self.v[i] -= c.n * (j * k * inv[i]);
            }
        }
    }

    /// Particles `a`, `b` closer than `t`: apart along the line between them (two on one
    /// point: apart upwards).
    pub(super) fn points(&mut self, a: usize, b: usize, t: f64, friction: Friction) -> bool {
        let d = self.x[b] - self.x[a];
        let dist2 = d.length_squared();
        if dist2 >= t * t || !dist2.is_finite() {
            return false;
        }
        let dist = dist2.sqrt();
        let n = if dist > 1e-9 * t { d / dist } else { DVec3::Y };
        self.push(b, &[(a, 1.0)], n, t - dist, friction)
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
    ) -> bool {
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
                return self.push(p, &others, n, over, friction);
            }
        }
        // Past the thickness from the plane, on the side it started on: not in contact.
        if d1 * d1 >= t * t * n1.length_squared() && d0 * d1 >= 0.0 {
            return false;
        }
        let w = closest_on_triangle(xp, a, b, c);
        let d = xp - (a * w[0] + b * w[1] + c * w[2]);
        let dist2 = d.length_squared();
        if dist2 >= t * t || !dist2.is_finite() {
            return false;
        }
        let dist = dist2.sqrt();
        let n = if dist > 1e-9 * t {
            d / dist
        } else {
            // On the triangle: out on the side it started on.
            let side = if d0 < 0.0 { -1.0 } else { 1.0 };
            (n1 * side).try_normalize().unwrap_or(DVec3::Y)
        };
        let others = [(ia, w[0]), (ib, w[1]), (ic, w[2])];
        self.push(p, &others, n, t - dist, friction)
    }
}
