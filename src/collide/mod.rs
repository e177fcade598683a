//! Self-collision and cloth–cloth collision: a particle of a cloth that collides
//! (`self_collision:`) closer than the thickness to a triangle of one (its own or another's)
//! is pushed out from the triangle's closest point to that thickness, the particle and the
//! triangle's corners moved by inverse mass (weighted by the point's barycentric weights, so
//! the momentum is kept), their approach along the normal removed, and their sliding across it
//! slowed by Coulomb friction (stopped where the normal impulse times the static coefficient
//! can stop it, else slowed by it times the kinetic one), as the colliders' contacts do. The
//! test is swept: a particle that crossed a triangle's plane inside it over the substep goes
//! back to the side it started on, however far it moved. Cloths that ask for `edges` also keep
//! their triangles' edges apart, swept too ([`edges`]). Cloths without triangles (a single
//! row) meet each other particle against particle.
//!
//! Pairs of one cloth closer at rest than twice its thickness never collide: they are
//! neighbours along the cloth, which its springs hold apart. Two cloths collide at the mean of
//! their thicknesses (each layer's surfaces half a thickness either side of its particles) and
//! slide at the mean of their coefficients (rapier's default rule).
//!
//! The candidates are those within their thickness plus a margin (the thinnest layer's
//! thickness), a Verlet list: found at the first frame and again, at a frame's start or within
//! it, whenever some pair left out may have closed past the margin since ([`skin`]: members
//! near each other moved apart by more than the margin, or any two by more than twice it).
//! They are found from members and triangles sorted by cell ([`search`]) and kept in one fixed
//! order (by kind, then their two indices), so the Gauss–Seidel pass over them each substep
//! gives the same bits on any number of threads and whenever they were found; a contact the
//! pass found apart waits until its ends' paths could close the gap ([`pass`]). With the
//! GPU the device searches, and the host keeps the CPU's candidates in the CPU's order
//! (`device.rs`), so both back ends pass the same ones; where [`crate::SimConfig`] asks
//! (`device_collide_pass`), every candidate is a particle against a triangle and no host
//! contact stage runs, the device runs the pass too, in colours (`colours.rs`,
//! `device_pass.rs`). What the pushes and friction do to `E` is booked on
//! [`crate::EnergyAudit::contacts`] (on the device, left in the residual, as the device's
//! contacts leave theirs).

use glam::DVec3;
use hecs::{Entity, World};
use serde::{Deserialize, Serialize};

use crate::buffers::Packed;
use crate::components::{Particle, SceneIndex};
use crate::error::GpuError;

mod colours;
mod contact;
#[cfg(feature = "gpu")]
mod device;
#[cfg(feature = "gpu")]
mod device_pass;
mod edges;
mod near;
mod neighbours;
mod pass;
mod search;
mod skin;

/// The inverse mass a particle a collider touched in the last substep pushes with, a share of
/// its own: ten times heavier, the lower layer of a stack is pushed into the collider by a
/// tenth of what it was (a whole hold would throw the corners of a triangle held on one side).
const GROUNDED: f64 = 0.1;

/// How far, in thicknesses, a particle the game moved between frames is swept from its old
/// place (further, it is taken as placed).
const EDIT_REACH: f64 = 10.0;

/// Passes over the pushed contacts' velocities each substep (the first with the pushes).
pub(crate) const VELOCITY_PASSES: usize = 4;

/// Seeded numbers uniform in [−1, 1) for the module's tests (a linear congruential
/// generator's top 53 bits).
#[cfg(test)]
fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
}

