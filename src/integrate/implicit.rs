//! Implicit Euler (Baraff–Witkin): one Newton step, solved matrix-free by conjugate gradients.
//!
//! `(M − h D − h² K) Δv = h (f + h K v)`, then `v += Δv`, `x += h v`. Per spring, with unit
//! axis `n`, length `l` and `t = max(0, 1 − l0/l)` (compressed springs get no transverse
//! stiffness, which keeps the matrix positive definite):
//! `−K_s = κ [n nᵀ + t (I − n nᵀ)]`, `−D_s = c n nᵀ`, so the spring's block of the system is
//! `B_s = h c n nᵀ + h² κ [n nᵀ + t (I − n nᵀ)]`, added at `(a,a)` and `(b,b)` and subtracted at
//! `(a,b)` and `(b,a)`. Pinned particles are held (`Δv = 0`).

use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

use super::par;
use crate::buffers::Packed;

/// Relative residual at which CG stops. On the 128×128 bench cloth at 30 steps/s, 1e-5 moves
/// the state at t = 1 s by under 1e-10 m from a solve to 1e-10, at about 60 % of its cost.
pub const CG_TOLERANCE: f64 = 1e-5;
/// CG iteration cap per step, against a hang only: a stiff cloth at large steps needs hundreds
/// of iterations under the diagonal preconditioner (a cap of 200 left 20–80 % of the residual
/// there).
pub const CG_MAX_ITERATIONS: usize = 4000;

/// One spring's block of the linearised system, `B_s = α n nᵀ + β I` with
/// `α = hs c + hs² κ (1 − t)` and `β = hs² κ t`, and its ends: all a product reads of a spring,
/// in one record (the products are most of a step, and bound by what they read).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Block {
    pub(super) a: u32,
    pub(super) b: u32,
    pub(super) n: DVec3,
    pub(super) alpha: f64,
    pub(super) beta: f64,
}

impl Block {
    /// `B_s u`.
    #[inline(always)]
    fn apply(&self, u: DVec3) -> DVec3 {
        self.alpha * self.n.dot(u) * self.n + self.beta * u
    }
}

/// Scratch for one implicit step, sized at prepare.
#[derive(Clone, Debug, Default)]
pub struct Implicit {
    /// Per spring: its block at the current state (zero for a degenerate spring).
    pub(super) block: Vec<Block>,
    /// Per spring: a product's per-spring term.
    pub(super) term: Vec<DVec3>,
    pub(super) rhs: Vec<DVec3>,
    pub(super) dv: Vec<DVec3>,
    r: Vec<DVec3>,
    z: Vec<DVec3>,
    p: Vec<DVec3>,
    ap: Vec<DVec3>,
    /// Diagonal preconditioner (see [`Self::linearise`]).
    pub(super) precond: Vec<DVec3>,
    partial: Vec<f64>,
    /// CG iterations of the last step.
    pub last_iterations: usize,
}

/// Chunk size for deterministic dot products (same partial sums whatever the thread count).
const DOT_CHUNK: usize = 2048;

impl Implicit {
    pub fn resize(&mut self, n: usize, m: usize) {
        self.block.resize(m, Block::default());
        self.term.resize(m, DVec3::ZERO);
        for v in [
            &mut self.rhs,
            &mut self.dv,
            &mut self.r,
            &mut self.z,
            &mut self.p,
            &mut self.ap,
            &mut self.precond,
        ] {
            v.resize(n, DVec3::ZERO);
        }
        self.partial.resize(n.div_ceil(DOT_CHUNK), 0.0);
    }

    pub fn step(&mut self, packed: &mut Packed, g: super::External<'_>, h: f64) {
        let degenerate = self.linearise(packed, g, h, h, false);
        self.solve(packed);
        self.finish(packed, h, 1.0, degenerate);
    }

