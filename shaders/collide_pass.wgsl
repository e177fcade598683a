// Self-collision's pass on the device: the twin of `Touch::face`, `Touch::push` and
// `Touch::settle` in src/collide/contact.rs, run after a substep's springs over the same
// position and velocity buffers. The contacts come in colours (src/collide/colours.rs): no two
// of a colour share a particle, so a colour's are taken side by side, colour after colour,
// and the result is the CPU's Gauss–Seidel over the same order, the same on every run: where
// every colour fits a workgroup, one workgroup takes them all with a barrier between colours
// (`one_group`), else a dispatch per colour. Then the passes over the pushed contacts'
// velocities the same way, and each particle's place kept as the next substep's start for the
// swept test. Host side: src/gpu/collide_pass.rs.

struct PassStep {
    particles: u32,
    // 1.0, read at run time so the compensated sums are not folded away.
    one: f32,
    // Colours, and velocity passes after the first (`one_group`).
    colours: u32,
    settles: u32,
}

// A colour's contacts: contacts[first .. end].
struct Span {
    first: u32,
    end: u32,
    _pad0: u32,
    _pad1: u32,
}

// A particle against a triangle's corners, and the pair's thickness and friction.
struct Contact {
    p: u32,
    a: u32,
    b: u32,
    c: u32,
    thickness: f32,
    mu: f32,
    mu_s: f32,
    _pad: f32,
}

// A contact the pass pushed: xyz its normal, w its `W` (0: not pushed); xyz the point's
// weights on the triangle's corners, w the normal impulse per unit of `W` so far.
struct Active {
    n: vec4<f32>,
    weights: vec4<f32>,
}

@group(0) @binding(0) var<uniform> step: PassStep;
@group(0) @binding(1) var<storage, read_write> pos: array<Position>;
// xyz velocity; w = the inverse mass, 0 for a pinned particle.
@group(0) @binding(2) var<storage, read_write> vel: array<vec4<f32>>;
// Each particle's place at the substep's start (xyz).
@group(0) @binding(3) var<storage, read_write> start: array<vec4<f32>>;
// In colour order.
@group(0) @binding(4) var<storage, read> contacts: array<Contact>;
@group(0) @binding(5) var<storage, read_write> pushed: array<Active>;
// The colour a dispatch takes (one per colour, at a dynamic offset).
@group(0) @binding(6) var<uniform> span: Span;
// Every colour's span (`one_group`).
@group(0) @binding(7) var<storage, read> spans: array<Span>;

fn x_of(i: u32) -> vec3<f32> {
    return pos[i].hi.xyz + pos[i].lo.xyz;
}

// x += dx, compensated.
fn move_by(i: u32, dx: vec3<f32>) {
    pos[i] = moved(pos[i], dx, step.one);
}

fn add_velocity(i: u32, dv: vec3<f32>) {
    let v = vel[i];
    vel[i] = vec4<f32>(v.xyz + dv, v.w);
}

// `Touch::push` for particle c.p against the point of weights `b` on the triangle: the gap
// opened by `over` along n by inverse mass, then the approach and the sliding removed.
fn push(k: u32, c: Contact, b: vec3<f32>, n: vec3<f32>, over: f32) {
    let ip = vel[c.p].w;
    let it = vec3(vel[c.a].w, vel[c.b].w, vel[c.c].w);
    var w = ip + dot(b * b, it);
    if !(w > 0.0) {
        return;
    }
    // A held corner's neighbour is thrown by at most four times `over`.
    let bw = b * it;
    w = max(w, 0.25 * max(ip, max(bw.x, max(bw.y, bw.z))));
    let lambda = over / w;
    move_by(c.p, n * (lambda * ip));
    move_by(c.a, -n * (lambda * bw.x));
    move_by(c.b, -n * (lambda * bw.y));
    move_by(c.c, -n * (lambda * bw.z));
    let vq = vel[c.a].xyz * b.x + vel[c.b].xyz * b.y + vel[c.c].xyz * b.z;
    let vr = vel[c.p].xyz - vq;
    let vn = dot(vr, n);
    pushed[k] = Active(vec4(n, w), vec4(b, max(-vn, 0.0) / w));
    if vn < 0.0 {
        let j = -vn / w;
        let vt = vr - n * vn;
        let slide = length(vt);
        var stop = 1.0;
        if !(slide <= c.mu_s * -vn) {
            stop = min(c.mu * -vn / slide, 1.0);
        }
        var kt = 0.0;
        if slide > 0.0 {
            kt = stop / w;
        }
        let dv = n * j - vt * kt;
        add_velocity(c.p, dv * ip);
        add_velocity(c.a, -dv * bw.x);
        add_velocity(c.b, -dv * bw.y);
        add_velocity(c.c, -dv * bw.z);
    }
}

