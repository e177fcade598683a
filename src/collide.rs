//! Self-collision and cloth–cloth collision, the particle layer: two particles of cloths that
//! collide (`self_collision:`) closer than their thickness are pushed apart along the line
//! between them to that thickness, in proportion to their inverse masses (the pair's momentum
//! kept), their approach along it removed, and their sliding across it slowed by Coulomb
//! friction (stopped where the normal impulse times the static coefficient can stop it, else
//! slowed by it times the kinetic one), as the colliders' contacts do.
//!
//! Pairs of one cloth closer at rest than twice its thickness never collide: they are
//! neighbours along the cloth, which its springs hold apart. Two cloths' pairs collide at the
//! mean of their thicknesses (each layer's surfaces half a thickness either side of its
//! particles) and slide at the mean of their coefficients (rapier's default rule).
//!
//! The candidates are the pairs within their thickness plus a margin (the thinnest layer's
//! thickness), a Verlet list: found at a frame's start and again whenever a member has moved
//! more than half the margin since, less the members' mean move (a pair's distance changes by
//! at most the two moves less any common one, so no pair outside the list can have closed to
//! its thickness). They are found from members sorted by cell, so they and the Gauss–Seidel
//! pass over them each substep run in one fixed order: the same on any number of threads. What the pushes and friction do to `E` is booked on
//! [`crate::EnergyAudit::contacts`].

use glam::DVec3;
use hecs::{Entity, World};
use serde::{Deserialize, Serialize};

use crate::buffers::Packed;
use crate::components::{Particle, SceneIndex};

/// The furthest cell from the origin a key tells apart, on each axis.
const SPAN: f64 = ((1 << 20) - 2) as f64;

/// A cloth's self-collision, as a scene gives it (`self_collision: Some((thickness: 0.005,
/// friction: 0.5))`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SelfCollision {
    /// How close two of its particles may come (m): under its particle spacing.
    pub thickness: f64,
    /// Static Coulomb friction between its layers (and with other cloths'): a sliding the
    /// normal impulse times this can stop, stops.
    #[serde(default = "default_friction")]
    pub friction: f64,
    /// Kinetic friction, at most `friction`: what slows a sliding it cannot stop.
    #[serde(default = "default_kinetic")]
    pub kinetic_friction: f64,
}

// The colliders' contact defaults (`ContactParams`).
fn default_friction() -> f64 {
    0.5
}

fn default_kinetic() -> f64 {
    0.4
}

impl SelfCollision {
    /// What a self-collision must be: a thickness finite and > 0, coefficients finite and ≥ 0.
    pub fn check(&self) -> Result<(), String> {
        if !(self.thickness.is_finite() && self.thickness > 0.0) {
            return Err(format!(
                "thickness must be finite and > 0 m, got {:?}",
                self.thickness
            ));
        }
        for (name, mu) in [
            ("friction", self.friction),
            ("kinetic_friction", self.kinetic_friction),
        ] {
            if !(mu.is_finite() && mu >= 0.0) {
                return Err(format!("{name} must be finite and ≥ 0, got {mu:?}"));
            }
        }
        if self.kinetic_friction > self.friction {
            return Err(format!(
                "kinetic_friction {} must be at most friction {}",
                self.kinetic_friction, self.friction
            ));
        }
        Ok(())
    }

    /// The thickness against the cloth's particle `spacing` (its shortest spring at rest, m):
    /// it must be under it, or neighbours along the cloth would push each other apart.
    pub fn check_spacing(&self, spacing: f64) -> Result<(), String> {
        if self.thickness >= spacing {
            return Err(format!(
                "thickness {} m must be under the cloth's particle spacing, {spacing} m (its \
                 shortest spring at rest)",
                self.thickness
            ));
        }
        Ok(())
    }
}

/// A colliding cloth's layer (a component on its cloth entity): its self-collision and its
/// particles' rest positions (scene indices `first ..`), which say which pairs are neighbours.
#[derive(Clone, Debug, PartialEq)]
pub struct Layer {
    /// What the scene asked for.
    pub spec: SelfCollision,
    /// The cloth's first particle (scene index).
    pub first: u32,
    /// Its particles' rest positions, from `first` on.
    pub rest: Vec<DVec3>,
}

/// The layer of the cloth whose particles are scene indices `first .. first + count` in
/// `world`, at their places now (the rest shape).
pub fn layer(world: &World, first: u32, count: u32, spec: SelfCollision) -> Layer {
    let mut parts: Vec<(u32, DVec3)> = world
        .query::<(Entity, &SceneIndex, &Particle)>()
        .iter()
        .filter(|(_, i, _)| (first..first + count).contains(&i.0))
        .map(|(_, i, p)| (i.0 - first, p.position))
        .collect();
    parts.sort_unstable_by_key(|p| p.0);
    Layer {
        spec,
        first,
        rest: parts.into_iter().map(|p| p.1).collect(),
    }
}

