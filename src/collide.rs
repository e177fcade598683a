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
//! Candidates come once a frame from a uniform grid of cells a reach wide: the largest
//! thickness plus twice the furthest any particle can move in the frame at its start velocity
//! under gravity. Cells are sorted by key (`std`'s sort, no hashing order), so the candidates
//! and the Gauss–Seidel passes over them each substep run in one fixed order: the same on any
//! number of threads. What the pushes and friction do to `E` is booked on
//! [`crate::EnergyAudit::contacts`].

use std::collections::HashMap;

use glam::DVec3;
use hecs::{Entity, World};
use serde::{Deserialize, Serialize};

use crate::buffers::Packed;
use crate::components::{Particle, SceneIndex};

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

/// The colliding particles in packed indices, this frame's candidate pairs, and what their
/// pushes did this frame.
#[derive(Debug, Default)]
pub(crate) struct CollideStage {
    /// Each colliding particle's packed index (ascending), layer and rest position.
    members: Vec<(u32, u16, DVec3)>,
    layers: Vec<SelfCollision>,
    /// The frame's candidates `(a, b, thickness, kinetic, static)`, packed indices, `a < b`.
    pairs: Vec<(u32, u32, f64, f64, f64)>,
    /// Cell keys of the members, sorted, and each cell's run of them.
    cells: Vec<((i64, i64, i64), u32)>,
    runs: HashMap<(i64, i64, i64), (u32, u32)>,
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
        self.moves.reset(n);
        self.before_v.resize(n, DVec3::ZERO);
        self.pairs.clear();
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.members.is_empty()
    }

    /// The candidate pairs for a frame of `dt` from the state at its start: every pair of
    /// members within their thickness plus twice the furthest a particle moves in the frame,
    /// less neighbours along one cloth; in order.
    pub(crate) fn begin_frame(&mut self, packed: &Packed, dt: f64, gravity: DVec3) {
        self.energy = 0.0;
        self.pairs.clear();
        let (x, v) = (&packed.x, &packed.v);
        let travel = (self.members.iter())
            .map(|m| v[m.0 as usize].length() * dt + 0.5 * gravity.length() * dt * dt)
            .filter(|d| d.is_finite())
            .fold(0.0, f64::max);
        let thickest = self.layers.iter().map(|l| l.thickness).fold(0.0, f64::max);
        let cell = thickest + 2.0 * travel;
        let key = |p: DVec3| {
            let c = (p / cell).floor();
            (c.x as i64, c.y as i64, c.z as i64)
        };
        self.cells.clear();
        self.cells.extend(
            (0u32..)
                .zip(&self.members)
                .filter(|(_, m)| x[m.0 as usize].is_finite())
                .map(|(s, m)| (key(x[m.0 as usize]), s)),
        );
        self.cells.sort_unstable();
        self.runs.clear();
        let mut lo = 0;
        for hi in 1..=self.cells.len() {
            if hi == self.cells.len() || self.cells[hi].0 != self.cells[lo].0 {
                self.runs.insert(self.cells[lo].0, (lo as u32, hi as u32));
                lo = hi;
            }
        }
        let inv = &packed.inv_mass;
        for &(c, s) in &self.cells {
            let (a, la, ra) = self.members[s as usize];
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let Some(&(lo, hi)) = self.runs.get(&(c.0 + dx, c.1 + dy, c.2 + dz)) else {
                            continue;
                        };
                        for &(_, u) in &self.cells[lo as usize..hi as usize] {
                            let (b, lb, rb) = self.members[u as usize];
                            if b <= a || inv[a as usize] + inv[b as usize] == 0.0 {
                                continue;
                            }
                            let (pa, pb) = (self.layers[la as usize], self.layers[lb as usize]);
                            let t = 0.5 * (pa.thickness + pb.thickness);
                            if la == lb && (rb - ra).length() < 2.0 * pa.thickness {
                                continue;
                            }
                            let reach = t + 2.0 * travel;
                            if (x[b as usize] - x[a as usize]).length_squared() >= reach * reach {
                                continue;
                            }
                            let mu = 0.5 * (pa.kinetic_friction + pb.kinetic_friction);
                            let mu_s = 0.5 * (pa.friction + pb.friction);
                            self.pairs.push((a, b, t, mu, mu_s));
                        }
                    }
                }
            }
        }
        self.pairs.sort_unstable_by_key(|p| (p.0, p.1));
    }

    /// Candidate pairs this frame.
    pub(crate) fn pair_count(&self) -> usize {
        self.pairs.len()
    }

    /// After a substep's springs: one pass over the candidates in order; the change of the
    /// particles' own energy booked. Returns whether any moved: the springs' change, from
    /// [`Self::moves`], is then the caller's to add.
    pub(crate) fn project(&mut self, packed: &mut Packed, gravity: DVec3) -> bool {
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
            let at = |i: usize, x: DVec3, v: DVec3| {
                crate::audit::particle_energy_at(inv[i], x, v, gravity)
            };
            let (moved, before) = (&self.moves.moved, &self.moves.before);
            for i in (0..moved.len()).filter(|&i| moved[i]) {
                let change = at(i, x[i], v[i]) - at(i, before[i], self.before_v[i]);
                if change.is_finite() {
                    self.energy += change;
                }
            }
        }
        any
    }

    /// What the last pass moved.
    pub(crate) fn moves(&self) -> &crate::audit::Moves {
        &self.moves
    }
}
