//! Rigid bodies: the scene's rapier world, kinematic paths, colliders from shapes.

use super::*;

/// A keyframe's pose.
pub(super) fn pose_of(k: &Keyframe) -> Pose {
    Pose::new(v3(k.position), axis_angle(k.rotation))
}

/// The pose on a keyframed path at time `t`: linear in position, spherical in rotation, held
/// before the first and after the last keyframe.
pub fn path_pose(path: &[Keyframe], t: f64) -> Pose {
    let next = path.partition_point(|k| k.time <= t);
    match (next.checked_sub(1).map(|i| &path[i]), path.get(next)) {
        (Some(a), Some(b)) => {
            let s = ((t - a.time) / (b.time - a.time)) as f32;
            pose_of(a).lerp(&pose_of(b), s)
        }
        (Some(a), None) => pose_of(a),
        (None, Some(b)) => pose_of(b),
        (None, None) => Pose::IDENTITY,
    }
}

/// The rapier collider of a shape, or why the shape is unusable.
/// A body's collider with its mass: the body's `mass`, else its `density` (default 1000
/// kg/m³) over the shape's volume.
pub(crate) fn massive_collider_of(b: &BodyDef) -> Result<ColliderBuilder, String> {
    let co = collider_of(&b.shape)?;
    Ok(match (b.mass, b.density) {
        (Some(m), _) => co.mass(m as f32),
        (None, Some(d)) => co.density(d as f32),
        (None, None) => co.density(1000.0),
    })
}

pub(crate) fn collider_of(shape: &Shape) -> Result<ColliderBuilder, String> {
    Ok(match shape {
        Shape::Ball { radius } => ColliderBuilder::ball(*radius as f32),
        Shape::Cuboid { half_extents: h } => {
            ColliderBuilder::cuboid(h[0] as f32, h[1] as f32, h[2] as f32)
        }
        Shape::Capsule {
            half_height,
            radius,
        } => ColliderBuilder::capsule_y(*half_height as f32, *radius as f32),
        Shape::Cylinder {
            half_height,
            radius,
        } => ColliderBuilder::cylinder(*half_height as f32, *radius as f32),
        Shape::ConvexHull { points } => {
            let pts: Vec<Vec3> = points.iter().map(|p| v3(*p)).collect();
            ColliderBuilder::convex_hull(&pts).ok_or("the points span no volume")?
        }
        Shape::TriMesh { vertices, indices } => {
            ColliderBuilder::trimesh(vertices.iter().map(|p| v3(*p)).collect(), indices.clone())
                .map_err(|e| e.to_string())?
        }
        Shape::HeightField { heights, scale } => {
            let rows = heights.len();
            let cols = heights.first().map_or(0, Vec::len);
            // parry's Array2 is column-major.
            let mut data = Vec::with_capacity(rows * cols);
            for c in 0..cols {
                for row in heights {
                    data.push(row[c] as f32);
                }
            }
            ColliderBuilder::heightfield(
                rapier3d::parry::utils::Array2::new(rows, cols, data),
                v3(*scale),
            )
        }
    })
}

impl Props {
    /// The rapier world of `bodies`, each also spawned into `world` as a [`RigidProp`] entity.
    /// Shapes must have passed scene validation.
    pub(crate) fn build(
        bodies: &[BodyDef],
        contact: ContactMaterial,
        gravity: DVec3,
        world: &mut World,
    ) -> Result<(Props, Vec<RigidBodyHandle>), String> {
        let mut physics = PhysicsWorld::new();
        physics.gravity = gravity.as_vec3();
        let mut props = Props {
            physics,
            moving: false,
            dynamic: false,
            paths: Vec::new(),
            driven: Vec::new(),
            time: 0.0,
            substep: 0,
            substeps: 1,
            stage: ContactStage::new(contact),
        };
        let mut handles = Vec::with_capacity(bodies.len());
        for (i, b) in bodies.iter().enumerate() {
            let prop = props
                .add_body(b, world)
                .map_err(|e| format!("bodies[{i}].{e}"))?;
            handles.push(prop.body);
        }
        Ok((props, handles))
    }

    /// Adds a body (validated like a scene's) to the rapier world and spawns its
    /// [`RigidProp`] entity into `world`.
    pub(crate) fn add_body(&mut self, b: &BodyDef, world: &mut World) -> Result<RigidProp, String> {
        let physics = &mut self.physics;
        let (position, rotation) = match b.path.first() {
            Some(k) => (k.position, k.rotation),
            None => (b.position, b.rotation),
        };
        let builder = match b.kind {
            BodyKind::Fixed => RigidBodyBuilder::fixed(),
            BodyKind::Dynamic => RigidBodyBuilder::dynamic(),
            BodyKind::Kinematic => RigidBodyBuilder::kinematic_velocity_based(),
            BodyKind::KinematicPosition => RigidBodyBuilder::kinematic_position_based(),
        }
        .translation(v3(position))
        .rotation(axis_angle(rotation))
        .linvel(v3(b.velocity))
        .angvel(v3(b.angular_velocity))
        .linear_damping(b.linear_damping as f32)
        .angular_damping(b.angular_damping as f32);
        let co = massive_collider_of(b)
            .map_err(|e| format!("shape: {e}"))?
            .friction(b.friction as f32)
            .restitution(b.restitution as f32);
        let body = physics.bodies.insert(builder);
        let collider = physics
            .colliders
            .insert_with_parent(co, body, &mut physics.bodies);
        let prop = RigidProp { body, collider };
        world.spawn((prop,));
        if !b.path.is_empty() {
            self.paths.push((body, b.path.clone()));
        }
        self.moving |= b.kind != BodyKind::Fixed;
        self.dynamic |= b.kind == BodyKind::Dynamic;
        Ok(prop)
    }

