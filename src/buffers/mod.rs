//! Gather and scatter: the World packed into structure-of-arrays buffers.
//!
//! The topology ([`Topology`]) is packed once per topology change; a pin set or freed
//! refreshes the mass split ([`Packed::repin`]); between them the buffers are the state and
//! the World is only written back at scatter.

// Not API: reachable from outside only through the hidden `internals` module.
#![allow(missing_docs)]

use std::ops::Range;
use std::sync::Arc;

use glam::DVec3;
use hecs::{Entity, World};
use rayon::prelude::*;

use crate::components::{GridLink, Particle};
use crate::error::SimError;

mod gather;
mod topology;

pub use topology::Topology;

/// A spring in packed form. `wa`/`wb` split the pair's relative velocity change by mass:
/// `Δv_a = −wa φ n`, `Δv_b = +wb φ n`, with `wa = μ/m_a`, `wb = μ/m_b` (0 at a pinned end).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PackedSpring {
    pub a: u32,
    pub b: u32,
    pub rest: f64,
    pub stiffness: f64,
    pub damping: f64,
    /// Reduced mass; infinite when both ends are pinned (the spring then does nothing).
    pub mu: f64,
    pub wa: f64,
    pub wb: f64,
}

impl PackedSpring {
    /// `κ/μ`, 0 when both ends are pinned.
    pub fn omega0_sq(&self) -> f64 {
        if self.mu.is_finite() {
            self.stiffness / self.mu
        } else {
            0.0
        }
    }

    /// `h/h_c` for a step `h`, `h_c = π/ω0`.
    pub fn step_ratio(&self, h: f64) -> f64 {
        h * self.omega0_sq().sqrt() / std::f64::consts::PI
    }
    /// `c/(2μ)`, 0 when both ends are pinned.
    pub fn alpha(&self) -> f64 {
        if self.mu.is_finite() {
            self.damping / (2.0 * self.mu)
        } else {
            0.0
        }
    }
    /// Damping ratio `ζ = α/ω0`.
    pub fn zeta(&self) -> f64 {
        let w2 = self.omega0_sq();
        if w2 > 0.0 {
            self.alpha() / w2.sqrt()
        } else {
            0.0
        }
    }
}

/// Per-particle lists of incident springs (CSR); pinned ends get no entry.
#[derive(Clone, Debug, Default)]
pub struct Incidence {
    /// `offsets[i]..offsets[i+1]` indexes `spring`/`coef` for particle `i`.
    pub offsets: Vec<u32>,
    pub spring: Vec<u32>,
    /// `−wa` at a spring's `a` end, `+wb` at its `b` end.
    pub coef: Vec<f64>,
}

impl Incidence {
    /// `Σ coef · per_spring[s]` over particle `i`'s springs, in a fixed order (deterministic).
    #[inline(always)]
    pub fn sum(&self, per_spring: &[DVec3], i: usize) -> DVec3 {
        if self.offsets.is_empty() {
            return DVec3::ZERO;
        }
        let (lo, hi) = (self.offsets[i] as usize, self.offsets[i + 1] as usize);
        let mut sum = DVec3::ZERO;
        for k in lo..hi {
            sum += self.coef[k] * per_spring[self.spring[k] as usize];
        }
        sum
    }
}

/// Springs grouped by colour: springs of one colour share no particle, so a colour can be
/// processed in parallel in Gauss–Seidel order. Springs with both ends pinned are left out.
#[derive(Clone, Debug, Default)]
pub struct Colouring {
    /// `offsets[c]..offsets[c+1]` indexes `springs` for colour `c`.
    pub offsets: Vec<u32>,
    pub springs: Vec<u32>,
}

impl Colouring {
    pub fn colours(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// The springs of colour `c`.
    pub fn members(&self, c: usize) -> &[u32] {
        &self.springs[self.offsets[c] as usize..self.offsets[c + 1] as usize]
    }

    /// Greedy edge colouring in spring order (at most 2·max degree − 1 colours).
    fn build(n: usize, springs: &[PackedSpring]) -> Self {
        let mut degree = vec![0u32; n];
        for s in springs {
            degree[s.a as usize] += 1;
            degree[s.b as usize] += 1;
        }
        let max_deg = degree.iter().copied().max().unwrap_or(0) as usize;
        let words = (2 * max_deg) / 64 + 1;
        let mut used = vec![0u64; n * words];
        let mut colour = vec![u32::MAX; springs.len()];
        let mut count = Vec::<u32>::new();
        for (k, s) in springs.iter().enumerate() {
            if s.wa == 0.0 && s.wb == 0.0 {
                continue;
            }
            let (a, b) = (s.a as usize * words, s.b as usize * words);
            #[allow(
                clippy::expect_used,
                reason = "a spring meets at most 2·max_deg − 2 others"
            )]
            let c = (0..words)
                .find_map(|w| {
                    let free = !(used[a + w] | used[b + w]);
                    (free != 0).then(|| w * 64 + free.trailing_zeros() as usize)
                })
                .expect("2·max degree colours always suffice");
            used[a + c / 64] |= 1 << (c % 64);
            used[b + c / 64] |= 1 << (c % 64);
            colour[k] = c as u32;
            if count.len() <= c {
                count.resize(c + 1, 0);
            }
            count[c] += 1;
        }
        let mut offsets = vec![0u32; count.len() + 1];
        for c in 0..count.len() {
            offsets[c + 1] = offsets[c] + count[c];
        }
        let mut fill = offsets.clone();
        let mut order = vec![0u32; offsets[count.len()] as usize];
        for (k, &c) in colour.iter().enumerate() {
            if c != u32::MAX {
                order[fill[c as usize] as usize] = k as u32;
                fill[c as usize] += 1;
            }
        }
        Colouring {
            offsets,
            springs: order,
        }
    }
}

