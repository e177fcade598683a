//! Symplectic and explicit Euler, and the closed form (`harmonic`, Jacobi), over cloth grids
//! ([`PackedGrid`]) with no memory per spring.
//!
//! Every link points forward in row-major order (gather makes it so), so a sweep over the
//! rows evaluates each spring once, at its earlier end, and adds its change to both ends in a
//! ring of the next `reach + 1` rows. A row is complete once the sweep has passed it; it then
//! moves, and is written back at once: no later spring reads it. Bands of rows run in
//! parallel, each also evaluating the springs that reach into it from the `reach` rows above
//! (their old state copied before the pass, as are the rows below it). Scratch is a few rows
//! per band instead of a buffer per spring or per particle, and each particle sums the same
//! terms in the same order whatever the banding (so whatever the thread count).
//!
//! The hot loop runs one link over a whole row: old state and sums are held per coordinate
//! (structure of arrays), so the compiler vectorises it across columns; on x86-64 the band is
//! also compiled for AVX2 and AVX-512 and the widest the CPU has is picked at run time. Every
//! lane does the scalar operations in the scalar order (no fused multiply-add), so each
//! build gives the same bits.

use std::ops::Range;

use glam::DVec3;
use rayon::prelude::*;

use super::harmonic::{self, Linear};
use super::{axial, euler_move, par, Accel, Constant, External, Update};
use crate::buffers::{Incidence, Packed, PackedGrid};
use crate::components::GridLink;

mod band;
use band::*;

/// Old `(x, v)` of a particle.
type State = (DVec3, DVec3);

/// Per coordinate: x, y, z.
type Soa3 = [Vec<f64>; 3];

/// A band of grid rows and its scratch.
#[derive(Clone, Debug, Default)]
struct Band {
    rows: Range<usize>,
    /// Old state of the `reach` rows above the band (rows before row 0 unused).
    above: Vec<State>,
    /// Old state of the `reach` rows below it (rows past the last unused).
    below: Vec<State>,
    /// Old positions and velocities of the `reach + 1` rows the sweep reads, per coordinate.
    x: Soa3,
    v: Soa3,
    /// Summed velocity changes of the same rows.
    ring: Soa3,
    /// One link's `φ n` along a row.
    f: Soa3,
    /// With the audit: the dampers' impulses summed per particle over the same rows, one
    /// link's damper impulse `q δ̇ n` along a row, a row of ones, and each of the band's rows'
    /// damper loss this substep (their impulses' work over each particle's mean velocity).
    ring_d: Soa3,
    fd: Soa3,
    ones: Vec<f64>,
    loss: Vec<f64>,
}

/// A link's Euler coefficients for step `h` (p = −κ h, q = −c h), in force form (μ = 1): the
/// particle's own 1/m scales the result. The GPU's `grid_pass` takes the same.
pub(crate) fn link_coefficients(l: &GridLink, h: f64) -> Linear {
    harmonic::euler(l.stiffness, 0.5 * l.damping, h)
}

/// A spring's closed-form coefficients in force form for two free ends of mass `m0`
/// (μ = m0/2): `f = μ φ`, so each end's change is `∓ f n / m`, as for the Euler links. The
/// closed form is not linear in 1/μ, so the pass holds it for one mass only ([`Fix`]).
fn harmonic_link(stiffness: f64, damping: f64, m0: f64, h: f64) -> Linear {
    let mu = 0.5 * m0;
    let l = harmonic::harmonic(stiffness / mu, damping / (2.0 * mu), h);
    Linear {
        p: mu * l.p,
        q: mu * l.q,
        r: 0.0,
        s: 0.0,
    }
}

/// What a grid pass applies to its links.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum GridLaw {
    /// Symplectic or explicit Euler: force-form coefficients, whatever the masses.
    Euler,
    /// The closed form (Jacobi, plain update), held for one free mass ([`nominal_inv_mass`]).
    Harmonic,
}

/// A grid spring whose ends are not both of the grid's nominal mass (a pinned end included),
/// under [`GridLaw::Harmonic`]: the pass applied the nominal force `f0`, the spring's own
/// closed form wants `w φ` at each end, so the difference is added after the pass. Each is
/// linear in the start-of-step state, so the sum is the spring's exact change. A cloth of one
/// mass has only its pins' springs here; one of many masses has most of its springs here, run
/// one after the other (correct, but slower than the springs one by one in parallel).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Fix {
    pub(crate) a: usize,
    pub(crate) b: usize,
    pub(crate) rest: f64,
    /// The spring's own closed form, relative (`φ`), and the nominal one in force form (`f0`).
    pub(crate) own: Linear,
    pub(crate) nominal: Linear,
    /// `μ/m` of each end (0 where pinned) and its inverse mass.
    pub(crate) wa: f64,
    pub(crate) wb: f64,
    pub(crate) ia: f64,
    pub(crate) ib: f64,
}

