//! Tethers (long-range attachments): each free particle of a cloth held within `(1 + slack)`
//! times its rest distance of its nearest anchors (the cloth's pinned or attached particles),
//! so a soft cloth hanging from a few points does not stretch without bound (Jolt's and
//! Chaos's long-range attachments, NvCloth's tethers).
//!
//! The rest distances are taken where the cloth is built (its rest shape), along the cloth:
//! geodesic over its triangles ([`geodesic`], a fast march), never shorter than the straight
//! line (a cloth made curved, a cape round the shoulders, may hang out straight to its full
//! length; a shortest path along the springs would overestimate it); a cloth without
//! triangles (a rope) takes the straight line.
//!
//! After each substep's springs, a particle's velocity away from an anchor (relative to the
//! anchor's own) is limited so that the next substep's move takes it at most to its limit,
//! and one past it comes back: a change of kinetic energy only, booked without evaluating a
//! spring. At a frame's last substep, a particle still past its limit
//! (its springs pulled it outward harder than gravity: by `h²` times the difference) is first
//! put back on that sphere and its velocity away from the anchor removed, so none ends a frame
//! past it. The audit books the change of `E` both made ([`crate::EnergyAudit::limits`], with
//! the stretch limits').
//!
//! With the springs on the GPU the clamp has a twin on the device (`shaders/tethers.wgsl`,
//! `gpu::tethers`) after every substep but the frame's last; that one's placing and clamp run
//! here, where the state comes back at a frame's end, so a tethered cloth's frame is one submit.

use glam::DVec3;
use hecs::{Entity, World};
use serde::{Deserialize, Serialize};

use crate::buffers::Packed;
use crate::components::{Particle, Pin, SceneIndex};
use crate::integrate::grid::Vector;

mod geodesic;
mod lanes;

use lanes::{clamp_one, Block, Rank, Substep, LANES, MAX_RANKS, MIXED, NONE};

/// A cloth's tethers, as a scene gives them (`tethers: Some((slack: 0.1, anchors: 1))`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TetherSpec {
    /// How far past its rest distance a particle may go, as a share of it (0.1: 10 %).
    #[serde(default = "default_slack")]
    pub slack: f64,
    /// Anchors per particle, its nearest (1 to 4; one leaves the seam between two anchors free
    /// to sag, more hold it).
    #[serde(default = "one")]
    pub anchors: u32,
}

fn default_slack() -> f64 {
    0.1
}

fn one() -> u32 {
    1
}

impl Default for TetherSpec {
    fn default() -> Self {
        TetherSpec {
            slack: default_slack(),
            anchors: 1,
        }
    }
}

impl TetherSpec {
    /// What a cloth's tethers must be: a slack finite and ≥ 0, 1 to 4 anchors.
    pub fn check(&self) -> Result<(), String> {
        if !(self.slack.is_finite() && self.slack >= 0.0) {
            return Err(format!(
                "slack must be finite and ≥ 0, got {:?}",
                self.slack
            ));
        }
        if !(1..=4).contains(&self.anchors) {
            return Err(format!("anchors must be 1 to 4, got {}", self.anchors));
        }
        Ok(())
    }
}

/// A tether: `(particle, anchor, limit m)`, the particle held within `limit` of the anchor.
pub type Link = (u32, u32, f64);

/// A cloth's tethers (a component on its cloth entity): for each free particle its nearest
/// anchors and the longest it may be from each, as offsets from the cloth's first particle.
#[derive(Clone, Debug, PartialEq)]
pub struct Tethers {
    /// The cloth's first particle (scene index).
    pub first: u32,
    /// Its tethers, particles and anchors as offsets from `first`.
    pub links: Vec<Link>,
}

