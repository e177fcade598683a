//! `theta-mg`: a θ-step solved by one multigrid V-cycle, for large steps with no global solve.
//!
//! `(M − θh D − θ²h² K) Δv = h (f + θh K v)`, `v += Δv`, `x += h (v₀ + θ Δv)`, θ = 0.6: θ = 1/2
//! (the trapezoidal rule) does not damp what one cycle leaves unconverged, θ = 1 (implicit
//! Euler) damps the motion itself (STABILITY.md, "one multigrid V-cycle").
//!
//! One V-cycle from `Δv = 0`: on each level an l1-Jacobi pre-sweep, the residual
//! restricted to the next level, that level's cycle, its correction interpolated back, a
//! post-sweep; l1-Jacobi sweeps on the coarsest. l1-Jacobi divides by each row's absolute sum
//! (`m + 2 Σ|B_s|`): at small steps that is the mass, so the cycle is exact as h → 0 (a fixed
//! Jacobi weight of 1/2 is not, and stalls at a constant error), and at large steps it is half
//! the diagonal, the weight the prototype measured stable. The finest level is the current Jacobian,
//! matrix-free (`implicit::product`). The coarse levels are fixed for a given `h`: Galerkin
//! products of an isotropic operator (each spring's full stiffness in every direction, one
//! scalar network applied to each axis, so it needs no update as the cloth turns; less than
//! the full stiffness over-corrects and blows up) through smoothed-aggregation transfers built
//! from the spring graph. Scenes of at most [`COARSEST`] free particles get the θ-step solved by
//! conjugate gradients instead.

use glam::DVec3;

use super::implicit::{self, Implicit};
use super::par;
use crate::buffers::Packed;

/// The step's θ.
pub const THETA: f64 = 0.6;
/// Jacobi sweeps on the coarsest level.
const COARSEST_SWEEPS: usize = 4;
/// Coarsening stops at this many nodes.
pub const COARSEST: usize = 8;

/// Compressed sparse rows: the coarse levels' scalar operators and the transfers.
#[derive(Clone, Debug, Default)]
struct Csr {
    offsets: Vec<usize>,
    cols: Vec<u32>,
    vals: Vec<f64>,
    width: usize,
}

impl Csr {
    fn from_rows(width: usize, rows: Vec<Vec<(u32, f64)>>) -> Csr {
        let mut m = Csr {
            offsets: vec![0],
            width,
            ..Csr::default()
        };
        for mut row in rows {
            row.sort_unstable_by_key(|e| e.0);
            let start = m.cols.len();
            for (c, v) in row {
                match (m.cols.len() > start, m.cols.last(), m.vals.last_mut()) {
                    (true, Some(&last), Some(sum)) if last == c => *sum += v,
                    _ => {
                        m.cols.push(c);
                        m.vals.push(v);
                    }
                }
            }
            m.offsets.push(m.cols.len());
        }
        m
    }

    fn rows(&self) -> usize {
        self.offsets.len() - 1
    }

    fn row(&self, i: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let r = self.offsets[i]..self.offsets[i + 1];
        self.cols[r.clone()]
            .iter()
            .zip(&self.vals[r])
            .map(|(&c, &v)| (c as usize, v))
    }

    fn transpose(&self) -> Csr {
        let mut rows = vec![Vec::new(); self.width];
        for i in 0..self.rows() {
            for (c, v) in self.row(i) {
                rows[c].push((i as u32, v));
            }
        }
        Csr::from_rows(self.rows(), rows)
    }

    /// `self · b`, row by row through a dense accumulator.
    fn mul(&self, b: &Csr) -> Csr {
        let mut acc = vec![0.0; b.width];
        let mut seen = vec![false; b.width];
        let mut rows = Vec::with_capacity(self.rows());
        for i in 0..self.rows() {
            let mut touched = Vec::new();
            for (k, a) in self.row(i) {
                for (j, v) in b.row(k) {
                    if !seen[j] {
                        seen[j] = true;
                        touched.push(j);
                    }
                    acc[j] += a * v;
                }
            }
            rows.push(
                touched
                    .into_iter()
                    .map(|j| {
                        seen[j] = false;
                        (j as u32, std::mem::take(&mut acc[j]))
                    })
                    .collect(),
            );
        }
        Csr::from_rows(b.width, rows)
    }

