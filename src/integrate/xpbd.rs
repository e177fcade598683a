//! Small-step XPBD: springs as compliant distance constraints, one Gauss–Seidel iteration per
//! substep over the colouring (Macklin et al., "Small Steps in Physics Simulation").
//!
//! Per substep: `x̃ = x + h v + h² g`; for each spring, `C = |x_b − x_a| − l0`, compliance
//! `α̃ = 1/(κ h²)`, damping `γ = c/(κ h)`, and
//! `Δλ = −(C + γ ∇C·(x − x_prev)) / ((1 + γ)(w_a + w_b) + α̃)` moves `x_a −= w_a Δλ n`,
//! `x_b += w_b Δλ n`; then `v = (x − x_prev)/h`.

use glam::DVec3;
use rayon::prelude::*;

use super::{PAR_CHUNK, PAR_MIN};
use crate::buffers::Packed;

/// Scratch: positions at the start of the substep.
#[derive(Clone, Debug, Default)]
pub struct Xpbd {
    prev: Vec<DVec3>,
}

impl Xpbd {
    pub fn resize(&mut self, n: usize) {
        self.prev.resize(n, DVec3::ZERO);
    }

    pub fn step(&mut self, packed: &mut Packed, g: DVec3, h: f64) {
        self.prev.copy_from_slice(&packed.x);
        let Packed {
            x,
            v,
            inv_mass,
            springs,
            colouring,
            ..
        } = packed;
        let predict = |((xi, vi), &w): ((&mut DVec3, &mut DVec3), &f64)| {
            if w != 0.0 {
                *vi += h * g;
                *xi += h * *vi;
            }
        };
        if x.len() < PAR_MIN {
            x.iter_mut()
                .zip(v.iter_mut())
                .zip(inv_mass.iter())
                .for_each(predict);
        } else {
            x.par_iter_mut()
                .zip(v.par_iter_mut())
                .zip(inv_mass.par_iter())
                .with_min_len(PAR_CHUNK)
                .for_each(predict);
        }
        let prev = &self.prev;
        let inv_mass = &inv_mass[..];
        let springs = &springs[..];
        let xs = super::gauss_seidel::Disjoint::new(&mut x[..]);
        for c in 0..colouring.colours() {
            let members = &colouring.springs
                [colouring.offsets[c] as usize..colouring.offsets[c + 1] as usize];
            let body = |&k: &u32| {
                let s = &springs[k as usize];
                if s.stiffness == 0.0 {
                    // No compliance to speak of: a pure damper has no XPBD form here.
                    return;
                }
                let (a, b) = (s.a as usize, s.b as usize);
                // SAFETY: springs of one colour have pairwise distinct ends, and a != b.
                let (xa, xb) = unsafe { (xs.get(a), xs.get(b)) };
                let (wa, wb) = (inv_mass[a], inv_mass[b]);
                let d = *xb - *xa;
                let len = d.length();
                let n = d / len;
                let compliance = 1.0 / (s.stiffness * h * h);
                let gamma = s.damping / (s.stiffness * h);
                let rel = n.dot((*xb - prev[b]) - (*xa - prev[a]));
                let dl = -((len - s.rest) + gamma * rel) / ((1.0 + gamma) * (wa + wb) + compliance);
                *xa -= wa * dl * n;
                *xb += wb * dl * n;
            };
            if members.len() < PAR_MIN {
                members.iter().for_each(body);
            } else {
                members.par_iter().with_min_len(PAR_CHUNK).for_each(body);
            }
        }
        let update = |(i, (vi, xi)): (usize, (&mut DVec3, &DVec3))| {
            if inv_mass[i] != 0.0 {
                *vi = (*xi - prev[i]) / h;
            }
        };
        if v.len() < PAR_MIN {
            v.iter_mut().zip(x.iter()).enumerate().for_each(update);
        } else {
            v.par_iter_mut()
                .zip(x.par_iter())
                .enumerate()
                .with_min_len(PAR_CHUNK)
                .for_each(update);
        }
    }
}