/// A cloth's self-collision, as a scene gives it (`self_collision: Some((thickness: 0.005,
/// friction: 0.5))`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SelfCollision {
    /// How close a particle may come to a colliding triangle (m): under its particle spacing.
    pub thickness: f64,
    /// Static Coulomb friction between its layers (and with other cloths'): a sliding the
    /// normal impulse times this can stop, stops.
    #[serde(default = "default_friction")]
    pub friction: f64,
    /// Kinetic friction, at most `friction`: what slows a sliding it cannot stop.
    #[serde(default = "default_kinetic")]
    pub kinetic_friction: f64,
    /// Whether its triangles' edges are kept a thickness from those of every cloth that asks
    /// the same (and swept), besides its particles from the triangles: two triangles can
    /// otherwise cross edge through edge where no corner comes near the other's face. A cloth
    /// the game pushes through itself untangles only with it: the triangles stretched where
    /// the moved part meets the rest cross the other part edge through edge. It costs: over
    /// the shipped colliding scenes the stage takes four to eight times as long.
    #[serde(default)]
    pub edges: bool,
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

/// A cloth's triangles, scene indices.
type Triangles = Vec<[u32; 3]>;

/// A colliding cloth's triangle: its corners' packed indices and member slots, and its layer.
#[derive(Clone, Copy, Debug)]
struct Triangle {
    at: [u32; 3],
    slots: [u32; 3],
    layer: u16,
}

/// A candidate of a particle against a triangle: its packed index, the triangle's index, and
/// the pair's thickness and friction.
#[derive(Clone, Copy, Debug)]
struct Face {
    p: u32,
    triangle: u32,
    thickness: f64,
    friction: contact::Friction,
}

/// The colliding particles and triangles in packed indices, the candidates, and what their
/// pushes did this frame.
#[derive(Debug, Default)]
pub(crate) struct CollideStage {
    /// Each colliding particle's packed index (ascending), layer and rest position.
    members: Vec<(u32, u16, DVec3)>,
    layers: Vec<SelfCollision>,
    /// Whether each layer has triangles: its particles then meet every layer through them.
    surfaced: Vec<bool>,
    triangles: Vec<Triangle>,
    /// Particle against particle, where neither has triangles: `(a, b, thickness,
    /// friction)`, packed indices, `a < b`.
    pairs: Vec<(u32, u32, f64, contact::Friction)>,
    /// Particle against triangle, in the particles' cells' order, each particle's triangles
    /// in their cells' order.
    faces: Vec<Face>,
    /// Cell keys of the members (then of the triangles' centres), sorted.
    cells: Vec<(u64, u32)>,
    triangle_cells: Vec<(u64, u32)>,
    /// Each triangle's centre and the radius about it that holds its corners; and (`near`) both
    /// in `triangle_cells`' order, for the search's first test.
    centres: Vec<(DVec3, f64)>,
    near: near::Near,
    /// Each member's triangles that never collide with it (neighbours along its cloth), by
    /// slot.
    excluded: neighbours::Neighbours,
    /// The triangles' edges, each once; each edge's edges that never collide with it,
    /// as `excluded`; edge against edge, in the edges' cells' order.
    edges: Vec<edges::Edge>,
    edge_excluded: neighbours::Neighbours,
    crossings: Vec<edges::Crossing>,
    /// Whether the pass takes them in colours (the device's order), and the colours.
    coloured: bool,
    colours: colours::Colours,
    /// As `triangle_cells`, `centres` and `near`, of the edges' midpoints.
    edge_cells: Vec<(u64, u32)>,
    edge_centres: Vec<(DVec3, f64)>,
    edge_near: near::Near,
    found_crossings: Vec<Vec<edges::Crossing>>,
    /// The particles' cells cut for the search's threads, and each part's candidates.
    runs: Vec<std::ops::Range<usize>>,
    found: Vec<Vec<Face>>,
    /// The members' positions when the candidates were found, and at the substep's start
    /// (packed indices; members only).
    built: Vec<DVec3>,
    start: Vec<DVec3>,
    /// The thinnest layer's thickness: how far past its thickness a pair's candidate reaches
    /// (on the drape with 10 mm, three quarters of it found them 1,109 times against 865, in
    /// as long; one and a half times it, 616 times, but the flat sheet's neighbours just past
    /// those at rest became candidates, 89 thousand, and the stage took twice as long).
    margin: f64,
    /// The reach the candidates were found with past the thickness: the margin, plus twice
    /// the largest of `swept`.
    reach: f64,
    /// The members' blocks at the find, for the test of whether the candidates still hold.
    skin: skin::Skin,
    /// Each member's move over the substep the candidates were found in, less the mean: a
    /// pair that crossed within it is as far apart as the two moves at most.
    swept: Vec<f64>,
    /// Times the candidates were found (for the stage's report).
    rebuilds: u64,
    moves: crate::audit::Moves,
    before_v: Vec<DVec3>,
    active: Vec<contact::Active>,
    /// Each particle's path (from 0 where the candidates are found at a frame's start), and
    /// each candidate's ends and the reading of their paths, summed, before which it is found
    /// apart ([`contact::Tested`], [`pass`]).
    odometer: Vec<f64>,
    due: Vec<(colours::Ends, f64)>,
    /// The dues by candidate across a find (scratch).
    kept: Vec<(pass::Key, f64)>,
    /// Tests that waited so (for the tests of the stage).
    waited: u64,
    /// The inverse masses the pushes move by: a particle a collider held in the last
    /// substep counts as held (see [`Self::ground`]).
    inv: Vec<f64>,
    grounded: Vec<bool>,
    /// Whether the next frame's start follows a gather of the same members (see
    /// [`Self::begin_frame`]).
    resume: bool,
    /// The change of `E` the pushes and friction made this frame (J).
    pub(crate) energy: f64,
    /// The searches on the device (against triangles, and of edges), where the springs run
    /// there; none after a gather until `enable_device`.
    #[cfg(feature = "gpu")]
    device: device::OnDevice,
}

