//! The energy audit: every frame, the cloth's mechanical energy booked against what went in
//! and out, as discrete work, so that what is left, the residual, is the integrator's own
//! energy error (`../shared/MATH.md`, "The energy audit"; the lines are defined on
//! [`EnergyAudit`]).
//!
//! Every sum runs over fixed blocks (loose springs by [`BLOCK`], a cloth grid by rows,
//! particles by [`BLOCK`]) added in block order, so the books are bit-identical on any number
//! of threads.

use glam::DVec3;
use rayon::prelude::*;

use crate::buffers::{Packed, PackedSpring};
use crate::components::GridLink;
use crate::config::Integrator;

/// Elements per block of the audit's fixed-order sums.
pub(crate) const BLOCK: usize = 4096;

mod moves;
pub(crate) use moves::Moves;

/// The energy books of a frame ([`crate::StepStats::audit`]) or of the run so far
/// ([`crate::Diagnostics::audit`]), in joules. The audited system is the cloth: its energy
/// `E = Σ ½ m|v|² − Σ m g·x + Σ ½ κ δ²` over free particles and all springs. Over a frame
///
/// `E₁ − E₀ = edits + attachments + forces − damping − contacts − friction − quarantine +
/// residual`.
///
/// Each line is discrete work: a damper's force over a substep does `h F·(v₀ + v₁)/2` over the
/// particles' velocities at the step's start and end, with `F` the force the step applied:
/// the start's for symplectic and explicit Euler and RK4, the end's for implicit Euler, θ-mg
/// and XPBD, the step's mean rate's for the closed forms. A projection (a contact's push-out
/// and velocity change, an attachment moving its particle) books the change of `E` it made,
/// springs included. The residual is what is left: the steps' own error, positive when they
/// made energy, negative when they damped the motion numerically. It includes the step's
/// error at the particles a contact or attachment then overrides (negative under symplectic
/// Euler: a particle resting on a collider loses `½ m |g|² h²` a substep), so the peak
/// residual, not the residual, is what measures energy made.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EnergyAudit {
    /// `E` at the start (J).
    pub start: f64,
    /// `E` at the end (J).
    pub energy: f64,
    /// Put in by the game between frames: particles dragged, pinned, freed or given a
    /// velocity, cloths added or removed, gravity changed (the change of `E` each made).
    pub edits: f64,
    /// Put in by attached particles following their bodies, and by the drive stage (driven
    /// pins following the game's targets, particles kept within their maximum distance of
    /// them), within the frame.
    pub attachments: f64,
    /// Put in by the game's forces ([`crate::Simulation::set_forces`]) within the frame: their
    /// work `Σ F·Δx` over the integrate stage's moves (as gravity's is part of `E`).
    pub forces: f64,
    /// Dissipated by the springs' dampers (≥ 0 for dampers with `c ≥ 0`).
    pub damping: f64,
    /// Removed by the contacts' push-out and their normal velocity change (work by a moving
    /// collider included; a restitution `e` keeps `e²` of the approach's energy). Where the
    /// contacts run on the device, the work the colliders' motion does on the cloth, read from
    /// the impulses the contacts hand the bodies (`−(J·v + L·ω)`): the contacts' own
    /// dissipation is then left in the residual, where it is negative.
    pub contacts: f64,
    /// Removed by friction (the tangential velocity change against the collider).
    pub friction: f64,
    /// Removed by the limits' projections: tethers ([`crate::TetherSpec`]) and stretch limits
    /// ([`crate::StretchLimit`]), the change of `E` their moves made, negated.
    pub limits: f64,
    /// Removed by tearing ([`crate::Tearing`]): the energy the springs that broke held.
    pub torn: f64,
    /// Removed by the quarantine: in a frame that froze particles, the change of `E` the
    /// other lines leave unexplained is booked here (a blow-up, not an integration error).
    pub quarantine: f64,
    /// The numerical energy error: `E₁ − E₀` less every line above.
    pub residual: f64,
    /// The largest the cumulative residual has been since the run began (≥ 0): energy the
    /// steps made beyond what went in, what the automatic substeps keep within
    /// [`crate::SimConfig::tolerance`] of the scale.
    pub peak_residual: f64,
    /// The energy scale the residual is measured against ([`crate::Diagnostics::energy_scale`]).
    pub scale: f64,
}

impl EnergyAudit {
    /// The residual as a share of the energy scale.
    pub fn relative_residual(&self) -> f64 {
        self.residual / self.scale
    }

