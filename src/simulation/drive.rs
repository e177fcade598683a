//! Driven pins and motion constraints: particles the game moves every frame (a cape's collar
//! following a skinned shoulder), and particles kept within a distance of the pose it drives
//! (a garment's motion constraint, as NvCloth and Chaos build garments on).
//!
//! A drive is a set of particles with a target each, set once a frame in one call
//! ([`Simulation::set_drive_targets`], no allocation). Over the next frame the targets are
//! reached along straight paths, a share at every substep (the drive stage, after the
//! integrate stage), so the cloth feels the motion instead of being teleported:
//! - a particle of maximum distance 0 is pinned and moved along its path, its velocity the
//!   path's (the springs' dampers read it);
//! - one of maximum distance `r > 0` stays free, and where it ends a substep further than `r`
//!   from its target's path it is put back on that sphere, its velocity away from the path's
//!   point (relative to the point's own) removed.
//!
//! The energy audit books both on its attachments line ([`crate::EnergyAudit::attachments`]):
//! a pin's move as its work along the path over the substep (the mean of the change of `E` the
//! move makes at the substep's start positions and at its end ones, springs included: second
//! order in the step), a projection as the change of `E` it made.

use super::*;
use crate::audit;

/// A drive of a simulation ([`Simulation::drive`]), to set its targets by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct DriveId(u32);

/// The simulation's drives and the stage's books.
#[derive(Debug, Default)]
pub(super) struct Drives {
    sets: Vec<DriveSet>,
    next: u32,
    /// What the stage put in this frame (J), for the attachments line.
    pub(super) energy: f64,
    /// The frame's substeps and their length, set at its start.
    substeps: u32,
    dt: f64,
    /// The substep's pin moves as the springs' start positions would take them (J): half of
    /// each move's booked work (see [`Drives::begin_substep`]).
    at_start: f64,
}

#[derive(Debug)]
struct DriveSet {
    id: DriveId,
    entities: Vec<Entity>,
    /// Packed index per element, `u32::MAX` once the particle is gone (refreshed at every
    /// gather).
    index: Vec<u32>,
    /// 0: a driven pin; `r > 0`: free within `r` of the target's path.
    max_distance: Vec<f64>,
    /// Where the frame's paths start: the targets the last frame reached.
    pose: Vec<DVec3>,
    /// Where they end: the game's latest targets.
    target: Vec<DVec3>,
    /// Elements this drive pinned (they were free): freed when it is removed.
    pinned_here: Vec<bool>,
}

const GONE: u32 = u32::MAX;

impl Drives {
    pub(super) fn is_empty(&self) -> bool {
        self.sets.is_empty()
    }

