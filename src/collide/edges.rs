//! Edge against edge: the colliding triangles' edges, each pair of them closer than the
//! thickness (or crossed over the substep) pushed apart at their closest points. Two
//! triangles can cross edge through edge where no corner comes near the other's face: a strip
//! landing across another's edge, or a fold's ridge pressed through another. The candidates
//! are found with the faces', from the edges' midpoints sorted by cell.

use glam::DVec3;

use super::neighbours::Neighbours;
use super::search::{beside, key, split_runs};
use super::{contact, CollideStage};
use crate::buffers::Packed;
use crate::error::GpuError;

/// A colliding triangle's edge: its ends' packed indices (ascending) and member slots, and
/// its layer.
#[derive(Clone, Copy, Debug)]
pub(super) struct Edge {
    pub(super) at: [u32; 2],
    pub(super) slots: [u32; 2],
    pub(super) layer: u16,
}

/// A candidate of an edge against another (indices into the edges, each pair once), with the pair's
/// thickness and friction.
#[derive(Clone, Copy, Debug)]
pub(super) struct Crossing {
    pub(super) a: u32,
    pub(super) b: u32,
    pub(super) thickness: f64,
    pub(super) friction: contact::Friction,
}

/// An edge's midpoint and half length.
fn sphere([a, b]: [DVec3; 2]) -> (DVec3, f64) {
    (0.5 * (a + b), 0.5 * (b - a).length())
}

impl CollideStage {
    /// The edges of the triangles of the layers that ask for them, each once, in order of
    /// their ends; and each edge's edges of its own layer within twice its thickness at rest
    /// (those sharing an end among them), which never collide with it.
    pub(super) fn gather_edges(&mut self) {
        self.edges.clear();
        let asked = |t: &&super::Triangle| self.layers[t.layer as usize].edges;
        for t in self.triangles.iter().filter(asked) {
            for (j, k) in [(0, 1), (1, 2), (2, 0)] {
                let (mut at, mut slots) = ([t.at[j], t.at[k]], [t.slots[j], t.slots[k]]);
                if at[0] > at[1] {
                    at.swap(0, 1);
                    slots.swap(0, 1);
                }
                let layer = t.layer;
                self.edges.push(Edge { at, slots, layer });
            }
        }
        self.edges.sort_unstable_by_key(|e| e.at);
        self.edges.dedup_by_key(|e| e.at);
        let rest_of = |e: &Edge| e.slots.map(|s| self.members[s as usize].2);
        let rest: Vec<(DVec3, f64)> = self.edges.iter().map(|e| sphere(rest_of(e))).collect();
        let near = 2.0 * self.thickest();
        let widest = rest.iter().map(|r| r.1).fold(0.0, f64::max);
        let cell = near + 2.0 * widest;
        if self.edges.is_empty() || !(cell.is_finite() && cell > 0.0) {
            self.edge_excluded = Neighbours::new(&mut [], self.edges.len());
            return;
        }
        let mut cells: Vec<(u64, u32)> = (0u32..)
            .zip(&rest)
            .filter(|(_, r)| r.0.is_finite() && r.1.is_finite())
            .map(|(k, r)| (key(r.0, cell), k))
            .collect();
        cells.sort_unstable();
        let mut pairs = Vec::new();
        beside(&cells, &cells, |run, near| {
            for &(_, s) in run {
                let e = self.edges[s as usize];
                let (ms, rs) = rest[s as usize];
                let apart = 2.0 * self.layers[e.layer as usize].thickness;
                for &(_, u) in near.iter().flat_map(|r| &cells[r.clone()]) {
                    let f = self.edges[u as usize];
                    let (mu, ru) = rest[u as usize];
                    let reach = apart + rs + ru;
                    if u <= s || f.layer != e.layer || (ms - mu).length_squared() >= reach * reach {
                        continue;
                    }
                    let [a, b] = rest_of(&e);
                    let [c, d] = rest_of(&f);
                    let (p, q) = closest_on_segments(a, b, c, d);
                    if (p - q).length_squared() < apart * apart {
                        pairs.push((s, u));
                    }
                }
            }
        });
        // Both ways: the search meets a pair from whichever comes first in its cells' order.
        let back: Vec<(u32, u32)> = pairs.iter().map(|&(s, u)| (u, s)).collect();
        pairs.extend(back);
        self.edge_excluded = Neighbours::new(&mut pairs, self.edges.len());
    }

