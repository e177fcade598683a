//! Run-time edits: grabbing, pinning, adding and removing cloths and bodies.

use super::*;

/// Contacts run on the CPU. Under `auto` a scene with props runs there entirely; under `gpu`
/// the springs run on the GPU and the state makes a round trip every substep for the contacts.
/// A part added at run time, checked as the one entry of an otherwise empty scene, so its
/// errors name it as a scene file's would (`add_cloth: cloths[0].resolution: ...`).
pub(super) fn valid_part(scene: &Scene, what: &str) -> Result<(), Error> {
    let issues = scene.validate();
    if issues.is_empty() {
        Ok(())
    } else {
        Err(crate::SceneError::Invalid {
            path: what.into(),
            issues,
        }
        .into())
    }
}

impl Simulation {
    /// Holds particle `index` (scene order) at `target`, at rest: the mouse drag of a viewer,
    /// a hand picking cloth up. A free particle is pinned until [`Self::release`]; a pinned
    /// one is moved. Neither re-gathers the World: moving a pinned particle writes its state,
    /// pinning a free one refreshes the springs touching it on the next step.
    pub fn grab(&mut self, index: usize, target: DVec3) -> Result<(), SimError> {
        if !target.is_finite() {
            return Err(SimError::BadPosition(target));
        }
        let entity = self.particle_entity(index)?;
        let was_pinned = self.world.get::<&Pin>(entity).is_ok();
        if !was_pinned {
            self.world
                .insert_one(entity, Pin)
                .map_err(|_| SimError::NoParticle { index })?;
            self.grabbed.push(entity);
        }
        if let Ok(mut p) = self.world.get::<&mut crate::Particle>(entity) {
            p.position = target;
            p.velocity = DVec3::ZERO;
        }
        self.edited(index, (!was_pinned).then_some(true), Some(target));
        Ok(())
    }

    /// Lets go of a particle [`Self::grab`] pinned (one pinned by its scene stays pinned); it
    /// starts at rest.
    pub fn release(&mut self, index: usize) -> Result<(), SimError> {
        let entity = self.particle_entity(index)?;
        if let Some(k) = self.grabbed.iter().position(|&e| e == entity) {
            self.grabbed.swap_remove(k);
            self.free(index, entity);
        }
        Ok(())
    }

    /// Records an edit of particle `index` that the World already holds, for the next step:
    /// its pin set or freed, and a pinned particle moved to `at`. After a World change the
    /// next step re-gathers instead and reads it there.
    pub(super) fn edited(&mut self, index: usize, pin: Option<bool>, at: Option<DVec3>) {
        if self.dirty {
            return;
        }
        if let Some(x) = at {
            self.packed.x[index] = x;
            self.packed.v[index] = DVec3::ZERO;
            self.state_edited = true;
        }
        if let Some(pinned) = pin {
            self.pins.push((index, pinned));
        }
    }

    /// Takes the pin off particle `index` (entity `e`); it starts at rest.
    pub(super) fn free(&mut self, index: usize, e: Entity) {
        if self.world.remove_one::<Pin>(e).is_ok() {
            if let Ok(mut p) = self.world.get::<&mut crate::Particle>(e) {
                p.velocity = DVec3::ZERO;
            }
            self.edited(index, Some(false), None);
        }
    }

