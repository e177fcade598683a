//! Diagnostics over the packed state: energy, strain, step size against the springs' periods.

// Not API: reachable from outside only through the hidden `internals` module.
#![allow(missing_docs)]

use glam::DVec3;
use rayon::prelude::*;

use crate::buffers::{Packed, PackedSpring};

use crate::integrate::par::PAR_MIN;

/// Kinetic + spring + gravitational potential energy (J); pinned particles hold none.
/// Gravity's potential is `−m g·x`, zero at the origin.
/// The terms are the energy audit's (`audit::particle_energy`, `audit::spring_energy`); this sum
/// is the quick one, in whatever order rayon splits it (the audit's is in fixed order).
pub fn energy(packed: &Packed, gravity: DVec3) -> f64 {
    let particle = |i: usize| crate::audit::particle_energy(packed, i, gravity);
    let spring = |s: PackedSpring| crate::audit::spring_energy(&packed.x, (&s).into());
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

/// A reduction over every spring as `(a, b, rest, stiffness)`: the loose springs, then each
/// cloth grid walked link by link (the set `PackedGrid::springs` expands, without building
/// each spring's mass split). In parallel for large scenes; `join` must be associative and
/// commutative, so the result does not depend on the split.
fn reduce_springs<R: Copy + Send + Sync>(
    packed: &Packed,
    identity: R,
    one: impl Fn(usize, usize, f64, f64) -> R + Sync + Send,
    join: impl Fn(R, R) -> R + Sync + Send,
) -> R {
    let row = |g: &crate::buffers::PackedGrid, r: u32| {
        let mut acc = identity;
        for l in &g.links {
            let Some((a, b, n)) = g.link_row(l, r) else {
                continue;
            };
            for k in 0..n {
                acc = join(
                    acc,
                    one(
                        (a + k) as usize,
                        (b + k) as usize,
                        l.rest_length,
                        l.stiffness,
                    ),
                );
            }
        }
        acc
    };
    let loose = |s: &PackedSpring| one(s.a as usize, s.b as usize, s.rest, s.stiffness);
    let grids = &packed.topology.grids;
    if packed.spring_count() < PAR_MIN {
        let cloth = grids
            .iter()
            .flat_map(|g| (0..g.rows).map(move |r| row(g, r)));
        packed
            .springs
            .iter()
            .map(loose)
            .chain(cloth)
            .fold(identity, &join)
    } else {
        let cloth = grids
            .par_iter()
            .flat_map(|g| (0..g.rows).into_par_iter().map(move |r| row(g, r)));
        let springs = packed.springs.par_iter().map(loose);
        springs.chain(cloth).reduce(|| identity, &join)
    }
}

/// `δ/l0` of the spring from `a` to `b`, or None between two pinned particles (the game's
/// length, not the cloth's stretch).
#[inline(always)]
fn extension(packed: &Packed, a: usize, b: usize, rest: f64) -> Option<f64> {
    let free = packed.inv_mass[a] != 0.0 || packed.inv_mass[b] != 0.0;
    free.then(|| ((packed.x[b] - packed.x[a]).length() - rest) / rest)
}

/// [`Stretch`] of the packed state.
pub fn stretch(packed: &Packed) -> Stretch {
    let one = |a, b, rest, _| match extension(packed, a, b, rest) {
        None => Stretch::default(),
        Some(e) if e.is_nan() => Stretch {
            tension: e,
            compression: e,
        },
        Some(e) => Stretch {
            tension: e.max(0.0),
            compression: (-e).max(0.0),
        },
    };
    let join = |a: Stretch, b: Stretch| Stretch {
        tension: nan_max(a.tension, b.tension),
        compression: nan_max(a.compression, b.compression),
    };
    reduce_springs(packed, Stretch::default(), one, join)
}

/// Whether any spring with a free end is stretched past `limit` (`δ/l0 > limit`) or has a
/// non-finite length: the per-frame strain check. Squared lengths against `((1 + limit) l0)²`,
/// so no root or division per spring; [`most_stretched`] names the spring after.
pub fn beyond(packed: &Packed, limit: f64) -> bool {
    let (x, inv) = (&packed.x[..], &packed.inv_mass[..]);
    let k = (1.0 + limit) * (1.0 + limit);
    let over = |a: usize, b: usize, rest: f64, _| {
        let d2 = (x[b] - x[a]).length_squared();
        (d2 > k * rest * rest || d2.is_nan()) && !(inv[a] == 0.0 && inv[b] == 0.0)
    };
    reduce_springs(packed, false, over, |p, q| p | q)
}

/// The spring stretched most, as in [`Stretch`]: its ends (packed indices), `δ/l0`, and `h/h_c`
/// at step `h`. A NaN length counts as the most; among equals the smallest pair, so the answer
/// is the same however the springs are split.
pub fn most_stretched(packed: &Packed, h: f64) -> Option<MostStretched> {
    let one = |a: usize, b: usize, rest: f64, stiffness: f64| {
        let e = extension(packed, a, b, rest)?;
        let mu = 1.0 / (packed.inv_mass[a] + packed.inv_mass[b]);
        Some(MostStretched {
            ends: (a, b),
            strain: e,
            step_ratio: h * (stiffness / mu).sqrt() / std::f64::consts::PI,
        })
    };
    // A total order: NaN first, then larger strain, then the smaller pair.
    let worse = |p: &MostStretched, q: &MostStretched| match (p.strain.is_nan(), q.strain.is_nan())
    {
        (true, false) => true,
        (false, true) => false,
        (true, true) => p.ends < q.ends,
        (false, false) => p.strain > q.strain || (p.strain == q.strain && p.ends < q.ends),
    };
    let join = |p: Option<MostStretched>, q: Option<MostStretched>| match (p, q) {
        (Some(p), Some(q)) => Some(if worse(&p, &q) { p } else { q }),
        (p, None) => p,
        (None, q) => q,
    };
    reduce_springs(packed, None, one, join)
}

/// What [`most_stretched`] finds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MostStretched {
    pub ends: (usize, usize),
    pub strain: f64,
    pub step_ratio: f64,
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
    let x = &packed.x[..];
    let strain = |a: usize, b: usize, rest: f64, _| ((x[b] - x[a]).length() - rest).abs() / rest;
    reduce_springs(packed, 0.0, strain, nan_max)
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

/// The scene's energy scale (J), what energy changes are measured against:
/// `max(E_kin + E_spring, M |g| H)`, with `M` the free particles' mass and `H` the diagonal of
/// the particles' bounding box, the furthest a part of the scene can fall (a chain released
/// horizontally swings down its length). One read of the state.
pub fn energy_scale(packed: &Packed, gravity: DVec3) -> f64 {
    energy_parts(packed, gravity).scale()
}

/// The parts of the state's energy the scale and the a priori substeps are taken from.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EnergyParts {
    /// Kinetic energy of the free particles, and of their centre of mass's motion.
    pub kinetic: f64,
    pub bulk: f64,
    /// The springs' energy.
    pub spring: f64,
    /// What falling the scene's height would give, `M |g| H`.
    pub fall: f64,
}

