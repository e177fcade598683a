//! Symplectic and explicit Euler, and the closed form (`harmonic`, Jacobi), over cloth grids
//! ([`PackedGrid`]) with no memory per spring.
//!
//! Every link points forward in row-major order (gather makes it so), so a sweep over the
//! rows evaluates each spring once, at its earlier end, and adds its change to both ends in a
//! ring of the next `reach + 1` rows. A row is complete once the sweep has passed it; it then
//! moves, and is written back at once: no later spring reads it. Bands of rows run in
//! parallel, each also evaluating the springs that reach into it from the `reach` rows above
//! (their old state copied before the pass, as are the rows below it). Scratch is a few rows
//! per band instead of a buffer per spring or per particle, and each particle sums the same
//! terms in the same order whatever the banding (so whatever the thread count).
//!
//! The hot loop runs one link over a whole row: old state and sums are held per coordinate
//! (structure of arrays), so the compiler vectorises it across columns; on x86-64 the band is
//! also compiled for AVX2 and AVX-512 and the widest the CPU has is picked at run time. Every
//! lane does the scalar operations in the scalar order (no fused multiply-add), so each
//! build gives the same bits.

use std::ops::Range;

use glam::DVec3;
use rayon::prelude::*;

use super::harmonic::{self, Linear};
use super::{axial, euler_move, par, Update};
use crate::buffers::{Incidence, Packed, PackedGrid};
use crate::components::GridLink;

/// Old `(x, v)` of a particle.
type State = (DVec3, DVec3);

/// Per coordinate: x, y, z.
type Soa3 = [Vec<f64>; 3];

/// A band of grid rows and its scratch.
#[derive(Clone, Debug, Default)]
struct Band {
    rows: Range<usize>,
    /// Old state of the `reach` rows above the band (rows before row 0 unused).
    above: Vec<State>,
    /// Old state of the `reach` rows below it (rows past the last unused).
    below: Vec<State>,
    /// Old positions and velocities of the `reach + 1` rows the sweep reads, per coordinate.
    x: Soa3,
    v: Soa3,
    /// Summed velocity changes of the same rows.
    ring: Soa3,
    /// One link's `φ n` along a row.
    f: Soa3,
}

/// A link's Euler coefficients for step `h` (p = −κ h, q = −c h), in force form (μ = 1): the
/// particle's own 1/m scales the result. The GPU's `grid_pass` takes the same.
pub(crate) fn link_coefficients(l: &GridLink, h: f64) -> Linear {
    harmonic::euler(l.stiffness, 0.5 * l.damping, h)
}

/// A spring's closed-form coefficients in force form for two free ends of mass `m0`
/// (μ = m0/2): `f = μ φ`, so each end's change is `∓ f n / m`, as for the Euler links. The
/// closed form is not linear in 1/μ, so the pass holds it for one mass only ([`Fix`]).
fn harmonic_link(stiffness: f64, damping: f64, m0: f64, h: f64) -> Linear {
    let mu = 0.5 * m0;
    let l = harmonic::harmonic(stiffness / mu, damping / (2.0 * mu), h);
    Linear {
        p: mu * l.p,
        q: mu * l.q,
        r: 0.0,
        s: 0.0,
    }
}

/// What a grid pass applies to its links.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum GridLaw {
    /// Symplectic or explicit Euler: force-form coefficients, whatever the masses.
    Euler,
    /// The closed form (Jacobi, plain update), held for one free mass ([`nominal_inv_mass`]).
    Harmonic,
}

/// A grid spring whose ends are not both of the grid's nominal mass (a pinned end included),
/// under [`GridLaw::Harmonic`]: the pass applied the nominal force `f0`, the spring's own
/// closed form wants `w φ` at each end, so the difference is added after the pass. Each is
/// linear in the start-of-step state, so the sum is the spring's exact change. A cloth of one
/// mass has only its pins' springs here; one of many masses has most of its springs here, run
/// one after the other (correct, but slower than the springs one by one in parallel).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Fix {
    pub(crate) a: usize,
    pub(crate) b: usize,
    pub(crate) rest: f64,
    /// The spring's own closed form, relative (`φ`), and the nominal one in force form (`f0`).
    pub(crate) own: Linear,
    pub(crate) nominal: Linear,
    /// `μ/m` of each end (0 where pinned) and its inverse mass.
    pub(crate) wa: f64,
    pub(crate) wb: f64,
    pub(crate) ia: f64,
    pub(crate) ib: f64,
}

