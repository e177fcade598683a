// The contact stage on the device, for balls and cuboids: the WGSL form of
// src/contacts/stage.rs (`ContactStage::contacts`, `Hit`) and src/contacts/queries.rs (`surface`,
// `respond`, `support`), run after each
// substep's integrate passes over the same position and velocity buffers. The CPU stage asks
// parry for projections and ray casts; here they are written out for the two shapes, and
// tests/gpu.rs holds the two against each other. Each workgroup sums what its particles did
// to each collider's body into one partial; the host adds the partials in order.

// The prelude (shaders/prelude.wgsl: WORKGROUP, Position, linear) is joined before this file.

// Colliders a pass can take (private per-thread sums).
const MAX_COLLIDERS: u32 = 8u;
const BALL: u32 = 0u;
const CUBOID: u32 = 1u;

struct Step {
    h: f32,
    thickness: f32,
    restitution: f32,
    particles: u32,
    // Colliders per slot, the slot (substep of the frame) and workgroups per slot.
    colliders: u32,
    slot: u32,
    groups: u32,
    _pad: u32,
}

struct Collider {
    kind: u32,
    dynamic: u32,
    _pad0: u32,
    _pad1: u32,
    translation: vec4<f32>,
    // Unit quaternion (x, y, z, w).
    rotation: vec4<f32>,
    // Ball: x = radius. Cuboid: half extents.
    dims: vec4<f32>,
    // Velocity of the centre of mass; w = static friction.
    lin: vec4<f32>,
    // Angular velocity; w = kinetic friction.
    ang: vec4<f32>,
    // Centre of mass; w = the body's mass.
    com: vec4<f32>,
    // Bounding sphere: centre, and w = radius + thickness.
    sphere: vec4<f32>,
}

// What the particles of one workgroup did to one collider's body (see contacts::Exchange).
struct Partial {
    // Impulse; w = contacts.
    impulse: vec4<f32>,
    // Angular impulse about the centre of mass; w = deepest penetration.
    torque: vec4<f32>,
    // Supported contacts: impulse sum; w = their count.
    support: vec4<f32>,
    // Their angular impulse sum; w = contacts found by the swept test.
    support_torque: vec4<f32>,
}

@group(0) @binding(0) var<uniform> step: Step;
@group(0) @binding(1) var<storage, read_write> pos: array<Position>;
@group(0) @binding(2) var<storage, read_write> vel: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> colliders: array<Collider>;
@group(0) @binding(4) var<storage, read_write> partials: array<Partial>;
// Per particle: its mass (0 for a particle the stage skips: pinned or attached).
@group(0) @binding(5) var<storage, read> mass: array<f32>;

var<workgroup> shared_sum: array<Partial, WORKGROUP>;

fn rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let t = 2.0 * cross(q.xyz, v);
    return v + q.w * t + cross(q.xyz, t);
}

fn unrotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    return rotate(vec4<f32>(-q.xyz, q.w), v);
}

// parry's project_point (solid = false) in the collider's frame: the nearest surface point,
// and whether p is inside.
struct Projection {
    point: vec3<f32>,
    inside: bool,
}

fn project_local(c: Collider, p: vec3<f32>) -> Projection {
    if c.kind == BALL {
        let r = c.dims.x;
        let len = length(p);
        var dir = vec3<f32>(0.0, 1.0, 0.0);
        if len > 0.0 {
            dir = p / len;
        }
        return Projection(dir * r, len < r);
    }
    let he = c.dims.xyz;
    let clamped = clamp(p, -he, he);
    if any(clamped != p) {
        return Projection(clamped, false);
    }
    // Inside: out through the nearest face.
    let gap = he - abs(p);
    var out = p;
    if gap.x <= gap.y && gap.x <= gap.z {
        out.x = select(-he.x, he.x, p.x >= 0.0);
    } else if gap.y <= gap.z {
        out.y = select(-he.y, he.y, p.y >= 0.0);
    } else {
        out.z = select(-he.z, he.z, p.z >= 0.0);
    }
    return Projection(out, true);
}