/// The tethers of the cloth whose particles are scene indices `first .. first + count` in
/// `world`, for `spec`: every particle neither pinned nor attached tied to its nearest anchors
/// along the cloth's `triangles` (offsets from `first`) where they are now (the rest shape),
/// by the straight line where it has none. None where the cloth has no anchor.
pub(crate) fn build(
    world: &World,
    first: u32,
    count: u32,
    spec: &TetherSpec,
    triangles: &[[u32; 3]],
) -> Option<Tethers> {
    let mut parts: Vec<(u32, DVec3, bool)> = world
        .query::<(Entity, &SceneIndex, &Particle)>()
        .iter()
        .filter(|(_, i, _)| (first..first + count).contains(&i.0))
        .map(|(e, i, p)| {
            let held = world.get::<&Pin>(e).is_ok()
                || world.get::<&crate::contacts::Attachment>(e).is_ok();
            (i.0 - first, p.position, held)
        })
        .collect();
    parts.sort_unstable_by_key(|p| p.0);
    let anchors: Vec<(u32, DVec3)> = parts.iter().filter(|p| p.2).map(|p| (p.0, p.1)).collect();
    if anchors.is_empty() {
        return None;
    }
    let k = (spec.anchors as usize).min(anchors.len());
    let mut links = Vec::new();
    // Along the cloth, where it is one piece with its particles numbered from 0.
    let along = (!triangles.is_empty() && (0u32..).zip(&parts).all(|(j, p)| p.0 == j)).then(|| {
        let rest: Vec<DVec3> = parts.iter().map(|p| p.1).collect();
        let ids: Vec<u32> = anchors.iter().map(|a| a.0).collect();
        geodesic::nearest(&rest, triangles, &ids, k)
    });
    let mut near: Vec<(f64, u32)> = Vec::with_capacity(anchors.len());
    for &(i, x, held) in &parts {
        if held {
            continue;
        }
        if let Some(labels) = along.as_ref().map(|l| &l[i as usize]) {
            if !labels.is_empty() {
                // Never shorter than the straight line (the march's estimate on a curved
                // rest shape may fall under it), and the straight line where they agree to
                // rounding (a flat rest shape).
                links.extend(labels.iter().map(|&(d, a)| {
                    let line = (x - parts[a as usize].1).length();
                    let rest = if d > line * (1.0 + 1e-9) { d } else { line };
                    (i, a, rest * (1.0 + spec.slack))
                }));
                continue;
            }
        }
        near.clear();
        near.extend(anchors.iter().map(|&(a, y)| ((x - y).length(), a)));
        near.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let nearest = &mut near[..k];
        nearest.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        links.extend(nearest.iter().map(|&(d, a)| (i, a, d * (1.0 + spec.slack))));
    }
    Some(Tethers { first, links })
}

/// Particles per block of the tethers' parallel pass (the blocks' sums are added in block
/// order: the same on any thread count).
const BLOCK: usize = crate::audit::BLOCK;

/// The simulation's tethers in packed indices, and what their projections did this frame.
#[derive(Debug, Default)]
pub(crate) struct TetherStage {
    /// `(particle, anchor slot, limit)`, by particle.
    links: Vec<Link>,
    /// Each anchor slot's packed index, and its state at the substep's projections.
    anchors: Vec<u32>,
    held: Vec<(DVec3, DVec3)>,
    /// `links[starts[k]..starts[k + 1]]`: block `k`'s links.
    starts: Vec<usize>,
    /// The links again by rank, for the lanes: `ranked[r]` holds, per particle (packed
    /// index), its `r`-th anchor's slot ([`NONE`] where it has fewer) and limit, and per
    /// eight particles ([`LANES`]) which of them have such a link and the one anchor they
    /// share ([`MIXED`] where they do not).
    ranked: Vec<Rank>,
    /// Whether the clamp runs eight particles at a time ([`lanes`]).
    lanes: bool,
    /// What the frame's last placing moved; each block's change of `E` from the clamps, and
    /// from the placing with whether it moved any.
    moves: crate::audit::Moves,
    sums: Vec<f64>,
    placed: Vec<(f64, bool)>,
    parallel: bool,
    /// The change of `E` the tethers made this frame (J; mostly taken out, though a clamp
    /// that brings a particle back from past its limit puts some in).
    pub(crate) energy: f64,
}