impl Fix {
    /// The velocity corrections of ends a and b from the start-of-step state.
    fn dv(&self, x: &[DVec3], v: &[DVec3]) -> (DVec3, DVec3) {
        let (n, delta, delta_dot) = axial(x[self.a], x[self.b], v[self.a], v[self.b], self.rest);
        let (phi, f0) = (
            self.own.phi(delta, delta_dot),
            self.nominal.phi(delta, delta_dot),
        );
        (
            -(self.wa * phi - self.ia * f0) * n,
            (self.wb * phi - self.ib * f0) * n,
        )
    }
}

/// The closed form on grid `g` for step `h`, as the CPU pass and the device's `grid_pass` both
/// apply it: each link's coefficients for the nominal mass, and the springs that need a [`Fix`].
pub(crate) fn harmonic_grid(g: &PackedGrid, inv: &[f64], h: f64) -> (Vec<Linear>, Vec<Fix>) {
    let w0 = nominal_inv_mass(g, inv);
    let m0 = if w0 > 0.0 { 1.0 / w0 } else { 1.0 };
    let fixes = g
        .springs(inv)
        .filter(|s| {
            let (ia, ib) = (inv[s.a as usize], inv[s.b as usize]);
            (ia != w0 || ib != w0) && (ia != 0.0 || ib != 0.0)
        })
        .map(|s| Fix {
            a: s.a as usize,
            b: s.b as usize,
            rest: s.rest,
            own: harmonic::harmonic(s.omega0_sq(), s.alpha(), h),
            nominal: harmonic_link(s.stiffness, s.damping, m0, h),
            wa: s.wa,
            wb: s.wb,
            ia: inv[s.a as usize],
            ib: inv[s.b as usize],
        })
        .collect();
    let links = g
        .links
        .iter()
        .map(|l| harmonic_link(l.stiffness, l.damping, m0, h))
        .collect();
    (links, fixes)
}

/// The inverse mass the pass holds the closed form for: the grid's centre particle's, or the
/// first free one's if the centre is pinned (0 if none is free).
fn nominal_inv_mass(g: &PackedGrid, inv_mass: &[f64]) -> f64 {
    let range = g.range();
    let centre = g.base as usize + (g.rows / 2 * g.cols + g.cols / 2) as usize;
    if inv_mass[centre] != 0.0 {
        return inv_mass[centre];
    }
    inv_mass[range]
        .iter()
        .copied()
        .find(|&w| w != 0.0)
        .unwrap_or(0.0)
}

/// The vector unit the band is compiled for. Every level gives the same bits (no fused
/// multiply-add, each lane in scalar order); `tests` hold them to it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum Vector {
    #[default]
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Vector {
    /// Every level this CPU runs, narrowest first.
    pub(crate) fn available() -> Vec<Self> {
        #[allow(unused_mut)]
        let mut v = vec![Self::Portable];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                v.push(Self::Avx2);
            }
            if std::arch::is_x86_feature_detected!("avx512f") {
                v.push(Self::Avx512);
            }
        }
        v
    }

    /// The widest this CPU runs, or the level `HARMONIC_SIMD` names (`portable`, `avx2`,
    /// `avx512`) when the CPU runs it: to measure what each level buys. Decided once.
    pub(crate) fn chosen() -> Self {
        static CHOSEN: std::sync::OnceLock<Vector> = std::sync::OnceLock::new();
        *CHOSEN.get_or_init(Self::decide)
    }

    fn decide() -> Self {
        let mut levels = Self::available();
        let named = std::env::var("HARMONIC_SIMD").ok();
        if let Some(k) = levels
            .iter()
            .position(|l| named.as_deref() == Some(l.name()))
        {
            return levels[k];
        }
        levels.pop().unwrap_or_default()
    }

    /// Whether the level has eight f64 lanes (AVX-512).
    pub(crate) fn lanes_of_8(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self == Self::Avx512 {
            return true;
        }
        false
    }

    fn name(self) -> &'static str {
        match self {
            Self::Portable => "portable",
            #[cfg(target_arch = "x86_64")]
            Self::Avx2 => "avx2",
            #[cfg(target_arch = "x86_64")]
            Self::Avx512 => "avx512",
        }
    }
}

