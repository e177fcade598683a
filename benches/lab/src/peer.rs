//! rapier 0.36's own soft-body cloth (`SoftBodyBuilder::cloth`) on the same cloth, so the
//! speed-against-error report can place it beside ours (feature `rapier`).
//!
//! rapier solves each edge as a soft distance constraint whose stiffness is a natural
//! frequency and damping ratio normalised by the constraint's effective mass, which for a
//! free pair is the reduced mass μ: the same `ω0 = √(κ/μ)` and `ζ` as ours. At a pin the
//! effective mass is the free particle's whole mass, so those edges (and shear edges whose
//! spring differs from the structural one) get per-edge coefficients: with the material's alone
//! rapier's cloth was twice as stiff at the pins and swung on another path (`tests/peer.rs`).

use std::time::Instant;

use harmonic::glam::DVec3;
use harmonic::rapier3d::prelude::*;

use harmonic::scene::{Anchor, Cloth, Plane};

/// rapier's cloth for ours: the builder, and rapier's particle index of our (column, row).
fn rapier_cloth(
    cloth: &Cloth,
) -> Result<(SoftBodyBuilder, impl Fn(usize, usize) -> usize), String> {
    let (cols, rows) = (cloth.resolution.0 as usize, cloth.resolution.1 as usize);
    if cloth
        .pins
        .iter()
        .any(|p| !matches!(p, Anchor::TopLeft | Anchor::TopRight))
    {
        return Err("the rapier peer maps cloths pinned at their top corners only".into());
    }
    let m = cloth.mass / (cols * rows) as f64;
    // rapier normalises each edge's frequency by its effective mass 1/(w_a + w_b): μ = m/2
    // between free particles, m at a pin. Ours resolves every cloth spring with μ = m/2, so an
    // edge at a pin gets its own coefficients, or rapier would make it twice as stiff.
    let coefficients = |s: &harmonic::scene::SpringSpec, m_eff: f64| {
        let (k, c) = s.resolve(m, m);
        let w0 = (k / m_eff).sqrt();
        SpringCoefficients::new(
            (w0 / (2.0 * std::f64::consts::PI)) as f32,
            (c / (2.0 * (k * m_eff).sqrt())) as f32,
        )
    };
    let bend_spec = cloth.bend.as_ref().unwrap_or(&cloth.structural);
    let edge = coefficients(&cloth.structural, m / 2.0);
    let bend = coefficients(bend_spec, m / 2.0);
    let du = Vector::new((cloth.size.0 / (cols - 1) as f64) as f32, 0.0, 0.0);
    let step = (cloth.size.1 / (rows - 1) as f64) as f32;
    let dv = match cloth.plane {
        Plane::Horizontal => Vector::new(0.0, 0.0, step),
        Plane::Vertical => Vector::new(0.0, -step, 0.0),
    };
    let origin = Vector::new(
        cloth.origin[0] as f32,
        cloth.origin[1] as f32,
        cloth.origin[2] as f32,
    );
    // rapier's particle (i, j) = origin + i du + j dv has index i·rows + j; ours (col, row) is row·cols + col.
    let rapier_index = move |col: usize, row: usize| col * rows + row;
    let mut pins = Vec::new();
    for p in &cloth.pins {
        pins.push(match p {
            Anchor::TopLeft => rapier_index(0, 0) as u32,
            _ => rapier_index(cols - 1, 0) as u32,
        });
    }
    let mut builder = SoftBodyBuilder::cloth(origin, du, dv, cols, rows)
        .mass(cloth.mass as f32)
        .pinned_particles(pins.iter().copied())
        .material(SoftBodyMaterial {
            edge_softness: edge,
            bend_softness: bend,
            ..Default::default()
        });
    // rapier's cloth always has shear diagonals and bend edges; ours only when the scene asks.
    let diagonal = |e: &[u32; 2]| {
        let d = builder.positions[e[0] as usize] - builder.positions[e[1] as usize];
        d.dot(du).abs() > 0.0 && d.dot(dv).abs() > 0.0
    };
    if cloth.shear.is_none() {
        builder.edges.retain(|e| !diagonal(e));
    }
    if cloth.bend.is_none() {
        builder.bend_edges.clear();
    }
    let shear_spec = cloth.shear.as_ref().unwrap_or(&cloth.structural);
    // Overrides index `edges` then `bend_edges`: the shear edges when their spring differs from
    // the structural one, and every edge at a pin.
    let at_pin = |e: &[u32; 2]| pins.contains(&e[0]) || pins.contains(&e[1]);
    let structural = builder.edges.len();
    let overrides: Vec<_> = builder
        .edges
        .iter()
        .chain(&builder.bend_edges)
        .enumerate()
        .filter_map(|(i, e)| {
            let spec = if i >= structural {
                bend_spec
            } else if diagonal(e) {
                shear_spec
            } else {
                &cloth.structural
            };
            let m_eff = if at_pin(e) { m } else { m / 2.0 };
            let c = coefficients(spec, m_eff);
            let default = if i >= structural { bend } else { edge };
            (c != default).then_some((i as u32, c))
        })
        .collect();
    builder.edge_softness.extend(overrides);
    Ok((builder, rapier_index))
}

