//! Tearing: at a frame's end, every spring of a tearable cloth stretched past `(1 + stretch)`
//! times its rest length breaks. The springs go from the World and the cloth's surface opens
//! along the tear ([`split`]): a vertex whose triangles the tear has cut into pieces becomes
//! one particle per piece, its mass shared by the pieces' areas, so the render mesh and the
//! air split along the tear and keep their triangles. The game hears of each break
//! ([`crate::Simulation::torn`]), and the next frame gathers the new topology. The energy a
//! broken spring held leaves `E`, booked as [`crate::EnergyAudit::torn`]; a split keeps
//! positions, velocities and the total mass, so it changes no energy.
//!
//! The check runs once a frame on the host, in the springs' fixed order, so it is the same on
//! any number of threads and on both back ends (with springs on the GPU the frame's end state
//! is on the host anyway). A tearable cloth keeps its springs one by one (a grid cloth is
//! built as a mesh of its grid), since a break changes them.

use std::collections::{BTreeSet, HashMap, HashSet};

use hecs::{Entity, World};
use serde::{Deserialize, Serialize};

use crate::buffers::{Packed, PackedSpring};
use crate::components::{MeshSurface, Particle, Pin, SceneIndex, Spring};

mod split;

use split::{edge, Edge, Fan};

/// Where a tear has cut a cloth's surface without opening it yet (edges still shared by two
/// triangles), as the surface's vertices: a component on the cloth's entity, so a later break
/// beside them opens the surface along both.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Cuts(Vec<Edge>);

/// A cloth's tearing, as a scene gives it (`tearing: Some((stretch: 0.5))`); a component on
/// the cloth's entity. A spring past the stretch breaks at the frame's end and cuts the
/// surface along its edge; a particle whose triangles the cuts part into pieces becomes one
/// particle per piece (added after the cloth's, its mass shared by the pieces' areas), and a
/// triangle fewer than two springs hold any more is dropped.
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

    /// The frame's breaks into `world`: the springs despawned; each break as `(cloth entity,
    /// a, b)` in scene indices (packed indices are scene indices) into `out`; and each torn
    /// cloth's opening (in the cloths' order), for [`Opening::carry_out`].
    pub(crate) fn apply(
        &self,
        world: &mut World,
        packed: &Packed,
        out: &mut Vec<(Entity, u32, u32)>,
    ) -> Vec<Opening> {
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
        let mut broken: Vec<Vec<Edge>> = vec![Vec::new(); self.cloths.len()];
        for &(a, b) in &self.broken {
            let c = self.cloths.partition_point(|c| c.1 <= a);
            if let Some(c) = c.checked_sub(1) {
                let (e, first, _) = self.cloths[c];
                out.push((e, a, b));
                broken[c].push(edge(a - first, b - first));
            }
        }
        (self.cloths.iter().zip(broken))
            .filter(|(_, b)| !b.is_empty())
            .filter_map(|(&(e, first, count), b)| Opening::plan(world, packed, e, first, count, b))
            .collect()
    }
}

/// How a torn cloth's surface opens: its triangles after the frame's breaks, the vertices
/// split and how their springs and mass follow the pieces.
#[derive(Debug)]
pub(crate) struct Opening {
    cloth: Entity,
    pub(crate) first: u32,
    pub(crate) count: u32,
    triangles: Vec<[u32; 3]>,
    fans: Vec<Fan>,
    shares: Vec<Vec<f64>>,
    cuts: Vec<Edge>,
    /// Springs whose ends change: the spring and its new ends (surface vertices).
    rewired: Vec<(Entity, u32, u32)>,
}

