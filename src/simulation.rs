//! The `Simulation` facade: a World, its packed buffers and the schedule that steps them.

use std::path::Path;
use std::time::{Duration, Instant};

use glam::{DVec3, Vec3};
use hecs::{Entity, World};

use crate::backend::Backend;
use crate::buffers::{GatherOptions, Packed};
use crate::components::{ClothGrid, ClothSprings, Pin, Quarantined, SceneIndex};
use rapier3d::prelude::{ColliderSet, RigidBodySet};

use crate::contacts::{ContactStage, ContactStats, Props};
use crate::error::{Error, SimError};
use crate::integrate::{Integrator, Solver};
use crate::metrics;
use crate::scene::props::ContactDef;
use crate::scene::{Limits, Scene};
use crate::schedule::StepStats;
use crate::step_control::{self, StepChoice};

/// How a simulation steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimConfig {
    /// Frame step (s).
    pub dt: f64,
    /// Substeps per frame; the integrator's step is `h = dt / substeps`. With
    /// `auto_substeps` this is chosen at every gather and on [`Simulation::set_config`].
    pub substeps: u32,
    /// Choose `substeps` from the network's highest frequency and the integrator's measured
    /// stability region ([`crate::step_control`]).
    pub auto_substeps: bool,
    pub gravity: DVec3,
    pub integrator: Integrator,
    /// Harmonic only: move positions by each spring's closed-form displacement too.
    pub exact_displacement: bool,
    /// Where the integrate stage runs.
    pub backend: Backend,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            dt: 1.0 / 60.0,
            substeps: 1,
            auto_substeps: true,
            gravity: DVec3::new(0.0, -9.81, 0.0),
            integrator: Integrator::default(),
            exact_displacement: false,
            backend: Backend::Cpu,
        }
    }
}

impl SimConfig {
    pub fn h(&self) -> f64 {
        self.dt / self.substeps as f64
    }
    fn check(&self) -> Result<(), SimError> {
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(SimError::BadStep(self.dt));
        }
        if self.substeps == 0 {
            return Err(SimError::NoSubsteps);
        }
        Ok(())
    }
}

/// Live figures of the current state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Diagnostics {
    /// Kinetic + spring + gravitational energy (J).
    pub energy: f64,
    /// Largest `|δ|/l0`.
    pub max_strain: f64,
    /// `h/h_c` of the stiffest spring (`h_c = π/ω0`).
    pub step_ratio: f64,
    /// Particles whose position or velocity is not finite: 0 after every step, which
    /// quarantines such particles (non-zero only for a state set from outside since).
    pub non_finite: usize,
    /// Particles in quarantine ([`Simulation::quarantined`]).
    pub quarantined: usize,
}

/// A mass-spring simulation over a hecs World.
pub struct Simulation {
    world: World,
    config: SimConfig,
    packed: Packed,
    solver: Solver,
    dirty: bool,
    /// The automatic step choice, when `auto_substeps` is on.
    choice: Option<StepChoice>,
    /// Whether the passes run on rayon's pool (large scenes only).
    parallel: bool,
    steps: u64,
    time: f64,
    stats: StepStats,
    /// The GPU step, when the backend resolved to the GPU.
    #[cfg(feature = "gpu")]
    gpu: Option<crate::gpu::GpuSolver>,
    /// Rigid props and the contact stage; None for a scene without bodies.
    props: Option<Props>,
    /// The contact stage against the caller's rapier sets ([`Simulation::step_with`]).
    user_stage: Option<ContactStage>,
    /// Host scratch for the device contact stage's colliders.
    #[cfg(feature = "gpu")]
    device_scratch: Vec<crate::gpu::contacts::Collider>,
    /// The cloth's contact material for [`Simulation::step_with`].
    contact: ContactDef,
    /// The game-loop side: fixed-step accumulator and render buffers.
    frame: Frame,
    /// Particles held by [`Simulation::grab`] that were free before.
    grabbed: Vec<Entity>,
    /// The cloths as units: each one's entity, whose [`ClothSprings`] holds its grid.
    cloths: Vec<(ClothId, Entity)>,
    next_cloth: u32,
    /// Particles found non-finite during the current frame (packed indices, may repeat).
    contained: Vec<usize>,
    /// Particles quarantined since the last frame's statistics.
    newly_quarantined: usize,
}

/// The quarantine's check, after every substep (and after a gather, for state set from
/// outside): each particle with a non-finite position or velocity goes back to its position in
/// `world` (the last finite frame) at rest, before any spring reads it again, and is recorded
/// in `found`. One parallel read of the state when nothing is wrong.
fn contain(packed: &mut Packed, world: &World, found: &mut Vec<usize>) -> bool {
    let bad = |x: &DVec3, v: &DVec3| !metrics::finite_state(*x, *v);
    if !crate::integrate::par::any2(&packed.x, &packed.v, bad) {
        return false;
    }
    for i in 0..packed.particle_count() {
        if bad(&packed.x[i], &packed.v[i]) {
            // Gather refuses non-finite positions and scatter writes only finite ones, so the
            // World's position is finite; the origin is only a last resort.
            packed.x[i] = world
                .get::<&crate::components::Particle>(packed.entities[i])
                .map_or(DVec3::ZERO, |p| p.position);
            packed.v[i] = DVec3::ZERO;
            found.push(i);
        }
    }
    true
}

/// A cloth of the simulation (from its scene or added at run time), to remove it by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ClothId(u32);