/// rapier's particle positions in our particle order.
fn our_order(body: &SoftBody, cloth: &Cloth, index: &impl Fn(usize, usize) -> usize) -> Vec<DVec3> {
    let (cols, rows) = (cloth.resolution.0 as usize, cloth.resolution.1 as usize);
    let mut out = vec![DVec3::ZERO; cols * rows];
    for row in 0..rows {
        for col in 0..cols {
            let p = body.particle_position(index(col, row));
            out[row * cols + col] = DVec3::new(p.x as f64, p.y as f64, p.z as f64);
        }
    }
    out
}

/// Positions at `seconds` (in our cloth's particle order) and the wall time of the steps.
/// `substeps` is rapier's `num_solver_iterations` per 1/60 s step (its default is 4).
/// `observe` sees the positions after every step, outside the timed region.
pub fn run_cloth(
    cloth: &Cloth,
    gravity: DVec3,
    seconds: f64,
    substeps: usize,
    observe: impl FnMut(&[DVec3]),
) -> Result<(Vec<DVec3>, f64), String> {
    let (builder, index) = rapier_cloth(cloth)?;
    let mut world = PhysicsWorld::new();
    world.gravity = gravity.as_vec3();
    world.integration_parameters.num_solver_iterations = substeps;
    let handle = insert(&mut world, builder.no_surface_collider(), cloth);
    Ok(timed_run(
        &mut world,
        handle,
        seconds,
        cloth,
        index,
        Some(&mut { observe }),
    ))
}

/// rapier's cloth dropped on a fixed ball (its own contacts: the cloth's surface collider with
/// a skin of `thickness`, friction `friction`): positions at `seconds` in our particle order,
/// and the wall time of the steps (rapier's default 60 Hz step and solver iterations).
pub fn drape_on_ball(
    cloth: &Cloth,
    gravity: DVec3,
    centre: DVec3,
    radius: f64,
    thickness: f64,
    friction: f64,
    seconds: f64,
) -> Result<(Vec<DVec3>, f64), String> {
    let (builder, index) = rapier_cloth(cloth)?;
    let mut world = PhysicsWorld::new();
    world.gravity = gravity.as_vec3();
    world.insert(
        RigidBodyBuilder::fixed().translation(centre.as_vec3()),
        ColliderBuilder::ball(radius as f32).friction(friction as f32),
    );
    let handle = insert(&mut world, builder.particle_radius(thickness as f32), cloth);
    Ok(timed_run(&mut world, handle, seconds, cloth, index, None))
}

/// Inserts the soft body with the cloth's initial velocity on its unpinned particles.
fn insert(world: &mut PhysicsWorld, builder: SoftBodyBuilder, cloth: &Cloth) -> SoftBodyHandle {
    let pinned = builder.pinned.clone();
    let handle = world.insert_soft_body(builder);
    let v = DVec3::from(cloth.velocity).as_vec3();
    let body = &mut world.soft_bodies[handle];
    for i in 0..body.num_particles() {
        if !pinned.contains(&(i as u32)) {
            body.set_particle_velocity(i, v);
        }
    }
    handle
}

/// Sees the cloth's positions (our order) after each step.
type Observer<'a> = dyn FnMut(&[DVec3]) + 'a;

/// Steps `world` through `seconds` at its own step: the soft body's positions (our order) and
/// the wall time of the steps; `observe`, if any, sees the positions after each step, untimed.
fn timed_run(
    world: &mut PhysicsWorld,
    handle: SoftBodyHandle,
    seconds: f64,
    cloth: &Cloth,
    index: impl Fn(usize, usize) -> usize,
    mut observe: Option<&mut Observer<'_>>,
) -> (Vec<DVec3>, f64) {
    let frames = (seconds / world.integration_parameters.dt as f64).round() as usize;
    let mut wall = 0.0;
    for _ in 0..frames {
        let t = Instant::now();
        world.step();
        wall += t.elapsed().as_secs_f64();
        if let Some(observe) = observe.as_mut() {
            observe(&our_order(&world.soft_bodies[handle], cloth, &index));
        }
    }
    (our_order(&world.soft_bodies[handle], cloth, &index), wall)
}

/// Largest and mean strain |ℓ − ℓ0|/ℓ0 of a cloth's structural edges (grid neighbours), from
/// positions in our particle order.
pub fn grid_strain(cloth: &Cloth, x: &[DVec3]) -> (f64, f64) {
    let (cols, rows) = (cloth.resolution.0 as usize, cloth.resolution.1 as usize);
    let (dx, dy) = (
        cloth.size.0 / (cols - 1) as f64,
        cloth.size.1 / (rows - 1) as f64,
    );
    let (mut max, mut sum, mut n) = (0.0f64, 0.0, 0usize);
    for row in 0..rows {
        for col in 0..cols {
            let i = row * cols + col;
            let mut edge = |j: usize, l0: f64| {
                let s = ((x[i] - x[j]).length() - l0).abs() / l0;
                max = max.max(s);
                sum += s;
                n += 1;
            };
            if col + 1 < cols {
                edge(i + 1, dx);
            }
            if row + 1 < rows {
                edge(i + cols, dy);
            }
        }
    }
    (max, sum / n.max(1) as f64)
}
