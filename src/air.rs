//! Air on cloth: per-triangle drag and lift from the air's velocity relative to the triangle
//! (`../shared/MATH.md`, "Air on a triangle"), and the wind field it blows in.
//!
//! For a triangle of unit normal `n` (either side) and area `A`, the relative air velocity
//! `u = w − v̄` (the wind at its centroid less its vertices' mean velocity) gives
//! - drag along `u`: `F_d = ½ ρ C_d A |u·n| u`,
//! - lift across `u`, in the plane of `u` and `n`: `F_l = ½ ρ C_l A (u·n) (|u|² n − (u·n) u)/|u|`,
//!
//! neither depending on the triangle's winding; each is split over the three vertices by a
//! third. Air is evaluated once a frame, at the frame's start state (its time constant, a
//! fraction of a second, is far longer than a frame), and held over the substeps as a force:
//! the integrate kernels read it where they read gravity, and the audit books its work with
//! the game's forces ([`crate::EnergyAudit::forces`]). With the springs on the GPU the forces
//! are made there (`shaders/air.wgsl`, this module's twin: the drag and lift, the wind field
//! and its noise, whose hash is on 32 bits so both sides hash the same values) and come back
//! for the books.

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// A cloth's aerodynamics: its air's density and its coefficients (a cloth component, set from
/// a scene's `air:`). A cloth without one feels no air.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Aero {
    /// Air density ρ (kg/m³; sea-level air 1.225).
    #[serde(default = "sea_level")]
    pub density: f64,
    /// Drag coefficient `C_d` (≥ 0; a flat plate face-on is about 1.2).
    #[serde(default = "plate_drag")]
    pub drag: f64,
    /// Lift coefficient `C_l` (0: none).
    #[serde(default)]
    pub lift: f64,
}

fn sea_level() -> f64 {
    1.225
}

fn plate_drag() -> f64 {
    1.2
}

impl Default for Aero {
    fn default() -> Self {
        Aero {
            density: sea_level(),
            drag: plate_drag(),
            lift: 0.0,
        }
    }
}

/// The wind: a constant velocity, and gusts if given ([`crate::SimConfig::wind`],
/// [`crate::Simulation::set_wind`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Wind {
    /// The mean wind (m/s).
    #[serde(default)]
    pub velocity: [f64; 3],
    /// Gusts on top of it.
    #[serde(default)]
    pub gust: Option<Gust>,
}

/// Gusts: seeded value noise carried along with the mean wind and changing in time, the same
/// for the same seed, place and time on any machine. At a point `x` and time `t` the gust is
/// `strength · (N₀(s), N₁(s), N₂(s))`, with `s = (x·ŵ − |w̄| t)/length + t/period` (ŵ the mean
/// wind's direction, or none when it is still) and each `Nᵢ` a smooth noise in [−1, 1].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gust {
    /// The gusts' largest speed along each axis (m/s).
    pub strength: f64,
    /// Their size along the wind (m).
    pub length: f64,
    /// The time over which a gust changes where it is (s).
    pub period: f64,
    /// The noise's seed.
    #[serde(default)]
    pub seed: u64,
}

impl Wind {
    /// A constant wind.
    pub fn steady(velocity: DVec3) -> Self {
        Wind {
            velocity: velocity.to_array(),
            gust: None,
        }
    }

    /// Whether it blows at all (a still wind with no gusts is none).
    pub fn is_still(&self) -> bool {
        self.velocity == [0.0; 3] && self.gust.is_none()
    }

    /// The wind at `x` at time `t` (m/s).
    pub fn at(&self, x: DVec3, t: f64) -> DVec3 {
        self.field(t).at(x)
    }

    /// The field at time `t`: what the wind at any point needs, the gusts' phase split into a
    /// whole cell and a fraction so the device's f32 keeps the fraction's precision at any `t`.
    pub(crate) fn field(&self, t: f64) -> Field {
        let mean = DVec3::from(self.velocity);
        let Some(g) = self.gust else {
            return Field {
                mean,
                strength: 0.0,
                along: DVec3::ZERO,
                cell: 0,
                phase: 0.0,
                keys: [0; 3],
            };
        };
        let speed = mean.length();
        let along = if speed > 0.0 {
            mean / (speed * g.length)
        } else {
            DVec3::ZERO
        };
        let s0 = t / g.period - speed * t / g.length;
        let whole = s0.floor();
        Field {
            mean,
            strength: g.strength,
            along,
            cell: whole as i64 as u32,
            phase: s0 - whole,
            keys: [0, 1, 2].map(|c| channel_key(g.seed, c)),
        }
    }