/// A cloth's springs in packed form ([`crate::ClothSprings`] with its particles located): the
/// particle at grid `(c, r)` is packed index `base + r·cols + c`.
#[derive(Clone, Debug, PartialEq)]
pub struct PackedGrid {
    /// The entity holding the [`crate::ClothSprings`].
    pub entity: Entity,
    pub base: u32,
    pub cols: u32,
    pub rows: u32,
    pub links: Vec<GridLink>,
}

impl PackedGrid {
    /// Its particles' packed indices.
    pub fn range(&self) -> Range<usize> {
        self.base as usize..self.base as usize + self.cols as usize * self.rows as usize
    }

    /// Rows a link reaches across (the largest `|dr|`; a link longer than the grid joins
    /// nothing).
    pub fn reach(&self) -> usize {
        self.links
            .iter()
            .map(|l| l.offset.1.unsigned_abs() as usize)
            .max()
            .unwrap_or(0)
            .min(self.rows.saturating_sub(1) as usize)
    }

    /// Link `l`'s springs anchored in grid row `row`: the packed ends of the first,
    /// `(a, b)`, and how many there are; the `k`-th joins `a + k` to `b + k`. None when the
    /// link reaches past the grid. The one definition of where a grid's springs are.
    #[inline]
    pub fn link_row(&self, l: &GridLink, row: u32) -> Option<(u32, u32, u32)> {
        let (dc, dr) = l.offset;
        let (adc, adr) = (dc.unsigned_abs(), dr.unsigned_abs());
        if adc >= self.cols || row + adr >= self.rows {
            return None;
        }
        let at = |c: u32, r: u32| self.base + r * self.cols + c;
        let a = at((-dc).max(0) as u32, row + (-dr).max(0) as u32);
        let b = at(dc.max(0) as u32, row + dr.max(0) as u32);
        Some((a, b, self.cols - adc))
    }

    /// The springs of grid row `row`, each once, in the order expansion packs them: cell by
    /// cell, the links in order, a link with `dc < 0` anchored `|dc|` columns right.
    fn row_springs<'a>(
        &'a self,
        row: u32,
        inv_mass: &'a [f64],
    ) -> impl Iterator<Item = PackedSpring> + 'a {
        (0..self.cols).flat_map(move |col| {
            self.links.iter().filter_map(move |l| {
                let (a, b, _) = self.link_row(l, row).filter(|&(_, _, n)| col < n)?;
                Some(PackedSpring::new(
                    a + col,
                    b + col,
                    l.rest_length,
                    l.stiffness,
                    l.damping,
                    inv_mass,
                ))
            })
        })
    }

    /// Every spring of the grid, in expansion order.
    pub fn springs<'a>(&'a self, inv_mass: &'a [f64]) -> impl Iterator<Item = PackedSpring> + 'a {
        (0..self.rows).flat_map(move |r| self.row_springs(r, inv_mass))
    }

    pub fn spring_count(&self) -> usize {
        self.links
            .iter()
            .map(|l| l.count(self.cols, self.rows) as usize)
            .sum()
    }
}

impl PackedSpring {
    /// A spring between packed particles `a` and `b`, split by their masses (`1/inv_mass`,
    /// infinite where pinned).
    pub fn new(a: u32, b: u32, rest: f64, stiffness: f64, damping: f64, inv_mass: &[f64]) -> Self {
        let (ma, mb) = (mass_of(inv_mass[a as usize]), mass_of(inv_mass[b as usize]));
        let mu = reduced_mass(ma, mb);
        let (wa, wb) = if mu.is_finite() {
            (mu / ma, mu / mb)
        } else {
            (0.0, 0.0)
        };
        PackedSpring {
            a,
            b,
            rest,
            stiffness,
            damping,
            mu,
            wa,
            wb,
        }
    }
}

/// What [`Packed::gather_with`] builds beyond the state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GatherOptions {
    /// Keep cloth springs as [`PackedGrid`]s (no memory per spring; only the integrators with
    /// a grid pass take them) instead of expanding them into [`Packed::springs`].
    pub keep_grids: bool,
    /// Build the colouring (Gauss–Seidel, XPBD and the GPU back end need it).
    pub colouring: bool,
}

impl GatherOptions {
    /// Everything expanded and coloured: what any integrator or tool can run on.
    pub const FULL: Self = Self {
        keep_grids: false,
        colouring: true,
    };
}