/// The colliding particles in packed indices, the candidate pairs, and what their pushes did
/// this frame.
#[derive(Debug, Default)]
pub(crate) struct CollideStage {
    /// Each colliding particle's packed index (ascending), layer and rest position.
    members: Vec<(u32, u16, DVec3)>,
    layers: Vec<SelfCollision>,
    /// The candidates `(a, b, thickness, kinetic, static)`, packed indices, `a < b`.
    pairs: Vec<(u32, u32, f64, f64, f64)>,
    /// Cell keys of the members, sorted.
    cells: Vec<(u64, u32)>,
    /// The members' positions when the candidates were found, and the margin past the
    /// thickness they were found within (m): the thinnest layer's thickness.
    built: Vec<DVec3>,
    margin: f64,
    /// Times the candidates were found (for the stage's report).
    rebuilds: u64,
    moves: crate::audit::Moves,
    before_v: Vec<DVec3>,
    /// The change of `E` the pushes and friction made this frame (J).
    pub(crate) energy: f64,
}

impl CollideStage {
    /// Every colliding cloth's particles from `world`, in packed indices.
    pub(crate) fn gather(&mut self, world: &World, packed: &Packed) {
        self.members.clear();
        self.layers.clear();
        let mut layers: Vec<(u32, SelfCollision, Vec<DVec3>)> = world
            .query::<&Layer>()
            .iter()
            .map(|l| (l.first, l.spec, l.rest.clone()))
            .collect();
        layers.sort_unstable_by_key(|l| l.0);
        let n = packed.particle_count() as u32;
        for (k, (first, spec, rest)) in layers.into_iter().enumerate() {
            self.layers.push(spec);
            let at = (0u32..).zip(rest).filter(|(i, _)| first + i < n);
            self.members
                .extend(at.map(|(i, x)| (first + i, k as u16, x)));
        }
        self.members.sort_by_key(|m| m.0);
        self.members.dedup_by_key(|m| m.0);
        let n = if self.members.is_empty() {
            0
        } else {
            n as usize
        };
        self.margin = (self.layers.iter())
            .map(|l| l.thickness)
            .fold(f64::MAX, f64::min);
        self.moves.reset(n);
        self.before_v.resize(n, DVec3::ZERO);
        self.pairs.clear();
        self.rebuilds = 0;
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.members.is_empty()
    }

    /// A frame's start: its books opened, and the candidates found again from its state (the
    /// game may have moved particles since the last frame).
    pub(crate) fn begin_frame(&mut self, packed: &Packed) {
        self.energy = 0.0;
        self.rebuild(packed);
    }

    /// The candidates found again if some pair may have closed past the margin since they
    /// were: a member's move since then, less the members' mean move, over half the margin.
    fn refresh(&mut self, packed: &Packed) {
        let x = &packed.x;
        // A particle gone non-finite is the quarantine's: the others' moves decide.
        let moves = || {
            (self.members.iter().zip(&self.built))
                .map(|(m, b)| x[m.0 as usize] - *b)
                .filter(|d| d.is_finite())
        };
        let mean = moves().sum::<DVec3>() / moves().count().max(1) as f64;
        let far = moves()
            .map(|d| (d - mean).length_squared())
            .fold(0.0, f64::max);
        let half = 0.5 * self.margin;
        if far > half * half {
            self.rebuild(packed);
        }
    }

