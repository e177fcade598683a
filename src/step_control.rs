//! Automatic substeps: estimate the network's highest natural frequency, then keep `ω_max h`
//! inside the stability region measured for the chosen integrator.
//!
//! `ω_max² ` is the largest eigenvalue of `M⁻¹K`, `K = Σ κ n nᵀ` over springs (axial
//! stiffness at the current geometry), found by power iteration. The stable `ω_max h` of each
//! integrator was measured (`stability::threshold`) on one spring, the chain of 20 and the 8×8
//! cloth at the damping ratios of [`ZETAS`] (the smallest of the three, then a safety factor).
//! The points are dense because a limit is convex in ζ where it falls (symplectic Euler's top
//! mode: ω_max h = 2(√(ζ_m² + 1) − ζ_m), ζ_m the mode's own damping ratio), so a straight line
//! between far points overestimates it: with points at 0.2 and 1 only, the default at ζ = 0.6
//! blew up the 8×8 cloth. Between points the reciprocal is interpolated, exact for that shape
//! far out and below the limit wherever the reciprocal is convex; past ζ = 2 the limit falls as
//! 1/ζ, as symplectic Euler's does.

use glam::DVec3;

use crate::buffers::{Packed, PackedSpring};
use crate::integrate::Integrator;

/// Largest natural angular frequency of the spring network (rad/s), by power iteration on
/// `M⁻¹K`; 0 without free, stiff springs. Each cloth grid kept whole takes part through a
/// window of at most [`WINDOW`]² particles around its stiffest particle (largest `Σκ/m`), its
/// neighbours outside held fixed: a principal submatrix, so the estimate stays a lower bound,
/// and the scratch stays small however large the cloth.
pub fn network_frequency(packed: &Packed, iterations: usize) -> f64 {
    if packed.topology.grids.is_empty() {
        power_iteration(packed, iterations)
    } else {
        power_iteration(&windowed(packed), iterations)
    }
}

/// Side of the window through which a large cloth grid enters the frequency estimate.
pub const WINDOW: u32 = 64;

/// The network with every grid cut down to its window, as explicit springs.
fn windowed(packed: &Packed) -> Packed {
    // Packed index → index in the window network.
    let mut map = std::collections::HashMap::new();
    let mut out = Packed::default();
    let mut add = |out: &mut Packed, i: usize, pinned: bool| -> u32 {
        *map.entry(i).or_insert_with(|| {
            out.x.push(packed.x[i]);
            out.v.push(packed.v[i]);
            out.inv_mass
                .push(if pinned { 0.0 } else { packed.inv_mass[i] });
            (out.x.len() - 1) as u32
        })
    };
    let mut pending = Vec::new();
    for g in &packed.topology.grids {
        let (cols, rows) = (g.cols as usize, g.rows as usize);
        let at = |c: usize, r: usize| g.base as usize + r * cols + c;
        // The stiffest particle, the one nearest the centre among equals.
        let score = |c: usize, r: usize| {
            let mut k = 0.0;
            for l in &g.links {
                let (dc, dr) = (l.offset.0 as isize, l.offset.1 as isize);
                for s in [1, -1] {
                    let (cc, rr) = (c as isize + s * dc, r as isize + s * dr);
                    if cc >= 0 && rr >= 0 && (cc as usize) < cols && (rr as usize) < rows {
                        k += l.stiffness;
                    }
                }
            }
            k * packed.inv_mass[at(c, r)]
        };
        let centre = |c: usize, r: usize| c.abs_diff(cols / 2) + r.abs_diff(rows / 2);
        let (mut best, mut pick) = (f64::NEG_INFINITY, (0, 0));
        for r in 0..rows {
            for c in 0..cols {
                let s = score(c, r);
                if s > best || (s == best && centre(c, r) < centre(pick.0, pick.1)) {
                    (best, pick) = (s, (c, r));
                }
            }
        }
        let w = WINDOW as usize;
        let c0 = pick.0.saturating_sub(w / 2).min(cols.saturating_sub(w));
        let r0 = pick.1.saturating_sub(w / 2).min(rows.saturating_sub(w));
        let inside = |c: usize, r: usize| (c0..c0 + w).contains(&c) && (r0..r0 + w).contains(&r);
        for s in g.springs(&packed.inv_mass) {
            let (a, b) = (
                s.a as usize - g.base as usize,
                s.b as usize - g.base as usize,
            );
            let (ia, ib) = (inside(a % cols, a / cols), inside(b % cols, b / cols));
            if ia || ib {
                pending.push((s, !ia, !ib));
            }
        }
    }
    for s in &packed.springs {
        pending.push((*s, false, false));
    }
    for (s, fix_a, fix_b) in pending {
        let a = add(&mut out, s.a as usize, fix_a);
        let b = add(&mut out, s.b as usize, fix_b);
        out.springs.push(PackedSpring::new(
            a,
            b,
            s.rest,
            s.stiffness,
            s.damping,
            &out.inv_mass,
        ));
    }
    out.rebuild_incidence();
    out
}