impl Fix {
    /// The velocity corrections of ends a and b from the start-of-step state.
    fn dv(&self, x: &[DVec3], v: &[DVec3]) -> (DVec3, DVec3) {
        let (n, delta, delta_dot) = axial(x[self.a], x[self.b], v[self.a], v[self.b], self.rest);
        let (phi, f0) = (
            self.own.phi(delta, delta_dot),
            self.nominal.phi(delta, delta_dot),
        );
        (
            -(self.wa * phi - self.ia * f0) * n,
            (self.wb * phi - self.ib * f0) * n,
        )
    }
}

/// The closed form on grid `g` for step `h`, as the CPU pass and the device's `grid_pass` both
/// apply it: each link's coefficients for the nominal mass, and the springs that need a [`Fix`].
pub(crate) fn harmonic_grid(g: &PackedGrid, inv: &[f64], h: f64) -> (Vec<Linear>, Vec<Fix>) {
    let w0 = nominal_inv_mass(g, inv);
    let m0 = if w0 > 0.0 { 1.0 / w0 } else { 1.0 };
    let fixes = g
        .springs(inv)
        .filter(|s| {
            let (ia, ib) = (inv[s.a as usize], inv[s.b as usize]);
            (ia != w0 || ib != w0) && (ia != 0.0 || ib != 0.0)
        })
        .map(|s| Fix {
            a: s.a as usize,
            b: s.b as usize,
            rest: s.rest,
            own: harmonic::harmonic(s.omega0_sq(), s.alpha(), h),
            nominal: harmonic_link(s.stiffness, s.damping, m0, h),
            wa: s.wa,
            wb: s.wb,
            ia: inv[s.a as usize],
            ib: inv[s.b as usize],
        })
        .collect();
    let links = g
        .links
        .iter()
        .map(|l| harmonic_link(l.stiffness, l.damping, m0, h))
        .collect();
    (links, fixes)
}

/// The inverse mass the pass holds the closed form for: the grid's centre particle's, or the
/// first free one's if the centre is pinned (0 if none is free).
fn nominal_inv_mass(g: &PackedGrid, inv_mass: &[f64]) -> f64 {
    let range = g.range();
    let centre = g.base as usize + (g.rows / 2 * g.cols + g.cols / 2) as usize;
    if inv_mass[centre] != 0.0 {
        return inv_mass[centre];
    }
    inv_mass[range]
        .iter()
        .copied()
        .find(|&w| w != 0.0)
        .unwrap_or(0.0)
}

/// The vector unit the band is compiled for. Every level gives the same bits (no fused
/// multiply-add, each lane in scalar order); `tests` hold them to it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
enum Vector {
    #[default]
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Vector {
    /// Every level this CPU runs, narrowest first.
    fn available() -> Vec<Self> {
        #[allow(unused_mut)]
        let mut v = vec![Self::Portable];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                v.push(Self::Avx2);
            }
            if std::arch::is_x86_feature_detected!("avx512f") {
                v.push(Self::Avx512);
            }
        }
        v
    }

    /// The widest this CPU runs, or the level `HARMONIC_SIMD` names (`portable`, `avx2`,
    /// `avx512`) when the CPU runs it: to measure what each level buys. Decided once.
    fn chosen() -> Self {
        static CHOSEN: std::sync::OnceLock<Vector> = std::sync::OnceLock::new();
        *CHOSEN.get_or_init(Self::decide)
    }

    fn decide() -> Self {
        let mut levels = Self::available();
        let named = std::env::var("HARMONIC_SIMD").ok();
        if let Some(k) = levels
            .iter()
            .position(|l| named.as_deref() == Some(l.name()))
        {
            return levels[k];
        }
        levels.pop().unwrap_or_default()
    }

    fn name(self) -> &'static str {
        match self {
            Self::Portable => "portable",
            #[cfg(target_arch = "x86_64")]
            Self::Avx2 => "avx2",
            #[cfg(target_arch = "x86_64")]
            Self::Avx512 => "avx512",
        }
    }
}

