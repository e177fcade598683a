//! The `Simulation` facade: a World, its packed buffers and the schedule that steps them.
//!
//! A frame's order is data: the [`Schedule`] of the stages the scene needs, built in
//! `build_schedule` and run by the one loop of `run.rs`; the frame's start and end are in
//! `step.rs`. The game-loop frame, run-time edits, the quarantine and the coupling with rigid
//! bodies each have a file.

use std::path::Path;
use std::time::{Duration, Instant};

use glam::{DVec3, Vec3};
use hecs::{Entity, World};

use crate::buffers::{GatherOptions, Packed};
use crate::components::{ClothGrid, ClothSprings, Pin, Quarantined, SceneIndex};
use crate::config::{Backend, SimConfig};
use rapier3d::prelude::{ColliderSet, RigidBodySet};

use crate::contacts::{ContactStage, ContactStats, Props};
use crate::error::{Error, SimError};
use crate::integrate::Solver;
use crate::metrics;
use crate::scene::props::ContactMaterial;
use crate::scene::{Limits, Scene};
use crate::schedule::{Needs, Schedule, StepStats};
use crate::step_control::{self, StepChoice};

mod accuracy;
mod coupling;
mod drive;
mod edit;
mod forces;
mod frame;
mod motion;
mod quarantine;
mod run;
mod step;
mod tearing;

use coupling::Coupling;
pub use drive::DriveId;
use frame::{grid_of, range_of, Frame};
pub use frame::{Advance, RenderView};
use quarantine::contain;

/// Live figures of the current state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Diagnostics {
    /// Kinetic + spring + gravitational energy (J).
    pub energy: f64,
    /// The cloth's stretch: the largest extension `δ/l0` of any spring (its tension).
    pub max_strain: f64,
    /// The largest compression `−δ/l0` of any spring (folds and bending), apart from the
    /// stretch.
    pub max_compression: f64,
    /// `h/h_c` of the stiffest spring (`h_c = π/ω0`).
    pub step_ratio: f64,
    /// Particles whose position or velocity is not finite: 0 after every step, which
    /// quarantines such particles (non-zero only for a state set from outside since).
    pub non_finite: usize,
    /// Particles in quarantine ([`Simulation::quarantined`]).
    pub quarantined: usize,
    /// The first frame of the run whose state was finite but wrong (see [`crate::Failure`]).
    pub failure: Option<crate::Failure>,
    /// What energy changes are measured against (J): `max(E_kin + E_spring, M |g| H)` with
    /// `M` the free particles' mass and `H` the diagonal of all particles' bounding box (the
    /// furthest a part of the scene can fall), taken when the World was last gathered (at
    /// load, and after a change to it).
    pub energy_scale: f64,
    /// The energy audit of the run so far (the lines summed over its frames; zero before the
    /// first step).
    pub audit: crate::EnergyAudit,
}

/// A mass-spring simulation over a hecs World.
pub struct Simulation {
    world: World,
    config: SimConfig,
    packed: Packed,
    solver: Solver,
    /// The World changed: the next step re-gathers it (topology and state).
    dirty: bool,
    /// Pins set or freed since the last step (packed index, pinned): the next step refreshes
    /// the mass split only ([`Packed::repin`]).
    pins: Vec<(usize, bool)>,
    /// Pinned particles moved since the last step: the device needs the state again.
    state_edited: bool,
    /// The automatic step choice, when `auto_substeps` is on.
    choice: Option<StepChoice>,
    /// The network's frequency and damping, taken at every gather and pin refresh when a
    /// choice needs it (automatic substeps, or the integrator still to choose).
    network: Option<step_control::Network>,
    /// Whether the passes run on rayon's pool (large scenes only).
    parallel: bool,
    steps: u64,
    time: f64,
    stats: StepStats,
    /// The stages a frame runs, in order.
    schedule: Schedule,
    /// The game's per-particle forces ([`Simulation::set_forces`]).
    forces: Option<forces::Forces>,
    /// Driven pins and motion constraints ([`Simulation::drive`]).
    drives: drive::Drives,
    /// The cloths that feel air, and their triangles.
    air: crate::air::AirSurfaces,
    /// The cloths' tethers, in packed indices.
    tethers: crate::tether::TetherStage,
    /// The cloths' stretch limits, in packed indices.
    stretch: crate::stretch::StretchStage,
    /// The colliding cloths' particles and the frame's candidate pairs.
    collide: crate::collide::CollideStage,
    /// The tearable cloths' springs, and the last frame's breaks.
    tear: crate::tear::TearStage,
    torn: Vec<crate::Tear>,
    /// The last frame's tear added particles: gathered before the step returns.
    opened: bool,
    /// Whether the frame times its stages ([`Simulation::set_timers`]).
    timers: bool,
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
    contact: ContactMaterial,
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
    /// The run's first [`crate::Failure`].
    failure: Option<crate::Failure>,
    /// [`Diagnostics::energy_scale`], taken at every World gather.
    energy_scale: f64,
    /// The energy audit's books and scratch.
    auditor: crate::audit::Auditor,
    /// The automatic substeps' accuracy controller.
    controller: accuracy::Controller,
    /// [`metrics::EnergyParts::internal`] at the last World gather (the a priori substeps').
    energy_in_motion: f64,
    /// Why the integrator was chosen, when the config left it to the springs.
    integrator_reason: Option<String>,
}

