// Air on the device: the WGSL form of src/air.rs (`triangle_force`, the wind field's `Field::at`
// and its `noise`), run once a frame at the start of its first submit over the resident state.
// One invocation per triangle writes a third of its drag and lift; then one per particle sums
// its triangles' thirds in triangle order, as the CPU adds them (no atomics, the same result
// run to run), and writes the frame's acceleration, the host's `g + F/m` for the game's forces
// plus the air's `F/m`. The sums come back with the state, for the audit's books of their work.

// The prelude (shaders/prelude.wgsl: WORKGROUP, Position, linear) is joined before this file.

// The wind field at the frame's start (src/air.rs, `Field`).
struct AirFrame {
    mean: vec3<f32>,
    // The gusts' strength (0: none).
    strength: f32,
    // The mean wind's direction over the gusts' length.
    along: vec3<f32>,
    // The phase's fraction, in [0, 1).
    phase: f32,
    // Each axis's noise key.
    keys: vec3<u32>,
    // The phase's whole cell (wrapping).
    cell: u32,
    triangles: u32,
    particles: u32,
    _pad0: u32,
    _pad1: u32,
}

// A triangle's corners and its cloth's coefficients' index.
struct Tri {
    a: u32,
    b: u32,
    c: u32,
    cloth: u32,
}

@group(0) @binding(0) var<uniform> frame: AirFrame;
@group(0) @binding(1) var<storage, read> pos: array<Position>;
@group(0) @binding(2) var<storage, read> vel: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> tris: array<Tri>;
// Per cloth: ¼ ρ C_d and ¼ ρ C_l (drag and lift per twice the area, as `triangle_force`).
@group(0) @binding(4) var<storage, read> coefs: array<vec2<f32>>;
// A third of each triangle's force.
@group(0) @binding(5) var<storage, read_write> thirds: array<vec4<f32>>;
// Each particle's triangles: incident[first[i] .. first[i + 1]], in increasing order.
@group(0) @binding(6) var<storage, read> first: array<u32>;
@group(0) @binding(7) var<storage, read> incident: array<u32>;
// The air's force on each particle (N).
@group(0) @binding(8) var<storage, read_write> force: array<vec4<f32>>;
// The host's acceleration without the air (gravity and the game's forces), and the frame's
// with it, which the integrate kernels read.
@group(0) @binding(9) var<storage, read> base: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read_write> accel: array<vec4<f32>>;

// Wellons' lowbias32 (src/air.rs, `hash`).
fn hash(v: u32) -> u32 {
    var x = v;
    x ^= x >> 16u;
    x *= 0x7feb352du;
    x ^= x >> 15u;
    x *= 0x846ca68bu;
    return x ^ (x >> 16u);
}

fn value(key: u32, k: u32) -> f32 {
    return f32(hash(key ^ hash(k)) >> 8u) / 16777216.0 * 2.0 - 1.0;
}

fn noise(key: u32, cell: u32, f: f32) -> f32 {
    let t = f * f * (3.0 - 2.0 * f);
    let a = value(key, cell);
    let b = value(key, cell + 1u);
    return a + (b - a) * t;
}

fn wind_at(x: vec3<f32>) -> vec3<f32> {
    if frame.strength == 0.0 {
        return frame.mean;
    }
    let s = frame.phase + dot(x, frame.along);
    let whole = floor(s);
    let cell = frame.cell + bitcast<u32>(i32(whole));
    let f = s - whole;
    let n = vec3<f32>(
        noise(frame.keys.x, cell, f),
        noise(frame.keys.y, cell, f),
        noise(frame.keys.z, cell, f),
    );
    return frame.mean + frame.strength * n;
}

fn finite(v: vec3<f32>) -> bool {
    // NaN fails every comparison.
    return all(abs(v) <= vec3<f32>(3.4028235e38));
}

@compute @workgroup_size(WORKGROUP)
fn air_triangles(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let k = linear(id, groups);
    if k >= frame.triangles {
        return;
    }
    let t = tris[k];
    let p0 = pos[t.a];
    let p1 = pos[t.b];
    let p2 = pos[t.c];
    let e1 = (p1.hi.xyz - p0.hi.xyz) + (p1.lo.xyz - p0.lo.xyz);
    let e2 = (p2.hi.xyz - p0.hi.xyz) + (p2.lo.xyz - p0.lo.xyz);
    let cross_ = cross(e1, e2);
    let twice_area = length(cross_);
    let centre = ((p0.hi.xyz + p1.hi.xyz + p2.hi.xyz) + (p0.lo.xyz + p1.lo.xyz + p2.lo.xyz)) / 3.0;
    let mean_v = (vel[t.a].xyz + vel[t.b].xyz + vel[t.c].xyz) / 3.0;
    let u = wind_at(centre) - mean_v;
    let speed = length(u);
    var f = vec3<f32>(0.0);
    if twice_area > 0.0 && speed > 0.0 && twice_area <= 3.4028235e38 {
        let n = cross_ / twice_area;
        let q = coefs[t.cloth] * twice_area;
        let un = dot(u, n);
        let drag = q.x * abs(un) * u;
        let lift = q.y * un * (speed * speed * n - un * u) / speed;
        f = (drag + lift) / 3.0;
        if !finite(f) {
            f = vec3<f32>(0.0);
        }
    }
    thirds[k] = vec4<f32>(f, 0.0);
}

@compute @workgroup_size(WORKGROUP)
fn air_particles(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let i = linear(id, groups);
    if i >= frame.particles {
        return;
    }
    var sum = vec3<f32>(0.0);
    for (var e = first[i]; e < first[i + 1u]; e++) {
        sum += thirds[incident[e]].xyz;
    }
    force[i] = vec4<f32>(sum, 0.0);
    // w: the inverse mass (0 pinned: its acceleration is never read).
    accel[i] = vec4<f32>(base[i].xyz + sum * vel[i].w, 0.0);
}