impl TetherStage {
    /// Every cloth's tethers from `world`, in packed indices.
    pub(crate) fn gather(&mut self, world: &World, packed: &Packed) {
        self.links.clear();
        self.anchors.clear();
        let mut cloths: Vec<(u32, Vec<Link>)> = world
            .query::<&Tethers>()
            .iter()
            .map(|t| (t.first, t.links.clone()))
            .collect();
        cloths.sort_unstable_by_key(|c| c.0);
        let n = packed.particle_count() as u32;
        for (first, links) in cloths {
            self.links.extend(
                (links.into_iter())
                    .map(|(i, a, d)| (first + i, first + a, d))
                    .filter(|&(i, a, _)| i < n && a < n),
            );
        }
        // By particle (stable: each particle's anchors keep their order), anchors by slot.
        self.links.sort_by_key(|l| l.0);
        self.anchors.extend(self.links.iter().map(|l| l.1));
        self.anchors.sort_unstable();
        self.anchors.dedup();
        for l in &mut self.links {
            l.1 = self.anchors.binary_search(&l.1).unwrap_or(0) as u32;
        }
        self.held
            .resize(self.anchors.len(), (DVec3::ZERO, DVec3::ZERO));
        let n = if self.links.is_empty() { 0 } else { n as usize };
        let blocks = n.div_ceil(BLOCK);
        self.starts.clear();
        let links = &self.links;
        self.starts
            .extend((0..=blocks).map(|k| links.partition_point(|l| (l.0 as usize) < k * BLOCK)));
        for r in &mut self.ranked {
            r.slots.clear();
            r.limits.clear();
        }
        let mut from = 0;
        while from < self.links.len() {
            let i = self.links[from].0;
            let to = from + self.links[from..].partition_point(|l| l.0 == i);
            if self.ranked.len() < to - from {
                self.ranked.resize(to - from, Default::default());
            }
            for (r, l) in self.links[from..to].iter().enumerate() {
                let Rank { slots, limits, .. } = &mut self.ranked[r];
                slots.resize(n, NONE);
                limits.resize(n, 0.0);
                (slots[i as usize], limits[i as usize]) = (l.1, l.2);
            }
            from = to;
        }
        self.ranked.retain(|r| !r.slots.is_empty());
        for r in &mut self.ranked {
            r.lanes.clear();
            (r.lanes).extend(r.slots.chunks(LANES).map(|s| {
                let linked =
                    (s.iter().enumerate()).fold(0u8, |m, (j, &q)| m | (u8::from(q != NONE) << j));
                let one = s.iter().find(|&&q| q != NONE).copied().unwrap_or(NONE);
                let shared = s.len() == LANES && s.iter().all(|&q| q == one || q == NONE);
                (if shared { one } else { MIXED }, linked)
            }));
        }
        // More anchors to a particle than a scene can give (a game's own `Tethers`): link by
        // link.
        self.lanes = Vector::chosen().lanes_of_8() && self.ranked.len() <= MAX_RANKS;
        self.moves.reset(n);
        self.sums.resize(blocks, 0.0);
        self.placed.resize(blocks, (0.0, false));
        self.parallel = crate::integrate::runs_parallel(packed);
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.links.is_empty()
    }

