//! Stretch limits (strain limiting): after the spring step, every spring of a cloth longer
//! than `(1 + stretch)` times its rest length is put back to that length, its ends moved in
//! proportion to their inverse masses (the pair's momentum kept), and the velocity that
//! separates them along it removed the same way. A stated number of Gauss–Seidel passes over
//! the cloth's springs in a fixed order, so a run is the same on any number of threads. What
//! the moves do to `E` is booked on [`crate::EnergyAudit::limits`].
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
    /// Passes over the cloth's springs each substep (1 to [`MAX_PASSES`]).
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
    /// What a stretch limit must be: a stretch finite and ≥ 0, 1 to [`MAX_PASSES`] passes.
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

/// The simulation's stretch limits in packed indices, and what their projections did this
/// frame.
#[derive(Debug, Default)]
pub(crate) struct StretchStage {
    bars: Vec<Bar>,
    /// Per limited cloth: its range of `bars` and its passes.
    cloths: Vec<(usize, usize, u32)>,
    /// What the substep's passes moved, and the moved particles' velocities before them.
    moves: crate::audit::Moves,
    before_v: Vec<DVec3>,
    /// The change of `E` the projections made this frame (J, ≤ 0 but for rounding).
    pub(crate) energy: f64,
}

impl StretchStage {
    /// Every limited cloth's springs from `packed`, by cloth in scene order, each cloth's in
    /// [`Packed::all_springs`]'s order; springs with both ends held are left out.
    pub(crate) fn gather(&mut self, world: &World, packed: &Packed) {
        self.bars.clear();
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
        for (bars, (_, _, limit)) in per.into_iter().zip(&limited) {
            let lo = self.bars.len();
            self.bars.extend(bars);
            self.cloths.push((lo, self.bars.len(), limit.passes));
        }
        let n = if self.bars.is_empty() {
            0
        } else {
            packed.particle_count()
        };
        self.moves.reset(n);
        self.before_v.resize(n, DVec3::ZERO);
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.bars.is_empty()
    }

    /// After a substep's springs: each limited cloth's passes over its springs; the change of
    /// the particles' own energy booked. Returns whether any moved: the springs' change, from
    /// [`Self::moves`], is then the caller's to add.
    pub(crate) fn project(&mut self, packed: &mut Packed, gravity: DVec3) -> bool {
        let n = self.moves.moved.len();
        self.moves.reset(n);
        let (moves, before_v) = (&mut self.moves, &mut self.before_v);
        let mut mark = |i: usize, x: DVec3, v: DVec3| {
            if !moves.moved[i] {
                before_v[i] = v;
            }
            crate::audit::Moves::mark(&mut moves.moved[i], &mut moves.before[i], x);
        };
        let mut moved = false;
        for &(lo, hi, passes) in &self.cloths {
            for _ in 0..passes {
                for &(a, b, longest) in &self.bars[lo..hi] {
                    let (a, b) = (a as usize, b as usize);
                    let d = packed.x[b] - packed.x[a];
                    let len2 = d.length_squared();
                    if len2 <= longest * longest || !len2.is_finite() {
                        continue;
                    }
                    let (wa, wb) = (packed.inv_mass[a], packed.inv_mass[b]);
                    let w = wa + wb;
                    moved = true;
                    mark(a, packed.x[a], packed.v[a]);
                    mark(b, packed.x[b], packed.v[b]);
                    let len = len2.sqrt();
                    let n = d / len;
                    let over = len - longest;
                    packed.x[a] += n * (over * wa / w);
                    packed.x[b] -= n * (over * wb / w);
                    let apart = (packed.v[b] - packed.v[a]).dot(n);
                    if apart > 0.0 {
                        packed.v[a] += n * (apart * wa / w);
                        packed.v[b] -= n * (apart * wb / w);
                    }
                }
            }
        }
        if moved {
            let (inv, x, v) = (&packed.inv_mass, &packed.x, &packed.v);
            let at = |i: usize, x: DVec3, v: DVec3| {
                crate::audit::particle_energy_at(inv[i], x, v, gravity)
            };
            let (moved, before) = (&self.moves.moved, &self.moves.before);
            for i in (0..moved.len()).filter(|&i| moved[i]) {
                let change = at(i, x[i], v[i]) - at(i, before[i], self.before_v[i]);
                // Gone non-finite: the quarantine's.
                if change.is_finite() {
                    self.energy += change;
                }
            }
        }
        moved
    }

    /// What the last passes moved.
    pub(crate) fn moves(&self) -> &crate::audit::Moves {
        &self.moves
    }
}
