//! Symplectic and explicit Euler over cloth grids ([`PackedGrid`]) with no memory per spring.
//!
//! Every link points forward in row-major order (gather makes it so), so a sweep over the
//! rows evaluates each spring once, at its earlier end, and adds its change to both ends in a
//! ring of the next `reach + 1` rows. A row is complete once the sweep has passed it; it then
//! moves, and is written back at once: no later spring reads it. Bands of rows run in
//! parallel, each also evaluating the springs that reach into it from the `reach` rows above
//! (their old state copied before the pass, as are the rows below it). Scratch is a few rows
//! per band instead of a buffer per spring or per particle, and each particle sums the same
//! terms in the same order whatever the banding (so whatever the thread count).

use std::ops::Range;

use glam::DVec3;
use rayon::prelude::*;

use super::harmonic::{self, Linear};
use super::{axial, euler_move, par, Update};
use crate::buffers::{Incidence, Packed, PackedGrid};
use crate::components::GridLink;

/// Old `(x, v)` of a particle.
type State = (DVec3, DVec3);

/// A band of grid rows and its scratch.
#[derive(Clone, Debug, Default)]
struct Band {
    rows: Range<usize>,
    /// Old state of the `reach` rows above the band (rows before row 0 unused).
    above: Vec<State>,
    /// Old state of the `reach` rows below it (rows past the last unused).
    below: Vec<State>,
    /// Summed velocity changes of the `reach + 1` rows the sweep is adding to.
    ring: Vec<DVec3>,
    /// Per link, for the row being swept: see [`Row::meta`].
    meta: Vec<(usize, bool, bool, usize)>,
}

/// The anchor row being swept.
struct Row<'a> {
    a: usize,
    /// Its ring slot, when it is one of the band's own rows.
    own: Option<usize>,
    /// Per link: the other end's row, whether that exists, whether it is in the band, and
    /// its ring slot.
    meta: &'a [(usize, bool, bool, usize)],
}

/// A link's Euler coefficients for step `h` (p = −κ h, q = −c h), in force form (μ = 1): the
/// particle's own 1/m scales the result. The GPU's `grid_pass` takes the same.
pub(crate) fn link_coefficients(l: &GridLink, h: f64) -> Linear {
    harmonic::euler(l.stiffness, 0.5 * l.damping, h)
}

/// Per grid: the links' coefficients for the prepared step, and the bands.
#[derive(Clone, Debug, Default)]
pub(crate) struct GridPass {
    grids: Vec<(Vec<Linear>, Vec<Band>)>,
}

impl GridPass {
    /// Coefficients for step `h` and scratch for `packed`'s grids (`bands` per large grid).
    pub(crate) fn prepare(&mut self, packed: &Packed, h: f64, bands: usize) {
        self.grids.clear();
        for g in &packed.grids {
            let lin = g.links.iter().map(|l| link_coefficients(l, h)).collect();
            let (cols, rows, reach) = (g.cols as usize, g.rows as usize, g.reach());
            let count = if g.range().len() < par::PAR_MIN {
                1
            } else {
                bands.clamp(1, rows)
            };
            let per = rows.div_ceil(count);
            let bands = (0..rows)
                .step_by(per)
                .map(|r0| Band {
                    rows: r0..(r0 + per).min(rows),
                    above: vec![(DVec3::ZERO, DVec3::ZERO); reach * cols],
                    below: vec![(DVec3::ZERO, DVec3::ZERO); reach * cols],
                    ring: vec![DVec3::ZERO; (reach + 1) * cols],
                    meta: vec![(0, false, false, 0); g.links.len()],
                })
                .collect();
            self.grids.push((lin, bands));
        }
    }

    /// One substep of every grid's particles: `Δv` from its springs plus the incidence sum of
    /// the other springs' `sdv`, then `update`.
    pub(crate) fn run(
        &mut self,
        packed: &mut Packed,
        sdv: &[DVec3],
        g: DVec3,
        h: f64,
        update: Update,
    ) {
        let Packed {
            x,
            v,
            inv_mass,
            grids,
            incidence,
            ..
        } = packed;
        for (grid, (lin, bands)) in grids.iter().zip(&mut self.grids) {
            let range = grid.range();
            let (x, v) = (&mut x[range.clone()], &mut v[range.clone()]);
            let cols = grid.cols as usize;
            let reach = grid.reach();
            // The rows each band's neighbours will overwrite, copied first.
            for b in bands.iter_mut() {
                let rows = grid.rows as usize;
                let copy = |dst: &mut [State], from: usize, to: usize, first: isize| {
                    for r in from..to {
                        let k = (r as isize - first) as usize * cols;
                        for c in 0..cols {
                            dst[k + c] = (x[r * cols + c], v[r * cols + c]);
                        }
                    }
                };
                let (r0, r1) = (b.rows.start, b.rows.end);
                copy(
                    &mut b.above,
                    r0.saturating_sub(reach),
                    r0,
                    r0 as isize - reach as isize,
                );
                copy(&mut b.below, r1, (r1 + reach).min(rows), r1 as isize);
            }
            let per = bands[0].rows.len() * cols;
            let ctx = Ctx {
                grid,
                inv: &inv_mass[range],
                lin,
                incidence,
                sdv,
                g,
                h,
                update,
                cols,
                reach,
            };
            if bands.len() == 1 {
                ctx.band(&mut bands[0], x, v);
            } else {
                x.par_chunks_mut(per)
                    .zip(v.par_chunks_mut(per))
                    .zip(bands.par_iter_mut())
                    .for_each(|((x, v), b)| ctx.band(b, x, v));
            }
        }
    }
}