    #[cfg(feature = "gpu")]
    /// `(particle, anchor, limit)` in packed indices, by particle (each particle's anchors in
    /// the order the clamp takes them).
    pub(crate) fn links(&self) -> impl Iterator<Item = Link> + '_ {
        (self.links.iter()).map(|&(i, slot, limit)| (i, self.anchors[slot as usize], limit))
    }

    /// After a substep's springs (`h` long): each particle's velocity away from each of its
    /// anchors (relative to the anchor's own) limited to what takes it, over the next
    /// substep's move, at most to its limit (a particle past it comes back); at the frame's
    /// `last` substep, first every particle past its limit put back on it ([`Self::place`]).
    /// Returns whether any was put back: the springs' change, from [`Self::moves`], is then
    /// the caller's to add.
    pub(crate) fn project(
        &mut self,
        packed: &mut Packed,
        gravity: DVec3,
        h: f64,
        last: bool,
    ) -> bool {
        let placed = last && self.place(packed, gravity);
        self.clamp(packed, gravity, h);
        placed
    }

    #[cfg(feature = "gpu")]
    /// The frame's last substep where the device ran the clamps of the others (`device`: the
    /// change of `E` they made): as [`Self::project`] at the `last` substep.
    pub(crate) fn finish_device(
        &mut self,
        packed: &mut Packed,
        gravity: DVec3,
        h: f64,
        device: f64,
    ) -> bool {
        self.energy += device;
        self.project(packed, gravity, h, true)
    }

    /// The anchors' states now: a tether changes its particle only, so the blocks read them.
    fn hold(&mut self, packed: &Packed) {
        for (h, &a) in self.held.iter_mut().zip(&self.anchors) {
            *h = (packed.x[a as usize], packed.v[a as usize]);
        }
    }

    /// Each particle's velocity away from each of its anchors limited, block by block: a
    /// tether changes its particle's velocity only, never an anchor's, and no position, so the
    /// kinetic energy it takes is the whole change of `E` (booked in `energy`). The next
    /// substep's move is taken as `h (v + h g)`: a particle whose springs pull it outward
    /// harder than gravity ends it past its limit by `h²` times the difference, and the next
    /// clamp brings it back.
    fn clamp(&mut self, packed: &mut Packed, gravity: DVec3, h: f64) {
        use rayon::prelude::*;
        self.hold(packed);
        let (ranked, held, lanes) = (&self.ranked, &self.held, self.lanes);
        let (x, inv) = (&packed.x, &packed.inv_mass);
        let at = Substep {
            ya: DVec3::ZERO,
            wa: DVec3::ZERO,
            gravity,
            hg: h * gravity,
            h,
            inv_h: 1.0 / h,
        };
        // Eight particles at a time, rank by rank (a particle's second anchor sees its first's
        // clamp): where the eight share one anchor their links run side by side, otherwise
        // (and without AVX-512) one by one; the same bits either way.
        // The energy is added particle by particle, each particle's anchors in order.
        let (links, starts) = (&self.links, &self.starts);
        let pull = |k: usize, vs: &mut [DVec3]| {
            let base = k * BLOCK;
            let mut change = 0.0;
            if !lanes {
                // Link by link, in the same order (as the lanes add their energies).
                for &(i, slot, limit) in &links[starts[k]..starts[k + 1]] {
                    let (i, (ya, wa)) = (i as usize, held[slot as usize]);
                    let s = Substep { ya, wa, ..at };
                    if let Some(e) = clamp_one(x[i], &mut vs[i - base], inv[i], limit, &s) {
                        change += e;
                    }
                }
                return change;
            }
            let block = Block {
                ranked,
                held,
                x,
                inv,
                at,
                base,
            };
            block.run(vs)
        };
        let (v, sums) = (&mut packed.v, &mut self.sums);
        if self.parallel {
            (v.par_chunks_mut(BLOCK).zip(sums.par_iter_mut()))
                .enumerate()
                .for_each(|(k, (vs, s))| *s = pull(k, vs));
        } else {
            (v.chunks_mut(BLOCK).zip(sums.iter_mut()))
                .enumerate()
                .for_each(|(k, (vs, s))| *s = pull(k, vs));
        }
        self.energy += self.sums.iter().sum::<f64>();
    }

    /// Every particle further than its limit from an anchor put back on the sphere, its
    /// velocity away from the anchor (relative to the anchor's) removed, block by block; the
    /// change of the particles' own energy booked. Whether any moved.
    fn place(&mut self, packed: &mut Packed, gravity: DVec3) -> bool {
        use rayon::prelude::*;
        self.hold(packed);
        let n = self.moves.moved.len();
        self.moves.reset(n);
        let (links, starts, held) = (&self.links, &self.starts, &self.held);
        let inv = &packed.inv_mass;
        let pull =
            |k: usize, xs: &mut [DVec3], vs: &mut [DVec3], bs: &mut [DVec3], ms: &mut [bool]| {
                let base = k * BLOCK;
                let (mut change, mut any) = (0.0, false);
                for &(i, slot, limit) in &links[starts[k]..starts[k + 1]] {
                    let (j, i) = (i as usize - base, i as usize);
                    let (ya, wa) = held[slot as usize];
                    let d = xs[j] - ya;
                    // Well within: no root taken (the margin keeps `len <= limit` below exact).
                    if d.length_squared() < limit * limit * (1.0 - 1e-12) {
                        continue;
                    }
                    let len = d.length();
                    if len <= limit || !len.is_finite() || inv[i] == 0.0 {
                        continue;
                    }
                    let was = crate::audit::particle_energy_at(inv[i], xs[j], vs[j], gravity);
                    crate::audit::Moves::mark(&mut ms[j], &mut bs[j], xs[j]);
                    any = true;
                    let n = d / len;
                    xs[j] = ya + n * limit;
                    let away = (vs[j] - wa).dot(n);
                    if away > 0.0 {
                        vs[j] -= away * n;
                    }
                    change += crate::audit::particle_energy_at(inv[i], xs[j], vs[j], gravity) - was;
                }
                (change, any)
            };
        let (x, v, sums) = (&mut packed.x, &mut packed.v, &mut self.placed);
        let (bs, ms) = (&mut self.moves.before, &mut self.moves.moved);
        if self.parallel {
            (x.par_chunks_mut(BLOCK).zip(v.par_chunks_mut(BLOCK)))
                .zip(bs.par_chunks_mut(BLOCK).zip(ms.par_chunks_mut(BLOCK)))
                .zip(sums.par_iter_mut())
                .enumerate()
                .for_each(|(k, (((xs, vs), (bs, ms)), s))| *s = pull(k, xs, vs, bs, ms));
        } else {
            (x.chunks_mut(BLOCK).zip(v.chunks_mut(BLOCK)))
                .zip(bs.chunks_mut(BLOCK).zip(ms.chunks_mut(BLOCK)))
                .zip(sums.iter_mut())
                .enumerate()
                .for_each(|(k, (((xs, vs), (bs, ms)), s))| *s = pull(k, xs, vs, bs, ms));
        }
        self.energy += self.placed.iter().map(|s| s.0).sum::<f64>();
        self.placed.iter().any(|s| s.1)
    }

    /// What the last placing moved.
    pub(crate) fn moves(&self) -> &crate::audit::Moves {
        &self.moves
    }
}
