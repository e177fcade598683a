//! The tethers' clamp eight particles at a time: a rank of links (each particle's first,
//! second, … nearest anchor) over eight particles in packed order that share one anchor is
//! tested and clamped side by side (AVX-512), with the operations of the one-by-one clamp in
//! the same order, lane by lane, so the bits are the same; elsewhere, and without AVX-512,
//! link by link.

use glam::DVec3;

use crate::integrate::grid::Vector;

/// A particle without a link of some rank.
pub(super) const NONE: u32 = u32::MAX;

/// Particles whose tests run side by side.
pub(super) const LANES: usize = 8;

/// The most anchors a particle has ([`super::TetherSpec::anchors`]).
pub(super) const MAX_RANKS: usize = 4;

/// Eight particles whose links of a rank go to more than one anchor.
pub(super) const MIXED: u32 = u32::MAX - 1;

/// One rank of the links (each particle's first, second, … nearest anchor).
#[derive(Clone, Debug, Default)]
pub(super) struct Rank {
    /// Per particle: the anchor's slot ([`NONE`]: no link of this rank) and the limit.
    pub(super) slots: Vec<u32>,
    pub(super) limits: Vec<f64>,
    /// Per eight particles: the anchor they share ([`MIXED`]: more than one, or fewer than
    /// eight particles), and which of them have a link.
    pub(super) lanes: Vec<(u32, u8)>,
}

/// The next substep moves a particle by `h (v + h a)`, `a` ≈ gravity: along `n = d/|d|` at
/// most `L − |d|`, that is `s ≤ |d| L` with `s = h (u + h g)·d + |d|²` (`u` its velocity
/// relative to the anchor's, `d = x − y`), tested without a root as `s |s| ≤ |d|² L²`.
#[inline(always)]
pub(super) fn within(
    x: DVec3,
    v: DVec3,
    ya: DVec3,
    wa: DVec3,
    hg: DVec3,
    h: f64,
    limit: f64,
) -> bool {
    let d = x - ya;
    let d2 = d.length_squared();
    let s = h * (v - wa + hg).dot(d) + d2;
    s * s.abs() <= d2 * limit * limit
}

/// What a clamp needs of the substep and of its link's anchor.
#[derive(Clone, Copy, Debug)]
pub(super) struct Substep {
    /// The anchor's position and velocity.
    pub(super) ya: DVec3,
    pub(super) wa: DVec3,
    pub(super) gravity: DVec3,
    /// `h g`, `h` and `1/h`.
    pub(super) hg: DVec3,
    pub(super) h: f64,
    pub(super) inv_h: f64,
}

/// One link, as the order of links sees it: tested against the velocity `v` its particle's
/// earlier links left ([`within`]), its velocity away from the anchor limited where it fails.
/// The change of kinetic energy, where it clamped.
#[inline(always)]
pub(super) fn clamp_one(x: DVec3, v: &mut DVec3, inv: f64, limit: f64, s: &Substep) -> Option<f64> {
    if within(x, *v, s.ya, s.wa, s.hg, s.h, limit) || inv == 0.0 {
        return None;
    }
    let d = x - s.ya;
    let len = d.length();
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    let n = d * len.recip();
    let most = (limit - len) * s.inv_h - s.h * s.gravity.dot(n);
    let excess = (*v - s.wa).dot(n) - most;
    if excess > 0.0 {
        // ½ m (|v − e n|² − |v|²): the kinetic energy the clamp takes.
        let taken = 0.5 / inv * excess * (excess - 2.0 * v.dot(n));
        *v -= excess * n;
        return Some(taken);
    }
    None
}

/// What the clamps of one rank did to eight particles: the change of kinetic energy in each
/// lane, and which lanes clamped.
pub(super) type Taken = ([f64; LANES], u8);

