//! The search's first test, a chunk of items (triangles, or edges) at a time in single
//! precision: whether a point is within reach of an item's sphere. It is widened past single precision's
//! rounding, so it turns away only what the double-precision tests after it would: the
//! candidates are the same, found without a branch per triangle.

use std::ops::Range;

use glam::{DVec3, Vec3};

/// Triangles a chunk tests at once (the arrays are padded by a chunk nothing reaches).
const LANES: usize = 8;

/// How much wider than its reach the test looks, relatively (the rounding of the sums and
/// squares, a few units of 2⁻²⁴), and absolutely per metre of the largest coordinate (the
/// rounding of the places themselves).
const WIDER: f64 = 2e-6;
const PER_METRE: f64 = 1e-6;

/// The items' spheres in the search's order, in single precision, with their items and
/// layers.
#[derive(Debug, Default)]
pub(super) struct Near {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    /// The radius with the item's `swept`, widened.
    r: Vec<f32>,
    pub(super) item: Vec<u32>,
    pub(super) layer: Vec<u16>,
}

impl Near {
    /// The spheres in the search's order, `(centre, radius with swept, item, layer)`;
    /// `places` the particles' (the widening grows with the largest coordinate).
    pub(super) fn fill(
        &mut self,
        sorted: impl Iterator<Item = (DVec3, f64, u32, u16)>,
        places: impl Iterator<Item = DVec3>,
    ) {
        for v in [&mut self.x, &mut self.y, &mut self.z, &mut self.r] {
            v.clear();
        }
        self.item.clear();
        self.layer.clear();
        let largest = |x: DVec3| {
            let x = x.abs().max_element();
            if x.is_finite() {
                x
            } else {
                0.0
            }
        };
        let mut scale = places.map(largest).fold(0.0, f64::max);
        for (m, r, k, layer) in sorted {
            scale = scale.max(largest(m));
            self.x.push(m.x as f32);
            self.y.push(m.y as f32);
            self.z.push(m.z as f32);
            self.r.push((r * (1.0 + WIDER)) as f32);
            self.item.push(k);
            self.layer.push(layer);
        }
        let slack = (PER_METRE * scale) as f32;
        self.r.iter_mut().for_each(|r| *r += slack);
        for v in [&mut self.x, &mut self.y, &mut self.z] {
            v.extend([f32::INFINITY; LANES]);
        }
        self.r.extend([0.0; LANES]);
    }

    /// `hit(i)` for each sphere `i` of `range`, in order, that `p` may be within `reach` of.
    #[inline]
    pub(super) fn within(
        &self,
        range: Range<usize>,
        p: DVec3,
        reach: f64,
        mut hit: impl FnMut(usize),
    ) {
        let (p, reach) = (p.as_vec3(), (reach * (1.0 + WIDER)) as f32);
        let mut j = range.start;
        while j < range.end {
            let (x, y, z) = (
                &self.x[j..j + LANES],
                &self.y[j..j + LANES],
                &self.z[j..j + LANES],
            );
            let r = &self.r[j..j + LANES];
            let mut mask = 0u32;
            for l in 0..LANES {
                let d = Vec3::new(x[l], y[l], z[l]) - p;
                let w = reach + r[l];
                mask |= u32::from(d.length_squared() < w * w) << l;
            }
            let left = range.end - j;
            if left < LANES {
                mask &= (1 << left) - 1;
            }
            while mask != 0 {
                hit(j + mask.trailing_zeros() as usize);
                mask &= mask - 1;
            }
            j += LANES;
        }
    }
}
