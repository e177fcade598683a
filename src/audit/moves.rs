//! What a projection (tethers, stretch limits, self-collision) moved, and the change of the
//! springs' energy at those particles only.

use glam::DVec3;

use super::{particle_energy_at, spring_energy, spring_energy_at, Auditor, Link};
use crate::buffers::Packed;
use crate::components::GridLink;

/// The particles a projection (tethers, stretch limits) moved this substep, and where each
/// was before it: the springs' change is then evaluated at those particles' springs only.
#[derive(Debug, Default)]
pub(crate) struct Moves {
    /// Each particle's position before its first move (stale where not `moved`).
    pub(crate) before: Vec<DVec3>,
    pub(crate) moved: Vec<bool>,
}

impl Moves {
    /// None moved yet, for `n` particles.
    pub(crate) fn reset(&mut self, n: usize) {
        self.before.resize(n, DVec3::ZERO);
        self.moved.clear();
        self.moved.resize(n, false);
    }

    /// Adds `E(x, v) − E(before, before_v)` of each moved particle to `sum`, in order: the
    /// change of their own energy (kinetic and gravity's); one gone non-finite is the
    /// quarantine's.
    pub(crate) fn book_particles(
        &self,
        before_v: &[DVec3],
        packed: &Packed,
        gravity: DVec3,
        sum: &mut f64,
    ) {
        let (inv, x, v) = (&packed.inv_mass, &packed.x, &packed.v);
        let at = |i: usize, x: DVec3, v: DVec3| particle_energy_at(inv[i], x, v, gravity);
        for i in (0..self.moved.len()).filter(|&i| self.moved[i]) {
            let change = at(i, x[i], v[i]) - at(i, self.before[i], before_v[i]);
            if change.is_finite() {
                *sum += change;
            }
        }
    }

    /// Keeps where particle `i` was, at its first move.
    #[inline]
    pub(crate) fn mark(moved: &mut bool, before: &mut DVec3, x: DVec3) {
        if !*moved {
            *moved = true;
            *before = x;
        }
    }
}

impl Auditor {
    /// `Σ U(x) − U(before)` over every spring: what a projection's `moves` did to the
    /// springs' energy (J), in fixed order. A spring with neither end moved changed by an
    /// exact 0 and is not evaluated; one at a particle gone non-finite is left out: that
    /// particle is the quarantine's.
    pub(crate) fn spring_change(&mut self, packed: &Packed, moves: &Moves) -> f64 {
        let (x, moved, before) = (&packed.x, &moves.moved, &moves.before);
        let was = |i: usize| if moved[i] { before[i] } else { x[i] };
        let one = |l: Link| {
            if !(moved[l.a] || moved[l.b]) {
                return 0.0;
            }
            let change = spring_energy(x, l) - spring_energy_at(was(l.a), was(l.b), l);
            if change.is_finite() {
                change
            } else {
                0.0
            }
        };
        let row = |l: &GridLink, ends, acc| row_change(x, moves, l, ends, acc);
        self.spring_sum_by_rows(packed, true, one, row)
    }
}

/// `acc` plus `Σ U(x) − U(before)` over a grid link's row of `n` springs `(a + k, b + k)` (as
/// [`Auditor::spring_change`] spring by spring, the same bits): lanes of [`LANES`] springs, a
/// lane with no end moved skipped (its change an exact 0), the others' changes evaluated side
/// by side and added in order.
fn row_change(
    x: &[DVec3],
    m: &Moves,
    l: &GridLink,
    (a, b, n): (usize, usize, usize),
    mut acc: f64,
) -> f64 {
    let (rest, half_k) = (l.rest_length, 0.5 * l.stiffness);
    let energy = |d2: f64| {
        let d = d2.sqrt() - rest;
        half_k * d * d
    };
    let (moved, before) = (&m.moved, &m.before);
    let mut k = 0;
    while k < n {
        let w = LANES.min(n - k);
        let (ma, mb) = (&moved[a + k..a + k + w], &moved[b + k..b + k + w]);
        if ma.iter().chain(mb).any(|&t| t) {
            let (xa, xb) = (&x[a + k..a + k + w], &x[b + k..b + k + w]);
            let (ba, bb) = (&before[a + k..a + k + w], &before[b + k..b + k + w]);
            let mut now = [0.0; LANES];
            let mut was = [0.0; LANES];
            for j in 0..w {
                now[j] = (xb[j] - xa[j]).length_squared();
                let pa = if ma[j] { ba[j] } else { xa[j] };
                let pb = if mb[j] { bb[j] } else { xb[j] };
                was[j] = (pb - pa).length_squared();
            }
            let mut changes = [0.0; LANES];
            for j in 0..LANES {
                changes[j] = energy(now[j]) - energy(was[j]);
            }
            for &change in &changes[..w] {
                if change.is_finite() {
                    acc += change;
                }
            }
        }
        k += w;
    }
    acc
}

/// Springs side by side in [`row_change`].
const LANES: usize = 8;
