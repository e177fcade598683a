//! Geodesic rest distances over a cloth's rest surface: each particle's `k` nearest anchors
//! along the cloth, by a label-setting march over its triangles (Kimmel and Sethian's fast
//! marching on triangulated domains, with each anchor's front kept apart so a particle can
//! take its `k` nearest). A particle's distance from an anchor comes from a triangle two of
//! whose corners that anchor's front has reached: the front unfolded into the triangle's plane
//! as the point `S` at those corners' distances (on the far side of their edge), the distance
//! `|S − C|` where the straight line from `S` crosses that edge, else the shorter way round a
//! corner. Exact on a rest shape that unrolls flat (a sheet, a cylinder, a cone) where the
//! fronts cross edges; elsewhere a close estimate, taken no shorter than the straight line.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use glam::{DVec2, DVec3};

/// A distance in the queue, ordered (distances are finite and ≥ 0).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Dist(f64);

impl Eq for Dist {}

impl PartialOrd for Dist {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Dist {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

/// For each of the `rest.len()` particles, its up to `k` nearest anchors along the surface of
/// `triangles` (indices into `rest`) as `(distance, anchor)`, nearest first (ties by anchor);
/// anchors are their own nearest at 0. A particle no anchor's front reaches (a piece of the
/// cloth with none) has none.
pub(super) fn nearest(
    rest: &[DVec3],
    triangles: &[[u32; 3]],
    anchors: &[u32],
    k: usize,
) -> Vec<Vec<(f64, u32)>> {
    let n = rest.len();
    let triangles: Vec<[u32; 3]> = (triangles.iter().copied())
        .filter(|t| t.iter().all(|&i| (i as usize) < n))
        .collect();
    // Each particle's triangles.
    let mut at = vec![0usize; n + 1];
    for t in &triangles {
        for &i in t {
            at[i as usize + 1] += 1;
        }
    }
    for i in 0..n {
        at[i + 1] += at[i];
    }
    let mut fill = at.clone();
    let mut of = vec![0u32; at[n]];
    for (j, t) in triangles.iter().enumerate() {
        for &i in t {
            of[fill[i as usize]] = j as u32;
            fill[i as usize] += 1;
        }
    }
    let mut done: Vec<Vec<(f64, u32)>> = vec![Vec::new(); n];
    let mut queue = BinaryHeap::new();
    for &a in anchors {
        if (a as usize) < n {
            queue.push(Reverse((Dist(0.0), a, a)));
        }
    }
    while let Some(Reverse((Dist(d), i, a))) = queue.pop() {
        let labels = &mut done[i as usize];
        if labels.len() >= k || labels.iter().any(|l| l.1 == a) {
            continue;
        }
        labels.push((d, a));
        // Out from `i` through each of its triangles, to each corner `a`'s front has not
        // settled yet.
        for &t in &of[at[i as usize]..at[i as usize + 1]] {
            let tri = triangles[t as usize];
            for &c in &tri {
                if c == i || settled(&done[c as usize], a, k) {
                    continue;
                }
                let other = tri.iter().copied().find(|&o| o != i && o != c);
                let mut best = d + (rest[c as usize] - rest[i as usize]).length();
                if let Some(o) = other {
                    if let Some(&(e, _)) = done[o as usize].iter().find(|l| l.1 == a) {
                        let (pi, po, pc) = (rest[i as usize], rest[o as usize], rest[c as usize]);
                        if let Some(u) = unfolded(pi, d, po, e, pc) {
                            best = best.min(u);
                        }
                    }
                }
                if best.is_finite() {
                    queue.push(Reverse((Dist(best), c, a)));
                }
            }
        }
    }
    for labels in &mut done {
        labels.sort_unstable_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    }
    done
}

/// Whether a particle's labels already hold anchor `a`'s, or `k` of them.
fn settled(labels: &[(f64, u32)], a: u32, k: usize) -> bool {
    labels.len() >= k || labels.iter().any(|l| l.1 == a)
}

/// The distance of `c` from a source at `da` from `a` and `db` from `b`, unfolded into the
/// plane of the triangle `(a, b, c)`: the source on the far side of `ab` from `c`; `None`
/// where no such point exists or the straight line from it to `c` misses the edge `ab`.
fn unfolded(a: DVec3, da: f64, b: DVec3, db: f64, c: DVec3) -> Option<f64> {
    let ab = b - a;
    let len = ab.length();
    if len.is_nan() || len <= 0.0 {
        return None;
    }
    let x = ab / len;
    let ac = c - a;
    let cx = ac.dot(x);
    let cy = (ac - x * cx).length();
    if cy.is_nan() || cy <= 0.0 {
        return None;
    }
    // The source at `(sx, sy)`, `sy < 0`: c is at `(cx, cy)`.
    let sx = (da * da - db * db + len * len) / (2.0 * len);
    let h2 = da * da - sx * sx;
    if h2.is_nan() || h2 < 0.0 {
        return None;
    }
    let s = DVec2::new(sx, -h2.sqrt());
    let cp = DVec2::new(cx, cy);
    // Where the line from the source to c meets the edge's line (y = 0).
    let along = s.x + (cp.x - s.x) * (-s.y) / (cp.y - s.y);
    if !(0.0..=len).contains(&along) {
        return None;
    }
    Some((cp - s).length())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid sheet of `cols × rows` particles, `spacing` apart, its place by `at(u, v)`
    /// (the sheet's own coordinates), split into two triangles a quad.
    fn sheet(
        cols: u32,
        rows: u32,
        spacing: f64,
        at: impl Fn(f64, f64) -> DVec3,
    ) -> (Vec<DVec3>, Vec<[u32; 3]>, Vec<DVec2>) {
        let mut rest = Vec::new();
        let mut flat = Vec::new();
        for r in 0..rows {
            for c in 0..cols {
                let (u, v) = (c as f64 * spacing, r as f64 * spacing);
                rest.push(at(u, v));
                flat.push(DVec2::new(u, v));
            }
        }
        let id = |c: u32, r: u32| r * cols + c;
        let mut tris = Vec::new();
        for r in 0..rows - 1 {
            for c in 0..cols - 1 {
                // Alternate diagonals, as a cloth grid does.
                if (r + c) % 2 == 0 {
                    tris.push([id(c, r), id(c + 1, r), id(c + 1, r + 1)]);
                    tris.push([id(c, r), id(c + 1, r + 1), id(c, r + 1)]);
                } else {
                    tris.push([id(c, r), id(c + 1, r), id(c, r + 1)]);
                    tris.push([id(c + 1, r), id(c + 1, r + 1), id(c, r + 1)]);
                }
            }
        }
        (rest, tris, flat)
    }

    /// On a flat sheet the distance along it is the straight line: from a corner and from
    /// two anchors, every particle's nearest as the plane says.
    #[test]
    fn on_a_flat_sheet_the_march_is_the_straight_line() {
        let (rest, tris, _) = sheet(21, 17, 0.05, |u, v| DVec3::new(u, 0.3 * v, 0.9 * v));
        let anchors = [0u32, 20, 7 * 21 + 11];
        let got = nearest(&rest, &tris, &anchors, 2);
        let mut worst = 0.0f64;
        for (i, labels) in got.iter().enumerate() {
            let mut want: Vec<(f64, u32)> = (anchors.iter())
                .map(|&a| ((rest[i] - rest[a as usize]).length(), a))
                .collect();
            want.sort_unstable_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            assert_eq!(labels.len(), 2, "particle {i}");
            for (g, w) in labels.iter().zip(&want) {
                // The two nearest by distance (two anchors as near are a tie either way), each
                // at its own anchor's distance.
                let own = (rest[i] - rest[g.1 as usize]).length();
                worst = worst.max((g.0 - w.0).abs()).max((g.0 - own).abs());
            }
        }
        println!("flat sheet: largest error {worst:e} m");
        assert!(worst < 1e-12, "{worst} m");
    }

    /// A sheet rolled into a half cylinder of radius `R`, anchored along a straight edge: each
    /// particle's distance along it to the anchor beside it is the arc, `R θ`, not the chord.
    #[test]
    fn on_a_rolled_sheet_the_march_is_the_arc() {
        let r = 0.3;
        let rows = 31;
        let spacing = std::f64::consts::PI * r / (rows - 1) as f64;
        let (rest, tris, flat) = sheet(9, rows, spacing, |u, v| {
            let theta = v / r;
            DVec3::new(u, r * theta.cos(), r * theta.sin())
        });
        // The rolled sheet is flat strips: unrolled, a row is a chord, not an arc, from the
        // next.
        let chord = 2.0 * r * (0.5 * spacing / r).sin();
        let flat: Vec<DVec2> = flat
            .iter()
            .map(|f| DVec2::new(f.x, f.y * chord / spacing))
            .collect();
        let anchors: Vec<u32> = (0..9).collect();
        let got = nearest(&rest, &tris, &anchors, 1);
        let mut worst = 0.0f64;
        for (i, labels) in got.iter().enumerate() {
            let (d, a) = labels[0];
            let arc = (flat[i] - flat[a as usize]).length();
            worst = worst.max((d - arc).abs() / arc.max(1e-300));
            assert!(d >= (rest[i] - rest[a as usize]).length() - 1e-12);
        }
        let far = got[got.len() - 1][0].0;
        let arc = std::f64::consts::PI * r;
        println!("rolled sheet: worst relative error {worst:e}; far edge {far} m, arc {arc} m");
        assert!(worst < 1e-12, "{worst}");
        // The arc to 5e-4 (30 chords), where the straight line across is 2r, 64 % of it.
        assert!((far - arc).abs() < 5e-4 * arc, "{far} m");
    }

    #[test]
    fn a_piece_no_front_reaches_has_no_anchor() {
        let rest = [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(5.0, 0.0, 0.0)];
        let got = nearest(&rest, &[[0, 1, 2]], &[0], 1);
        assert_eq!(got[1], vec![(1.0, 0)]);
        assert!(got[3].is_empty());
    }
}