    /// Linearises the springs at the current state for the system `A Δv = rhs` with
    /// `A = M − hs D − hs² K` and `rhs = h (f + hs K v)` (`hs = h` for implicit Euler, `θ h` for a
    /// θ-step): fills the per-spring geometry, `rhs` and the preconditioner: the inverse of
    /// `A`'s diagonal, or with `l1` of its absolute row sums (l1-Jacobi). Returns whether a
    /// degenerate spring left the system.
    pub(super) fn linearise(
        &mut self,
        packed: &Packed,
        g: super::External<'_>,
        h: f64,
        hs: f64,
        l1: bool,
    ) -> bool {
        let springs = &packed.springs;
        let (x, v) = (&packed.x, &packed.v);
        let degenerate = AtomicBool::new(false);
        // Geometry, and per spring the force term `f_s + h K_s (v_b − v_a)` acting on b.
        par::each2(&mut self.block, &mut self.term, |k, blk, term| {
            let s = &springs[k];
            let (a, b) = (s.a as usize, s.b as usize);
            let d = x[b] - x[a];
            let len = d.length();
            // One division, not four.
            let inv = 1.0 / len;
            let nn = d * inv;
            let t = (1.0 - s.rest * inv).max(0.0);
            *blk = Block {
                a: s.a,
                b: s.b,
                n: nn,
                alpha: hs * s.damping + hs * hs * s.stiffness * (1.0 - t),
                beta: hs * hs * s.stiffness * t,
            };
            let dv = v[b] - v[a];
            let force = -(s.stiffness * (len - s.rest) + s.damping * nn.dot(dv)) * nn;
            let k_dv = -s.stiffness * (nn * nn.dot(dv) + t * (dv - nn * nn.dot(dv)));
            *term = force + hs * k_dv;
            if !(term.is_finite() && nn.is_finite()) {
                // The quarantine's guard (see `integrate::guard`): a degenerate spring leaves
                // the solve, whose dot products would carry its NaN to every particle, and
                // only its ends are marked, below.
                *blk = Block {
                    a: s.a,
                    b: s.b,
                    ..Block::default()
                };
                *term = DVec3::ZERO;
                degenerate.store(true, Ordering::Relaxed);
            }
        });
        // rhs = h (m g + Σ ±term); preconditioner = 1 / diag(M + Σ B_s).
        {
            let (block, term) = (&self.block, &self.term);
            par::each2(&mut self.rhs, &mut self.precond, |i, rhs, pre| {
                if packed.inv_mass[i] == 0.0 {
                    *rhs = DVec3::ZERO;
                    *pre = DVec3::ZERO;
                    return;
                }
                let (lo, hi) = (
                    packed.incidence.offsets[i] as usize,
                    packed.incidence.offsets[i + 1] as usize,
                );
                let mut f = packed.mass(i) * g.at(i);
                let mut diag = DVec3::splat(packed.mass(i));
                for e in lo..hi {
                    let k = packed.incidence.spring[e] as usize;
                    let sign = packed.incidence.coef[e].signum();
                    f += sign * term[k];
                    let Block { n, alpha, beta, .. } = block[k];
                    diag += if l1 {
                        // The block is α n nᵀ + β I (α, β ≥ 0); its rows' absolute sums are
                        // α |n| ‖n‖₁ + β, once on the diagonal block, once off it.
                        let a = n.abs();
                        2.0 * (alpha * a * (a.x + a.y + a.z) + DVec3::splat(beta))
                    } else {
                        alpha * n * n + DVec3::splat(beta)
                    };
                }
                *rhs = h * f;
                *pre = diag.recip();
            });
        }
        degenerate.into_inner()
    }

    /// With the solved `dv`: `x += h (v₀ + θ Δv)`, `v += Δv`; the ends of a degenerate spring
    /// get NaN velocities for the quarantine.
    pub(super) fn finish(&mut self, packed: &mut Packed, h: f64, theta: f64, degenerate: bool) {
        let dv = &self.dv;
        let Packed { x, v, inv_mass, .. } = packed;
        par::each2(x, v, |i, xi, vi| {
            if inv_mass[i] != 0.0 {
                *xi += h * (*vi + theta * dv[i]);
                *vi += dv[i];
            }
        });
        if degenerate {
            for blk in &self.block {
                if blk.n == DVec3::ZERO {
                    for e in [blk.a as usize, blk.b as usize] {
                        if inv_mass[e] != 0.0 {
                            v[e] = DVec3::NAN;
                        }
                    }
                }
            }
        }
    }