// parry's cast_ray_and_get_normal (solid = false, max time 1) from a point outside: time of
// impact (negative: none) and the outward normal, in the collider's frame.
fn cast_local(c: Collider, p: vec3<f32>, d: vec3<f32>) -> vec4<f32> {
    if c.kind == BALL {
        let r = c.dims.x;
        let a = dot(d, d);
        let b = dot(p, d);
        let disc = b * b - a * (dot(p, p) - r * r);
        if a == 0.0 || disc < 0.0 {
            return vec4<f32>(-1.0);
        }
        let s = (-b - sqrt(disc)) / a;
        if s < 0.0 || s > 1.0 {
            return vec4<f32>(-1.0);
        }
        return vec4<f32>(normalize(p + s * d), s);
    }
    let he = c.dims.xyz;
    var near = -1e30;
    var far = 1e30;
    var axis = 0u;
    for (var k = 0u; k < 3u; k++) {
        if d[k] == 0.0 {
            if abs(p[k]) > he[k] {
                return vec4<f32>(-1.0);
            }
            continue;
        }
        let t1 = (-he[k] - p[k]) / d[k];
        let t2 = (he[k] - p[k]) / d[k];
        let lo = min(t1, t2);
        if lo > near {
            near = lo;
            axis = k;
        }
        far = min(far, max(t1, t2));
    }
    if near > far || near < 0.0 || near > 1.0 {
        return vec4<f32>(-1.0);
    }
    var n = vec3<f32>(0.0);
    n[axis] = -sign(d[axis]);
    return vec4<f32>(n, near);
}

// Mirrors contacts::stage::Hit.
struct Hit {
    found: bool,
    point: vec3<f32>,
    normal: vec3<f32>,
    depth: f32,
    swept: bool,
}

// Mirrors contacts::queries::surface.
fn surface(c: Collider, x0: vec3<f32>, x1: vec3<f32>, fast: bool, thickness: f32) -> Hit {
    let q = c.rotation;
    let t = c.translation.xyz;
    let d = x1 - x0;
    if fast {
        let l0 = unrotate(q, x0 - t);
        if !project_local(c, l0).inside {
            let r = cast_local(c, l0, unrotate(q, d));
            if r.w >= 0.0 {
                let point = x0 + d * r.w;
                var normal = rotate(q, r.xyz);
                if dot(normal, d) > 0.0 {
                    normal = -normal;
                }
                let depth = max(dot(x1 - point, -normal), 0.0);
                return Hit(true, point, normal, depth, true);
            }
        }
    }
    let p = project_local(c, unrotate(q, x1 - t));
    let point = rotate(q, p.point) + t;
    let diff = x1 - point;
    let dist = length(diff);
    if !p.inside && dist >= thickness {
        return Hit(false, point, vec3<f32>(0.0), 0.0, false);
    }
    var normal = vec3<f32>(0.0, 1.0, 0.0);
    if dist > 1e-9 {
        normal = select(diff / dist, -diff / dist, p.inside);
    } else if length(x0 - point) > 0.0 {
        normal = normalize(x0 - point);
    }
    return Hit(true, point, normal, select(0.0, dist, p.inside), false);
}

fn velocity_at(c: Collider, p: vec3<f32>) -> vec3<f32> {
    return c.lin.xyz + cross(c.ang.xyz, p - c.com.xyz);
}

fn add(a: Partial, b: Partial) -> Partial {
    return Partial(
        vec4<f32>(a.impulse + b.impulse),
        vec4<f32>(a.torque.xyz + b.torque.xyz, max(a.torque.w, b.torque.w)),
        a.support + b.support,
        a.support_torque + b.support_torque,
    );
}

