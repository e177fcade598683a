//! The frame as a schedule: the ordered list of the stages a scene needs, built from the scene
//! and run by one loop for both back ends (`Simulation`'s `simulation/run.rs`), and what each
//! stage cost.
//!
//! A stage the scene does not need is not in its list: a scene without bodies has no contact
//! stage, one without gravity no gravity. Each kind declares where it runs in a frame
//! ([`StageKind::cadence`]), whether it needs the state on the host between substeps
//! ([`Stage::needs_host_state`]) and what it books in the energy audit
//! ([`StageKind::books`]); the order is written once, where the list is built.

mod stats;

pub use stats::{Failure, StepStats};

use std::fmt;
use std::ops::{AddAssign, Index, IndexMut};
use std::time::Duration;

use crate::config::{Backend, Integrator};

/// A kind of stage a frame may run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum StageKind {
    /// Gravity: a uniform acceleration, summed into the external acceleration the integrate
    /// kernel reads where it adds forces (a constant: no pass of its own).
    Gravity,
    /// Air on the cloths that have it ([`crate::Aero`]): once a frame, each triangle's drag and
    /// lift at the frame's start state in the wind ([`crate::Wind`]), held over the substeps
    /// as forces the force stage adds up (no pass of its own inside the substeps).
    Air,
    /// The game's per-particle forces ([`crate::Simulation::set_forces`]): once a frame, `F/m`
    /// is added to gravity into one acceleration per particle, which the integrate kernel reads
    /// where it reads gravity (no pass of its own inside the substeps).
    Forces,
    /// The springs' step: the integrator's kernel over every spring and particle.
    Integrate,
    /// Driven pins moved along their paths to the game's targets, and particles kept within
    /// their maximum distance of them ([`crate::Simulation::drive`]), a share every substep.
    Drive,
    /// Tethers ([`crate::Tethers`]): particles further than their limit from an anchor put
    /// back, their velocity away from it removed.
    Tethers,
    /// Stretch limits ([`crate::StretchLimit`]): springs longer than their limit put back,
    /// their ends' separating velocity removed.
    StretchLimit,
    /// Self-collision ([`crate::SelfCollision`]): particles of colliding cloths closer than
    /// their thickness pushed apart, their approach removed, with friction.
    SelfCollision,
    /// Rigid bodies (the scene's own rapier world or the caller's sets): attached particles
    /// follow their bodies, then particles are pushed out of colliders with friction and the
    /// dynamic bodies get the opposite impulses.
    Contacts,
    /// Tearing ([`crate::Tearing`]): at the frame's end, springs stretched past their
    /// cloth's breaking stretch break, and their triangles go from its surface.
    Tearing,
    /// Particles gone non-finite are frozen at their last finite position, before any spring
    /// reads them again.
    Quarantine,
}

impl StageKind {
    /// Every kind, in the order a frame runs them.
    pub const ALL: [StageKind; 11] = [
        StageKind::Gravity,
        StageKind::Air,
        StageKind::Forces,
        StageKind::Integrate,
        StageKind::Drive,
        StageKind::Tethers,
        StageKind::StretchLimit,
        StageKind::SelfCollision,
        StageKind::Contacts,
        StageKind::Quarantine,
        StageKind::Tearing,
    ];

    /// How many kinds there are (the length of [`StageTimes`]).
    pub const COUNT: usize = Self::ALL.len();