/// Eight particles' links of one rank, all to one anchor, taken side by side.
pub(super) struct Lanes<'a> {
    pub(super) x: &'a [DVec3],
    pub(super) v: &'a mut [DVec3],
    pub(super) inv: &'a [f64],
    pub(super) limits: &'a [f64],
    /// Which of the eight have a link of this rank.
    pub(super) linked: u8,
}

/// One block's links, eight particles at a time and rank by rank (a particle's second anchor
/// sees its first's clamp): where the eight share one anchor their links run side by side,
/// otherwise one by one; the energies are added particle by particle, each particle's anchors
/// in order, as link by link.
pub(super) struct Block<'a> {
    pub(super) ranked: &'a [Rank],
    pub(super) held: &'a [(DVec3, DVec3)],
    pub(super) x: &'a [DVec3],
    pub(super) inv: &'a [f64],
    pub(super) at: Substep,
    /// The block's first particle.
    pub(super) base: usize,
}

impl Block<'_> {
    /// The block's clamps over its velocities `vs`: the change of kinetic energy they made.
    /// Only where the CPU has AVX-512; elsewhere the caller takes the links one by one.
    pub(super) fn run(&self, vs: &mut [DVec3]) -> f64 {
        #[cfg(target_arch = "x86_64")]
        if Vector::chosen().lanes_of_8() {
            // SAFETY: `Vector::chosen` found the feature on this CPU.
            return unsafe { self.run_avx512(vs) };
        }
        unreachable!("the lanes run only where the CPU has AVX-512")
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    fn run_avx512(&self, vs: &mut [DVec3]) -> f64 {
        let Block {
            ranked,
            held,
            x,
            inv,
            at,
            base,
        } = *self;
        let mut change = 0.0;
        // Each rank's energies per lane (read only where its lane's bit is set).
        let mut taken: [Taken; MAX_RANKS] = [([0.0; LANES], 0); MAX_RANKS];
        for c in (0..vs.len()).step_by(LANES) {
            let g = (base + c) / LANES;
            let m = LANES.min(vs.len() - c);
            for t in &mut taken {
                t.1 = 0;
            }
            for (r, t) in ranked.iter().zip(&mut taken) {
                let (q, linked) = r.lanes[g];
                if linked == 0 {
                    continue;
                }
                let l = &r.limits[base + c..];
                if q != MIXED {
                    let (ya, wa) = held[q as usize];
                    let mut lanes = Lanes {
                        x: &x[base + c..base + c + m],
                        v: &mut vs[c..c + m],
                        inv: &inv[base + c..base + c + m],
                        limits: &l[..m],
                        linked,
                    };
                    lanes.clamp_avx512(&Substep { ya, wa, ..at }, t);
                    continue;
                }
                let mut each = linked;
                while each != 0 {
                    let j = each.trailing_zeros() as usize;
                    each &= each - 1;
                    let (i, slot) = (base + c + j, r.slots[base + c + j]);
                    let (ya, wa) = held[slot as usize];
                    let s = Substep { ya, wa, ..at };
                    if let Some(e) = clamp_one(x[i], &mut vs[c + j], inv[i], l[j], &s) {
                        (t.0[j], t.1) = (e, t.1 | 1 << j);
                    }
                }
            }
            let ranks = &taken[..ranked.len()];
            let mut any = ranks.iter().fold(0, |a, t| a | t.1);
            while any != 0 {
                let j = any.trailing_zeros() as usize;
                any &= any - 1;
                for t in ranks {
                    if t.1 & 1 << j != 0 {
                        change += t.0[j];
                    }
                }
            }
        }
        change
    }
}

