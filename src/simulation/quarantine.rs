//! The quarantine: particles gone non-finite are frozen at their last finite position.

use super::*;

/// The quarantine's check, after every substep (and after a gather, for state set from
/// outside): each particle with a non-finite position or velocity goes back to its position in
/// `world` (the last finite frame) at rest, before any spring reads it again, and is recorded
/// in `found`. One parallel read of the state when nothing is wrong.
pub(super) fn contain(packed: &mut Packed, world: &World, found: &mut Vec<usize>) -> bool {
    let bad = |x: &DVec3, v: &DVec3| !metrics::finite_state(*x, *v);
    if !crate::integrate::par::any2(&packed.x, &packed.v, bad) {
        return false;
    }
    for i in 0..packed.particle_count() {
        if bad(&packed.x[i], &packed.v[i]) {
            // Gather refuses non-finite positions and scatter writes only finite ones, so the
            // World's position is finite; the origin is only a last resort.
            packed.x[i] = world
                .get::<&crate::components::Particle>(packed.topology.entities[i])
                .map_or(DVec3::ZERO, |p| p.position);
            packed.v[i] = DVec3::ZERO;
            found.push(i);
        }
    }
    true
}

impl Simulation {
    /// Pins the particles this frame contained and marks them [`Quarantined`]; their state is
    /// already restored. Re-gathers on the next step, so they stay frozen from then on.
    pub(super) fn quarantine(&mut self) -> usize {
        if self.contained.is_empty() {
            return 0;
        }
        self.contained.sort_unstable();
        self.contained.dedup();
        for &i in &self.contained {
            let e = self.packed.topology.entities[i];
            let was_pinned = self.packed.inv_mass[i] == 0.0;
            let q = Quarantined {
                step: self.steps,
                was_pinned,
            };
            let _ = self.world.insert(e, (Pin, q));
            // At rest where it was put back, so a release starts it from there.
            if let Ok(mut p) = self.world.get::<&mut crate::components::Particle>(e) {
                p.position = self.packed.x[i];
                p.velocity = DVec3::ZERO;
            }
            self.grabbed.retain(|g| *g != e);
        }
        self.dirty = true;
        let n = self.contained.len();
        self.contained.clear();
        self.newly_quarantined += n;
        n
    }

    /// Particles in quarantine (scene order): each went non-finite in a step and was frozen at
    /// its last finite position. A game may log them, hide them, or release them.
    pub fn quarantined(&self) -> Vec<(usize, Quarantined)> {
        let mut out: Vec<_> = self
            .world
            .query::<(Entity, &Quarantined)>()
            .iter()
            .filter_map(|(e, q)| self.packed.index_of(e).map(|i| (i, *q)))
            .collect();
        out.sort_unstable_by_key(|(i, _)| *i);
        out
    }

    /// Lets a quarantined particle (scene order) move again, unpinned unless it was pinned
    /// before; whatever made it non-finite should be fixed first, or it comes straight back.
    pub fn release_quarantine(&mut self, index: usize) -> Result<(), SimError> {
        let e = self.particle_entity(index)?;
        let q = self
            .world
            .remove_one::<Quarantined>(e)
            .map_err(|_| SimError::NotQuarantined { index })?;
        if !q.was_pinned {
            let _ = self.world.remove_one::<Pin>(e);
        }
        self.dirty = true;
        Ok(())
    }
}