    /// The peak residual as a share of the energy scale.
    pub fn relative_peak(&self) -> f64 {
        self.peak_residual / self.scale
    }

    fn lines_add(&mut self, o: &EnergyAudit) {
        self.edits += o.edits;
        self.attachments += o.attachments;
        self.forces += o.forces;
        self.damping += o.damping;
        self.contacts += o.contacts;
        self.friction += o.friction;
        self.limits += o.limits;
        self.torn += o.torn;
        self.quarantine += o.quarantine;
        self.residual += o.residual;
    }
}

/// A line of a frame's books that a stage reports to ([`Auditor::book`]): the one interface
/// through which each stage books its work or its projections.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Line {
    /// [`EnergyAudit::damping`]: the integrate stage's dampers.
    Damping,
    /// [`EnergyAudit::forces`]: the force stages' work.
    Forces,
    /// [`EnergyAudit::attachments`]: the contact stage's attached particles, the drive stage's
    /// moves.
    Attachments,
    /// [`EnergyAudit::contacts`]: the contact stage's push-out.
    Contacts,
    /// [`EnergyAudit::friction`]: the contact stage's friction.
    Friction,
    /// [`EnergyAudit::limits`]: the tethers' and stretch limits' projections.
    Limits,
    /// [`EnergyAudit::torn`]: the broken springs' energy.
    Torn,
}

/// What the projections of a contact stage did to the cloth's energy in a frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProjectionLines {
    /// [`EnergyAudit::attachments`].
    pub attachments: f64,
    /// [`EnergyAudit::contacts`].
    pub contacts: f64,
    /// [`EnergyAudit::friction`].
    pub friction: f64,
}

impl ProjectionLines {
    /// The lines with their amounts, for [`Auditor::book`].
    pub fn lines(&self) -> [(Line, f64); 3] {
        [
            (Line::Attachments, self.attachments),
            (Line::Contacts, self.contacts),
            (Line::Friction, self.friction),
        ]
    }
}

/// How a damper's discrete work over a substep is booked.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DamperLaw {
    /// Force at the step's start: `h c δ̇₀ (δ̇₀ + δ̇₁)/2`, both rates along the start's axis.
    Start,
    /// Force at the step's end: `h c δ̇₁ (δ̇₀ + δ̇₁)/2`, along the end's axis.
    End,
    /// Force at the step's mean rate, the closed forms' (their impulse is the whole step's):
    /// `h c ((δ̇₀ + δ̇₁)/2)²`, along the start's axis.
    Mid,
}

impl DamperLaw {
    /// The law `integrator`'s steps are booked by.
    /// The closed forms book the work over the motion the step made, not an isolated
    /// oscillator's loss: a spring held stretched by its load (gravity, its neighbours) would
    /// swing back within the step alone and lose energy the network never moves through.
    pub fn of(integrator: Integrator) -> Self {
        use Integrator::*;
        match integrator {
            SymplecticEuler | ExplicitEuler => DamperLaw::Start,
            ImplicitEuler | ThetaMg | Xpbd => DamperLaw::End,
            Harmonic | HarmonicGs => DamperLaw::Mid,
        }
    }
}

/// A spring as the audit walks it: ends, rest length, stiffness, damping.
#[derive(Clone, Copy)]
pub(crate) struct Link {
    pub a: usize,
    pub b: usize,
    pub rest: f64,
    pub stiffness: f64,
    pub damping: f64,
}

impl From<&PackedSpring> for Link {
    fn from(s: &PackedSpring) -> Self {
        Link {
            a: s.a as usize,
            b: s.b as usize,
            rest: s.rest,
            stiffness: s.stiffness,
            damping: s.damping,
        }
    }
}

/// `sums[k] = block(k)` for every block (on rayon's pool when `parallel`), then their sum in
/// block order: the same whatever the thread count.
fn fixed_sum(sums: &mut [f64], parallel: bool, block: impl Fn(usize) -> f64 + Sync) -> f64 {
    if parallel {
        sums.par_iter_mut()
            .enumerate()
            .for_each(|(k, s)| *s = block(k));
    } else {
        sums.iter_mut().enumerate().for_each(|(k, s)| *s = block(k));
    }
    sums.iter().sum()
}

/// A block of the fixed-order sums over springs.
#[derive(Clone, Copy, Debug)]
enum Block {
    Loose(usize, usize),
    Row(usize, u32),
}