impl EnergyParts {
    /// [`energy_scale`].
    pub fn scale(&self) -> f64 {
        (self.kinetic + self.spring).max(self.fall)
    }

    /// The energy in the cloth's own motion and stretch: the springs' plus the kinetic energy
    /// about the centre of mass (a cloth thrown whole has none).
    pub fn internal(&self) -> f64 {
        (self.kinetic - self.bulk).max(0.0) + self.spring
    }
}

/// [`EnergyParts`] of the state, in one read of the particles and one of the springs.
pub fn energy_parts(packed: &Packed, gravity: DVec3) -> EnergyParts {
    let (mut kinetic, mut mass, mut momentum) = (0.0, 0.0, DVec3::ZERO);
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for i in 0..packed.particle_count() {
        (lo, hi) = (lo.min(packed.x[i]), hi.max(packed.x[i]));
        if packed.inv_mass[i] != 0.0 {
            let m = packed.mass(i);
            mass += m;
            momentum += m * packed.v[i];
            kinetic += 0.5 * m * packed.v[i].length_squared();
        }
    }
    let spring: f64 = packed
        .all_springs()
        .map(|s| crate::audit::spring_energy(&packed.x, (&s).into()))
        .sum();
    let height = if packed.particle_count() > 0 {
        (hi - lo).length()
    } else {
        0.0
    };
    EnergyParts {
        kinetic,
        bulk: if mass > 0.0 {
            0.5 * momentum.length_squared() / mass
        } else {
            0.0
        },
        spring,
        fall: mass * gravity.length() * height,
    }
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