    /// The name the `schedule:` line and the docs use.
    pub fn name(self) -> &'static str {
        match self {
            StageKind::Gravity => "gravity",
            StageKind::Air => "air",
            StageKind::Forces => "forces",
            StageKind::Integrate => "integrate",
            StageKind::Drive => "drive",
            StageKind::Tethers => "tethers",
            StageKind::StretchLimit => "stretch-limit",
            StageKind::SelfCollision => "self-collision",
            StageKind::Contacts => "contacts",
            StageKind::Quarantine => "quarantine",
            StageKind::Tearing => "tearing",
        }
    }

    /// How often the stage runs within a frame.
    pub fn cadence(self) -> Cadence {
        match self {
            StageKind::Gravity => Cadence::Fused,
            StageKind::Air | StageKind::Forces | StageKind::Tearing => Cadence::Frame,
            StageKind::Integrate
            | StageKind::Drive
            | StageKind::Tethers
            | StageKind::StretchLimit
            | StageKind::SelfCollision
            | StageKind::Contacts
            | StageKind::Quarantine => Cadence::Substep,
        }
    }

    /// Where the stage sits against the integrate stage.
    pub fn place(self) -> Place {
        match self {
            StageKind::Gravity | StageKind::Air | StageKind::Forces => Place::BeforeIntegrate,
            StageKind::Integrate => Place::Integrate,
            StageKind::Drive
            | StageKind::Tethers
            | StageKind::StretchLimit
            | StageKind::SelfCollision
            | StageKind::Contacts
            | StageKind::Quarantine
            | StageKind::Tearing => Place::AfterIntegrate,
        }
    }

    /// What the stage books in the frame's energy audit ([`crate::EnergyAudit`]).
    pub fn books(self) -> &'static str {
        match self {
            StageKind::Gravity => "potential energy (part of the energy itself)",
            StageKind::Air => "forces: its work over the integrate stage's moves, with the game's",
            StageKind::Forces => "forces: their work over the integrate stage's moves",
            StageKind::Integrate => "damping: the dampers' loss",
            StageKind::Drive => {
                "attachments: the driven pins' moves and the maximum distances' projections"
            }
            StageKind::Tethers | StageKind::StretchLimit => {
                "limits: the change of E its projections made"
            }
            StageKind::SelfCollision => "contacts: the change of E its pushes and friction made",
            StageKind::Contacts => "attachments, contacts and friction: its projections",
            StageKind::Quarantine => "quarantine: the energy of the particles it froze",
            StageKind::Tearing => "torn: the energy the broken springs held",
        }
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// Where a stage sits against the integrate stage ([`StageKind::place`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Place {
    /// Before: a force summed into the external acceleration the kernel reads.
    BeforeIntegrate,
    /// The integrate stage itself.
    Integrate,
    /// After: a projection or check on the substep's new state.
    AfterIntegrate,
}

/// How often a stage runs within a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Cadence {
    /// Summed into the integrate kernel's external acceleration: no pass of its own.
    Fused,
    /// Once per frame: before the substeps (air and forces, their result then held for all
    /// of them), or at the frame's end (tearing).
    Frame,
    /// Once per substep (on the device, quarantine checks the state where it comes back to
    /// the host: after each substep where a host stage needs the state, else once a frame).
    Substep,
}

/// One stage of a scene's schedule: its kind and the back end it runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stage {
    /// What it does.
    pub kind: StageKind,
    /// Where it runs: [`Backend::Cpu`] or [`Backend::Gpu`] (never `Auto`).
    pub on: Backend,
}

impl Stage {
    /// Whether the stage needs the state on the host between substeps: a CPU stage in a frame
    /// whose springs run on the device (the state then goes back and forth every substep), and
    /// self-collision wherever its pass runs (the host decides each substep whether to find
    /// the candidates again). The quarantine only checks the state where it is on the host
    /// anyway.
    pub fn needs_host_state(&self) -> bool {
        let host = self.on == Backend::Cpu
            && matches!(
                self.kind,
                StageKind::Drive
                    | StageKind::Tethers
                    | StageKind::StretchLimit
                    | StageKind::Contacts
            );
        host || self.kind == StageKind::SelfCollision
    }
}

/// The ordered stages of a scene's frame, rebuilt whenever what the scene needs may have
/// changed (a gather, a new config, a cloth added, the first coupled step).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Schedule {
    stages: Vec<Stage>,
    integrator: Option<Integrator>,
    substeps: u32,
    device_per_substep: bool,
    /// Self-collision's candidates are found on the device.
    finds_on_device: bool,
}

/// What a scene asks of the schedule.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Needs {
    pub(crate) gravity: bool,
    /// The game set per-particle forces.
    pub(crate) forces: bool,
    /// The game drives particles.
    pub(crate) drives: bool,
    /// Cloths feel air: where its passes run.
    pub(crate) air: Option<Backend>,
    /// Cloths have tethers: where their clamp runs.
    pub(crate) tethers: Option<Backend>,
    /// Cloths have stretch limits.
    pub(crate) stretch: bool,
    /// Cloths tear.
    pub(crate) tearing: bool,
    /// Cloths collide with themselves and each other: where the candidates are found, and
    /// where the pass over them runs.
    pub(crate) collide: Option<(Backend, Backend)>,
    pub(crate) integrator: Integrator,
    pub(crate) substeps: u32,
    /// Where the springs run.
    pub(crate) springs_on: Backend,
    /// Where the contact stage runs, when the frame couples with bodies.
    pub(crate) contacts_on: Option<Backend>,
    /// The device's contact stage must hand the bodies their impulses after every substep
    /// (dynamic bodies): one submit per substep.
    pub(crate) device_contacts_per_substep: bool,
}

