//! The closed-form step of one damped spring, `μ δ̈ = −κ δ − c δ̇`, over a step `h`.
//!
//! This module is the single definition of the spring math. Over a fixed `h` the exact
//! solution is linear in the initial stretch and stretch rate, so each spring's step reduces
//! to four coefficients computed once per (spring, h) at gather:
//!
//! ```text
//! φ = δ̇(h) − δ̇0                 = p δ0 + q δ̇0      (change of stretch rate)
//! D = δ(h) − δ0 − δ̇0 h          = r δ0 + s δ̇0      (stretch beyond free drift)
//! ```
//!
//! The hot loop then costs the same as symplectic Euler's; only the coefficients differ.

/// Linear per-spring step coefficients: `φ = p δ + q δ̇`, `D = r δ + s δ̇`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Linear {
    pub p: f64,
    pub q: f64,
    pub r: f64,
    pub s: f64,
}

impl Linear {
    /// `φ = p δ + q δ̇`: the change of relative velocity along the axis.
    #[inline(always)]
    pub fn phi(&self, delta: f64, delta_dot: f64) -> f64 {
        self.p * delta + self.q * delta_dot
    }
}

/// Below this `|β²| h²` the Taylor series replaces cos/sin and cosh/sinh, continuous across ζ = 1.
pub const SERIES_LIMIT: f64 = 0.25;
/// Terms of the series in `z = β² h²`; at `|z| < 0.25` the 9th term is below 1e-18.
const SERIES_TERMS: usize = 8;

/// `e^(−αh)·C − 1` and `e^(−αh)·S`, and `e^(−αh)·S − h`, for `ω0² = κ/μ`, `α = c/(2μ)`.
///
/// Each regime is written so that nothing overflows (over-damped with `αh = 1e6`) and the
/// "minus one" parts keep their relative precision as `h → 0`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Propagator {
    /// `e^(−αh) C − 1`
    pub ec_m1: f64,
    /// `e^(−αh) S`
    pub es: f64,
    /// `e^(−αh) S − h`
    pub es_mh: f64,
}

impl Propagator {
    pub fn new(omega0_sq: f64, alpha: f64, h: f64) -> Self {
        let beta_sq = omega0_sq - alpha * alpha;
        let z = beta_sq * h * h;
        let e = (-alpha * h).exp();
        let e_m1 = (-alpha * h).exp_m1();
        if z.abs() < SERIES_LIMIT {
            // C = Σ (−z)^k/(2k)!, S/h = Σ (−z)^k/(2k+1)!; sums start at k = 1 to keep C−1, S/h−1.
            let (mut c_m1, mut s_m1) = (0.0, 0.0);
            let (mut tc, mut ts) = (1.0, 1.0);
            for k in 1..=SERIES_TERMS {
                let kf = k as f64;
                tc *= -z / ((2.0 * kf - 1.0) * (2.0 * kf));
                ts *= -z / ((2.0 * kf) * (2.0 * kf + 1.0));
                c_m1 += tc;
                s_m1 += ts;
            }
            Self {
                ec_m1: e * c_m1 + e_m1,
                es: e * h * (1.0 + s_m1),
                es_mh: h * (e * s_m1 + e_m1),
            }
        } else if z > 0.0 {
            let beta = beta_sq.sqrt();
            let half = (0.5 * beta * h).sin();
            let c_m1 = -2.0 * half * half;
            let es = e * (beta * h).sin() / beta;
            Self {
                ec_m1: e * c_m1 + e_m1,
                es,
                es_mh: es - h,
            }
        } else {
            // Over-damped: decay rates λ1 = α−γ (written without cancellation) and λ2 = α+γ.
            let gamma = (-beta_sq).sqrt();
            let lambda2 = alpha + gamma;
            let lambda1 = omega0_sq / lambda2;
            let es = -(-lambda1 * h).exp() * (-2.0 * gamma * h).exp_m1() / (2.0 * gamma);
            Self {
                ec_m1: 0.5 * ((-lambda1 * h).exp_m1() + (-lambda2 * h).exp_m1()),
                es,
                es_mh: es - h,
            }
        }
    }
}

/// The exact step of the corrected method (MATH notes, "One spring, exactly").
pub fn harmonic(omega0_sq: f64, alpha: f64, h: f64) -> Linear {
    let pr = Propagator::new(omega0_sq, alpha, h);
    Linear {
        p: -omega0_sq * pr.es,
        q: pr.ec_m1 - alpha * pr.es,
        r: pr.ec_m1 + alpha * pr.es,
        s: pr.es_mh,
    }
}

/// One explicit force evaluation: `φ = h·δ̈ = −h (ω0² δ + 2α δ̇)`, no displacement term.
/// With `h = 1` this is the relative acceleration, which the RK4 reference uses.
pub fn euler(omega0_sq: f64, alpha: f64, h: f64) -> Linear {
    Linear {
        p: -omega0_sq * h,
        q: -2.0 * alpha * h,
        r: 0.0,
        s: 0.0,
    }
}

