//! The pass over the candidates, in their fixed order (by kind, then their two indices,
//! however they were found), and how a contact found apart waits: each particle's path (less
//! the members' mean move each substep, and every push) runs on an odometer, and a candidate
//! tested apart by `d` past its thickness is not tested again until its ends' odometers,
//! summed, have run `d` further ([`super::contact::Tested`]): the test would find it apart
//! until then. A candidate found again keeps its due, the odometers running on; they start
//! from 0 where the candidates are found at a frame's start.

use glam::DVec3;

use super::{contact, CollideStage, GROUNDED, VELOCITY_PASSES};
use crate::buffers::Packed;

/// A candidate by kind (particle pair, face, edge pair) and its two indices: the pass's order.
pub(super) type Key = (u8, u32, u32);

impl CollideStage {
    /// The pass over the candidates (in colours where the device runs it), the particles' own
    /// energy change booked; whether any moved.
    pub(super) fn pass(&mut self, packed: &mut Packed, gravity: DVec3) -> bool {
        let n = self.moves.moved.len();
        self.moves.reset(n);
        let mut any = false;
        self.inv.clear();
        self.inv.extend_from_slice(&packed.inv_mass);
        if self.grounded.len() == self.inv.len() {
            for (w, &g) in self.inv.iter_mut().zip(&self.grounded) {
                if g {
                    *w *= GROUNDED;
                }
            }
        }
        let (np, nf) = (self.pairs.len(), self.faces.len());
        self.advance_odometer(&packed.x);
        let mut touch = contact::Touch {
            x: &mut packed.x,
            v: &mut packed.v,
            inv: &self.inv,
            moves: &mut self.moves,
            before_v: &mut self.before_v,
            active: &mut self.active,
            odometer: &mut self.odometer,
        };
        touch.active.clear();
        let (due, waited) = (&mut self.due, &mut self.waited);
        let mut push = |k: usize| {
            // A contact found apart is tested again only once its sides' paths since, summed,
            // may have closed the gap (the test would find it apart until then).
            let (ends, at) = &mut due[k];
            let used = ends
                .iter()
                .map(|&i| touch.odometer[i as usize])
                .sum::<f64>();
            if used < *at {
                *waited += 1;
                return;
            }
            let tested = if k < np {
                let (a, b, t, friction) = self.pairs[k];
                touch.points(a as usize, b as usize, t, friction)
            } else if k < np + nf {
                let f = &self.faces[k - np];
                let at = self.triangles[f.triangle as usize].at;
                touch.face(f.p as usize, at, &self.start, f.thickness, f.friction)
            } else {
                let c = &self.crossings[k - np - nf];
                let [e, f] = [c.a, c.b].map(|k| self.edges[k as usize].at.map(|i| i as usize));
                touch.edges(e, f, &self.start, c.thickness, c.friction)
            };
            any |= tested.moved;
            *at = if tested.apart > 0.0 {
                used + tested.apart
            } else {
                f64::NEG_INFINITY
            };
        };
        if self.coloured {
            self.colours.order.iter().for_each(|&k| push(k as usize));
        } else {
            (0..np + nf + self.crossings.len()).for_each(push);
        }
        for _ in 1..VELOCITY_PASSES {
            touch.settle();
        }
        if any {
            (self.moves).book_particles(&self.before_v, packed, gravity, &mut self.energy);
        }
        any
    }

