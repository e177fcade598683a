//! Building a World from a validated scene: explicit entries, then the generators.

use glam::DVec3;
use hecs::{Entity, World};

use super::mesh::MeshCloth;
use super::{Anchor, Cloth, Plane, Rope, Scene, SpringSpec};
use crate::components::{
    ClothGrid, ClothSprings, GridLink, MeshSurface, Particle, Pin, SceneIndex, Spring,
};
use crate::integrate::Integrator;
use crate::SimConfig;

/// A scene's World and the settings it asked for.
pub struct BuiltScene {
    /// The scene's entities: particles, springs, each cloth's [`ClothSprings`] and a
    /// [`crate::RigidProp`] per body.
    pub world: World,
    /// The step, gravity, integrator and back end the scene asked for.
    pub config: SimConfig,
    /// The rapier world of the scene's bodies; None without bodies (no contact stage then).
    pub props: Option<crate::contacts::Props>,
    /// Each cloth's entity, holding its [`ClothSprings`] (and so its grid), then each mesh's,
    /// holding its [`MeshSurface`].
    pub cloths: Vec<Entity>,
}

impl BuiltScene {
    /// The cloths' triangles (see [`ClothGrid::triangles`]), then the meshes'
    /// ([`MeshSurface`]), in scene indices.
    pub fn triangles(&self) -> Vec<[u32; 3]> {
        let mut out = Vec::new();
        for &e in &self.cloths {
            if let Ok(c) = self.world.get::<&ClothSprings>(e) {
                c.grid.triangles(&mut out);
            }
        }
        MeshSurface::all(&self.world, &mut out);
        out
    }
}

/// Spawns `cloth` into `world` (its particles and one [`ClothSprings`]) with its particles
/// numbered from scene index `first`; returns the [`ClothSprings`] entity. The cloth must have
/// passed validation.
pub fn spawn_cloth(world: &mut World, first: u32, cloth: &Cloth) -> Entity {
    let e = spawn(world, first, |b| b.cloth(cloth));
    tie(world, e, cloth.tethers, cloth.self_collision);
    e
}

/// Spawns `mesh` into `world` (its particles, springs and one [`MeshSurface`]) with its
/// particles numbered from scene index `first`; returns the [`MeshSurface`] entity. The mesh
/// must have passed validation.
pub fn spawn_mesh(world: &mut World, first: u32, mesh: &MeshCloth) -> Entity {
    let e = spawn(world, first, |b| b.mesh(mesh, "mesh"));
    tie(world, e, mesh.tethers, mesh.self_collision);
    e
}

/// The tethers `spec` and the collision layer `collide` ask for on the cloth (or mesh) entity
/// `e`, from its particles' places and pins as they are (its rest shape, once its pins and
/// attachments are set).
fn tie(
    world: &mut World,
    e: Entity,
    spec: Option<crate::TetherSpec>,
    collide: Option<crate::SelfCollision>,
) {
    let range = match (world.get::<&ClothSprings>(e), world.get::<&MeshSurface>(e)) {
        (Ok(c), _) => (c.grid.first, (c.grid.cols * c.grid.rows)),
        (_, Ok(m)) => (m.first, m.count),
        _ => return,
    };
    if let Some(s) = spec {
        let mut triangles = Vec::new();
        crate::components::cloth_triangles(world, e, &mut triangles);
        for t in &mut triangles {
            *t = t.map(|i| i.wrapping_sub(range.0));
        }
        if let Some(t) = crate::tether::build(world, range.0, range.1, &s, &triangles) {
            let _ = world.insert_one(e, t);
        }
    }
    if let Some(c) = collide {
        let layer = crate::collide::layer(world, range.0, range.1, c);
        let _ = world.insert_one(e, layer);
    }
}

fn spawn(world: &mut World, first: u32, part: impl FnOnce(&mut Builder)) -> Entity {
    let mut b = Builder {
        world: std::mem::take(world),
        next: first,
        cloths: Vec::new(),
        hung: Vec::new(),
    };
    part(&mut b);
    *world = b.world;
    b.cloths[0]
}

impl SpringSpec {
    /// `(κ, c)` for a spring between masses `m_a`, `m_b` (see the module docs for the conversion).
    pub fn resolve(&self, m_a: f64, m_b: f64) -> (f64, f64) {
        let mu = m_a * m_b / (m_a + m_b);
        let stiffness = match (self.stiffness, self.frequency) {
            (Some(k), _) => k,
            (None, Some(f)) => mu * (2.0 * std::f64::consts::PI * f).powi(2),
            (None, None) => 0.0,
        };
        let damping = match (self.damping, self.damping_ratio) {
            (Some(c), _) => c,
            (None, Some(z)) => 2.0 * z * (stiffness * mu).sqrt(),
            (None, None) => 0.0,
        };
        (stiffness, damping)
    }
}