/// The audit's state between frames and its scratch (sized at gather; a step allocates
/// nothing).
#[derive(Clone, Debug, Default)]
pub struct Auditor {
    blocks: Vec<Block>,
    sums: Vec<f64>,
    /// The state at the current substep's start (scenes with dampers only).
    x0: Vec<DVec3>,
    v0: Vec<DVec3>,
    /// Whether the pass after each substep has dampers to book: loose springs, or cloth
    /// grids whose pass does not book its own.
    pub damped: bool,
    /// Whether the frame books the work of per-particle forces (the start positions kept).
    forced: bool,
    /// The grids' dampers are booked by the grid pass.
    grids_booked: bool,
    parallel: bool,
    /// `E` at the end of the last frame (None before the first).
    pub end: Option<f64>,
    /// The frame being booked.
    pub frame: EnergyAudit,
    /// The run so far.
    pub run: EnergyAudit,
    /// The run's peak residual before the last frame.
    pub peak_before: f64,
}

impl Auditor {
    /// Sizes the blocks and scratch for the packed buffers (after every gather or repin);
    /// `grids_booked`: the grid pass books its dampers itself.
    pub fn prepare(&mut self, packed: &Packed, grids_booked: bool) {
        self.grids_booked = grids_booked;
        self.blocks.clear();
        let m = packed.springs.len();
        self.blocks.extend(
            (0..m.div_ceil(BLOCK)).map(|k| Block::Loose(k * BLOCK, ((k + 1) * BLOCK).min(m))),
        );
        for (g, grid) in packed.topology.grids.iter().enumerate() {
            self.blocks.extend((0..grid.rows).map(|r| Block::Row(g, r)));
        }
        let n = packed.particle_count();
        let slots = self.blocks.len().max(n.div_ceil(BLOCK));
        self.sums.resize(slots, 0.0);
        let damped_grids =
            (packed.topology.grids.iter()).any(|g| g.links.iter().any(|l| l.damping != 0.0));
        self.damped =
            packed.springs.iter().any(|s| s.damping != 0.0) || (damped_grids && !grids_booked);
        let keep = if self.damped { n } else { 0 };
        self.x0.resize(keep, DVec3::ZERO);
        self.v0.resize(keep, DVec3::ZERO);
        self.parallel = crate::integrate::runs_parallel(packed);
    }

    /// `Σ f` over every spring, in block order.
    fn spring_sum(&mut self, packed: &Packed, f: impl Fn(Link) -> f64 + Sync + Send) -> f64 {
        self.spring_sum_of(packed, true, f)
    }

    /// As [`Self::spring_sum`], the cloth grids' springs only if `grids`.
    fn spring_sum_of(
        &mut self,
        packed: &Packed,
        grids_too: bool,
        f: impl Fn(Link) -> f64 + Sync + Send,
    ) -> f64 {
        let row = |l: &GridLink, (a, b, n): (usize, usize, usize), mut acc: f64| {
            for k in 0..n {
                acc += f(Link {
                    a: a + k,
                    b: b + k,
                    rest: l.rest_length,
                    stiffness: l.stiffness,
                    damping: l.damping,
                });
            }
            acc
        };
        self.spring_sum_by_rows(packed, grids_too, &f, row)
    }

    /// As [`Self::spring_sum_of`], a grid link's row of `n` springs `(a + k, b + k)` added
    /// to the block's sum by `row` (in order: the same bits as `f` spring by spring).
    fn spring_sum_by_rows(
        &mut self,
        packed: &Packed,
        grids_too: bool,
        f: impl Fn(Link) -> f64 + Sync + Send,
        row: impl Fn(&GridLink, (usize, usize, usize), f64) -> f64 + Sync + Send,
    ) -> f64 {
        let blocks = &self.blocks;
        let grids = &packed.topology.grids;
        let block = |k: usize| -> f64 {
            let mut acc = 0.0;
            match blocks[k] {
                Block::Loose(lo, hi) => {
                    for s in &packed.springs[lo..hi] {
                        acc += f(s.into());
                    }
                }
                Block::Row(_, _) if !grids_too => {}
                Block::Row(g, r) => {
                    let grid = &grids[g];
                    for l in &grid.links {
                        let Some((a, b, n)) = grid.link_row(l, r) else {
                            continue;
                        };
                        acc = row(l, (a as usize, b as usize, n as usize), acc);
                    }
                }
            }
            acc
        };
        fixed_sum(&mut self.sums[..blocks.len()], self.parallel, block)
    }

