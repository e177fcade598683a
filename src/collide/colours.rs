//! The pass's order: the candidates in colours, no two of one colour sharing a particle, each
//! colour's in the candidates' order. Gauss–Seidel over the colours one after another gives
//! the same result whether a colour's contacts run one after another (the CPU) or side by side
//! (the device's invocations): the two back ends can run one order.

use super::CollideStage;

/// The candidates (particle pairs, then faces, then edge crossings, numbered in that order)
/// by colour: `order[at[c]..at[c + 1]]` are colour `c`'s.
#[derive(Debug, Default)]
pub(super) struct Colours {
    pub(super) order: Vec<u32>,
    pub(super) at: Vec<u32>,
    /// Each particle's colours taken so far, a bit each (scratch).
    taken: Vec<u64>,
    colour: Vec<u32>,
}

/// A candidate's particles (packed indices); `u32::MAX` where it has fewer than four.
pub(super) type Ends = [u32; 4];

impl Colours {
    /// Greedy colouring in the candidates' order: each takes the first colour none of its
    /// particles has (at most four times the largest number of candidates a particle is in).
    pub(super) fn build(&mut self, n: usize, ends: impl Iterator<Item = Ends> + Clone) {
        let mut degree = vec![0u32; n];
        for e in ends.clone() {
            for i in e.into_iter().filter(|&i| i != u32::MAX) {
                degree[i as usize] += 1;
            }
        }
        let most = degree.iter().copied().max().unwrap_or(0) as usize;
        let words = (4 * most) / 64 + 1;
        self.taken.clear();
        self.taken.resize(n * words, 0);
        self.colour.clear();
        let mut count = Vec::<u32>::new();
        for e in ends {
            let own = |i: &u32| *i != u32::MAX;
            // Four particles have taken at most four times the largest degree of colours, under
            // `words` words: a free one is always within them.
            let (mut w, mut c) = (0, words * 64);
            while w < words {
                let taken = (e.iter().filter(|i| own(i)))
                    .fold(0, |m, &i| m | self.taken[i as usize * words + w]);
                if taken != u64::MAX {
                    c = w * 64 + taken.trailing_ones() as usize;
                    break;
                }
                w += 1;
            }
            if w < words {
                for i in e.into_iter().filter(own) {
                    self.taken[i as usize * words + w] |= 1u64 << (c % 64);
                }
            }
            if c >= count.len() {
                count.resize(c + 1, 0);
            }
            count[c] += 1;
            self.colour.push(c as u32);
        }
        self.at.clear();
        self.at.push(0);
        for &k in &count {
            self.at.push(self.at.last().copied().unwrap_or(0) + k);
        }
        let mut next: Vec<u32> = self.at[..count.len()].to_vec();
        self.order.clear();
        self.order.resize(self.colour.len(), 0);
        for (k, &c) in self.colour.iter().enumerate() {
            self.order[next[c as usize] as usize] = k as u32;
            next[c as usize] += 1;
        }
    }

    #[cfg(test)]
    pub(super) fn colours(&self) -> usize {
        self.at.len().saturating_sub(1)
    }
}

impl CollideStage {
    /// The candidates' particles, in their numbering.
    pub(super) fn ends(&self) -> impl Iterator<Item = Ends> + Clone + '_ {
        let none = u32::MAX;
        let pairs = self.pairs.iter().map(move |p| [p.0, p.1, none, none]);
        let faces = (self.faces.iter()).map(|f| {
            let t = self.triangles[f.triangle as usize].at;
            [f.p, t[0], t[1], t[2]]
        });
        let crossings = (self.crossings.iter()).map(|c| {
            let [e, f] = [c.a, c.b].map(|k| self.edges[k as usize].at);
            [e[0], e[1], f[0], f[1]]
        });
        pairs.chain(faces).chain(crossings)
    }

    /// The candidates coloured for the pass.
    pub(super) fn colour(&mut self, n: usize) {
        let mut colours = std::mem::take(&mut self.colours);
        colours.build(n, self.ends());
        self.colours = colours;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every candidate once, no two of a colour sharing a particle, each colour's in order,
    /// against a random set of candidates.
    #[test]
    fn no_two_of_a_colour_share_a_particle() {
        let mut r = super::super::uniform(3);
        let n = 40;
        let ends: Vec<Ends> = (0..500)
            .map(|k| {
                let mut pick = || ((r() + 1.0) * 0.5 * n as f64) as u32 % n as u32;
                if k % 3 == 0 {
                    let (a, b) = (pick(), pick());
                    [a, b.max(a + 1) % n as u32, u32::MAX, u32::MAX]
                } else {
                    let a = pick();
                    [a, (a + 1) % 40, (a + 2) % 40, (a + 7) % 40]
                }
            })
            .collect();
        let mut c = Colours::default();
        c.build(n, ends.iter().copied());
        let mut seen = vec![false; ends.len()];
        for colour in 0..c.colours() {
            let members = &c.order[c.at[colour] as usize..c.at[colour + 1] as usize];
            assert!(members.windows(2).all(|w| w[0] < w[1]), "in order");
            let mut used = vec![false; n];
            for &k in members {
                assert!(!std::mem::replace(&mut seen[k as usize], true));
                for i in ends[k as usize].into_iter().filter(|&i| i != u32::MAX) {
                    assert!(!std::mem::replace(&mut used[i as usize], true));
                }
            }
        }
        assert!(seen.iter().all(|&s| s));
        assert!(c.colours() > 10, "{} colours", c.colours());
    }
}
