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
    let boxes: Vec<(DVec3, DVec3, usize)> = (triangles.iter().enumerate())
        .map(|(k, t)| {
            let c = t.map(|i| x[i as usize]);
            (c[0].min(c[1]).min(c[2]), c[0].max(c[1]).max(c[2]), k)
        })
        .collect();
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_by(|&i, &j| boxes[i].0.x.total_cmp(&boxes[j].0.x));
    let mut count = 0;
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
                count += 1;
            }
        }
    }
    count
}