struct Builder {
    world: World,
    next: u32,
    cloths: Vec<Entity>,
    /// Pinned mesh particles that hang on a body (`MeshCloth::pinned_to`).
    hung: Vec<(Entity, usize)>,
}

impl Builder {
    fn particle(&mut self, position: DVec3, velocity: DVec3, mass: f64, pinned: bool) -> Entity {
        let p = Particle {
            position,
            velocity,
            mass,
        };
        let idx = SceneIndex(self.next);
        self.next += 1;
        if pinned {
            self.world.spawn((p, idx, Pin))
        } else {
            self.world.spawn((p, idx))
        }
    }

    fn spring(
        &mut self,
        a: Entity,
        b: Entity,
        spec: &SpringSpec,
        mass: (f64, f64),
        rest_length: f64,
    ) {
        let (stiffness, damping) = spec.resolve(mass.0, mass.1);
        self.world.spawn((Spring {
            a,
            b,
            rest_length,
            stiffness,
            damping,
        },));
    }

    fn cloth(&mut self, c: &Cloth) {
        let (cols, rows) = (c.resolution.0 as usize, c.resolution.1 as usize);
        let m = c.mass / (cols * rows) as f64;
        let (du, dv) = (c.size.0 / (cols - 1) as f64, c.size.1 / (rows - 1) as f64);
        let (u, v) = match c.plane {
            Plane::Vertical => (DVec3::X, DVec3::NEG_Y),
            Plane::Horizontal => (DVec3::X, DVec3::Z),
        };
        let pinned = |col: usize, row: usize| {
            let (l, r, t, b) = (col == 0, col == cols - 1, row == 0, row == rows - 1);
            c.pins.iter().any(|p| match *p {
                Anchor::TopLeft => t && l,
                Anchor::TopRight => t && r,
                Anchor::BottomLeft => b && l,
                Anchor::BottomRight => b && r,
                Anchor::TopEdge => t,
                Anchor::BottomEdge => b,
                Anchor::LeftEdge => l,
                Anchor::RightEdge => r,
                Anchor::Particle(pc, pr) => pc as usize == col && pr as usize == row,
            })
        };
        let origin = DVec3::from(c.origin);
        let vel = DVec3::from(c.velocity);
        let first = self.next;
        // One allocation each for the particles and their entity records: growing by doubling
        // leaves up to half the capacity unused and the freed blocks behind in the allocator
        // (a fifth more resident memory at 1024²). The first call sizes the entity records for
        // every particle and the springs' entity; the free particles' storage has a few slots
        // to spare, one per pin.
        let pins = (0..rows)
            .flat_map(|r| (0..cols).map(move |c| (c, r)))
            .filter(|&(c, r)| pinned(c, r))
            .count();
        self.world
            .reserve::<(Particle, SceneIndex)>((cols * rows + 1) as u32);
        self.world
            .reserve::<(Particle, SceneIndex, Pin)>(pins as u32);
        let mut ids = Vec::with_capacity(if c.tearing.is_some() { cols * rows } else { 0 });
        for row in 0..rows {
            for col in 0..cols {
                let x = origin + u * (col as f64 * du) + v * (row as f64 * dv);
                let e = self.particle(x, vel, m, pinned(col, row));
                if c.tearing.is_some() {
                    ids.push(e);
                }
            }
        }
        let mut links = Vec::new();
        let mut link = |spec: &SpringSpec, (dc, dr): (i32, i32)| {
            let (stiffness, damping) = spec.resolve(m, m);
            links.push(GridLink {
                offset: (dc, dr),
                rest_length: (u * (dc as f64 * du) + v * (dr as f64 * dv)).length(),
                stiffness,
                damping,
            });
        };
        link(&c.structural, (1, 0));
        link(&c.structural, (0, 1));
        if let Some(s) = &c.shear {
            link(s, (1, 1));
            link(s, (-1, 1));
        }
        if let Some(s) = &c.bend {
            link(s, (2, 0));
            link(s, (0, 2));
        }
        let grid = ClothGrid {
            first,
            cols: cols as u32,
            rows: rows as u32,
        };
        let e = if let Some(tearing) = c.tearing {
            self.torn_grid(grid, &ids, &links, tearing)
        } else {
            self.world.spawn((ClothSprings { grid, links },))
        };
        if let Some(aero) = c.air {
            let _ = self.world.insert_one(e, aero);
        }
        if let Some(limit) = c.stretch_limit {
            let _ = self.world.insert_one(e, limit);
        }
        self.cloths.push(e);
    }

