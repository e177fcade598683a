//! Finding the candidates: members and triangles sorted by a cell key, each cell's neighbours
//! found by cursors that only move on (no hashing, so one fixed order on any thread count);
//! and the closest-point queries they and the pass use.

use std::ops::Range;

use glam::DVec3;

use super::near::Near;
use super::neighbours::Neighbours;
use super::{contact, CollideStage, Face};
use crate::buffers::Packed;
use crate::error::GpuError;

/// The furthest cell from the origin a key tells apart, on each axis.
const SPAN: f64 = ((1 << 20) - 2) as f64;

/// The key of the cell of side `cell` holding `p`: each coordinate in its 21 bits (far cells
/// share the edge ones: the distance decides), so the keys sort as the cells do, a column's
/// cells in a row.
pub(super) fn key(p: DVec3, cell: f64) -> u64 {
    let c = (p / cell).floor();
    let f = |v: f64| (v.clamp(-SPAN, SPAN) as i64 + (1 << 20)) as u64;
    (f(c.x) << 42) | (f(c.y) << 21) | f(c.z)
}

/// For each run of one cell in `a` (sorted by key), `visit(run, near)` with the nine ranges
/// of `b` (sorted by key, keyed with the same cell) that hold the three cells of each column
/// beside it: together the 27 cells around the run's, in a fixed order.
pub(super) fn beside(
    a: &[(u64, u32)],
    b: &[(u64, u32)],
    mut visit: impl FnMut(&[(u64, u32)], &[Range<usize>; 9]),
) {
    let columns: [i64; 9] = std::array::from_fn(|j| {
        let (dx, dy) = (j as i64 / 3 - 1, j as i64 % 3 - 1);
        (dx << 42) + (dy << 21)
    });
    let (mut starts, mut ends) = ([0usize; 9], [0usize; 9]);
    let mut near: [Range<usize>; 9] = std::array::from_fn(|_| 0..0);
    let mut lo = 0;
    while lo < a.len() {
        let c = a[lo].0;
        let hi = lo + a[lo..].partition_point(|e| e.0 == c);
        for (j, &column) in columns.iter().enumerate() {
            let (from, to) = (
                (c as i64 + column - 1) as u64,
                (c as i64 + column + 1) as u64,
            );
            if lo == 0 {
                // The first run's: a part of `a` may start anywhere in `b`.
                starts[j] = b.partition_point(|e| e.0 < from);
            }
            while starts[j] < b.len() && b[starts[j]].0 < from {
                starts[j] += 1;
            }
            ends[j] = ends[j].max(starts[j]);
            while ends[j] < b.len() && b[ends[j]].0 <= to {
                ends[j] += 1;
            }
            near[j] = starts[j]..ends[j];
        }
        visit(&a[lo..hi], &near);
        lo = hi;
    }
}

impl CollideStage {
    pub(super) fn thickest(&self) -> f64 {
        self.layers.iter().map(|l| l.thickness).fold(0.0, f64::max)
    }

    /// The pair's thickness and friction: the means of the two layers'.
    pub(super) fn combine(&self, la: u16, lb: u16) -> (f64, contact::Friction) {
        let (pa, pb) = (self.layers[la as usize], self.layers[lb as usize]);
        let t = 0.5 * (pa.thickness + pb.thickness);
        let mu = 0.5 * (pa.kinetic_friction + pb.kinetic_friction);
        let mu_s = 0.5 * (pa.friction + pb.friction);
        (t, (mu, mu_s))
    }

