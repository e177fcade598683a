//! ECS components. Positions and velocities are `f64` on the CPU: a gravity step of
//! `g·h² ≈ 2e-8 m` is below half an `f32` ulp at a height of 2 m, so `f32` state would not move.

use glam::DVec3;
use hecs::Entity;

/// A point mass. A pinned particle also carries [`Pin`] and then ignores its mass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Particle {
    pub position: DVec3,
    pub velocity: DVec3,
    /// kg, finite and > 0.
    pub mass: f64,
}

/// Holds a particle where it is: infinite mass, no gravity, no spring impulse.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Pin;

/// A particle whose position or velocity went non-finite in a step (a degenerate spring, an
/// overflowing stiffness, a NaN set from outside): the step put it back at its last finite
/// position, at rest, and pinned it, so nothing spreads from it. See
/// [`crate::Simulation::quarantined`] and [`crate::Simulation::release_quarantine`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Quarantined {
    /// Frames completed before the one that found it.
    pub step: u64,
    /// Whether it was pinned before, so a release leaves it pinned.
    pub was_pinned: bool,
}

/// A spring between two particle entities, force `−κ δ − c δ̇` along its axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spring {
    pub a: Entity,
    pub b: Entity,
    /// m, > 0.
    pub rest_length: f64,
    /// κ, N/m, ≥ 0.
    pub stiffness: f64,
    /// c, N·s/m, ≥ 0.
    pub damping: f64,
}

/// A particle's position in its scene (explicit particles first, then generators row-major).
/// Packed buffers, trajectories and [`crate::Simulation::positions`] follow this order;
/// particles without it follow, in spawn order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct SceneIndex(pub u32);