    /// What a scene's or [`crate::Simulation::set_wind`]'s wind must be: finite, gusts of
    /// strength ≥ 0 with a length and a period > 0. The message names the field.
    pub fn check(&self) -> Result<(), String> {
        if !self.velocity.iter().all(|c| c.is_finite()) {
            return Err(format!("velocity must be finite, got {:?}", self.velocity));
        }
        if let Some(g) = self.gust {
            if !(g.strength.is_finite() && g.strength >= 0.0) {
                return Err(format!(
                    "gust.strength must be finite and ≥ 0, got {:?}",
                    g.strength
                ));
            }
            for (name, v) in [("length", g.length), ("period", g.period)] {
                if !(v.is_finite() && v > 0.0) {
                    return Err(format!("gust.{name} must be finite and > 0, got {v:?}"));
                }
            }
        }
        Ok(())
    }
}

impl Aero {
    /// What a cloth's air must be: a density and drag ≥ 0, a lift, all finite. The message names
    /// the field.
    pub fn check(&self) -> Result<(), String> {
        for (name, v) in [("density", self.density), ("drag", self.drag)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} must be finite and ≥ 0, got {v:?}"));
            }
        }
        if !self.lift.is_finite() {
            return Err(format!("lift must be finite, got {:?}", self.lift));
        }
        Ok(())
    }
}

/// The wind field at one time ([`Wind::field`]): `shaders/air.wgsl`'s `AirFrame` mirrors it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Field {
    pub(crate) mean: DVec3,
    /// The gusts' strength (0: none).
    pub(crate) strength: f64,
    /// `ŵ / length`: `x · along` is how many gust lengths `x` lies down the wind.
    pub(crate) along: DVec3,
    /// The phase `t/period − |w̄| t/length` as a whole cell (wrapping) and a fraction in [0, 1).
    pub(crate) cell: u32,
    pub(crate) phase: f64,
    /// Each axis's noise key, from the seed.
    pub(crate) keys: [u32; 3],
}

impl Field {
    /// The wind at `x` (m/s): the mean, plus `strength · (N₀(s), N₁(s), N₂(s))` at
    /// `s = x·ŵ/length + phase`.
    pub(crate) fn at(&self, x: DVec3) -> DVec3 {
        if self.strength == 0.0 {
            return self.mean;
        }
        let s = self.phase + x.dot(self.along);
        let whole = s.floor();
        let cell = self.cell.wrapping_add(whole as i64 as u32);
        let f = s - whole;
        let n = self.keys.map(|key| noise(key, cell, f));
        self.mean + self.strength * DVec3::from(n)
    }
}

/// Smooth value noise in [−1, 1] at `f` ∈ [0, 1) of the way through `cell`: values hashed at
/// the cell's ends, joined by a smoothstep. Integer steps only on 32 bits, so the device hashes
/// the same values (`shaders/air.wgsl`, `noise`).
fn noise(key: u32, cell: u32, f: f64) -> f64 {
    let value = |k: u32| f64::from(hash(key ^ hash(k)) >> 8) / f64::from(1u32 << 24) * 2.0 - 1.0;
    let t = f * f * (3.0 - 2.0 * f);
    let (a, b) = (value(cell), value(cell.wrapping_add(1)));
    a + (b - a) * t
}

/// An axis's key from the seed.
fn channel_key(seed: u64, channel: u32) -> u32 {
    hash(hash(seed as u32 ^ hash(channel.wrapping_add(1))) ^ (seed >> 32) as u32)
}

/// A 32-bit integer hash (Wellons' `lowbias32`), as the device computes it.
fn hash(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}

/// The air's force on one triangle `[x0, x1, x2]` moving at its mean velocity `v̄`, in a wind
/// `w` (the module's drag and lift; zero for a triangle with no area).
pub fn triangle_force(aero: &Aero, x: [DVec3; 3], mean_v: DVec3, w: DVec3) -> DVec3 {
    let cross = (x[1] - x[0]).cross(x[2] - x[0]);
    let twice_area = cross.length();
    let u = w - mean_v;
    let speed = u.length();
    if twice_area == 0.0 || speed == 0.0 || !twice_area.is_finite() {
        return DVec3::ZERO;
    }
    let n = cross / twice_area;
    let q = 0.25 * aero.density * twice_area; // ½ ρ A
    let un = u.dot(n);
    let drag = q * aero.drag * un.abs() * u;
    let lift = q * aero.lift * un * (speed * speed * n - un * u) / speed;
    drag + lift
}