    /// The particles the drives pinned (they were free before).
    pub(super) fn pinned_here(&self) -> impl Iterator<Item = Entity> + '_ {
        (self.sets.iter()).flat_map(|s| {
            (s.entities.iter().zip(&s.pinned_here))
                .filter(|(_, &p)| p)
                .map(|(&e, _)| e)
        })
    }

    /// Every element's packed index again, after a gather (a cloth removed shifts them).
    pub(super) fn refresh(&mut self, packed: &Packed) {
        for set in &mut self.sets {
            for (i, &e) in set.index.iter_mut().zip(&set.entities) {
                *i = packed.index_of(e).map_or(GONE, |i| i as u32);
            }
        }
    }

    /// The frame's start: its books opened, and the driven pins given their paths' velocity
    /// (the first substep's dampers read it). Run again when a frame is taken again.
    pub(super) fn begin_frame(&mut self, packed: &mut Packed, substeps: u32, h: f64) {
        self.energy = 0.0;
        self.substeps = substeps.max(1);
        self.dt = h * self.substeps as f64;
        for set in &self.sets {
            for k in 0..set.index.len() {
                let i = set.index[k];
                if i != GONE && set.max_distance[k] == 0.0 {
                    packed.v[i as usize] = (set.target[k] - set.pose[k]) / self.dt;
                }
            }
        }
    }

    /// The path's point at share `s / substeps` of element `k` of `set`.
    fn at(&self, set: &DriveSet, k: usize, s: u32) -> DVec3 {
        let (from, to) = (set.pose[k], set.target[k]);
        if s >= self.substeps {
            to
        } else {
            from + (to - from) * (s as f64 / self.substeps as f64)
        }
    }

    /// Before substep `s`'s springs move: the change of `E` each pin's move would make at the
    /// substep's start positions. A pin's work is booked as the mean of that and the change the
    /// move makes after the springs' step (a trapezoid over the substep, second order in the
    /// step; the change after alone is first order: `../shared/MATH.md`'s audit books a
    /// projection's change, but a driven pin is a force doing work along a path).
    pub(super) fn begin_substep(&mut self, packed: &mut Packed, s: u32, gravity: DVec3) {
        let mut start = 0.0;
        for set in &self.sets {
            for k in 0..set.index.len() {
                let i = set.index[k];
                if i == GONE || set.max_distance[k] != 0.0 {
                    continue;
                }
                let i = i as usize;
                let here = packed.x[i];
                let before = audit::local_energy(packed, i, gravity);
                packed.x[i] = self.at(set, k, s);
                start += audit::local_energy(packed, i, gravity) - before;
                packed.x[i] = here;
            }
        }
        self.at_start = start;
    }

    /// Substep `s` of the frame's (1-based): every element at its path's share `s / substeps`.
    pub(super) fn substep(&mut self, packed: &mut Packed, s: u32, gravity: DVec3) {
        let (mut moved, mut projected) = (0.0, 0.0);
        for set in &self.sets {
            for k in 0..set.index.len() {
                let i = set.index[k];
                if i == GONE {
                    continue;
                }
                let i = i as usize;
                let at = self.at(set, k, s);
                let vp = (set.target[k] - set.pose[k]) / self.dt;
                let r = set.max_distance[k];
                if r == 0.0 {
                    let before = audit::local_energy(packed, i, gravity);
                    packed.x[i] = at;
                    packed.v[i] = vp;
                    moved += audit::local_energy(packed, i, gravity) - before;
                    continue;
                }
                let d = packed.x[i] - at;
                let len = d.length();
                if packed.inv_mass[i] == 0.0 || len <= r || !len.is_finite() {
                    continue;
                }
                let before = audit::local_energy(packed, i, gravity);
                let n = d / len;
                packed.x[i] = at + n * r;
                let away = (packed.v[i] - vp).dot(n);
                if away > 0.0 {
                    packed.v[i] -= away * n;
                }
                projected += audit::local_energy(packed, i, gravity) - before;
            }
        }
        self.energy += 0.5 * (self.at_start + moved) + projected;
    }

    /// The frame's end: the targets reached are where the next frame's paths start.
    pub(super) fn end_frame(&mut self) {
        for set in &mut self.sets {
            set.pose.copy_from_slice(&set.target);
        }
    }

    fn set(&self, id: DriveId) -> Result<&DriveSet, SimError> {
        self.sets
            .iter()
            .find(|s| s.id == id)
            .ok_or(SimError::UnknownDrive)
    }
}

impl Simulation {
    /// Makes particles (scene order) driven pins: pinned where they are, then moved each frame
    /// to the targets the game sets with [`Self::set_drive_targets`] (a cape's collar on a
    /// skinned shoulder, a hand holding a cloth's corner). The returned id sets their targets,
    /// in the order given here. See [`Self::drive_within`] for particles that stay free within
    /// a distance of their targets.
    pub fn drive(&mut self, particles: &[usize]) -> Result<DriveId, SimError> {
        self.add_drive("drive", particles, None)
    }

    /// A drive whose particle `particles[k]` stays within `max_distance[k]` (m) of its target,
    /// the pose the game drives (a garment's motion constraint: the distance it may swing from
    /// its skinned pose). A distance of 0 makes that particle a driven pin, as in
    /// [`Self::drive`]; an infinite one leaves it unconstrained.
    ///
    /// Errors: [`SimError::NoParticle`] for an index out of range, [`SimError::BadDrive`] for
    /// lists of different lengths or a distance that is negative or NaN.
    pub fn drive_within(
        &mut self,
        particles: &[usize],
        max_distance: &[f64],
    ) -> Result<DriveId, SimError> {
        const CALL: &str = "drive_within";
        if particles.len() != max_distance.len() {
            return Err(SimError::BadDrive {
                call: CALL,
                what: format!(
                    "{} particle(s) and {} maximum distance(s); give one distance per particle",
                    particles.len(),
                    max_distance.len()
                ),
            });
        }
        if let Some(k) = max_distance.iter().position(|r| r.is_nan() || *r < 0.0) {
            return Err(SimError::BadDrive {
                call: CALL,
                what: format!(
                    "max_distance[{k}] = {:?}: a distance is ≥ 0 m (0 pins, infinite frees)",
                    max_distance[k]
                ),
            });
        }
        self.add_drive(CALL, particles, Some(max_distance))
    }

