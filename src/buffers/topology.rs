//! The part of [`Packed`] only a topology change rebuilds, and the pin refresh that leaves it
//! alone.

use std::ops::Range;
use std::sync::OnceLock;

use glam::DVec3;
use hecs::Entity;

use super::*;
use crate::error::SimError;

/// What a World gather builds and nothing else changes: the particles in scene order, the
/// cloth grids, and which springs touch each particle, pins aside. Features that add
/// constraints over the cloth hang their data here.
#[derive(Clone, Debug, Default)]
pub struct Topology {
    pub entities: Vec<Entity>,
    /// Cloth springs kept implicit ([`GatherOptions::keep_grids`]), by packed range.
    pub grids: Vec<PackedGrid>,
    /// Packed ranges of the particles in no grid (with kept grids; otherwise everything).
    pub loose: Vec<Range<usize>>,
    /// `touching[offsets[i]..offsets[i+1]]`: the indices in [`Packed::springs`] of the springs
    /// with an end at particle `i`, pinned or not (both empty without such springs: a cloth
    /// kept as a grid needs none).
    pub touching_offsets: Vec<u32>,
    pub touching: Vec<u32>,
    /// What was built beyond the state.
    pub options: GatherOptions,
    /// Entity id → packed index (`u32::MAX` where none), built on first use.
    pub(super) index_by_id: OnceLock<Vec<u32>>,
}

impl Topology {
    /// The packed index of a particle entity, if it was packed. The map behind it is built on
    /// first use (4 B per entity id), so a step that never asks costs nothing for it.
    pub fn index_of(&self, e: Entity) -> Option<usize> {
        let map = self.index_by_id.get_or_init(|| {
            let max_id = self.entities.iter().map(|e| e.id()).max();
            let mut index_of = vec![u32::MAX; max_id.map_or(0, |m| m as usize + 1)];
            for (i, e) in self.entities.iter().enumerate() {
                index_of[e.id() as usize] = i as u32;
            }
            index_of
        });
        let i = *map.get(e.id() as usize)? as usize;
        (self.entities.get(i) == Some(&e)).then_some(i)
    }

    /// The springs touching particle `i`.
    pub fn touching(&self, i: usize) -> &[u32] {
        match self.touching_offsets.get(i..i + 2) {
            Some(&[lo, hi]) => &self.touching[lo as usize..hi as usize],
            _ => &[],
        }
    }

    /// Indexes the springs by the particles they touch (both ends, pins aside).
    pub(super) fn index_springs(&mut self, n: usize, springs: &[PackedSpring]) {
        if springs.is_empty() {
            self.touching_offsets = Vec::new();
            self.touching = Vec::new();
            return;
        }
        let mut offsets = vec![0u32; n + 1];
        for s in springs {
            offsets[s.a as usize + 1] += 1;
            offsets[s.b as usize + 1] += 1;
        }
        for i in 0..n {
            offsets[i + 1] += offsets[i];
        }
        let mut fill = offsets.clone();
        let mut touching = vec![0u32; offsets[n] as usize];
        for (k, s) in springs.iter().enumerate() {
            for end in [s.a, s.b] {
                touching[fill[end as usize] as usize] = k as u32;
                fill[end as usize] += 1;
            }
        }
        self.touching_offsets = offsets;
        self.touching = touching;
    }
}

impl Packed {
    /// Pins (`None`) or frees with its mass (`Some(kg)`) particles by packed index, the
    /// topology untouched: the particle's inverse mass, the split of the springs touching it,
    /// the incidence and the colouring are refreshed, exactly as a gather of the same World
    /// would build them. Both kinds come to rest (a pinned particle has no velocity to resume).
    /// Checked before anything changes: an index out of range or a mass not finite and > 0.
    pub fn repin(&mut self, pins: &[(usize, Option<f64>)]) -> Result<(), SimError> {
        let n = self.x.len();
        for &(i, mass) in pins {
            if i >= n {
                return Err(SimError::NoParticle { index: i });
            }
            if let Some(m) = mass.filter(|m| !(m.is_finite() && *m > 0.0)) {
                let what = format!("mass must be finite and > 0, got {m:?}");
                return Err(match self.topology.entities.get(i) {
                    Some(&particle) => SimError::BadParticle { particle, what },
                    None => SimError::NoParticle { index: i },
                });
            }
        }
        for &(i, mass) in pins {
            self.inv_mass[i] = mass.map_or(0.0, |m| 1.0 / m);
            self.v[i] = DVec3::ZERO;
        }
        let topology = Arc::clone(&self.topology);
        for &(i, _) in pins {
            for &k in topology.touching(i) {
                let s = self.springs[k as usize];
                self.springs[k as usize] =
                    PackedSpring::new(s.a, s.b, s.rest, s.stiffness, s.damping, &self.inv_mass);
            }
        }
        if !self.springs.is_empty() {
            self.build_incidence();
        }
        if topology.options.colouring {
            self.colouring = Colouring::build(n, &self.springs);
        }
        Ok(())
    }
}
