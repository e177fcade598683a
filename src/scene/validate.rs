//! Semantic checks; each problem names its entry.

use super::{Anchor, Limits, Scene, SpringSpec, SPEED_BOUND, V3, WORLD_BOUND};
use crate::error::Issue;
use crate::integrate::Integrator;

pub(super) struct Issues(pub(super) Vec<Issue>);

impl Issues {
    pub(super) fn push(&mut self, location: impl Into<String>, message: impl Into<String>) {
        self.0.push(Issue {
            location: location.into(),
            message: message.into(),
        });
    }
    pub(super) fn positive(&mut self, location: impl Into<String>, v: f64) {
        if !(v.is_finite() && v > 0.0) {
            self.push(location, format!("must be finite and > 0, got {v:?}"));
        }
    }
    /// A limit: > 0, infinite for none; `unit` says what it is a share of, if anything.
    pub(super) fn limit(&mut self, location: &str, v: Option<f64>, unit: &str) {
        if let Some(l) = v.filter(|l| l.is_nan() || *l <= 0.0) {
            self.push(
                location,
                format!("must be > 0 ({unit}inf: not checked), got {l:?}"),
            );
        }
    }
    pub(super) fn non_negative(&mut self, location: impl Into<String>, v: f64) {
        if !(v.is_finite() && v >= 0.0) {
            self.push(location, format!("must be finite and ≥ 0, got {v:?}"));
        }
    }
    pub(super) fn finite(&mut self, location: impl Into<String>, v: V3) {
        if !v.iter().all(|c| c.is_finite()) {
            self.push(location, format!("must be finite, got {v:?}"));
        }
    }
    /// A point: finite, each coordinate within [`WORLD_BOUND`].
    pub(super) fn point(&mut self, location: impl Into<String>, v: V3) {
        self.bounded(location, v, WORLD_BOUND, "m (WORLD_BOUND)");
    }
    /// A velocity: finite, each component within [`SPEED_BOUND`].
    pub(super) fn speed(&mut self, location: impl Into<String>, v: V3) {
        self.bounded(location, v, SPEED_BOUND, "m/s or rad/s (SPEED_BOUND)");
    }
    pub(super) fn bounded(&mut self, location: impl Into<String>, v: V3, bound: f64, unit: &str) {
        let location = location.into();
        let before = self.0.len();
        self.finite(location.clone(), v);
        if self.0.len() == before && v.iter().any(|c| c.abs() > bound) {
            self.push(
                location,
                format!("{v:?} is beyond the world's bound of ±{bound:e} {unit}"),
            );
        }
    }
    /// A length: finite, > 0 and within [`WORLD_BOUND`].
    pub(super) fn size(&mut self, location: impl Into<String>, v: f64) {
        let location = location.into();
        let before = self.0.len();
        self.positive(location.clone(), v);
        if self.0.len() == before && v > WORLD_BOUND {
            self.push(
                location,
                format!("{v:?} is beyond the world's bound of {WORLD_BOUND:e} m (WORLD_BOUND)"),
            );
        }
    }
    /// An axis-angle rotation: finite, its angle at most [`crate::contacts::MAX_ANGLE`] (it is
    /// taken modulo 4π, which beyond that is rounding noise).
    pub(super) fn rotation(&mut self, location: impl Into<String>, v: V3) {
        let location = location.into();
        let before = self.0.len();
        self.finite(location.clone(), v);
        let angle = v.iter().map(|c| c * c).sum::<f64>().sqrt();
        if self.0.len() == before && (angle.is_nan() || angle > crate::contacts::MAX_ANGLE) {
            self.push(
                location,
                format!(
                    "an angle of {angle:?} rad has no meaningful remainder modulo 4π; at most {:e}",
                    crate::contacts::MAX_ANGLE
                ),
            );
        }
    }
    /// [`Self::spec`], then the stiffness and damping it gives between masses `m_a`, `m_b`
    /// within f32's range: the GPU back end's precision, beyond which the step would freeze
    /// the spring's ends (the CPU does the same, so the back ends agree).
    pub(super) fn spec_between(&mut self, at: &str, s: &SpringSpec, m_a: f64, m_b: f64) {
        let before = self.0.len();
        self.spec(at, s);
        let mass_ok = |m: f64| m.is_finite() && m > 0.0;
        if self.0.len() > before || !(mass_ok(m_a) && mass_ok(m_b)) {
            return;
        }
        let (k, c) = s.resolve(m_a, m_b);
        for (what, v) in [("stiffness", k), ("damping", c)] {
            if v.is_nan() || v > f32::MAX as f64 {
                self.push(
                    at,
                    format!(
                        "gives a {what} of {v:?}, beyond f32's range ({:?}), the precision of the \
                         GPU back end",
                        f32::MAX
                    ),
                );
            }
        }
    }