    /// `Σ f(i)` over every particle, in block order.
    fn particle_sum(&mut self, n: usize, f: impl Fn(usize) -> f64 + Sync + Send) -> f64 {
        let block = |k: usize| (k * BLOCK..((k + 1) * BLOCK).min(n)).map(&f).sum::<f64>();
        fixed_sum(&mut self.sums[..n.div_ceil(BLOCK)], self.parallel, block)
    }

    /// The cloth's mechanical energy `E` (J), in fixed order.
    pub fn energy(&mut self, packed: &Packed, gravity: DVec3) -> f64 {
        let particles = self.particle_sum(packed.particle_count(), |i| {
            particle_energy(packed, i, gravity)
        });
        let x = &packed.x;
        let springs = self.spring_sum(packed, |l| spring_energy(x, l));
        particles + springs
    }

    /// Keeps the state at a substep's start, for [`Self::damping`] and [`Self::force_work`]
    /// after it.
    pub fn begin_substep(&mut self, packed: &Packed) {
        if self.damped {
            self.x0.copy_from_slice(&packed.x);
            self.v0.copy_from_slice(&packed.v);
        } else if self.forced {
            self.x0.copy_from_slice(&packed.x);
        }
    }

    /// Whether this frame has per-particle forces whose work to book (the start positions are
    /// kept for them).
    pub fn set_forced(&mut self, forced: bool, particles: usize) {
        self.forced = forced;
        if forced {
            self.x0.resize(particles, DVec3::ZERO);
        }
    }

    /// Books the work of the forces `f` (N, packed order, constant over the frame) over the
    /// moves since [`Self::begin_substep`]: `Σ F·(x₁ − x₀)` over free particles, in fixed
    /// order.
    pub fn force_work(&mut self, packed: &Packed, f: &[DVec3]) {
        let x0 = std::mem::take(&mut self.x0);
        let (x1, inv) = (&packed.x, &packed.inv_mass);
        let work = self.particle_sum(packed.particle_count(), |i| {
            if inv[i] == 0.0 {
                0.0
            } else {
                f[i].dot(x1[i] - x0[i])
            }
        });
        self.x0 = x0;
        self.book(Line::Forces, work);
    }

    /// What the dampers dissipated over the substep of `h` just taken (from the state
    /// [`Self::begin_substep`] kept), booked on the frame with `booked`, what the grid pass
    /// booked itself.
    pub fn damping(&mut self, packed: &Packed, law: DamperLaw, h: f64, booked: f64) {
        self.book(Line::Damping, booked);
        if !self.damped {
            return;
        }
        let (x0, v0) = (std::mem::take(&mut self.x0), std::mem::take(&mut self.v0));
        let (x1, v1) = (&packed.x[..], &packed.v[..]);
        let grids_too = !self.grids_booked;
        let loss = self.spring_sum_of(packed, grids_too, |l| {
            if l.damping == 0.0 {
                return 0.0;
            }
            let (a, b) = (l.a, l.b);
            damper_loss(
                law,
                h,
                l,
                [x0[a], x0[b], v0[a], v0[b]],
                [x1[a], x1[b], v1[a], v1[b]],
            )
        });
        (self.x0, self.v0) = (x0, v0);
        self.book(Line::Damping, loss);
    }

    /// Opens the books of a frame: `start` is `E` after the game's edits, which are booked as
    /// the change from the last frame's end.
    pub fn begin_frame(&mut self, start: f64, scale: f64) {
        let edits = self.end.map_or(0.0, |e| start - e);
        if self.end.is_none() {
            self.run = EnergyAudit {
                start,
                ..EnergyAudit::default()
            };
            self.peak_before = 0.0;
        }
        self.frame = EnergyAudit {
            start,
            edits,
            scale,
            ..EnergyAudit::default()
        };
    }

    /// Books `joules` on the frame's `line`: what a stage did (work put in, or energy its
    /// dampers or projections removed, each with the sign of its line).
    pub fn book(&mut self, line: Line, joules: f64) {
        let f = &mut self.frame;
        *match line {
            Line::Damping => &mut f.damping,
            Line::Forces => &mut f.forces,
            Line::Attachments => &mut f.attachments,
            Line::Contacts => &mut f.contacts,
            Line::Friction => &mut f.friction,
            Line::Limits => &mut f.limits,
            Line::Torn => &mut f.torn,
        } += joules;
    }