/// Per grid: the links' coefficients for the prepared step, and the bands.
#[derive(Clone, Debug, Default)]
pub(crate) struct GridPass {
    grids: Vec<(Vec<Linear>, Vec<Band>)>,
    vector: Vector,
    /// Corrections of the springs off the nominal mass ([`GridLaw::Harmonic`] only), and
    /// their velocity changes for the current step.
    fixes: Vec<Fix>,
    fix_dv: Vec<(DVec3, DVec3)>,
    /// Whether the pass books its dampers' loss ([`Self::damper_loss`]).
    pub(crate) audit: bool,
}

fn soa(len: usize) -> Soa3 {
    [vec![0.0; len], vec![0.0; len], vec![0.0; len]]
}

impl GridPass {
    /// Coefficients of `law` for step `h` and scratch for `packed`'s grids (`bands` per large
    /// grid).
    pub(crate) fn prepare(&mut self, packed: &Packed, h: f64, bands: usize, law: GridLaw) {
        // Euler links book their dampers' work in the pass (the energy audit); the closed
        // form's exact loss is booked after the substep.
        let audit = law == GridLaw::Euler
            && (packed.topology.grids.iter()).any(|g| g.links.iter().any(|l| l.damping != 0.0));
        self.audit = audit;
        self.grids.clear();
        self.fixes.clear();
        self.vector = Vector::chosen();
        for g in &packed.topology.grids {
            let lin = match law {
                GridLaw::Euler => g.links.iter().map(|l| link_coefficients(l, h)).collect(),
                GridLaw::Harmonic => {
                    let (lin, fixes) = harmonic_grid(g, &packed.inv_mass, h);
                    self.fixes.extend(fixes);
                    lin
                }
            };
            let (cols, rows, reach) = (g.cols as usize, g.rows as usize, g.reach());
            let count = if g.range().len() < par::PAR_MIN {
                1
            } else {
                bands.clamp(1, rows)
            };
            let per = rows.div_ceil(count);
            let bands = (0..rows)
                .step_by(per)
                .map(|r0| Band {
                    rows: r0..(r0 + per).min(rows),
                    above: vec![(DVec3::ZERO, DVec3::ZERO); reach * cols],
                    below: vec![(DVec3::ZERO, DVec3::ZERO); reach * cols],
                    x: soa((reach + 1) * cols),
                    v: soa((reach + 1) * cols),
                    ring: soa((reach + 1) * cols),
                    f: soa(cols),
                    ring_d: soa(if audit { (reach + 1) * cols } else { 0 }),
                    fd: soa(if audit { cols } else { 0 }),
                    ones: vec![1.0; if audit { cols } else { 0 }],
                    loss: vec![0.0; if audit { per.min(rows - r0) } else { 0 }],
                })
                .collect();
            self.grids.push((lin, bands));
        }
        self.fix_dv
            .resize(self.fixes.len(), (DVec3::ZERO, DVec3::ZERO));
    }

    /// One substep of every grid's particles: `Δv` from its springs plus the incidence sum of
    /// the other springs' `sdv`, then `update`.
    pub(crate) fn run(
        &mut self,
        packed: &mut Packed,
        sdv: &[DVec3],
        g: External<'_>,
        h: f64,
        update: Update,
    ) {
        // Read before the pass moves anything.
        for (f, dv) in self.fixes.iter().zip(&mut self.fix_dv) {
            *dv = f.dv(&packed.x, &packed.v);
        }
        self.run_pass(packed, sdv, g, h, update);
        // `v += Δv, x += h Δv` is what the velocity-first move does with a summand it gets
        // late; the harmonic law moves velocity first.
        debug_assert!(self.fixes.is_empty() || update == Update::VelocityFirst);
        for (f, &(dva, dvb)) in self.fixes.iter().zip(&self.fix_dv) {
            for (i, dv) in [(f.a, dva), (f.b, dvb)] {
                if packed.inv_mass[i] != 0.0 {
                    packed.v[i] += dv;
                    packed.x[i] += h * dv;
                }
            }
        }
    }

