//! An exact count of crossing triangles, independent of the engine's own queries: two
//! triangles that share no corner intersect when an edge of one passes through the other
//! (the ends of the segment two non-coplanar triangles meet along lie on such edges).

use harmonic::prelude::DVec3;

/// The sign of the volume of tetrahedron `(a, b, c, d)`.
fn orient(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> f64 {
    (b - a).cross(c - a).dot(d - a)
}

/// Whether segment `p q` passes through triangle `t` (its ends strictly either side of the
/// plane, the line within the triangle's edges or on one).
fn segment_crosses(p: DVec3, q: DVec3, t: [DVec3; 3]) -> bool {
    let (sp, sq) = (orient(t[0], t[1], t[2], p), orient(t[0], t[1], t[2], q));
    if sp * sq >= 0.0 || sp.is_nan() || sq.is_nan() {
        return false;
    }
    let e = [
        orient(p, q, t[0], t[1]),
        orient(p, q, t[1], t[2]),
        orient(p, q, t[2], t[0]),
    ];
    e.iter().all(|&s| s >= 0.0) || e.iter().all(|&s| s <= 0.0)
}

/// Whether triangles `a` and `b` intersect (coplanar contact is not counted).
pub fn triangles_cross(a: [DVec3; 3], b: [DVec3; 3]) -> bool {
    (0..3).any(|i| segment_crosses(a[i], a[(i + 1) % 3], b))
        || (0..3).any(|i| segment_crosses(b[i], b[(i + 1) % 3], a))
}

/// The pairs of `triangles` (indices into `x`) sharing no corner that intersect: a sweep
/// over their bounding boxes sorted along x, then the exact test.
pub fn crossing_pairs(x: &[DVec3], triangles: &[[u32; 3]]) -> usize {
    crossing_list(x, triangles).len()
}

/// Those pairs, as indices into `triangles`.
pub fn crossing_list(x: &[DVec3], triangles: &[[u32; 3]]) -> Vec<(usize, usize)> {
    let boxes: Vec<(DVec3, DVec3, usize)> = (triangles.iter().enumerate())
        .map(|(k, t)| {
            let c = t.map(|i| x[i as usize]);
            (c[0].min(c[1]).min(c[2]), c[0].max(c[1]).max(c[2]), k)
        })
        .collect();
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_by(|&i, &j| boxes[i].0.x.total_cmp(&boxes[j].0.x));
    let mut out = Vec::new();
    for (n, &i) in order.iter().enumerate() {
        let (lo, hi, ki) = boxes[i];
        for &j in &order[n + 1..] {
            let (lo2, hi2, kj) = boxes[j];
            if lo2.x > hi.x {
                break;
            }
            if lo2.y > hi.y || lo.y > hi2.y || lo2.z > hi.z || lo.z > hi2.z {
                continue;
            }
            let (ta, tb) = (triangles[ki], triangles[kj]);
            if ta.iter().any(|v| tb.contains(v)) {
                continue;
            }
            if triangles_cross(ta.map(|v| x[v as usize]), tb.map(|v| x[v as usize])) {
                out.push((ki.min(kj), ki.max(kj)));
            }
        }
    }
    out
}

/// The distance from `p` to the segment `a b`.
pub fn to_segment(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let s = if ab.length_squared() > 0.0 {
        ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * s)).length()
}

/// The distance from `p` to triangle `t`: to its plane where `p` projects inside it (all three
/// edge tests on one side), else to its nearest edge.
pub fn to_triangle(p: DVec3, t: [DVec3; 3]) -> f64 {
    let n = (t[1] - t[0]).cross(t[2] - t[0]);
    let edges = (0..3).map(|i| to_segment(p, t[i], t[(i + 1) % 3]));
    let nearest = edges.fold(f64::MAX, f64::min);
    if n.length_squared() == 0.0 {
        return nearest;
    }
    let inside = (0..3).all(|i| (t[(i + 1) % 3] - t[i]).cross(p - t[i]).dot(n) >= 0.0);
    if inside {
        (p - t[0]).dot(n).abs() / n.length()
    } else {
        nearest
    }
}

/// Whether triangles `a` and `b` are apart along the cloth at `rest`: no corner of one within
/// `apart` of the other there (the self-collision stage leaves pairs nearer at rest than twice
/// the thickness to the springs).
pub fn apart_at_rest(rest: &[DVec3], a: [u32; 3], b: [u32; 3], apart: f64) -> bool {
    let corners = |t: [u32; 3]| t.map(|v| rest[v as usize]);
    let (ta, tb) = (corners(a), corners(b));
    ta.iter().all(|&p| to_triangle(p, tb) >= apart)
        && tb.iter().all(|&p| to_triangle(p, ta) >= apart)
}
