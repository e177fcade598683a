#![doc = include_str!("MATH.md")]
// Not API: reachable from outside only through the hidden `internals` module.
#![allow(missing_docs)]

pub mod gauss_seidel;
pub(crate) mod grid;
pub mod harmonic;
pub mod implicit;
pub mod multigrid;
pub mod par;
mod particles;
pub mod xpbd;

use glam::DVec3;

use crate::buffers::{Packed, PackedSpring};
pub use crate::config::Integrator;
use crate::error::SimError;
use harmonic::Linear;
pub(crate) use particles::{euler_move, Accel, Constant};
pub use particles::{particle_pass, External};

/// Whether any pass over this scene goes to rayon's pool.
pub fn runs_parallel(packed: &Packed) -> bool {
    packed.particle_count() >= par::PAR_MIN || packed.springs.len() >= par::PAR_MIN
}

/// Bands per large cloth grid in the grid pass: two per thread, for balance.
fn grid_bands() -> usize {
    2 * rayon::current_num_threads()
}

/// How the particle pass turns summed velocity changes into a new state.
#[derive(Clone, Copy, PartialEq)]
pub enum Update {
    /// `v += Δv + g h; x += h v` (symplectic Euler, plain harmonic).
    VelocityFirst,
    /// `x += h v; v += Δv + g h`.
    PositionFirst,
    /// `x += h v + ½ g h² + ΣD n; v += Δv + g h` (harmonic with exact displacement).
    Exact,
}

/// Per-scene solver state: step coefficients for the current `h` and scratch, sized at gather.
#[derive(Clone, Debug)]
pub struct Solver {
    pub integrator: Integrator,
    pub exact_displacement: bool,
    pub gravity: DVec3,
    h: f64,
    /// (particles, springs) the scratch was sized for.
    sized_for: (usize, usize),
    lin: Vec<Linear>,
    /// Gauss–Seidel: the springs and coefficients in colour order.
    swept: Vec<gauss_seidel::SweepSpring>,
    sdv: Vec<DVec3>,
    sdx: Vec<DVec3>,
    implicit: implicit::Implicit,
    multigrid: multigrid::Multigrid,
    xpbd: xpbd::Xpbd,
    grid: grid::GridPass,
}

impl Solver {
    pub fn new(integrator: Integrator, exact_displacement: bool, gravity: DVec3) -> Self {
        Self {
            integrator,
            exact_displacement,
            gravity,
            h: f64::NAN,
            sized_for: (0, 0),
            lin: Vec::new(),
            swept: Vec::new(),
            sdv: Vec::new(),
            sdx: Vec::new(),
            implicit: implicit::Implicit::default(),
            multigrid: multigrid::Multigrid::default(),
            xpbd: xpbd::Xpbd::default(),
            grid: grid::GridPass::default(),
        }
    }

    /// Per-spring step coefficients for the prepared `h` (Jacobi and Gauss–Seidel integrators;
    /// empty for the others). The GPU back end uploads these.
    pub fn coefficients(&self) -> &[Linear] {
        &self.lin
    }

    /// Whether the grid pass books its dampers' loss itself ([`Self::grid_damper_loss`]).
    pub fn grid_audits(&self) -> bool {
        self.grid.audit
    }

    /// What the cloth grids' dampers dissipated in the last substep, when the grid pass books
    /// it (Euler links; 0 otherwise).
    pub fn grid_damper_loss(&self) -> f64 {
        if self.grid.audit {
            self.grid.damper_loss()
        } else {
            0.0
        }
    }

    /// Forgets the coefficients, so the next [`Self::prepare`] recomputes them (after a gather).
    pub fn invalidate(&mut self) {
        self.h = f64::NAN;
    }

    /// Sizes scratch and computes step coefficients for `h`. Call after every gather and
    /// whenever `h` changes; a no-op when nothing did.
    pub fn prepare(&mut self, packed: &Packed, h: f64) -> Result<(), SimError> {
        let m = packed.springs.len();
        let n = packed.particle_count();
        if self.h == h && self.sized_for == (n, m) {
            return Ok(());
        }
        if !packed.topology.grids.is_empty()
            && !self.integrator.runs_on_grids(self.exact_displacement)
        {
            return Err(SimError::GridsUnsupported(self.integrator));
        }
        if !packed.topology.grids.is_empty() {
            let law = if self.integrator == Integrator::Harmonic {
                grid::GridLaw::Harmonic
            } else {
                grid::GridLaw::Euler
            };
            self.grid.prepare(packed, h, grid_bands(), law);
        }
        self.sdv.resize(m, DVec3::ZERO);
        let disp = self.integrator == Integrator::Harmonic && self.exact_displacement;
        self.sdx.resize(if disp { m } else { 0 }, DVec3::ZERO);
        self.lin.clear();
        match self.integrator {
            Integrator::Harmonic | Integrator::HarmonicGs => self.lin.extend(
                packed
                    .springs
                    .iter()
                    .map(|s| harmonic::harmonic(s.omega0_sq(), s.alpha(), h)),
            ),
            Integrator::SymplecticEuler | Integrator::ExplicitEuler => self.lin.extend(
                packed
                    .springs
                    .iter()
                    .map(|s| harmonic::euler(s.omega0_sq(), s.alpha(), h)),
            ),
            Integrator::ImplicitEuler => self.implicit.resize(n, m),
            Integrator::ThetaMg => self.multigrid.prepare(packed, h),
            Integrator::Xpbd => self.xpbd.resize(n),
        }
        self.swept.clear();
        if self.integrator.sweeps() {
            gauss_seidel::order(packed, &self.lin, &mut self.swept);
        }
        self.h = h;
        self.sized_for = (n, m);
        Ok(())
    }

