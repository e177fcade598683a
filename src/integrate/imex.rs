//! Symplectic Euler with the damping taken linearly implicit (explicit elastic, implicit
//! damping, as in Bridson, Marino and Fedkiw's cloth).
//!
//! A step kicks every velocity by the springs' stiffness and gravity (`v* = v + h M⁻¹ f_k(x)
//! + g h`), then applies the damping force at `v*` over an enlarged mass, and drifts:
//!
//! ```text
//! v' = v* + h M'⁻¹ f_c(x, v*),   M'_i = m_i + 2 h Σ_{s ∋ i} c_s,   x' = x + h v'
//! ```
//!
//! The pass is one Jacobi iteration of backward Euler's damping solve `(M + h C) v' = M v*`
//! with a diagonal large enough that it always contracts: `C ≼ 2 diag(Σ c)` (each spring's
//! `c (n·(u_b − u_a))² ≤ 2c (|u_a|² + |u_b|²)`), so every eigenvalue of `h M'⁻¹ C` lies in
//! [0, 1) and no velocity is reversed, whatever the damping. For one spring between equal
//! masses it is backward Euler's damping exactly. Statics are symplectic Euler's (the damping
//! vanishes at rest); the stiffest modes, which carry the most damping, no longer set the
//! step: symplectic Euler's explicit damping is what lowers its limit on damped networks.

use glam::DVec3;

use super::harmonic::{self, Linear};
use super::par;
use crate::buffers::Packed;

/// Per-scene coefficients of the damping pass.
#[derive(Clone, Debug, Default)]
pub struct Imex {
    /// Per spring, the stiffness impulse: `φ = −ω0² h δ`.
    pub stiffness: Vec<Linear>,
    /// Per spring, the damping impulse at `v*`: `φ = −2α h δ̇` (empty when no spring is damped).
    pub damping: Vec<Linear>,
    /// Per particle, `m_i / M'_i`: the share of its damping change it takes.
    pub relax: Vec<f64>,
}

impl Imex {
    pub fn prepare(&mut self, packed: &Packed, h: f64) {
        self.stiffness.clear();
        self.stiffness.extend(
            packed
                .springs
                .iter()
                .map(|s| harmonic::euler(s.omega0_sq(), 0.0, h)),
        );
        self.damping.clear();
        self.relax.clear();
        if packed.springs.iter().all(|s| s.damping == 0.0) {
            return;
        }
        self.damping.extend(
            packed
                .springs
                .iter()
                .map(|s| harmonic::euler(0.0, s.alpha(), h)),
        );
        // Σ c over each particle's springs, then m / (m + 2 h Σ c) = 1 / (1 + 2 h w Σ c).
        let mut sum_c = vec![0.0; packed.particle_count()];
        for s in &packed.springs {
            sum_c[s.a as usize] += s.damping;
            sum_c[s.b as usize] += s.damping;
        }
        self.relax.extend(
            sum_c
                .iter()
                .zip(&packed.inv_mass)
                .map(|(c, w)| 1.0 / (1.0 + 2.0 * h * w * c)),
        );
    }
}

/// `v += scale_i · Σ dv + g h` on the free particles outside grids; with `drift`, then `x += h v`.
pub(super) fn kick(
    packed: &mut Packed,
    sdv: &[DVec3],
    scale: Option<&[f64]>,
    g: DVec3,
    h: f64,
    drift: bool,
) {
    let Packed {
        x,
        v,
        inv_mass,
        incidence,
        loose,
        ..
    } = packed;
    let (inv_mass, inc) = (&inv_mass[..], &*incidence);
    for range in loose.iter() {
        let first = range.start;
        let (x, v) = (&mut x[range.clone()], &mut v[range.clone()]);
        par::each2(x, v, |k, xi, vi| {
            let i = first + k;
            if inv_mass[i] == 0.0 {
                return;
            }
            let dv = inc.sum(sdv, i);
            *vi += match scale {
                Some(s) => s[i] * dv,
                None => dv,
            } + g * h;
            if drift {
                *xi += h * *vi;
            }
        });
    }
}
