//! Rigid props: the rapier world a scene's bodies live in, the contact stage that keeps
//! particles outside colliders, and attachments of particles to bodies.
//!
//! Per substep, after the integrate stage:
//! 1. rapier steps the bodies by `h` (only when some body can move);
//! 2. attachments put their particles at their body points, at the body's point velocity;
//! 3. contacts: each particle within `thickness` of a collider (or whose path this substep
//!    crossed one) goes back to the surface plus `thickness`; its normal velocity into the
//!    collider is removed (restitution `e` keeps `e` of it) and its tangential velocity obeys
//!    Coulomb friction, static then kinetic.
//!
//! Steps 2 and 3 change particle momenta by `J`; a dynamic body receives `−J` at the contact
//! point, so cloth and bodies exchange momentum exactly (two-way coupling). Candidate colliders
//! come from a broad phase on bounding boxes (the cloth's box against each collider's, then each
//! particle against its candidates'); the contact itself is parry's shape projection, and a ray
//! cast along the particle's path catches particles that would tunnel through thin shapes.

use glam::{DMat3, DVec3, Vec3};
use hecs::{Entity, World};
use rapier3d::parry::bounding_volume::BoundingVolume;
use rapier3d::parry::query::{PointQuery, Ray, RayCast};
use rapier3d::parry::shape::{Ball, Cuboid};
use rapier3d::prelude::{
    ColliderBuilder, ColliderHandle, ColliderSet, PhysicsWorld, Pose, RigidBody, RigidBodyBuilder,
    RigidBodyHandle, RigidBodySet, RigidBodyType, SharedShape,
};
use rayon::prelude::*;

use crate::audit::{self, ProjectionLines};
use crate::buffers::Packed;
use crate::scene::props::{BodyDef, BodyKind, ContactMaterial, Keyframe, Shape};

mod bodies;
mod body;
#[cfg(feature = "gpu")]
mod device;
mod queries;
mod stage;
#[cfg(test)]
mod tests;

pub use bodies::*;
pub use body::*;
use queries::*;
pub use stage::*;

/// A body of the scene, as an ECS component on its own entity (the rapier handles stay opaque:
/// the sets live in [`Props`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RigidProp {
    /// The body in [`Props::bodies`].
    pub body: RigidBodyHandle,
    /// Its collider in [`Props::colliders`].
    pub collider: ColliderHandle,
}

/// On a particle: it is held at `local` (body frame) of `body`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Attachment {
    /// The body the particle is held to.
    pub body: RigidBodyHandle,
    /// The point it is held at, in the body's frame (m).
    pub local: Vec3,
}

/// What the contact stage did in the last frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactStats {
    /// Particle–collider contacts resolved, summed over substeps.
    pub contacts: usize,
    /// Deepest any particle got inside a collider before being pushed out (m).
    pub max_depth: f64,
    /// Particles caught by the swept test (their path crossed a collider's surface).
    pub swept: usize,
    /// Total impulse given to dynamic bodies by contacts and attachments (N·s).
    pub impulse_on_bodies: DVec3,
}

/// The rigid side of a scene: rapier's world, the bodies driven along paths, and the contact
/// stage.
pub struct Props {
    /// rapier's world: the bodies, colliders and joints, stepped by the contact stage.
    pub(crate) physics: PhysicsWorld,
    /// Some body can move: rapier steps each substep.
    pub(crate) moving: bool,
    /// Some body is dynamic: impulses go back to bodies.
    pub(crate) dynamic: bool,
    /// Position-driven bodies following keyframed paths from the scene.
    paths: Vec<(RigidBodyHandle, Vec<Keyframe>)>,
    /// Position-driven bodies moved through the API this frame: (body, start, target).
    driven: Vec<(RigidBodyHandle, Pose, Pose)>,
    /// Simulated time of the paths (s).
    time: f64,
    /// Substep within the frame, and substeps per frame.
    substep: u32,
    substeps: u32,
    stage: ContactStage,
}

fn v3(v: [f64; 3]) -> Vec3 {
    DVec3::from(v).as_vec3()
}

/// The largest axis-angle rotation a scene may give (rad): beyond it an f64 angle's remainder
/// modulo 4π is rounding noise.
pub(crate) const MAX_ANGLE: f64 = 1e15;

/// An axis-angle rotation in rapier's f32, its angle reduced modulo 4π in f64 first (the same
/// quaternion): f32 would overflow squaring an angle past about 1.8e19 rad.
fn axis_angle(v: [f64; 3]) -> Vec3 {
    let r = DVec3::from(v);
    let angle = r.length();
    let period = 4.0 * std::f64::consts::PI;
    if angle > period {
        (r * (angle.rem_euclid(period) / angle)).as_vec3()
    } else {
        r.as_vec3()
    }
}