impl Opening {
    /// The opening of the cloth `e` (particles `first .. first + count`, at `packed`'s state)
    /// for its `broken` edges (surface vertices); None without a surface.
    fn plan(
        world: &World,
        packed: &Packed,
        e: Entity,
        first: u32,
        count: u32,
        broken: Vec<Edge>,
    ) -> Option<Opening> {
        let mut triangles = world.get::<&MeshSurface>(e).ok()?.triangles.clone();
        let mine = &packed.topology.entities[first as usize..(first + count) as usize];
        let index: HashMap<Entity, u32> = (0u32..).zip(mine).map(|(i, &e)| (e, i)).collect();
        let springs: Vec<(Entity, u32, u32)> = world
            .query::<(Entity, &Spring)>()
            .iter()
            .filter_map(|(e, s)| Some((e, *index.get(&s.a)?, *index.get(&s.b)?)))
            .collect();
        let sprung: HashSet<Edge> = springs.iter().map(|s| edge(s.1, s.2)).collect();
        let mut cut: HashSet<Edge> = world
            .get::<&Cuts>(e)
            .map_or_else(|_| HashSet::new(), |c| c.0.iter().copied().collect());
        let broken: HashSet<Edge> = broken.into_iter().collect();
        cut.extend(&broken);
        let mut touched: BTreeSet<u32> = broken.iter().flat_map(|&(a, b)| [a, b]).collect();
        split::drop_loose(&mut triangles, &broken, &sprung, &mut touched);
        let fans = split::split(&mut triangles, &cut, &touched, count);
        let mut of: HashMap<u32, usize> = HashMap::new();
        let mut origin: HashMap<u32, u32> = HashMap::new();
        for (f, fan) in fans.iter().enumerate() {
            of.insert(fan.vertex(), f);
            origin.extend(fan.pieces.iter().map(|p| (p.0, fan.vertex())));
        }
        let x = |v: u32| packed.x[(first + origin.get(&v).copied().unwrap_or(v)) as usize];
        let fan_of = |v: u32| of.get(&v).copied();
        let rewired = (springs.iter())
            .filter(|s| of.contains_key(&s.1) || of.contains_key(&s.2))
            .map(|&(s, a, b)| {
                let (na, nb) = split::ends(&triangles, &fan_of, &fans, (a, b), &x);
                (s, na, nb)
            })
            .filter(|&(_, na, nb)| na >= count || nb >= count)
            .collect();
        let shares = (fans.iter())
            .map(|f| split::shares(&triangles, f, &x))
            .collect();
        let cuts = split::still_shared(&triangles, &cut);
        Some(Opening {
            cloth: e,
            first,
            count,
            triangles,
            fans,
            shares,
            cuts,
            rewired,
        })
    }

    /// The particles the opening adds (after the cloth's, in order).
    pub(crate) fn added(&self) -> u32 {
        self.fans.iter().map(|f| f.pieces.len() as u32 - 1).sum()
    }

    /// Into `world`, whose scene indices from `first + count` on have already made room for
    /// [`Self::added`] particles: each piece's particle spawned where its vertex stands (with
    /// its velocity, its share of the mass, its pin or attachment unless `held` by the game),
    /// the springs moved to their pieces, and the surface, tethers, collision layer and cuts
    /// of the cloth made whole again.
    pub(crate) fn carry_out(self, world: &mut World, entities: &[Entity], held: &[Entity]) {
        let mine = &entities[self.first as usize..(self.first + self.count) as usize];
        let mut new: Vec<Entity> = Vec::with_capacity(self.added() as usize);
        for (fan, shares) in self.fans.iter().zip(&self.shares) {
            let v = mine[fan.vertex() as usize];
            let Ok(p) = world.get::<&Particle>(v).map(|p| *p) else {
                continue;
            };
            // A pin the game or the quarantine put on it (not the scene's) stays its own.
            let quarantined = world
                .get::<&crate::components::Quarantined>(v)
                .is_ok_and(|q| !q.was_pinned);
            let pinned = world.get::<&Pin>(v).is_ok() && !held.contains(&v) && !quarantined;
            let attached = world
                .get::<&crate::contacts::Attachment>(v)
                .map(|a| *a)
                .ok();
            let mut given = 0.0;
            for (piece, share) in fan.pieces.iter().zip(shares).skip(1) {
                let mass = p.mass * share;
                given += mass;
                let copy = world.spawn((Particle { mass, ..p }, SceneIndex(self.first + piece.0)));
                if pinned {
                    let _ = world.insert_one(copy, Pin);
                }
                if let Some(a) = attached {
                    let _ = world.insert_one(copy, a);
                }
                new.push(copy);
            }
            if let Ok(mut p) = world.get::<&mut Particle>(v) {
                p.mass -= given;
            }
        }
        let at = |v: u32| {
            if v < self.count {
                mine[v as usize]
            } else {
                new[(v - self.count) as usize]
            }
        };
        for &(s, a, b) in &self.rewired {
            if let Ok(mut s) = world.get::<&mut Spring>(s) {
                (s.a, s.b) = (at(a), at(b));
            }
        }
        let copies = || {
            (self.fans.iter()).flat_map(|f| f.pieces[1..].iter().map(move |p| (f.vertex(), p.0)))
        };
        if let Ok(mut t) = world.get::<&mut crate::Tethers>(self.cloth) {
            let mut more = Vec::new();
            for (v, c) in copies() {
                more.extend(t.links.iter().filter(|l| l.0 == v).map(|l| (c, l.1, l.2)));
            }
            t.links.extend(more);
        }
        if let Ok(mut l) = world.get::<&mut crate::collide::Layer>(self.cloth) {
            for (v, _) in copies() {
                let x = l.rest[v as usize];
                l.rest.push(x);
            }
        }
        if let Ok(mut s) = world.get::<&mut MeshSurface>(self.cloth) {
            s.triangles = self.triangles;
            s.count += new.len() as u32;
        }
        let _ = world.insert_one(self.cloth, Cuts(self.cuts));
    }
}