    /// The cloths, each with its particles' range in scene order (see [`Self::positions`]);
    /// a cloth whose [`ClothSprings`] (or a mesh whose [`crate::MeshSurface`]) were despawned
    /// through [`Self::world_mut`] is left out. Meshes are cloths here too.
    pub fn cloths(&self) -> impl Iterator<Item = (ClothId, std::ops::Range<usize>)> + '_ {
        self.cloths.iter().filter_map(|&(id, e)| {
            let r = range_of(&self.world, e)?;
            Some((id, r.start as usize..r.end as usize))
        })
    }

    /// Adds a mesh cloth, validated as a scene's would be (its geometry inline: a scene's
    /// `file` is read by [`Scene::load`]), after every particle of the scene; its triangles join
    /// [`Self::triangles`], and [`Self::remove_cloth`] removes it. Re-gathers on the next step.
    pub fn add_mesh(&mut self, mesh: &crate::scene::mesh::MeshCloth) -> Result<ClothId, Error> {
        let mut check = Scene::new(self.config.dt);
        check.meshes.push(mesh.clone());
        valid_part(&check, "add_mesh")?;
        let first = self.next_index();
        let e = crate::scene::spawn_mesh(&mut self.world, first, mesh);
        let id = ClothId(self.next_cloth);
        self.next_cloth += 1;
        self.cloths.push((id, e));
        if let Some(custom) = &mut self.frame.custom {
            crate::MeshSurface::all_of(&self.world, e, custom);
        }
        self.frame.triangles.take();
        self.dirty = true;
        Ok(id)
    }

    /// The World's cloths and meshes (their [`ClothSprings`] or [`crate::MeshSurface`]) as
    /// units, in scene order: a World built outside a scene has its cloths listed, removable
    /// and named in [`Self::torn`] too.
    pub(super) fn register_cloths(&mut self) {
        let w = &self.world;
        let grids = w
            .query::<(Entity, &ClothSprings)>()
            .iter()
            .map(|(e, _)| e)
            .collect::<Vec<_>>();
        let meshes = w
            .query::<(Entity, &crate::MeshSurface)>()
            .iter()
            .map(|(e, _)| e)
            .collect::<Vec<_>>();
        let mut found: Vec<(u32, Entity)> = (grids.into_iter().chain(meshes))
            .filter_map(|e| Some((range_of(w, e)?.start, e)))
            .collect();
        found.sort_unstable();
        found.dedup();
        for (_, e) in found {
            self.cloths.push((ClothId(self.next_cloth), e));
            self.next_cloth += 1;
        }
    }

    /// The scene index after every particle's.
    fn next_index(&self) -> u32 {
        self.world
            .query::<&SceneIndex>()
            .iter()
            .map(|i| i.0 + 1)
            .max()
            .unwrap_or(0)
    }

    /// Adds a cloth, validated as a scene's would be, after every particle of the scene
    /// (scene order); its triangles join [`Self::triangles`]. Re-gathers on the next step.
    pub fn add_cloth(&mut self, cloth: &crate::scene::Cloth) -> Result<ClothId, Error> {
        let mut check = Scene::new(self.config.dt);
        check.cloths.push(cloth.clone());
        valid_part(&check, "add_cloth")?;
        let first = self.next_index();
        let e = crate::scene::spawn_cloth(&mut self.world, first, cloth);
        let id = ClothId(self.next_cloth);
        self.next_cloth += 1;
        self.cloths.push((id, e));
        if let (Some(custom), Some(grid)) = (&mut self.frame.custom, grid_of(&self.world, e)) {
            grid.triangles(custom);
        }
        self.frame.triangles.take();
        self.dirty = true;
        Ok(id)
    }

    /// Removes a cloth: its particles, every spring touching them, their pins and attachments
    /// and its triangles. Later particles move up in scene order to close the gap.
    /// [`SimError::UnknownCloth`] if there is no such cloth, or if its [`ClothSprings`] were
    /// despawned through [`Self::world_mut`] (its particles are then ordinary particles).
    pub fn remove_cloth(&mut self, id: ClothId) -> Result<(), SimError> {
        let k = self
            .cloths
            .iter()
            .position(|(c, _)| *c == id)
            .ok_or(SimError::UnknownCloth)?;
        let (_, e) = self.cloths.remove(k);
        // Its springs' (or surface's) component removed by hand: no longer a cloth.
        let range = range_of(&self.world, e).ok_or(SimError::UnknownCloth)?;
        let n = range.end - range.start;
        let doomed: std::collections::HashSet<Entity> = self
            .world
            .query::<(Entity, &SceneIndex)>()
            .iter()
            .filter(|(_, i)| range.contains(&i.0))
            .map(|(e, _)| e)
            .collect();
        let mut springs: Vec<Entity> = self
            .world
            .query::<(Entity, &crate::Spring)>()
            .iter()
            .filter(|(_, s)| doomed.contains(&s.a) || doomed.contains(&s.b))
            .map(|(e, _)| e)
            .collect();
        // Cloth springs over any of its particles go too.
        let (lo, hi) = (range.start as u64, range.end as u64);
        for (e, c) in self.world.query::<(Entity, &ClothSprings)>().iter() {
            let r = c.grid.range();
            if r.start < hi && lo < r.end {
                springs.push(e);
            }
        }
        // A mesh's surface goes with it (a grid's is its springs' entity, listed above).
        springs.push(e);
        for e in springs.into_iter().chain(doomed.iter().copied()) {
            let _ = self.world.despawn(e);
        }
        self.grabbed.retain(|e| !doomed.contains(e));
        if let Some(custom) = &mut self.frame.custom {
            custom.retain(|t| !t.iter().any(|i| range.contains(i)));
        }
        self.renumber(range.end, -(n as i64));
        self.frame.triangles.take();
        self.frame.prev.clear();
        self.dirty = true;
        Ok(())
    }

    /// Every scene index from `from` on moved by `by` (a cloth removed before them, or
    /// particles inserted): the particles', and every per-cloth record kept from its first
    /// particle (grids, surfaces, tethers, collision layers) and the game's own triangles.
    pub(super) fn renumber(&mut self, from: u32, by: i64) {
        let moved = |i: &mut u32| {
            if *i >= from {
                *i = (*i as i64 + by) as u32;
            }
        };
        for i in self.world.query_mut::<&mut SceneIndex>() {
            moved(&mut i.0);
        }
        for c in self.world.query_mut::<&mut ClothSprings>() {
            moved(&mut c.grid.first);
        }
        for m in self
            .world
            .query_mut::<&mut crate::components::MeshSurface>()
        {
            moved(&mut m.first);
        }
        for t in self.world.query_mut::<&mut crate::Tethers>() {
            moved(&mut t.first);
        }
        for l in self.world.query_mut::<&mut crate::collide::Layer>() {
            moved(&mut l.first);
        }
        for t in self.frame.custom.iter_mut().flatten() {
            t.iter_mut().for_each(moved);
        }
    }

    /// Adds a rigid body, validated as a scene's would be (an error names the field, e.g.
    /// `add_body: mass`). The first body of a simulation without any brings the rapier world and
    /// the contact stage (default contact material, see [`Self::set_contact_material`]).
    pub fn add_body(&mut self, body: &crate::Body) -> Result<crate::RigidProp, Error> {
        let def = body.to_def();
        let mut check = Scene::new(self.config.dt);
        check.bodies.push(def.clone());
        match valid_part(&check, "add_body") {
            Ok(()) => {}
            Err(Error::Scene(crate::SceneError::Invalid { path, mut issues })) => {
                for i in &mut issues {
                    if let Some(field) = i.location.strip_prefix("bodies[0].") {
                        i.location = field.to_string();
                    } else if i.location == "bodies[0]" {
                        i.location = "body".into();
                    }
                }
                return Err(crate::SceneError::Invalid { path, issues }.into());
            }
            Err(e) => return Err(e),
        }
        if self.props.is_none() {
            let (props, _) = Props::build(&[], self.contact, self.config.gravity, &mut self.world)
                .map_err(|e| SimError::BadBody(e.to_string()))?;
            self.props = Some(props);
        }
        let props = self.props.as_mut().ok_or(SimError::UnknownBody)?;
        let prop = props
            .add_body(&def, &mut self.world)
            .map_err(SimError::BadBody)?;
        self.dirty = true;
        Ok(prop)
    }

    /// Removes a body with its collider; particles attached to it go free.
    pub fn remove_body(&mut self, prop: crate::contacts::RigidProp) -> Result<(), SimError> {
        let props = self.props.as_mut().ok_or(SimError::UnknownBody)?;
        if !props.remove_body(prop.body, &mut self.world) {
            return Err(SimError::UnknownBody);
        }
        self.dirty = true;
        Ok(())
    }

    /// Pins particle `index` (scene order) where it is. The next step refreshes the springs
    /// touching it (no re-gather).
    pub fn pin(&mut self, index: usize) -> Result<(), SimError> {
        let e = self.particle_entity(index)?;
        self.grabbed.retain(|g| *g != e);
        if self.world.get::<&Pin>(e).is_err() {
            let _ = self.world.insert_one(e, Pin);
            self.edited(index, Some(true), None);
        }
        Ok(())
    }

    /// Frees particle `index` (scene order) from its pin; it starts at rest. The next step
    /// refreshes the springs touching it (no re-gather); it fails then, naming the particle,
    /// if its mass is not valid.
    pub fn unpin(&mut self, index: usize) -> Result<(), SimError> {
        let e = self.particle_entity(index)?;
        self.grabbed.retain(|g| *g != e);
        self.free(index, e);
        Ok(())
    }

    /// The entity of particle `index` in scene order.
    pub fn particle_entity(&self, index: usize) -> Result<Entity, SimError> {
        self.packed
            .topology
            .entities
            .get(index)
            .copied()
            .filter(|&e| self.world.contains(e))
            .ok_or(SimError::NoParticle { index })
    }
}
