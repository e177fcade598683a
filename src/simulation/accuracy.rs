//! Substeps chosen for accuracy: the automatic controller keeps the energy the steps make
//! within [`SimConfig::tolerance`] of the energy scale, and the motion's error per frame within
//! [`MOTION_TOLERANCE`] of the scene's size, adapting at frame boundaries. It reads only the
//! state, so it decides the same on any number of threads.
//!
//! - The first frame's substeps are chosen a priori: a first-order step makes at most about
//!   `ω h` times the energy in a mode of frequency `ω`, so with a share `f` of the energy scale
//!   in the cloth's own motion and stretch at the start (kinetic energy about its centre of
//!   mass, and the springs') the step is held to `ω_max h ≤ tol/(4 f)`, and never above the
//!   stability floor ([`step_control::choose`]). A cloth starting at rest or thrown whole, and
//!   unstretched, has no such energy and starts at the floor.
//! - Up: when the cumulative residual has risen by more than a quarter of the tolerance above
//!   its lowest since the last change, or the motion check finds a frame's error past its
//!   bound, the substeps double. A bounded oscillation (symplectic Euler's) halves with them, so
//!   the rises add up to at most half the tolerance; a drift (explicit Euler's) doubles them to
//!   [`MAX_RAISE`] times the floor, past which the energy limit reports it. A fall is numerical
//!   damping: reported, not controlled.
//! - Down: after [`CALM_FRAMES`] frames in which the residual rose by less than 1/32 of the
//!   tolerance and the last motion check within a quarter of its bound, they halve, never
//!   below the stability floor.
//! - The motion check ([`super::motion`]), every [`CHECK_EVERY`] frames on scenes without
//!   bodies on the CPU, steps the check frame again from its start at twice the substeps,
//!   spread over the 8 frames that follow, and compares the positions: for a first-order step
//!   the frame's own error is about twice their difference (step doubling). It catches what
//!   the energy misses: a step that conserves energy but runs slow in phase, or one that damps
//!   the motion away.
//! - Retry: on the CPU without bodies or a step budget, a frame whose own energy error would lift the
//!   cumulative residual more than half the tolerance above its low is taken again from its
//!   start at twice the substeps, until it fits or the substeps reach their cap. A long frame
//!   (several periods of the cloth's motion) is thus held to the tolerance before its books
//!   close, not one frame late.

use super::*;

/// A frame's position error, as a share of the scene's size (its particles' bounding box
/// diagonal), past which the motion check doubles the substeps.
pub const MOTION_TOLERANCE: f64 = 1e-3;
/// Frames between motion checks.
pub const CHECK_EVERY: u64 = 30;
/// Calm frames before the substeps may halve.
pub const CALM_FRAMES: u64 = 120;
/// The most the controller raises the substeps over the stability floor: a step whose error
/// drifts (explicit Euler's energy) is not chased further; the energy limit reports it.
pub const MAX_RAISE: u32 = 64;

/// The controller's state between frames.
#[derive(Clone, Debug, Default)]
pub(super) struct Controller {
    /// The stability floor the substeps never go under.
    floor: u32,
    /// Frames since the last change; since then, the cumulative residual's lowest value and
    /// its largest rise above an earlier low.
    since: u64,
    low: f64,
    rise: f64,
    /// The scene's size (m).
    size: f64,
    /// The last motion check's error, a share of the size (NaN before the first).
    pub(super) motion: f64,
    /// Substep changes made so far (a frame taken again included).
    pub(super) changes: u32,
    /// The motion check under way.
    pub(super) probe: super::motion::Probe,
}

impl Controller {
    /// After a choice of the stability floor (every gather and pin refresh).
    pub(super) fn reset(&mut self, floor: u32, packed: &Packed, residual: f64) {
        self.floor = floor.max(1);
        self.since = 0;
        (self.low, self.rise) = (residual, 0.0);
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for x in &packed.x {
            (lo, hi) = (lo.min(*x), hi.max(*x));
        }
        self.size = if packed.x.is_empty() {
            0.0
        } else {
            (hi - lo).length()
        };
        self.motion = f64::NAN;
        // A check under way was of the old buffers.
        self.probe.abandon();
    }
}

