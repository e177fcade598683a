// Drawing a simulation (src/render/renderer.rs): lit two-sided meshes (cloth and rigid bodies), unlit
// lines (ropes, wireframe) and a procedural floor grid. Positions arrive in world space.

struct View {
    view_proj: mat4x4<f32>,
    // xyz: the eye.
    eye: vec4<f32>,
    // Floor: centre x, height y, centre z, half extent w.
    floor: vec4<f32>,
    // x: grid spacing (m).
    grid: vec4<f32>,
};

@group(0) @binding(0) var<uniform> view: View;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) colour: vec3<f32>,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) colour: vec3<f32>,
};

@vertex
fn vs_mesh(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    out.clip = view.view_proj * vec4<f32>(v.position, 1.0);
    out.world = v.position;
    out.normal = v.normal;
    out.colour = v.colour;
    return out;
}

// A key light from above, a cool fill from the other side, ambient and a little specular.
fn shade(n: vec3<f32>, world: vec3<f32>, colour: vec3<f32>) -> vec3<f32> {
    let key = normalize(vec3<f32>(0.45, 1.0, 0.35));
    let fill = normalize(vec3<f32>(-0.6, 0.35, -0.55));
    let diffuse = 0.28 + 0.62 * max(dot(n, key), 0.0) + 0.22 * max(dot(n, fill), 0.0);
    let to_eye = normalize(view.eye.xyz - world);
    let spec = 0.12 * pow(max(dot(n, normalize(key + to_eye)), 0.0), 32.0);
    return colour * diffuse + vec3<f32>(spec);
}

@fragment
fn fs_mesh(v: VertexOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    var n = v.normal;
    let len = length(n);
    n = select(vec3<f32>(0.0, 1.0, 0.0), n / len, len > 1e-12);
    // Both sides lit: the side seen faces the viewer; the back side is a shade darker.
    var colour = v.colour;
    if !front {
        n = -n;
        colour = colour * 0.8;
    }
    return vec4<f32>(shade(n, v.world, colour), 1.0);
}

@fragment
fn fs_line(v: VertexOut) -> @location(0) vec4<f32> {
    return vec4<f32>(v.colour, 1.0);
}

struct FloorOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
};

// Two triangles spanning the floor square, made from the vertex index (no vertex buffer).
@vertex
fn vs_floor(@builtin(vertex_index) i: u32) -> FloorOut {
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    let c = corners[i] * view.floor.w;
    let world = vec3<f32>(view.floor.x + c.x, view.floor.y, view.floor.z + c.y);
    var out: FloorOut;
    out.clip = view.view_proj * vec4<f32>(world, 1.0);
    out.world = world;
    return out;
}

@fragment
fn fs_floor(f: FloorOut) -> @location(0) vec4<f32> {
    let g = f.world.xz / view.grid.x;
    // Anti-aliased lines one pixel wide, from the screen-space rate of change.
    let w = fwidth(g);
    let d = abs(fract(g - 0.5) - 0.5) / max(w, vec2<f32>(1e-6));
    let line = 1.0 - min(min(d.x, d.y), 1.0);
    let r = length(f.world.xz - view.floor.xz) / view.floor.w;
    let fade = clamp(1.0 - r * r, 0.0, 1.0);
    let base = vec3<f32>(0.78, 0.79, 0.81);
    let ink = vec3<f32>(0.52, 0.54, 0.58);
    let sky = vec3<f32>(0.86, 0.89, 0.93);
    let floor = mix(base, ink, line * 0.8);
    return vec4<f32>(mix(sky, floor, fade), 1.0);
}
