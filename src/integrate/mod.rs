#![doc = include_str!("MATH.md")]
// Not API: reachable from outside only through the hidden `internals` module.
#![allow(missing_docs)]

mod gauss_seidel;
pub(crate) mod grid;
pub mod harmonic;
pub mod implicit;
pub mod multigrid;
pub mod paper;
pub(crate) mod par;
mod particles;
pub mod xpbd;

use glam::DVec3;

use crate::buffers::{Packed, PackedSpring};
pub use crate::config::Integrator;
use crate::error::SimError;
use harmonic::Linear;
use paper::PaperSpring;
pub use particles::External;
use particles::{acceleration, particle_pass};
pub(crate) use particles::{euler_move, Accel, Constant};

/// Sweeps of `harmonic-sgs`, alternating direction, each applying 1/SGS_SWEEPS of the impulse.
pub const SGS_SWEEPS: usize = 2;

/// Whether any pass over this scene goes to rayon's pool.
pub fn runs_parallel(packed: &Packed) -> bool {
    packed.particle_count() >= par::PAR_MIN || packed.springs.len() >= par::PAR_MIN
}

/// Bands per large cloth grid in the grid pass: two per thread, for balance.
fn grid_bands() -> usize {
    2 * rayon::current_num_threads()
}

/// How a spring's relative velocity change is computed in the spring pass.
#[derive(Clone, Copy)]
enum Law<'a> {
    Linear(&'a [Linear]),
    /// `φ = p δ + q δ̇ + s a` with `a` the frozen relative acceleration from everything else.
    Forced(&'a [Linear], &'a [f64]),
    Paper(&'a [PaperSpring], f64),
}

/// How the particle pass turns summed velocity changes into a new state.
#[derive(Clone, Copy, PartialEq)]
pub(crate) enum Update {
    /// `v += Δv + g h; x += h v` (symplectic Euler, plain harmonic).
    VelocityFirst,
    /// `x += h v; v += Δv + g h`.
    PositionFirst,
    /// `x += h v + ½ g h² + ΣD n; v += Δv + g h` (harmonic with exact displacement).
    Exact,
    /// Algorithm 1 as printed: `v += h Δv + g h; x += h v`.
    PaperAlgorithm1,
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
    /// Gauss–Seidel integrators: the springs and coefficients in colour order.
    swept: Vec<gauss_seidel::SweepSpring>,
    paper: Vec<PaperSpring>,
    sdv: Vec<DVec3>,
    sdx: Vec<DVec3>,
    rk: Vec<Vec<DVec3>>,
    /// Forced variants: per-spring relative accelerations at h = 1, per-particle
    /// accelerations, and each spring's frozen relative acceleration from everything else.
    acc: Vec<Linear>,
    pacc: Vec<DVec3>,
    force: Vec<f64>,
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
            paper: Vec::new(),
            sdv: Vec::new(),
            sdx: Vec::new(),
            rk: Vec::new(),
            acc: Vec::new(),
            pacc: Vec::new(),
            force: Vec::new(),
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
        self.paper.clear();
        self.rk.clear();
        self.acc.clear();
        let forced = matches!(
            self.integrator,
            Integrator::HarmonicForced | Integrator::HarmonicForcedGs
        );
        if forced {
            self.acc.extend(
                packed
                    .springs
                    .iter()
                    .map(|s| harmonic::euler(s.omega0_sq(), s.alpha(), 1.0)),
            );
        }
        self.pacc.resize(if forced { n } else { 0 }, DVec3::ZERO);
        self.force.resize(if forced { m } else { 0 }, 0.0);
        match self.integrator {
            Integrator::HarmonicSgs => self.lin.extend(packed.springs.iter().map(|s| {
                let l = harmonic::harmonic(s.omega0_sq(), s.alpha(), h);
                let k = SGS_SWEEPS as f64;
                Linear {
                    p: l.p / k,
                    q: l.q / k,
                    r: 0.0,
                    s: 0.0,
                }
            })),
            Integrator::Harmonic
            | Integrator::HarmonicGs
            | Integrator::HarmonicForced
            | Integrator::HarmonicForcedGs => self.lin.extend(
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
            Integrator::Rk4 => {
                // Acceleration coefficients (h = 1); 10 state-sized scratch vectors.
                self.lin.extend(
                    packed
                        .springs
                        .iter()
                        .map(|s| harmonic::euler(s.omega0_sq(), s.alpha(), 1.0)),
                );
                self.rk = vec![vec![DVec3::ZERO; n]; 10];
            }
            Integrator::ImplicitEuler => self.implicit.resize(n, m),
            Integrator::ThetaMg => self.multigrid.prepare(packed, h),
            Integrator::Xpbd => self.xpbd.resize(n),
            Integrator::HarmonicPaper => {
                for (k, s) in packed.springs.iter().enumerate() {
                    if !s.mu.is_finite() {
                        // Both ends pinned: the spring never acts.
                        self.paper.push(PaperSpring {
                            omega0_sq: 1.0,
                            alpha: 0.0,
                            omega_d: 1.0,
                            scale: 0.0,
                            damped: false,
                        });
                        continue;
                    }
                    let ma = packed.mass(s.a as usize);
                    let mb = packed.mass(s.b as usize);
                    let p = PaperSpring::new(s.stiffness, s.damping, ma, mb).map_err(|e| {
                        SimError::PaperUndefined {
                            spring: k,
                            zeta: e.zeta,
                        }
                    })?;
                    self.paper.push(p);
                }
            }
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
                let law = Law::Linear(&self.lin);
                spring_pass(
                    &packed.springs,
                    &packed.x,
                    &packed.v,
                    law,
                    &mut self.sdv,
                    sdx,
                    false,
                );
                particle_pass(packed, &self.sdv, &self.sdx, g, h, update);
                if !packed.topology.grids.is_empty() {
                    self.grid.run(packed, &self.sdv, g, h, update);
                }
            }
            Integrator::HarmonicPaper => {
                spring_pass(
                    &packed.springs,
                    &packed.x,
                    &packed.v,
                    Law::Paper(&self.paper, h),
                    &mut self.sdv,
                    None,
                    false,
                );
                particle_pass(packed, &self.sdv, &[], g, h, Update::PaperAlgorithm1);
            }
            Integrator::Rk4 => self.rk4(packed, g, h),
            Integrator::HarmonicGs => {
                gauss_seidel::add_gravity(packed, g, h);
                gauss_seidel::sweep(packed, &self.swept, None, false);
                gauss_seidel::drift(packed, h);
            }
            Integrator::HarmonicSgs => {
                gauss_seidel::add_gravity(packed, g, h);
                for k in 0..SGS_SWEEPS {
                    gauss_seidel::sweep(packed, &self.swept, None, k % 2 == 1);
                }
                gauss_seidel::drift(packed, h);
            }
            Integrator::HarmonicForced => {
                self.freeze_forcing(packed, g);
                let law = Law::Forced(&self.lin, &self.force);
                spring_pass(
                    &packed.springs,
                    &packed.x,
                    &packed.v,
                    law,
                    &mut self.sdv,
                    None,
                    true,
                );
                particle_pass(packed, &self.sdv, &[], g, h, Update::VelocityFirst);
            }
            Integrator::HarmonicForcedGs => {
                self.freeze_forcing(packed, g);
                // Gravity is in the forcing; it reaches the velocities after the sweep.
                gauss_seidel::sweep(packed, &self.swept, Some(&self.force), false);
                gauss_seidel::add_gravity(packed, g, h);
                gauss_seidel::drift(packed, h);
            }
            Integrator::ImplicitEuler => self.implicit.step(packed, g, h),
            Integrator::ThetaMg => self.multigrid.step(packed, g, h),
            Integrator::Xpbd => self.xpbd.step(packed, g, h),
        }
        Ok(())
    }

    /// For each spring, the relative acceleration along its axis from every force but its
    /// own (other springs, gravity), at the start of the step.
    fn freeze_forcing(&mut self, packed: &Packed, g: External<'_>) {
        spring_pass(
            &packed.springs,
            &packed.x,
            &packed.v,
            Law::Linear(&self.acc),
            &mut self.sdv,
            None,
            false,
        );
        acceleration(packed, &self.sdv, g, &mut self.pacc);
        let (springs, x, sacc, pacc) = (&packed.springs, &packed.x, &self.sdv, &self.pacc);
        par::each(&mut self.force, |k, out| {
            let s = &springs[k];
            let (a, b) = (s.a as usize, s.b as usize);
            let n = (x[b] - x[a]).normalize();
            // Remove this spring's own share: +wb·sacc at b, −wa·sacc at a.
            let other_b = pacc[b] - s.wb * sacc[k];
            let other_a = pacc[a] + s.wa * sacc[k];
            let f = n.dot(other_b - other_a);
            // A NaN from a degenerate neighbour is dropped (the quarantine's guard); the
            // degenerate spring itself is caught by the guarded pass that follows.
            *out = if f.is_finite() { f } else { 0.0 };
        });
    }

    fn rk4(&mut self, packed: &mut Packed, g: External<'_>, h: f64) {
        let [x0, v0, xt, vt, ax, av, bx, bv, sx, sv] = &mut self.rk[..] else {
            unreachable!("prepare sizes rk to 10 vectors")
        };
        x0.copy_from_slice(&packed.x);
        v0.copy_from_slice(&packed.v);
        // Stage k: (xt, vt) is the stage state; (ax, av) its derivative; (sx, sv) the weighted sum.
        for (stage, (c, w)) in [(0.0, 1.0), (0.5, 2.0), (0.5, 2.0), (1.0, 1.0)]
            .into_iter()
            .enumerate()
        {
            if stage == 0 {
                xt.copy_from_slice(x0);
                vt.copy_from_slice(v0);
            } else {
                for i in 0..x0.len() {
                    xt[i] = x0[i] + c * h * ax[i];
                    vt[i] = v0[i] + c * h * av[i];
                }
            }
            spring_pass(
                &packed.springs,
                xt,
                vt,
                Law::Linear(&self.lin),
                &mut self.sdv,
                None,
                true,
            );
            acceleration(packed, &self.sdv, g, bv);
            bx.copy_from_slice(vt);
            for i in 0..x0.len() {
                if stage == 0 {
                    sx[i] = w * bx[i];
                    sv[i] = w * bv[i];
                } else {
                    sx[i] += w * bx[i];
                    sv[i] += w * bv[i];
                }
            }
            std::mem::swap(ax, bx);
            std::mem::swap(av, bv);
        }
        for i in 0..x0.len() {
            if packed.inv_mass[i] != 0.0 {
                packed.x[i] = x0[i] + h / 6.0 * sx[i];
                packed.v[i] = v0[i] + h / 6.0 * sv[i];
            }
        }
    }
}