/// Per grid: the links' coefficients for the prepared step, and the bands.
#[derive(Clone, Debug, Default)]
pub(crate) struct GridPass {
    grids: Vec<(Vec<Linear>, Vec<Band>)>,
    vector: Vector,
    /// Corrections of the springs off the nominal mass ([`GridLaw::Harmonic`] only), and
    /// their velocity changes for the current step.
    fixes: Vec<Fix>,
    fix_dv: Vec<(DVec3, DVec3)>,
}

fn soa(len: usize) -> Soa3 {
    [vec![0.0; len], vec![0.0; len], vec![0.0; len]]
}

impl GridPass {
    /// Coefficients of `law` for step `h` and scratch for `packed`'s grids (`bands` per large
    /// grid).
    pub(crate) fn prepare(&mut self, packed: &Packed, h: f64, bands: usize, law: GridLaw) {
        self.grids.clear();
        self.fixes.clear();
        self.vector = Vector::chosen();
        for g in &packed.grids {
            let lin = match law {
                GridLaw::Euler => g.links.iter().map(|l| link_coefficients(l, h)).collect(),
                GridLaw::Harmonic => {
                    let (lin, fixes) = harmonic_grid(g, &packed.inv_mass, h);
                    self.fixes.extend(fixes);
                    lin
                }
            };
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
                    x: soa((reach + 1) * cols),
                    v: soa((reach + 1) * cols),
                    ring: soa((reach + 1) * cols),
                    f: soa(cols),
                })
                .collect();
            self.grids.push((lin, bands));
        }
        self.fix_dv
            .resize(self.fixes.len(), (DVec3::ZERO, DVec3::ZERO));
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
        // Read before the pass moves anything.
        for (f, dv) in self.fixes.iter().zip(&mut self.fix_dv) {
            *dv = f.dv(&packed.x, &packed.v);
        }
        self.run_pass(packed, sdv, g, h, update);
        // `v += Δv, x += h Δv` is what the velocity-first move does with a summand it gets
        // late; the harmonic law moves velocity first.
        debug_assert!(self.fixes.is_empty() || update == Update::VelocityFirst);
        for (f, &(dva, dvb)) in self.fixes.iter().zip(&self.fix_dv) {
            for (i, dv) in [(f.a, dva), (f.b, dvb)] {
                if packed.inv_mass[i] != 0.0 {
                    packed.v[i] += dv;
                    packed.x[i] += h * dv;
                }
            }
        }
    }

    fn run_pass(&mut self, packed: &mut Packed, sdv: &[DVec3], g: DVec3, h: f64, update: Update) {
        let Packed {
            x,
            v,
            inv_mass,
            grids,
            incidence,
            ..
        } = packed;
        let (Some(first), Some(last)) = (grids.first(), grids.last()) else {
            return;
        };
        let shared = Shared {
            vector: self.vector,
            inv_mass,
            incidence,
            sdv,
            g,
            h,
            update,
        };
        // Grids hold disjoint, increasing packed ranges (gather checks it): many small cloths
        // run side by side, each on one thread.
        let span = first.range().start..last.range().end;
        let total = grids.iter().map(|g| g.range().len()).sum::<usize>();
        let (x, v) = (&mut x[span.clone()], &mut v[span.clone()]);
        run_grids(
            &shared,
            grids,
            &mut self.grids,
            x,
            v,
            span.start,
            total >= par::PAR_MIN,
        );
    }
}

/// What every grid of a pass shares.
struct Shared<'a> {
    vector: Vector,
    /// Every particle's inverse mass.
    inv_mass: &'a [f64],
    incidence: &'a Incidence,
    sdv: &'a [DVec3],
    g: DVec3,
    h: f64,
    update: Update,
}

