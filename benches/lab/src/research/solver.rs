//! The research integrators' steps over the engine's packed buffers, built from the engine's
//! own pieces: the closed form's coefficients (`harmonic::harmonic`, `harmonic::euler`), the
//! spring geometry and the quarantine's guard (`axial`, `guard`), the particle pass and the
//! Gauss–Seidel sweep.

use harmonic::glam::DVec3;
use harmonic::internals::buffers::{Packed, PackedSpring};
use harmonic::internals::integrate::gauss_seidel::{self, SweepSpring};
use harmonic::internals::integrate::harmonic::{self as closed, Linear};
use harmonic::internals::integrate::{axial, guard, par, particle_pass, External, Update};

use super::paper::PaperSpring;
use super::{Research, StepError, SGS_SWEEPS};

/// Per-scene state of a research integrator: coefficients for the current `h` and scratch.
#[derive(Clone, Debug)]
pub struct Solver {
    method: Research,
    gravity: DVec3,
    h: f64,
    /// (particles, springs) the scratch was sized for.
    sized_for: (usize, usize),
    lin: Vec<Linear>,
    /// The Gauss–Seidel variants: the springs and coefficients in colour order.
    swept: Vec<SweepSpring>,
    paper: Vec<PaperSpring>,
    sdv: Vec<DVec3>,
    /// RK4's ten state-sized vectors.
    rk: Vec<Vec<DVec3>>,
    /// Forced variants: per-spring relative accelerations at h = 1, per-particle
    /// accelerations, and each spring's frozen relative acceleration from everything else.
    acc: Vec<Linear>,
    pacc: Vec<DVec3>,
    force: Vec<f64>,
}

impl Solver {
    /// A solver for `method` under `gravity`; scratch is sized at the first [`Self::prepare`].
    pub fn new(method: Research, gravity: DVec3) -> Self {
        Self {
            method,
            gravity,
            h: f64::NAN,
            sized_for: (0, 0),
            lin: Vec::new(),
            swept: Vec::new(),
            paper: Vec::new(),
            sdv: Vec::new(),
            rk: Vec::new(),
            acc: Vec::new(),
            pacc: Vec::new(),
            force: Vec::new(),
        }
    }

    /// Sizes scratch and computes step coefficients for `h`; a no-op when nothing changed.
    /// The research steps take springs one by one: cloth grids must be gathered expanded.
    pub fn prepare(&mut self, packed: &Packed, h: f64) -> Result<(), StepError> {
        let (n, m) = (packed.particle_count(), packed.springs.len());
        if self.h == h && self.sized_for == (n, m) {
            return Ok(());
        }
        if !packed.topology.grids.is_empty() {
            return Err(StepError::Grids(self.method));
        }
        self.sdv.resize(m, DVec3::ZERO);
        self.lin.clear();
        self.paper.clear();
        self.rk.clear();
        self.acc.clear();
        let forced = matches!(self.method, Research::Forced | Research::ForcedGs);
        if forced {
            self.acc.extend(
                packed
                    .springs
                    .iter()
                    .map(|s| closed::euler(s.omega0_sq(), s.alpha(), 1.0)),
            );
        }
        self.pacc.resize(if forced { n } else { 0 }, DVec3::ZERO);
        self.force.resize(if forced { m } else { 0 }, 0.0);
        let springs = packed.springs.iter();
        match self.method {
            Research::Sgs => self.lin.extend(springs.map(|s| {
                let l = closed::harmonic(s.omega0_sq(), s.alpha(), h);
                let k = SGS_SWEEPS as f64;
                Linear {
                    p: l.p / k,
                    q: l.q / k,
                    r: 0.0,
                    s: 0.0,
                }
            })),
            Research::Forced | Research::ForcedGs => {
                self.lin
                    .extend(springs.map(|s| closed::harmonic(s.omega0_sq(), s.alpha(), h)));
            }
            Research::Rk4 => {
                // Acceleration coefficients (h = 1).
                self.lin
                    .extend(springs.map(|s| closed::euler(s.omega0_sq(), s.alpha(), 1.0)));
                self.rk = vec![vec![DVec3::ZERO; n]; 10];
            }
            Research::Paper => {
                for (k, s) in packed.springs.iter().enumerate() {
                    self.paper.push(paper_spring(packed, s, k)?);
                }
            }
        }
        self.swept.clear();
        if matches!(self.method, Research::Sgs | Research::ForcedGs) {
            gauss_seidel::order(packed, &self.lin, &mut self.swept);
        }
        self.h = h;
        self.sized_for = (n, m);
        Ok(())
    }