    /// Particle against particle between layers without triangles.
    pub(super) fn find_pairs(&mut self, packed: &Packed) {
        self.pairs.clear();
        let (x, inv) = (&packed.x, &packed.inv_mass);
        let cell = self.thickest() + self.reach;
        self.cells.clear();
        self.cells.extend(
            (0u32..)
                .zip(&self.members)
                .filter(|(_, m)| !self.surfaced[m.1 as usize] && x[m.0 as usize].is_finite())
                .map(|(s, m)| (key(x[m.0 as usize], cell), s)),
        );
        if self.cells.is_empty() {
            return;
        }
        self.cells.sort_unstable();
        let mut pairs = std::mem::take(&mut self.pairs);
        beside(&self.cells, &self.cells, |run, near| {
            for &(_, s) in run {
                let (a, la, ra) = self.members[s as usize];
                for &(_, u) in near.iter().flat_map(|r| &self.cells[r.clone()]) {
                    let (b, lb, rb) = self.members[u as usize];
                    if b <= a {
                        continue;
                    }
                    let (t, friction) = self.combine(la, lb);
                    let reach = t + self.margin + self.swept[s as usize] + self.swept[u as usize];
                    if (x[b as usize] - x[a as usize]).length_squared() >= reach * reach
                        || inv[a as usize] + inv[b as usize] == 0.0
                    {
                        continue;
                    }
                    let near = 2.0 * self.layers[la as usize].thickness;
                    if la == lb && (rb - ra).length_squared() < near * near {
                        continue;
                    }
                    pairs.push((a, b, t, friction));
                }
            }
        });
        pairs.sort_unstable_by_key(|p| (p.0, p.1));
        self.pairs = pairs;
    }

    /// Particle against triangle: the triangles sorted by the cell of their centres (cells
    /// the largest thickness plus the reach plus the widest triangle's radius wide), the
    /// particles by theirs; a triangle not its particle's, within the reach of it, and not
    /// within twice the thickness of it at rest on one cloth.
    pub(super) fn find_faces(&mut self, packed: &Packed) -> Result<(), GpuError> {
        self.faces.clear();
        if self.triangles.is_empty() {
            return Ok(());
        }
        let (x, inv) = (&packed.x, &packed.inv_mass);
        self.centres.clear();
        let mut widest = 0.0f64;
        for t in &self.triangles {
            let (m, r) = sphere(t.at.map(|i| x[i as usize]));
            if r.is_finite() {
                widest = widest.max(r);
            }
            self.centres.push((m, r));
        }
        let cell = self.thickest() + self.reach + widest;
        self.cells.clear();
        self.cells.extend(
            (0u32..)
                .zip(&self.members)
                .filter(|(_, m)| x[m.0 as usize].is_finite())
                .map(|(s, m)| (key(x[m.0 as usize], cell), s)),
        );
        #[cfg(feature = "gpu")]
        if self.device.find.is_some() {
            return self.faces_on_device(packed, cell);
        }
        self.triangle_cells.clear();
        self.triangle_cells.extend(
            (0u32..)
                .zip(&self.centres)
                .filter(|(_, c)| c.1.is_finite())
                .map(|(k, c)| (key(c.0, cell), k)),
        );
        use rayon::prelude::*;
        self.cells.par_sort_unstable();
        self.triangle_cells.par_sort_unstable();
        // The centres beside their keys, so the search reads them in order, each radius
        // with its triangle's largest `swept` added (what the pair's reach adds for it).
        let sorted = self.triangle_cells.iter().map(|&(_, k)| {
            let (m, r) = self.centres[k as usize];
            let tri = &self.triangles[k as usize];
            let swept = tri.slots.map(|s| self.swept[s as usize]);
            (m, r + swept[0].max(swept[1]).max(swept[2]), k, tri.layer)
        });
        let mut near: Near = std::mem::take(&mut self.near);
        near.fill(sorted, self.members.iter().map(|m| x[m.0 as usize]));
        self.near = near;
        // The particles' cells in runs of whole cells, searched side by side into buffers
        // kept between finds, then joined in the cells' order: the split does not change them.
        let mut runs = std::mem::take(&mut self.runs);
        split_runs(&self.cells, 4 * rayon::current_num_threads(), &mut runs);
        let mut found = std::mem::take(&mut self.found);
        found.resize_with(runs.len(), Vec::new);
        (found.par_iter_mut().zip(&runs)).for_each(|(out, r)| {
            out.clear();
            self.faces_of(&self.cells[r.clone()], x, inv, out);
        });
        for f in &found[..runs.len()] {
            self.faces.extend_from_slice(f);
        }
        (self.runs, self.found) = (runs, found);
        Ok(())
    }