/// Steps `grids` (their state in `x`, `v`, which start at packed index `offset`): in two
/// halves of about equal particle counts side by side when `parallel`, else one by one.
fn run_grids(
    shared: &Shared<'_>,
    grids: &[PackedGrid],
    work: &mut [(Vec<Linear>, Vec<Band>)],
    x: &mut [DVec3],
    v: &mut [DVec3],
    offset: usize,
    parallel: bool,
) {
    if parallel && grids.len() > 1 {
        let half = grids.iter().map(|g| g.range().len()).sum::<usize>() / 2;
        let mut seen = 0;
        let mid = grids
            .iter()
            .position(|g| {
                seen += g.range().len();
                seen > half
            })
            .unwrap_or(0)
            .clamp(1, grids.len() - 1);
        let cut = grids[mid].range().start - offset;
        let (gl, gr) = grids.split_at(mid);
        let (wl, wr) = work.split_at_mut(mid);
        let (xl, xr) = x.split_at_mut(cut);
        let (vl, vr) = v.split_at_mut(cut);
        rayon::join(
            || run_grids(shared, gl, wl, xl, vl, offset, true),
            || run_grids(shared, gr, wr, xr, vr, offset + cut, true),
        );
        return;
    }
    for (grid, (lin, bands)) in grids.iter().zip(work) {
        let range = grid.range();
        let local = range.start - offset..range.end - offset;
        let (x, v) = (&mut x[local.clone()], &mut v[local]);
        let cols = grid.cols as usize;
        let reach = grid.reach();
        let rows = grid.rows as usize;
        // The rows each band's neighbours will overwrite, copied first.
        for b in bands.iter_mut() {
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
            shared,
            grid,
            inv: &shared.inv_mass[range],
            lin,
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

/// Where a band finds the old state of a row it reads.
struct Halo<'a> {
    above: &'a [State],
    below: &'a [State],
    r0: usize,
    r1: usize,
    reach: usize,
    cols: usize,
}

impl Halo<'_> {
    /// Row `r`'s old state into slot `s` of `[x, v]`: from the copies for the halo, from
    /// `x`, `v` (not yet moved) for the band's own rows.
    #[inline(always)]
    fn hold(&self, r: usize, s: usize, [ox, ov]: [&mut Soa3; 2], x: &[DVec3], v: &[DVec3]) {
        let (r0, r1, reach, cols) = (self.r0, self.r1, self.reach, self.cols);
        for c in 0..cols {
            let (p, u) = if r < r0 {
                self.above[(r + reach - r0) * cols + c]
            } else if r >= r1 {
                self.below[(r - r1) * cols + c]
            } else {
                let j = (r - r0) * cols + c;
                (x[j], v[j])
            };
            (ox[0][s + c], ox[1][s + c], ox[2][s + c]) = (p.x, p.y, p.z);
            (ov[0][s + c], ov[1][s + c], ov[2][s + c]) = (u.x, u.y, u.z);
        }
    }
}

/// What every band of one grid shares.
struct Ctx<'a> {
    shared: &'a Shared<'a>,
    grid: &'a PackedGrid,
    /// The grid's inverse masses.
    inv: &'a [f64],
    lin: &'a [Linear],
    cols: usize,
    reach: usize,
}