    /// Edge against edge: the edges sorted by the cell of their midpoints (cells the largest
    /// thickness plus the reach plus the longest edge wide); each pair within the reach, not
    /// within twice the thickness at rest on one cloth, and not held at all four ends, once.
    pub(super) fn find_crossings(&mut self, packed: &Packed) -> Result<(), GpuError> {
        self.crossings.clear();
        if self.edges.is_empty() {
            return Ok(());
        }
        let x = &packed.x;
        self.edge_centres.clear();
        let mut widest = 0.0f64;
        for e in &self.edges {
            let (m, r) = sphere(e.at.map(|i| x[i as usize]));
            if r.is_finite() {
                widest = widest.max(r);
            }
            self.edge_centres.push((m, r));
        }
        let cell = self.thickest() + self.reach + 2.0 * widest;
        self.edge_cells.clear();
        self.edge_cells.extend(
            (0u32..)
                .zip(&self.edge_centres)
                .filter(|(_, c)| c.0.is_finite() && c.1.is_finite())
                .map(|(k, c)| (key(c.0, cell), k)),
        );
        use rayon::prelude::*;
        self.edge_cells.par_sort_unstable();
        #[cfg(feature = "gpu")]
        if self.device.edges.is_some() {
            return self.crossings_on_device(packed, cell);
        }
        // The midpoints beside their keys, so the search reads them in order, each half
        // length with its edge's larger `swept` added (what the pair's reach adds for it).
        let mut near = std::mem::take(&mut self.edge_near);
        let sorted = self.edge_cells.iter().map(|&(_, k)| {
            let (m, r) = self.edge_centres[k as usize];
            let e = &self.edges[k as usize];
            (m, r + self.edge_swept(e), k, e.layer)
        });
        near.fill(sorted, self.members.iter().map(|m| x[m.0 as usize]));
        self.edge_near = near;
        let mut runs = std::mem::take(&mut self.runs);
        split_runs(
            &self.edge_cells,
            4 * rayon::current_num_threads(),
            &mut runs,
        );
        let mut found = std::mem::take(&mut self.found_crossings);
        found.resize_with(runs.len(), Vec::new);
        (found.par_iter_mut().zip(&runs)).for_each(|(out, r)| {
            out.clear();
            self.crossings_of(&self.edge_cells[r.clone()], x, &packed.inv_mass, out);
        });
        for f in &found[..runs.len()] {
            self.crossings.extend_from_slice(f);
        }
        (self.runs, self.found_crossings) = (runs, found);
        Ok(())
    }

    /// The candidates of the edges of `cells` (whole runs of cells) against those after them
    /// in the sorted order.
    fn crossings_of(
        &self,
        cells: &[(u64, u32)],
        x: &[DVec3],
        inv: &[f64],
        out: &mut Vec<Crossing>,
    ) {
        // The pair's reach with the thickest layer's thickness: at least the pair's (a hair
        // over, so rounding never turns away what `crossing` would take).
        let own = (self.thickest() + self.margin) * (1.0 + 1e-12);
        beside(cells, &self.edge_cells, |run, near| {
            for &(key, s) in run {
                let e = self.edges[s as usize];
                let (ms, rs) = self.edge_centres[s as usize];
                let reach = own + (rs + self.edge_swept(&e)) * (1.0 + 1e-12);
                // Each pair once, from the first of the two in the sorted order: only the later
                // entries of the run's column, and the columns after it.
                let (from, to) = (near[4].start, near[4].end);
                let from = from + self.edge_cells[from..to].partition_point(|&e| e <= (key, s));
                let later = std::iter::once(from..to).chain(near[5..].iter().cloned());
                let mut hit = |i: usize| {
                    // Within the widest reach of the midpoint (from the sorted copy), and not a
                    // neighbour at rest, first.
                    let (u, layer) = (self.edge_near.item[i], self.edge_near.layer[i]);
                    if layer == e.layer && self.edge_excluded.contains(s, u) {
                        return;
                    }
                    let centre = self.edge_centres[u as usize];
                    if let Some(c) = self.crossing(s, u, (ms, rs), centre, x, inv) {
                        out.push(c);
                    }
                };
                for r in later {
                    self.edge_near.within(r, ms, reach, &mut hit);
                }
            }
        });
    }

