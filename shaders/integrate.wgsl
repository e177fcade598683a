// The GPU step: the WGSL mirror of src/integrate/mod.rs (spring_pass),
// src/integrate/particles.rs (particle_pass, External),
// src/integrate/grid/ (the cloth grid pass: mod.rs, band.rs) and src/integrate/gauss_seidel.rs (add_gravity,
// sweep, drift). Each function names its Rust mirror;
// tests/gpu.rs holds the two together. No atomics: every particle gathers its springs' changes
// over a CSR list, so GL and Vulkan adapters both work and results are deterministic.
//
// State is f32. A position is hi + lo (a compensated pair) so that a drift h·v below half an
// ulp of x still moves the particle (a 2 m tall cloth at h = 5e-5 s moves 2e-8 m per step).

// The prelude (shaders/prelude.wgsl: WORKGROUP, Position, linear) is joined before this file.

// Specialisation, chosen per scene at gather (src/gpu/pipelines.rs, `Specialisation`).
// Some spring responds to its stretch rate (q ≠ 0); false for undamped Euler springs.
override RATE: bool = true;
// Some particle is pinned; false drops the pin test.
override PINS: bool = true;
// 0: v += Δv + g h; x += h v (symplectic Euler, harmonic). 1: x += h v; v += Δv + g h.
override UPDATE: u32 = 0u;
// Cloth grids are kept whole (grid_pass runs); false when every spring is in `ends`.
override GRIDS: bool = false;
// The schedule lists a force stage: each particle's external acceleration (gravity included)
// is `accel[i]`, not `params.gravity` (the CPU's integrate::External).
override FORCES: bool = false;

struct Params {
    gravity: vec3<f32>,
    h: f32,
    particles: u32,
    springs: u32,
    // Exactly 1, unknown to the shader compiler: keeps it from folding the two-sum.
    one: f32,
    _pad1: u32,
}

// A spring's ends are `ends[k]`; the rest is here. Past the springs (k ≥ params.springs), the
// cloth grids' links: `ends` holds the link's (dc, dr) as i32 bits, and p, q are in force form
// (the particle's own inverse mass scales φ n; wa unused). Under harmonic the springs include
// the grid pass's corrections (grid::Fix): each as its own closed form, then as the nominal
// force that particle_pass takes back. φ = p δ + q δ̇ (coefficients from
// integrate::harmonic, computed once per h on the CPU); wa is end a's share of the relative
// velocity change, m_b/(m_a+m_b) (0 when a is pinned), and end b's is 1 − wa. Two arrays, not
// one struct, so no binding exceeds 128 MiB (lavapipe's limit) before 8 M springs.
struct Coef {
    rest: f32,
    p: f32,
    q: f32,
    wa: f32,
}

// One incident spring of a particle: sdv[spring] scaled by ±w.
struct Entry {
    spring: u32,
    coef: f32,
}