    pub(super) fn spec(&mut self, at: &str, s: &SpringSpec) {
        match (s.stiffness, s.frequency) {
            (Some(k), None) => self.non_negative(format!("{at}.stiffness"), k),
            (None, Some(f)) => self.positive(format!("{at}.frequency"), f),
            (Some(_), Some(_)) => self.push(at, "give `stiffness` or `frequency`, not both"),
            (None, None) => self.push(at, "needs `stiffness` (N/m) or `frequency` (Hz)"),
        }
        match (s.damping, s.damping_ratio) {
            (Some(c), None) => self.non_negative(format!("{at}.damping"), c),
            (None, Some(z)) => self.non_negative(format!("{at}.damping_ratio"), z),
            (Some(_), Some(_)) => self.push(at, "give `damping` or `damping_ratio`, not both"),
            (None, None) => {}
        }
    }
}

impl Scene {
    /// Every semantic problem, in file order, within the default [`Limits`]; empty when the
    /// scene is sound.
    pub fn validate(&self) -> Vec<Issue> {
        self.validate_with(&Limits::DEFAULT)
    }

    /// Every semantic problem, in file order, within `limits`.
    pub fn validate_with(&self, limits: &Limits) -> Vec<Issue> {
        let mut is = Issues(Vec::new());
        is.positive("dt", self.dt);
        match self.substeps {
            Some(0) => is.push("substeps", "must be ≥ 1"),
            Some(k) if k > limits.max_substeps => is.push(
                "substeps",
                format!(
                    "{k} per frame; the limit is {} (Limits::max_substeps)",
                    limits.max_substeps
                ),
            ),
            _ => {}
        }
        is.finite("gravity", self.gravity);
        if let Err(e) = self.wind.check() {
            is.push("wind", e);
        }
        if let Some(name) = &self.integrator {
            if crate::RESEARCH_INTEGRATORS.contains(&name.as_str()) {
                is.push(
                    "integrator",
                    format!(
                        "`{name}` is a research variant: it moved to the lab crate \
                         (`harmonic-lab bench --integrators {name}`); a scene names one of: {}",
                        known_integrators()
                    ),
                );
            } else if name.parse::<Integrator>().is_err() {
                is.push(
                    "integrator",
                    format!("unknown `{name}` (known: {})", known_integrators()),
                );
            }
        }
        if let Some(name) = &self.backend {
            if name.parse::<crate::Backend>().is_err() {
                is.push(
                    "backend",
                    format!("unknown `{name}` (known: cpu, gpu, auto)"),
                );
            }
        }
        is.limit("strain_limit", self.strain_limit, "");
        if let Some(t) = self.tolerance {
            if !(t.is_finite() && t > 0.0) {
                is.push(
                    "tolerance",
                    format!("must be finite and > 0 (a share of the energy scale), got {t:?}"),
                );
            }
        }
        is.limit(
            "energy_limit",
            self.energy_limit,
            "a share of the energy scale; ",
        );
        if let Some(t) = self.seconds {
            // How many frames that is, is checked where a run takes its length from it
            // (`Limits::frames`, `harmonic run`): a scene stepped by a game has no end.
            is.positive("seconds", t);
        }
        for (i, p) in self.particles.iter().enumerate() {
            is.point(format!("particles[{i}].position"), p.position);
            is.speed(format!("particles[{i}].velocity"), p.velocity);
            is.positive(format!("particles[{i}].mass"), p.mass);
        }
        let n = self.particles.len();
        for (k, s) in self.springs.iter().enumerate() {
            let at = format!("springs[{k}]");
            let mut ends_ok = true;
            for (end, idx) in [("a", s.a), ("b", s.b)] {
                if idx >= n {
                    is.push(
                        format!("{at}.{end}"),
                        format!("particle {idx} does not exist ({n} particles)"),
                    );
                    ends_ok = false;
                }
            }
            if s.a == s.b {
                is.push(&at, format!("both ends are particle {}", s.a));
                ends_ok = false;
            }
            let mass = |i: usize| self.particles.get(i).map_or(0.0, |p| p.mass);
            is.spec_between(&at, &s.spec(), mass(s.a), mass(s.b));
            if let Some(l) = s.rest_length {
                is.positive(format!("{at}.rest_length"), l);
            }
            if ends_ok {
                let (pa, pb) = (self.particles[s.a].position, self.particles[s.b].position);
                let d = (0..3).map(|c| (pb[c] - pa[c]).powi(2)).sum::<f64>().sqrt();
                if d == 0.0 {
                    let what = if s.rest_length.is_none() {
                        "zero-length spring with no rest_length: its ends start at the same point"
                    } else {
                        "its ends start at the same point, so its direction is undefined"
                    };
                    is.push(&at, what);
                }
            }
        }
        for (i, c) in self.cloths.iter().enumerate() {
            let at = format!("cloths[{i}]");
            is.behaviour(&at, super::behaviour::Behaviour::of_cloth(c));
            is.point(format!("{at}.origin"), c.origin);
            is.speed(format!("{at}.velocity"), c.velocity);
            is.size(format!("{at}.size.0"), c.size.0);
            is.size(format!("{at}.size.1"), c.size.1);
            is.positive(format!("{at}.mass"), c.mass);
            let (cols, rows) = c.resolution;
            if cols < 2 || rows < 2 {
                is.push(
                    format!("{at}.resolution"),
                    format!("needs ≥ 2 particles each way, got {cols}×{rows}"),
                );
            }
            let m = c.mass / (cols as f64 * rows as f64);
            is.spec_between(&format!("{at}.structural"), &c.structural, m, m);
            if let Some(s) = &c.shear {
                is.spec_between(&format!("{at}.shear"), s, m, m);
            }
            if let Some(s) = &c.bend {
                is.spec_between(&format!("{at}.bend"), s, m, m);
                if cols < 3 && rows < 3 {
                    is.push(
                        format!("{at}.bend"),
                        "bend springs need ≥ 3 particles along a row or column",
                    );
                }
            }
            for (j, p) in c.pins.iter().enumerate() {
                if let Anchor::Particle(col, row) = *p {
                    if col >= cols || row >= rows {
                        is.push(
                            format!("{at}.pins[{j}]"),
                            format!("particle ({col}, {row}) is outside the {cols}×{rows} grid"),
                        );
                    }
                }
            }
        }
        for (i, r) in self.ropes.iter().enumerate() {
            let at = format!("ropes[{i}]");
            is.point(format!("{at}.start"), r.start);
            is.point(format!("{at}.end"), r.end);
            is.positive(format!("{at}.mass"), r.mass);
            if r.particles < 2 {
                is.push(
                    format!("{at}.particles"),
                    format!("needs ≥ 2, got {}", r.particles),
                );
            }
            if r.start == r.end {
                is.push(&at, "start and end coincide: zero-length segments");
            }
            let m = r.mass / r.particles as f64;
            is.spec_between(&format!("{at}.spring"), &r.spring, m, m);
            if let Some(s) = &r.bend {
                is.spec_between(&format!("{at}.bend"), s, m, m);
            }
        }
        for (i, m) in self.meshes.iter().enumerate() {
            m.check(&format!("meshes[{i}]"), limits, &mut is);
            match m.pinned_to {
                Some(b) if b >= self.bodies.len() => is.push(
                    format!("meshes[{i}].pinned_to"),
                    format!("body {b} does not exist ({} bodies)", self.bodies.len()),
                ),
                Some(_) if m.pins.is_empty() => is.push(
                    format!("meshes[{i}].pinned_to"),
                    "the mesh has no pins to hang on the body; give `pins`",
                ),
                _ => {}
            }
        }
        self.validate_props(&mut is);
        for (count, limit, what) in [
            (self.particle_count(), limits.max_particles, "particles"),
            (self.spring_count(), limits.max_springs, "springs"),
        ] {
            if count > limit {
                is.push(
                    "scene",
                    format!(
                        "asks for {count} {what}; the limit is {limit} (Limits::max_{what}, --max-{what})"
                    ),
                );
            }
        }
        is.0
    }

