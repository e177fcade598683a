//! Gathering the World into [`Packed`]: every component checked before the old buffers go,
//! springs sorted, cloth grids located, the incidence and colouring built.

use glam::DVec3;
use hecs::{Entity, World};

use super::*;
use crate::components::{ClothSprings, GridLink, Particle, Pin, SceneIndex, Spring};
use crate::error::SimError;

impl Packed {
    /// Packs the World into `self`. Everything is checked before the old buffers go, so an
    /// error leaves them as they were; after that the only scratch beside the World is the
    /// sort keys (16 B per particle), freed before the state is allocated.
    pub fn regather(&mut self, world: &World, options: GatherOptions) -> Result<(), SimError> {
        let mut keys: Vec<(u32, u32, Entity)> = world
            .query::<(Entity, &Particle, Option<&SceneIndex>)>()
            .iter()
            .map(|(e, _, idx)| (idx.map_or(u32::MAX, |i| i.0), e.id(), e))
            .collect();
        keys.sort_unstable_by_key(|k| (k.0, k.1));
        let view = world.view::<(&Particle, Option<&Pin>)>();
        for &(_, _, e) in &keys {
            let Some((p, pin)) = view.get(e) else {
                continue;
            };
            // Components set through the World get the checks a scene file gets. A non-finite
            // velocity is not refused: the step quarantines the particle instead.
            let bad = |what: String| SimError::BadParticle { particle: e, what };
            if !p.position.is_finite() {
                return Err(bad(format!(
                    "position must be finite, got {}",
                    crate::error::V(p.position)
                )));
            }
            let mass_ok = p.mass.is_finite() && p.mass > 0.0;
            if !(pin.is_some() || mass_ok) {
                return Err(bad(format!(
                    "mass must be finite and > 0, got {:?}",
                    p.mass
                )));
            }
        }
        let mut springs: Vec<(Entity, Spring)> = world
            .query::<(Entity, &Spring)>()
            .iter()
            .map(|(e, s)| (e, *s))
            .collect();
        springs.sort_unstable_by_key(|(e, _)| e.id());
        for (e, s) in &springs {
            for end in [s.a, s.b] {
                if !world.satisfies::<&Particle>(end) {
                    return Err(SimError::DanglingSpring { spring: *e, end });
                }
            }
            let bad = |what: String| SimError::BadSpring { spring: *e, what };
            if s.a == s.b {
                return Err(bad("both ends are the same particle".into()));
            }
            check_spring(s.rest_length, s.stiffness, s.damping).map_err(bad)?;
        }
        let grids = locate_grids(world, &keys)?;

        *self = Packed::default();
        let n = keys.len();
        let entities: Vec<Entity> = keys.iter().map(|k| k.2).collect();
        drop(keys);
        let mut topology = Topology {
            options,
            ..Default::default()
        };
        let mut packed = Packed {
            x: Vec::with_capacity(n),
            v: Vec::with_capacity(n),
            inv_mass: Vec::with_capacity(n),
            ..Default::default()
        };
        for &e in &entities {
            let Some((p, pin)) = view.get(e) else {
                continue;
            };
            let pinned = pin.is_some();
            packed.x.push(p.position);
            packed.v.push(if pinned { DVec3::ZERO } else { p.velocity });
            packed
                .inv_mass
                .push(if pinned { 0.0 } else { 1.0 / p.mass });
        }
        drop(view);
        topology.entities = entities;
        let lookup = |spring: Entity, end: Entity| -> Result<u32, SimError> {
            topology
                .index_of(end)
                .map(|i| i as u32)
                .ok_or(SimError::DanglingSpring { spring, end })
        };

        let mut out = Vec::with_capacity(springs.len());
        for (e, s) in &springs {
            let (a, b) = (lookup(*e, s.a)?, lookup(*e, s.b)?);
            out.push(PackedSpring::new(
                a,
                b,
                s.rest_length,
                s.stiffness,
                s.damping,
                &packed.inv_mass,
            ));
        }
        drop(springs);
        if options.keep_grids {
            topology.grids = grids;
            let mut at = 0;
            for g in &topology.grids {
                if g.range().start > at {
                    topology.loose.push(at..g.range().start);
                }
                at = g.range().end;
            }
            if at < n {
                topology.loose.push(at..n);
            }
        } else {
            out.reserve(grids.iter().map(PackedGrid::spring_count).sum());
            for g in &grids {
                out.extend(g.springs(&packed.inv_mass));
            }
            topology.loose.push(0..n);
        }
        packed.springs = out;
        topology.index_springs(n, &packed.springs);
        packed.topology = Arc::new(topology);
        if !packed.springs.is_empty() {
            packed.build_incidence();
        }
        if options.colouring {
            packed.colouring = Colouring::build(packed.x.len(), &packed.springs);
        }
        *self = packed;
        Ok(())
    }