    /// Removes a body, its collider, its [`RigidProp`] entity and the attachments of particles
    /// to it (those particles go free). False when the body is not in this world.
    pub(crate) fn remove_body(&mut self, body: RigidBodyHandle, world: &mut World) -> bool {
        if self.physics.remove_body(body).is_none() {
            return false;
        }
        self.paths.retain(|(h, _)| *h != body);
        // The body's own entity, and the particles attached to it.
        let mine: Vec<(Entity, bool)> = world
            .query::<(Entity, Option<&RigidProp>, Option<&Attachment>)>()
            .iter()
            .filter_map(|(e, p, a)| match (p, a) {
                (Some(p), _) if p.body == body => Some((e, true)),
                (_, Some(a)) if a.body == body => Some((e, false)),
                _ => None,
            })
            .collect();
        for (e, is_body) in mine {
            if is_body {
                let _ = world.despawn(e);
            } else {
                let _ = world.remove_one::<Attachment>(e);
            }
        }
        let bodies = &self.physics.bodies;
        self.moving = bodies.iter().any(|(_, b)| !b.is_fixed());
        self.dynamic = bodies.iter().any(|(_, b)| b.is_dynamic());
        true
    }

    /// After a gather: the attached particles' packed indices.
    pub(crate) fn gather(&mut self, world: &World, packed: &Packed) {
        self.stage.gather(world, packed);
    }

    /// Entities of attached particles whose body no longer exists.
    pub(crate) fn dangling(&self, world: &World) -> Option<Entity> {
        self.stage.dangling(world, &self.physics.bodies)
    }

    /// The contact stage (the simulation's substep loop drives it directly).
    pub(crate) fn stage_mut(&mut self) -> &mut ContactStage {
        &mut self.stage
    }

    /// The frame's statistics start again; position-driven bodies given a target through the
    /// API (`set_next_kinematic_position`) reach it at the frame's end, in even substeps.
    pub(crate) fn begin_frame(&mut self, substeps: u32) {
        self.stage.begin_frame();
        (self.substep, self.substeps) = (0, substeps.max(1));
        self.driven.clear();
        for (handle, b) in self.physics.bodies.iter() {
            let by_path = self.paths.iter().any(|(p, _)| *p == handle);
            if b.body_type() == RigidBodyType::KinematicPositionBased && !by_path {
                self.driven
                    .push((handle, *b.position(), *b.next_position()));
            }
        }
    }

    /// Steps 1–3 of the module docs, after the integrate stage of one substep.
    pub(crate) fn substep(&mut self, packed: &mut Packed, h: f64) {
        self.step_bodies(h);
        let (bodies, colliders) = (&mut self.physics.bodies, &self.physics.colliders);
        self.stage.substep(packed, bodies, colliders, 0.0, h);
    }

    /// Step 1: the bodies move by one substep (paths, API targets, then rapier).
    pub(crate) fn step_bodies(&mut self, h: f64) {
        self.substep += 1;
        self.time += h;
        if self.moving {
            let bodies = &mut self.physics.bodies;
            for (handle, path) in &self.paths {
                if let Some(b) = bodies.get_mut(*handle) {
                    b.set_next_kinematic_position(path_pose(path, self.time));
                }
            }
            let s = self.substep as f32 / self.substeps as f32;
            for (handle, start, target) in &self.driven {
                if let Some(b) = bodies.get_mut(*handle) {
                    b.set_next_kinematic_position(start.lerp(target, s.min(1.0)));
                }
            }
            self.physics.integration_parameters.dt = h as f32;
            self.physics.step();
        }
    }

    /// Some body can move (rapier steps every substep); false when all are fixed.
    pub fn moving(&self) -> bool {
        self.moving
    }

    /// What the contact stage did in the last frame.
    pub fn stats(&self) -> &ContactStats {
        &self.stage.stats
    }

    /// The cloth's contact material: thickness and friction.
    pub fn contact(&self) -> &ContactMaterial {
        &self.stage.contact
    }

    /// rapier's rigid bodies.
    pub fn bodies(&self) -> &RigidBodySet {
        &self.physics.bodies
    }

    /// rapier's colliders.
    pub fn colliders(&self) -> &ColliderSet {
        &self.physics.colliders
    }
}
