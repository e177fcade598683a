//! Tearing: at a frame's end, every spring of a tearable cloth stretched past `(1 + stretch)`
//! times its rest length breaks. The springs go from the World, the cloth's triangles that
//! had a broken edge go from its surface (the render mesh and the air split along the tear),
//! the game hears of each break ([`crate::Simulation::torn`]), and the next frame gathers the
//! new topology. The energy a broken spring held leaves `E`, booked as
//! [`crate::EnergyAudit::torn`].
//!
//! The check runs once a frame on the host, in the springs' fixed order, so it is the same on
//! any number of threads and on both back ends (with springs on the GPU the frame's end state
//! is on the host anyway). A tearable cloth keeps its springs one by one (a grid cloth is
//! built as a mesh of its grid), since a break changes them.

use std::collections::HashSet;

use hecs::{Entity, World};
use serde::{Deserialize, Serialize};

use crate::buffers::{Packed, PackedSpring};
use crate::components::{MeshSurface, Spring};

/// A cloth's tearing, as a scene gives it (`tearing: Some((stretch: 0.5))`); a component on
/// the cloth's entity.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tearing {
    /// The stretch, a share of the rest length, past which a spring breaks (0.5: at 1.5 times
    /// its rest length).
    pub stretch: f64,
}

impl Tearing {
    /// What a cloth's tearing must be, beside its stretch limit if it has one: a stretch
    /// finite and > 0, and past the limit's (which would hold every spring short of it).
    pub fn check_beside(&self, limit: Option<crate::StretchLimit>) -> Result<(), String> {
        if !(self.stretch.is_finite() && self.stretch > 0.0) {
            return Err(format!(
                "stretch must be finite and > 0, got {:?}",
                self.stretch
            ));
        }
        if let Some(l) = limit.filter(|l| l.stretch >= self.stretch) {
            return Err(format!(
                "stretch {:?} must be past the stretch limit's {:?}, which holds every spring \
                 short of it",
                self.stretch, l.stretch
            ));
        }
        Ok(())
    }
}

/// A spring that broke: its cloth, its ends (scene indices) and the frame it broke in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tear {
    /// The cloth it belonged to.
    pub cloth: crate::ClothId,
    /// One end, a scene index (the order of [`crate::Simulation::positions`]).
    pub a: usize,
    /// The other end.
    pub b: usize,
    /// Frames completed before the one it broke in.
    pub step: u64,
}

/// The tearable cloths' springs in packed indices, and the frame's breaks.
#[derive(Debug, Default)]
pub(crate) struct TearStage {
    /// Per tearable cloth: its entity and its particles' packed range.
    cloths: Vec<(Entity, u32, u32)>,
    /// `(index in Packed::springs, breaking length m)`.
    springs: Vec<(u32, f64)>,
    /// The frame's breaks: their ends (packed indices, the lower first), in springs' order.
    pub(crate) broken: Vec<(u32, u32)>,
    /// The energy the broken springs held at the frame's end (J).
    pub(crate) energy: f64,
}

impl TearStage {
    /// Every tearable cloth's springs from `packed` (a tearable cloth's are all loose).
    pub(crate) fn gather(&mut self, world: &World, packed: &Packed) {
        self.cloths.clear();
        self.springs.clear();
        self.broken.clear();
        let mut stretch = Vec::new();
        for (e, (surface, tearing)) in world.query::<(Entity, (&MeshSurface, &Tearing))>().iter() {
            self.cloths.push((e, surface.first, surface.count));
            stretch.push((surface.first, surface.count, tearing.stretch));
        }
        self.cloths.sort_unstable_by_key(|c| c.1);
        stretch.sort_unstable_by_key(|c| c.0);
        for (k, s) in packed.springs.iter().enumerate() {
            let c = stretch.partition_point(|c| c.0 <= s.a);
            let Some(&(first, count, stretch)) = c.checked_sub(1).and_then(|c| stretch.get(c))
            else {
                continue;
            };
            let within = |i: u32| (first..first + count).contains(&i);
            if within(s.a) && within(s.b) {
                self.springs.push((k as u32, s.rest * (1.0 + stretch)));
            }
        }
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.springs.is_empty()
    }

    /// At the frame's end: the springs past their breaking length, and the energy they held;
    /// each one left in `packed` as a spring of no length and no stiffness, so nothing that
    /// reads the buffers before the next gather (the strain check) sees it.
    pub(crate) fn find(&mut self, packed: &mut Packed) {
        self.broken.clear();
        self.energy = 0.0;
        for &(k, longest) in &self.springs {
            let s = packed.springs[k as usize];
            let (a, b) = (s.a as usize, s.b as usize);
            // A NaN length is the quarantine's, not a tear.
            if (packed.x[b] - packed.x[a]).length_squared() > longest * longest {
                self.broken.push((s.a.min(s.b), s.a.max(s.b)));
                self.energy +=
                    crate::audit::spring_energy_at(packed.x[a], packed.x[b], (&s).into());
                packed.springs[k as usize] = PackedSpring {
                    b: s.a,
                    stiffness: 0.0,
                    damping: 0.0,
                    ..s
                };
            }
        }
    }

    /// The frame's breaks into `world`: the springs despawned, the triangles with a broken
    /// edge dropped from their surface; each break as `(cloth entity, a, b)` in scene indices
    /// (packed indices are scene indices) into `out`.
    pub(crate) fn apply(
        &self,
        world: &mut World,
        packed: &Packed,
        out: &mut Vec<(Entity, u32, u32)>,
    ) {
        let pairs: HashSet<(u32, u32)> = self.broken.iter().copied().collect();
        let entities = &packed.topology.entities;
        let by_entity: HashSet<(Entity, Entity)> = (pairs.iter())
            .flat_map(|&(a, b)| {
                let (ea, eb) = (entities[a as usize], entities[b as usize]);
                [(ea, eb), (eb, ea)]
            })
            .collect();
        let mut gone: Vec<Entity> = world
            .query::<(Entity, &Spring)>()
            .iter()
            .filter(|(_, s)| by_entity.contains(&(s.a, s.b)))
            .map(|(e, _)| e)
            .collect();
        gone.sort_unstable();
        for e in gone {
            let _ = world.despawn(e);
        }
        for &(e, first, _) in &self.cloths {
            if let Ok(mut surface) = world.get::<&mut MeshSurface>(e) {
                let broken = |i: u32, j: u32| {
                    pairs.contains(&((i + first).min(j + first), (i + first).max(j + first)))
                };
                surface
                    .triangles
                    .retain(|&[a, b, c]| !(broken(a, b) || broken(b, c) || broken(c, a)));
            }
        }
        for &(a, b) in &self.broken {
            let c = self.cloths.partition_point(|c| c.1 <= a);
            if let Some(&(e, _, _)) = c.checked_sub(1).and_then(|c| self.cloths.get(c)) {
                out.push((e, a, b));
            }
        }
    }
}