impl CollideStage {
    /// Every colliding cloth's particles and triangles from `world`, in packed indices.
    pub(crate) fn gather(&mut self, world: &World, packed: &Packed) {
        let before: Vec<u32> = self.members.iter().map(|m| m.0).collect();
        let stepped = self.rebuilds > 0;
        self.members.clear();
        self.layers.clear();
        self.surfaced.clear();
        self.triangles.clear();
        let mut layers: Vec<(u32, SelfCollision, Vec<DVec3>, Triangles)> = world
            .query::<(Entity, &Layer)>()
            .iter()
            .map(|(e, l)| {
                let mut tris = Vec::new();
                crate::components::cloth_triangles(world, e, &mut tris);
                (l.first, l.spec, l.rest.clone(), tris)
            })
            .collect();
        layers.sort_unstable_by_key(|l| l.0);
        let n = packed.particle_count() as u32;
        let mut tris = Vec::new();
        for (k, (first, spec, rest, t)) in layers.into_iter().enumerate() {
            self.layers.push(spec);
            self.surfaced.push(!t.is_empty());
            let at = (0u32..).zip(rest).filter(|(i, _)| first + i < n);
            self.members
                .extend(at.map(|(i, x)| (first + i, k as u16, x)));
            tris.extend(t.into_iter().map(|t| (t, k as u16)));
        }
        self.members.sort_by_key(|m| m.0);
        self.members.dedup_by_key(|m| m.0);
        let slot = |i: u32| {
            let s = self.members.partition_point(|m| m.0 < i);
            (self.members.get(s)?.0 == i).then_some(s as u32)
        };
        for (at, layer) in tris {
            if let [Some(a), Some(b), Some(c)] = at.map(slot) {
                let slots = [a, b, c];
                (self.triangles).push(Triangle { at, slots, layer });
            }
        }
        self.find_excluded();
        self.gather_edges();
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
        self.start.resize(n, DVec3::ZERO);
        self.pairs.clear();
        self.faces.clear();
        self.crossings.clear();
        // None found yet: the next frame's start finds them.
        self.built.clear();
        self.colours = Default::default();
        self.rebuilds = 0;
        #[cfg(feature = "gpu")]
        {
            (self.device.find, self.device.edges, self.device.pass) = (None, None, None);
        }
        self.coloured = false;
        // The same particles collide as before the game's edit: the next frame's first test
        // sweeps from where this stage left them.
        self.resume = stepped && before.iter().copied().eq(self.members.iter().map(|m| m.0));
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.members.is_empty()
    }