    /// The larger `swept` of an edge's ends.
    fn edge_swept(&self, e: &Edge) -> f64 {
        self.swept[e.slots[0] as usize].max(self.swept[e.slots[1] as usize])
    }

    /// Edge `s` (midpoint and half length `ms`, `rs`) against edge `u` (`m`, `r`), past the
    /// widest reach's test and the neighbours at rest: a candidate if they share no end, are
    /// not all held, and are within the pair's reach of each other's midpoint and then at
    /// their closest points.
    #[inline]
    pub(super) fn crossing(
        &self,
        s: u32,
        u: u32,
        (ms, rs): (DVec3, f64),
        (m, r): (DVec3, f64),
        x: &[DVec3],
        inv: &[f64],
    ) -> Option<Crossing> {
        let held = |e: &Edge| e.at.iter().all(|&i| inv[i as usize] == 0.0);
        let (e, f) = (self.edges[s as usize], self.edges[u as usize]);
        if f.at.iter().any(|i| e.at.contains(i)) || (held(&e) && held(&f)) {
            return None;
        }
        let (t, friction) = self.combine(e.layer, f.layer);
        let reach = t + self.margin + self.edge_swept(&e) + self.edge_swept(&f);
        if (ms - m).length_squared() >= (reach + rs + r) * (reach + rs + r) {
            return None;
        }
        let [a, b] = e.at.map(|i| x[i as usize]);
        let [c, d] = f.at.map(|i| x[i as usize]);
        let (p, q) = closest_on_segments(a, b, c, d);
        ((p - q).length_squared() < reach * reach).then_some(Crossing {
            a: s,
            b: u,
            thickness: t,
            friction,
        })
    }
}

