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
//! the integrate kernels read it where they read gravity, so it runs on either back end and
//! the audit books its work with the game's forces ([`crate::EnergyAudit::forces`]).

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
        let mean = DVec3::from(self.velocity);
        let Some(g) = self.gust else {
            return mean;
        };
        let speed = mean.length();
        let along = if speed > 0.0 {
            x.dot(mean / speed)
        } else {
            0.0
        };
        let s = (along - speed * t) / g.length + t / g.period;
        mean + g.strength
            * DVec3::new(
                noise(g.seed, 0, s),
                noise(g.seed, 1, s),
                noise(g.seed, 2, s),
            )
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

/// Smooth value noise in [−1, 1]: values hashed at the integers of `s`, joined by a smoothstep.
fn noise(seed: u64, channel: u64, s: f64) -> f64 {
    let cell = s.floor();
    let f = s - cell;
    let k = cell as i64 as u64;
    let value = |k: u64| {
        let h = splitmix(seed ^ splitmix(channel.wrapping_add(k.wrapping_mul(0x9E37_79B9))));
        (h >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let t = f * f * (3.0 - 2.0 * f);
    value(k) + (value(k.wrapping_add(1)) - value(k)) * t
}

fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
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

    /// The air's force on every particle (N, packed order) at positions `x` and velocities `v`
    /// at time `t` in `wind`, written over `out`: each triangle's force, a third to each
    /// vertex, summed in triangle order (deterministic).
    pub(crate) fn forces(&self, x: &[DVec3], v: &[DVec3], wind: &Wind, t: f64, out: &mut [DVec3]) {
        out.fill(DVec3::ZERO);
        let mut start = 0;
        for &(end, aero) in &self.cloths {
            for t3 in &self.triangles[start..end] {
                let [a, b, c] = t3.map(|i| i as usize);
                let (Some(&xa), Some(&xb), Some(&xc)) = (x.get(a), x.get(b), x.get(c)) else {
                    continue;
                };
                let centre = (xa + xb + xc) / 3.0;
                let mean_v = (v[a] + v[b] + v[c]) / 3.0;
                let f = triangle_force(&aero, [xa, xb, xc], mean_v, wind.at(centre, t)) / 3.0;
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
