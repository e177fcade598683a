//! The `#[repr(C)]` mirrors of `shaders/integrate.wgsl`'s structs (held to naga's layout by `tests/gpu.rs`).

use super::*;

/// `Params` in shaders/integrate.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Params {
    pub gravity: [f32; 3],
    pub h: f32,
    pub particles: u32,
    pub springs: u32,
    /// Always 1.0 (see `drift_by` in the shader).
    pub one: f32,
    pub _pad1: u32,
}

/// `Position`: `x = hi + lo`, a compensated pair.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Position {
    pub hi: [f32; 4],
    pub lo: [f32; 4],
}

impl Position {
    pub fn from_f64(x: DVec3) -> Self {
        let hi = x.as_vec3();
        let lo = (x - hi.as_dvec3()).as_vec3();
        Self {
            hi: [hi.x, hi.y, hi.z, 0.0],
            lo: [lo.x, lo.y, lo.z, 0.0],
        }
    }
    pub fn to_f64(self) -> DVec3 {
        let [hx, hy, hz, _] = self.hi.map(f64::from);
        let [lx, ly, lz, _] = self.lo.map(f64::from);
        DVec3::new(hx + lx, hy + ly, hz + lz)
    }
}

/// `Coef`: a spring's rest length, step coefficients and end a's mass share (b's is 1 − wa).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Coef {
    pub rest: f32,
    pub p: f32,
    pub q: f32,
    pub wa: f32,
}

/// `Entry`: one incident spring of a particle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Entry {
    pub spring: u32,
    pub coef: f32,
}

/// `Range`: one colour's springs, or one cloth grid's particles and links.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Range {
    pub start: u32,
    pub count: u32,
    /// A grid's columns (0 for a colour).
    pub cols: u32,
    /// A grid's first link, counted past the springs.
    pub links: u32,
    pub link_count: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}
