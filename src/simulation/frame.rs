//! The game-loop frame: the fixed-step accumulator and the buffers a renderer reads.

use super::*;

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
pub(super) struct Frame {
    pub(super) accumulator: f64,
    pub(super) max_steps: u32,
    /// The state before the last step of the last advance.
    pub(super) prev: Vec<DVec3>,
    /// Triangles set by the caller; otherwise the cloths' grids, made when first asked for.
    pub(super) custom: Option<Vec<[u32; 3]>>,
    pub(super) triangles: std::sync::OnceLock<Vec<[u32; 3]>>,
    pub(super) positions: Vec<Vec3>,
    pub(super) normals: Vec<Vec3>,
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
pub(super) fn frame_triangles<'a>(
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
        crate::components::MeshSurface::all(world, &mut out);
        out
    })
}

/// A cloth's grid, read from its entity's [`ClothSprings`] (`None` once that is gone).
pub(super) fn grid_of(world: &World, e: Entity) -> Option<ClothGrid> {
    world.get::<&ClothSprings>(e).ok().map(|c| c.grid)
}

/// A cloth's particles in scene order: a grid's ([`ClothSprings`]) or a mesh's
/// ([`crate::MeshSurface`]); `None` once its entity is gone.
pub(super) fn range_of(world: &World, e: Entity) -> Option<std::ops::Range<u32>> {
    if let Some(g) = grid_of(world, e) {
        let r = g.range();
        // A built cloth's indices fit u32 (validated).
        return Some(r.start as u32..r.end as u32);
    }
    let m = world.get::<&crate::MeshSurface>(e).ok()?;
    Some(m.first..m.first + m.count)
}

/// What a renderer uploads each frame: positions and normals (f32, one per particle in scene
/// order) and the triangles indexing them. Borrowed from buffers the simulation keeps, so a
/// frame allocates nothing.
pub struct RenderView<'a> {
    /// Particle positions (m), interpolated to the frame.
    pub positions: &'a [Vec3],
    /// Unit vertex normals, area-weighted over the triangles.
    pub normals: &'a [Vec3],
    /// Triangles as indices into `positions`.
    pub triangles: &'a [[u32; 3]],
}

impl Simulation {
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

    /// Draw these triangles instead of the cloths' own (indices in scene order).
    pub fn set_triangles(&mut self, triangles: Vec<[u32; 3]>) {
        self.frame.custom = Some(triangles);
    }
}
