// What the step's compute shaders share, defined once: joined before integrate.wgsl and
// contacts.wgsl when the shaders are assembled (src/gpu/mod.rs, `SHADER` and
// `contacts::SHADER`). The Rust mirror of `Position` is in src/gpu/layout.rs; tests/gpu_shaders.rs
// validates each assembled shader and holds the layouts together.

// Invocations per workgroup (src/gpu/mod.rs, `WORKGROUP`).
override WORKGROUP: u32 = 256u;

// x = hi + lo, a compensated pair (f32 state; a drift below half an ulp of x still moves it);
// w unused.
struct Position {
    hi: vec4<f32>,
    lo: vec4<f32>,
}

// p + dx, compensated (Knuth's two-sum: exact whatever the magnitudes); `one` is 1.0 read at
// run time, which keeps the compiler from folding the sums away.
fn moved(p: Position, dx: vec3<f32>, one: f32) -> Position {
    let hi = p.hi.xyz;
    let y = dx + p.lo.xyz;
    let t = hi + y;
    let yv = t * one - hi;
    let lo = (hi - (t - yv)) + (y - yv);
    return Position(vec4<f32>(t, 0.0), vec4<f32>(lo, 0.0));
}

// A 2-D grid of workgroups (one dimension stops at 65,535) read as one index.
fn linear(id: vec3<u32>, groups: vec3<u32>) -> u32 {
    return id.x + id.y * groups.x * WORKGROUP;
}
