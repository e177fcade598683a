// What self-collision's shaders share (joined after the prelude before collide.wgsl and
// collide_pass.wgsl): the twins of the CPU's triangle queries in src/collide/search.rs.

// The barycentric weights of the point of triangle (a, b, c) closest to p: the twin of
// `closest_on_triangle` in src/collide/search.rs (Ericson 5.1.5).
fn closest_on_triangle(p: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> vec3<f32> {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return vec3(1.0, 0.0, 0.0);
    }
    let bp = p - b;
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return vec3(0.0, 1.0, 0.0);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return vec3(1.0 - v, v, 0.0);
    }
    let cp = p - c;
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return vec3(0.0, 0.0, 1.0);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return vec3(1.0 - w, 0.0, w);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return vec3(0.0, 1.0 - w, w);
    }
    let sum = va + vb + vc;
    if !(sum > 0.0) {
        return vec3(1.0, 0.0, 0.0);
    }
    let v = vb / sum;
    let w = vc / sum;
    return vec3(1.0 - v - w, v, w);
}

// The barycentric weights of p's projection onto the plane of triangle (a, b, c), unclamped,
// in xyz; w = 0 for a degenerate triangle (else 1): the twin of `plane_weights`.
fn plane_weights(p: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> vec4<f32> {
    let n = cross(b - a, c - a);
    let nn = dot(n, n);
    if !(nn > 0.0) {
        return vec4(0.0);
    }
    let v = dot(cross(p - a, c - a), n) / nn;
    let w = dot(cross(b - a, p - a), n) / nn;
    return vec4(1.0 - v - w, v, w, 1.0);
}