/// A cloth of the simulation (from its scene or added at run time), to remove it by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ClothId(u32);

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
    let extra = if config.integrator == crate::Integrator::Harmonic {
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
        // Gathered first as symplectic Euler: both candidates step the grids whole, so the
        // choice reads the simulation's own gather, not a second copy of the cloth.
        if config.auto_integrator {
            config.integrator = crate::Integrator::SymplecticEuler;
        }
        let mut sim = Self {
            world,
            config,
            packed: Packed::default(),
            solver: Solver::new(config.integrator, config.exact_displacement, config.gravity),
            dirty: true,
            pins: Vec::new(),
            state_edited: false,
            grabbed: Vec::new(),
            cloths: Vec::new(),
            next_cloth: 0,
            contained: Vec::new(),
            newly_quarantined: 0,
            failure: None,
            energy_scale: 0.0,
            auditor: Default::default(),
            controller: Default::default(),
            energy_in_motion: 0.0,
            integrator_reason: None,
            choice: None,
            network: None,
            parallel: false,
            steps: 0,
            time: 0.0,
            stats: StepStats::default(),
            schedule: Schedule::default(),
            forces: None,
            drives: Default::default(),
            air: Default::default(),
            tethers: Default::default(),
            stretch: Default::default(),
            collide: Default::default(),
            tear: Default::default(),
            opened: false,
            torn: Vec::new(),
            timers: true,
            #[cfg(feature = "gpu")]
            gpu: gpu_solver(&config)?,
            props,
            user_stage: None,
            #[cfg(feature = "gpu")]
            device_scratch: Vec::new(),
            contact: ContactMaterial::default(),
            frame: Frame::default(),
        };
        #[cfg(not(feature = "gpu"))]
        refuse_gpu(&config)?;
        sim.register_cloths();
        sim.gather()?;
        if let (true, Some(network)) = (config.auto_integrator, sim.network) {
            let (integrator, why) = step_control::choose_integrator(&network, config.dt);
            sim.integrator_reason = Some(why);
            if integrator != sim.config.integrator {
                let c = &mut sim.config;
                c.integrator = integrator;
                sim.solver = Solver::new(integrator, c.exact_displacement, c.gravity);
                #[cfg(feature = "gpu")]
                {
                    sim.gpu = gpu_solver(c)?;
                }
                sim.gather()?;
            }
        }
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
        // The scene's order of cloths and meshes.
        sim.cloths.clear();
        sim.next_cloth = 0;
        for e in built.cloths {
            sim.cloths.push((ClothId(sim.next_cloth), e));
            sim.next_cloth += 1;
        }
        Ok(sim)
    }

    /// Loads, validates and builds a scene file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, Error> {
        Ok(Self::from_scene(&Scene::load(path)?)?)
    }

    /// The ECS World: particles, springs, pins and bodies as components.
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

    /// How the simulation steps.
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
        if self.gather_options() != self.packed.topology.options {
            // The new integrator or back end takes the cloths in another form.
            self.dirty = true;
            return self.gather();
        }
        self.estimate_network();
        self.choose_substeps();
        self.solver.prepare(&self.packed, self.config.h())?;
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &mut self.gpu {
            gpu.set_step(&self.packed, self.solver.coefficients(), self.config.h())?;
        }
        #[cfg(feature = "gpu")]
        self.device_contacts()?;
        #[cfg(feature = "gpu")]
        self.device_tethers()?;
        #[cfg(feature = "gpu")]
        self.device_air()?;
        #[cfg(feature = "gpu")]
        self.device_collide()?;
        self.build_schedule(self.user_stage.is_some());
        Ok(())
    }

    /// The rigid props (rapier world, contact statistics), when the scene has bodies.
    pub fn props(&self) -> Option<&Props> {
        self.props.as_ref()
    }

    /// Mutable props: move kinematic bodies, push dynamic ones, add colliders.
    pub fn props_mut(&mut self) -> Option<&mut Props> {
        self.props.as_mut()
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

    /// The GPU solver, when the step runs on the GPU. Not API: for the lab and the tests.
    #[doc(hidden)]
    #[cfg(feature = "gpu")]
    pub fn gpu_solver(&mut self) -> Option<&mut crate::gpu::GpuSolver> {
        self.gpu.as_mut()
    }

    /// Estimates the network where a choice needs it ([`Self::choose_substeps`], the
    /// integrator at load).
    fn estimate_network(&mut self) {
        let wanted = self.config.auto_substeps
            || (self.config.auto_integrator && self.integrator_reason.is_none());
        self.network = wanted.then(|| step_control::Network::of(&self.packed));
    }

    /// The automatic substeps, from the last [`Self::estimate_network`].
    fn choose_substeps(&mut self) {
        let (config, network) = (&mut self.config, self.network);
        self.choice = network.filter(|_| config.auto_substeps).map(|n| {
            let choice = n.choose(config.integrator, config.dt);
            config.substeps = choice.substeps;
            choice
        });
        if let Some(c) = &self.choice {
            let residual = self.auditor.run.residual;
            self.controller.reset(c.substeps, &self.packed, residual);
            // The first frame's a priori; later choices start at the floor and adapt.
            if self.steps == 0 {
                self.config.substeps = self.controller.a_priori(
                    c,
                    &self.config,
                    self.energy_in_motion / self.energy_scale,
                );
            }
        }
    }

    /// The accuracy controller's record: how many times it changed the substeps, and the
    /// last motion check's error per frame as a share of the scene's size (NaN before one).
    pub fn accuracy(&self) -> (u32, f64) {
        match self.choice {
            Some(_) => (self.controller.changes, self.controller.motion),
            None => (0, f64::NAN),
        }
    }

    /// Why the integrator is the one it is, when [`SimConfig::auto_integrator`] chose it.
    pub fn integrator_choice(&self) -> Option<&str> {
        self.integrator_reason.as_deref()
    }

    /// What automatic step control chose (None with fixed substeps).
    pub fn step_choice(&self) -> Option<&StepChoice> {
        self.choice.as_ref()
    }

    /// Positions in scene order (see [`crate::SceneIndex`]), as of the last step.
    pub fn positions(&self) -> &[DVec3] {
        &self.packed.x
    }

    /// Particle velocities (m/s), in scene order, as of the last step.
    pub fn velocities(&self) -> &[DVec3] {
        &self.packed.v
    }

    /// The packed buffers (read-only). Not API: for the lab and the tests.
    #[doc(hidden)]
    pub fn packed(&self) -> &Packed {
        &self.packed
    }

    /// What the last frame did, and what each stage cost.
    pub fn stats(&self) -> &StepStats {
        &self.stats
    }

    /// Whether a frame times its stages (on by default). Off, as rapier's `Counters` can be,
    /// the substeps read no clock: [`StepStats::stages`] and [`StepStats::audit_time`] stay
    /// zero (the gather and the scatter are still timed, once a frame).
    pub fn set_timers(&mut self, on: bool) {
        self.timers = on;
    }

    /// The stages a frame runs, in order (as of the last step, or of the last change of the
    /// scene or settings before it): `schedule: {}` prints
    /// `gravity → integrate (symplectic-euler, 30 substeps) → quarantine`.
    pub fn schedule(&self) -> &Schedule {
        &self.schedule
    }

    /// Builds the schedule, in place, from what the scene needs now (`coupled`: this frame
    /// steps against the caller's rapier sets).
    fn build_schedule(&mut self, coupled: bool) {
        #[cfg(feature = "gpu")]
        let device_contacts = self.gpu.as_ref().is_some_and(|g| g.has_contacts());
        #[cfg(not(feature = "gpu"))]
        let device_contacts = false;
        #[cfg(feature = "gpu")]
        let device_tethers = self.gpu.as_ref().is_some_and(|g| g.has_tethers());
        #[cfg(not(feature = "gpu"))]
        let device_tethers = false;
        #[cfg(feature = "gpu")]
        let device_air = self.gpu.as_ref().is_some_and(|g| g.has_air());
        #[cfg(not(feature = "gpu"))]
        let device_air = false;
        let on = |device| if device { Backend::Gpu } else { Backend::Cpu };
        let contacts_on = match (&self.props, coupled) {
            (Some(_), _) if device_contacts => Some(Backend::Gpu),
            (Some(_), _) | (None, true) => Some(Backend::Cpu),
            (None, false) => None,
        };
        self.schedule.rebuild(Needs {
            gravity: self.config.gravity != DVec3::ZERO,
            forces: self.forces.as_ref().is_some_and(|f| f.game()),
            air: (!self.air.is_empty()).then_some(on(device_air)),
            tethers: (!self.tethers.is_empty()).then_some(on(device_tethers)),
            stretch: !self.stretch.is_empty(),
            collide: (!self.collide.is_empty()).then_some((
                on(self.collide.finds_on_device()),
                on(self.collide.passes_on_device()),
            )),
            tearing: !self.tear.is_empty(),
            drives: !self.drives.is_empty(),
            integrator: self.config.integrator,
            substeps: self.config.substeps,
            springs_on: self.backend(),
            contacts_on,
            device_contacts_per_substep: self.props.as_ref().is_some_and(|p| p.dynamic),
        });
    }

    /// Frames stepped so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Simulated time (s).
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Live figures of the current state: energy, strain, step ratio, non-finite count.
    pub fn diagnostics(&self) -> Diagnostics {
        let stretch = metrics::stretch(&self.packed);
        Diagnostics {
            energy: metrics::energy(&self.packed, self.config.gravity),
            max_strain: stretch.tension,
            max_compression: stretch.compression,
            failure: self.failure,
            energy_scale: self.energy_scale,
            audit: self.auditor.run,
            step_ratio: metrics::worst_step_ratio(&self.packed, self.config.h())
                .map_or(0.0, |r| r.0),
            non_finite: metrics::non_finite_count(&self.packed),
            quarantined: self.world.query::<&Quarantined>().iter().count(),
        }
    }
}