// The springs of one colour: springs[start .. start + count]. Or one cloth grid: particles
// start .. start + count, row-major, `cols` to a row, its links at params.springs + links
// .. + links + link_count in `ends` and `coefs`.
struct Range {
    start: u32,
    count: u32,
    cols: u32,
    links: u32,
    link_count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> pos: array<Position>;
// xyz velocity; w = the inverse mass, 0 for a pinned particle.
@group(0) @binding(2) var<storage, read_write> vel: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> ends: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read> coefs: array<Coef>;
@group(0) @binding(5) var<storage, read_write> sdv: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> offsets: array<u32>;
@group(0) @binding(7) var<storage, read> entries: array<Entry>;
// The external acceleration per particle, xyz (FORCES only; one unread element otherwise).
@group(0) @binding(9) var<storage, read> accel: array<vec4<f32>>;

// Mirrors integrate::particles::External::at: particle i's external acceleration.
fn external_accel(i: u32) -> vec3<f32> {
    if FORCES {
        return accel[i].xyz;
    }
    return params.gravity;
}
@group(0) @binding(8) var<uniform> colour: Range;

fn free(i: u32) -> bool {
    return !PINS || vel[i].w != 0.0;
}

// x_b − x_a. Near neighbours' hi parts subtract exactly; the lo parts restore the rest.
fn separation(a: u32, b: u32) -> vec3<f32> {
    return (pos[b].hi.xyz - pos[a].hi.xyz) + (pos[b].lo.xyz - pos[a].lo.xyz);
}

// x += dx, compensated.
fn drift_by(i: u32, dx: vec3<f32>) {
    pos[i] = moved(pos[i], dx, params.one);
}

// Mirrors integrate::spring_response: the unit axis n and φ = p δ + q δ̇.
fn spring_response(e: vec2<u32>, c: Coef, va: vec3<f32>, vb: vec3<f32>) -> vec4<f32> {
    let d = separation(e.x, e.y);
    let len = length(d);
    let n = d * (1.0 / len);
    let delta = len - c.rest;
    var phi = c.p * delta;
    if RATE {
        let delta_dot = dot(n, vb - va);
        phi += c.q * delta_dot;
    }
    return vec4<f32>(n, phi);
}

// Whether every component is finite: exponent bits not all set (WGSL has no isnan).
fn finite3(v: vec3<f32>) -> bool {
    let inf = vec3<u32>(0x7f800000u);
    return all((bitcast<vec3<u32>>(v) & inf) != inf);
}

// Mirrors integrate::guard (the quarantine): a finite change passes; a non-finite one from
// finite ends becomes NaN, marking both ends; one from an end already non-finite is dropped.
fn guard(dv: vec3<f32>, e: vec2<u32>, va: vec3<f32>, vb: vec3<f32>) -> vec3<f32> {
    if finite3(vec3<f32>(dv.x + dv.y + dv.z)) {
        return dv;
    }
    if finite3(pos[e.x].hi.xyz) && finite3(pos[e.y].hi.xyz) && finite3(va) && finite3(vb) {
        // A NaN made at run time (params.one is 1.0): a constant NaN is a shader error.
        return vec3<f32>(bitcast<f32>(0x7fc00000u ^ (bitcast<u32>(params.one) ^ 0x3f800000u)));
    }
    return vec3<f32>(0.0);
}

// Mirrors integrate::spring_pass: each spring writes its relative velocity change φ n.
@compute @workgroup_size(WORKGROUP)
fn spring_pass(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = linear(id, groups);
    if k >= params.springs {
        return;
    }
    let e = ends[k];
    var va = vec3<f32>(0.0);
    var vb = vec3<f32>(0.0);
    if RATE {
        va = vel[e.x].xyz;
        vb = vel[e.y].xyz;
    }
    let r = spring_response(e, coefs[k], va, vb);
    sdv[k] = vec4<f32>(guard(r.w * r.xyz, e, va, vb), 0.0);
}

// The GPU form of grid::band's band_rows for one grid: each particle sums −φ n / m over the links that
// reach it, from either end (each spring is evaluated at both its ends, with n pointing away
// from the particle), into sdv[params.springs + i] for particle_pass.
@compute @workgroup_size(WORKGROUP)
fn grid_pass(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let j = linear(id, groups);
    if j >= colour.count {
        return;
    }
    let i = colour.start + j;
    if !free(i) {
        return;
    }
    let cols = i32(colour.cols);
    let rows = i32(colour.count / colour.cols);
    let c = i32(j % colour.cols);
    let r = i32(j / colour.cols);
    let inv = vel[i].w;
    var va = vec3<f32>(0.0);
    if RATE {
        va = vel[i].xyz;
    }
    var dv = vec3<f32>(0.0);
    for (var k = colour.links; k < colour.links + colour.link_count; k++) {
        let offset = bitcast<vec2<i32>>(ends[params.springs + k]);
        let lc = coefs[params.springs + k];
        for (var side = -1; side <= 1; side += 2) {
            let cb = c + side * offset.x;
            let rb = r + side * offset.y;
            if cb < 0 || cb >= cols || rb < 0 || rb >= rows {
                continue;
            }
            let b = colour.start + u32(rb * cols + cb);
            var vb = vec3<f32>(0.0);
            if RATE {
                vb = vel[b].xyz;
            }
            let s = spring_response(vec2<u32>(i, b), lc, va, vb);
            // The guard keeps a degenerate spring's NaN to its two ends over the substeps of
            // one submit (the CPU grid pass needs none: its quarantine runs every substep).
            dv -= guard(inv * (s.w * s.xyz), vec2<u32>(i, b), va, vb);
        }
    }
    sdv[params.springs + i] = vec4<f32>(dv, 0.0);
}

// Mirrors integrate::particles::particle_pass (and, for a grid's particles, the move at the end of
// grid::Ctx::band): each particle gathers its springs' changes and moves.
@compute @workgroup_size(WORKGROUP)
fn particle_pass(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear(id, groups);
    if i >= params.particles || !free(i) {
        return;
    }
    var dv = vec3<f32>(0.0);
    if GRIDS {
        // What grid_pass summed (zero for a particle in no grid).
        dv = sdv[params.springs + i].xyz;
    }
    for (var e = offsets[i]; e < offsets[i + 1u]; e++) {
        let en = entries[e];
        dv += en.coef * sdv[en.spring].xyz;
    }
    let h = params.h;
    let g = external_accel(i);
    var v = vel[i];
    if UPDATE == 0u {
        v = vec4<f32>(v.xyz + dv + g * h, v.w);
        drift_by(i, h * v.xyz);
    } else {
        drift_by(i, h * v.xyz);
        v = vec4<f32>(v.xyz + dv + g * h, v.w);
    }
    vel[i] = v;
}

// Mirrors gauss_seidel::add_gravity: v += g h on free particles (g the external acceleration).
@compute @workgroup_size(WORKGROUP)
fn add_gravity(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear(id, groups);
    if i >= params.particles || !free(i) {
        return;
    }
    let v = vel[i];
    vel[i] = vec4<f32>(v.xyz + external_accel(i) * params.h, v.w);
}

// Mirrors gauss_seidel::sweep for one colour: springs of a colour share no particle, so each
// applies its impulse to both ends directly.
@compute @workgroup_size(WORKGROUP)
fn sweep_colour(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let j = linear(id, groups);
    if j >= colour.count {
        return;
    }
    let k = colour.start + j;
    let e = ends[k];
    let c = coefs[k];
    let va = vel[e.x];
    let vb = vel[e.y];
    let r = spring_response(e, c, va.xyz, vb.xyz);
    let dv = guard(r.w * r.xyz, e, va.xyz, vb.xyz);
    vel[e.x] = vec4<f32>(va.xyz - c.wa * dv, va.w);
    vel[e.y] = vec4<f32>(vb.xyz + (1.0 - c.wa) * dv, vb.w);
}

// Mirrors gauss_seidel::drift: x += h v on free particles.
@compute @workgroup_size(WORKGROUP)
fn drift(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear(id, groups);
    if i >= params.particles || !free(i) {
        return;
    }
    drift_by(i, params.h * vel[i].xyz);
}