    /// Advances the packed state by one substep `h`.
    pub fn substep(&mut self, packed: &mut Packed, h: f64) -> Result<(), StepError> {
        self.prepare(packed, h)?;
        let g = External::Uniform(self.gravity);
        match self.method {
            Research::Paper => {
                let paper = &self.paper;
                spring_pass(packed, &packed.x, &packed.v, &mut self.sdv, |k, d, dd| {
                    paper[k].phi(d, dd, h)
                });
                // Algorithm 1 as printed: `v += h Δv + g h; x += h v`.
                let Packed {
                    x,
                    v,
                    inv_mass,
                    incidence,
                    ..
                } = packed;
                let (sdv, gravity) = (&self.sdv, self.gravity);
                par::each2(x, v, |i, xi, vi| {
                    if inv_mass[i] != 0.0 {
                        *vi += h * incidence.sum(sdv, i) + gravity * h;
                        *xi += h * *vi;
                    }
                });
            }
            Research::Rk4 => self.rk4(packed, g, h),
            Research::Sgs => {
                gauss_seidel::add_gravity(packed, g, h);
                for k in 0..SGS_SWEEPS {
                    gauss_seidel::sweep(packed, &self.swept, None, k % 2 == 1);
                }
                gauss_seidel::drift(packed, h);
            }
            Research::Forced => {
                self.freeze_forcing(packed, g);
                let (lin, force) = (&self.lin, &self.force);
                spring_pass(packed, &packed.x, &packed.v, &mut self.sdv, |k, d, dd| {
                    lin[k].phi(d, dd) + lin[k].s * force[k]
                });
                particle_pass(packed, &self.sdv, &[], g, h, Update::VelocityFirst);
            }
            Research::ForcedGs => {
                self.freeze_forcing(packed, g);
                // Gravity is in the forcing; it reaches the velocities after the sweep.
                gauss_seidel::sweep(packed, &self.swept, Some(&self.force), false);
                gauss_seidel::add_gravity(packed, g, h);
                gauss_seidel::drift(packed, h);
            }
        }
        Ok(())
    }

    /// For each spring, the relative acceleration along its axis from every force but its
    /// own (other springs, gravity), at the start of the step.
    fn freeze_forcing(&mut self, packed: &Packed, g: External<'_>) {
        let acc = &self.acc;
        spring_pass(packed, &packed.x, &packed.v, &mut self.sdv, |k, d, dd| {
            acc[k].phi(d, dd)
        });
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
        let lin = &self.lin;
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
            spring_pass(packed, xt, vt, &mut self.sdv, |k, d, dd| lin[k].phi(d, dd));
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

/// The paper's constants for spring `k`; a spring with both ends pinned never acts.
fn paper_spring(packed: &Packed, s: &PackedSpring, k: usize) -> Result<PaperSpring, StepError> {
    if !s.mu.is_finite() {
        return Ok(PaperSpring {
            omega0_sq: 1.0,
            alpha: 0.0,
            omega_d: 1.0,
            scale: 0.0,
            damped: false,
        });
    }
    let (ma, mb) = (packed.mass(s.a as usize), packed.mass(s.b as usize));
    PaperSpring::new(s.stiffness, s.damping, ma, mb).map_err(|e| StepError::PaperUndefined {
        spring: k,
        zeta: e.zeta,
    })
}

/// Each spring writes `φ n` into `sdv`, `φ = law(k, δ, δ̇)` at the state `(x, v)`, guarded as
/// the engine's chained passes are: these passes chain within a substep (RK4's stages, the
/// forced step after its forcing), so a non-finite end must not spread.
fn spring_pass(
    packed: &Packed,
    x: &[DVec3],
    v: &[DVec3],
    sdv: &mut [DVec3],
    law: impl Fn(usize, f64, f64) -> f64 + Sync + Send,
) {
    let springs = &packed.springs;
    par::each(sdv, |k, out| {
        let s = &springs[k];
        let (va, vb) = (v[s.a as usize], v[s.b as usize]);
        let (n, delta, delta_dot) = axial(x[s.a as usize], x[s.b as usize], va, vb, s.rest);
        *out = guard(law(k, delta, delta_dot) * n, s, x, va, vb);
    });
}

/// Accelerations from per-spring relative accelerations (RK4's derivative, the forced steps'
/// forcing).
fn acceleration(packed: &Packed, sdv: &[DVec3], g: External<'_>, out: &mut [DVec3]) {
    par::each(out, |i, a| {
        *a = if packed.inv_mass[i] == 0.0 {
            DVec3::ZERO
        } else {
            packed.incidence.sum(sdv, i) + g.at(i)
        };
    });
}