/// The packed scene. Split the way Jolt splits a soft body's shared settings from its
/// instance: [`Topology`] (the particle order, the cloth grids, which springs touch
/// which particle) is built by a World gather and shared; the state (`x`, `v`) and the mass
/// split (`inv_mass` with pins applied, the springs' `mu`/`wa`/`wb`, the incidence and
/// colouring) are the instance. Moving a pinned particle writes the state only; pinning or
/// freeing one refreshes the mass split ([`Self::repin`]); neither reads the World.
#[derive(Clone, Debug, Default)]
pub struct Packed {
    pub topology: Arc<Topology>,
    pub x: Vec<DVec3>,
    pub v: Vec<DVec3>,
    /// 0 for pinned particles.
    pub inv_mass: Vec<f64>,
    /// Springs one by one: the World's [`crate::Spring`]s, then the cloths' unless kept as grids.
    /// `a`, `b`, `rest`, `stiffness`, `damping` are topology; `mu`, `wa`, `wb` the mass split.
    pub springs: Vec<PackedSpring>,
    /// Incidence of `springs` (empty without springs); pinned ends have no entry.
    pub incidence: Incidence,
    pub colouring: Colouring,
}

impl Packed {
    pub fn particle_count(&self) -> usize {
        self.x.len()
    }

    /// Particle `i`'s mass (kg), infinite when pinned.
    #[inline]
    pub fn mass(&self, i: usize) -> f64 {
        mass_of(self.inv_mass[i])
    }

    /// Springs in all, kept grids included.
    pub fn spring_count(&self) -> usize {
        self.springs.len()
            + self
                .topology
                .grids
                .iter()
                .map(PackedGrid::spring_count)
                .sum::<usize>()
    }

    /// Every spring, `springs` then the kept grids' (expansion order).
    pub fn all_springs(&self) -> impl Iterator<Item = PackedSpring> + '_ {
        let inv = &self.inv_mass[..];
        self.springs
            .iter()
            .copied()
            .chain(self.topology.grids.iter().flat_map(move |g| g.springs(inv)))
    }

    /// [`Self::all_springs`] in parallel (unordered).
    pub fn par_springs(&self) -> impl ParallelIterator<Item = PackedSpring> + '_ {
        let inv = &self.inv_mass[..];
        self.springs
            .par_iter()
            .copied()
            .chain(self.topology.grids.par_iter().flat_map(move |g| {
                (0..g.rows)
                    .into_par_iter()
                    .flat_map_iter(move |r| g.row_springs(r, inv))
            }))
    }

    /// Packs every particle and spring of the World, cloths expanded and coloured.
    pub fn gather(world: &World) -> Result<Self, SimError> {
        Self::gather_with(world, GatherOptions::FULL)
    }

    /// Packs the World.
    pub fn gather_with(world: &World, options: GatherOptions) -> Result<Self, SimError> {
        let mut packed = Packed::default();
        packed.regather(world, options)?;
        Ok(packed)
    }

    /// Writes positions and velocities back into the World's particles.
    pub fn scatter(&self, world: &mut World) {
        // Entity by entity, in packed order: no index map, and (unlike a view) no allocation.
        for (i, &e) in self.topology.entities.iter().enumerate() {
            if let Ok(p) = world.query_one_mut::<&mut Particle>(e) {
                p.position = self.x[i];
                if self.inv_mass[i] != 0.0 {
                    p.velocity = self.v[i];
                }
            }
        }
    }

    /// Puts back the state the World holds, which the last scatter or edit wrote: every
    /// particle's position, a free particle's velocity, a pinned one at rest (as gathered).
    /// Entity by entity, in packed order, as [`Self::scatter`] writes it: bit for bit the
    /// state the frame started from, with no copy of it kept.
    pub fn reload_state(&mut self, world: &World) {
        for (i, &e) in self.topology.entities.iter().enumerate() {
            if let Ok(p) = world.get::<&Particle>(e) {
                self.x[i] = p.position;
                self.v[i] = if self.inv_mass[i] != 0.0 {
                    p.velocity
                } else {
                    DVec3::ZERO
                };
            }
        }
    }

    /// The packed index of a particle entity, if it was packed.
    pub fn index_of(&self, e: Entity) -> Option<usize> {
        self.topology.index_of(e)
    }

    /// Stretch `δ = |x_b − x_a| − l0` of spring `s`.
    pub fn stretch(&self, s: &PackedSpring) -> f64 {
        (self.x[s.b as usize] - self.x[s.a as usize]).length() - s.rest
    }
}

/// The mass of an inverse mass: infinite for 0 (pinned).
#[inline]
fn mass_of(inv_mass: f64) -> f64 {
    if inv_mass == 0.0 {
        f64::INFINITY
    } else {
        1.0 / inv_mass
    }
}

/// `m_a m_b/(m_a+m_b)`, the free end's mass when the other is pinned (infinite).
pub fn reduced_mass(m_a: f64, m_b: f64) -> f64 {
    match (m_a.is_finite(), m_b.is_finite()) {
        (true, true) => m_a * m_b / (m_a + m_b),
        (true, false) => m_a,
        (false, true) => m_b,
        (false, false) => f64::INFINITY,
    }
}
