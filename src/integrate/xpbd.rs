//! Small-step XPBD: springs as compliant distance constraints, one Gauss–Seidel iteration per
//! substep over the colouring (Macklin et al., "Small Steps in Physics Simulation").
//!
//! Per substep: `x̃ = x + h v + h² g`; for each spring, `C = |x_b − x_a| − l0`, compliance
//! `α̃ = 1/(κ h²)`, damping `γ = c/(κ h)`, and
//! `Δλ = −(C + γ ∇C·(x − x_prev)) / ((1 + γ)(w_a + w_b) + α̃)` moves `x_a −= w_a Δλ n`,
//! `x_b += w_b Δλ n`; then `v = (x − x_prev)/h`.

use glam::DVec3;

use super::gauss_seidel::{self, Disjoint};
use super::par;
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

    pub fn step(&mut self, packed: &mut Packed, g: super::External<'_>, h: f64) {
        self.prev.copy_from_slice(&packed.x);
        // Predict: x̃ = x + h (v + h g).
        gauss_seidel::add_gravity(packed, g, h);
        gauss_seidel::drift(packed, h);
        let Packed {
            x,
            v,
            inv_mass,
            springs,
            colouring,
            ..
        } = packed;
        let prev = &self.prev;
        let inv_mass = &inv_mass[..];
        let springs = &springs[..];
        let xs = Disjoint::new(&mut x[..]);
        for c in 0..colouring.colours() {
            par::each_of(colouring.members(c), |&k| {
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
                // The quarantine's guard, on the position correction (see `guard`).
                let dx = dl * n;
                if dx.is_finite() {
                    *xa -= wa * dx;
                    *xb += wb * dx;
                } else if xa.is_finite() && xb.is_finite() {
                    *xa = DVec3::NAN;
                    *xb = DVec3::NAN;
                }
            });
        }
        let x = &x[..];
        par::each(v, |i, vi| {
            if inv_mass[i] != 0.0 {
                *vi = (x[i] - prev[i]) / h;
            }
        });
    }
}
