//! Drawing a simulation with wgpu: the cloth shaded from its normals with both sides lit
//! (or coloured by strain), ropes as particles and springs, the rapier bodies as meshes from
//! parry's shape tessellation, and a floor grid. [`Renderer`] draws into any texture view (a
//! window's surface in `examples/viewer.rs`); [`Offscreen`] draws into its own texture and
//! reads the pixels back, which is what `harmonic render` writes to PNG. Both work on a
//! software adapter (Mesa's lavapipe).

use glam::{Mat4, Vec3};

use crate::Simulation;

mod geometry;
mod offscreen;
mod renderer;

pub use offscreen::{Image, ImageError, Offscreen, Sheet, SheetError, MAX_SHEET_SIDE};
pub use renderer::Renderer;

/// The WGSL source of the renderer's pipelines (`shaders/render.wgsl`).
pub const SHADER: &str = include_str!("../../shaders/render.wgsl");

/// The offscreen colour format (no sRGB conversion: the shader's colours are written as is).
pub const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
const SAMPLES: u32 = 4;
/// The background, also the far colour of the floor grid's fade.
pub const SKY: [f64; 3] = [0.86, 0.89, 0.93];
/// Cloth and rope colour when not coloured by strain.
pub const CLOTH: [f32; 3] = [0.88, 0.42, 0.16];

/// What to draw besides the shaded cloth.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Style {
    /// Draw the cloth's triangle edges.
    pub wireframe: bool,
    /// Colour the cloth by strain (each particle's largest stretch `(l − l0)/l0` over its
    /// springs) instead of its plain colour: blue (unstretched) through green and yellow to
    /// red at `strain_scale` or more.
    pub strain: bool,
    /// The strain drawn fully red; a value that is not finite and > 0 means 10 % (the
    /// `harmonic render` flag refuses one).
    pub strain_scale: f32,
}

/// An orbit camera: it looks at `target` from `distance` away, turned `yaw` about the vertical
/// and raised `pitch` (radians).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// The point looked at (m).
    pub target: Vec3,
    /// Turn about the vertical axis (radians); 0 looks from +z.
    pub yaw: f32,
    /// Elevation above the horizontal (radians).
    pub pitch: f32,
    /// From the eye to `target` (m).
    pub distance: f32,
    /// Vertical field of view (radians).
    pub fov_y: f32,
}

impl Camera {
    /// A three-quarter view from above that fits the box `lo..hi`.
    pub fn framing(lo: Vec3, hi: Vec3) -> Self {
        let fov_y = 40f32.to_radians();
        let radius = (0.5 * (hi - lo).length()).max(0.05);
        Self {
            target: 0.5 * (lo + hi),
            yaw: 0.65,
            pitch: 0.38,
            distance: 0.95 * radius / (0.5 * fov_y).tan(),
            fov_y,
        }
    }

    /// [`Self::framing`] of `sim`'s [`bounds`] grown by `margin` of their size on each side.
    pub fn of(sim: &Simulation, margin: f32) -> Self {
        let (lo, hi) = bounds(sim);
        let pad = margin * (hi - lo);
        Self::framing(lo - pad, hi + pad)
    }

    /// The eye's position: `distance` from `target`, at `yaw` and `pitch`.
    pub fn eye(&self) -> Vec3 {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        self.target + self.distance * Vec3::new(cp * sy, sp, cp * cy)
    }

    /// Projection times view for a viewport of `aspect` = width / height (depth 0..1).
    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        let near = (0.01 * self.distance).max(1e-3);
        use glam::camera::rh::{proj::directx, view::look_at_mat4};
        let proj = directx::perspective(self.fov_y, aspect, near, 100.0 * self.distance);
        proj * look_at_mat4(self.eye(), self.target, Vec3::Y)
    }

    /// The ray through a viewport point (`ndc` in −1..1, y up): origin and unit direction.
    pub fn ray(&self, ndc: glam::Vec2, aspect: f32) -> (Vec3, Vec3) {
        let inv = self.view_proj(aspect).inverse();
        let near = inv.project_point3(Vec3::new(ndc.x, ndc.y, 0.0));
        let far = inv.project_point3(Vec3::new(ndc.x, ndc.y, 1.0));
        (near, (far - near).normalize_or(Vec3::NEG_Z))
    }
}

/// The box a picture of `sim` should hold: its particles and its bodies, leaving out fixed
/// colliders much larger than the rest (a ground slab would make everything else small).
pub fn bounds(sim: &Simulation) -> (Vec3, Vec3) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for x in sim.positions() {
        lo = lo.min(x.as_vec3());
        hi = hi.max(x.as_vec3());
    }
    if let Some(p) = sim.props() {
        let size = if lo.x.is_finite() {
            (hi - lo).length()
        } else {
            0.0
        };
        for (_, co) in p.colliders().iter() {
            let aabb = co.compute_aabb();
            let big = (aabb.maxs - aabb.mins).length() > 3.0 * size.max(0.1);
            let fixed = co
                .parent()
                .and_then(|h| p.bodies().get(h))
                .is_none_or(|b| b.is_fixed());
            if big && fixed {
                continue;
            }
            lo = lo.min(aabb.mins);
            hi = hi.max(aabb.maxs);
        }
    }
    if !lo.x.is_finite() || !hi.x.is_finite() {
        return (Vec3::splat(-1.0), Vec3::splat(1.0));
    }
    (lo, hi)
}

/// The colour of a strain `s` on a scale where `scale` is fully red.
pub fn strain_colour(s: f32, scale: f32) -> [f32; 3] {
    let stops = [
        [0.20, 0.35, 0.90],
        [0.15, 0.75, 0.35],
        [0.95, 0.85, 0.15],
        [0.90, 0.15, 0.10],
    ];
    let t = (s / scale.max(1e-9)).clamp(0.0, 1.0) * 3.0;
    let k = (t as usize).min(2);
    let f = t - k as f32;
    let (a, b) = (stops[k], stops[k + 1]);
    [0, 1, 2].map(|c| a[c] + f * (b[c] - a[c]))
}