    /// Whether the candidates are found on the device.
    pub(crate) fn finds_on_device(&self) -> bool {
        #[cfg(feature = "gpu")]
        return self.device.find.is_some();
        #[cfg(not(feature = "gpu"))]
        false
    }

    /// Whether the pass over the candidates runs on the device.
    pub(crate) fn passes_on_device(&self) -> bool {
        #[cfg(feature = "gpu")]
        return self.device.pass.is_some();
        #[cfg(not(feature = "gpu"))]
        false
    }

    /// A frame's start: its books opened, and the candidates found again from its state (the
    /// first substep's start) unless they still hold: no gather since they were found (the
    /// game's edits), no member gone non-finite, and no pair left out come within its
    /// thickness ([`skin::Skin::holds`]). The candidates in their fixed order, a pass over
    /// candidates that hold gives the same pushes whenever they were found.
    pub(crate) fn begin_frame(&mut self, packed: &Packed) -> Result<(), GpuError> {
        self.energy = 0.0;
        #[cfg(feature = "gpu")]
        self.start_from_device()?;
        self.swept.clear();
        self.swept.resize(self.members.len(), 0.0);
        let resumed = std::mem::take(&mut self.resume);
        if resumed {
            self.sweep_edits(packed);
        } else {
            // The colliders' pushes since the last pass, before the substep starts here.
            self.advance_odometer(&packed.x);
            self.keep_start(packed);
        }
        let x = &packed.x;
        let since = || (self.members.iter().zip(&self.built)).map(|(m, b)| x[m.0 as usize] - *b);
        // A member non-finite then and now is the quarantine's either way.
        let same = |(m, b): (&(u32, u16, DVec3), &DVec3)| {
            let x = x[m.0 as usize];
            (x - *b).is_finite() || !(x.is_finite() || b.is_finite())
        };
        let found = self.built.len() == self.members.len()
            && self.members.iter().zip(&self.built).all(same);
        if resumed || !found || !self.skin.holds(since(), self.margin) {
            // The odometers from 0 (a particle the game placed has its jump on none).
            self.odometer.clear();
            self.rebuild(packed)?;
        }
        #[cfg(feature = "gpu")]
        self.start_to_device();
        Ok(())
    }

    /// After the game moved particles between frames (through the World): the first substep
    /// tests each particle's path from where the stage left it, so one the game pushed through
    /// a triangle goes back to its side (a cloth pushed through itself untangles). A particle
    /// moved further than [`EDIT_REACH`] thicknesses past the others' mean move is taken as
    /// placed there, not swept: its path from its old place is not tested.
    fn sweep_edits(&mut self, packed: &Packed) {
        let x = &packed.x;
        let mean = self.mean_move(x);
        let reach = EDIT_REACH * self.thickest();
        for (s, m) in self.members.iter().enumerate() {
            let i = m.0 as usize;
            let d = (x[i] - self.start[i] - mean).length();
            if d.is_finite() && d <= reach {
                self.swept[s] = d;
            } else {
                self.start[i] = x[i];
            }
        }
    }

    /// Each member's move since the substep's start.
    fn moved_since_start<'a>(&'a self, x: &'a [DVec3]) -> impl Iterator<Item = DVec3> + 'a {
        (self.members.iter()).map(|m| x[m.0 as usize] - self.start[m.0 as usize])
    }

    /// The members' mean move since the substep's start, over the finite ones.
    fn mean_move(&self, x: &[DVec3]) -> DVec3 {
        let finite = || self.moved_since_start(x).filter(|d| d.is_finite());
        finite().sum::<DVec3>() / finite().count().max(1) as f64
    }

    /// The candidates: particle pairs, faces and edge pairs.
    fn candidate_count(&self) -> usize {
        self.pairs.len() + self.faces.len() + self.crossings.len()
    }

    fn keep_start(&mut self, packed: &Packed) {
        for m in &self.members {
            self.start[m.0 as usize] = packed.x[m.0 as usize];
        }
    }