    /// The candidates of the particles of `cells` (whole runs of cells) against the
    /// triangles.
    fn faces_of(&self, cells: &[(u64, u32)], x: &[DVec3], inv: &[f64], faces: &mut Vec<Face>) {
        let own = self.thickest() + self.margin;
        beside(cells, &self.triangle_cells, |run, near| {
            for &(_, s) in run {
                let (p, lp, _) = self.members[s as usize];
                let xp = x[p as usize];
                // The pair's reach with the thickest layer's thickness: at least the pair's
                // (a hair over, so rounding never turns away what `face` would take).
                let reach = (own + self.swept[s as usize]) * (1.0 + 1e-12);
                let mut hit = |i: usize| {
                    // Within that reach of the centre (from the sorted copy), and not a
                    // neighbour at rest, first.
                    let (k, layer) = (self.near.item[i], self.near.layer[i]);
                    if layer == lp && self.excluded.contains(s, k) {
                        return;
                    }
                    let centre = self.centres[k as usize];
                    if let Some(face) = self.face(s, k, centre, x, inv) {
                        faces.push(face);
                    }
                };
                for r in near {
                    self.near.within(r.clone(), xp, reach, &mut hit);
                }
            }
        });
    }

    /// Member `s` against triangle `k` (centre and radius `m`, `r`), past the widest reach's
    /// test and the neighbours at rest: a candidate if not its own, within the pair's reach of
    /// its centre and then of its closest point, and not all held.
    #[inline]
    pub(super) fn face(
        &self,
        s: u32,
        k: u32,
        (m, r): (DVec3, f64),
        x: &[DVec3],
        inv: &[f64],
    ) -> Option<Face> {
        let (p, lp, _) = self.members[s as usize];
        let xp = x[p as usize];
        let tri = self.triangles[k as usize];
        if tri.at.contains(&p) {
            return None;
        }
        let (t, friction) = self.combine(lp, tri.layer);
        let swept = tri.slots.map(|s| self.swept[s as usize]);
        let reach = t + self.margin + self.swept[s as usize] + swept[0].max(swept[1]).max(swept[2]);
        if (xp - m).length_squared() >= (reach + r) * (reach + r) {
            return None;
        }
        let [a, b, c] = tri.at.map(|i| x[i as usize]);
        let w = closest_on_triangle(xp, a, b, c);
        let q = a * w[0] + b * w[1] + c * w[2];
        let held = tri.at.iter().all(|&i| inv[i as usize] == 0.0);
        if (xp - q).length_squared() >= reach * reach || (held && inv[p as usize] == 0.0) {
            return None;
        }
        Some(Face {
            p,
            triangle: k,
            thickness: t,
            friction,
        })
    }