    /// A tearable grid cloth's springs one by one (a break changes them) and its grid's
    /// triangles as a [`MeshSurface`], for the particles `ids` of `grid`; returns the surface's
    /// entity.
    fn torn_grid(
        &mut self,
        grid: ClothGrid,
        ids: &[Entity],
        links: &[GridLink],
        tearing: crate::Tearing,
    ) -> Entity {
        let (cols, rows) = (grid.cols as i64, grid.rows as i64);
        for l in links {
            let (dc, dr) = (l.offset.0 as i64, l.offset.1 as i64);
            for row in 0..rows {
                for col in 0..cols {
                    let (cb, rb) = (col + dc, row + dr);
                    if cb < 0 || rb < 0 || cb >= cols || rb >= rows {
                        continue;
                    }
                    self.world.spawn((Spring {
                        a: ids[(row * cols + col) as usize],
                        b: ids[(rb * cols + cb) as usize],
                        rest_length: l.rest_length,
                        stiffness: l.stiffness,
                        damping: l.damping,
                    },));
                }
            }
        }
        let mut triangles = Vec::new();
        ClothGrid { first: 0, ..grid }.triangles(&mut triangles);
        self.world.spawn((
            MeshSurface {
                first: grid.first,
                count: grid.cols * grid.rows,
                triangles,
            },
            tearing,
        ))
    }

    /// A mesh cloth: its particles, a spring per edge (and across each interior edge), and a
    /// [`MeshSurface`] for its render triangles. Springs given by frequency resolve through the
    /// mesh's reference mass.
    fn mesh(&mut self, m: &MeshCloth, at: &str) {
        let t = m.topology(at);
        let first = self.next;
        let vel = DVec3::from(m.velocity);
        let ids: Vec<Entity> = (t.positions.iter().zip(&t.masses).zip(&t.pinned))
            .map(|((&x, &mass), &pinned)| self.particle(x, vel, mass, pinned))
            .collect();
        if let Some(body) = m.pinned_to {
            let pinned = ids.iter().zip(&t.pinned).filter(|(_, &p)| p);
            self.hung.extend(pinned.map(|(&e, _)| (e, body)));
        }
        let r = t.reference_mass();
        let rest = |[a, b]: [u32; 2]| (t.positions[b as usize] - t.positions[a as usize]).length();
        for &e in &t.edges {
            let (a, b) = (ids[e[0] as usize], ids[e[1] as usize]);
            self.spring(a, b, &m.stretch, (r, r), rest(e));
        }
        if let Some(bend) = &m.bend {
            for &e in &t.bends {
                let (a, b) = (ids[e[0] as usize], ids[e[1] as usize]);
                self.spring(a, b, bend, (r, r), rest(e));
            }
        }
        let e = self.world.spawn((MeshSurface {
            first,
            count: t.positions.len() as u32,
            triangles: t.triangles,
        },));
        if let Some(aero) = m.air {
            let _ = self.world.insert_one(e, aero);
        }
        if let Some(limit) = m.stretch_limit {
            let _ = self.world.insert_one(e, limit);
        }
        if let Some(tearing) = m.tearing {
            let _ = self.world.insert_one(e, tearing);
        }
        self.cloths.push(e);
    }

    fn rope(&mut self, r: &Rope) {
        let n = r.particles as usize;
        let m = r.mass / n as f64;
        let (start, end) = (DVec3::from(r.start), DVec3::from(r.end));
        let pos = |i: usize| start + (end - start) * (i as f64 / (n - 1) as f64);
        let ids: Vec<Entity> = (0..n)
            .map(|i| {
                let pinned = (i == 0 && r.pin_start) || (i == n - 1 && r.pin_end);
                self.particle(pos(i), DVec3::ZERO, m, pinned)
            })
            .collect();
        for i in 0..n - 1 {
            self.spring(
                ids[i],
                ids[i + 1],
                &r.spring,
                (m, m),
                (pos(i + 1) - pos(i)).length(),
            );
        }
        if let Some(bend) = &r.bend {
            for i in 0..n.saturating_sub(2) {
                self.spring(
                    ids[i],
                    ids[i + 2],
                    bend,
                    (m, m),
                    (pos(i + 2) - pos(i)).length(),
                );
            }
        }
    }
}