/// What [`Simulation::advance`] did with a frame's time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Advance {
    /// Fixed steps of `dt` taken.
    pub steps: u32,
    /// Where the render time sits between the last two states, in [0, 1): pass it to
    /// [`Simulation::render`] to draw without the stutter of whole steps.
    pub alpha: f64,
    /// Time dropped because the frame needed more than the cap of steps (s): the simulation
    /// runs slower than the clock instead of spiralling.
    pub dropped: f64,
}

/// Game-loop state: the time not yet stepped, the cap, and the buffers a renderer reads.
struct Frame {
    accumulator: f64,
    max_steps: u32,
    /// The state before the last step of the last advance.
    prev: Vec<DVec3>,
    /// Triangles set by the caller; otherwise the cloths' grids, made when first asked for.
    custom: Option<Vec<[u32; 3]>>,
    triangles: std::sync::OnceLock<Vec<[u32; 3]>>,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
}

impl Default for Frame {
    fn default() -> Self {
        Self {
            accumulator: 0.0,
            max_steps: 8,
            prev: Vec::new(),
            custom: None,
            triangles: std::sync::OnceLock::new(),
            positions: Vec::new(),
            normals: Vec::new(),
        }
    }
}

/// The caller's triangles, or the cloths' (made on first use).
fn frame_triangles<'a>(
    custom: &'a Option<Vec<[u32; 3]>>,
    made: &'a std::sync::OnceLock<Vec<[u32; 3]>>,
    cloths: &[(ClothId, Entity)],
    world: &World,
) -> &'a [[u32; 3]] {
    if let Some(t) = custom {
        return t;
    }
    made.get_or_init(|| {
        let mut out = Vec::new();
        for &(_, e) in cloths {
            if let Some(grid) = grid_of(world, e) {
                grid.triangles(&mut out);
            }
        }
        out
    })
}

/// A cloth's grid, read from its entity's [`ClothSprings`] (`None` once that is gone).
fn grid_of(world: &World, e: Entity) -> Option<ClothGrid> {
    world.get::<&ClothSprings>(e).ok().map(|c| c.grid)
}

/// What a renderer uploads each frame: positions and normals (f32, one per particle in scene
/// order) and the triangles indexing them. Borrowed from buffers the simulation keeps, so a
/// frame allocates nothing.
pub struct RenderView<'a> {
    pub positions: &'a [Vec3],
    pub normals: &'a [Vec3],
    pub triangles: &'a [[u32; 3]],
}

/// The rigid side a frame couples with: the scene's own rapier world, or the caller's sets.
enum Coupling<'a> {
    Own(&'a mut Props),
    User {
        stage: &'a mut ContactStage,
        bodies: &'a mut RigidBodySet,
        colliders: &'a ColliderSet,
    },
}

/// A frame with springs and contacts on the device. Without dynamic bodies the bodies move
/// first for every substep (nothing they do depends on the cloth), all substeps go in one
/// submit and the partials come back once, for the statistics. With dynamic bodies each
/// substep is its own submit and its partials come back to push the bodies before the next.
#[cfg(feature = "gpu")]
fn device_frame(
    gpu: &mut crate::gpu::GpuSolver,
    p: &mut Props,
    scratch: &mut Vec<crate::gpu::contacts::Collider>,
    substeps: u32,
    h: f64,
    host_time: &mut Duration,
) -> Result<(), SimError> {
    let Some(dc) = gpu.contacts() else {
        return Ok(());
    };
    let (groups, nc) = dc.shape();
    let per_slot = groups * nc;
    if !p.dynamic {
        let t = Instant::now();
        for s in 0..substeps {
            p.step_bodies(h);
            p.device_colliders(scratch);
            if let Some(dc) = gpu.contacts() {
                dc.set_colliders(s, scratch);
            }
        }
        *host_time += t.elapsed();
        gpu.run(substeps)?;
        let partials = gpu.read_partials(0, substeps)?;
        for slot in partials.chunks(per_slot) {
            p.apply_device(slot, groups, nc);
        }
        return Ok(());
    }
    for s in 0..substeps {
        let t = Instant::now();
        p.step_bodies(h);
        p.device_colliders(scratch);
        if let Some(dc) = gpu.contacts() {
            dc.set_colliders(s, scratch);
        }
        *host_time += t.elapsed();
        gpu.run_slots(s, 1)?;
        let partials = gpu.read_partials(s, 1)?;
        let t = Instant::now();
        p.apply_device(partials, groups, nc);
        *host_time += t.elapsed();
    }
    Ok(())
}

impl Coupling<'_> {
    fn begin_frame(&mut self, substeps: u32) {
        match self {
            Coupling::Own(p) => p.begin_frame(substeps),
            Coupling::User { stage, .. } => stage.begin_frame(),
        }
    }

    fn begin_substep(&mut self, packed: &Packed) {
        self.stage().begin_substep(packed);
    }

    /// Particles were moved outside the stages (the quarantine restored some).
    fn moved(&mut self) {
        self.stage().moved();
    }

    fn stage(&mut self) -> &mut ContactStage {
        match self {
            Coupling::Own(p) => p.stage_mut(),
            Coupling::User { stage, .. } => stage,
        }
    }

    /// After the integrate stage of substep `k` (1-based).
    fn substep(&mut self, packed: &mut Packed, h: f64, k: u32) {
        match self {
            Coupling::Own(p) => p.substep(packed, h),
            Coupling::User {
                stage,
                bodies,
                colliders,
            } => stage.substep(packed, bodies, colliders, k as f64 * h, h),
        }
    }
}

