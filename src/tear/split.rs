//! The surface along a tear: which triangles a break drops, and which vertices it splits.
//!
//! Around a vertex, two of its triangles hold together where they share an edge that no break
//! has cut. A vertex whose triangles fall in more than one such piece is split: the piece with
//! the lowest triangle keeps it, each other piece gets a copy of it (a new particle), so the
//! render mesh opens along the tear and every triangle stays. A triangle with a broken edge
//! whose two other edges are not both springs (nothing holds its corners together any more)
//! is dropped.

use std::collections::{BTreeSet, HashMap, HashSet};

use glam::DVec3;

/// An edge as its ends (vertices of one surface), the lower first.
pub(crate) type Edge = (u32, u32);

pub(crate) fn edge(a: u32, b: u32) -> Edge {
    (a.min(b), a.max(b))
}

fn edges([a, b, c]: [u32; 3]) -> [Edge; 3] {
    [edge(a, b), edge(b, c), edge(c, a)]
}

/// A split vertex: its pieces, each a vertex (the first the original, the others new) and
/// the triangles (indices) that now use it.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Fan {
    pub(crate) pieces: Vec<(u32, Vec<usize>)>,
}

impl Fan {
    pub(crate) fn vertex(&self) -> u32 {
        self.pieces[0].0
    }
}

/// Drops the triangles with an edge in `broken` that are no longer held by springs on two
/// of their edges (`sprung`: the edges with a spring left); their corners go into `touched`.
pub(crate) fn drop_loose(
    triangles: &mut Vec<[u32; 3]>,
    broken: &HashSet<Edge>,
    sprung: &HashSet<Edge>,
    touched: &mut BTreeSet<u32>,
) {
    triangles.retain(|&t| {
        let e = edges(t);
        let loose = e.iter().any(|e| broken.contains(e))
            && e.iter().filter(|e| sprung.contains(e)).count() < 2;
        if loose {
            touched.extend(t);
        }
        !loose
    });
}

/// Splits every vertex of `at` (in order) whose triangles fall in more than one piece across
/// the edges they share outside `cut`; the new vertices are numbered from `next` on, in order,
/// and put in their pieces' triangles.
pub(crate) fn split(
    triangles: &mut [[u32; 3]],
    cut: &HashSet<Edge>,
    at: &BTreeSet<u32>,
    mut next: u32,
) -> Vec<Fan> {
    let mut around: HashMap<u32, Vec<usize>> = HashMap::new();
    for (k, t) in triangles.iter().enumerate() {
        for v in t.iter().filter(|v| at.contains(v)) {
            around.entry(*v).or_default().push(k);
        }
    }
    let mut fans = Vec::new();
    for &v in at {
        let Some(fan) = around.get(&v) else { continue };
        // Union–find over the fan (a handful of triangles), each root its lowest triangle.
        let mut root: Vec<usize> = (0..fan.len()).collect();
        fn find(root: &mut [usize], mut i: usize) -> usize {
            while root[i] != i {
                root[i] = root[root[i]];
                i = root[i];
            }
            i
        }
        for i in 0..fan.len() {
            for j in i + 1..fan.len() {
                let (s, t) = (triangles[fan[i]], triangles[fan[j]]);
                let joined = s
                    .iter()
                    .any(|&r| r != v && t.contains(&r) && !cut.contains(&edge(v, r)));
                if joined {
                    let (a, b) = (find(&mut root, i), find(&mut root, j));
                    root[a.max(b)] = a.min(b);
                }
            }
        }
        let mut pieces: Vec<(u32, Vec<usize>)> = Vec::new();
        let mut piece_of: HashMap<usize, usize> = HashMap::new();
        for (i, &k) in fan.iter().enumerate() {
            let r = find(&mut root, i);
            let p = *piece_of.entry(r).or_insert_with(|| {
                pieces.push((0, Vec::new()));
                pieces.len() - 1
            });
            pieces[p].1.push(k);
        }
        if pieces.len() < 2 {
            continue;
        }
        pieces[0].0 = v;
        for piece in &mut pieces[1..] {
            piece.0 = next;
            for &k in &piece.1 {
                for c in &mut triangles[k] {
                    if *c == v {
                        *c = next;
                    }
                }
            }
            next += 1;
        }
        fans.push(Fan { pieces });
    }
    fans
}