/// The parameters `(s, u)` of the closest points `a + s (b − a)` and `c + u (d − c)` of the
/// lines through the two segments, unclamped; `None` where they are parallel (or a segment has
/// no length).
pub(super) fn line_parameters(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> Option<(f64, f64)> {
    let (d1, d2, r) = (b - a, d - c, a - c);
    let (aa, ee, bb) = (d1.length_squared(), d2.length_squared(), d1.dot(d2));
    let (cc, ff) = (d1.dot(r), d2.dot(r));
    let denom = aa * ee - bb * bb;
    if denom.is_nan() || denom <= 1e-12 * aa * ee {
        return None;
    }
    Some(((bb * ff - cc * ee) / denom, (aa * ff - bb * cc) / denom))
}

/// The weights `(s, u)` of the closest points `a + s (b − a)` and `c + u (d − c)` of the two
/// segments (Ericson, *Real-Time Collision Detection*, 5.1.9): each clamped to its segment in
/// turn; parallel segments give one pair of the closest.
pub(super) fn segment_weights(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> (f64, f64) {
    let (d1, d2, r) = (b - a, d - c, a - c);
    let (aa, ee, ff) = (d1.length_squared(), d2.length_squared(), d2.dot(r));
    let tiny = 1e-300;
    if aa <= tiny && ee <= tiny {
        return (0.0, 0.0);
    }
    if aa <= tiny {
        return (0.0, (ff / ee).clamp(0.0, 1.0));
    }
    let cc = d1.dot(r);
    if ee <= tiny {
        return ((-cc / aa).clamp(0.0, 1.0), 0.0);
    }
    let bb = d1.dot(d2);
    let denom = aa * ee - bb * bb;
    let mut s = if denom > 1e-12 * aa * ee {
        ((bb * ff - cc * ee) / denom).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let mut u = (bb * s + ff) / ee;
    if u < 0.0 {
        u = 0.0;
        s = (-cc / aa).clamp(0.0, 1.0);
    } else if u > 1.0 {
        u = 1.0;
        s = ((bb - cc) / aa).clamp(0.0, 1.0);
    }
    (s, u)
}

/// The closest points of the two segments.
pub(super) fn closest_on_segments(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> (DVec3, DVec3) {
    let (s, u) = segment_weights(a, b, c, d);
    (a + (b - a) * s, c + (d - c) * u)
}

/// The times in `[0, 1]`, ascending, at which edges `a b` and `c d`, each corner moving
/// linearly from `p0` to `p1`, lie in one plane (their lines meet or are parallel): the roots
/// of the cubic `((b − a) × (d − c)) · (c − a)` (Bridson et al. 2002), each found by bisection
/// between its turning points.
pub(super) fn coplanar_times(p0: [DVec3; 4], p1: [DVec3; 4]) -> ([f64; 3], usize) {
    let [a, b, c, d] = p0;
    let [da, db, dc, dd] = [0, 1, 2, 3].map(|i| p1[i] - p0[i]);
    let (e1, f1, e2, f2, r, g) = (b - a, db - da, d - c, dd - dc, c - a, dc - da);
    let (m0, m1, m2) = (e1.cross(e2), e1.cross(f2) + f1.cross(e2), f1.cross(f2));
    let k = [
        m0.dot(r),
        m0.dot(g) + m1.dot(r),
        m1.dot(g) + m2.dot(r),
        m2.dot(g),
    ];
    let f = |t: f64| ((k[3] * t + k[2]) * t + k[1]) * t + k[0];
    // The turning points in (0, 1): the roots of 3 k3 t² + 2 k2 t + k1.
    let mut cuts = [0.0, 1.0, 1.0, 1.0];
    let (qa, qb, qc) = (3.0 * k[3], 2.0 * k[2], k[1]);
    let mut n = 1;
    let mut turn = |t: f64| {
        if t > 0.0 && t < 1.0 {
            cuts[n] = t;
            n += 1;
        }
    };
    if qa != 0.0 {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            // The root of the larger magnitude first, the other from their product.
            let big = -0.5 * (qb + qb.signum() * disc.sqrt());
            if big != 0.0 {
                turn(big / qa);
                turn(qc / big);
            }
        }
    } else if qb != 0.0 {
        turn(-qc / qb);
    }
    cuts[n] = 1.0;
    cuts[..=n].sort_unstable_by(f64::total_cmp);
    let (mut roots, mut count) = ([0.0; 3], 0);
    for w in cuts[..=n].windows(2) {
        let (mut lo, mut hi) = (w[0], w[1]);
        let (flo, fhi) = (f(lo), f(hi));
        if flo == 0.0 && (count == 0 || roots[count - 1] < lo) {
            roots[count] = lo;
            count += 1;
            continue;
        }
        if flo * fhi >= 0.0 || flo.is_nan() || fhi.is_nan() || count == 3 {
            continue;
        }
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if f(mid) * flo > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        roots[count] = 0.5 * (lo + hi);
        count += 1;
    }
    (roots, count)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collide::search::tests::crumpled;

    /// The search of the edges against every pair of edges tested by the pair's own test,
    /// the neighbours at rest from their rest places: the same candidates, each pair once,
    /// with the first test in single precision, also where its rounding is thousands of times
    /// the sheets' noise.
    #[test]
    fn the_edges_search_finds_what_every_pair_tested_finds() {
        for shift in [0.0, 1e3, -4e4] {
            let (mut stage, mut packed) = crumpled();
            packed.x.iter_mut().for_each(|x| *x += DVec3::splat(shift));
            stage.find_crossings(&packed).unwrap();
            let mut found: Vec<(u32, u32)> = stage.crossings.iter().map(|c| (c.a, c.b)).collect();
            let mut all = Vec::new();
            let rest = |k: u32| {
                stage.edges[k as usize]
                    .slots
                    .map(|s| stage.members[s as usize].2)
            };
            for s in 0..stage.edges.len() as u32 {
                for u in s + 1..stage.edges.len() as u32 {
                    let (e, f) = (stage.edges[s as usize], stage.edges[u as usize]);
                    let centres = [s, u].map(|k| stage.edge_centres[k as usize]);
                    if centres
                        .iter()
                        .any(|c| !(c.0.is_finite() && c.1.is_finite()))
                    {
                        continue;
                    }
                    let [a, b] = rest(s);
                    let [c, d] = rest(u);
                    let (p, q) = closest_on_segments(a, b, c, d);
                    let apart = 2.0 * stage.layers[e.layer as usize].thickness;
                    if e.layer == f.layer && (p - q).length() < apart {
                        continue;
                    }
                    let (x, inv) = (&packed.x, &packed.inv_mass);
                    if stage
                        .crossing(s, u, centres[0], centres[1], x, inv)
                        .is_some()
                    {
                        all.push((s, u));
                    }
                }
            }
            println!(
                "shifted {shift} m: {} found, {} by every pair",
                found.len(),
                all.len()
            );
            assert!(all.len() > 1000, "{}", all.len());
            found = found
                .into_iter()
                .map(|(a, b)| (a.min(b), a.max(b)))
                .collect();
            found.sort_unstable();
            let count = found.len();
            found.dedup();
            assert_eq!(found.len(), count, "a pair found twice");
            assert_eq!(found, all);
        }
    }

    /// The closest points against a brute-force search over both segments.
    #[test]
    fn the_closest_points_are_the_nearest_of_a_fine_search() {
        let mut r = super::super::uniform(11);
        for k in 0..300 {
            let v = |r: &mut dyn FnMut() -> f64| DVec3::new(r(), r(), r());
            let (a, b, c) = (v(&mut r), v(&mut r), v(&mut r));
            // Every tenth pair parallel, every thirteenth with a point for a segment.
            let d = match (k % 10, k % 13) {
                (0, _) => c + (b - a) * (0.5 + r()),
                (_, 0) => c,
                _ => v(&mut r),
            };
            let (p, q) = closest_on_segments(a, b, c, d);
            let n = 400;
            let mut best = f64::MAX;
            for i in 0..=n {
                let x = a + (b - a) * (i as f64 / n as f64);
                let (s, u) = segment_weights(x, x, c, d);
                assert_eq!(s, 0.0);
                best = best.min((x - (c + (d - c) * u)).length());
            }
            let dist = (p - q).length();
            assert!(dist <= best + 1e-12, "{k}: {dist} > search {best}");
            assert!(best - dist < 0.01, "{k}: {dist} far under search {best}");
        }
    }

    /// Edges that translate, and edges that turn: the times found against a fine scan of the
    /// cubic's sign.
    #[test]
    fn coplanar_times_are_the_cubics_roots() {
        let mut r = super::super::uniform(5);
        let mut found = 0;
        for _ in 0..500 {
            let mut v = || DVec3::new(r(), r(), r());
            let p0 = [v(), v(), v(), v()];
            let p1 = [0, 1, 2, 3].map(|i| p0[i] + v());
            let (roots, count) = coplanar_times(p0, p1);
            let at = |t: f64| {
                let q = [0, 1, 2, 3].map(|i| p0[i] + (p1[i] - p0[i]) * t);
                (q[1] - q[0]).cross(q[3] - q[2]).dot(q[2] - q[0])
            };
            let n = 20_000;
            let changes: Vec<f64> = (0..n)
                .filter(|&i| at(i as f64 / n as f64) * at((i + 1) as f64 / n as f64) < 0.0)
                .map(|i| (i as f64 + 0.5) / n as f64)
                .collect();
            assert_eq!(changes.len(), count, "{changes:?} against {roots:?}");
            for (c, r) in changes.iter().zip(&roots[..count]) {
                assert!((c - r).abs() <= 0.5 / n as f64, "{c} against {r}");
                assert!(at(*r).abs() < 1e-9, "{}", at(*r));
            }
            found += count;
        }
        assert!(found > 100, "{found}");
        // Translating edges that cross: one time, where the moving one's line meets the other's.
        let (roots, count) = coplanar_times(
            [
                DVec3::new(-1.0, 0.0, 0.0),
                DVec3::X,
                DVec3::new(0.0, 1.0, -1.0),
                DVec3::new(0.0, 1.0, 1.0),
            ],
            [
                DVec3::new(-1.0, 0.0, 0.0),
                DVec3::X,
                DVec3::new(0.0, -3.0, -1.0),
                DVec3::new(0.0, -3.0, 1.0),
            ],
        );
        assert_eq!(count, 1);
        assert!((roots[0] - 0.25).abs() < 1e-15, "{}", roots[0]);
    }

    #[test]
    fn crossing_lines_meet_at_their_parameters() {
        let (a, b) = (DVec3::new(-1.0, 0.0, 0.0), DVec3::new(3.0, 0.0, 0.0));
        let (c, d) = (DVec3::new(0.0, 1.0, -1.0), DVec3::new(0.0, 1.0, 1.0));
        let (s, u) = line_parameters(a, b, c, d).unwrap();
        assert!((s - 0.25).abs() < 1e-15 && (u - 0.5).abs() < 1e-15);
        assert!(line_parameters(a, b, c, c + (b - a)).is_none());
    }
}
