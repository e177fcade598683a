//! Each member's neighbours at rest as bits: a window of bits from its first neighbour, so
//! the search asks whether a triangle is one with one load (nearly every triangle it meets
//! within reach is one), where a binary search of the list took a chain of dependent loads.
//! A member whose neighbours' indices spread too wide for a window keeps the list.

/// Each member's neighbours at rest, as a list and as bits, built together.
#[derive(Debug, Default)]
pub(super) struct Neighbours {
    /// Member `s`'s: `list[at[s]..at[s + 1]]`, ascending (what the device is sent).
    pub(super) list: Vec<u32>,
    pub(super) at: Vec<u32>,
    windows: Windows,
}

impl Neighbours {
    /// From `(member, neighbour)` pairs (each once), for `members` members.
    pub(super) fn new(pairs: &mut [(u32, u32)], members: usize) -> Self {
        pairs.sort_unstable();
        let mut at = vec![0u32; members + 1];
        let list = pairs.iter().map(|&(s, k)| {
            at[s as usize + 1] += 1;
            k
        });
        let list: Vec<u32> = list.collect();
        for s in 1..at.len() {
            at[s] += at[s - 1];
        }
        let windows = Windows::new(&list, &at);
        Self { list, at, windows }
    }

    /// Whether `k` is among member `s`'s neighbours.
    #[inline]
    pub(super) fn contains(&self, s: u32, k: u32) -> bool {
        let own = &self.list[self.at[s as usize] as usize..self.at[s as usize + 1] as usize];
        self.windows.contains(s, k, own)
    }
}

/// The widest window, in words of 64 bits: a 128-wide sheet's neighbours span about 16.
const WIDEST: usize = 64;

/// The windows of bits of each member's neighbours.
#[derive(Debug, Default)]
struct Windows {
    /// Each member's first neighbour, its first word in `bits` and its count of words (none
    /// where it has no neighbours; [`u32::MAX`] where the list decides).
    window: Vec<(u32, u32, u32)>,
    bits: Vec<u64>,
}

impl Windows {
    /// The windows of the lists `list[at[s]..at[s + 1]]` (each ascending).
    fn new(list: &[u32], at: &[u32]) -> Self {
        let mut w = Self::default();
        for s in at.windows(2) {
            let own = &list[s[0] as usize..s[1] as usize];
            let (Some(&first), Some(&last)) = (own.first(), own.last()) else {
                w.window.push((0, 0, 0));
                continue;
            };
            let words = (last - first) as usize / 64 + 1;
            if words > WIDEST {
                w.window.push((first, 0, u32::MAX));
                continue;
            }
            let start = w.bits.len();
            w.bits.resize(start + words, 0);
            for &k in own {
                let o = (k - first) as usize;
                w.bits[start + o / 64] |= 1 << (o % 64);
            }
            w.window.push((first, start as u32, words as u32));
        }
        w
    }

    /// Whether `k` is among member `s`'s neighbours, `list` its list.
    #[inline]
    fn contains(&self, s: u32, k: u32, list: &[u32]) -> bool {
        let (first, start, words) = self.window[s as usize];
        if words == u32::MAX {
            return list.binary_search(&k).is_ok();
        }
        let o = k.wrapping_sub(first) as usize;
        o < 64 * words as usize && self.bits[start as usize + o / 64] & (1 << (o % 64)) != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every index answered as its list answers, windows and lists alike.
    #[test]
    fn the_windows_answer_as_the_lists() {
        let mut r = super::super::uniform(3);
        let mut lists: Vec<Vec<u32>> = Vec::new();
        for n in 0..40 {
            // Some clustered, some spread past the widest window, some empty.
            let spread = if n % 3 == 0 { 100_000.0 } else { 600.0 };
            let base = (5000.0 * (1.0 + r())) as u32;
            let mut l: Vec<u32> = (0..n % 17)
                .map(|_| base + (spread * (1.0 + r())) as u32)
                .collect();
            l.sort_unstable();
            l.dedup();
            lists.push(l);
        }
        let mut at = vec![0u32];
        let list: Vec<u32> = lists.concat();
        for l in &lists {
            at.push(at.last().copied().unwrap_or(0) + l.len() as u32);
        }
        let w = Windows::new(&list, &at);
        assert!(w.window.iter().any(|x| x.2 == u32::MAX));
        assert!(w.window.iter().any(|x| x.2 > 1 && x.2 != u32::MAX));
        for (s, l) in lists.iter().enumerate() {
            let own = &list[at[s] as usize..at[s + 1] as usize];
            for k in (0..210_000).step_by(7).chain(l.iter().copied()) {
                assert_eq!(w.contains(s as u32, k, own), l.contains(&k), "{s} {k}");
            }
        }
    }
}