impl Lanes<'_> {
    /// The eight links tested and clamped as [`clamp_one`] takes them one by one (the same
    /// operations in the same order, lane by lane: the same bits), what each took in `taken`.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    #[inline]
    fn clamp_avx512(&mut self, s: &Substep, (each, clamped): &mut Taken) {
        use std::arch::x86_64::*;
        const _: () = assert!(std::mem::size_of::<DVec3>() == 24);
        assert!(self.x.len() >= LANES && self.v.len() >= LANES);
        assert!(self.limits.len() >= LANES && self.inv.len() >= LANES);
        // Eight (x, y, z) in a row as three rows of eight.
        let columns = |p: *const f64| {
            // SAFETY: `p` starts eight `DVec3`s (24 f64, checked above).
            let (a, b, c) = unsafe {
                (
                    _mm512_loadu_pd(p),
                    _mm512_loadu_pd(p.add(8)),
                    _mm512_loadu_pd(p.add(16)),
                )
            };
            // Component `k` of row `j` is element `3 j + k` of the 24: from a or b (indices
            // 0–15) where it is under 16, then from c (indices 8–15 of the second pick).
            let pick = |k: i64| {
                let at = |j: i64| 3 * j + k;
                let ab: [i64; LANES] = std::array::from_fn(|j| at(j as i64) % 16);
                let abc: [i64; LANES] = std::array::from_fn(|j| {
                    let p = at(j as i64);
                    if p < 16 {
                        j as i64
                    } else {
                        p - 8
                    }
                });
                // SAFETY: eight i64 each.
                let (ab, abc) = unsafe {
                    (
                        _mm512_loadu_epi64(ab.as_ptr()),
                        _mm512_loadu_epi64(abc.as_ptr()),
                    )
                };
                _mm512_permutex2var_pd(_mm512_permutex2var_pd(a, ab, b), abc, c)
            };
            (pick(0), pick(1), pick(2))
        };
        let (x, y, z) = columns(self.x.as_ptr().cast());
        let (vx, vy, vz) = columns(self.v.as_ptr().cast());
        let (add, sub, mul, one) = (_mm512_add_pd, _mm512_sub_pd, _mm512_mul_pd, _mm512_set1_pd);
        let dot = |ax, ay, az, bx, by, bz| add(add(mul(ax, bx), mul(ay, by)), mul(az, bz));
        let (ya, wa, g, hg) = (s.ya, s.wa, s.gravity, s.hg);
        let (dx, dy, dz) = (sub(x, one(ya.x)), sub(y, one(ya.y)), sub(z, one(ya.z)));
        // v − wa (and + h g for the test).
        let (rx, ry, rz) = (sub(vx, one(wa.x)), sub(vy, one(wa.y)), sub(vz, one(wa.z)));
        let (ux, uy, uz) = (add(rx, one(hg.x)), add(ry, one(hg.y)), add(rz, one(hg.z)));
        let d2 = dot(dx, dy, dz, dx, dy, dz);
        let t = add(mul(one(s.h), dot(ux, uy, uz, dx, dy, dz)), d2);
        // SAFETY: eight limits and inverse masses (checked above).
        let (l, inv) = unsafe {
            (
                _mm512_loadu_pd(self.limits.as_ptr()),
                _mm512_loadu_pd(self.inv.as_ptr()),
            )
        };
        let within = _mm512_cmp_pd_mask::<_CMP_LE_OQ>(mul(t, _mm512_abs_pd(t)), mul(mul(d2, l), l));
        let massive = _mm512_cmp_pd_mask::<_CMP_NEQ_UQ>(inv, _mm512_setzero_pd());
        let failing = !within & self.linked & massive;
        if failing == 0 {
            return;
        }
        let len = _mm512_sqrt_pd(d2);
        let finite = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(len, _mm512_setzero_pd())
            & _mm512_cmp_pd_mask::<_CMP_LT_OQ>(len, one(f64::INFINITY));
        let recip = _mm512_div_pd(one(1.0), len);
        let (nx, ny, nz) = (mul(dx, recip), mul(dy, recip), mul(dz, recip));
        let most = sub(
            mul(sub(l, len), one(s.inv_h)),
            mul(one(s.h), dot(one(g.x), one(g.y), one(g.z), nx, ny, nz)),
        );
        let excess = sub(dot(rx, ry, rz, nx, ny, nz), most);
        let out = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(excess, _mm512_setzero_pd());
        let mut moved = failing & finite & out;
        if moved == 0 {
            return;
        }
        let vn = dot(vx, vy, vz, nx, ny, nz);
        let taken = mul(
            mul(_mm512_div_pd(one(0.5), inv), excess),
            sub(excess, mul(one(2.0), vn)),
        );
        *clamped = moved;
        let lanes = |a: __m512d| {
            let mut o = [0.0; LANES];
            // SAFETY: eight f64.
            unsafe { _mm512_storeu_pd(o.as_mut_ptr(), a) };
            o
        };
        let (wx, wy, wz) = (
            lanes(sub(vx, mul(excess, nx))),
            lanes(sub(vy, mul(excess, ny))),
            lanes(sub(vz, mul(excess, nz))),
        );
        *each = lanes(taken);
        while moved != 0 {
            let j = moved.trailing_zeros() as usize;
            moved &= moved - 1;
            self.v[j] = DVec3::new(wx[j], wy[j], wz[j]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eight links side by side give the bits of the same links one by one: random states
    /// about their limits (half of them past), a pinned particle, a lane without a link, one
    /// on its anchor and one gone non-finite among them.
    #[test]
    fn eight_side_by_side_are_eight_one_by_one() {
        if !Vector::available().into_iter().any(|v| v.lanes_of_8()) {
            println!("no AVX-512 here: the links run one by one only");
            return;
        }
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut uniform = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let mut clamped = 0;
        for round in 0..2000 {
            let ya = DVec3::new(uniform(), uniform(), uniform());
            let s = Substep {
                ya,
                wa: DVec3::new(uniform(), uniform(), uniform()) * 0.1,
                gravity: DVec3::new(0.0, -9.81, 0.0),
                hg: DVec3::new(0.0, -9.81, 0.0) * 5e-4,
                h: 5e-4,
                inv_h: 1.0 / 5e-4,
            };
            let limits: [f64; LANES] = std::array::from_fn(|_| 0.2 + 0.1 * uniform());
            let x: [DVec3; LANES] = std::array::from_fn(|j| {
                let dir = DVec3::new(uniform(), uniform(), uniform()).normalize_or(DVec3::X);
                ya + dir * limits[j] * (1.0 + 0.01 * uniform())
            });
            let mut v: [DVec3; LANES] =
                std::array::from_fn(|_| DVec3::new(uniform(), uniform(), uniform()) * 5.0);
            let mut inv = [1000.0; LANES];
            let (mut x, mut linked) = (x, u8::MAX);
            if round % 3 == 0 {
                inv[1] = 0.0;
                linked &= !(1 << 2);
                x[3] = ya;
                v[4].y = f64::NAN;
            }
            let mut one = v;
            let mut want: Taken = ([0.0; LANES], 0);
            for j in 0..LANES {
                if linked & 1 << j != 0 {
                    if let Some(e) = clamp_one(x[j], &mut one[j], inv[j], limits[j], &s) {
                        (want.0[j], want.1) = (e, want.1 | 1 << j);
                    }
                }
            }
            let mut got: Taken = ([0.0; LANES], 0);
            let mut lanes = Lanes {
                x: &x,
                v: &mut v,
                inv: &inv,
                limits: &limits,
                linked,
            };
            // SAFETY: the CPU has AVX-512 (above).
            #[cfg(target_arch = "x86_64")]
            unsafe {
                lanes.clamp_avx512(&s, &mut got)
            };
            assert_eq!(got.1, want.1, "round {round}: which lanes clamped");
            for j in 0..LANES {
                assert_eq!(
                    v[j].to_array().map(f64::to_bits),
                    one[j].to_array().map(f64::to_bits)
                );
                if want.1 & 1 << j != 0 {
                    assert_eq!(
                        got.0[j].to_bits(),
                        want.0[j].to_bits(),
                        "round {round} lane {j}"
                    );
                }
            }
            clamped += want.1.count_ones();
        }
        assert!(
            clamped > 2000,
            "the states reach their limits: {clamped} clamps"
        );
    }
}