impl Controller {
    /// The scene's size (m), as of the last gather.
    pub(super) fn size(&self) -> f64 {
        self.size
    }

    /// The first frame's substeps for `choice` (the stability floor) and a share `f` of the
    /// energy scale in motion and stretch, for the first-order explicit steps (the others'
    /// error is damping, or the closed form's is not first order in `ω h`).
    pub(super) fn a_priori(&self, choice: &StepChoice, config: &SimConfig, f: f64) -> u32 {
        use crate::config::Integrator::*;
        let first_order = matches!(config.integrator, SymplecticEuler | ExplicitEuler);
        let positive = |x: f64| x > 0.0;
        if !first_order || !positive(f) || !positive(choice.omega_max) {
            return choice.substeps;
        }
        let bound = config.tolerance / (4.0 * f);
        let wanted = (choice.omega_max * config.dt / bound).ceil();
        let cap = step_control::MAX_SUBSTEPS as f64;
        choice.substeps.max(wanted.min(cap) as u32)
    }
}

impl Simulation {
    /// After a frame's books: the substeps for the next frame.
    /// `probed`: the substeps of the frame a motion check just finished measuring.
    pub(super) fn adapt(&mut self, probed: Option<u32>) {
        if !self.config.auto_substeps {
            return;
        }
        let run = self.auditor.run;
        let tol = self.config.tolerance * run.scale;
        let c = &mut self.controller;
        c.since += 1;
        c.low = c.low.min(run.residual);
        // A rise, not a fall: a steady loss (numerical damping, the step's error at particles
        // a contact holds) is not the steps making energy.
        c.rise = c.rise.max(run.residual - c.low);
        let substeps = self.config.substeps;
        let energy_up = tol > 0.0 && c.rise > 0.25 * tol;
        // A NaN error (the probe blew up) counts as past the bound.
        // A verdict on fewer substeps than the frames take now has been acted on already.
        let motion_up = probed.is_some_and(|n| n >= substeps)
            && (c.motion > MOTION_TOLERANCE || c.motion.is_nan());
        let calm = c.since >= CALM_FRAMES
            && (tol <= 0.0 || c.rise < tol / 32.0)
            && c.motion <= MOTION_TOLERANCE / 4.0;
        let mut next = if energy_up || motion_up {
            (substeps.saturating_mul(2))
                .min(c.floor.saturating_mul(MAX_RAISE))
                .min(step_control::MAX_SUBSTEPS)
                .max(substeps)
        } else if calm && substeps / 2 >= c.floor {
            substeps / 2
        } else {
            substeps
        };
        // The budget, from the wall clock: over it, halve toward the floor; raise only while
        // twice the step fits.
        let budget = self.config.step_budget;
        if budget.is_finite() {
            let spent = self.stats.total().as_secs_f64();
            let wanted = next;
            if spent > budget {
                next = (substeps / 2).max(c.floor);
            } else if next > substeps && 2.0 * spent > budget {
                next = substeps;
            }
            self.stats.budget_limited = next < wanted || (spent > budget && substeps == c.floor);
        }
        if next != substeps {
            self.config.substeps = next;
            c.changes += 1;
            c.since = 0;
            (c.low, c.rise) = (run.residual, 0.0);
            if calm {
                c.motion = f64::NAN;
            }
        }
    }
}

impl Controller {
    /// Whether a frame taken at `substeps` is rejected and taken again at the substeps
    /// returned: its books would leave the cumulative residual at `after`, more than half
    /// the tolerance `tol` (J) above its lowest since the last change, and the substeps may
    /// still double. The run's residual before the frame, `before`, becomes the new low.
    pub(super) fn rejects(
        &mut self,
        substeps: u32,
        before: f64,
        after: f64,
        tol: f64,
    ) -> Option<u32> {
        let cap = (self.floor.saturating_mul(MAX_RAISE)).min(step_control::MAX_SUBSTEPS);
        let rise = after - self.low.min(before);
        if !(tol > 0.0 && rise > 0.5 * tol) || substeps.saturating_mul(2) > cap {
            return None;
        }
        self.changes += 1;
        self.since = 0;
        (self.low, self.rise) = (before, 0.0);
        Some(substeps * 2)
    }
}
