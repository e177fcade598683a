//! The motion check: every [`CHECK_EVERY`] frames, on scenes without bodies on the CPU, the
//! check frame is stepped again from its start at twice the substeps and the positions
//! compared; for a first-order step the frame's own error is about twice their difference
//! (step doubling). The second run is spread over the `PROBE_FRAMES` (8) frames that follow, a
//! quarter of a frame's work after each, so no frame pays for it whole (it was 3× a frame's
//! work on the check frame); its verdict comes 8 frames after the frame it measured. Its state waits between frames in
//! f32 (24 B per particle, and the check frame's end positions, 12 B); its half-steps run in the
//! frame's buffers, and the frame's state comes back from the World after them (what the
//! frame's scatter wrote, bit for bit). The f32 rounding (10⁻⁷ of the positions) is far below
//! the error it measures (10⁻³ of the scene's size). Its own solver (band scratch, a few bytes per particle) keeps the frame's
//! from being prepared twice a frame.

use super::accuracy::CHECK_EVERY;
use super::*;

/// Frames over which a check's second run (twice the check frame's substeps) is spread.
pub(super) const PROBE_FRAMES: u32 = 8;

/// A motion check under way.
#[derive(Clone, Debug, Default)]
pub(super) struct Probe {
    /// Half-steps still to take (0: none under way).
    left: u32,
    /// Half-steps taken after each frame.
    share: u32,
    /// The check frame's substeps.
    substeps: u32,
    /// The half-step (s).
    h: f64,
    /// The second run's state between frames.
    x: Vec<Vec3>,
    v: Vec<Vec3>,
    /// Where the check frame ended.
    end: Vec<Vec3>,
    solver: Option<Solver>,
}

impl Probe {
    /// Keeps the check frame's start, where the second run starts from.
    pub(super) fn keep_start(&mut self, packed: &Packed) {
        store(&mut self.x, &packed.x);
        store(&mut self.v, &packed.v);
    }

    /// Drops a check under way, and its solver: the buffers, or the integrator, changed.
    pub(super) fn abandon(&mut self) {
        self.left = 0;
        self.solver = None;
    }
}

fn store(to: &mut Vec<Vec3>, from: &[DVec3]) {
    to.clear();
    to.extend(from.iter().map(|x| x.as_vec3()));
}

fn load(to: &mut [DVec3], from: &[Vec3]) {
    for (t, f) in to.iter_mut().zip(from) {
        *t = f.as_dvec3();
    }
}

impl Simulation {
    /// Whether this frame starts a motion check: automatic substeps, the CPU, no bodies.
    pub(super) fn checks_motion(&self) -> bool {
        #[cfg(feature = "gpu")]
        if self.gpu.is_some() {
            return false;
        }
        self.config.auto_substeps
            && self.props.is_none()
            && self.user_stage.is_none()
            && self.drives.is_empty()
            && self.tethers.is_empty()
            && self.stretch.is_empty()
            && self.tear.is_empty()
            && self.steps.is_multiple_of(CHECK_EVERY)
            && !self.packed.x.is_empty()
    }

    /// After a check frame of `substeps` (its start kept by [`Probe::keep_start`]): the
    /// second run starts from there at half the step.
    pub(super) fn begin_probe(&mut self, substeps: u32) {
        let p = &mut self.controller.probe;
        store(&mut p.end, &self.packed.x);
        p.substeps = substeps;
        p.left = 2 * substeps;
        p.share = p.left.div_ceil(PROBE_FRAMES);
        p.h = self.config.dt / f64::from(p.left);
    }

    /// After a frame: the check's next share of half-steps; when it finished, the motion
    /// error set and the check frame's substeps.
    pub(super) fn advance_probe(&mut self) -> Result<Option<u32>, SimError> {
        let c = &mut self.controller;
        if c.probe.left == 0 {
            return Ok(None);
        }
        let size = c.size();
        let (pr, p) = (&mut c.probe, &mut self.packed);
        // The check's run in the frame's buffers; the frame's state is in the World.
        load(&mut p.x, &pr.x);
        load(&mut p.v, &pr.v);
        let steps = pr.share.min(pr.left);
        let config = &self.config;
        let solver = pr.solver.get_or_insert_with(|| {
            Solver::new(config.integrator, config.exact_displacement, config.gravity)
        });
        let h = pr.h;
        // The game's forces as they are now (they may have changed since the check frame).
        let accel = self.forces.as_ref().map(|f| &f.accel[..]);
        let run = |solver: &mut Solver, p: &mut Packed| {
            (0..steps).try_for_each(|_| solver.substep_with(p, h, accel))
        };
        let result = if self.parallel {
            rayon::scope(|_| run(solver, p))
        } else {
            run(solver, p)
        };
        pr.left -= steps;
        let done = pr.left == 0;
        if done {
            let worst = (p.x.iter().zip(&pr.end))
                .zip(&p.inv_mass)
                .filter(|(_, &w)| w != 0.0)
                .map(|((x, q), _)| (x.as_vec3() - *q).length() as f64)
                .fold(0.0, f64::max);
            // A first-order step: the frame's error is about twice the difference.
            c.motion = if size > 0.0 { 2.0 * worst / size } else { 0.0 };
        } else {
            store(&mut pr.x, &p.x);
            store(&mut pr.v, &p.v);
        }
        p.reload_state(&self.world);
        result.map(|()| done.then_some(pr.substeps))
    }
}