    fn run_pass(
        &mut self,
        packed: &mut Packed,
        sdv: &[DVec3],
        g: External<'_>,
        h: f64,
        update: Update,
    ) {
        let Packed {
            topology,
            x,
            v,
            inv_mass,
            incidence,
            ..
        } = packed;
        let grids = &topology.grids;
        let (Some(first), Some(last)) = (grids.first(), grids.last()) else {
            return;
        };
        let shared = Shared {
            audit: self.audit,
            vector: self.vector,
            inv_mass,
            incidence,
            sdv,
            g,
            h,
            update,
        };
        // Grids hold disjoint, increasing packed ranges (gather checks it): many small cloths
        // run side by side, each on one thread.
        let span = first.range().start..last.range().end;
        let total = grids.iter().map(|g| g.range().len()).sum::<usize>();
        let (x, v) = (&mut x[span.clone()], &mut v[span.clone()]);
        run_grids(
            &shared,
            grids,
            &mut self.grids,
            x,
            v,
            span.start,
            total >= par::PAR_MIN,
        );
    }
}

impl GridPass {
    /// What the grids' dampers dissipated in the last substep, summed row by row in order,
    /// so the same whatever the banding (0 unless [`Self::audit`]).
    pub(crate) fn damper_loss(&self) -> f64 {
        (self.grids.iter().flat_map(|(_, bands)| bands))
            .flat_map(|b| &b.loss)
            .sum()
    }
}

/// What every grid of a pass shares.
struct Shared<'a> {
    audit: bool,
    vector: Vector,
    /// Every particle's inverse mass.
    inv_mass: &'a [f64],
    incidence: &'a Incidence,
    sdv: &'a [DVec3],
    /// The external acceleration (packed order).
    g: External<'a>,
    h: f64,
    update: Update,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::buffers::GatherOptions;

    #[test]
    fn a_links_columns_are_those_with_both_ends_in_the_grid() {
        for (cols, dc, want) in [
            (16, 0, 0..16),
            (16, 2, 0..14),
            (16, -1, 1..16),
            (16, 16, 0..0),
            (1, 2, 0..0),
            (2, -3, 2..2),
            (3, -2, 2..3),
        ] {
            let got = columns(cols, dc);
            assert_eq!(got, want, "{cols} columns, dc {dc}");
            // Independently: the c whose c + dc is a column.
            let brute: Vec<usize> = (0..cols)
                .filter(|&c| (0..cols as isize).contains(&(c as isize + dc)))
                .collect();
            assert_eq!(got.clone().collect::<Vec<_>>(), brute);
        }
    }

    /// Every vector level steps a cloth to the same bits, in three bands (halo rows; every
    /// grid is over `par::PAR_MIN` particles): rows of 70 (whole chunks and an overlapping last
    /// one), 16 (exact chunks for some links), 9 (one chunk and an overlap of 7) and 5 (padded).
    #[test]
    fn every_vector_unit_gives_the_same_bits() {
        for (cols, rows) in [(70, 70), (16, 300), (9, 500), (5, 900)] {
            let mut scene = crate::internals::hanging_cloth(cols);
            scene.cloths[0].resolution = (cols, rows);
            let built = scene.build();
            let options = GatherOptions {
                keep_grids: true,
                colouring: false,
            };
            let mut start = Packed::gather_with(&built.world, options).unwrap();
            assert_eq!(start.topology.grids.len(), 1);
            // A twist, so every spring is stretched and moving.
            for (i, (x, v)) in start.x.iter_mut().zip(&mut start.v).enumerate() {
                let t = i as f64 * 0.37;
                *x += 0.01 * DVec3::new(t.sin(), t.cos(), (2.0 * t).sin());
                *v = DVec3::new((3.0 * t).cos(), t.sin(), 0.5);
            }
            let (g, h) = (DVec3::new(0.0, -9.81, 0.0), 1e-3);
            let run = |vector: Vector| {
                let mut p = start.clone();
                let mut pass = GridPass::default();
                pass.prepare(&p, h, 3, GridLaw::Euler);
                pass.vector = vector;
                assert_eq!(pass.grids[0].1.len(), 3);
                for _ in 0..20 {
                    pass.run(&mut p, &[], External::Uniform(g), h, Update::VelocityFirst);
                }
                (p.x, p.v)
            };
            let reference = run(Vector::Portable);
            assert!(reference.0.iter().all(|x| x.is_finite()));
            assert_ne!(reference.0, start.x);
            for level in Vector::available() {
                let (x, v) = run(level);
                let same = |a: &[DVec3], b: &[DVec3]| {
                    a.iter().zip(b).all(|(p, q)| {
                        p.to_array().map(f64::to_bits) == q.to_array().map(f64::to_bits)
                    })
                };
                assert!(
                    same(&x, &reference.0) && same(&v, &reference.1),
                    "{cols}×{rows}: {level:?}"
                );
            }
        }
    }
}