/// The GPU solver a config asks for: `None` runs on the CPU.
#[cfg(feature = "gpu")]
fn gpu_solver(config: &SimConfig) -> Result<Option<crate::gpu::GpuSolver>, SimError> {
    use crate::gpu::{GpuContext, GpuSolver, Kernel};
    let kernel = Kernel::of(config.integrator, config.exact_displacement);
    match (config.backend, kernel) {
        (Backend::Cpu, _) | (Backend::Auto, None) => Ok(None),
        (Backend::Gpu, None) => Err(no_kernel(config)),
        (Backend::Gpu, Some(k)) => Ok(Some(GpuSolver::new(GpuContext::shared(true)?, k)?)),
        (Backend::Auto, Some(k)) => Ok(GpuContext::shared(false)
            .ok()
            .map(|ctx| GpuSolver::new(ctx, k))
            .transpose()?),
    }
}

/// Contacts run on the CPU. Under `auto` a scene with props runs there entirely; under `gpu`
/// the springs run on the GPU and the state makes a round trip every substep for the contacts.
/// A part added at run time, checked as the one entry of an otherwise empty scene, so its
/// errors name it as a scene file's would (`add_cloth: cloths[0].resolution: ...`).
fn valid_part(scene: &Scene, what: &str) -> Result<(), Error> {
    let issues = scene.validate();
    if issues.is_empty() {
        Ok(())
    } else {
        Err(crate::SceneError::Invalid {
            path: what.into(),
            issues,
        }
        .into())
    }
}

fn props_backend(asked: Backend) -> Backend {
    match asked {
        Backend::Auto => Backend::Cpu,
        b => b,
    }
}

/// A build without the `gpu` feature refuses `Backend::Gpu` (`auto` falls back to the CPU).
#[cfg(not(feature = "gpu"))]
fn refuse_gpu(config: &SimConfig) -> Result<(), SimError> {
    if config.backend == Backend::Gpu {
        return Err(crate::error::GpuError::NotBuilt.into());
    }
    Ok(())
}

#[cfg(feature = "gpu")]
fn no_kernel(config: &SimConfig) -> SimError {
    let supported = crate::gpu::Kernel::supported()
        .map(|i| i.name())
        .collect::<Vec<_>>()
        .join(", ");
    let extra = if config.integrator == Integrator::Harmonic {
        " (harmonic runs on the GPU without exact_displacement)"
    } else {
        ""
    };
    crate::error::GpuError::NoKernel {
        integrator: config.integrator,
        supported,
        extra,
    }
    .into()
}

impl Simulation {
    /// Takes a World of [`crate::Particle`], [`crate::Spring`] and [`crate::Pin`] components.
    pub fn new(world: World, config: SimConfig) -> Result<Self, SimError> {
        Self::with_props(world, config, None)
    }

    /// As [`Self::new`], with rigid props: a rapier world whose colliders the cloth touches,
    /// and [`crate::contacts::Attachment`] components on particles.
    pub fn with_props(
        world: World,
        mut config: SimConfig,
        props: Option<Props>,
    ) -> Result<Self, SimError> {
        config.check()?;
        if props.is_some() {
            config.backend = props_backend(config.backend);
        }
        let mut sim = Self {
            world,
            config,
            packed: Packed::default(),
            solver: Solver::new(config.integrator, config.exact_displacement, config.gravity),
            dirty: true,
            grabbed: Vec::new(),
            cloths: Vec::new(),
            next_cloth: 0,
            contained: Vec::new(),
            newly_quarantined: 0,
            choice: None,
            parallel: false,
            steps: 0,
            time: 0.0,
            stats: StepStats::default(),
            #[cfg(feature = "gpu")]
            gpu: gpu_solver(&config)?,
            props,
            user_stage: None,
            #[cfg(feature = "gpu")]
            device_scratch: Vec::new(),
            contact: ContactDef::default(),
            frame: Frame::default(),
        };
        #[cfg(not(feature = "gpu"))]
        refuse_gpu(&config)?;
        sim.gather()?;
        Ok(sim)
    }

    /// The scene's World, settings, bodies and cloth triangles. The scene is validated first
    /// (within the default [`Limits`]), so one built in code gets the same located errors as a
    /// file.
    pub fn from_scene(scene: &Scene) -> Result<Self, SimError> {
        Self::from_scene_with(scene, &Limits::DEFAULT)
    }

    /// As [`Self::from_scene`], within `limits`.
    pub fn from_scene_with(scene: &Scene, limits: &Limits) -> Result<Self, SimError> {
        let issues = scene.validate_with(limits);
        if !issues.is_empty() {
            return Err(SimError::InvalidScene(issues));
        }
        let built = scene.build();
        let mut sim = Self::with_props(built.world, built.config, built.props)?;
        for e in built.cloths {
            sim.cloths.push((ClothId(sim.next_cloth), e));
            sim.next_cloth += 1;
        }
        Ok(sim)
    }

