//! Stretch limits (strain limiting): after the spring step, every spring of a cloth longer
//! than `(1 + stretch)` times its rest length is put back to that length, its ends moved in
//! proportion to their inverse masses (the pair's momentum kept), and the velocity that
//! separates them along it removed the same way. A stated number of Gauss–Seidel passes over
//! the cloth's springs in a fixed order, so a run is the same on any number of threads. What
//! the moves do to `E` is booked on [`crate::EnergyAudit::limits`].
//!
//! A pass runs the springs inside each block of [`BLOCK`] particles side by side (the blocks
//! share no particle, so their order does not matter), then the springs between blocks.
//!
//! Soft springs then give a cloth its swing and folds while the limit gives it a stiff
//! cloth's length, as in Provot's and Chaos's strain limiting; tethers
//! ([`crate::TetherSpec`]) hold the long range that local passes converge on slowly.

use glam::DVec3;
use hecs::World;
use serde::{Deserialize, Serialize};

use crate::buffers::Packed;
use crate::components::{ClothSprings, MeshSurface};

/// A cloth's stretch limit, as a scene gives it (`stretch_limit: Some((stretch: 0.1,
/// passes: 4))`); a component on the cloth's entity.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StretchLimit {
    /// The most a spring may stretch, as a share of its rest length (0.1: 10 %).
    #[serde(default = "default_stretch")]
    pub stretch: f64,
    /// Passes over the cloth's springs each substep (1 to 64).
    #[serde(default = "default_passes")]
    pub passes: u32,
}

/// The most passes a stretch limit may ask for each substep.
pub const MAX_PASSES: u32 = 64;

fn default_stretch() -> f64 {
    0.1
}

fn default_passes() -> u32 {
    4
}

impl Default for StretchLimit {
    fn default() -> Self {
        StretchLimit {
            stretch: default_stretch(),
            passes: default_passes(),
        }
    }
}

impl StretchLimit {
    /// What a stretch limit must be: a stretch finite and ≥ 0, 1 to 64 passes.
    pub fn check(&self) -> Result<(), String> {
        if !(self.stretch.is_finite() && self.stretch >= 0.0) {
            return Err(format!(
                "stretch must be finite and ≥ 0, got {:?}",
                self.stretch
            ));
        }
        if !(1..=MAX_PASSES).contains(&self.passes) {
            return Err(format!(
                "passes must be 1 to {MAX_PASSES}, got {}",
                self.passes
            ));
        }
        Ok(())
    }
}

/// A limited spring: `(a, b, longest m)` in packed indices.
type Bar = (u32, u32, f64);

/// Particles per block of a pass's parallel part.
const BLOCK: usize = crate::audit::BLOCK;

/// A limited cloth: its passes, and its bars, by block.
#[derive(Debug, Default)]
struct Limited {
    passes: u32,
    /// `blocks[k]`: the bars with both ends in particle block `k` (empty outside the cloth).
    blocks: Vec<Vec<Bar>>,
    /// The bars between blocks, after them.
    between: Vec<Bar>,
}

/// The simulation's stretch limits in packed indices, and what their projections did this
/// frame.
#[derive(Debug, Default)]
pub(crate) struct StretchStage {
    cloths: Vec<Limited>,
    /// What the substep's passes moved, and the moved particles' velocities before them.
    moves: crate::audit::Moves,
    before_v: Vec<DVec3>,
    parallel: bool,
    /// The change of `E` the projections made this frame (J, ≤ 0 but for rounding).
    pub(crate) energy: f64,
}

/// A block's chunks of the positions, velocities, and [`View`]'s `before`, `before_v` and
/// `moved`, as the zipped chunk iterators give them.
type Parts<'a> = (
    (
        ((&'a mut [DVec3], &'a mut [DVec3]), &'a mut [DVec3]),
        &'a mut [DVec3],
    ),
    &'a mut [bool],
);

/// One block's (or all particles') state, from particle `base`.
struct View<'a> {
    base: usize,
    x: &'a mut [DVec3],
    v: &'a mut [DVec3],
    inv: &'a [f64],
    before: &'a mut [DVec3],
    before_v: &'a mut [DVec3],
    moved: &'a mut [bool],
}

impl View<'_> {
    /// The passes' projection of one bar; whether it moved its ends.
    #[inline]
    fn bar(&mut self, (a, b, longest): Bar) -> bool {
        let (a, b) = (a as usize - self.base, b as usize - self.base);
        let d = self.x[b] - self.x[a];
        let len2 = d.length_squared();
        if len2 <= longest * longest || !len2.is_finite() {
            return false;
        }
        for i in [a, b] {
            if !self.moved[i] {
                self.before_v[i] = self.v[i];
            }
            crate::audit::Moves::mark(&mut self.moved[i], &mut self.before[i], self.x[i]);
        }
        let (wa, wb) = (self.inv[a], self.inv[b]);
        let w = wa + wb;
        let len = len2.sqrt();
        let n = d / len;
        let over = len - longest;
        self.x[a] += n * (over * wa / w);
        self.x[b] -= n * (over * wb / w);
        let apart = (self.v[b] - self.v[a]).dot(n);
        if apart > 0.0 {
            self.v[a] += n * (apart * wa / w);
            self.v[b] -= n * (apart * wb / w);
        }
        true
    }

    fn bars(&mut self, bars: &[Bar]) -> bool {
        let mut moved = false;
        for &bar in bars {
            moved |= self.bar(bar);
        }
        moved
    }
}