    /// Closes the frame's books at `end` (J); `quarantined`: the frame froze particles.
    pub fn end_frame(&mut self, end: f64, quarantined: bool) {
        let f = &mut self.frame;
        f.energy = end;
        let unexplained = end - f.start - f.edits - f.attachments - f.forces
            + f.damping
            + f.contacts
            + f.friction
            + f.limits
            + f.torn;
        if quarantined || !unexplained.is_finite() {
            f.quarantine = -unexplained;
        } else {
            f.residual = unexplained;
        }
        self.run.lines_add(f);
        self.run.energy = end;
        self.run.scale = f.scale;
        self.peak_before = self.run.peak_residual;
        self.run.peak_residual = self.run.peak_residual.max(self.run.residual);
        f.peak_residual = self.run.peak_residual;
        self.end = Some(end);
    }
}

/// `½ m|v|² − m g·x` of a free particle; a pinned one holds none.
#[inline]
pub(crate) fn particle_energy(packed: &Packed, i: usize, gravity: DVec3) -> f64 {
    particle_energy_at(packed.inv_mass[i], packed.x[i], packed.v[i], gravity)
}

/// A particle's kinetic and potential energy at `x`, `v` (0 for a pinned one, `inv` = 0).
#[inline]
pub(crate) fn particle_energy_at(inv: f64, x: DVec3, v: DVec3, gravity: DVec3) -> f64 {
    if inv == 0.0 {
        return 0.0;
    }
    let m = 1.0 / inv;
    0.5 * m * v.length_squared() - m * gravity.dot(x)
}

/// `½ κ δ²` of one spring at positions `x`.
#[inline]
pub(crate) fn spring_energy(x: &[DVec3], l: Link) -> f64 {
    spring_energy_at(x[l.a], x[l.b], l)
}

/// `½ κ δ²` of one spring with its ends at `xa`, `xb`.
#[inline]
pub(crate) fn spring_energy_at(xa: DVec3, xb: DVec3, l: Link) -> f64 {
    let d = (xb - xa).length() - l.rest;
    0.5 * l.stiffness * d * d
}

/// One damper's discrete loss over a substep `h` from the ends' start `[xa, xb, va, vb]` and
/// end states, by `law`.
pub(crate) fn damper_loss(
    law: DamperLaw,
    h: f64,
    l: Link,
    [xa0, xb0, va0, vb0]: [DVec3; 4],
    [xa1, xb1, va1, vb1]: [DVec3; 4],
) -> f64 {
    let c = l.damping;
    match law {
        DamperLaw::Start => {
            let n = (xb0 - xa0).normalize();
            let (r0, r1) = (n.dot(vb0 - va0), n.dot(vb1 - va1));
            h * c * r0 * 0.5 * (r0 + r1)
        }
        DamperLaw::Mid => {
            let n = (xb0 - xa0).normalize();
            let mean = 0.5 * (n.dot(vb0 - va0) + n.dot(vb1 - va1));
            h * c * mean * mean
        }
        DamperLaw::End => {
            let n = (xb1 - xa1).normalize();
            let (r0, r1) = (n.dot(vb0 - va0), n.dot(vb1 - va1));
            h * c * r1 * 0.5 * (r0 + r1)
        }
    }
}

/// The springs touching particle `i`, each as a [`Link`] (loose ones by the topology's index,
/// a grid's by its links both ways).
pub(crate) fn springs_at(packed: &Packed, i: usize, mut f: impl FnMut(Link)) {
    for &k in packed.topology.touching(i) {
        f((&packed.springs[k as usize]).into());
    }
    for g in &packed.topology.grids {
        if !g.range().contains(&i) {
            continue;
        }
        let (cols, rows) = (g.cols as i64, g.rows as i64);
        let j = (i - g.base as usize) as i64;
        let (c, r) = (j % cols, j / cols);
        for l in &g.links {
            let (dc, dr) = (l.offset.0 as i64, l.offset.1 as i64);
            for s in [1, -1] {
                let (cb, rb) = (c + s * dc, r + s * dr);
                if cb < 0 || rb < 0 || cb >= cols || rb >= rows {
                    continue;
                }
                let other = g.base as usize + (rb * cols + cb) as usize;
                let (a, b) = if s == 1 { (i, other) } else { (other, i) };
                f(Link {
                    a,
                    b,
                    rest: l.rest_length,
                    stiffness: l.stiffness,
                    damping: l.damping,
                });
            }
        }
    }
}

/// The part of `E` that moving particle `i` alone changes: its own energy and its springs'.
pub(crate) fn local_energy(packed: &Packed, i: usize, gravity: DVec3) -> f64 {
    let mut e = particle_energy(packed, i, gravity);
    springs_at(packed, i, |l| e += spring_energy(&packed.x, l));
    e
}