    /// Each member's triangles of its own layer within twice its thickness at rest (its own
    /// among them): the neighbours along the cloth, which never collide. Found once, from the
    /// rest places, sorted by triangle for each member.
    pub(super) fn find_excluded(&mut self) {
        let rest: Vec<(DVec3, f64)> = (self.triangles.iter())
            .map(|t| sphere(t.slots.map(|s| self.members[s as usize].2)))
            .collect();
        let near = 2.0 * self.thickest();
        let widest = rest.iter().map(|r| r.1).fold(0.0, f64::max);
        let cell = near + widest;
        if self.triangles.is_empty() || !(cell.is_finite() && cell > 0.0) {
            self.excluded = Neighbours::new(&mut [], self.members.len());
            return;
        }
        let mut members: Vec<(u64, u32)> = (0u32..)
            .zip(&self.members)
            .filter(|(_, m)| m.2.is_finite())
            .map(|(s, m)| (key(m.2, cell), s))
            .collect();
        let mut triangles: Vec<(u64, u32)> = (0u32..)
            .zip(&rest)
            .filter(|(_, r)| r.1.is_finite())
            .map(|(k, r)| (key(r.0, cell), k))
            .collect();
        members.sort_unstable();
        triangles.sort_unstable();
        let mut pairs = Vec::new();
        beside(&members, &triangles, |run, near| {
            for &(_, s) in run {
                let (_, lp, rp) = self.members[s as usize];
                for &(_, k) in near.iter().flat_map(|r| &triangles[r.clone()]) {
                    let tri = self.triangles[k as usize];
                    if tri.layer != lp {
                        continue;
                    }
                    // Within twice the layer's thickness of the triangle at rest.
                    let near = 2.0 * self.layers[lp as usize].thickness;
                    let (m, r) = rest[k as usize];
                    if (rp - m).length_squared() >= (near + r) * (near + r) {
                        continue;
                    }
                    let [a, b, c] = tri.slots.map(|s| self.members[s as usize].2);
                    let w = closest_on_triangle(rp, a, b, c);
                    if (rp - (a * w[0] + b * w[1] + c * w[2])).length_squared() < near * near {
                        pairs.push((s, k));
                    }
                }
            }
        });
        self.excluded = Neighbours::new(&mut pairs, self.members.len());
    }
}

/// A triangle's centre and the radius about it that holds its corners; the radius not finite
/// where a corner is not (such a triangle is the quarantine's, never a candidate).
pub(super) fn sphere(corners: [DVec3; 3]) -> (DVec3, f64) {
    let m = (corners[0] + corners[1] + corners[2]) / 3.0;
    if !m.is_finite() {
        return (m, f64::NAN);
    }
    let r = (corners.iter())
        .map(|c| (*c - m).length_squared())
        .fold(0.0, f64::max)
        .sqrt();
    (m, r)
}

/// `cells` (sorted) cut into about `parts` ranges of whole runs of one key, into `out`.
pub(super) fn split_runs(cells: &[(u64, u32)], parts: usize, out: &mut Vec<Range<usize>>) {
    out.clear();
    let mut from = 0;
    for k in 1..=parts {
        let mut to = (cells.len() * k / parts).max(from);
        while to < cells.len() && to > 0 && cells[to].0 == cells[to - 1].0 {
            to += 1;
        }
        if to > from {
            out.push(from..to);
            from = to;
        }
    }
}

/// The barycentric weights of the point of triangle `(a, b, c)` closest to `p` (Ericson,
/// *Real-Time Collision Detection*, 5.1.5): by the Voronoi region of `p`, the vertex, edge or
/// face. A degenerate triangle gives its nearest vertex or edge point.
pub(crate) fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> [f64; 3] {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let sum = va + vb + vc;
    if sum.is_nan() || sum <= 0.0 {
        // Degenerate (collinear) and past every test above: the nearer of a's edges.
        return [1.0, 0.0, 0.0];
    }
    let (v, w) = (vb / sum, vc / sum);
    [1.0 - v - w, v, w]
}