// Mirrors ContactStage::contacts for one particle, then sums per collider over the workgroup.
@compute @workgroup_size(WORKGROUP)
fn contact_pass(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let i = linear(gid, groups);
    let group = wid.x + wid.y * groups.x;
    let nc = min(step.colliders, MAX_COLLIDERS);
    var acc: array<Partial, MAX_COLLIDERS>;
    let zero = Partial(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
    for (var c = 0u; c < MAX_COLLIDERS; c++) {
        acc[c] = zero;
    }
    var m = 0.0;
    if i < step.particles {
        m = mass[i];
    }
    if m > 0.0 {
        let h = step.h;
        let th = step.thickness;
        var v = vel[i].xyz;
        let x1 = pos[i].hi.xyz + pos[i].lo.xyz;
        // Where the particle started the substep: every update moves x by h times the final v.
        let x0 = x1 - h * v;
        var x = x1;
        var moved = false;
        var supported = false;
        for (var c = 0u; c < nc; c++) {
            let col = colliders[step.slot * step.colliders + c];
            // Bounding-sphere rejection, as the CPU stage does: the L1 length bounds the path.
            let d = x - x0;
            let path = dot(abs(d), vec3<f32>(1.0));
            let r = x - col.sphere.xyz;
            if dot(r, r) > (col.sphere.w + path) * (col.sphere.w + path) {
                continue;
            }
            let hit = surface(col, x0, x, dot(d, d) > th * th, th);
            if !hit.found {
                continue;
            }
            acc[c].impulse.w += 1.0;
            acc[c].torque.w = max(acc[c].torque.w, hit.depth);
            if hit.swept {
                acc[c].support_torque.w += 1.0;
            }
            let n = hit.normal;
            let body_mass = col.com.w;
            if col.dynamic != 0u && supported {
                // Mirrors contacts::queries::support.
                let rel = v - velocity_at(col, hit.point);
                let vn = dot(rel, n);
                let overlap = max(th - dot(x - hit.point, n), 0.0);
                let approach = -vn + 0.2 * overlap / h;
                if approach > 0.0 {
                    let jn = body_mass * approach;
                    let vt = rel - vn * n;
                    let speed = length(vt);
                    var jt = vt * (col.ang.w * jn / speed);
                    if body_mass * speed <= col.lin.w * jn {
                        jt = body_mass * vt;
                    }
                    let j = -jn * n + jt;
                    acc[c].support += vec4<f32>(j, 1.0);
                    acc[c].support_torque += vec4<f32>(cross(hit.point - col.com.xyz, j), 0.0);
                }
                continue;
            }
            supported = supported || col.dynamic == 0u;
            x = hit.point + n * th;
            moved = true;
            // Mirrors contacts::queries::respond.
            let vb = velocity_at(col, hit.point);
            let rel = v - vb;
            let vn = dot(rel, n);
            if vn >= 0.0 {
                continue;
            }
            let dvn = -(1.0 + step.restitution) * vn;
            var vt = rel - vn * n;
            let speed2 = dot(vt, vt);
            if speed2 <= (col.lin.w * dvn) * (col.lin.w * dvn) {
                vt = vec3<f32>(0.0);
            } else {
                vt = vt * max(1.0 - col.ang.w * dvn / sqrt(speed2), 0.0);
            }
            let old = v;
            v = vb + (vn + dvn) * n + vt;
            if col.dynamic != 0u {
                let j = m * (v - old);
                acc[c].impulse -= vec4<f32>(j, 0.0);
                acc[c].torque -= vec4<f32>(cross(hit.point - col.com.xyz, j), 0.0);
            }
        }
        if moved {
            pos[i] = Position(vec4<f32>(x, 0.0), vec4<f32>(0.0));
            vel[i] = vec4<f32>(v, vel[i].w);
        }
    }
    // Per collider: a tree sum over the workgroup, then one partial per workgroup.
    for (var c = 0u; c < nc; c++) {
        shared_sum[lid] = acc[c];
        workgroupBarrier();
        for (var s = WORKGROUP / 2u; s > 0u; s >>= 1u) {
            if lid < s {
                shared_sum[lid] = add(shared_sum[lid], shared_sum[lid + s]);
            }
            workgroupBarrier();
        }
        if lid == 0u && group < step.groups {
            partials[(step.slot * step.groups + group) * step.colliders + c] = shared_sum[0];
        }
        workgroupBarrier();
    }
}