    /// Rebuilds the incidence after `springs` was filled by hand.
    pub(crate) fn rebuild_incidence(&mut self) {
        let n = self.x.len();
        let topology = Arc::make_mut(&mut self.topology);
        topology.loose.clear();
        topology.loose.push(0..n);
        topology.index_springs(n, &self.springs);
        self.build_incidence();
    }

    pub(super) fn build_incidence(&mut self) {
        let n = self.x.len();
        let mut count = vec![0u32; n + 1];
        for s in &self.springs {
            if s.wa != 0.0 {
                count[s.a as usize + 1] += 1;
            }
            if s.wb != 0.0 {
                count[s.b as usize + 1] += 1;
            }
        }
        for i in 0..n {
            count[i + 1] += count[i];
        }
        let total = count[n] as usize;
        let mut fill = count.clone();
        let mut spring = vec![0; total];
        let mut coef = vec![0.0; total];
        for (k, s) in self.springs.iter().enumerate() {
            for (end, c) in [(s.a, -s.wa), (s.b, s.wb)] {
                if c != 0.0 {
                    let slot = fill[end as usize] as usize;
                    spring[slot] = k as u32;
                    coef[slot] = c;
                    fill[end as usize] += 1;
                }
            }
        }
        self.incidence = Incidence {
            offsets: count,
            spring,
            coef,
        };
    }
}

/// The rest length, stiffness and damping a spring must have.
fn check_spring(rest: f64, stiffness: f64, damping: f64) -> Result<(), String> {
    if !(rest.is_finite() && rest > 0.0) {
        return Err(format!("rest length must be finite and > 0, got {rest:?}"));
    }
    if !(stiffness.is_finite() && stiffness >= 0.0) {
        return Err(format!(
            "stiffness must be finite and ≥ 0, got {stiffness:?}"
        ));
    }
    if !(damping.is_finite() && damping >= 0.0) {
        return Err(format!("damping must be finite and ≥ 0, got {damping:?}"));
    }
    Ok(())
}

/// Checks every [`ClothSprings`] and finds its particles among the sorted gather keys (scene
/// index, id, entity): the grid's scene indices must each belong to exactly one particle, and
/// no two grids may share a particle.
fn locate_grids(world: &World, keys: &[(u32, u32, Entity)]) -> Result<Vec<PackedGrid>, SimError> {
    let mut grids = Vec::new();
    let mut cloths: Vec<(Entity, ClothSprings)> = world
        .query::<(Entity, &ClothSprings)>()
        .iter()
        .map(|(e, c)| (e, c.clone()))
        .collect();
    cloths.sort_unstable_by_key(|(e, c)| (c.grid.first, e.id()));
    let mut end = 0u64;
    for (e, c) in cloths {
        let bad = |what: String| SimError::BadCloth { cloth: e, what };
        let g = c.grid;
        if g.cols == 0 || g.rows == 0 {
            return Err(bad(format!(
                "grid must be at least 1 × 1, got {} × {}",
                g.cols, g.rows
            )));
        }
        let range = g.range();
        if range.end > u32::MAX as u64 {
            return Err(bad(format!("scene indices {range:?} overflow u32")));
        }
        if range.start < end {
            return Err(bad(format!(
                "scene indices {range:?} overlap another cloth's springs"
            )));
        }
        end = range.end;
        for (k, l) in c.links.iter().enumerate() {
            if l.offset == (0, 0) || l.offset.0 == i32::MIN || l.offset.1 == i32::MIN {
                return Err(bad(format!(
                    "links[{k}]: offset must not be (0, 0) and within ±(2³¹ − 1), got {:?}",
                    l.offset
                )));
            }
            check_spring(l.rest_length, l.stiffness, l.damping)
                .map_err(|w| bad(format!("links[{k}]: {w}")))?;
        }
        let base = keys.partition_point(|k| (k.0 as u64) < range.start);
        let count = (range.end - range.start) as usize;
        let at = |k: usize| keys.get(base + k).map(|r| r.0 as u64);
        let next = at(count);
        let broken = (0..count as u64)
            .find(|&k| at(k as usize) != Some(range.start + k))
            .map(|k| range.start + k)
            .or((next == Some(range.end - 1)).then_some(range.end - 1));
        if let Some(index) = broken {
            return Err(SimError::BrokenCloth {
                cloth: e,
                index: index as u32,
            });
        }
        // Every link pointing forward in row-major order (the same springs): the grid pass
        // evaluates a spring at its earlier end.
        let links = c
            .links
            .iter()
            .map(|l| {
                let (dc, dr) = l.offset;
                let forward = dr > 0 || (dr == 0 && dc > 0);
                GridLink {
                    offset: if forward { (dc, dr) } else { (-dc, -dr) },
                    ..*l
                }
            })
            .collect();
        grids.push(PackedGrid {
            entity: e,
            base: base as u32,
            cols: g.cols,
            rows: g.rows,
            links,
        });
    }
    Ok(grids)
}