impl Ctx<'_> {
    /// The band, compiled for the chosen vector unit.
    fn band(&self, b: &mut Band, x: &mut [DVec3], v: &mut [DVec3]) {
        match self.shared.vector {
            Vector::Portable => self.band_rows(b, x, v),
            // SAFETY: `Vector::available` found the feature on this CPU.
            #[cfg(target_arch = "x86_64")]
            Vector::Avx2 => unsafe { self.band_avx2(b, x, v) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Vector::Avx512 => unsafe { self.band_avx512(b, x, v) },
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    fn band_avx512(&self, b: &mut Band, x: &mut [DVec3], v: &mut [DVec3]) {
        self.band_rows(b, x, v);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn band_avx2(&self, b: &mut Band, x: &mut [DVec3], v: &mut [DVec3]) {
        self.band_rows(b, x, v);
    }

    /// The band's rows in order: the springs anchored in each, then the row's move.
    #[inline(always)]
    fn band_rows(&self, b: &mut Band, x: &mut [DVec3], v: &mut [DVec3]) {
        let (cols, reach, rows) = (self.cols, self.reach, self.grid.rows as usize);
        let (r0, r1) = (b.rows.start, b.rows.end);
        let slot = |r: usize| (r % (reach + 1)) * cols;
        let first = r0.saturating_sub(reach);
        let last = (r1 + reach).min(rows);
        let Band {
            above,
            below,
            x: ox,
            v: ov,
            ring,
            f,
            ..
        } = b;
        let halo = Halo {
            above,
            below,
            r0,
            r1,
            reach,
            cols,
        };
        for r in first..(first + reach + 1).min(last) {
            halo.hold(r, slot(r), [ox, ov], x, v);
        }
        for s in ring.iter_mut() {
            s.fill(0.0);
        }
        for a in first..r1 {
            // The slots of row a − 1, complete (and moved, if the band's), now take row a + reach.
            if a > first {
                let s = slot(a + reach);
                for k in ring.iter_mut() {
                    k[s..s + cols].fill(0.0);
                }
                if a + reach < last {
                    halo.hold(a + reach, s, [ox, ov], x, v);
                }
            }
            let own = a >= r0;
            for (link, l) in self.grid.links.iter().zip(self.lin) {
                let rb = a + link.offset.1 as usize;
                let in_band = (r0..r1).contains(&rb);
                if rb >= rows || !(own || in_band) {
                    continue;
                }
                let dc = link.offset.0 as isize;
                let Range { start: lo, end: hi } = columns(cols, dc);
                if lo >= hi {
                    continue;
                }
                let n = hi - lo;
                let (ka, kb) = (slot(a) + lo, slot(rb) + (lo as isize + dc) as usize);
                link_row(
                    [span(ox, ka, n), span(ov, ka, n)],
                    [span(ox, kb, n), span(ov, kb, n)],
                    link.rest_length,
                    l,
                    f,
                    n,
                );
                // Force form (μ = 1): each end's change is −φ n / m at a, +φ n / m at b.
                if own {
                    let ia = &self.inv[a * cols + lo..a * cols + hi];
                    add_scaled::<false>(ring, slot(a) + lo, ia, f, n);
                }
                if in_band {
                    let cb = (lo as isize + dc) as usize;
                    let ib = &self.inv[rb * cols + cb..rb * cols + cb + n];
                    add_scaled::<true>(ring, slot(rb) + cb, ib, f, n);
                }
            }
            if own {
                let Shared {
                    incidence,
                    sdv,
                    g,
                    h,
                    update,
                    ..
                } = *self.shared;
                let s = slot(a);
                for c in 0..cols {
                    let k = (a - r0) * cols + c;
                    let i = a * cols + c;
                    if self.inv[i] != 0.0 {
                        let sum = DVec3::new(ring[0][s + c], ring[1][s + c], ring[2][s + c]);
                        let dv = sum + incidence.sum(sdv, self.grid.base as usize + i);
                        (x[k], v[k]) = euler_move(update, x[k], v[k], dv, g, h);
                    }
                }
            }
        }
    }
}

/// The columns `c` of a row whose link `dc` has its other end, `c + dc`, in the grid (empty
/// for a link longer than the grid is wide).
fn columns(cols: usize, dc: isize) -> Range<usize> {
    let lo = (-dc).clamp(0, cols as isize) as usize;
    let hi = (cols as isize - dc.max(0)).max(0) as usize;
    lo..hi.max(lo)
}

/// Width of the row loops' chunks: 8 f64 fill an AVX-512 register (two AVX2, four SSE2). A
/// row's last partial chunk is its last 8 elements again, so a 16-column cloth runs vectorised
/// throughout; only rows under 8 long are padded.
const L: usize = 8;
type Lane = [f64; L];

/// `m ≤ L` elements of `s` from `k`, padded with zeros.
#[inline(always)]
fn get(s: &[f64], k: usize, m: usize) -> Lane {
    let mut a = [0.0; L];
    a[..m].copy_from_slice(&s[k..k + m]);
    a
}

#[inline(always)]
fn put(s: &mut [f64], k: usize, m: usize, a: &Lane) {
    s[k..k + m].copy_from_slice(&a[..m]);
}

/// `n` elements from `k` of each coordinate.
#[inline(always)]
fn span(s: &Soa3, k: usize, n: usize) -> [&[f64]; 3] {
    [&s[0][k..k + n], &s[1][k..k + n], &s[2][k..k + n]]
}

/// `ring[s..s + n] ±= inv · f` per coordinate (`+` when `ADD`), in chunks of `L`; a row's
/// last, partial chunk is the last `L` elements with the ones already done left alone.
#[inline(always)]
fn add_scaled<const ADD: bool>(ring: &mut Soa3, s: usize, inv: &[f64], f: &Soa3, n: usize) {
    for (r, fc) in ring.iter_mut().zip(f) {
        if n < L {
            add_chunk::<ADD>(r, s, inv, fc, 0, n, 0);
            continue;
        }
        let mut k = 0;
        while k + L <= n {
            add_chunk::<ADD>(r, s, inv, fc, k, L, 0);
            k += L;
        }
        if k < n {
            add_chunk::<ADD>(r, s, inv, fc, n - L, L, L - (n - k));
        }
    }
}

/// One chunk of [`add_scaled`]: `m` elements from `k`, the first `skip` unchanged.
#[inline(always)]
fn add_chunk<const ADD: bool>(
    r: &mut [f64],
    s: usize,
    inv: &[f64],
    f: &[f64],
    k: usize,
    m: usize,
    skip: usize,
) {
    let (mut acc, w, fl) = (get(r, s + k, m), get(inv, k, m), get(f, k, m));
    for i in 0..L {
        let new = if ADD {
            acc[i] + w[i] * fl[i]
        } else {
            acc[i] - w[i] * fl[i]
        };
        acc[i] = if i < skip { acc[i] } else { new };
    }
    put(r, s + k, m, &acc);
}

/// One link along a row: `f = φ n` of the springs from `a`'s columns to `b`'s, `n` of them,
/// in chunks of `L`; a row's last, partial chunk is its last `L` springs (the overlap is
/// computed twice, to the same values).
#[inline(always)]
fn link_row(
    a: [[&[f64]; 3]; 2],
    b: [[&[f64]; 3]; 2],
    rest: f64,
    l: &Linear,
    f: &mut Soa3,
    n: usize,
) {
    if n < L {
        link_chunk(&a, &b, rest, l, f, 0, n);
        return;
    }
    let mut k = 0;
    while k + L <= n {
        link_chunk(&a, &b, rest, l, f, k, L);
        k += L;
    }
    if k < n {
        link_chunk(&a, &b, rest, l, f, n - L, L);
    }
}

/// One chunk of [`link_row`]: `m` springs from `k`, each through [`axial`] and
/// [`Linear::phi`], the math every pass shares (inlined, the lanes vectorise).
#[inline(always)]
fn link_chunk(
    a: &[[&[f64]; 3]; 2],
    b: &[[&[f64]; 3]; 2],
    rest: f64,
    l: &Linear,
    f: &mut Soa3,
    k: usize,
    m: usize,
) {
    let [[ax, ay, az], [avx, avy, avz]] = a;
    let [[bx, by, bz], [bvx, bvy, bvz]] = b;
    let (ax, ay, az) = (get(ax, k, m), get(ay, k, m), get(az, k, m));
    let (avx, avy, avz) = (get(avx, k, m), get(avy, k, m), get(avz, k, m));
    let (bx, by, bz) = (get(bx, k, m), get(by, k, m), get(bz, k, m));
    let (bvx, bvy, bvz) = (get(bvx, k, m), get(bvy, k, m), get(bvz, k, m));
    let (mut fx, mut fy, mut fz) = ([0.0; L], [0.0; L], [0.0; L]);
    for i in 0..L {
        let xa = DVec3::new(ax[i], ay[i], az[i]);
        let xb = DVec3::new(bx[i], by[i], bz[i]);
        let va = DVec3::new(avx[i], avy[i], avz[i]);
        let vb = DVec3::new(bvx[i], bvy[i], bvz[i]);
        let (n, delta, delta_dot) = axial(xa, xb, va, vb, rest);
        let fi = l.phi(delta, delta_dot) * n;
        (fx[i], fy[i], fz[i]) = (fi.x, fi.y, fi.z);
    }
    put(&mut f[0], k, m, &fx);
    put(&mut f[1], k, m, &fy);
    put(&mut f[2], k, m, &fz);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::buffers::GatherOptions;

    #[test]
    fn a_links_columns_are_those_with_both_ends_in_the_grid() {
        for (cols, dc, want) in [
            (16, 0, 0..16),
            (16, 2, 0..14),
            (16, -1, 1..16),
            (16, 16, 0..0),
            (1, 2, 0..0),
            (2, -3, 2..2),
            (3, -2, 2..3),
        ] {
            let got = columns(cols, dc);
            assert_eq!(got, want, "{cols} columns, dc {dc}");
            // Independently: the c whose c + dc is a column.
            let brute: Vec<usize> = (0..cols)
                .filter(|&c| (0..cols as isize).contains(&(c as isize + dc)))
                .collect();
            assert_eq!(got.clone().collect::<Vec<_>>(), brute);
        }
    }

    /// Every vector level steps a cloth to the same bits, in three bands (halo rows; every
    /// grid is over `par::PAR_MIN` particles): rows of 70 (whole chunks and an overlapping last
    /// one), 16 (exact chunks for some links), 9 (one chunk and an overlap of 7) and 5 (padded).
    #[test]
    fn every_vector_unit_gives_the_same_bits() {
        for (cols, rows) in [(70, 70), (16, 300), (9, 500), (5, 900)] {
            let mut scene = crate::internals::hanging_cloth(cols);
            scene.cloths[0].resolution = (cols, rows);
            let built = scene.build();
            let options = GatherOptions {
                keep_grids: true,
                colouring: false,
            };
            let mut start = Packed::gather_with(&built.world, options).unwrap();
            assert_eq!(start.grids.len(), 1);
            // A twist, so every spring is stretched and moving.
            for (i, (x, v)) in start.x.iter_mut().zip(&mut start.v).enumerate() {
                let t = i as f64 * 0.37;
                *x += 0.01 * DVec3::new(t.sin(), t.cos(), (2.0 * t).sin());
                *v = DVec3::new((3.0 * t).cos(), t.sin(), 0.5);
            }
            let (g, h) = (DVec3::new(0.0, -9.81, 0.0), 1e-3);
            let run = |vector: Vector| {
                let mut p = start.clone();
                let mut pass = GridPass::default();
                pass.prepare(&p, h, 3, GridLaw::Euler);
                pass.vector = vector;
                assert_eq!(pass.grids[0].1.len(), 3);
                for _ in 0..20 {
                    pass.run(&mut p, &[], g, h, Update::VelocityFirst);
                }
                (p.x, p.v)
            };
            let reference = run(Vector::Portable);
            assert!(reference.0.iter().all(|x| x.is_finite()));
            assert_ne!(reference.0, start.x);
            for level in Vector::available() {
                let (x, v) = run(level);
                let same = |a: &[DVec3], b: &[DVec3]| {
                    a.iter().zip(b).all(|(p, q)| {
                        p.to_array().map(f64::to_bits) == q.to_array().map(f64::to_bits)
                    })
                };
                assert!(
                    same(&x, &reference.0) && same(&v, &reference.1),
                    "{cols}×{rows}: {level:?}"
                );
            }
        }
    }
}