/// The barycentric weights of `p`'s projection onto the plane of triangle `(a, b, c)`,
/// unclamped (outside the triangle some are negative); `None` for a degenerate triangle.
pub(crate) fn plane_weights(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> Option<[f64; 3]> {
    let n = (b - a).cross(c - a);
    let nn = n.length_squared();
    if nn.is_nan() || nn <= 0.0 {
        return None;
    }
    let v = (p - a).cross(c - a).dot(n) / nn;
    let w = (b - a).cross(p - a).dot(n) / nn;
    Some([1.0 - v - w, v, w])
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::collide::{SelfCollision, Triangle};

    /// The triangles of an `n` by `n` sheet of members from `first` (slots and packed
    /// indices alike), two a cell.
    pub(in crate::collide) fn grid_triangles(
        stage: &mut CollideStage,
        first: u32,
        n: usize,
        layer: u16,
    ) {
        let id = |i: usize, j: usize| first + (i * n + j) as u32;
        for i in 0..n - 1 {
            for j in 0..n - 1 {
                for at in [
                    [id(i, j), id(i + 1, j), id(i + 1, j + 1)],
                    [id(i, j), id(i + 1, j + 1), id(i, j + 1)],
                ] {
                    let slots = at;
                    (stage.triangles).push(Triangle { at, slots, layer });
                }
            }
        }
    }

    /// Whether member `s` and triangle `k` are of one layer and closer at rest than twice its
    /// thickness (neighbours along the cloth, which never collide), by the closest point.
    pub(in crate::collide) fn neighbours_at_rest(stage: &CollideStage, s: u32, k: u32) -> bool {
        let (_, lp, rp) = stage.members[s as usize];
        let tri = &stage.triangles[k as usize];
        let [a, b, c] = tri.slots.map(|s| stage.members[s as usize].2);
        let w = closest_on_triangle(rp, a, b, c);
        let near = 2.0 * stage.layers[lp as usize].thickness;
        tri.layer == lp && (rp - (a * w[0] + b * w[1] + c * w[2])).length() < near
    }

    /// The places' and velocities' bits, to compare two runs.
    pub(in crate::collide) fn bits(packed: &Packed) -> Vec<[u64; 6]> {
        (packed.x.iter().zip(&packed.v))
            .map(|(x, v)| {
                let [a, b, c] = x.to_array().map(f64::to_bits);
                let [d, e, f] = v.to_array().map(f64::to_bits);
                [a, b, c, d, e, f]
            })
            .collect()
    }

    /// Two crumpled sheets of different thicknesses, one folded onto itself and the other
    /// through it, with noise, held corners, per-member sweeps and a member gone non-finite.
    pub(in crate::collide) fn crumpled() -> (CollideStage, Packed) {
        let mut stage = CollideStage::default();
        let mut r = super::super::uniform(11);
        let (n, spacing) = (24usize, 0.02);
        let length = spacing * (n - 1) as f64;
        let (mut x, mut inv) = (Vec::new(), Vec::new());
        for (layer, thickness) in [0.008, 0.012].into_iter().enumerate() {
            stage.layers.push(SelfCollision {
                thickness,
                friction: 0.5 + 0.2 * layer as f64,
                kinetic_friction: 0.3,
                edges: true,
            });
            stage.surfaced.push(true);
            let first = x.len() as u32;
            for i in 0..n {
                for j in 0..n {
                    let (a, b) = (i as f64 * spacing, j as f64 * spacing);
                    let rest = DVec3::new(a, 0.0, b);
                    let p = if layer == 0 {
                        // Folded in half along x, the halves 12 mm apart, wavy.
                        let side = if a < 0.5 * length { -1.0 } else { 1.0 };
                        DVec3::new(
                            0.5 * length - (a - 0.5 * length).abs(),
                            0.006 * side + 0.01 * (9.0 * b).sin(),
                            b,
                        )
                    } else {
                        // Flat, turned, through the fold.
                        let (c, s) = (0.5f64.cos(), 0.5f64.sin());
                        DVec3::new(c * a - s * b + 0.1, 0.004 + 0.02 * b, s * a + c * b - 0.1)
                    };
                    let noise = DVec3::new(r(), r(), r()) * 0.003;
                    stage
                        .members
                        .push((first + (i * n + j) as u32, layer as u16, rest));
                    x.push(p + noise);
                    inv.push(if i == 0 && j < 4 { 0.0 } else { 1.0 });
                }
            }
            grid_triangles(&mut stage, first, n, layer as u16);
        }
        stage.find_excluded();
        stage.gather_edges();
        stage.margin = 0.008;
        stage.swept = (0..x.len()).map(|_| 0.002 * (1.0 + r())).collect();
        stage.reach = stage.margin + 2.0 * stage.swept.iter().copied().fold(0.0, f64::max);
        x[17] = DVec3::NAN;
        let packed = Packed {
            x,
            inv_mass: inv,
            ..Default::default()
        };
        (stage, packed)
    }

    /// The search against every member tested with every triangle by the pair's own test,
    /// the neighbours at rest from their rest places: the same candidates, with the search's
    /// first test in single precision, its neighbours as bits, and at scales where single
    /// precision's rounding is thousands of times the sheets' noise.
    #[test]
    fn the_search_finds_what_every_pair_tested_finds() {
        for shift in [0.0, 1e3, -4e4] {
            let (mut stage, mut packed) = crumpled();
            packed.x.iter_mut().for_each(|x| *x += DVec3::splat(shift));
            stage.find_faces(&packed).unwrap();
            let found: Vec<(u32, u32)> = stage.faces.iter().map(|f| (f.p, f.triangle)).collect();
            let mut all = Vec::new();
            for (s, &(p, _, _)) in (0u32..).zip(&stage.members) {
                for k in 0..stage.triangles.len() as u32 {
                    // A particle or triangle gone non-finite is the quarantine's, never a
                    // candidate.
                    let centre = stage.centres[k as usize];
                    let finite = packed.x[p as usize].is_finite() && centre.1.is_finite();
                    if neighbours_at_rest(&stage, s, k) || !finite {
                        continue;
                    }
                    if stage
                        .face(s, k, centre, &packed.x, &packed.inv_mass)
                        .is_some()
                    {
                        all.push((p, k));
                    }
                }
            }
            println!(
                "shifted {shift} m: {} found, {} by every pair",
                found.len(),
                all.len()
            );
            assert!(all.len() > 1000, "{}", all.len());
            let mut sorted = found.clone();
            sorted.sort_unstable();
            sorted.dedup();
            assert_eq!(sorted.len(), found.len(), "a pair found twice");
            all.sort_unstable();
            assert_eq!(sorted, all);
        }
    }

    /// The closest point against a brute-force search over a fine barycentric lattice.
    #[test]
    fn the_closest_point_is_the_lattices_nearest() {
        let mut r = super::super::uniform(7);
        for _ in 0..200 {
            let v = |r: &mut dyn FnMut() -> f64| DVec3::new(r(), r(), r());
            let (a, b, c, p) = (v(&mut r), v(&mut r), v(&mut r), v(&mut r) * 1.5);
            let w = closest_on_triangle(p, a, b, c);
            assert!(
                w.iter().all(|&w| (-1e-12..=1.0 + 1e-12).contains(&w)),
                "{w:?}"
            );
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            let q = a * w[0] + b * w[1] + c * w[2];
            let n = 200;
            let mut best = f64::MAX;
            for i in 0..=n {
                for j in 0..=n - i {
                    let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                    let s = a * (1.0 - u - v) + b * u + c * v;
                    best = best.min((p - s).length());
                }
            }
            let d = (p - q).length();
            assert!(d <= best + 1e-12, "{d} > lattice {best}");
            assert!(best - d < 0.02, "{d} far under lattice {best}");
        }
    }

    #[test]
    fn plane_weights_give_back_the_point_in_the_plane() {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Z);
        let w = plane_weights(DVec3::new(0.25, 3.0, 0.5), a, b, c).unwrap();
        assert!((w[0] - 0.25).abs() < 1e-15 && (w[1] - 0.25).abs() < 1e-15);
        assert!((w[2] - 0.5).abs() < 1e-15);
        assert!(plane_weights(DVec3::ONE, a, a, c).is_none());
    }
}