    /// Preconditioned CG on `A Δv = rhs`, starting from `Δv = 0`.
    pub(super) fn solve(&mut self, packed: &Packed) {
        self.dv.iter_mut().for_each(|d| *d = DVec3::ZERO);
        self.r.copy_from_slice(&self.rhs);
        apply_precond(&self.precond, &self.r, &mut self.z);
        self.p.copy_from_slice(&self.z);
        let mut rz = dot(&self.r, &self.z, &mut self.partial);
        let r0 = dot(&self.rhs, &self.rhs, &mut self.partial).sqrt();
        self.last_iterations = 0;
        if r0 == 0.0 {
            return;
        }
        for it in 1..=CG_MAX_ITERATIONS {
            self.multiply(packed);
            let pap = dot(&self.p, &self.ap, &mut self.partial);
            if pap <= 0.0 || !pap.is_finite() {
                break;
            }
            let alpha = rz / pap;
            axpy(alpha, &self.p, &mut self.dv);
            axpy(-alpha, &self.ap, &mut self.r);
            self.last_iterations = it;
            if dot(&self.r, &self.r, &mut self.partial).sqrt() <= CG_TOLERANCE * r0 {
                break;
            }
            apply_precond(&self.precond, &self.r, &mut self.z);
            let rz_new = dot(&self.r, &self.z, &mut self.partial);
            let beta = rz_new / rz;
            rz = rz_new;
            let z = &self.z;
            par::each(&mut self.p, |i, pi| *pi = z[i] + beta * *pi);
        }
    }

    /// `ap = A p` without forming `A`.
    fn multiply(&mut self, packed: &Packed) {
        product(packed, &self.block, &mut self.term, &self.p, &mut self.ap);
    }
}

/// `out = A p` without forming `A` (`A = M − hs D − hs² K` at the linearised state, `block`);
/// `term` is per-spring scratch.
pub(super) fn product(
    packed: &Packed,
    block: &[Block],
    term: &mut [DVec3],
    p: &[DVec3],
    out: &mut [DVec3],
) {
    par::each(term, |k, t_out| {
        let blk = &block[k];
        *t_out = blk.apply(p[blk.b as usize] - p[blk.a as usize]);
    });
    let term = &*term;
    let inc = &packed.incidence;
    par::each(out, |i, o| {
        if packed.inv_mass[i] == 0.0 {
            *o = DVec3::ZERO;
            return;
        }
        // (A p)_b gets +B(p_b − p_a), (A p)_a gets −B(p_b − p_a).
        let (lo, hi) = (inc.offsets[i] as usize, inc.offsets[i + 1] as usize);
        let mut sum = packed.mass(i) * p[i];
        for e in lo..hi {
            sum += inc.coef[e].signum() * term[inc.spring[e] as usize];
        }
        *o = sum;
    });
}

fn apply_precond(pre: &[DVec3], r: &[DVec3], z: &mut [DVec3]) {
    par::each(z, |i, zi| *zi = r[i] * pre[i]);
}

fn axpy(alpha: f64, x: &[DVec3], y: &mut [DVec3]) {
    par::each(y, |i, yi| *yi += alpha * x[i]);
}

/// Dot product with fixed chunking, so the result is bit-identical for any thread count.
fn dot(a: &[DVec3], b: &[DVec3], partial: &mut [f64]) -> f64 {
    let body = |(c, out): (usize, &mut f64)| {
        let lo = c * DOT_CHUNK;
        let hi = (lo + DOT_CHUNK).min(a.len());
        *out = (lo..hi).map(|i| a[i].dot(b[i])).sum();
    };
    // Few partial sums, long chunks: go parallel on the length of the vectors.
    if a.len() < par::PAR_MIN {
        partial.iter_mut().enumerate().for_each(body);
    } else {
        partial.par_iter_mut().enumerate().for_each(body);
    }
    partial.iter().sum()
}