    fn add_drive(
        &mut self,
        call: &'static str,
        particles: &[usize],
        max_distance: Option<&[f64]>,
    ) -> Result<DriveId, SimError> {
        if particles.is_empty() {
            return Err(SimError::BadDrive {
                call,
                what: "no particles given".into(),
            });
        }
        let entities = (particles.iter())
            .map(|&i| self.particle_entity(i))
            .collect::<Result<Vec<_>, _>>()?;
        let max_distance = max_distance.map_or_else(|| vec![0.0; particles.len()], <[f64]>::to_vec);
        let mut pose = Vec::with_capacity(particles.len());
        let mut pinned_here = Vec::with_capacity(particles.len());
        for (k, (&i, &e)) in particles.iter().zip(&entities).enumerate() {
            let x = self
                .world
                .get::<&crate::Particle>(e)
                .map_or(self.packed.x[i], |p| p.position);
            pose.push(x);
            let pin = max_distance[k] == 0.0 && self.world.get::<&Pin>(e).is_err();
            if pin {
                self.grabbed.retain(|g| *g != e);
                let _ = self.world.insert_one(e, Pin);
                self.edited(i, Some(true), None);
            }
            pinned_here.push(pin);
        }
        let id = DriveId(self.next_drive());
        self.drives.sets.push(DriveSet {
            id,
            index: particles.iter().map(|&i| i as u32).collect(),
            entities,
            max_distance,
            target: pose.clone(),
            pose,
            pinned_here,
        });
        self.build_schedule(self.user_stage.is_some());
        Ok(id)
    }

    fn next_drive(&mut self) -> u32 {
        let n = self.drives.next;
        self.drives.next += 1;
        n
    }

    /// Sets the drive's targets (m, in the order its particles were given), reached at the end
    /// of the next frame along straight paths, a share every substep. Allocates nothing: call
    /// it every frame. Targets not set again stay where they are (the pins then rest there).
    /// [`Self::advance`] running several steps reaches them in the first.
    ///
    /// Errors: [`SimError::UnknownDrive`]; [`SimError::BadDrive`] for a count that is not the
    /// drive's or a target that is not finite (nothing is changed then).
    pub fn set_drive_targets(&mut self, id: DriveId, targets: &[DVec3]) -> Result<(), SimError> {
        const CALL: &str = "set_drive_targets";
        let set = self.drives.set(id)?;
        if targets.len() != set.target.len() {
            return Err(SimError::BadDrive {
                call: CALL,
                what: format!(
                    "{} target(s) for a drive of {} particle(s)",
                    targets.len(),
                    set.target.len()
                ),
            });
        }
        if let Some(k) = targets.iter().position(|t| !t.is_finite()) {
            return Err(SimError::BadDrive {
                call: CALL,
                what: format!("targets[{k}] is not finite: {:?}", targets[k].to_array()),
            });
        }
        let set = (self.drives.sets.iter_mut())
            .find(|s| s.id == id)
            .ok_or(SimError::UnknownDrive)?;
        set.target.copy_from_slice(targets);
        Ok(())
    }

    /// The drive's targets as last set (its particles' rest places before any were set).
    pub fn drive_targets(&self, id: DriveId) -> Result<&[DVec3], SimError> {
        Ok(&self.drives.set(id)?.target)
    }

    /// Ends a drive: the particles it pinned are freed (at rest), the others left as they are.
    pub fn remove_drive(&mut self, id: DriveId) -> Result<(), SimError> {
        let k = (self.drives.sets.iter())
            .position(|s| s.id == id)
            .ok_or(SimError::UnknownDrive)?;
        let set = self.drives.sets.remove(k);
        for ((&e, &i), &pinned) in set.entities.iter().zip(&set.index).zip(&set.pinned_here) {
            if pinned && i != GONE && self.world.contains(e) {
                self.free(i as usize, e);
            }
        }
        self.build_schedule(self.user_stage.is_some());
        Ok(())
    }
}