/// Geometry of one spring from `a` to `b`: unit axis `n`, stretch `δ` and stretch rate `δ̇`.
#[inline(always)]
pub(crate) fn axial(xa: DVec3, xb: DVec3, va: DVec3, vb: DVec3, rest: f64) -> (DVec3, f64, f64) {
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
pub(crate) fn spring_response(
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
pub(crate) fn guard(dv: DVec3, s: &PackedSpring, x: &[DVec3], va: DVec3, vb: DVec3) -> DVec3 {
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

/// One spring's change of relative velocity: the axis `n` and `φ`.
#[inline(always)]
fn spring_update(
    springs: &[PackedSpring],
    x: &[DVec3],
    v: &[DVec3],
    law: Law<'_>,
    k: usize,
) -> (DVec3, f64) {
    let s = &springs[k];
    let (va, vb) = (v[s.a as usize], v[s.b as usize]);
    match law {
        Law::Linear(lin) => spring_response(s, x, va, vb, &lin[k]),
        Law::Forced(lin, force) => {
            let l = &lin[k];
            let (n, phi) = spring_response(s, x, va, vb, l);
            (n, phi + l.s * force[k])
        }
        Law::Paper(paper, h) => {
            let (n, delta, delta_dot) = stretch(s, x, va, vb);
            (n, paper[k].phi(delta, delta_dot, h))
        }
    }
}

/// Pass 1: each spring writes its velocity change `φ n` (and, for the exact-displacement
/// update, its displacement `D n = (r δ + s δ̇) n` into `sdx`).
fn spring_pass(
    springs: &[PackedSpring],
    x: &[DVec3],
    v: &[DVec3],
    law: Law<'_>,
    sdv: &mut [DVec3],
    sdx: Option<&mut [DVec3]>,
    guarded: bool,
) {
    match (sdx, law) {
        (Some(sdx), Law::Linear(lin)) => par::each2(sdv, sdx, |k, dv, dx| {
            let (s, l) = (&springs[k], &lin[k]);
            let (n, delta, delta_dot) = stretch(s, x, v[s.a as usize], v[s.b as usize]);
            *dv = l.phi(delta, delta_dot) * n;
            *dx = (l.r * delta + l.s * delta_dot) * n;
        }),
        // Passes that chain within a substep (RK4's stages, the forced step after its
        // forcing) are guarded. A lone Jacobi pass is not: it reads only the state at the
        // start of the substep, which the quarantine check left finite, so a NaN reaches only
        // the degenerate spring's own ends. (The device batches a frame's substeps, and
        // guards this pass.)
        _ if guarded => par::each(sdv, |k, out| {
            let (n, phi) = spring_update(springs, x, v, law, k);
            let s = &springs[k];
            *out = guard(phi * n, s, x, v[s.a as usize], v[s.b as usize]);
        }),
        _ => par::each(sdv, |k, out| {
            let (n, phi) = spring_update(springs, x, v, law, k);
            *out = phi * n;
        }),
    }
}