    /// The candidates found again if some pair left out may have closed past the margin since
    /// they were ([`skin::Skin::holds`]).
    fn refresh(&mut self, packed: &Packed) -> Result<(), GpuError> {
        let x = &packed.x;
        let since = (self.members.iter().zip(&self.built)).map(|(m, b)| x[m.0 as usize] - *b);
        if !self.skin.holds(since, self.margin) {
            let mean = self.mean_move(x);
            let mut swept = std::mem::take(&mut self.swept);
            swept.clear();
            swept.extend(self.moved_since_start(x).map(|d| {
                let s = (d - mean).length();
                if s.is_finite() {
                    s
                } else {
                    0.0
                }
            }));
            self.swept = swept;
            self.rebuild(packed)?;
        }
        Ok(())
    }

    /// The candidates within their thickness plus the margin (and the two ends' `swept`, so
    /// that a pair that crossed within the substep is found from where it ended), less
    /// neighbours along one cloth, in order.
    fn rebuild(&mut self, packed: &Packed) -> Result<(), GpuError> {
        self.rebuilds += 1;
        self.keep_dues();
        let sweep = self.swept.iter().copied().fold(0.0, f64::max);
        self.reach = self.margin + 2.0 * sweep;
        let x = &packed.x;
        self.built.clear();
        self.built
            .extend(self.members.iter().map(|m| x[m.0 as usize]));
        self.find_pairs(packed);
        self.find_faces(packed)?;
        self.find_crossings(packed)?;
        // In the order of their particles and triangles (or edges), whenever they were found.
        use rayon::prelude::*;
        (self.faces).par_sort_unstable_by_key(|f| (f.p, f.triangle));
        for c in &mut self.crossings {
            (c.a, c.b) = (c.a.min(c.b), c.a.max(c.b));
        }
        (self.crossings).par_sort_unstable_by_key(|c| (c.a, c.b));
        self.set_dues(x.len());
        // How far a pair's distance may exceed that of two of their ends: across a triangle
        // from a corner, or across two edges.
        let radius = |c: &[(DVec3, f64)]| {
            (c.iter().map(|c| c.1).filter(|r| r.is_finite())).fold(0.0, f64::max)
        };
        let across = (2.0 * radius(&self.centres)).max(4.0 * radius(&self.edge_centres));
        let thickest = self.thickest();
        (self.skin).build(&self.built, across, thickest, self.margin);
        if self.coloured {
            self.colour(x.len());
            #[cfg(feature = "gpu")]
            self.upload_pass()?;
        }
        Ok(())
    }

    /// The candidates, and the times they were found since the stage was gathered.
    pub(crate) fn pair_count(&self) -> (usize, u64) {
        (self.candidate_count(), self.rebuilds)
    }

    /// After a substep's springs: one pass over the candidates in order (particle against
    /// particle, against triangle, then edge against edge); the change of the particles' own
    /// energy booked. Returns whether any moved: the springs' change, from [`Self::moves`], is
    /// then the caller's to add.
    pub(crate) fn project(
        &mut self,
        packed: &mut Packed,
        gravity: DVec3,
    ) -> Result<bool, GpuError> {
        self.refresh(packed)?;
        let any = self.pass(packed, gravity);
        self.keep_start(packed);
        Ok(any)
    }

    /// The particles the colliders' contacts moved in the last substep (`touched`, packed
    /// indices; empty where the contacts ran on the device): in the next pass they push as
    /// ten times heavier ([`GROUNDED`]), so a cloth lying on another that lies on a collider
    /// is pushed up off it instead of both being pushed halfway, the lower one into the
    /// collider (which then pushes it back, a fight that pumps energy in and out every
    /// substep). The collider takes the difference, as it takes the lower cloth's weight: the
    /// pair's momentum is not kept then.
    pub(crate) fn ground(&mut self, touched: &[bool]) {
        self.grounded.clear();
        self.grounded.extend_from_slice(touched);
    }

    /// What the last pass moved.
    pub(crate) fn moves(&self) -> &crate::audit::Moves {
        &self.moves
    }
}
