//! The band kernel of a grid pass: rows swept in a ring, halos copied before the pass, and
//! the lane-wide link loops (vectorised per coordinate).

use super::*;

/// Steps `grids` (their state in `x`, `v`, which start at packed index `offset`): in two
/// halves of about equal particle counts side by side when `parallel`, else one by one.
pub(super) fn run_grids(
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
pub(super) struct Halo<'a> {
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
pub(super) struct Ctx<'a> {
    shared: &'a Shared<'a>,
    grid: &'a PackedGrid,
    /// The grid's inverse masses.
    inv: &'a [f64],
    lin: &'a [Linear],
    cols: usize,
    reach: usize,
}

impl Ctx<'_> {
    /// The band, compiled for the chosen vector unit and the kind of external acceleration.
    fn band(&self, b: &mut Band, x: &mut [DVec3], v: &mut [DVec3]) {
        match self.shared.g {
            External::Uniform(g) => self.band_with(b, x, v, Constant(g)),
            External::PerParticle(a) => self.band_with(b, x, v, a),
        }
    }

    fn band_with<A: Accel>(&self, b: &mut Band, x: &mut [DVec3], v: &mut [DVec3], g: A) {
        match self.shared.vector {
            Vector::Portable => self.band_rows(b, x, v, g),
            // SAFETY: `Vector::available` found the feature on this CPU.
            #[cfg(target_arch = "x86_64")]
            Vector::Avx2 => unsafe { self.band_avx2(b, x, v, g) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Vector::Avx512 => unsafe { self.band_avx512(b, x, v, g) },
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    fn band_avx512<A: Accel>(&self, b: &mut Band, x: &mut [DVec3], v: &mut [DVec3], g: A) {
        self.band_rows(b, x, v, g);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn band_avx2<A: Accel>(&self, b: &mut Band, x: &mut [DVec3], v: &mut [DVec3], g: A) {
        self.band_rows(b, x, v, g);
    }

    /// The band's rows in order: the springs anchored in each, then the row's move.
    #[inline(always)]
    fn band_rows<A: Accel>(&self, b: &mut Band, x: &mut [DVec3], v: &mut [DVec3], accel: A) {
        let (cols, reach, rows) = (self.cols, self.reach, self.grid.rows as usize);
        let (r0, r1) = (b.rows.start, b.rows.end);
        let slot = |r: usize| (r % (reach + 1)) * cols;
        let first = r0.saturating_sub(reach);
        let last = (r1 + reach).min(rows);
        let audit = self.shared.audit;
        let Band {
            above,
            below,
            x: ox,
            v: ov,
            ring,
            f,
            ring_d,
            fd,
            ones,
            loss,
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
        for s in ring.iter_mut().chain(ring_d.iter_mut()) {
            s.fill(0.0);
        }
        for a in first..r1 {
            // The slots of row a − 1, complete (and moved, if the band's), now take row a + reach.
            if a > first {
                let s = slot(a + reach);
                for k in ring.iter_mut() {
                    k[s..s + cols].fill(0.0);
                }
                if audit {
                    for k in ring_d.iter_mut() {
                        k[s..s + cols].fill(0.0);
                    }
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
                let (ea, eb) = (
                    [span(ox, ka, n), span(ov, ka, n)],
                    [span(ox, kb, n), span(ov, kb, n)],
                );
                if audit {
                    link_row::<true>(ea, eb, link.rest_length, l, [f, fd], n);
                } else {
                    link_row::<false>(ea, eb, link.rest_length, l, [f, fd], n);
                }
                // Force form (μ = 1): each end's change is −φ n / m at a, +φ n / m at b.
                if own {
                    let ia = &self.inv[a * cols + lo..a * cols + hi];
                    add_scaled::<false>(ring, slot(a) + lo, ia, f, n);
                    if audit {
                        add_scaled::<false>(ring_d, slot(a) + lo, &ones[..n], fd, n);
                    }
                }
                if in_band {
                    let cb = (lo as isize + dc) as usize;
                    let ib = &self.inv[rb * cols + cb..rb * cols + cb + n];
                    add_scaled::<true>(ring, slot(rb) + cb, ib, f, n);
                    if audit {
                        add_scaled::<true>(ring_d, slot(rb) + cb, &ones[..n], fd, n);
                    }
                }
            }
            if own && audit {
                loss[a - r0] = 0.0;
            }
            if own {
                let Shared {
                    incidence,
                    sdv,
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
                        let v0 = v[k];
                        let g = accel.at(self.grid.base as usize + i);
                        (x[k], v[k]) = euler_move(update, x[k], v[k], dv, g, h);
                        if audit {
                            // The dampers' impulse on this particle does J·(v₀ + v₁)/2.
                            let j =
                                DVec3::new(ring_d[0][s + c], ring_d[1][s + c], ring_d[2][s + c]);
                            loss[a - r0] -= 0.5 * j.dot(v0 + v[k]);
                        }
                    }
                }
            }
        }
    }
}

/// The columns `c` of a row whose link `dc` has its other end, `c + dc`, in the grid (empty
/// for a link longer than the grid is wide).
pub(super) fn columns(cols: usize, dc: isize) -> Range<usize> {
    let lo = (-dc).clamp(0, cols as isize) as usize;
    let hi = (cols as isize - dc.max(0)).max(0) as usize;
    lo..hi.max(lo)
}

/// Width of the row loops' chunks: 8 f64 fill an AVX-512 register (two AVX2, four SSE2). A
/// row's last partial chunk is its last 8 elements again, so a 16-column cloth runs vectorised
/// throughout; only rows under 8 long are padded.
pub(super) const L: usize = 8;
pub(super) type Lane = [f64; L];

/// `m ≤ L` elements of `s` from `k`, padded with zeros.
#[inline(always)]
pub(super) fn get(s: &[f64], k: usize, m: usize) -> Lane {
    let mut a = [0.0; L];
    a[..m].copy_from_slice(&s[k..k + m]);
    a
}

#[inline(always)]
pub(super) fn put(s: &mut [f64], k: usize, m: usize, a: &Lane) {
    s[k..k + m].copy_from_slice(&a[..m]);
}

/// `n` elements from `k` of each coordinate.
#[inline(always)]
pub(super) fn span(s: &Soa3, k: usize, n: usize) -> [&[f64]; 3] {
    [&s[0][k..k + n], &s[1][k..k + n], &s[2][k..k + n]]
}

/// `ring[s..s + n] ±= inv · f` per coordinate (`+` when `ADD`), in chunks of `L`; a row's
/// last, partial chunk is the last `L` elements with the ones already done left alone.
#[inline(always)]
pub(super) fn add_scaled<const ADD: bool>(
    ring: &mut Soa3,
    s: usize,
    inv: &[f64],
    f: &Soa3,
    n: usize,
) {
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
pub(super) fn add_chunk<const ADD: bool>(
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
/// With `DAMPERS`, the dampers' share `q δ̇ n` of each spring's `φ n` goes to `fd` too.
#[inline(always)]
pub(super) fn link_row<const DAMPERS: bool>(
    a: [[&[f64]; 3]; 2],
    b: [[&[f64]; 3]; 2],
    rest: f64,
    l: &Linear,
    [f, fd]: [&mut Soa3; 2],
    n: usize,
) {
    if n < L {
        link_chunk::<DAMPERS>(&a, &b, rest, l, [f, fd], 0, n);
        return;
    }
    let mut k = 0;
    while k + L <= n {
        link_chunk::<DAMPERS>(&a, &b, rest, l, [&mut *f, &mut *fd], k, L);
        k += L;
    }
    if k < n {
        link_chunk::<DAMPERS>(&a, &b, rest, l, [f, fd], n - L, L);
    }
}

/// One chunk of [`link_row`]: `m` springs from `k`, each through [`axial`] and
/// [`Linear::phi`], the math every pass shares (inlined, the lanes vectorise).
#[inline(always)]
pub(super) fn link_chunk<const DAMPERS: bool>(
    a: &[[&[f64]; 3]; 2],
    b: &[[&[f64]; 3]; 2],
    rest: f64,
    l: &Linear,
    [f, fd]: [&mut Soa3; 2],
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
    let (mut dx, mut dy, mut dz) = ([0.0; L], [0.0; L], [0.0; L]);
    for i in 0..L {
        let xa = DVec3::new(ax[i], ay[i], az[i]);
        let xb = DVec3::new(bx[i], by[i], bz[i]);
        let va = DVec3::new(avx[i], avy[i], avz[i]);
        let vb = DVec3::new(bvx[i], bvy[i], bvz[i]);
        let (n, delta, delta_dot) = axial(xa, xb, va, vb, rest);
        let fi = l.phi(delta, delta_dot) * n;
        (fx[i], fy[i], fz[i]) = (fi.x, fi.y, fi.z);
        if DAMPERS {
            let di = (l.q * delta_dot) * n;
            (dx[i], dy[i], dz[i]) = (di.x, di.y, di.z);
        }
    }
    put(&mut f[0], k, m, &fx);
    put(&mut f[1], k, m, &fy);
    put(&mut f[2], k, m, &fz);
    if DAMPERS {
        put(&mut fd[0], k, m, &dx);
        put(&mut fd[1], k, m, &dy);
        put(&mut fd[2], k, m, &dz);
    }
}