    /// Advances the packed state by one substep `h` (allocates nothing).
    pub fn substep(&mut self, packed: &mut Packed, h: f64) -> Result<(), SimError> {
        self.substep_with(packed, h, None)
    }

    /// As [`Self::substep`], with `accel` (packed order, gravity included) for the external
    /// acceleration instead of gravity alone.
    pub fn substep_with(
        &mut self,
        packed: &mut Packed,
        h: f64,
        accel: Option<&[DVec3]>,
    ) -> Result<(), SimError> {
        self.prepare(packed, h)?;
        let g = accel.map_or(External::Uniform(self.gravity), External::PerParticle);
        match self.integrator {
            Integrator::Harmonic | Integrator::SymplecticEuler | Integrator::ExplicitEuler => {
                // One pass shape; the coefficients (set in `prepare`) and the update differ.
                let update = match self.integrator {
                    Integrator::Harmonic if self.exact_displacement => Update::Exact,
                    Integrator::ExplicitEuler => Update::PositionFirst,
                    _ => Update::VelocityFirst,
                };
                let sdx = (update == Update::Exact).then_some(&mut self.sdx[..]);
                spring_pass(
                    &packed.springs,
                    &packed.x,
                    &packed.v,
                    &self.lin,
                    &mut self.sdv,
                    sdx,
                );
                particle_pass(packed, &self.sdv, &self.sdx, g, h, update);
                if !packed.topology.grids.is_empty() {
                    self.grid.run(packed, &self.sdv, g, h, update);
                }
            }
            Integrator::HarmonicGs => {
                gauss_seidel::add_gravity(packed, g, h);
                gauss_seidel::sweep(packed, &self.swept, None, false);
                gauss_seidel::drift(packed, h);
            }
            Integrator::ImplicitEuler => self.implicit.step(packed, g, h),
            Integrator::ThetaMg => self.multigrid.step(packed, g, h),
            Integrator::Xpbd => self.xpbd.step(packed, g, h),
        }
        Ok(())
    }
}

/// Geometry of one spring from `a` to `b`: unit axis `n`, stretch `δ` and stretch rate `δ̇`.
#[inline(always)]
pub fn axial(xa: DVec3, xb: DVec3, va: DVec3, vb: DVec3, rest: f64) -> (DVec3, f64, f64) {
    let d = xb - xa;
    let len = d.length();
    // One division, not three (a large share of the grid pass's time).
    let n = d * (1.0 / len);
    let delta = len - rest;
    let delta_dot = n.dot(vb - va);
    (n, delta, delta_dot)
}

#[inline(always)]
fn stretch(s: &PackedSpring, x: &[DVec3], va: DVec3, vb: DVec3) -> (DVec3, f64, f64) {
    axial(x[s.a as usize], x[s.b as usize], va, vb, s.rest)
}

/// The unit axis `n` and `φ = p δ + q δ̇` of one spring: the hot line of every Jacobi and
/// Gauss–Seidel step. `spring_response` in shaders/integrate.wgsl mirrors it.
#[inline(always)]
pub fn spring_response(
    s: &PackedSpring,
    x: &[DVec3],
    va: DVec3,
    vb: DVec3,
    l: &Linear,
) -> (DVec3, f64) {
    let (n, delta, delta_dot) = stretch(s, x, va, vb);
    (n, l.phi(delta, delta_dot))
}

/// The quarantine's guard on one spring's velocity change `dv = φ n` (`guard` in
/// shaders/integrate.wgsl mirrors it). A finite change passes. A non-finite one from finite
/// ends (the spring degenerated to a point, or overflowed) becomes NaN, which marks both ends
/// for the quarantine after the substep. One caused by an end that is already non-finite is
/// dropped, so a sweep or a frame of device substeps carries it no further.
#[inline(always)]
pub fn guard(dv: DVec3, s: &PackedSpring, x: &[DVec3], va: DVec3, vb: DVec3) -> DVec3 {
    // One test for the common case: the sum is finite only if every component is.
    if (dv.x + dv.y + dv.z).is_finite() {
        dv
    } else if x[s.a as usize].is_finite()
        && x[s.b as usize].is_finite()
        && va.is_finite()
        && vb.is_finite()
    {
        DVec3::NAN
    } else {
        DVec3::ZERO
    }
}

/// Pass 1: each spring writes its velocity change `φ n` (and, for the exact-displacement
/// update, its displacement `D n = (r δ + s δ̇) n` into `sdx`). Unguarded: it reads only the
/// state at the start of the substep, which the quarantine check left finite, so a NaN reaches
/// only the degenerate spring's own ends. (The device batches a frame's substeps, and guards
/// this pass.)
fn spring_pass(
    springs: &[PackedSpring],
    x: &[DVec3],
    v: &[DVec3],
    lin: &[Linear],
    sdv: &mut [DVec3],
    sdx: Option<&mut [DVec3]>,
) {
    match sdx {
        Some(sdx) => par::each2(sdv, sdx, |k, dv, dx| {
            let (s, l) = (&springs[k], &lin[k]);
            let (n, delta, delta_dot) = stretch(s, x, v[s.a as usize], v[s.b as usize]);
            *dv = l.phi(delta, delta_dot) * n;
            *dx = (l.r * delta + l.s * delta_dot) * n;
        }),
        None => par::each(sdv, |k, out| {
            let s = &springs[k];
            let (n, phi) = spring_response(s, x, v[s.a as usize], v[s.b as usize], &lin[k]);
            *out = phi * n;
        }),
    }
}