impl StretchStage {
    /// Every limited cloth's springs from `packed`, by cloth in scene order, each cloth's in
    /// [`Packed::all_springs`]'s order, split by block; springs with both ends held are left
    /// out.
    pub(crate) fn gather(&mut self, world: &World, packed: &Packed) {
        self.cloths.clear();
        let mut limited: Vec<(u32, u32, StretchLimit)> = world
            .query::<(&StretchLimit, Option<&ClothSprings>, Option<&MeshSurface>)>()
            .iter()
            .filter_map(|(l, c, m)| match (c, m) {
                (Some(c), _) => Some((c.grid.first, c.grid.cols * c.grid.rows, *l)),
                (_, Some(m)) => Some((m.first, m.count, *l)),
                _ => None,
            })
            .collect();
        limited.sort_unstable_by_key(|c| c.0);
        let mut per: Vec<Vec<Bar>> = vec![Vec::new(); limited.len()];
        let inv = &packed.inv_mass;
        for s in packed.all_springs() {
            let k = limited.partition_point(|c| c.0 <= s.a);
            let Some(&(first, count, limit)) = k.checked_sub(1).and_then(|k| limited.get(k)) else {
                continue;
            };
            let within = |i: u32| (first..first + count).contains(&i);
            let free = inv[s.a as usize] + inv[s.b as usize] > 0.0;
            if within(s.a) && within(s.b) && free {
                per[k - 1].push((s.a, s.b, s.rest * (1.0 + limit.stretch)));
            }
        }
        let n = packed.particle_count();
        let blocks = n.div_ceil(BLOCK);
        for (bars, (_, _, limit)) in per.into_iter().zip(&limited) {
            let mut cloth = Limited {
                passes: limit.passes,
                blocks: vec![Vec::new(); blocks],
                between: Vec::new(),
            };
            for bar in bars {
                let (ka, kb) = (bar.0 as usize / BLOCK, bar.1 as usize / BLOCK);
                if ka == kb {
                    cloth.blocks[ka].push(bar);
                } else {
                    cloth.between.push(bar);
                }
            }
            self.cloths.push(cloth);
        }
        let n = if self.is_empty() { 0 } else { n };
        self.moves.reset(n);
        self.before_v.resize(n, DVec3::ZERO);
        self.parallel = crate::integrate::runs_parallel(packed);
    }

    pub(crate) fn is_empty(&self) -> bool {
        (self.cloths.iter()).all(|c| c.between.is_empty() && c.blocks.iter().all(Vec::is_empty))
    }

    /// After a substep's springs: each limited cloth's passes over its springs; the change of
    /// the particles' own energy booked. Returns whether any moved: the springs' change, from
    /// [`Self::moves`], is then the caller's to add.
    pub(crate) fn project(&mut self, packed: &mut Packed, gravity: DVec3) -> bool {
        use rayon::prelude::*;
        let n = self.moves.moved.len();
        self.moves.reset(n);
        let mut moved = false;
        let parallel = self.parallel;
        for cloth in &self.cloths {
            for _ in 0..cloth.passes {
                let (x, v, inv) = (&mut packed.x, &mut packed.v, &packed.inv_mass[..]);
                let (before, moves) = (&mut self.moves.before, &mut self.moves.moved);
                let before_v = &mut self.before_v;
                let block = |(k, ((((x, v), before), before_v), moved)): (usize, Parts)| {
                    let base = k * BLOCK;
                    let bars = &cloth.blocks[k];
                    if bars.is_empty() {
                        return false;
                    }
                    let inv = &inv[base..base + x.len()];
                    View {
                        base,
                        x,
                        v,
                        inv,
                        before,
                        before_v,
                        moved,
                    }
                    .bars(bars)
                };
                moved |= if parallel {
                    (x.par_chunks_mut(BLOCK).zip(v.par_chunks_mut(BLOCK)))
                        .zip(before.par_chunks_mut(BLOCK))
                        .zip(before_v.par_chunks_mut(BLOCK))
                        .zip(moves.par_chunks_mut(BLOCK))
                        .enumerate()
                        .map(block)
                        .reduce(|| false, |a, b| a | b)
                } else {
                    (x.chunks_mut(BLOCK).zip(v.chunks_mut(BLOCK)))
                        .zip(before.chunks_mut(BLOCK))
                        .zip(before_v.chunks_mut(BLOCK))
                        .zip(moves.chunks_mut(BLOCK))
                        .enumerate()
                        .map(block)
                        .fold(false, |a, b| a | b)
                };
                let mut all = View {
                    base: 0,
                    x,
                    v,
                    inv,
                    before,
                    before_v,
                    moved: moves,
                };
                moved |= all.bars(&cloth.between);
            }
        }
        if moved {
            (self.moves).book_particles(&self.before_v, packed, gravity, &mut self.energy);
        }
        moved
    }

    /// What the last passes moved.
    pub(crate) fn moves(&self) -> &crate::audit::Moves {
        &self.moves
    }
}