    fn diagonal(&self) -> Vec<f64> {
        (0..self.rows())
            .map(|i| self.row(i).find(|e| e.0 == i).map_or(0.0, |e| e.1))
            .collect()
    }

    /// `out = self · x`, each axis alike.
    fn apply(&self, x: &[DVec3], out: &mut [DVec3]) {
        par::each(out, |i, o| *o = self.row(i).map(|(c, v)| v * x[c]).sum());
    }

    /// Inverse absolute row sums.
    fn inv_l1(&self) -> Vec<f64> {
        (0..self.rows())
            .map(|i| self.row(i).map(|e| e.1.abs()).sum::<f64>().recip())
            .collect()
    }

    /// Largest eigenvalue of `D⁻¹ A` (power iteration; `A` symmetric with a positive diagonal).
    fn jacobi_radius(&self, diag: &[f64]) -> f64 {
        let n = self.rows();
        let mut u: Vec<f64> = (0..n).map(|i| 1.0 + (i % 7) as f64 * 0.1).collect();
        let mut lambda = 0.0;
        for _ in 0..50 {
            let y: Vec<f64> = (0..n)
                .map(|i| self.row(i).map(|(c, v)| v * u[c]).sum::<f64>() / diag[i])
                .collect();
            let norm = y.iter().map(|a| a * a).sum::<f64>().sqrt();
            let unorm = u.iter().map(|a| a * a).sum::<f64>().sqrt();
            if norm == 0.0 || unorm == 0.0 {
                return 0.0;
            }
            lambda = norm / unorm;
            u = y.into_iter().map(|a| a / norm).collect();
        }
        lambda
    }
}

/// A coarse level: its operator, the transfers to and from the level above, and scratch.
#[derive(Clone, Debug, Default)]
struct Level {
    a: Csr,
    /// Inverse absolute row sums (l1-Jacobi).
    inv_l1: Vec<f64>,
    /// Restriction from the level above (`Pᵀ`).
    down: Csr,
    /// Interpolation to the level above (`P`).
    up: Csr,
    x: Vec<DVec3>,
    b: Vec<DVec3>,
    r: Vec<DVec3>,
}

/// Greedy aggregates over a graph's nodes (`None`: not in the system): a node whose neighbours
/// are all unaggregated takes them; the rest join a neighbour's aggregate, or form their own.
fn aggregates(graph: &Csr, member: &[bool]) -> (Vec<Option<u32>>, usize) {
    let n = graph.rows();
    let mut agg: Vec<Option<u32>> = vec![None; n];
    let mut count = 0u32;
    for i in 0..n {
        if !member[i] || agg[i].is_some() {
            continue;
        }
        if graph.row(i).all(|(j, _)| j == i || agg[j].is_none()) {
            agg[i] = Some(count);
            for (j, _) in graph.row(i) {
                agg[j] = Some(count);
            }
            count += 1;
        }
    }
    for i in 0..n {
        if member[i] && agg[i].is_none() {
            agg[i] = graph.row(i).find_map(|(j, _)| agg[j]).or_else(|| {
                count += 1;
                Some(count - 1)
            });
        }
    }
    (agg, count as usize)
}

/// The smoothed-aggregation transfer `P = (I − ω D⁻¹L) P_tent`, ω = 4 / (3 ρ(D⁻¹L)).
fn transfer(lap: &Csr, member: &[bool]) -> Option<Csr> {
    let (agg, count) = aggregates(lap, member);
    if count == 0 || count * 4 > lap.rows() * 3 {
        return None;
    }
    let diag = lap.diagonal();
    let safe: Vec<f64> = diag
        .iter()
        .map(|&d| if d > 0.0 { d } else { 1.0 })
        .collect();
    let omega = 4.0 / (3.0 * lap.jacobi_radius(&safe).max(1e-300));
    let rows = (0..lap.rows())
        .map(|i| {
            let Some(own) = agg[i] else {
                return Vec::new();
            };
            let mut row = vec![(own, 1.0)];
            if diag[i] > 0.0 {
                for (j, v) in lap.row(i) {
                    if let Some(a) = agg[j] {
                        row.push((a, -omega * v / diag[i]));
                    }
                }
            }
            row
        })
        .collect();
    Some(Csr::from_rows(count, rows))
}

