//! Symplectic and explicit Euler over cloth grids ([`PackedGrid`]) with no memory per spring.
//!
//! Each particle sums its own springs, reading only the state at the start of the substep, so
//! a spring is evaluated once from each end (the two results are exact negatives: the same
//! differences, negated). The new state goes back in place a few rows behind the row being
//! computed, once no later row reads the old one; the rows a band's neighbours read are copied
//! before the pass. Scratch is a few rows per band instead of a buffer per spring or particle,
//! and every particle's result is independent of the banding (so of the thread count).

use std::ops::Range;

use glam::DVec3;
use rayon::prelude::*;

use super::harmonic::{self, Linear};
use super::{axial, par, Update};
use crate::buffers::{Incidence, Packed, PackedGrid};

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
    /// New state of the last `reach + 1` rows computed, not yet written back.
    pending: Vec<State>,
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
            // Force form (μ = 1): the particle's own 1/m scales the result.
            let lin = g
                .links
                .iter()
                .map(|l| harmonic::euler(l.stiffness, 0.5 * l.damping, h))
                .collect();
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
                    pending: vec![(DVec3::ZERO, DVec3::ZERO); (reach + 1) * cols],
                })
                .collect();
            self.grids.push((lin, bands));
        }
    }

    /// One substep of every grid's particles: `Δv` from its springs plus `extra` (the
    /// incidence sum of the other springs' `sdv`), then `update`.
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
            let (x, v, inv) = (
                &mut x[range.clone()],
                &mut v[range.clone()],
                &inv_mass[range],
            );
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
                ctx.band(&mut bands[0], x, v, inv);
            } else {
                x.par_chunks_mut(per)
                    .zip(v.par_chunks_mut(per))
                    .zip(inv.par_chunks(per))
                    .zip(bands.par_iter_mut())
                    .for_each(|(((x, v), inv), b)| ctx.band(b, x, v, inv));
            }
        }
    }
}

/// What every band of one grid shares.
struct Ctx<'a> {
    grid: &'a PackedGrid,
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
    /// The band's rows in order, each written back `reach + 1` rows later.
    fn band(&self, b: &mut Band, x: &mut [DVec3], v: &mut [DVec3], inv: &[f64]) {
        let (cols, reach) = (self.cols, self.reach);
        let Band {
            rows,
            above,
            below,
            pending,
        } = b;
        let (r0, r1) = (rows.start, rows.end);
        let slot = |r: usize| (r % (reach + 1)) * cols;
        let write_back = |r: usize, x: &mut [DVec3], v: &mut [DVec3], pending: &[State]| {
            let (at, from) = ((r - r0) * cols, slot(r));
            for c in 0..cols {
                (x[at + c], v[at + c]) = pending[from + c];
            }
        };
        for r in r0..r1 {
            if r > r0 + reach {
                write_back(r - reach - 1, x, v, pending);
            }
            let out = slot(r);
            for c in 0..cols {
                let k = (r - r0) * cols + c;
                pending[out + c] = self.particle(c, r, (x[k], v[k]), inv[k], |cc, rr| {
                    if rr < r0 {
                        above[(rr + reach - r0) * cols + cc]
                    } else if rr >= r1 {
                        below[(rr - r1) * cols + cc]
                    } else {
                        let j = (rr - r0) * cols + cc;
                        (x[j], v[j])
                    }
                });
            }
        }
        for r in r0.max(r1.saturating_sub(reach + 1))..r1 {
            write_back(r, x, v, pending);
        }
    }

    /// The new state of grid particle `(c, r)` from its old one and its neighbours' (`old`).
    #[inline(always)]
    fn particle(
        &self,
        c: usize,
        r: usize,
        (xi, vi): State,
        inv: f64,
        old: impl Fn(usize, usize) -> State,
    ) -> State {
        if inv == 0.0 {
            return (xi, vi);
        }
        let (cols, rows) = (self.cols as isize, self.grid.rows as isize);
        let i = self.grid.base as usize + r * self.cols + c;
        let mut dv = self.incidence.sum(self.sdv, i);
        for (link, l) in self.grid.links.iter().zip(self.lin) {
            let (dc, dr) = (link.offset.0 as isize, link.offset.1 as isize);
            for (cc, rr) in [
                (c as isize + dc, r as isize + dr),
                (c as isize - dc, r as isize - dr),
            ] {
                if cc < 0 || rr < 0 || cc >= cols || rr >= rows {
                    continue;
                }
                let (xj, vj) = old(cc as usize, rr as usize);
                let (n, delta, delta_dot) = axial(xi, xj, vi, vj, link.rest_length);
                // This end's share of the force-form change: −φ n / m.
                dv -= inv * (l.p * delta + l.q * delta_dot) * n;
            }
        }
        let (g, h) = (self.g, self.h);
        match self.update {
            Update::PositionFirst => (xi + h * vi, vi + dv + g * h),
            _ => {
                let v = vi + dv + g * h;
                (xi + h * v, v)
            }
        }
    }
}
