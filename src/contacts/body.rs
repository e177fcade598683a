//! The body a game adds at run time: glam types and a builder, converted to the scene's
//! [`BodyDef`] and validated exactly as a scene's body would be.

use glam::{DQuat, DVec3};

use crate::scene::props::{BodyDef, BodyKind, Shape};

/// How a dynamic body's mass is given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BodyMass {
    /// Density of the collider's volume (kg/m³).
    Density(f64),
    /// Total mass (kg).
    Mass(f64),
}

/// A rigid body with one collider, for [`crate::Simulation::add_body`].
///
/// ```
/// use harmonic::{Body, BodyKind, Shape};
/// use harmonic::glam::DVec3;
/// let ball = Body::new(BodyKind::Dynamic, Shape::Ball { radius: 0.2 })
///     .at(DVec3::new(0.0, 1.0, 0.0))
///     .with_mass(2.0);
/// assert_eq!(ball.position.y, 1.0);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Body {
    /// How it moves.
    pub kind: BodyKind,
    /// Its collider's shape, in the body's frame.
    pub shape: Shape,
    /// Position (m).
    pub position: DVec3,
    /// Orientation.
    pub rotation: DQuat,
    /// Velocity (m/s).
    pub velocity: DVec3,
    /// Angular velocity (rad/s).
    pub angular_velocity: DVec3,
    /// Mass or density; `None`: density 1000 kg/m³.
    pub mass: Option<BodyMass>,
    /// Coulomb friction of the collider, combined with the cloth's by averaging (rapier's rule).
    pub friction: f64,
    /// Restitution against other bodies.
    pub restitution: f64,
    /// Dynamic only: rapier's velocity damping (1/s).
    pub linear_damping: f64,
    /// Dynamic only: rapier's angular velocity damping (1/s).
    pub angular_damping: f64,
}

impl Body {
    /// A body of `kind` with `shape` at the origin, at rest, with the scene format's defaults.
    pub fn new(kind: BodyKind, shape: Shape) -> Self {
        Self {
            kind,
            shape,
            position: DVec3::ZERO,
            rotation: DQuat::IDENTITY,
            velocity: DVec3::ZERO,
            angular_velocity: DVec3::ZERO,
            mass: None,
            friction: crate::scene::props::default_body_friction(),
            restitution: 0.0,
            linear_damping: 0.0,
            angular_damping: 0.0,
        }
    }

    /// At `position`.
    pub fn at(mut self, position: DVec3) -> Self {
        self.position = position;
        self
    }

    /// Turned by `rotation`.
    pub fn rotated(mut self, rotation: DQuat) -> Self {
        self.rotation = rotation;
        self
    }

    /// Moving at `velocity` and `angular_velocity`.
    pub fn moving(mut self, velocity: DVec3, angular_velocity: DVec3) -> Self {
        self.velocity = velocity;
        self.angular_velocity = angular_velocity;
        self
    }

    /// Of total mass `mass` (kg).
    pub fn with_mass(mut self, mass: f64) -> Self {
        self.mass = Some(BodyMass::Mass(mass));
        self
    }

    /// Of density `density` (kg/m³).
    pub fn with_density(mut self, density: f64) -> Self {
        self.mass = Some(BodyMass::Density(density));
        self
    }

    /// With Coulomb friction `friction`.
    pub fn with_friction(mut self, friction: f64) -> Self {
        self.friction = friction;
        self
    }

    /// The scene format's form of the body (rotation as axis times angle).
    pub(crate) fn to_def(&self) -> BodyDef {
        let (density, mass) = match self.mass {
            Some(BodyMass::Density(d)) => (Some(d), None),
            Some(BodyMass::Mass(m)) => (None, Some(m)),
            None => (None, None),
        };
        let rotation = if self.rotation.is_finite() {
            self.rotation.normalize().to_scaled_axis()
        } else {
            DVec3::NAN
        };
        BodyDef {
            kind: self.kind,
            shape: self.shape.clone(),
            position: self.position.to_array(),
            rotation: rotation.to_array(),
            velocity: self.velocity.to_array(),
            angular_velocity: self.angular_velocity.to_array(),
            density,
            mass,
            friction: self.friction,
            restitution: self.restitution,
            linear_damping: self.linear_damping,
            angular_damping: self.angular_damping,
            path: Vec::new(),
        }
    }
}