/// The edges of `cut` still shared by two triangles (the others have opened or gone).
pub(crate) fn still_shared(triangles: &[[u32; 3]], cut: &HashSet<Edge>) -> Vec<Edge> {
    let mut count: HashMap<Edge, u32> = HashMap::new();
    for e in triangles.iter().flat_map(|&t| edges(t)) {
        if cut.contains(&e) {
            *count.entry(e).or_default() += 1;
        }
    }
    let mut shared: Vec<Edge> = (count.into_iter())
        .filter(|&(_, n)| n >= 2)
        .map(|(e, _)| e)
        .collect();
    shared.sort_unstable();
    shared
}

/// Which copies of its ends a spring between `a` and `b` holds after `fans` split them
/// (`fan_of` gives a split vertex's fan): along an edge, the copies that share a triangle;
/// otherwise, for each split end, the piece whose triangles' centres are nearest the other
/// end (`x`: a vertex's position; copies stand where their vertex does).
pub(crate) fn ends(
    triangles: &[[u32; 3]],
    fan_of: &impl Fn(u32) -> Option<usize>,
    fans: &[Fan],
    (a, b): (u32, u32),
    x: &impl Fn(u32) -> DVec3,
) -> (u32, u32) {
    let copies = |v: u32| -> Vec<u32> {
        fan_of(v).map_or(vec![v], |f| fans[f].pieces.iter().map(|p| p.0).collect())
    };
    let (ca, cb) = (copies(a), copies(b));
    // A triangle with both ends holds a copy of a split end: it is in that end's fan.
    let fan = fan_of(a).or_else(|| fan_of(b)).map(|f| &fans[f]);
    let mut near: Vec<usize> = (fan.iter())
        .flat_map(|f| f.pieces.iter().flat_map(|p| p.1.iter().copied()))
        .collect();
    near.sort_unstable();
    for t in near.into_iter().map(|k| &triangles[k]) {
        let (pa, pb) = (
            ca.iter().find(|v| t.contains(v)),
            cb.iter().find(|v| t.contains(v)),
        );
        if let (Some(&pa), Some(&pb)) = (pa, pb) {
            return (pa, pb);
        }
    }
    let nearest = |v: u32, to: DVec3| -> u32 {
        let Some(f) = fan_of(v) else { return v };
        let far = |piece: &(u32, Vec<usize>)| {
            (piece.1.iter())
                .map(|&k| triangles[k].map(x).iter().sum::<DVec3>() / 3.0)
                .map(|c| c.distance_squared(to))
                .fold(f64::INFINITY, f64::min)
        };
        let pieces = &fans[f].pieces;
        (pieces.iter())
            .min_by(|p, q| far(p).total_cmp(&far(q)))
            .map_or(v, |p| p.0)
    };
    (nearest(a, x(b)), nearest(b, x(a)))
}