    /// Game-loop step: adds `frame_dt` (the frame's wall time, s) to the time owed and takes
    /// as many fixed steps of `dt` as fit, at most [`Self::set_max_steps_per_advance`] (8 by
    /// default; the rest is dropped, so a slow frame cannot make the next one slower still).
    /// The answer's `alpha` is for [`Self::render`].
    ///
    /// ```
    /// # use harmonic::prelude::*;
    /// # let scene = Scene::parse("Scene(dt: 0.01, particles: [(position: (0.0, 0.0, 0.0), mass: 1.0)])", "s").unwrap();
    /// let mut sim = Simulation::from_scene(&scene)?;
    /// let a = sim.advance(0.025)?; // 2.5 steps of 0.01 s owed
    /// assert_eq!((a.steps, (a.alpha * 100.0).round()), (2, 50.0));
    /// # Ok::<(), harmonic::SimError>(())
    /// ```
    pub fn advance(&mut self, frame_dt: f64) -> Result<Advance, SimError> {
        if !(frame_dt.is_finite() && frame_dt >= 0.0) {
            return Err(SimError::BadFrameTime(frame_dt));
        }
        let dt = self.config.dt;
        self.frame.accumulator += frame_dt;
        let mut steps = 0;
        while self.frame.accumulator >= dt && steps < self.frame.max_steps {
            self.frame.prev.clone_from(&self.packed.x);
            self.step()?;
            self.frame.accumulator -= dt;
            steps += 1;
        }
        let dropped = (self.frame.accumulator - dt).max(0.0);
        self.frame.accumulator -= dropped;
        Ok(Advance {
            steps,
            alpha: (self.frame.accumulator / dt).clamp(0.0, 1.0),
            dropped,
        })
    }

    /// The most steps one [`Self::advance`] takes.
    pub fn set_max_steps_per_advance(&mut self, steps: u32) {
        self.frame.max_steps = steps.max(1);
    }

