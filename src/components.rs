//! ECS components. Positions and velocities are `f64` on the CPU: a gravity step of
//! `g·h² ≈ 2e-8 m` is below half an `f32` ulp at a height of 2 m, so `f32` state would not move.

use glam::DVec3;
use hecs::Entity;

/// A point mass. A pinned particle also carries [`Pin`] and then ignores its mass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Particle {
    /// Position (m).
    pub position: DVec3,
    /// Velocity (m/s).
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
    /// One end: a particle entity.
    pub a: Entity,
    /// The other end: a particle entity.
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

/// A cloth's particles: scene indices `first .. first + cols·rows`, a `cols × rows` grid,
/// row-major.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClothGrid {
    /// Scene index of particle `(0, 0)`.
    pub first: u32,
    /// Particles per row.
    pub cols: u32,
    /// Rows of particles.
    pub rows: u32,
}

impl ClothGrid {
    /// Scene indices covered, `first .. first + cols·rows` (u64: an unchecked grid may pass u32).
    pub fn range(&self) -> std::ops::Range<u64> {
        let first = self.first as u64;
        first..first + self.cols as u64 * self.rows as u64
    }

    /// Appends the grid's triangles, as scene indices (counter-clockwise seen from the side
    /// the cloth's normal points to: +y for horizontal cloths, +z for vertical ones).
    pub fn triangles(&self, out: &mut Vec<[u32; 3]>) {
        let cols = self.cols;
        for row in 0..self.rows.saturating_sub(1) {
            for col in 0..cols.saturating_sub(1) {
                let a = self.first + row * cols + col;
                let (b, c) = (a + 1, a + cols);
                out.push([a, c, b]);
                out.push([b, c, c + 1]);
            }
        }
    }
}

/// A cloth's springs as one component: each [`GridLink`] joins every particle `(c, r)` of the
/// grid to `(c + dc, r + dr)` where that exists. The topology is implicit, so the springs cost
/// no memory each; scene cloths are built this way.
#[derive(Clone, Debug, PartialEq)]
pub struct ClothSprings {
    /// The particles it joins.
    pub grid: ClothGrid,
    /// The springs, each link repeated over the whole grid.
    pub links: Vec<GridLink>,
}

/// One spring of every grid cell: from `(c, r)` to `(c + offset.0, r + offset.1)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridLink {
    /// `(dc, dr)`, not both 0.
    pub offset: (i32, i32),
    /// m, > 0.
    pub rest_length: f64,
    /// κ, N/m, ≥ 0.
    pub stiffness: f64,
    /// c, N·s/m, ≥ 0.
    pub damping: f64,
}

impl ClothSprings {
    /// Springs in all.
    pub fn spring_count(&self) -> u64 {
        self.links
            .iter()
            .map(|l| l.count(self.grid.cols, self.grid.rows))
            .sum()
    }
}

impl GridLink {
    /// Its springs in a `cols × rows` grid: `(cols − |dc|)·(rows − |dr|)` when positive.
    pub fn count(&self, cols: u32, rows: u32) -> u64 {
        let (dc, dr) = (self.offset.0.unsigned_abs(), self.offset.1.unsigned_abs());
        cols.saturating_sub(dc) as u64 * rows.saturating_sub(dr) as u64
    }
}

/// A mesh cloth's surface: its triangles, indexing its particles from scene index `first`
/// (what the render draws; the springs are [`Spring`] entities).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MeshSurface {
    /// Scene index of the mesh's particle 0.
    pub first: u32,
    /// Its particles: scene indices `first .. first + count`.
    pub count: u32,
    /// Triangles over the mesh's particles (0-based).
    pub triangles: Vec<[u32; 3]>,
}

impl MeshSurface {
    /// Every mesh's triangles in `world`, in scene indices, appended to `out` in scene order.
    pub fn all(world: &hecs::World, out: &mut Vec<[u32; 3]>) {
        let mut surfaces: Vec<(u32, hecs::Entity)> = world
            .query::<(hecs::Entity, &MeshSurface)>()
            .iter()
            .map(|(e, s)| (s.first, e))
            .collect();
        surfaces.sort_unstable();
        for (_, e) in surfaces {
            Self::all_of(world, e, out);
        }
    }

    /// The triangles of the mesh whose surface is entity `e`, in scene indices, appended to
    /// `out`.
    pub fn all_of(world: &hecs::World, e: hecs::Entity, out: &mut Vec<[u32; 3]>) {
        if let Ok(s) = world.get::<&MeshSurface>(e) {
            out.extend(s.triangles.iter().map(|t| t.map(|i| s.first + i)));
        }
    }
}

/// The triangles of the cloth entity `e`, a grid's ([`ClothSprings`]) or a mesh's
/// ([`MeshSurface`]), in scene indices, appended to `out`.
pub(crate) fn cloth_triangles(world: &hecs::World, e: hecs::Entity, out: &mut Vec<[u32; 3]>) {
    if let Ok(c) = world.get::<&ClothSprings>(e) {
        c.grid.triangles(out);
    }
    MeshSurface::all_of(world, e, out);
}