    fn validate_props(&self, is: &mut Issues) {
        use super::props::{ParticleRef, Shape};
        for (i, b) in self.bodies.iter().enumerate() {
            let at = format!("bodies[{i}]");
            is.point(format!("{at}.position"), b.position);
            is.rotation(format!("{at}.rotation"), b.rotation);
            is.speed(format!("{at}.velocity"), b.velocity);
            is.speed(format!("{at}.angular_velocity"), b.angular_velocity);
            match (b.mass, b.density) {
                (Some(_), Some(_)) => is.push(&at, "give `mass` or `density`, not both"),
                (Some(m), None) => is.positive(format!("{at}.mass"), m),
                (None, Some(d)) => is.positive(format!("{at}.density"), d),
                (None, None) => {}
            }
            is.non_negative(format!("{at}.friction"), b.friction);
            if !(0.0..=1.0).contains(&b.restitution) {
                is.push(
                    format!("{at}.restitution"),
                    format!("must be in [0, 1], got {:?}", b.restitution),
                );
            }
            is.non_negative(format!("{at}.linear_damping"), b.linear_damping);
            is.non_negative(format!("{at}.angular_damping"), b.angular_damping);
            if !b.path.is_empty() && b.kind != super::props::BodyKind::KinematicPosition {
                is.push(
                    format!("{at}.path"),
                    format!(
                        "only a KinematicPosition body follows a path, this one is {:?}",
                        b.kind
                    ),
                );
            }
            let mut last = f64::NEG_INFINITY;
            for (k, key) in b.path.iter().enumerate() {
                let kt = format!("{at}.path[{k}]");
                is.point(format!("{kt}.position"), key.position);
                is.rotation(format!("{kt}.rotation"), key.rotation);
                if !(key.time.is_finite() && key.time >= 0.0 && key.time > last) {
                    is.push(
                        format!("{kt}.time"),
                        format!(
                            "must be finite, ≥ 0 and after the keyframe before, got {:?}",
                            key.time
                        ),
                    );
                }
                last = key.time;
            }
            let sh = format!("{at}.shape");
            match &b.shape {
                Shape::Ball { radius } => is.size(format!("{sh}.radius"), *radius),
                Shape::Cuboid { half_extents } => {
                    for (k, h) in half_extents.iter().enumerate() {
                        is.size(format!("{sh}.half_extents[{k}]"), *h);
                    }
                }
                Shape::Capsule {
                    half_height,
                    radius,
                }
                | Shape::Cylinder {
                    half_height,
                    radius,
                } => {
                    is.size(format!("{sh}.half_height"), *half_height);
                    is.size(format!("{sh}.radius"), *radius);
                }
                Shape::ConvexHull { points } => {
                    for (k, p) in points.iter().enumerate() {
                        is.point(format!("{sh}.points[{k}]"), *p);
                    }
                    if points.len() < 4 {
                        is.push(
                            &sh,
                            format!("a convex hull needs ≥ 4 points, got {}", points.len()),
                        );
                    }
                }
                Shape::TriMesh { vertices, indices } => {
                    for (k, p) in vertices.iter().enumerate() {
                        is.point(format!("{sh}.vertices[{k}]"), *p);
                    }
                    if indices.is_empty() {
                        is.push(&sh, "a triangle mesh needs ≥ 1 triangle");
                    }
                    for (k, t) in indices.iter().enumerate() {
                        if t.iter().any(|&v| v as usize >= vertices.len()) {
                            is.push(
                                format!("{sh}.indices[{k}]"),
                                format!("{t:?} refers past the {} vertices", vertices.len()),
                            );
                        }
                    }
                }
                Shape::HeightField { heights, scale } => {
                    is.point(format!("{sh}.scale"), *scale);
                    let cols = heights.first().map_or(0, Vec::len);
                    if heights.len() < 2 || cols < 2 {
                        is.push(&sh, "a height field needs ≥ 2 rows and ≥ 2 columns");
                    }
                    for (r, row) in heights.iter().enumerate() {
                        if row.len() != cols {
                            is.push(
                                format!("{sh}.heights[{r}]"),
                                format!("has {} columns, row 0 has {cols}", row.len()),
                            );
                        }
                        if row
                            .iter()
                            .any(|h| !(h.is_finite() && h.abs() <= WORLD_BOUND))
                        {
                            is.push(
                                format!("{sh}.heights[{r}]"),
                                format!("must be finite and within ±{WORLD_BOUND:e} (WORLD_BOUND)"),
                            );
                        }
                    }
                }
            }
            // The shape's own checks, then (mass and density sound too) the body's mass.
            let sound = |is: &Issues, of: &str| is.0.iter().all(|e| !e.location.starts_with(of));
            if sound(is, &sh) {
                match crate::contacts::collider_of(&b.shape) {
                    Err(e) => is.push(&sh, e),
                    // rapier gives a dynamic body the mass of its shape's volume; with none,
                    // mass 0, it would silently behave as fixed.
                    Ok(co) if b.kind == super::props::BodyKind::Dynamic && b.mass.is_none() => {
                        // The shape's volume: its mass at density 1.
                        let volume = co.density(1.0).build().mass();
                        if !(volume.is_finite() && volume > 0.0) {
                            is.push(
                                &sh,
                                "encloses no volume, so a dynamic body would get mass 0 from its \
                                 density; give the body a `mass`, or a shape with volume",
                            );
                        }
                    }
                    Ok(_) => {}
                }
            }
            // rapier steps a dynamic body in f32: its mass and inertia (m r²) must fit.
            if sound(is, &at) && b.kind == super::props::BodyKind::Dynamic {
                let of = |co: rapier3d::prelude::ColliderBuilder| {
                    let mp = co.build().mass_properties();
                    (mp.mass(), mp.principal_inertia())
                };
                let unit = crate::contacts::collider_of(&b.shape).map(|c| of(c.density(1.0)));
                if let (Ok(co), Ok(unit)) = (crate::contacts::massive_collider_of(b), unit) {
                    let (m, inertia) = of(co);
                    // Past f32's range a value is infinite, or stored as an inverse of 0 and
                    // read back as 0 where the shape has some.
                    let lost =
                        |v: f32, u: f32| !v.is_finite() || v >= f32::MAX || (u > 0.0 && v <= 0.0);
                    let inertia_lost = (inertia.to_array().into_iter())
                        .zip(unit.1.to_array())
                        .any(|(v, u)| lost(v, u));
                    if lost(m, 1.0) || inertia_lost {
                        // What they would be, in f64: the unit-density values scaled.
                        let scale = match (b.mass, b.density) {
                            (Some(mass), _) => mass / f64::from(unit.0),
                            (None, Some(d)) => d,
                            (None, None) => 1000.0,
                        };
                        is.push(
                            &at,
                            format!(
                                "a mass of {:.3e} kg and an inertia of {:.3e} kg·m², beyond \
                                 f32's range (rapier's precision): a smaller body, mass or density",
                                scale * f64::from(unit.0),
                                scale * f64::from(unit.1.max_element())
                            ),
                        );
                    }
                }
            }
        }
        if let Some(c) = &self.contact {
            is.positive("contact.thickness", c.thickness);
            is.non_negative("contact.friction", c.friction);
            is.non_negative("contact.kinetic_friction", c.kinetic_friction);
            if c.kinetic_friction > c.friction {
                is.push(
                    "contact.kinetic_friction",
                    format!(
                        "{} exceeds the static friction {}",
                        c.kinetic_friction, c.friction
                    ),
                );
            }
            if !(0.0..=1.0).contains(&c.restitution) {
                is.push(
                    "contact.restitution",
                    format!("must be in [0, 1], got {:?}", c.restitution),
                );
            }
        }
        // Each particle's first attachment.
        let mut attached = std::collections::HashMap::new();
        for (i, a) in self.attachments.iter().enumerate() {
            attached.entry(a.particle).or_insert(i);
        }
        for (i, a) in self.attachments.iter().enumerate() {
            let at = format!("attachments[{i}]");
            if let Some(&j) = attached.get(&a.particle).filter(|&&j| j != i) {
                is.push(
                    format!("{at}.particle"),
                    format!(
                        "{:?} is already attached by attachments[{j}]; a particle follows one body",
                        a.particle
                    ),
                );
            }
            if a.body >= self.bodies.len() {
                is.push(
                    format!("{at}.body"),
                    format!(
                        "body {} does not exist ({} bodies)",
                        a.body,
                        self.bodies.len()
                    ),
                );
            }
            if let Some(p) = a.local {
                is.finite(format!("{at}.local"), p);
            }
            match a.particle {
                ParticleRef::Particle(k) if k >= self.particles.len() => is.push(
                    format!("{at}.particle"),
                    format!(
                        "particle {k} does not exist ({} particles)",
                        self.particles.len()
                    ),
                ),
                ParticleRef::Cloth(c, col, row) => match self.cloths.get(c) {
                    None => is.push(
                        format!("{at}.particle"),
                        format!("cloth {c} does not exist"),
                    ),
                    Some(cl) if col >= cl.resolution.0 || row >= cl.resolution.1 => is.push(
                        format!("{at}.particle"),
                        format!(
                            "({col}, {row}) is outside cloth {c}'s {}×{} grid",
                            cl.resolution.0, cl.resolution.1
                        ),
                    ),
                    Some(_) => {}
                },
                ParticleRef::Mesh(m, v) => {
                    if let Err(e) = self.mesh_particle(m, v) {
                        is.push(format!("{at}.particle"), e);
                    }
                }
                _ => {}
            }
        }
    }
}

/// The integrators' names as messages list them.
fn known_integrators() -> String {
    let known: Vec<_> = Integrator::ALL.iter().map(|i| i.name()).collect();
    known.join(", ")
}