    /// Positions `alpha` of the way from the state before the last advanced step to the
    /// current one, their vertex normals (area-weighted over the triangles, zero for a particle
    /// in none), and the triangles: ready for a vertex buffer, without allocation after the
    /// first frame.
    pub fn render(&mut self, alpha: f64) -> RenderView<'_> {
        let f = &mut self.frame;
        let triangles = frame_triangles(&f.custom, &f.triangles, &self.cloths, &self.world);
        let x = &self.packed.x;
        let prev = if f.prev.len() == x.len() { &f.prev } else { x };
        f.positions.clear();
        f.positions
            .extend(prev.iter().zip(x).map(|(p, c)| p.lerp(*c, alpha).as_vec3()));
        f.normals.clear();
        f.normals.resize(x.len(), Vec3::ZERO);
        let n = f.positions.len() as u32;
        for t in triangles {
            if t.iter().any(|&i| i >= n) {
                continue;
            }
            let [a, b, c] = t.map(|i| f.positions[i as usize]);
            // The cross product's length is twice the area: larger faces weigh more.
            let face = (b - a).cross(c - a);
            for &i in t {
                f.normals[i as usize] += face;
            }
        }
        for v in &mut f.normals {
            *v = v.normalize_or_zero();
        }
        RenderView {
            positions: &f.positions,
            normals: &f.normals,
            triangles,
        }
    }

    /// The triangles drawn by [`Self::render`]: the cloths' from a scene, or your own mesh
    /// over the particles (scene-order indices).
    pub fn triangles(&self) -> &[[u32; 3]] {
        frame_triangles(
            &self.frame.custom,
            &self.frame.triangles,
            &self.cloths,
            &self.world,
        )
    }

    pub fn set_triangles(&mut self, triangles: Vec<[u32; 3]>) {
        self.frame.custom = Some(triangles);
    }

    /// Loads, validates and builds a scene file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, Error> {
        Ok(Self::from_scene(&Scene::load(path)?)?)
    }

    /// Advances one frame of `dt`. Stages, in order:
    /// 1. gather: World → buffers, only if the World may have changed (see [`Self::world_mut`]);
    /// 2. integrate: `substeps` substeps on the buffers (no allocation), each followed by the
    ///    contact stage when the scene has bodies;
    /// 3. scatter: buffers → World.
    ///
    /// A scene without colliders has no contact stage. The state the World gets is always
    /// finite: a particle gone non-finite is quarantined ([`Self::quarantined`]).
    pub fn step(&mut self) -> Result<&StepStats, SimError> {
        self.step_coupled(None)
    }

    /// As [`Self::step`], with the caller's own rapier sets as the rigid side, the way rapier's
    /// own step takes them: particles collide with `colliders` and push the dynamic bodies of
    /// `bodies`; particles with an [`crate::contacts::Attachment`] follow their body.
    ///
    /// The engine does not step these sets: the caller's loop steps rapier once per frame,
    /// before or after this call. Within the frame a moving body is taken at its current
    /// velocity (its pose `k·h` ahead at substep `k`), which is what rapier's step will do.
    /// A simulation whose scene has bodies of its own refuses this (use [`Self::step`]).
    pub fn step_with(
        &mut self,
        bodies: &mut RigidBodySet,
        colliders: &ColliderSet,
    ) -> Result<&StepStats, SimError> {
        if self.props.is_some() {
            return Err(SimError::OwnBodies);
        }
        if self.dirty {
            self.gather()?;
        }
        let stage = self.user_stage.get_or_insert_with(|| {
            let mut s = ContactStage::new(self.contact);
            s.gather(&self.world, &self.packed);
            s
        });
        if let Some(particle) = stage.dangling(&self.world, bodies) {
            return Err(SimError::DanglingAttachment { particle });
        }
        self.step_coupled(Some((bodies, colliders)))
    }

    fn step_coupled(
        &mut self,
        user: Option<(&mut RigidBodySet, &ColliderSet)>,
    ) -> Result<&StepStats, SimError> {
        let t0 = Instant::now();
        let gathered = self.dirty;
        self.contained.clear();
        if self.dirty {
            self.gather()?;
        }
        let t1 = Instant::now();
        let h = self.config.h();
        let substeps = self.config.substeps;
        let mut coupling = match (user, self.props.as_mut(), self.user_stage.as_mut()) {
            (Some((bodies, colliders)), _, Some(stage)) => Some(Coupling::User {
                stage,
                bodies,
                colliders,
            }),
            (None, Some(p), _) => Some(Coupling::Own(p)),
            _ => None,
        };
        let mut contacts = Duration::ZERO;
        if let Some(c) = coupling.as_mut() {
            c.begin_frame(substeps);
        }
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &mut self.gpu {
            match coupling.as_mut() {
                // On the device the quarantine checks the state where it comes back: once per
                // frame when the substeps go in one submit.
                None => {
                    // Every substep in one submit; the state comes back once, for the scatter.
                    gpu.run(substeps)?;
                    gpu.read_back(&mut self.packed)?;
                    contain(&mut self.packed, &self.world, &mut self.contained);
                }
                Some(Coupling::Own(p)) if gpu.contacts().is_some() => {
                    device_frame(gpu, p, &mut self.device_scratch, substeps, h, &mut contacts)?;
                    gpu.read_back(&mut self.packed)?;
                    contain(&mut self.packed, &self.world, &mut self.contained);
                }
                Some(c) => {
                    // Contacts run on the CPU: the state goes back and forth every substep.
                    for k in 1..=substeps {
                        let t = Instant::now();
                        c.begin_substep(&self.packed);
                        contacts += t.elapsed();
                        gpu.run(1)?;
                        gpu.read_back(&mut self.packed)?;
                        let t = Instant::now();
                        c.substep(&mut self.packed, h, k);
                        contacts += t.elapsed();
                        if contain(&mut self.packed, &self.world, &mut self.contained) {
                            c.moved();
                        }
                        gpu.write_state(&self.packed);
                    }
                }
            }
            return self.finish_frame(t0, t1, gathered, contacts);
        }
        let (solver, packed) = (&mut self.solver, &mut self.packed);
        let (world, found) = (&self.world, &mut self.contained);
        let contacts_time = &mut contacts;
        let mut integrate = move || {
            (1..=substeps).try_for_each(|k| {
                match coupling.as_mut() {
                    None => solver.substep(packed, h)?,
                    Some(c) => {
                        let t = Instant::now();
                        c.begin_substep(packed);
                        *contacts_time += t.elapsed();
                        solver.substep(packed, h)?;
                        let t = Instant::now();
                        c.substep(packed, h, k);
                        *contacts_time += t.elapsed();
                    }
                }
                if contain(packed, world, found) {
                    if let Some(c) = coupling.as_mut() {
                        c.moved();
                    }
                }
                Ok::<(), SimError>(())
            })
        };
        if self.parallel {
            // One rayon job per frame: the passes inside run from a worker's own deque, so
            // the only allocation is the injector's queue block, recycled every 63 frames.
            rayon::scope(|_| integrate())?;
        } else {
            integrate()?;
        }
        self.finish_frame(t0, t1, gathered, contacts)
    }

    /// The end of a frame: the quarantine (the state is finite: every substep ended with
    /// [`contain`]), then the scatter.
    fn finish_frame(
        &mut self,
        t0: Instant,
        t1: Instant,
        gathered: bool,
        contacts: Duration,
    ) -> Result<&StepStats, SimError> {
        let t2 = Instant::now();
        self.quarantine();
        self.steps += 1;
        self.time += self.config.dt;
        let quarantined = std::mem::take(&mut self.newly_quarantined);
        self.packed.scatter(&mut self.world);
        let t3 = Instant::now();
        self.stats = StepStats {
            gather: t1 - t0,
            integrate: (t2 - t1).saturating_sub(contacts),
            contacts,
            scatter: t3 - t2,
            gathered,
            substeps: self.config.substeps,
            quarantined,
        };
        Ok(&self.stats)
    }

    /// Pins the particles this frame contained and marks them [`Quarantined`]; their state is
    /// already restored. Re-gathers on the next step, so they stay frozen from then on.
    fn quarantine(&mut self) -> usize {
        if self.contained.is_empty() {
            return 0;
        }
        self.contained.sort_unstable();
        self.contained.dedup();
        for &i in &self.contained {
            let e = self.packed.entities[i];
            let was_pinned = self.packed.inv_mass[i] == 0.0;
            let q = Quarantined {
                step: self.steps,
                was_pinned,
            };
            let _ = self.world.insert(e, (Pin, q));
            // At rest where it was put back, so a release starts it from there.
            if let Ok(mut p) = self.world.get::<&mut crate::components::Particle>(e) {
                p.position = self.packed.x[i];
                p.velocity = DVec3::ZERO;
            }
            self.grabbed.retain(|g| *g != e);
        }
        self.dirty = true;
        let n = self.contained.len();
        self.contained.clear();
        self.newly_quarantined += n;
        n
    }

    /// Particles in quarantine (scene order): each went non-finite in a step and was frozen at
    /// its last finite position. A game may log them, hide them, or release them.
    pub fn quarantined(&self) -> Vec<(usize, Quarantined)> {
        let mut out: Vec<_> = self
            .world
            .query::<(Entity, &Quarantined)>()
            .iter()
            .filter_map(|(e, q)| self.packed.index_of(e).map(|i| (i, *q)))
            .collect();
        out.sort_unstable_by_key(|(i, _)| *i);
        out
    }

    /// Lets a quarantined particle (scene order) move again, unpinned unless it was pinned
    /// before; whatever made it non-finite should be fixed first, or it comes straight back.
    pub fn release_quarantine(&mut self, index: usize) -> Result<(), SimError> {
        let e = self.particle_entity(index)?;
        let q = self
            .world
            .remove_one::<Quarantined>(e)
            .map_err(|_| SimError::NotQuarantined { index })?;
        if !q.was_pinned {
            let _ = self.world.remove_one::<Pin>(e);
        }
        self.dirty = true;
        Ok(())
    }

    /// What the step needs packed: cloth grids kept whole for an integrator with a grid pass
    /// (on either back end), the colouring only for the sweeping integrators and the GPU.
    fn gather_options(&self) -> GatherOptions {
        #[cfg(feature = "gpu")]
        let gpu = self.gpu.is_some();
        #[cfg(not(feature = "gpu"))]
        let gpu = false;
        let i = self.config.integrator;
        let keep_grids = if gpu {
            i.runs_on_gpu_grids()
        } else {
            i.runs_on_grids(self.config.exact_displacement)
        };
        GatherOptions {
            keep_grids,
            colouring: gpu || self.config.integrator.needs_colouring(),
        }
    }

    fn gather(&mut self) -> Result<(), SimError> {
        let options = self.gather_options();
        // In place: the old buffers go before the new ones are made (never two copies), and
        // only once the World is known to be sound (an error leaves them as they were).
        self.packed.regather(&self.world, options)?;
        // Frozen before anything reads them: particles with a velocity set non-finite from
        // outside, and the free ends of springs beyond f32's range (the device's precision,
        // where they turn non-finite at once; the CPU does the same so the back ends agree).
        let over = |v: f64| v > f32::MAX as f64;
        let p = &self.packed;
        self.contained.extend(
            p.all_springs()
                .filter(|s| over(s.stiffness) || over(s.damping))
                .flat_map(|s| [s.a as usize, s.b as usize])
                .filter(|&i| p.inv_mass[i] != 0.0),
        );
        contain(&mut self.packed, &self.world, &mut self.contained);
        if !self.contained.is_empty() {
            self.quarantine();
            self.packed.regather(&self.world, options)?;
        }
        self.solver.invalidate();
        self.parallel = crate::integrate::runs_parallel(&self.packed);
        self.choose_substeps();
        self.solver.prepare(&self.packed, self.config.h())?;
        if let Some(p) = &mut self.props {
            if let Some(particle) = p.dangling(&self.world) {
                return Err(SimError::DanglingAttachment { particle });
            }
            p.gather(&self.world, &self.packed);
        }
        if let Some(s) = &mut self.user_stage {
            s.gather(&self.world, &self.packed);
        }
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &mut self.gpu {
            let c = &self.config;
            let lin = self.solver.coefficients();
            gpu.upload(&self.packed, lin, c.gravity, c.h(), c.integrator)?;
        }
        #[cfg(feature = "gpu")]
        self.device_contacts()?;
        self.dirty = false;
        Ok(())
    }

    /// Holds particle `index` (scene order) at `target`, at rest: the mouse drag of a viewer,
    /// a hand picking cloth up. A free particle is pinned until [`Self::release`]; a pinned
    /// one is moved. Re-gathers on the next step (like any World change).
    pub fn grab(&mut self, index: usize, target: DVec3) -> Result<(), SimError> {
        if !target.is_finite() {
            return Err(SimError::BadPosition(target));
        }
        let entity = self.particle_entity(index)?;
        if self.world.get::<&Pin>(entity).is_err() {
            self.world
                .insert_one(entity, Pin)
                .map_err(|_| SimError::NoParticle { index })?;
            self.grabbed.push(entity);
        }
        if let Ok(mut p) = self.world.get::<&mut crate::Particle>(entity) {
            p.position = target;
            p.velocity = DVec3::ZERO;
        }
        self.dirty = true;
        Ok(())
    }

    /// Lets go of a particle [`Self::grab`] pinned (one pinned by its scene stays pinned).
    pub fn release(&mut self, index: usize) -> Result<(), SimError> {
        let entity = self.particle_entity(index)?;
        if let Some(k) = self.grabbed.iter().position(|&e| e == entity) {
            self.grabbed.swap_remove(k);
            let _ = self.world.remove_one::<Pin>(entity);
            self.dirty = true;
        }
        Ok(())
    }

    /// The cloths, each with its particles' range in scene order (see [`Self::positions`]);
    /// a cloth whose [`ClothSprings`] were despawned through [`Self::world_mut`] is left out.
    pub fn cloths(&self) -> impl Iterator<Item = (ClothId, std::ops::Range<usize>)> + '_ {
        self.cloths.iter().filter_map(|&(id, e)| {
            let r = grid_of(&self.world, e)?.range();
            Some((id, r.start as usize..r.end as usize))
        })
    }

    /// Adds a cloth, validated as a scene's would be, after every particle of the scene
    /// (scene order); its triangles join [`Self::triangles`]. Re-gathers on the next step.
    pub fn add_cloth(&mut self, cloth: &crate::scene::Cloth) -> Result<ClothId, Error> {
        let mut check = Scene::new(self.config.dt);
        check.cloths.push(cloth.clone());
        valid_part(&check, "add_cloth")?;
        let first = self
            .world
            .query::<&SceneIndex>()
            .iter()
            .map(|i| i.0 + 1)
            .max()
            .unwrap_or(0);
        let e = crate::scene::spawn_cloth(&mut self.world, first, cloth);
        let id = ClothId(self.next_cloth);
        self.next_cloth += 1;
        self.cloths.push((id, e));
        if let (Some(custom), Some(grid)) = (&mut self.frame.custom, grid_of(&self.world, e)) {
            grid.triangles(custom);
        }
        self.frame.triangles.take();
        self.dirty = true;
        Ok(id)
    }

    /// Removes a cloth: its particles, every spring touching them, their pins and attachments
    /// and its triangles. Later particles move up in scene order to close the gap.
    /// [`SimError::UnknownCloth`] if there is no such cloth, or if its [`ClothSprings`] were
    /// despawned through [`Self::world_mut`] (its particles are then ordinary particles).
    pub fn remove_cloth(&mut self, id: ClothId) -> Result<(), SimError> {
        let k = self
            .cloths
            .iter()
            .position(|(c, _)| *c == id)
            .ok_or(SimError::UnknownCloth)?;
        let (_, e) = self.cloths.remove(k);
        let grid = grid_of(&self.world, e);
        // Its springs' component removed by hand: the particles are no longer a cloth.
        let grid = grid.ok_or(SimError::UnknownCloth)?;
        // A built cloth's indices fit u32 (validated).
        let range = grid.range();
        let range = range.start as u32..range.end as u32;
        let n = range.end - range.start;
        let doomed: std::collections::HashSet<Entity> = self
            .world
            .query::<(Entity, &SceneIndex)>()
            .iter()
            .filter(|(_, i)| range.contains(&i.0))
            .map(|(e, _)| e)
            .collect();
        let mut springs: Vec<Entity> = self
            .world
            .query::<(Entity, &crate::Spring)>()
            .iter()
            .filter(|(_, s)| doomed.contains(&s.a) || doomed.contains(&s.b))
            .map(|(e, _)| e)
            .collect();
        // Cloth springs over any of its particles go too; later ones move up with theirs.
        let (lo, hi) = (range.start as u64, range.end as u64);
        for (e, c) in self.world.query_mut::<(Entity, &mut ClothSprings)>() {
            let r = c.grid.range();
            if r.start < hi && lo < r.end {
                springs.push(e);
            } else if r.start >= hi {
                c.grid.first -= n;
            }
        }
        for e in springs.into_iter().chain(doomed.iter().copied()) {
            let _ = self.world.despawn(e);
        }
        self.grabbed.retain(|e| !doomed.contains(e));
        for i in self.world.query_mut::<&mut SceneIndex>() {
            if i.0 >= range.end {
                i.0 -= n;
            }
        }
        if let Some(custom) = &mut self.frame.custom {
            custom.retain(|t| !t.iter().any(|i| range.contains(i)));
            for t in custom.iter_mut() {
                for i in t.iter_mut() {
                    if *i >= range.end {
                        *i -= n;
                    }
                }
            }
        }
        self.frame.triangles.take();
        self.frame.prev.clear();
        self.dirty = true;
        Ok(())
    }

    /// Adds a rigid body, validated as a scene's would be. The first body of a simulation
    /// without any brings the rapier world and the contact stage (default contact material,
    /// see [`Self::set_contact_material`]).
    pub fn add_body(
        &mut self,
        body: &crate::scene::props::BodyDef,
    ) -> Result<crate::contacts::RigidProp, Error> {
        let mut check = Scene::new(self.config.dt);
        check.bodies.push(body.clone());
        valid_part(&check, "add_body")?;
        if self.props.is_none() {
            let (props, _) = Props::build(&[], self.contact, self.config.gravity, &mut self.world)
                .map_err(|e| SimError::BadBody(e.to_string()))?;
            self.props = Some(props);
        }
        let props = self.props.as_mut().ok_or(SimError::UnknownBody)?;
        let prop = props
            .add_body(body, &mut self.world)
            .map_err(SimError::BadBody)?;
        self.dirty = true;
        Ok(prop)
    }

    /// Removes a body with its collider; particles attached to it go free.
    pub fn remove_body(&mut self, prop: crate::contacts::RigidProp) -> Result<(), SimError> {
        let props = self.props.as_mut().ok_or(SimError::UnknownBody)?;
        if !props.remove_body(prop.body, &mut self.world) {
            return Err(SimError::UnknownBody);
        }
        self.dirty = true;
        Ok(())
    }

    /// Pins particle `index` (scene order) where it is. Re-gathers on the next step.
    pub fn pin(&mut self, index: usize) -> Result<(), SimError> {
        let e = self.particle_entity(index)?;
        let _ = self.world.insert_one(e, Pin);
        self.grabbed.retain(|g| *g != e);
        self.dirty = true;
        Ok(())
    }

    /// Frees particle `index` (scene order) from its pin.
    pub fn unpin(&mut self, index: usize) -> Result<(), SimError> {
        let e = self.particle_entity(index)?;
        let _ = self.world.remove_one::<Pin>(e);
        self.grabbed.retain(|g| *g != e);
        self.dirty = true;
        Ok(())
    }

    /// The entity of particle `index` in scene order.
    pub fn particle_entity(&self, index: usize) -> Result<Entity, SimError> {
        self.packed
            .entities
            .get(index)
            .copied()
            .filter(|&e| self.world.contains(e))
            .ok_or(SimError::NoParticle { index })
    }

    pub fn world(&self) -> &World {
        &self.world
    }

    /// Mutable access; the next step re-gathers the World (state and topology), and the
    /// cloths' triangles are made again from their [`ClothSprings`] when next asked for.
    pub fn world_mut(&mut self) -> &mut World {
        self.dirty = true;
        self.frame.triangles.take();
        &mut self.world
    }

    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// Changes the step settings; coefficients are recomputed on the next step.
    pub fn set_config(&mut self, mut config: SimConfig) -> Result<(), SimError> {
        config.check()?;
        if self.props.is_some() {
            config.backend = props_backend(config.backend);
        }
        let keep_solver = config.integrator == self.config.integrator
            && config.exact_displacement == self.config.exact_displacement
            && config.gravity == self.config.gravity;
        #[cfg(feature = "gpu")]
        if !(keep_solver && config.backend == self.config.backend) {
            self.gpu = gpu_solver(&config)?;
            self.dirty = true;
        }
        #[cfg(not(feature = "gpu"))]
        refuse_gpu(&config)?;
        self.config = config;
        if !keep_solver {
            self.solver = Solver::new(config.integrator, config.exact_displacement, config.gravity);
        }
        if self.gather_options() != self.packed.options {
            // The new integrator or back end takes the cloths in another form.
            self.dirty = true;
            return self.gather();
        }
        self.choose_substeps();
        self.solver.prepare(&self.packed, self.config.h())?;
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &mut self.gpu {
            gpu.set_step(&self.packed, self.solver.coefficients(), self.config.h())?;
        }
        #[cfg(feature = "gpu")]
        self.device_contacts()?;
        Ok(())
    }

    /// With the springs on the GPU and colliders the device stage takes (balls and cuboids,
    /// no attachments), contacts run there too; otherwise on the CPU, with the state read back
    /// every substep.
    #[cfg(feature = "gpu")]
    fn device_contacts(&mut self) -> Result<(), SimError> {
        let (Some(gpu), Some(p)) = (&mut self.gpu, &self.props) else {
            return Ok(());
        };
        if !p.device_ready() {
            return Ok(());
        }
        let masses = p.device_masses(&self.packed);
        let c = p.contact();
        gpu.enable_contacts(&crate::gpu::contacts::ContactSetup {
            masses: &masses,
            colliders: p.colliders().len(),
            slots: self.config.substeps,
            h: self.config.h(),
            thickness: c.thickness,
            restitution: c.restitution,
        })?;
        Ok(())
    }

    /// Whether the contact stage runs on the GPU.
    pub fn contacts_on_gpu(&mut self) -> bool {
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &mut self.gpu {
            return gpu.contacts().is_some();
        }
        false
    }

    /// The rigid props (rapier world, contact statistics), when the scene has bodies.
    pub fn props(&self) -> Option<&Props> {
        self.props.as_ref()
    }

    /// Mutable props: move kinematic bodies, push dynamic ones, add colliders.
    pub fn props_mut(&mut self) -> Option<&mut Props> {
        self.props.as_mut()
    }

    /// What the contact stage did in the last frame (None when the simulation has never
    /// coupled with bodies).
    pub fn contact_stats(&self) -> Option<&ContactStats> {
        match (&self.props, &self.user_stage) {
            (Some(p), _) => Some(p.stats()),
            (None, Some(s)) => Some(&s.stats),
            (None, None) => None,
        }
    }

    /// The cloth's contact material against the caller's sets ([`Self::step_with`]); a scene's
    /// own bodies use the scene's `contact`.
    pub fn set_contact_material(&mut self, contact: ContactDef) {
        self.contact = contact;
        if let Some(s) = &mut self.user_stage {
            s.contact = contact;
        }
    }

    /// The back end the integrate stage runs on: `Cpu` or `Gpu` (never `Auto`).
    pub fn backend(&self) -> Backend {
        #[cfg(feature = "gpu")]
        if self.gpu.is_some() {
            return Backend::Gpu;
        }
        Backend::Cpu
    }

    /// The GPU adapter in use, e.g. "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu)".
    pub fn gpu_adapter(&self) -> Option<String> {
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &self.gpu {
            return Some(gpu.context().describe());
        }
        None
    }

    /// The GPU solver, when the step runs on the GPU (for tools and tests).
    #[cfg(feature = "gpu")]
    pub fn gpu_solver(&mut self) -> Option<&mut crate::gpu::GpuSolver> {
        self.gpu.as_mut()
    }

    fn choose_substeps(&mut self) {
        self.choice = self.config.auto_substeps.then(|| {
            let choice = step_control::choose(&self.packed, self.config.integrator, self.config.dt);
            self.config.substeps = choice.substeps;
            choice
        });
    }

    /// What automatic step control chose (None with fixed substeps).
    pub fn step_choice(&self) -> Option<&StepChoice> {
        self.choice.as_ref()
    }

    /// Positions in scene order (see [`crate::SceneIndex`]), as of the last step.
    pub fn positions(&self) -> &[DVec3] {
        &self.packed.x
    }

    pub fn velocities(&self) -> &[DVec3] {
        &self.packed.v
    }

    /// The packed buffers (read-only), for metrics and tools.
    pub fn packed(&self) -> &Packed {
        &self.packed
    }

    pub fn stats(&self) -> &StepStats {
        &self.stats
    }

    /// Frames stepped so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Simulated time (s).
    pub fn time(&self) -> f64 {
        self.time
    }

    pub fn diagnostics(&self) -> Diagnostics {
        Diagnostics {
            energy: metrics::energy(&self.packed, self.config.gravity),
            max_strain: metrics::max_strain(&self.packed),
            step_ratio: metrics::worst_step_ratio(&self.packed, self.config.h())
                .map_or(0.0, |r| r.0),
            non_finite: metrics::non_finite_count(&self.packed),
            quarantined: self.world.query::<&Quarantined>().iter().count(),
        }
    }
}