/// What every band of one grid shares.
struct Ctx<'a> {
    grid: &'a PackedGrid,
    /// The grid's inverse masses.
    inv: &'a [f64],
    lin: &'a [Linear],
    incidence: &'a Incidence,
    sdv: &'a [DVec3],
    g: DVec3,
    h: f64,
    update: Update,
    cols: usize,
    reach: usize,
}

impl Ctx<'_> {
    /// The band's rows in order: the springs anchored in each, then the row's move.
    fn band(&self, b: &mut Band, x: &mut [DVec3], v: &mut [DVec3]) {
        let (cols, reach, rows) = (self.cols, self.reach, self.grid.rows as usize);
        let Band {
            rows: band,
            above,
            below,
            ring,
            meta,
        } = b;
        let (r0, r1) = (band.start, band.end);
        let slot = |r: usize| (r % (reach + 1)) * cols;
        ring.fill(DVec3::ZERO);
        let first = r0.saturating_sub(reach);
        for a in first..r1 {
            // The slot of row a − 1, complete and moved, now collects row a + reach.
            if a > first {
                let s = slot(a + reach);
                ring[s..s + cols].fill(DVec3::ZERO);
            }
            // Per link: the other end's row, whether it exists and is in the band, its slot.
            for (m, l) in meta.iter_mut().zip(&self.grid.links) {
                let rb = a + l.offset.1 as usize;
                *m = (rb, rb < rows, (r0..r1).contains(&rb), slot(rb));
            }
            let row = Row {
                a,
                own: (a >= r0).then(|| slot(a)),
                meta,
            };
            if a >= r0 && a + reach < r1 {
                // Every row read is in the band (the common case: no halo lookups).
                self.anchor_row(&row, ring, |c, r| {
                    let j = (r - r0) * cols + c;
                    (x[j], v[j])
                });
            } else {
                self.anchor_row(&row, ring, |c, r| {
                    if r < r0 {
                        above[(r + reach - r0) * cols + c]
                    } else if r >= r1 {
                        below[(r - r1) * cols + c]
                    } else {
                        let j = (r - r0) * cols + c;
                        (x[j], v[j])
                    }
                });
            }
            if a >= r0 {
                let s = slot(a);
                for c in 0..cols {
                    let k = (a - r0) * cols + c;
                    let i = a * cols + c;
                    if self.inv[i] != 0.0 {
                        let dv =
                            ring[s + c] + self.incidence.sum(self.sdv, self.grid.base as usize + i);
                        (x[k], v[k]) = euler_move(self.update, x[k], v[k], dv, self.g, self.h);
                    }
                }
            }
        }
    }

    /// The springs anchored in one row: each evaluated once, its change added to both ends.
    #[inline(always)]
    fn anchor_row(&self, row: &Row<'_>, ring: &mut [DVec3], old: impl Fn(usize, usize) -> State) {
        let (cols, a) = (self.cols, row.a);
        for c in 0..cols {
            let (xa, va) = old(c, a);
            let inv_a = self.inv[a * cols + c];
            for ((link, l), &(rb, exists, in_band, sb)) in
                self.grid.links.iter().zip(self.lin).zip(row.meta.iter())
            {
                let cb = c as isize + link.offset.0 as isize;
                if !exists || cb < 0 || cb as usize >= cols {
                    continue;
                }
                let cb = cb as usize;
                let (xb, vb) = old(cb, rb);
                let (n, delta, delta_dot) = axial(xa, xb, va, vb, link.rest_length);
                // Force form (μ = 1): each end's change is −φ n / m at a, +φ n / m at b.
                let f = l.phi(delta, delta_dot) * n;
                if let Some(sa) = row.own {
                    ring[sa + c] -= inv_a * f;
                }
                if in_band {
                    ring[sb + cb] += self.inv[rb * cols + cb] * f;
                }
            }
        }
    }
}
