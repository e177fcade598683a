//! # harmonic
//!
//! Mass-spring simulation (cloth, ropes, soft props) whose springs are integrated in closed
//! form as damped harmonic oscillators over each step: explicit and parallel like Euler, but
//! exact for an isolated spring in every damping regime. See [`math`] for the math and
//! how it departs from the paper it comes from.
//!
//! Particles, springs and pins are hecs components; a [`Simulation`] owns the World, packs
//! it into flat buffers once per topology change and steps those.
//!
//! ```
//! use harmonic::prelude::*;
//!
//! let scene = Scene::parse(r#"
//!     Scene(
//!         dt: 0.001,
//!         gravity: (0.0, -9.81, 0.0),
//!         particles: [
//!             (position: (0.0, 0.0, 0.0), mass: 1.0, pinned: true),
//!             (position: (0.0, -1.0, 0.0), mass: 1.0),
//!         ],
//!         springs: [(a: 0, b: 1, stiffness: 1000.0, damping: 5.0)],
//!     )"#, "inline.ron").unwrap();
//! let mut sim = Simulation::from_scene(&scene).unwrap();
//! for _ in 0..2000 {
//!     sim.step().unwrap();
//! }
//! // The bob settles where the spring carries its weight: stretch m g / κ.
//! let sag = -1.0 - sim.positions()[1].y;
//! assert!((sag - 9.81 / 1000.0).abs() < 1e-3, "{sag}");
//! ```

// Library code returns errors; each remaining unwrap/expect names the invariant it relies on.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
#![warn(missing_docs)]

pub mod air;
mod audit;
mod buffers;
mod collide;
mod components;
mod config;
mod contacts;
mod error;
#[cfg(feature = "gpu")]
mod gpu;
mod integrate;
mod metrics;
#[cfg(feature = "gpu")]
pub mod render;
pub mod scene;
mod schedule;
mod simulation;
mod step_control;
mod stretch;
mod tear;
mod tether;

#[doc(hidden)]
pub mod internals;

/// The closed-form spring step: the math, its derivation and how it corrects the paper.
pub mod math {
    #![doc = include_str!("integrate/MATH.md")]
}

pub use air::{Aero, Gust, Wind};
pub use audit::EnergyAudit;
pub use collide::{Layer, SelfCollision};
pub use components::{
    ClothGrid, ClothSprings, GridLink, MeshSurface, Particle, Pin, Quarantined, SceneIndex, Spring,
};
pub use config::{Backend, Integrator, SimConfig, RESEARCH_INTEGRATORS};
pub use contacts::{Attachment, Body, BodyMass, ContactStats, Props, RigidProp};
pub use error::{Error, GpuError, Issue, SceneError, SimError};
pub use scene::props::{BodyKind, ContactMaterial, Shape};
pub use scene::Scene;
pub use schedule::{Cadence, Failure, Place, Schedule, Stage, StageKind, StageTimes, StepStats};
pub use simulation::{Advance, ClothId, Diagnostics, DriveId, RenderView, Simulation};
pub use step_control::StepChoice;
pub use stretch::StretchLimit;
pub use tear::{Tear, Tearing};
pub use tether::{TetherSpec, Tethers};

// The versions the engine is built against, so a game matches them without guessing.
pub use glam;
pub use hecs;
pub use rapier3d;

/// The names most programs need: `use harmonic::prelude::*;`.
pub mod prelude {
    pub use crate::{
        Advance, Backend, Body, BodyKind, Diagnostics, Integrator, Particle, Pin, Scene, Shape,
        SimConfig, Simulation, Spring, StageKind, StepStats,
    };
    pub use glam::DVec3;
}