fn power_iteration(packed: &Packed, iterations: usize) -> f64 {
    let n = packed.particle_count();
    if packed.springs.is_empty() || n == 0 {
        return 0.0;
    }
    let axes: Vec<DVec3> = packed
        .springs
        .iter()
        .map(|s| (packed.x[s.b as usize] - packed.x[s.a as usize]).normalize_or_zero())
        .collect();
    // Deterministic start with every direction present.
    let mut u: Vec<DVec3> = (0..n)
        .map(|i| {
            let t = i as f64;
            DVec3::new(
                (t * 0.7548).sin(),
                (t * 1.3247 + 0.5).sin(),
                (t * 2.1).cos(),
            )
        })
        .collect();
    let mut y = vec![DVec3::ZERO; n];
    let mut per_spring = vec![DVec3::ZERO; packed.springs.len()];
    let mut lambda = 0.0;
    for _ in 0..iterations {
        for (k, s) in packed.springs.iter().enumerate() {
            let nn = axes[k];
            // Relative acceleration ω0² n (n·(u_b − u_a)), split by the incidence weights.
            per_spring[k] = s.omega0_sq() * nn * nn.dot(u[s.b as usize] - u[s.a as usize]);
        }
        for (i, yi) in y.iter_mut().enumerate() {
            *yi = if packed.inv_mass[i] == 0.0 {
                DVec3::ZERO
            } else {
                -packed.incidence.sum(&per_spring, i)
            };
        }
        let norm = y.iter().map(|v| v.length_squared()).sum::<f64>().sqrt();
        let unorm = u.iter().map(|v| v.length_squared()).sum::<f64>().sqrt();
        if norm == 0.0 || unorm == 0.0 {
            return 0.0;
        }
        lambda = norm / unorm;
        for (ui, yi) in u.iter_mut().zip(&y) {
            *ui = *yi / norm;
        }
    }
    lambda.sqrt()
}

/// Largest stable `ω_max h` of an integrator at damping ratio `zeta`, or `None` when it has no
/// stability limit.
pub fn stable_omega_h(integrator: Integrator, zeta: f64) -> Option<f64> {
    let table = match integrator {
        Integrator::ImplicitEuler | Integrator::Xpbd | Integrator::ThetaMg => return None,
        Integrator::SymplecticEuler => &TABLE_SE,
        Integrator::ExplicitEuler => &TABLE_EE,
        Integrator::Harmonic => &TABLE_H,
        Integrator::HarmonicGs => &TABLE_GS,
    };
    Some(on_table(table, zeta))
}

/// A stability table's `ω_max h` at damping ratio `zeta`: measured at each of [`ZETAS`], the
/// reciprocal interpolated between them, falling as `1/ζ` past the last.
pub fn on_table(table: &[f64; ZETAS.len()], zeta: f64) -> f64 {
    let last = ZETAS.len() - 1;
    let zeta = zeta.max(0.0);
    if zeta >= ZETAS[last] {
        return table[last] * ZETAS[last] / zeta;
    }
    let k = (0..last)
        .find(|&k| zeta <= ZETAS[k + 1])
        .unwrap_or(last - 1);
    let t = (zeta - ZETAS[k]) / (ZETAS[k + 1] - ZETAS[k]);
    1.0 / (1.0 / table[k] + t * (1.0 / table[k + 1] - 1.0 / table[k]))
}

