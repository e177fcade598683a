//! Rigid props in a scene: rapier bodies with one collider each, the cloth's contact material,
//! and attachments of particles to bodies.

use serde::{Deserialize, Serialize};

use super::V3;

/// How a body moves.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
pub enum BodyKind {
    /// Never moves.
    Fixed,
    /// Moved by gravity, contacts with other bodies and the cloth's impulses.
    Dynamic,
    /// Moves at its `velocity` and `angular_velocity` whatever pushes it (a character).
    Kinematic,
    /// Goes where it is put, whatever pushes it: along its `path`, or to the pose given through
    /// the API (`set_next_kinematic_position`), reached at the end of the frame.
    KinematicPosition,
}

/// A pose of a position-driven body at a time; poses between keyframes are interpolated
/// (position linearly, rotation spherically) and the last one is held.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Keyframe {
    /// Simulated time (s).
    pub time: f64,
    /// The body's position (m).
    pub position: V3,
    /// Axis-angle (axis times angle in radians).
    #[serde(default)]
    pub rotation: V3,
}

/// A collider shape, in the body's frame. Lengths in metres.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub enum Shape {
    /// A sphere.
    Ball {
        /// Radius (m).
        radius: f64,
    },
    /// A box.
    Cuboid {
        /// Half its size along x, y and z (m).
        half_extents: V3,
    },
    /// Along the body's y axis.
    Capsule {
        /// Half the length of the segment between the caps' centres (m).
        half_height: f64,
        /// Radius of the caps and the shaft (m).
        radius: f64,
    },
    /// Along the body's y axis.
    Cylinder {
        /// Half its height (m).
        half_height: f64,
        /// Radius (m).
        radius: f64,
    },
    /// The convex hull of a set of points.
    ConvexHull {
        /// The points (m), at least 4, spanning a volume.
        points: Vec<V3>,
    },
    /// A triangle mesh.
    TriMesh {
        /// Vertex positions (m).
        vertices: Vec<V3>,
        /// Triangles, as indices into `vertices`.
        indices: Vec<[u32; 3]>,
    },
    /// `heights[row][col]` on a grid spanning `scale.x` × `scale.z`, heights times `scale.y`,
    /// centred on the body.
    HeightField {
        /// Heights before scaling, one row of columns each (at least 2 × 2, rows of equal length).
        heights: Vec<Vec<f64>>,
        /// Extent of the grid along x and z (m), and the factor on the heights.
        scale: V3,
    },
}

/// A rigid body with one collider.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BodyDef {
    /// How it moves.
    pub kind: BodyKind,
    /// Its collider's shape.
    pub shape: Shape,
    /// Start position (m); a body with a `path` starts at its first keyframe.
    #[serde(default)]
    pub position: V3,
    /// Axis-angle (axis times angle in radians).
    #[serde(default)]
    pub rotation: V3,
    /// Start velocity (m/s).
    #[serde(default)]
    pub velocity: V3,
    /// Start angular velocity (rad/s).
    #[serde(default)]
    pub angular_velocity: V3,
    /// kg/m³ (default 1000); give this or `mass`.
    #[serde(default)]
    pub density: Option<f64>,
    /// kg; give this or `density`.
    #[serde(default)]
    pub mass: Option<f64>,
    /// Coulomb friction of the collider, combined with the cloth's by averaging (rapier's rule).
    #[serde(default = "default_body_friction")]
    pub friction: f64,
    /// Restitution against other bodies.
    #[serde(default)]
    pub restitution: f64,
    /// Dynamic only: rapier's velocity damping (1/s), the drag of the air around the body.
    #[serde(default)]
    pub linear_damping: f64,
    /// Dynamic only: rapier's angular velocity damping (1/s).
    #[serde(default)]
    pub angular_damping: f64,
    /// `KinematicPosition` only: keyframes in increasing time; the body starts at the first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub path: Vec<Keyframe>,
}

pub(crate) fn default_body_friction() -> f64 {
    0.5
}

/// The cloth's contact material.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ContactMaterial {
    /// Particles are kept this far outside every collider (m).
    #[serde(default = "default_thickness")]
    pub thickness: f64,
    /// Static friction coefficient of the cloth.
    #[serde(default = "default_friction")]
    pub friction: f64,
    /// Kinetic friction coefficient of the cloth (≤ `friction`).
    #[serde(default = "default_kinetic")]
    pub kinetic_friction: f64,
    /// Fraction of the normal approach speed a particle keeps, bouncing off (0 to 1).
    #[serde(default)]
    pub restitution: f64,
}

impl Default for ContactMaterial {
    fn default() -> Self {
        Self {
            thickness: default_thickness(),
            friction: default_friction(),
            kinetic_friction: default_kinetic(),
            restitution: 0.0,
        }
    }
}

fn default_thickness() -> f64 {
    0.01
}
fn default_friction() -> f64 {
    0.5
}
fn default_kinetic() -> f64 {
    0.4
}

/// A particle of the scene.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, Hash)]
pub enum ParticleRef {
    /// Index into `particles`.
    Particle(usize),
    /// `(cloth, column, row)` of `cloths`.
    Cloth(usize, u32, u32),
    /// `(mesh, vertex)` of `meshes`: the particle the vertex welds into.
    Mesh(usize, u32),
}

/// A particle held at a point of a body: it follows the body; a dynamic body feels its pull.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AttachmentDef {
    /// The particle held.
    pub particle: ParticleRef,
    /// Index into `bodies`.
    pub body: usize,
    /// The point in the body's frame (default: where the particle starts).
    #[serde(default)]
    pub local: Option<V3>,
}
