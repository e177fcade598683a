// Self-collision's candidates on the device: the twin of `find_faces` in src/collide/search.rs
// (particles against triangles) and of `find_crossings` in src/collide/edges.rs (edges against
// edges). The items (triangles, or edges) are sorted into hashed cells by a counting sort
// (integer atomics count, a scan places, atomics scatter, then each bucket is put in item
// order, so the atomics' order never shows); each query (a member, or an edge) then scans the
// 27 cells around its own for items within its reach, counting in one pass and writing in a
// second at its place from a scan of the counts: each query's list in the same order on every
// run. The tests are the CPU's with a slack that covers f32's rounding, so the lists hold the
// CPU's candidates; the host tests each again in f64 and orders them as the CPU does
// (src/collide/device.rs). Host side: src/gpu/collide.rs.

struct Find {
    // Cells' side, the widest reach past a pair's thickness (the CPU's `thickest + reach`),
    // the slack every distance test adds, the margin.
    cell: f32,
    reach_max: f32,
    slack: f32,
    margin: f32,
    members: u32,
    // Items: triangles, or edges (their third corner NONE).
    triangles: u32,
    // Hash buckets, a power of two.
    buckets: u32,
    // Room in `list`.
    capacity: u32,
    // Where each part of `topo` starts.
    tris_at: u32,
    excluded_at: u32,
    thickness_at: u32,
    flags_at: u32,
    // Queries: the members, or the edges.
    queries: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// A triangle's centre and the radius about it that holds its corners; its cell and bucket
// (bucket NONE where not finite).
struct Centre {
    m: vec4<f32>,
    cell: vec4<i32>,
}

const NONE: u32 = 0xffffffffu;
// Member flags (`topo[flags_at + s]`): held (inverse mass 0), left out (not finite).
const HELD: u32 = 1u;
const OUT: u32 = 2u;

@group(0) @binding(0) var<uniform> find: Find;
// Per member: position and its `swept` (m).
@group(0) @binding(1) var<storage, read> points: array<vec4<f32>>;
// Member layers [0, members); items' corner slots and layer, four an item, from `tris_at`;
// each query's excluded items' start, from `excluded_at` (queries + 1 of them, offsets into
// the list that follows them); each layer's thickness (f32 bits), from `thickness_at`; each
// member's flags, from `flags_at`.
@group(0) @binding(2) var<storage, read> topo: array<u32>;
@group(0) @binding(3) var<storage, read_write> centres: array<Centre>;
// Counts then cursors: the buckets' at [0, buckets), the queries' at [buckets + 1, ...).
@group(0) @binding(4) var<storage, read_write> counts: array<atomic<u32>>;
// Their exclusive scans, one longer each: [0, buckets], [buckets + 1, buckets + 2 + queries).
@group(0) @binding(5) var<storage, read_write> starts: array<u32>;
// The items by bucket; the queries' lists.
@group(0) @binding(6) var<storage, read_write> sorted: array<u32>;
@group(0) @binding(7) var<storage, read_write> list: array<u32>;

fn finite(v: f32) -> bool {
    return (bitcast<u32>(v) & 0x7f800000u) != 0x7f800000u;
}

fn bucket_of(c: vec3<i32>) -> u32 {
    let u = bitcast<vec3<u32>>(c);
    return ((u.x * 73856093u) ^ (u.y * 19349663u) ^ (u.z * 83492791u)) & (find.buckets - 1u);
}

fn cell_of(p: vec3<f32>) -> vec3<i32> {
    return vec3<i32>(floor(clamp(p / find.cell, vec3(-1.0e9), vec3(1.0e9))));
}

// One invocation per item: its centre, radius and bucket, counted. A triangle's centre is its
// corners' mean; an edge's, its midpoint (the CPU's `sphere`s).
@compute @workgroup_size(WORKGROUP)
fn centres_pass(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = linear(id, groups);
    if k >= find.triangles {
        return;
    }
    let at = find.tris_at + 4u * k;
    let a = points[topo[at]].xyz;
    let b = points[topo[at + 1u]].xyz;
    var m = 0.5 * (a + b);
    var r = 0.5 * length(b - a);
    if topo[at + 2u] != NONE {
        let c = points[topo[at + 2u]].xyz;
        m = (a + b + c) / 3.0;
        r = sqrt(max(max(dot(a - m, a - m), dot(b - m, b - m)), dot(c - m, c - m)));
    }
    var out = Centre(vec4(m, r), vec4<i32>(0, 0, 0, -1));
    if finite(r) && finite(m.x) && finite(m.y) && finite(m.z) {
        let cell = cell_of(m);
        let h = bucket_of(cell);
        out.cell = vec4(cell, bitcast<i32>(h));
        atomicAdd(&counts[h], 1u);
    }
    centres[k] = out;
}

var<workgroup> sums: array<u32, 256>;

// An exclusive scan of `counts[base, base + len)` into `starts[base, base + len]` by one
// workgroup of 256, each invocation a run; the counts become the runs' cursors.
fn scan(base: u32, len: u32, t: u32) {
    let run = (len + 255u) / 256u;
    let lo = min(t * run, len);
    let hi = min(lo + run, len);
    var total = 0u;
    for (var i = lo; i < hi; i++) {
        total += atomicLoad(&counts[base + i]);
    }
    sums[t] = total;
    workgroupBarrier();
    // Hillis–Steele, inclusive.
    for (var d = 1u; d < 256u; d *= 2u) {
        var add = 0u;
        if t >= d {
            add = sums[t - d];
        }
        workgroupBarrier();
        sums[t] += add;
        workgroupBarrier();
    }
    var at = sums[t] - total;
    for (var i = lo; i < hi; i++) {
        let n = atomicLoad(&counts[base + i]);
        starts[base + i] = at;
        atomicStore(&counts[base + i], at);
        at += n;
    }
    if t == 255u {
        starts[base + len] = sums[255];
    }
}

@compute @workgroup_size(256)
fn scan_buckets(@builtin(local_invocation_index) t: u32) {
    scan(0u, find.buckets, t);
}

@compute @workgroup_size(256)
fn scan_queries(@builtin(local_invocation_index) t: u32) {
    scan(find.buckets + 1u, find.queries, t);
}

// One invocation per triangle: its place in its bucket (in any order).
@compute @workgroup_size(WORKGROUP)
fn scatter_pass(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = linear(id, groups);
    if k >= find.triangles {
        return;
    }
    let h = bitcast<u32>(centres[k].cell.w);
    if h != NONE {
        sorted[atomicAdd(&counts[h], 1u)] = k;
    }
}

// One invocation per bucket: its triangles in ascending order (an insertion sort; a bucket
// holds a few).
@compute @workgroup_size(WORKGROUP)
fn order_pass(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let h = linear(id, groups);
    if h >= find.buckets {
        return;
    }
    let lo = starts[h];
    let hi = starts[h + 1u];
    for (var i = lo + 1u; i < hi; i++) {
        let k = sorted[i];
        var j = i;
        while j > lo && sorted[j - 1u] > k {
            sorted[j] = sorted[j - 1u];
            j -= 1u;
        }
        sorted[j] = k;
    }
}

fn thickness(layer: u32) -> f32 {
    return bitcast<f32>(topo[find.thickness_at + layer]);
}

fn swept(s: u32) -> f32 {
    return points[s].w;
}

// Whether item k is in query s's list of neighbours at rest (a binary search).
fn excluded(s: u32, k: u32) -> bool {
    let base = find.excluded_at + find.queries + 1u;
    var lo = topo[find.excluded_at + s];
    var hi = topo[find.excluded_at + s + 1u];
    while lo < hi {
        let mid = (lo + hi) / 2u;
        let e = topo[base + mid];
        if e == k {
            return true;
        }
        if e < k {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return false;
}

// Member s's candidates, counted (write false) or written from `at` (write true).
fn search(s: u32, write: bool, at: u32) -> u32 {
    let flags = topo[find.flags_at + s];
    if (flags & OUT) != 0u {
        return 0u;
    }
    let xp = points[s].xyz;
    let lp = topo[s];
    let tp = thickness(lp);
    let own = cell_of(xp);
    var n = 0u;
    for (var dx = -1; dx <= 1; dx++) {
        for (var dy = -1; dy <= 1; dy++) {
            for (var dz = -1; dz <= 1; dz++) {
                let cell = own + vec3(dx, dy, dz);
                let h = bucket_of(cell);
                for (var i = starts[h]; i < starts[h + 1u]; i++) {
                    let k = sorted[i];
                    let centre = centres[k];
                    if any(centre.cell.xyz != cell) {
                        continue;
                    }
                    let m = centre.m.xyz;
                    let r = centre.m.w;
                    let d2 = dot(xp - m, xp - m);
                    let widest = find.reach_max + r + find.slack;
                    if d2 >= widest * widest {
                        continue;
                    }
                    let t = find.tris_at + 4u * k;
                    let corners = vec3(topo[t], topo[t + 1u], topo[t + 2u]);
                    let layer = topo[t + 3u];
                    if (layer == lp && excluded(s, k)) || any(corners == vec3(s)) {
                        continue;
                    }
                    let reach = 0.5 * (tp + thickness(layer)) + find.margin + swept(s)
                        + max(max(swept(corners.x), swept(corners.y)), swept(corners.z))
                        + find.slack;
                    if d2 >= (reach + r) * (reach + r) {
                        continue;
                    }
                    let a = points[corners.x].xyz;
                    let b = points[corners.y].xyz;
                    let c = points[corners.z].xyz;
                    let w = closest_on_triangle(xp, a, b, c);
                    let q = a * w.x + b * w.y + c * w.z;
                    let held = (topo[find.flags_at + corners.x] & topo[find.flags_at + corners.y]
                        & topo[find.flags_at + corners.z] & flags & HELD) != 0u;
                    if dot(xp - q, xp - q) >= reach * reach || held {
                        continue;
                    }
                    if write && at + n < find.capacity {
                        list[at + n] = k;
                    }
                    n += 1u;
                }
            }
        }
    }
    return n;
}

// The weights (s, u) of the closest points of segments ab and cd: the twin of
// `segment_weights` in src/collide/edges.rs (Ericson 5.1.9).
fn segment_weights(a: vec3<f32>, b: vec3<f32>, c: vec3<f32>, d: vec3<f32>) -> vec2<f32> {
    let d1 = b - a;
    let d2 = d - c;
    let r = a - c;
    let aa = dot(d1, d1);
    let ee = dot(d2, d2);
    let ff = dot(d2, r);
    let tiny = 1.0e-30;
    if aa <= tiny && ee <= tiny {
        return vec2(0.0, 0.0);
    }
    if aa <= tiny {
        return vec2(0.0, clamp(ff / ee, 0.0, 1.0));
    }
    let cc = dot(d1, r);
    if ee <= tiny {
        return vec2(clamp(-cc / aa, 0.0, 1.0), 0.0);
    }
    let bb = dot(d1, d2);
    let denom = aa * ee - bb * bb;
    var s = 0.0;
    if denom > 1.0e-6 * aa * ee {
        s = clamp((bb * ff - cc * ee) / denom, 0.0, 1.0);
    }
    var u = (bb * s + ff) / ee;
    if u < 0.0 {
        u = 0.0;
        s = clamp(-cc / aa, 0.0, 1.0);
    } else if u > 1.0 {
        u = 1.0;
        s = clamp((bb - cc) / aa, 0.0, 1.0);
    }
    return vec2(s, u);
}

// Edge s's candidates among the other edges (both ways: the host keeps each pair once),
// counted (write false) or written from `at` (write true).
fn search_edges(s: u32, write: bool, at: u32) -> u32 {
    let own = centres[s];
    if bitcast<u32>(own.cell.w) == NONE {
        return 0u;
    }
    let es = find.tris_at + 4u * s;
    let ends = vec2(topo[es], topo[es + 1u]);
    let ls = topo[es + 3u];
    let ms = own.m.xyz;
    let rs = own.m.w;
    let held_s = topo[find.flags_at + ends.x] & topo[find.flags_at + ends.y] & HELD;
    let swept_s = max(swept(ends.x), swept(ends.y));
    let ts = thickness(ls);
    var n = 0u;
    for (var dx = -1; dx <= 1; dx++) {
        for (var dy = -1; dy <= 1; dy++) {
            for (var dz = -1; dz <= 1; dz++) {
                let cell = own.cell.xyz + vec3(dx, dy, dz);
                let h = bucket_of(cell);
                for (var i = starts[h]; i < starts[h + 1u]; i++) {
                    let u = sorted[i];
                    let centre = centres[u];
                    if u == s || any(centre.cell.xyz != cell) {
                        continue;
                    }
                    let m = centre.m.xyz;
                    let r = centre.m.w;
                    let d2 = dot(ms - m, ms - m);
                    let widest = find.reach_max + rs + r + find.slack;
                    if d2 >= widest * widest {
                        continue;
                    }
                    let eu = find.tris_at + 4u * u;
                    let other = vec2(topo[eu], topo[eu + 1u]);
                    let lu = topo[eu + 3u];
                    if (lu == ls && excluded(s, u)) || any(other == vec2(ends.x))
                        || any(other == vec2(ends.y)) {
                        continue;
                    }
                    let held = held_s & topo[find.flags_at + other.x]
                        & topo[find.flags_at + other.y];
                    let reach = 0.5 * (ts + thickness(lu)) + find.margin + swept_s
                        + max(swept(other.x), swept(other.y)) + find.slack;
                    if held != 0u || d2 >= (reach + rs + r) * (reach + rs + r) {
                        continue;
                    }
                    let a = points[ends.x].xyz;
                    let b = points[ends.y].xyz;
                    let c = points[other.x].xyz;
                    let d = points[other.y].xyz;
                    let w = segment_weights(a, b, c, d);
                    let gap = (a + (b - a) * w.x) - (c + (d - c) * w.y);
                    if dot(gap, gap) >= reach * reach {
                        continue;
                    }
                    if write && at + n < find.capacity {
                        list[at + n] = u;
                    }
                    n += 1u;
                }
            }
        }
    }
    return n;
}

// One invocation per query: its candidates counted.
@compute @workgroup_size(WORKGROUP)
fn count_pass(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let s = linear(id, groups);
    if s >= find.queries {
        return;
    }
    atomicStore(&counts[find.buckets + 1u + s], search(s, false, 0u));
}

// One invocation per query: its candidates written at its place.
@compute @workgroup_size(WORKGROUP)
fn write_pass(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let s = linear(id, groups);
    if s >= find.queries {
        return;
    }
    search(s, true, starts[find.buckets + 1u + s]);
}

// As count_pass and write_pass, of edges against edges.
@compute @workgroup_size(WORKGROUP)
fn count_edges(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let s = linear(id, groups);
    if s >= find.queries {
        return;
    }
    atomicStore(&counts[find.buckets + 1u + s], search_edges(s, false, 0u));
}

@compute @workgroup_size(WORKGROUP)
fn write_edges(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let s = linear(id, groups);
    if s >= find.queries {
        return;
    }
    search_edges(s, true, starts[find.buckets + 1u + s]);
}