/// XPBD's `ω_max h` per substep: an accuracy bound, not a stability limit (it has none). One
/// constraint pass per substep resolves a stiff network only so far: a 20-link chain (0.5 kg,
/// 20 kN/m, ζ ≈ 0.01) released horizontally stretches 462 % and ends 252 J above its start at
/// ω_max h = 30 (one substep at 60 Hz), 6.8 % and 0.1 J from the converged energy at 1.9
/// (16 substeps), against 3.5 % converged.
pub const XPBD_OMEGA_H: f64 = 2.0;

/// Damping ratios at which the limits were measured.
pub const ZETAS: [f64; 11] = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0, 1.5, 2.0];
// ω_max·h at the measured thresholds (the least of one spring, the chain of 20 and the 8×8
// cloth; rounded down). 20 where none was found up to 8 h_c.
/// Symplectic Euler's measured stable `ω_max h` at each damping ratio of [`ZETAS`].
pub const TABLE_SE: [f64; 11] = [
    1.997, 1.607, 1.311, 1.083, 0.913, 0.778, 0.676, 0.533, 0.44, 0.296, 0.228,
];
/// Explicit Euler grows at any step undamped; ζ = 0 is where the growth passes the tolerance.
pub const TABLE_EE: [f64; 11] = [
    0.05, 0.215, 0.408, 0.604, 0.805, 1.001, 0.947, 0.634, 0.49, 0.313, 0.228,
];
/// `harmonic`'s measured stable `ω_max h` at each of [`ZETAS`].
pub const TABLE_H: [f64; 11] = [
    1.455, 1.286, 1.133, 1.015, 0.905, 0.812, 0.736, 0.617, 0.524, 0.372, 0.287,
];
/// Held by the single spring's plain-update limit at low damping.
pub const TABLE_GS: [f64; 11] = [
    1.72, 1.798, 1.971, 3.294, 3.432, 3.632, 3.934, 5.273, 8.884, 20.0, 20.0,
];
/// Fraction of the measured limit the controller uses.
pub const SAFETY: f64 = 0.8;
/// Never more substeps than this per frame; a scene needing more gets it with a warning.
pub const MAX_SUBSTEPS: u32 = 100_000;

/// What the controller chose, for the run summary.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepChoice {
    /// Highest natural frequency of the network (rad/s).
    pub omega_max: f64,
    /// Damping ratios of the least and most damped springs.
    pub zeta_range: (f64, f64),
    /// Largest stable `ω_max h` used (after the safety factor), if the integrator has a limit;
    /// for XPBD its accuracy bound [`XPBD_OMEGA_H`].
    pub limit: Option<f64>,
    /// Substeps per frame chosen (≥ 1).
    pub substeps: u32,
    /// Substeps were capped at [`MAX_SUBSTEPS`].
    pub capped: bool,
}

/// What the step choices read from a network: its highest natural frequency and its springs'
/// damping ratios. Taken once per gather; every integrator's floor follows from it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Network {
    /// Highest natural frequency (rad/s).
    pub omega_max: f64,
    /// Damping ratios of the least and most damped springs.
    pub zeta_range: (f64, f64),
}

impl Network {
    /// Estimates the network's frequency (grids through their window) and damping range.
    pub fn of(packed: &Packed) -> Self {
        let w0_max = packed
            .all_springs()
            .map(|s| s.omega0_sq())
            .fold(0.0, f64::max)
            .sqrt();
        // The network is at least as fast as its stiffest spring; power iteration approaches
        // the top from below, so take the larger.
        let omega_max = network_frequency(packed, 100).max(w0_max);
        let active = packed.all_springs().filter(|s| s.omega0_sq() > 0.0);
        let zeta_range = active
            .map(|s| s.zeta())
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), z| {
                (lo.min(z), hi.max(z))
            });
        let zeta_range = if zeta_range.0.is_finite() {
            zeta_range
        } else {
            (0.0, 0.0)
        };
        Self {
            omega_max,
            zeta_range,
        }
    }

    /// Substeps for a frame of `dt` with `integrator` on this network.
    pub fn choose(&self, integrator: Integrator, dt: f64) -> StepChoice {
        let (lo, hi) = self.zeta_range;
        let limit = match (
            stable_omega_h(integrator, lo),
            stable_omega_h(integrator, hi),
        ) {
            (Some(a), Some(b)) => Some(SAFETY * a.min(b)),
            _ if integrator == Integrator::Xpbd => Some(XPBD_OMEGA_H),
            _ => None,
        };
        self.choose_within(limit, dt)
    }

    /// Substeps for a frame of `dt` keeping `ω_max h` within `limit` (safety factor applied;
    /// `None`: no limit, one substep). The lab chooses its research integrators' steps with it.
    pub fn choose_within(&self, limit: Option<f64>, dt: f64) -> StepChoice {
        let Self {
            omega_max,
            zeta_range,
        } = *self;
        let (substeps, capped) = match limit {
            Some(c) if omega_max > 0.0 => {
                let k = (dt * omega_max / c).ceil().max(1.0);
                if k > MAX_SUBSTEPS as f64 {
                    (MAX_SUBSTEPS, true)
                } else {
                    (k as u32, false)
                }
            }
            _ => (1, false),
        };
        StepChoice {
            omega_max,
            zeta_range,
            limit,
            substeps,
            capped,
        }
    }
}

