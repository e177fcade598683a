// Tethers on the device: the WGSL form of src/tether/lanes.rs (`clamp_one`), run after each
// substep's integrate passes over the same position and velocity buffers. One invocation per
// tethered particle takes its links in order (a second anchor sees the first's clamp). An
// anchor is pinned or attached, never a tethered particle, so no invocation reads a velocity
// another writes. Each invocation adds the kinetic energy its clamps change to its own element
// of `change`; the host sums them in order at the frame's end (no atomics, the same result run
// to run). The frame's last placing (`TetherStage::place`) runs on the host, where the state
// comes back at a frame's end.

// The prelude (shaders/prelude.wgsl: WORKGROUP, Position, linear) is joined before this file.

struct TetherStep {
    gravity: vec3<f32>,
    h: f32,
    parts: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// A tethered particle: its links are links[first .. first + count].
struct Part {
    particle: u32,
    first: u32,
    count: u32,
    _pad: u32,
}

// A tether: the anchor's particle, and the longest the particle may be from it.
struct Link {
    anchor: u32,
    limit: f32,
}

@group(0) @binding(0) var<uniform> step: TetherStep;
@group(0) @binding(1) var<storage, read> pos: array<Position>;
// xyz velocity; w = the inverse mass, 0 for a pinned particle.
@group(0) @binding(2) var<storage, read_write> vel: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> parts: array<Part>;
@group(0) @binding(4) var<storage, read> links: array<Link>;
// Per tethered particle: the change of kinetic energy its clamps made this frame (J).
@group(0) @binding(5) var<storage, read_write> change: array<f32>;

// The next substep moves a particle by h (v + h a), a ≈ gravity: along n = d/|d| at most
// L − |d|, that is s ≤ |d| L with s = h (u + h g)·d + |d|² (u its velocity relative to the
// anchor's), tested without a root as s |s| ≤ |d|² L². A link that fails has the velocity
// away from its anchor limited to (L − |d|)/h − h g·n.
@compute @workgroup_size(WORKGROUP)
fn tether_pass(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let k = linear(id, groups);
    if k >= step.parts {
        return;
    }
    let p = parts[k];
    var v = vel[p.particle];
    if v.w == 0.0 {
        return;
    }
    let h = step.h;
    let g = step.gravity;
    let x = pos[p.particle];
    var taken = 0.0;
    var clamped = false;
    for (var e = p.first; e < p.first + p.count; e++) {
        let l = links[e];
        let a = pos[l.anchor];
        let wa = vel[l.anchor].xyz;
        let d = (x.hi.xyz - a.hi.xyz) + (x.lo.xyz - a.lo.xyz);
        let d2 = dot(d, d);
        let s = h * dot(v.xyz - wa + h * g, d) + d2;
        if s * abs(s) <= d2 * l.limit * l.limit {
            continue;
        }
        let len = sqrt(d2);
        if !(len > 0.0) {
            continue;
        }
        let n = d / len;
        let most = (l.limit - len) / h - h * dot(g, n);
        let excess = dot(v.xyz - wa, n) - most;
        if excess > 0.0 {
            // ½ m (|v − e n|² − |v|²): the kinetic energy the clamp takes.
            taken += 0.5 / v.w * excess * (excess - 2.0 * dot(v.xyz, n));
            v = vec4<f32>(v.xyz - excess * n, v.w);
            clamped = true;
        }
    }
    if clamped {
        vel[p.particle] = v;
        change[k] += taken;
    }
}