/// Scratch and hierarchy of one `theta-mg` step, built at prepare.
#[derive(Clone, Debug, Default)]
pub struct Multigrid {
    lin: Implicit,
    levels: Vec<Level>,
    /// Fine residual and product scratch.
    r: Vec<DVec3>,
    ap: Vec<DVec3>,
    /// Per particle, its free body (connected by springs, touching no pin), if any; per body,
    /// its mass and scratch for its momentum error.
    body: Vec<Option<u32>>,
    body_mass: Vec<f64>,
    body_error: Vec<DVec3>,
}

impl Multigrid {
    /// Sizes scratch and builds the coarse levels for step `h`.
    pub fn prepare(&mut self, packed: &Packed, h: f64) {
        let (n, m) = (packed.particle_count(), packed.springs.len());
        self.lin.resize(n, m);
        self.r.resize(n, DVec3::ZERO);
        self.ap.resize(n, DVec3::ZERO);
        self.levels.clear();
        let free: Vec<bool> = packed.inv_mass.iter().map(|&w| w != 0.0).collect();
        self.bodies(packed, &free);
        if free.iter().filter(|&&f| f).count() <= COARSEST {
            return;
        }
        // The spring graph (stiffness weights) and the isotropic operator, over free particles;
        // a spring to a pinned particle adds to its free end's diagonal only.
        let hs = THETA * h;
        let mut lap = vec![Vec::new(); n];
        let mut iso: Vec<Vec<(u32, f64)>> = (0..n)
            .map(|i| {
                if free[i] {
                    vec![(i as u32, packed.mass(i))]
                } else {
                    Vec::new()
                }
            })
            .collect();
        for s in &packed.springs {
            let (a, b) = (s.a as usize, s.b as usize);
            let w = hs * s.damping + hs * hs * s.stiffness;
            for (i, j) in [(a, b), (b, a)] {
                if free[i] {
                    lap[i].push((i as u32, s.stiffness));
                    iso[i].push((i as u32, w));
                    if free[j] {
                        lap[i].push((j as u32, -s.stiffness));
                        iso[i].push((j as u32, -w));
                    }
                }
            }
        }
        let (mut lap, mut a) = (Csr::from_rows(n, lap), Csr::from_rows(n, iso));
        let mut member = free;
        while lap.rows() > COARSEST {
            let Some(p) = transfer(&lap, &member) else {
                break;
            };
            let pt = p.transpose();
            let coarse = pt.mul(&a.mul(&p));
            lap = pt.mul(&lap.mul(&p));
            let k = coarse.rows();
            self.levels.push(Level {
                inv_l1: coarse.inv_l1(),
                a: coarse.clone(),
                down: pt,
                up: p,
                x: vec![DVec3::ZERO; k],
                b: vec![DVec3::ZERO; k],
                r: vec![DVec3::ZERO; k],
            });
            a = coarse;
            member = vec![true; k];
        }
    }

    pub fn step(&mut self, packed: &mut Packed, g: super::External<'_>, h: f64) {
        let hs = THETA * h;
        // l1 sweeps on the fine level; the same diagonal preconditions CG on small scenes.
        let degenerate = self.lin.linearise(packed, g, h, hs, true);
        if self.levels.is_empty() {
            self.lin.solve(packed);
        } else {
            self.cycle(packed);
        }
        self.keep_momentum(packed);
        self.lin.finish(packed, h, THETA, degenerate);
    }