// `Touch::face`: swept first (a particle that crossed the plane inside the triangle over the
// substep goes back to the side it started on), else out from the closest point.
fn face(k: u32) {
    pushed[k].n.w = 0.0;
    let c = contacts[k];
    let t = c.thickness;
    let xp = x_of(c.p);
    let a = x_of(c.a);
    let b = x_of(c.b);
    let cc = x_of(c.c);
    let p0 = start[c.p].xyz;
    let a0 = start[c.a].xyz;
    let b0 = start[c.b].xyz;
    let c0 = start[c.c].xyz;
    let n0 = cross(b0 - a0, c0 - a0);
    let n1 = cross(b - a, cc - a);
    let d0 = dot(n0, p0 - a0);
    let d1 = dot(n1, xp - a);
    if d0 * d1 < 0.0 {
        let e0 = d0 / length(n0);
        let e1 = d1 / length(n1);
        let tau = e0 / (e0 - e1);
        let w = plane_weights(
            mix(p0, xp, tau),
            mix(a0, a, tau),
            mix(b0, b, tau),
            mix(c0, cc, tau),
        );
        if w.w > 0.0 && all(w.xyz >= vec3(0.0)) {
            let n = n1 * (sign(d0) / length(n1));
            let q = a * w.x + b * w.y + cc * w.z;
            push(k, c, w.xyz, n, t - dot(n, xp - q));
            return;
        }
    }
    if d1 * d1 >= t * t * dot(n1, n1) && d0 * d1 >= 0.0 {
        return;
    }
    let w = closest_on_triangle(xp, a, b, cc);
    let d = xp - (a * w.x + b * w.y + cc * w.z);
    let dist2 = dot(d, d);
    if !(dist2 < t * t) {
        return;
    }
    let dist = sqrt(dist2);
    var n = vec3(0.0, 1.0, 0.0);
    if dist > 1e-9 * t {
        n = d / dist;
    } else {
        var side = 1.0;
        if d0 < 0.0 {
            side = -1.0;
        }
        let m = n1 * side;
        let l = length(m);
        if l > 0.0 && l < 3.4e38 {
            n = m / l;
        }
    }
    push(k, c, w, n, t - dist);
}

// `Touch::settle` for one pushed contact: its approach removed again, or an impulse the others
// made more than needed taken back, never past none.
fn settle(k: u32) {
    let s = pushed[k];
    if !(s.n.w > 0.0) {
        return;
    }
    let c = contacts[k];
    let b = s.weights.xyz;
    let vq = vel[c.a].xyz * b.x + vel[c.b].xyz * b.y + vel[c.c].xyz * b.z;
    let vn = dot(vel[c.p].xyz - vq, s.n.xyz);
    let impulse = max(s.weights.w - vn / s.n.w, 0.0);
    let j = impulse - s.weights.w;
    if j == 0.0 {
        return;
    }
    pushed[k].weights.w = impulse;
    let dv = s.n.xyz * j;
    let it = vec3(vel[c.a].w, vel[c.b].w, vel[c.c].w) * b;
    add_velocity(c.p, dv * vel[c.p].w);
    add_velocity(c.a, -dv * it.x);
    add_velocity(c.b, -dv * it.y);
    add_velocity(c.c, -dv * it.z);
}

// Every colour in one workgroup, one after another, with the velocity passes and the places
// kept (where no colour holds more contacts than a workgroup has invocations, this saves a
// dispatch per colour and runs as side by side).
@compute @workgroup_size(WORKGROUP)
fn one_group(@builtin(local_invocation_index) t: u32) {
    for (var round = 0u; round <= step.settles; round++) {
        for (var c = 0u; c < step.colours; c++) {
            for (var k = spans[c].first + t; k < spans[c].end; k += WORKGROUP) {
                if round == 0u {
                    face(k);
                } else {
                    settle(k);
                }
            }
            storageBarrier();
        }
    }
    for (var i = t; i < step.particles; i += WORKGROUP) {
        start[i] = vec4(x_of(i), 0.0);
    }
}

// One colour's contacts pushed, side by side.
@compute @workgroup_size(WORKGROUP)
fn push_colour(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = span.first + linear(id, groups);
    if k < span.end {
        face(k);
    }
}

// One colour's pushed contacts' velocities settled, side by side.
@compute @workgroup_size(WORKGROUP)
fn settle_colour(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = span.first + linear(id, groups);
    if k < span.end {
        settle(k);
    }
}

// Each particle's place kept as the next substep's start.
@compute @workgroup_size(WORKGROUP)
fn keep_start(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear(id, groups);
    if i < step.particles {
        start[i] = vec4(x_of(i), 0.0);
    }
}