impl Scene {
    /// Builds the World. The scene must have passed [`Scene::validate`] (as [`Scene::load`] ensures).
    pub fn build(&self) -> BuiltScene {
        let mut b = Builder {
            world: World::new(),
            next: 0,
            cloths: Vec::new(),
            hung: Vec::new(),
        };
        let ids: Vec<Entity> = self
            .particles
            .iter()
            .map(|p| b.particle(p.position.into(), p.velocity.into(), p.mass, p.pinned))
            .collect();
        for s in &self.springs {
            let (pa, pb) = (&self.particles[s.a], &self.particles[s.b]);
            let rest = s
                .rest_length
                .unwrap_or_else(|| (DVec3::from(pb.position) - DVec3::from(pa.position)).length());
            b.spring(ids[s.a], ids[s.b], &s.spec(), (pa.mass, pb.mass), rest);
        }
        for c in &self.cloths {
            b.cloth(c);
        }
        for r in &self.ropes {
            b.rope(r);
        }
        for (i, m) in self.meshes.iter().enumerate() {
            b.mesh(m, &format!("meshes[{i}]"));
        }
        let integrator = self
            .integrator
            .as_deref()
            .and_then(|n| n.parse::<Integrator>().ok())
            .unwrap_or_default();
        let props = self.build_props(&mut b.world, &b.hung);
        let specs = (self.cloths.iter().map(|c| (c.tethers, c.self_collision)))
            .chain(self.meshes.iter().map(|m| (m.tethers, m.self_collision)));
        for (&e, (spec, collide)) in b.cloths.iter().zip(specs) {
            tie(&mut b.world, e, spec, collide);
        }
        BuiltScene {
            props,
            cloths: b.cloths,
            world: b.world,
            config: SimConfig {
                dt: self.dt,
                substeps: self.substeps.unwrap_or(1),
                auto_substeps: self.substeps.is_none(),
                gravity: self.gravity.into(),
                wind: self.wind,
                integrator,
                auto_integrator: self.integrator.is_none(),
                exact_displacement: self.exact_displacement,
                backend: self
                    .backend
                    .as_deref()
                    .and_then(|n| n.parse().ok())
                    .unwrap_or_default(),
                strain_limit: self
                    .strain_limit
                    .unwrap_or(crate::config::DEFAULT_STRAIN_LIMIT),
                tolerance: self.tolerance.unwrap_or(crate::config::DEFAULT_TOLERANCE),
                step_budget: f64::INFINITY,
                energy_limit: self
                    .energy_limit
                    .unwrap_or(crate::config::DEFAULT_ENERGY_LIMIT),
                device_collide_pass: false,
            },
        }
    }

    /// Scene index of a particle reference.
    fn scene_index(&self, p: super::props::ParticleRef) -> Option<u32> {
        use super::props::ParticleRef;
        match p {
            ParticleRef::Particle(k) => (k < self.particles.len()).then_some(k as u32),
            ParticleRef::Mesh(m, v) => self.mesh_particle(m, v).ok(),
            ParticleRef::Cloth(c, col, row) => {
                let before: u64 = self.particles.len() as u64
                    + self.cloths[..c.min(self.cloths.len())]
                        .iter()
                        .map(|cl| cl.resolution.0 as u64 * cl.resolution.1 as u64)
                        .sum::<u64>();
                let cl = self.cloths.get(c)?;
                (col < cl.resolution.0 && row < cl.resolution.1)
                    .then(|| (before + row as u64 * cl.resolution.0 as u64 + col as u64) as u32)
            }
        }
    }

    /// Bodies into a rapier world, and attachments as components on their particles. Assumes
    /// a validated scene: a body whose collider cannot be built is left out.
    fn build_props(
        &self,
        world: &mut World,
        hung: &[(Entity, usize)],
    ) -> Option<crate::contacts::Props> {
        use crate::contacts::{Attachment, Props};
        if self.bodies.is_empty() {
            return None;
        }
        let (props, handles) = Props::build(
            &self.bodies,
            self.contact.unwrap_or_default(),
            self.gravity.into(),
            world,
        )
        .ok()?;
        let by_index: std::collections::HashMap<u32, (Entity, DVec3)> = world
            .query::<(Entity, &SceneIndex, &Particle)>()
            .iter()
            .map(|(e, i, p)| (i.0, (e, p.position)))
            .collect();
        for a in &self.attachments {
            let (Some(idx), Some(&body)) = (self.scene_index(a.particle), handles.get(a.body))
            else {
                continue;
            };
            let Some(&(entity, x)) = by_index.get(&idx) else {
                continue;
            };
            let local = match a.local {
                Some(p) => DVec3::from(p).as_vec3(),
                None => props.physics.bodies[body]
                    .position()
                    .inverse_transform_point(x.as_vec3()),
            };
            let _ = world.insert_one(entity, Attachment { body, local });
        }
        // Meshes' pins hung on bodies: attached where they start (an explicit attachment of
        // the same particle comes first), no longer pinned.
        for &(entity, b) in hung {
            let Some(&body) = handles.get(b) else {
                continue;
            };
            if world.get::<&Attachment>(entity).is_err() {
                let x = world.get::<&Particle>(entity).map(|p| p.position);
                if let Ok(x) = x {
                    let pose = props.physics.bodies[body].position();
                    let local = pose.inverse_transform_point(x.as_vec3());
                    let _ = world.insert_one(entity, Attachment { body, local });
                }
            }
            let _ = world.remove_one::<Pin>(entity);
        }
        Some(props)
    }
}
