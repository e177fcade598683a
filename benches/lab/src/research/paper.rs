//! The paper's spring step as printed, kept only so reports can show what the corrections change.
//!
//! Equations (numbers are the paper's): amplitude from undamped energy (eq. 9), phase
//! `θ = arcsin(δ/A)` (eq. 12), velocity change of eq. 14's second line (too small by
//! `μ/(2(m_i+m_j))`), the mass split of eq. 17, the damped integral of eq. 19–23 (only `κδ`
//! integrated, `1/(α²+ω_d²)` where `e^(−αh)` belongs) and `ω_d` of eq. 27 with 2 where 4
//! belongs. Algorithm 1's extra factor `h` on the velocity change lives in the particle
//! update ([`super::solver`]).

use harmonic::internals::buffers::reduced_mass;

/// Per-spring constants of the printed method.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PaperSpring {
    /// `κ/μ`
    pub omega0_sq: f64,
    /// `c/(2μ)`
    pub alpha: f64,
    /// `ω_d` of eq. 27 as printed.
    pub omega_d: f64,
    /// The printed factor `μ/(2(m_i+m_j))` of eq. 14.
    pub scale: f64,
    pub damped: bool,
}

/// Why the printed equations have no value for a spring.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PaperUndefined {
    /// The true damping ratio; eq. 27 as printed takes the square root of `1 − 2ζ²`.
    pub zeta: f64,
}

impl PaperSpring {
    /// `m_a`, `m_b` are the end masses (`f64::INFINITY` for a pinned end).
    pub fn new(stiffness: f64, damping: f64, m_a: f64, m_b: f64) -> Result<Self, PaperUndefined> {
        let mu = reduced_mass(m_a, m_b);
        let omega0_sq = stiffness / mu;
        let alpha = damping / (2.0 * mu);
        // Eq. 27: ζ² = c²(m_i+m_j)/(2κ m_i m_j), i.e. twice the true ζ².
        let zeta_true_sq = damping * damping / (4.0 * stiffness * mu);
        let zeta_printed_sq = 2.0 * zeta_true_sq;
        let omega_d = omega0_sq.sqrt() * (1.0 - zeta_printed_sq).sqrt();
        if !omega_d.is_finite() {
            return Err(PaperUndefined {
                zeta: zeta_true_sq.sqrt(),
            });
        }
        // A pinned end counts with the free end's mass only, so the printed factor stays finite.
        let total = [m_a, m_b].iter().filter(|m| m.is_finite()).sum::<f64>();
        let scale = mu / (2.0 * total);
        Ok(Self {
            omega0_sq,
            alpha,
            omega_d,
            scale,
            damped: damping > 0.0,
        })
    }

    /// The printed velocity change `φ` for stretch `δ` and stretch rate `δ̇`.
    pub fn phi(&self, delta: f64, delta_dot: f64, h: f64) -> f64 {
        // Eq. 9: amplitude from the undamped energy, even when damped.
        let amp = (delta * delta + delta_dot * delta_dot / self.omega0_sq).sqrt();
        if amp == 0.0 {
            return 0.0;
        }
        // Eq. 12: the phase loses the sign of δ̇ (cos θ ≥ 0 always).
        let theta = (delta / amp).clamp(-1.0, 1.0).asin();
        let w = self.omega_d;
        let true_phi = if !self.damped {
            // (1/μ)∫ −κ A sin(ωt+θ) dt = A ω (cos(ωh+θ) − cos θ)
            amp * w * ((w * h + theta).cos() - theta.cos())
        } else {
            // Eq. 19–23: only κδ is integrated, and the end term carries 1/(α²+ω_d²) instead of e^(−αh).
            let a = self.alpha;
            let k2 = a * a + w * w;
            let g = |t: f64| -a * (w * t + theta).sin() - w * (w * t + theta).cos();
            let integral = (g(h) / k2 - g(0.0)) / k2;
            -self.omega0_sq * amp * integral
        };
        self.scale * true_phi
    }
}