/// Exact `(δ(h), δ̇(h))` of one isolated spring: the same propagator, applied to a state.
pub fn advance(omega0_sq: f64, alpha: f64, h: f64, delta: f64, delta_dot: f64) -> (f64, f64) {
    let l = harmonic(omega0_sq, alpha, h);
    (
        delta + delta_dot * h + l.r * delta + l.s * delta_dot,
        delta_dot + l.p * delta + l.q * delta_dot,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Direct textbook solution in each regime, independent of the propagator's rewriting.
    fn textbook(w2: f64, a: f64, t: f64, d0: f64, v0: f64) -> (f64, f64) {
        let b2 = w2 - a * a;
        if b2 > 0.0 {
            let b = b2.sqrt();
            let e = (-a * t).exp();
            let d = e * (d0 * (b * t).cos() + (v0 + a * d0) * (b * t).sin() / b);
            let v = e * (v0 * (b * t).cos() - (w2 * d0 + a * v0) * (b * t).sin() / b);
            (d, v)
        } else if b2 < 0.0 {
            let g = (-b2).sqrt();
            let e = (-a * t).exp();
            let d = e * (d0 * (g * t).cosh() + (v0 + a * d0) * (g * t).sinh() / g);
            let v = e * (v0 * (g * t).cosh() - (w2 * d0 + a * v0) * (g * t).sinh() / g);
            (d, v)
        } else {
            let e = (-a * t).exp();
            (
                e * (d0 + (v0 + a * d0) * t),
                e * (v0 - (w2 * d0 + a * v0) * t),
            )
        }
    }

    #[test]
    fn matches_textbook_in_every_regime() {
        let w2: f64 = 400.0;
        let w = w2.sqrt();
        for zeta in [0.0, 0.2, 0.9, 0.999, 1.0, 1.001, 1.3, 2.0, 10.0] {
            for t in [1e-4, 0.01, 0.07, 0.3] {
                let a = zeta * w;
                let (d, v) = advance(w2, a, t, 0.3, -2.0);
                let (dr, vr) = textbook(w2, a, t, 0.3, -2.0);
                let scale_d = 0.3 + 2.0 * t;
                let scale_v = 2.0 + w2 * 0.3 * t;
                assert!(
                    (d - dr).abs() <= 1e-12 * scale_d,
                    "zeta {zeta} t {t}: {d} vs {dr}"
                );
                assert!(
                    (v - vr).abs() <= 1e-12 * scale_v,
                    "zeta {zeta} t {t}: {v} vs {vr}"
                );
            }
        }
    }

    #[test]
    fn continuous_across_critical_damping_and_the_series_boundary() {
        let (w2, h): (f64, f64) = (1.0e4, 0.01);
        let w = w2.sqrt();
        let close = |x: Linear, y: Linear, tol: f64| {
            [(x.p, y.p), (x.q, y.q), (x.r, y.r), (x.s, y.s)]
                .iter()
                .all(|(a, b)| (a - b).abs() <= tol * (a.abs() + b.abs() + 1e-300))
        };
        // Across ζ = 1 the coefficients move by O(ζ − 1).
        for eps in [1e-12, 1e-8, 1e-4] {
            let (lo, hi) = (
                harmonic(w2, (1.0 - eps) * w, h),
                harmonic(w2, (1.0 + eps) * w, h),
            );
            assert!(
                close(lo, hi, 10.0 * eps),
                "jump across ζ = 1 at eps {eps}: {lo:?} vs {hi:?}"
            );
        }
        // Where the series hands over to cos/sin (β²h² = 0.25) and to cosh/sinh (−0.25).
        for side in [1.0, -1.0] {
            let alpha_at = |z: f64| (w2 - z / (h * h)).sqrt();
            let z = side * SERIES_LIMIT;
            let (a, b) = (
                harmonic(w2, alpha_at(z * (1.0 - 1e-12)), h),
                harmonic(w2, alpha_at(z * (1.0 + 1e-12)), h),
            );
            assert!(close(a, b, 1e-11), "jump at z = {z}: {a:?} vs {b:?}");
        }
    }

    #[test]
    fn huge_damping_neither_overflows_nor_loses_the_slow_mode() {
        // αh = 1e6: the slow rate λ1 ≈ ω0²/(2α) must survive.
        let (w2, a, h) = (1.0, 1.0e6, 1.0);
        let l = harmonic(w2, a, h);
        for x in [l.p, l.q, l.r, l.s] {
            assert!(x.is_finite());
        }
        let (d, _) = advance(w2, a, h, 1.0, 0.0);
        let lambda1 = w2 / (2.0 * a);
        assert!((d - (-lambda1 * h).exp()).abs() < 1e-9, "{d}");
    }

    #[test]
    fn small_steps_keep_relative_precision() {
        // q ≈ −2αh − ω0²h²/... must not be round-off when h is tiny.
        let (w2, a, h) = (1.0e6, 50.0, 1.0e-9);
        let l = harmonic(w2, a, h);
        // q = −2αh + (2α² − ω0²/2) h² + O(h³)
        let q_expected = -2.0 * a * h + (2.0 * a * a - 0.5 * w2) * h * h;
        assert!(
            (l.q - q_expected).abs() < 1e-9 * q_expected.abs(),
            "{} vs {q_expected}",
            l.q
        );
        let s_expected = -a * h * h; // ES − h ≈ −αh² to leading order
        assert!(
            (l.s - s_expected).abs() < 1e-3 * s_expected.abs(),
            "{} vs {s_expected}",
            l.s
        );
    }
}