/// Each piece's share of its vertex's mass: its triangles' area over the fan's (equal shares
/// where the fan has no area).
pub(crate) fn shares(triangles: &[[u32; 3]], fan: &Fan, x: &impl Fn(u32) -> DVec3) -> Vec<f64> {
    let area = |k: usize| {
        let [p, q, r] = triangles[k].map(x);
        0.5 * (q - p).cross(r - p).length()
    };
    let areas: Vec<f64> = (fan.pieces.iter())
        .map(|p| p.1.iter().map(|&k| area(k)).sum())
        .collect();
    let total: f64 = areas.iter().sum();
    if total > 0.0 && total.is_finite() {
        areas.iter().map(|a| a / total).collect()
    } else {
        vec![1.0 / areas.len() as f64; areas.len()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 3×3 grid of vertices `3 r + c`, two triangles a cell, diagonal from (r, c) to
    /// (r + 1, c + 1): vertex 4 is interior with six triangles.
    fn grid() -> Vec<[u32; 3]> {
        let mut t = Vec::new();
        for r in 0..2 {
            for c in 0..2 {
                let v = 3 * r + c;
                t.push([v, v + 1, v + 4]);
                t.push([v, v + 4, v + 3]);
            }
        }
        t
    }

    /// Where the grid's vertex stands, the middle column's copies (9, 10, 11 after the tear
    /// down it) with their originals.
    fn place(v: u32) -> DVec3 {
        let v = match v {
            9 => 1,
            10 => 4,
            11 => 7,
            v => v,
        };
        DVec3::new((v % 3) as f64, -((v / 3) as f64), 0.0)
    }

    fn set(e: &[Edge]) -> HashSet<Edge> {
        e.iter().copied().collect()
    }

    #[test]
    fn one_cut_leaves_an_interior_fan_whole_and_two_split_it() {
        let mut t = grid();
        // Vertex 4 is interior: one cut leaves its six triangles joined round the other side.
        assert!(split(&mut t, &set(&[(1, 4)]), &[4].into(), 9).is_empty());
        assert_eq!(t, grid());
        // 1–4 then 4–7: the tear runs down the middle column from the top edge to the bottom.
        let at: BTreeSet<u32> = [1, 4, 7].into();
        let fans = split(&mut t, &set(&[(1, 4), (4, 7)]), &at, 9);
        let split_at: Vec<u32> = fans.iter().map(Fan::vertex).collect();
        assert_eq!(split_at, [1, 4, 7], "{fans:?}");
        assert_eq!(
            fans.iter().map(|f| f.pieces[1].0).collect::<Vec<_>>(),
            [9, 10, 11]
        );
        // The middle column's three vertices are in two copies each now.
        assert_eq!(t.len(), 8);
        let corners: HashSet<u32> = t.iter().flatten().copied().collect();
        assert_eq!(corners.len(), 12, "{t:?}");
        // Every triangle kept its area's vertices at the same places: each corner of a new
        // number stands for 1, 4 or 7.
        let old = grid();
        for (n, o) in t.iter().zip(&old) {
            for (a, b) in n.iter().zip(o) {
                assert!(a == b || (*a >= 9 && [1, 4, 7].contains(b)), "{n:?} {o:?}");
            }
        }
        // The cut edges now border one triangle each.
        assert!(still_shared(&t, &set(&[(1, 4), (4, 7)])).is_empty());
    }

    #[test]
    fn a_boundary_vertex_splits_at_one_cut() {
        let mut t = grid();
        // Vertex 1 (top edge) has triangles 0 [0, 1, 4], 2 [1, 2, 5] and 3 [1, 5, 4].
        let fans = split(&mut t, &set(&[(1, 4)]), &[1].into(), 9);
        assert_eq!(fans.len(), 1);
        assert_eq!(fans[0].pieces, vec![(1, vec![0]), (9, vec![2, 3])]);
        assert_eq!(t[2], [9, 2, 5]);
        assert_eq!(t[3], [9, 5, 4]);
        assert_eq!(still_shared(&t, &set(&[(1, 4)])), Vec::<Edge>::new());
    }

    #[test]
    fn a_triangle_held_by_one_spring_is_dropped() {
        let mut t = vec![[0, 1, 2], [1, 3, 2]];
        let mut touched = BTreeSet::new();
        // 0–1 broke; 1–2 and 2–0 hold the first triangle: it stays.
        let sprung = set(&[(1, 2), (0, 2), (1, 3), (2, 3)]);
        drop_loose(&mut t, &set(&[(0, 1)]), &sprung, &mut touched);
        assert_eq!(t.len(), 2);
        // 0–2 broke too: only 1–2 is left on it.
        let sprung = set(&[(1, 2), (1, 3), (2, 3)]);
        drop_loose(&mut t, &set(&[(0, 2)]), &sprung, &mut touched);
        assert_eq!(t, [[1, 3, 2]]);
        assert_eq!(touched, [0, 1, 2].into());
    }

    #[test]
    fn springs_follow_their_triangles_or_the_nearest_piece() {
        let mut t = grid();
        let fans = split(&mut t, &set(&[(1, 4), (4, 7)]), &[1, 4, 7].into(), 9);
        let fan_of = |v: u32| fans.iter().position(|f| f.vertex() == v);
        let x = place;
        let ends = |a, b| ends(&t, &fan_of, &fans, (a, b), &x);
        // Structural springs along edges go with their triangles' copies.
        let (l, r) = (ends(3, 4), ends(4, 5));
        assert!(l.0 == 3 && r.1 == 5, "{l:?} {r:?}");
        assert_ne!(l.1, r.0, "the two sides hold different copies of 4");
        // A bend spring 3–5 across the tear has no split end; 0–4, a diagonal edge, follows
        // its triangle.
        assert_eq!(ends(3, 5), (3, 5));
        let d = ends(0, 4);
        assert!(t.iter().any(|t| t.contains(&d.0) && t.contains(&d.1)));
        // 4 to 6 is no edge (the other diagonal): the piece nearest 6 (the left) takes it.
        assert_eq!(ends(4, 6).0, l.1);
    }

    #[test]
    fn mass_shares_follow_the_pieces_areas() {
        let mut t = grid();
        let fans = split(&mut t, &set(&[(1, 4), (4, 7)]), &[1, 4, 7].into(), 9);
        let x = place;
        let centre = &fans[1];
        let s = shares(&t, centre, &x);
        assert_eq!(s.len(), 2);
        assert!((s.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        // Vertex 4's triangles: 3 left of the tear, 3 right, each of area ½.
        assert!((s[0] - 0.5).abs() < 1e-15, "{s:?}");
    }
}