/// Substeps for a frame of `dt` with `integrator` on this network ([`Network::of`], then
/// [`Network::choose`]).
pub fn choose(packed: &Packed, integrator: Integrator, dt: f64) -> StepChoice {
    Network::of(packed).choose(integrator, dt)
}

/// The spring whose `h/h_c` lies closest to a whole number ≥ 1, if within `tolerance`: at
/// `h = n h_c` the closed form's impulse vanishes (even n) or reverses the stretch rate (odd n).
pub fn aliasing(packed: &Packed, h: f64, tolerance: f64) -> Option<(usize, f64)> {
    packed
        .all_springs()
        .enumerate()
        .map(|(k, s)| (k, s.step_ratio(h)))
        .filter(|&(_, r)| r >= 0.5 && (r - r.round()).abs() <= tolerance * r)
        .min_by(|a, b| {
            (a.1 - a.1.round())
                .abs()
                .total_cmp(&(b.1 - b.1.round()).abs())
        })
}

/// How many times fewer substeps the closed form's stability floor must need than symplectic
/// Euler's before it is chosen: its measured cost at equal substeps within the tolerance (the
/// pass after each substep that books its dampers, and the substeps the accuracy controller
/// adds for the energy it makes) is about twice symplectic Euler's on a damped cloth.
pub const CLOSED_FORM_MARGIN: f64 = 2.0;

/// The integrator for a scene that names none, and why: the one inside the tolerance at the
/// least cost. Both stability floors are estimated at the scene's damping; the closed form is
/// chosen where symplectic Euler would need more than [`CLOSED_FORM_MARGIN`] times its
/// substeps, symplectic Euler otherwise (on a 16×16 cloth at ζ = 1, 3, 10 and 30, symplectic
/// Euler took 1.2–1.3× the closed form's floor substeps and ran 2.0–4.7× faster within the
/// tolerance: NOTES.md, "The integrator chosen"). Both floors come from one estimate of the
/// network, taken on the simulation's own gather (grids kept whole: both candidates step them
/// so), so the choice costs no second copy of the cloth.
pub fn choose_integrator(network: &Network, dt: f64) -> (Integrator, String) {
    let se = network.choose(Integrator::SymplecticEuler, dt);
    let cf = network.choose(Integrator::Harmonic, dt);
    let zeta = se.zeta_range.1;
    let ratio = se.substeps as f64 / cf.substeps.max(1) as f64;
    if ratio > CLOSED_FORM_MARGIN {
        (
            Integrator::Harmonic,
            format!(
                "springs damped up to ζ = {zeta:.3}: symplectic Euler would need {} substeps a \
                 frame for stability, {ratio:.2}× the closed form's {}",
                se.substeps, cf.substeps
            ),
        )
    } else {
        (
            Integrator::SymplecticEuler,
            format!(
                "springs damped up to ζ = {zeta:.3}: symplectic Euler's {} substeps a frame for \
                 stability are {ratio:.2}× the closed form's {}, within its cost margin of \
                 {CLOSED_FORM_MARGIN}×",
                se.substeps, cf.substeps
            ),
        )
    }
}