    /// Every pair of members within their thickness plus the margin, less neighbours along one
    /// cloth, in order: members sorted by cell (cells the largest thickness plus the margin
    /// wide), each cell's neighbours found by binary search, three cells of a column at once.
    fn rebuild(&mut self, packed: &Packed) {
        self.rebuilds += 1;
        self.pairs.clear();
        let (x, inv) = (&packed.x, &packed.inv_mass);
        self.built.clear();
        self.built
            .extend(self.members.iter().map(|m| x[m.0 as usize]));
        let thickest = self.layers.iter().map(|l| l.thickness).fold(0.0, f64::max);
        let cell = thickest + self.margin;
        let key = |p: DVec3| {
            let c = (p / cell).floor();
            // Each coordinate in its 21 bits (far cells share the edge ones: the distance
            // decides), so the keys sort as the cells do, a column's cells in a row.
            let f = |v: f64| (v.clamp(-SPAN, SPAN) as i64 + (1 << 20)) as u64;
            (f(c.x) << 42) | (f(c.y) << 21) | f(c.z)
        };
        self.cells.clear();
        self.cells.extend(
            (0u32..)
                .zip(&self.members)
                .filter(|(_, m)| x[m.0 as usize].is_finite())
                .map(|(s, m)| (key(x[m.0 as usize]), s)),
        );
        self.cells.sort_unstable();
        let cells = &self.cells;
        // The nine columns beside a cell, as key offsets; each column's run of three cells
        // found by cursors that only move on, as the cells come in key order.
        let columns: Vec<i64> = (-1i64..=1)
            .flat_map(|dx| (-1i64..=1).map(move |dy| (dx << 42) + (dy << 21)))
            .collect();
        let (mut starts, mut ends) = ([0usize; 9], [0usize; 9]);
        let mut lo = 0;
        while lo < cells.len() {
            let c = cells[lo].0;
            let hi = lo + cells[lo..].partition_point(|e| e.0 == c);
            for (j, &column) in columns.iter().enumerate() {
                let (from, to) = (
                    (c as i64 + column - 1) as u64,
                    (c as i64 + column + 1) as u64,
                );
                while starts[j] < cells.len() && cells[starts[j]].0 < from {
                    starts[j] += 1;
                }
                ends[j] = ends[j].max(starts[j]);
                while ends[j] < cells.len() && cells[ends[j]].0 <= to {
                    ends[j] += 1;
                }
                let (first, last) = (starts[j], ends[j]);
                for &(_, s) in &cells[lo..hi] {
                    let (a, la, ra) = self.members[s as usize];
                    for &(_, u) in &cells[first..last] {
                        let (b, lb, rb) = self.members[u as usize];
                        if b <= a {
                            continue;
                        }
                        let (pa, pb) = (self.layers[la as usize], self.layers[lb as usize]);
                        let t = 0.5 * (pa.thickness + pb.thickness);
                        let reach = t + self.margin;
                        if (x[b as usize] - x[a as usize]).length_squared() >= reach * reach
                            || inv[a as usize] + inv[b as usize] == 0.0
                        {
                            continue;
                        }
                        let near = 2.0 * pa.thickness;
                        if la == lb && (rb - ra).length_squared() < near * near {
                            continue;
                        }
                        let mu = 0.5 * (pa.kinetic_friction + pb.kinetic_friction);
                        let mu_s = 0.5 * (pa.friction + pb.friction);
                        self.pairs.push((a, b, t, mu, mu_s));
                    }
                }
            }
            lo = hi;
        }
        self.pairs.sort_unstable_by_key(|p| (p.0, p.1));
    }

    /// The candidate pairs, and the times they were found since the stage was gathered.
    pub(crate) fn pair_count(&self) -> (usize, u64) {
        (self.pairs.len(), self.rebuilds)
    }

    /// After a substep's springs: one pass over the candidates in order; the change of the
    /// particles' own energy booked. Returns whether any moved: the springs' change, from
    /// [`Self::moves`], is then the caller's to add.
    pub(crate) fn project(&mut self, packed: &mut Packed, gravity: DVec3) -> bool {
        self.refresh(packed);
        let n = self.moves.moved.len();
        self.moves.reset(n);
        let mut any = false;
        let (x, v, inv) = (&mut packed.x, &mut packed.v, &packed.inv_mass);
        for &(a, b, t, mu, mu_s) in &self.pairs {
            let (a, b) = (a as usize, b as usize);
            let d = x[b] - x[a];
            let dist2 = d.length_squared();
            if dist2 >= t * t || !dist2.is_finite() {
                continue;
            }
            let dist = dist2.sqrt();
            // Two particles on one point: apart upwards.
            let n = if dist > 1e-9 * t { d / dist } else { DVec3::Y };
            for i in [a, b] {
                if !self.moves.moved[i] {
                    self.before_v[i] = v[i];
                }
                crate::audit::Moves::mark(
                    &mut self.moves.moved[i],
                    &mut self.moves.before[i],
                    x[i],
                );
            }
            any = true;
            let (wa, wb) = (inv[a], inv[b]);
            let w = wa + wb;
            let over = t - dist;
            x[a] -= n * (over * wa / w);
            x[b] += n * (over * wb / w);
            let vr = v[b] - v[a];
            let vn = vr.dot(n);
            if vn < 0.0 {
                v[a] += n * (vn * wa / w);
                v[b] -= n * (vn * wb / w);
                let vt = vr - n * vn;
                let slide = vt.length();
                let stop = if slide <= mu_s * -vn {
                    1.0
                } else {
                    (mu * -vn / slide).min(1.0)
                };
                if slide > 0.0 {
                    v[a] += vt * (stop * wa / w);
                    v[b] -= vt * (stop * wb / w);
                }
            }
        }
        if any {
            (self.moves).book_particles(&self.before_v, packed, gravity, &mut self.energy);
        }
        any
    }

    /// What the last pass moved.
    pub(crate) fn moves(&self) -> &crate::audit::Moves {
        &self.moves
    }
}