    /// The candidates' keys, in their order (ascending).
    fn keys(&self) -> impl Iterator<Item = Key> + '_ {
        let pairs = self.pairs.iter().map(|p| (0, p.0, p.1));
        let faces = self.faces.iter().map(|f| (1, f.p, f.triangle));
        let crossings = self.crossings.iter().map(|c| (2, c.a, c.b));
        pairs.chain(faces).chain(crossings)
    }

    /// Before a find: the candidates' dues by key, where the odometers run on.
    pub(super) fn keep_dues(&mut self) {
        let mut kept = std::mem::take(&mut self.kept);
        kept.clear();
        let count = self.candidate_count();
        if !self.odometer.is_empty() && self.due.len() == count {
            kept.extend(self.keys().zip(self.due.iter().map(|d| d.1)));
        }
        self.kept = kept;
    }

    /// After a find (in key order): each candidate's ends and due, kept where it was a
    /// candidate before and the odometers ran on, else now; the odometers from 0 where they
    /// do not run on (`n` particles).
    pub(super) fn set_dues(&mut self, n: usize) {
        if self.odometer.len() != n + 1 {
            // One more odometer, always 0, for the ends a candidate lacks.
            self.odometer.clear();
            self.odometer.resize(n + 1, 0.0);
            self.kept.clear();
        }
        let none = n as u32;
        let mut due = std::mem::take(&mut self.due);
        due.clear();
        let mut kept = self.kept.iter().peekable();
        for (ends, key) in self.ends().zip(self.keys()) {
            while kept.next_if(|k| k.0 < key).is_some() {}
            let at = kept
                .next_if(|k| k.0 == key)
                .map_or(f64::NEG_INFINITY, |k| k.1);
            due.push((ends.map(|i| if i == u32::MAX { none } else { i }), at));
        }
        self.due = due;
    }

    /// Each member's move since the last pass (the springs', the colliders', the game's), less
    /// the members' mean move, onto its odometer (or the dues set, where the candidates have
    /// none yet).
    pub(super) fn advance_odometer(&mut self, x: &[DVec3]) {
        let count = self.candidate_count();
        if self.due.len() != count || self.odometer.len() != x.len() + 1 {
            self.odometer.clear();
            self.set_dues(x.len());
            return;
        }
        let mean = self.mean_move(x);
        let mut odometer = std::mem::take(&mut self.odometer);
        for (m, d) in self.members.iter().zip(self.moved_since_start(x)) {
            let o = &mut odometer[m.0 as usize];
            *o += (d - mean).length();
            if o.is_nan() {
                *o = f64::INFINITY;
            }
        }
        self.odometer = odometer;
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use crate::collide::search::tests::{bits, crumpled};

    /// A sheet sinking slowly through a folded one, 30 frames of 8 substeps, every particle
    /// pushed up to 0.5 mm between frames: where the candidates still hold at a frame's start
    /// they are kept (with their dues), and the run gives the bits of finding them at every
    /// frame's start.
    #[test]
    fn candidates_kept_at_a_frames_start_give_the_same_bits() {
        let run = |keep: bool| -> (Vec<[u64; 6]>, u64) {
            let (mut stage, mut packed) = crumpled();
            let n = packed.x.len();
            packed.v = (0..n)
                .map(|i| DVec3::new(0.0, -0.05 * f64::from(stage.members[i].1), 0.0))
                .collect();
            stage.moves.reset(n);
            stage.before_v.resize(n, DVec3::ZERO);
            stage.start = packed.x.clone();
            let mut r = crate::collide::uniform(3);
            let h = 1.0 / 480.0;
            for _ in 0..30 {
                // Pushed between frames (as a collider's contacts do, after the pass).
                for i in 0..n {
                    packed.x[i].y += 5e-4 * r().abs();
                }
                if !keep {
                    stage.built.clear();
                }
                stage.begin_frame(&packed).unwrap();
                for _ in 0..8 {
                    for i in 0..n {
                        let shake = DVec3::new(r(), r(), r()) * 2e-5;
                        packed.x[i] += packed.v[i] * h + shake;
                    }
                    stage.project(&mut packed, DVec3::ZERO).unwrap();
                }
            }
            let bits = bits(&packed);
            (bits, stage.rebuilds)
        };
        let (every, found_every) = run(false);
        let (kept, found_kept) = run(true);
        println!("found {found_kept} times, against {found_every} at every frame's start");
        assert!(
            found_kept + 10 < found_every,
            "{found_kept} against {found_every}"
        );
        assert!(every == kept);
    }
}