    /// Free bodies: particles joined by springs among free particles, unless a spring ties
    /// them to a pin (a pin's force changes their momentum).
    fn bodies(&mut self, packed: &Packed, free: &[bool]) {
        let n = free.len();
        let mut parent: Vec<usize> = (0..n).collect();
        fn root(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        for s in &packed.springs {
            let (a, b) = (s.a as usize, s.b as usize);
            let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
            parent[ra.max(rb)] = ra.min(rb);
        }
        let mut anchored = vec![false; n];
        for (i, _) in free.iter().enumerate().filter(|(_, &f)| !f) {
            let r = root(&mut parent, i);
            anchored[r] = true;
        }
        let mut id = vec![None; n];
        self.body_mass.clear();
        self.body = (0..n)
            .map(|i| {
                let r = root(&mut parent, i);
                if !free[i] || anchored[r] {
                    return None;
                }
                let b = *id[r].get_or_insert_with(|| {
                    self.body_mass.push(0.0);
                    self.body_mass.len() as u32 - 1
                });
                self.body_mass[b as usize] += packed.mass(i);
                Some(b)
            })
            .collect();
        self.body_error = vec![DVec3::ZERO; self.body_mass.len()];
    }

    /// The exact step keeps each free body's momentum (`Σ m Δv = Σ rhs`: the springs' forces
    /// cancel); an unconverged cycle does not, so each body's error is spread over its mass.
    fn keep_momentum(&mut self, packed: &Packed) {
        if self.body_mass.is_empty() {
            return;
        }
        self.body_error.iter_mut().for_each(|e| *e = DVec3::ZERO);
        let lin = &mut self.lin;
        for (i, b) in self.body.iter().enumerate() {
            let e = lin.rhs[i] - packed.mass(i) * lin.dv[i];
            // A particle the quarantine will stop must not spread its NaN to its body.
            if let (Some(b), true) = (b, e.is_finite()) {
                self.body_error[*b as usize] += e;
            }
        }
        let (body, error, mass) = (&self.body, &self.body_error, &self.body_mass);
        par::each(&mut lin.dv, |i, d| {
            if let Some(b) = body[i] {
                *d += error[b as usize] / mass[b as usize];
            }
        });
    }

    /// One V-cycle on the fine system, into `lin.dv`.
    fn cycle(&mut self, packed: &Packed) {
        let lin = &mut self.lin;
        let (rhs, pre) = (&lin.rhs, &lin.precond);
        par::each(&mut lin.dv, |i, d| *d = rhs[i] * pre[i]);
        residual(packed, lin, &mut self.ap, &mut self.r);
        let first = &mut self.levels[0];
        first.down.apply(&self.r, &mut first.b);
        let last = self.levels.len() - 1;
        for l in 0..last {
            let (this, next) = self.levels.split_at_mut(l + 1);
            let lv = &mut this[l];
            sweep_from_zero(lv);
            coarse_residual(lv);
            next[0].down.apply(&lv.r, &mut next[0].b);
        }
        {
            let lv = &mut self.levels[last];
            lv.x.iter_mut().for_each(|x| *x = DVec3::ZERO);
            for _ in 0..COARSEST_SWEEPS {
                coarse_residual(lv);
                let (r, inv) = (&lv.r, &lv.inv_l1);
                par::each(&mut lv.x, |i, x| *x += inv[i] * r[i]);
            }
        }
        for l in (0..last).rev() {
            let (this, next) = self.levels.split_at_mut(l + 1);
            let lv = &mut this[l];
            next[0].up.apply(&next[0].x, &mut lv.r);
            let r = &lv.r;
            par::each(&mut lv.x, |i, x| *x += r[i]);
            coarse_residual(lv);
            let (r, inv) = (&lv.r, &lv.inv_l1);
            par::each(&mut lv.x, |i, x| *x += inv[i] * r[i]);
        }
        let lin = &mut self.lin;
        let first = &self.levels[0];
        first.up.apply(&first.x, &mut self.r);
        let r = &self.r;
        par::each(&mut lin.dv, |i, d| *d += r[i]);
        residual(packed, lin, &mut self.ap, &mut self.r);
        let (r, pre) = (&self.r, &lin.precond);
        par::each(&mut lin.dv, |i, d| *d += r[i] * pre[i]);
    }
}

/// `r = rhs − A Δv` on the fine level (0 at pinned particles).
fn residual(packed: &Packed, lin: &mut Implicit, ap: &mut [DVec3], r: &mut [DVec3]) {
    implicit::product(packed, &lin.block, &mut lin.term, &lin.dv, ap);
    let rhs = &lin.rhs;
    let ap = &*ap;
    par::each(r, |i, ri| {
        *ri = if packed.inv_mass[i] == 0.0 {
            DVec3::ZERO
        } else {
            rhs[i] - ap[i]
        }
    });
}

/// `x = D_l1⁻¹ b` (a sweep from zero).
fn sweep_from_zero(lv: &mut Level) {
    let (b, inv) = (&lv.b, &lv.inv_l1);
    par::each(&mut lv.x, |i, x| *x = inv[i] * b[i]);
}

/// `r = b − A x` on a coarse level.
fn coarse_residual(lv: &mut Level) {
    lv.a.apply(&lv.x, &mut lv.r);
    let b = &lv.b;
    par::each(&mut lv.r, |i, r| *r = b[i] - *r);
}
