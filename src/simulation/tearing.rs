//! The tearing stage's frame end on the World ([`crate::tear`]): the broken springs and their
//! triangles gone, the game's events, the next frame's gather.

use super::*;

impl Simulation {
    /// After the frame's scatter: the breaks the tearing stage found, into the World.
    pub(super) fn tear_apart(&mut self) {
        self.torn.clear();
        if self.tear.broken.is_empty() {
            return;
        }
        let mut breaks = Vec::with_capacity(self.tear.broken.len());
        self.tear.apply(&mut self.world, &self.packed, &mut breaks);
        let step = self.steps - 1;
        for (e, a, b) in breaks {
            if let Some(&(cloth, _)) = self.cloths.iter().find(|c| c.1 == e) {
                let (a, b) = (a as usize, b as usize);
                self.torn.push(crate::Tear { cloth, a, b, step });
            }
        }
        self.tear.broken.clear();
        // The next step gathers the new topology; the surfaces' triangles are made again.
        self.dirty = true;
        self.frame.triangles.take();
    }

    /// The springs that broke in the last frame ([`crate::Tearing`]), in the springs' order:
    /// each one's cloth and ends. Empty after a frame without a break.
    pub fn torn(&self) -> &[crate::Tear] {
        &self.torn
    }

    /// Self-collision's candidates ([`crate::SelfCollision`]): the pairs of particles the
    /// last substep tested, and the times the candidates were found since the scene was last
    /// gathered (once a frame, and again where the particles moved past their margin; 0
    /// without a colliding cloth).
    pub fn collision_pairs(&self) -> (usize, u64) {
        self.collide.pair_count()
    }
}