impl Schedule {
    /// The list for a scene's needs, in place (no allocation once built): the one place the
    /// order is written.
    pub(crate) fn rebuild(&mut self, n: Needs) {
        let stages = &mut self.stages;
        stages.clear();
        stages.reserve(StageKind::COUNT);
        let mut push = |kind, on| stages.push(Stage { kind, on });
        if n.gravity {
            push(StageKind::Gravity, n.springs_on);
        }
        if let Some(on) = n.air {
            push(StageKind::Air, on);
        }
        if n.forces || n.air.is_some() {
            push(StageKind::Forces, n.springs_on);
        }
        push(StageKind::Integrate, n.springs_on);
        if n.drives {
            push(StageKind::Drive, Backend::Cpu);
        }
        if let Some(on) = n.tethers {
            push(StageKind::Tethers, on);
        }
        if n.stretch {
            push(StageKind::StretchLimit, Backend::Cpu);
        }
        if let Some((_, on)) = n.collide {
            push(StageKind::SelfCollision, on);
        }
        if let Some(on) = n.contacts_on {
            push(StageKind::Contacts, on);
        }
        push(StageKind::Quarantine, Backend::Cpu);
        if n.tearing {
            push(StageKind::Tearing, Backend::Cpu);
        }
        self.integrator = Some(n.integrator);
        self.substeps = n.substeps;
        self.device_per_substep = n.device_contacts_per_substep;
        self.finds_on_device = n.collide.is_some_and(|c| c.0 == Backend::Gpu);
    }

    /// The stages in the order a frame runs them.
    pub fn stages(&self) -> &[Stage] {
        &self.stages
    }

    /// Whether the list holds a stage of this kind.
    pub fn has(&self, kind: StageKind) -> bool {
        self.stages.iter().any(|s| s.kind == kind)
    }

    /// Substeps per submit on the device: all of a frame's in one, unless a stage needs the
    /// host between substeps (a CPU stage needing the state, or the device's contacts handing
    /// dynamic bodies their impulses). 1 on the CPU.
    pub fn substeps_per_submit(&self, substeps: u32) -> u32 {
        let device = self.stages.iter().any(|s| s.on == Backend::Gpu);
        let host = self.stages.iter().any(Stage::needs_host_state);
        if device && !host && !self.device_per_substep {
            substeps.max(1)
        } else {
            1
        }
    }

    /// Sets the substeps the listing gives (the next frame's).
    pub(crate) fn set_substeps(&mut self, substeps: u32) {
        self.substeps = substeps;
    }
}

/// `gravity → integrate (symplectic-euler, 30 substeps) → contacts → quarantine`; a stage on
/// the GPU says so.
impl fmt::Display for Schedule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, s) in self.stages.iter().enumerate() {
            if i > 0 {
                f.write_str(" → ")?;
            }
            f.write_str(s.kind.name())?;
            let gpu = s.on == Backend::Gpu;
            match (s.kind, self.integrator) {
                (StageKind::Integrate, Some(i)) => {
                    let n = self.substeps;
                    let on = if gpu { " on the GPU" } else { "" };
                    write!(
                        f,
                        " ({i}{on}, {n} substep{})",
                        if n == 1 { "" } else { "s" }
                    )?;
                }
                (
                    StageKind::Air
                    | StageKind::Contacts
                    | StageKind::Tethers
                    | StageKind::SelfCollision,
                    _,
                ) if gpu => f.write_str(" (on the GPU)")?,
                (StageKind::SelfCollision, _) if self.finds_on_device => {
                    f.write_str(" (its candidates found on the GPU)")?
                }
                _ => {}
            }
        }
        Ok(())
    }
}

/// Wall time per stage kind, indexed by [`StageKind`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTimes([Duration; StageKind::COUNT]);

impl StageTimes {
    /// The sum over the kinds.
    pub fn total(&self) -> Duration {
        self.0.iter().sum()
    }

    /// `(kind, time)` for every kind, in frame order.
    pub fn iter(&self) -> impl Iterator<Item = (StageKind, Duration)> + '_ {
        StageKind::ALL.into_iter().map(|k| (k, self[k]))
    }
}

impl Index<StageKind> for StageTimes {
    type Output = Duration;
    fn index(&self, kind: StageKind) -> &Duration {
        &self.0[kind.index()]
    }
}

impl IndexMut<StageKind> for StageTimes {
    fn index_mut(&mut self, kind: StageKind) -> &mut Duration {
        &mut self.0[kind.index()]
    }
}

impl AddAssign for StageTimes {
    fn add_assign(&mut self, o: Self) {
        for (a, b) in self.0.iter_mut().zip(o.0) {
            *a += b;
        }
    }
}