/// The cloths that feel air: their triangles (packed indices) and each cloth's coefficients.
#[derive(Debug, Default)]
pub(crate) struct AirSurfaces {
    triangles: Vec<[u32; 3]>,
    /// `(end of the cloth's triangles, its air)`, in order.
    cloths: Vec<(usize, Aero)>,
}

impl AirSurfaces {
    /// Adds a cloth's triangles with its air.
    pub(crate) fn push(&mut self, triangles: impl IntoIterator<Item = [u32; 3]>, aero: Aero) {
        self.triangles.extend(triangles);
        self.cloths.push((self.triangles.len(), aero));
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.cloths.is_empty()
    }

    /// The triangles, and each cloth's `(end of its triangles, its air)`.
    #[cfg(feature = "gpu")]
    pub(crate) fn parts(&self) -> (&[[u32; 3]], &[(usize, Aero)]) {
        (&self.triangles, &self.cloths)
    }

    /// The air's force on every particle (N, packed order) at positions `x` and velocities `v`
    /// at time `t` in `wind`, written over `out`: each triangle's force, a third to each
    /// vertex, summed in triangle order (deterministic).
    pub(crate) fn forces(&self, x: &[DVec3], v: &[DVec3], wind: &Wind, t: f64, out: &mut [DVec3]) {
        out.fill(DVec3::ZERO);
        let field = wind.field(t);
        let mut start = 0;
        for &(end, aero) in &self.cloths {
            for t3 in &self.triangles[start..end] {
                let [a, b, c] = t3.map(|i| i as usize);
                let (Some(&xa), Some(&xb), Some(&xc)) = (x.get(a), x.get(b), x.get(c)) else {
                    continue;
                };
                let centre = (xa + xb + xc) / 3.0;
                let mean_v = (v[a] + v[b] + v[c]) / 3.0;
                let f = triangle_force(&aero, [xa, xb, xc], mean_v, field.at(centre)) / 3.0;
                if f.is_finite() {
                    out[a] += f;
                    out[b] += f;
                    out[c] += f;
                }
            }
            start = end;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drag_and_lift_do_not_depend_on_the_winding() {
        let aero = Aero {
            density: 1.2,
            drag: 1.1,
            lift: 0.7,
        };
        let x = [DVec3::ZERO, DVec3::X, DVec3::Z];
        let w = DVec3::new(3.0, -2.0, 1.0);
        let f = triangle_force(&aero, x, DVec3::ZERO, w);
        let g = triangle_force(&aero, [x[0], x[2], x[1]], DVec3::ZERO, w);
        assert!((f - g).length() < 1e-12 * f.length());
        // Face-on: drag only, ½ ρ C_d A |u|² along u (A = ½).
        let f = triangle_force(&aero, x, DVec3::ZERO, DVec3::new(0.0, 2.0, 0.0));
        assert!((f - DVec3::new(0.0, 0.5 * 1.2 * 1.1 * 0.5 * 4.0, 0.0)).length() < 1e-12);
        // Edge-on: none.
        assert_eq!(triangle_force(&aero, x, DVec3::ZERO, DVec3::X), DVec3::ZERO);
    }

    #[test]
    fn gusts_are_smooth_bounded_and_seeded() {
        let g = Gust {
            strength: 2.0,
            length: 3.0,
            period: 1.5,
            seed: 7,
        };
        let wind = Wind {
            velocity: [5.0, 0.0, 0.0],
            gust: Some(g),
        };
        let mut last = wind.at(DVec3::ZERO, 0.0);
        for k in 1..2000 {
            let w = wind.at(DVec3::new(0.01 * k as f64, 0.0, 0.0), 0.001 * k as f64);
            assert!((w - DVec3::new(5.0, 0.0, 0.0)).abs().max_element() <= 2.0);
            assert!((w - last).length() < 0.05, "a jump at {k}");
            last = w;
        }
        let other = Wind {
            gust: Some(Gust { seed: 8, ..g }),
            ..wind
        };
        assert_ne!(wind.at(DVec3::ZERO, 0.3), other.at(DVec3::ZERO, 0.3));
        assert_eq!(wind.at(DVec3::ONE, 0.3), wind.at(DVec3::ONE, 0.3));
    }
}
