//! Diagnostics over the packed state: energy, strain, step size against the springs' periods.

// Not API: reachable from outside only through the hidden `internals` module.
#![allow(missing_docs)]

use glam::DVec3;
use rayon::prelude::*;

use crate::buffers::{Packed, PackedSpring};

use crate::integrate::par::PAR_MIN;

/// Kinetic + spring + gravitational potential energy (J); pinned particles hold none.
/// Gravity's potential is `−m g·x`, zero at the origin.
pub fn energy(packed: &Packed, gravity: DVec3) -> f64 {
    let particle = |i: usize| {
        if packed.inv_mass[i] == 0.0 {
            0.0
        } else {
            let m = packed.mass(i);
            0.5 * m * packed.v[i].length_squared() - m * gravity.dot(packed.x[i])
        }
    };
    let spring = |s: PackedSpring| {
        let d = packed.stretch(&s);
        0.5 * s.stiffness * d * d
    };
    let (n, m) = (packed.particle_count(), packed.spring_count());
    if n + m < PAR_MIN {
        (0..n).map(particle).sum::<f64>() + packed.all_springs().map(spring).sum::<f64>()
    } else {
        (0..n).into_par_iter().map(particle).sum::<f64>()
            + packed.par_springs().map(spring).sum::<f64>()
    }
}

/// How far the cloth is stretched: the largest extension `δ/l0` of any spring with a free end
/// (its tension), and apart the largest compression `−δ/l0` (a fold or a bend shortens springs
/// without stretching the cloth). NaN where any spring's is.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Stretch {
    pub tension: f64,
    pub compression: f64,
}

/// [`Stretch`] of the packed state.
pub fn stretch(packed: &Packed) -> Stretch {
    // A spring between two pinned particles is the game's length, not the cloth's stretch.
    let one = |s: PackedSpring| {
        if !s.mu.is_finite() {
            return Stretch::default();
        }
        let e = packed.stretch(&s) / s.rest;
        Stretch {
            tension: if e.is_nan() { e } else { e.max(0.0) },
            compression: if e.is_nan() { e } else { (-e).max(0.0) },
        }
    };
    let join = |a: Stretch, b: Stretch| Stretch {
        tension: nan_max(a.tension, b.tension),
        compression: nan_max(a.compression, b.compression),
    };
    if packed.spring_count() < PAR_MIN {
        packed.all_springs().map(one).fold(Stretch::default(), join)
    } else {
        packed.par_springs().map(one).reduce(Stretch::default, join)
    }
}

/// The spring stretched most: its index in [`Packed::all_springs`] order (the first among
/// equals) and its `δ/l0`. Sequential: for reports, not for every frame.
pub fn most_stretched(packed: &Packed) -> Option<(usize, f64)> {
    let mut best: Option<(usize, f64)> = None;
    for (k, s) in packed.all_springs().enumerate() {
        if !s.mu.is_finite() {
            continue;
        }
        let e = packed.stretch(&s) / s.rest;
        if best.is_none_or(|(_, b)| e > b || (e.is_nan() && !b.is_nan())) {
            best = Some((k, e));
        }
    }
    best
}

/// The larger of two values, NaN if either is (a broken state cannot report a small one).
fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// Largest `|δ|/l0` over all springs; NaN if any spring's is.
pub fn max_strain(packed: &Packed) -> f64 {
    let strain = |s: PackedSpring| packed.stretch(&s).abs() / s.rest;
    // Unlike f64::max, keeps a NaN so a broken state cannot report a small strain.
    let max = |a: f64, b: f64| {
        if a.is_nan() || b.is_nan() {
            f64::NAN
        } else {
            a.max(b)
        }
    };
    if packed.spring_count() < PAR_MIN {
        packed.all_springs().map(strain).fold(0.0, max)
    } else {
        packed.par_springs().map(strain).reduce(|| 0.0, max)
    }
}

/// `h/h_c` of the stiffest spring, `h_c = π/ω0`, and that spring's index.
pub fn worst_step_ratio(packed: &Packed, h: f64) -> Option<(f64, usize)> {
    packed
        .all_springs()
        .enumerate()
        .map(|(k, s)| (s.step_ratio(h), k))
        .max_by(|a, b| a.0.total_cmp(&b.0))
}

/// Whether a particle's position and velocity are both finite.
#[inline(always)]
pub fn finite_state(x: DVec3, v: DVec3) -> bool {
    x.is_finite() && v.is_finite()
}

/// Index of the first particle whose position or velocity is not finite.
pub fn first_non_finite(packed: &Packed) -> Option<usize> {
    (0..packed.particle_count()).find(|&i| !finite_state(packed.x[i], packed.v[i]))
}

/// How many particles have a non-finite position or velocity.
pub fn non_finite_count(packed: &Packed) -> usize {
    packed
        .x
        .iter()
        .zip(&packed.v)
        .filter(|(x, v)| !finite_state(**x, **v))
        .count()
}

/// Total linear momentum of the free particles.
pub fn momentum(packed: &Packed) -> DVec3 {
    (0..packed.particle_count())
        .filter(|&i| packed.inv_mass[i] != 0.0)
        .map(|i| packed.mass(i) * packed.v[i])
        .sum()
}

/// RMS distance between two position sets of equal length.
pub fn rms(a: &[DVec3], b: &[DVec3]) -> f64 {
    (a.iter()
        .zip(b)
        .map(|(x, y)| (*x - *y).length_squared())
        .sum::<f64>()
        / a.len() as f64)
        .sqrt()
}
