//! Cloth from a triangle mesh: the schema ([`MeshCloth`], a scene's `meshes`), and the cloth a
//! mesh gives ([`MeshCloth::topology`]): its vertices welded by position, so a seam split for
//! UVs or normals never splits the cloth; masses lumped from the triangles' areas; a stretch
//! spring on every edge; a bending spring across every interior edge, between the two
//! vertices opposite it. A spring given by frequency is resolved through one reference mass
//! per mesh (its mean vertex mass), so uneven triangles keep one material.

use std::collections::HashMap;

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

use super::{SpringSpec, V3};
use crate::error::Issue;

fn one() -> f64 {
    1.0
}
fn default_weld() -> f64 {
    1e-6
}

/// A cloth given as a triangle mesh.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MeshCloth {
    /// A file beside the scene (a path relative to the scene file) to read `vertices` and
    /// `triangles` from: Wavefront OBJ (every object, faces triangulated) or glTF 2.0 (`.gltf`
    /// with its `.bin`, or `.glb`: the first mesh, placed by its node); give this or the two.
    #[serde(default)]
    pub file: Option<String>,
    /// Vertex positions in the mesh's own frame (m, before `transform`).
    #[serde(default)]
    pub vertices: Vec<V3>,
    /// Triangles, three indices into `vertices` each.
    #[serde(default)]
    pub triangles: Vec<[u32; 3]>,
    /// Where the mesh goes: scaled, rotated, then translated.
    #[serde(default)]
    pub transform: Transform,
    /// Total mass (kg), lumped to the vertices by triangle area; give this or `density`.
    #[serde(default)]
    pub mass: Option<f64>,
    /// Mass per area (kg/m²) of the placed surface; give this or `mass`.
    #[serde(default)]
    pub density: Option<f64>,
    /// Springs along every edge.
    pub stretch: SpringSpec,
    /// Springs across every interior edge, between the two vertices opposite it.
    #[serde(default)]
    pub bend: Option<SpringSpec>,
    /// Vertices closer than this once placed (m) are one particle; 1e-6 when absent, 0: only
    /// equal positions.
    #[serde(default = "default_weld")]
    pub weld: f64,
    /// The parts held in place.
    #[serde(default)]
    pub pins: Vec<MeshPin>,
    /// The body (index into `bodies`) the pinned vertices hang on: they follow it, attached
    /// where they start, instead of staying where they are (a cape's collar on a character).
    #[serde(default)]
    pub pinned_to: Option<usize>,
    /// Start velocity of every particle (m/s).
    #[serde(default)]
    pub velocity: V3,
    /// Its aerodynamics (`(density, drag, lift)`); none: it feels no air.
    #[serde(default)]
    pub air: Option<crate::Aero>,
    /// Tethers from its pinned or attached particles (`(slack, anchors)`); none: no tethers.
    #[serde(default)]
    pub tethers: Option<crate::TetherSpec>,
    /// Its springs held within `(1 + stretch)` of their rest lengths (`(stretch, passes)`);
    /// none: no limit.
    #[serde(default)]
    pub stretch_limit: Option<crate::StretchLimit>,
    /// Its springs break past a stretch (`(stretch)`); none: it does not tear.
    #[serde(default)]
    pub tearing: Option<crate::Tearing>,
    /// Collision of its particles with each other and other colliding cloths' (`(thickness,
    /// friction)`); none: it passes through itself.
    #[serde(default)]
    pub self_collision: Option<crate::SelfCollision>,
    /// The per-vertex values of the glTF attributes its pins name ([`MeshPin::Attribute`]),
    /// read with its file; not written to a scene.
    #[serde(skip)]
    pub attributes: Vec<(String, Vec<f64>)>,
}

/// Scale, then rotation, then translation.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Transform {
    /// Translation (m).
    #[serde(default)]
    pub translation: V3,
    /// Rotation as axis times angle (rad), as a body's.
    #[serde(default)]
    pub rotation: V3,
    /// Uniform scale, > 0.
    #[serde(default = "one")]
    pub scale: f64,
}

impl Default for Transform {
    fn default() -> Self {
        Transform {
            translation: [0.0; 3],
            rotation: [0.0; 3],
            scale: 1.0,
        }
    }
}

impl Transform {
    /// Where a point of the mesh's own frame goes.
    pub fn apply(&self, p: V3) -> DVec3 {
        let q = DQuat::from_scaled_axis(DVec3::from(self.rotation));
        q * (DVec3::from(p) * self.scale) + DVec3::from(self.translation)
    }
}

/// A pinned part of a mesh cloth. Regions are tested on the placed positions.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub enum MeshPin {
    /// These vertices (indices into `vertices`).
    Vertices(Vec<u32>),
    /// Every vertex with `normal · x ≥ offset`: `Above((0, 1, 0), 1.4)` is "y ≥ 1.4".
    Above(V3, f64),
    /// Every vertex inside the box `(min, max)`.
    Box(V3, V3),
    /// Every vertex whose value of a glTF file's scalar float attribute (a custom one such as
    /// `_PIN`, painted in the modeller) is at least the threshold: `Attribute("_PIN", 0.5)`.
    Attribute(String, f64),
}

impl MeshCloth {
    /// The values of attribute `name` read from its file, one per vertex.
    pub fn attribute(&self, name: &str) -> Option<&[f64]> {
        (self.attributes.iter())
            .find(|(n, _)| n == name)
            .map(|(_, v)| &v[..])
    }
}

/// The cloth a mesh gives: particles in order of first appearance among the vertices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshTopology {
    /// Placed positions (m).
    pub positions: Vec<DVec3>,
    /// Masses (kg), lumped by area.
    pub masses: Vec<f64>,
    /// Held in place.
    pub pinned: Vec<bool>,
    /// Each vertex's particle, `None` for a vertex in no kept triangle.
    pub particle_of: Vec<Option<u32>>,
    /// The triangles kept (indices into the particles): the render's triangles.
    pub triangles: Vec<[u32; 3]>,
    /// The edges, each once (`a < b`): the stretch springs.
    pub edges: Vec<[u32; 2]>,
    /// Each interior edge's two opposite vertices: the bending springs.
    pub bends: Vec<[u32; 2]>,
    /// What was dropped or is suspect, by triangle or edge: not errors.
    pub warnings: Vec<Issue>,
}

impl MeshTopology {
    /// The mean particle mass: the reference mass that turns a frequency into a stiffness.
    pub fn reference_mass(&self) -> f64 {
        self.masses.iter().sum::<f64>() / self.masses.len().max(1) as f64
    }
}

impl MeshCloth {
    /// The cloth this mesh gives (`at` locates its warnings, as `meshes[0]`). Assumes the
    /// indices are in range (as validation checks).
    pub fn topology(&self, at: &str) -> MeshTopology {
        let mut t = MeshTopology::default();
        let placed: Vec<DVec3> = self
            .vertices
            .iter()
            .map(|&v| self.transform.apply(v))
            .collect();
        let welded = weld(&placed, self.weld);
        // Triangles over welded vertices; degenerate ones dropped.
        let mut kept = Vec::with_capacity(self.triangles.len());
        for (k, tri) in self.triangles.iter().enumerate() {
            let w = tri.map(|i| welded[i as usize]);
            let p = w.map(|i| placed[i as usize]);
            let cross = (p[1] - p[0]).cross(p[2] - p[0]).length();
            let longest = [p[1] - p[0], p[2] - p[1], p[0] - p[2]]
                .iter()
                .map(|e| e.length_squared())
                .fold(0.0, f64::max);
            // No area: a repeated vertex, or a cross product at rounding's level (NaN too).
            let flat = cross.is_nan() || cross <= 1e-12 * longest;
            if w[0] == w[1] || w[1] == w[2] || w[0] == w[2] || flat {
                t.warnings.push(Issue {
                    location: format!("{at}.triangles[{k}]"),
                    message: format!("{tri:?} has no area once welded (vertices {w:?}): dropped"),
                });
                continue;
            }
            kept.push(w);
        }
        // Particles: the welded vertices some kept triangle uses, in order.
        let mut used = vec![false; placed.len()];
        for w in &kept {
            for &i in w {
                used[i as usize] = true;
            }
        }
        let mut index = vec![u32::MAX; placed.len()];
        for (i, &u) in used.iter().enumerate() {
            if u {
                index[i] = t.positions.len() as u32;
                t.positions.push(placed[i]);
            }
        }
        let loose = (0..placed.len())
            .filter(|&i| welded[i] as usize == i && !used[i])
            .count();
        if loose > 0 {
            t.warnings.push(Issue {
                location: format!("{at}.vertices"),
                message: format!("{loose} vertex(es) in no triangle: dropped"),
            });
        }
        t.particle_of = welded
            .iter()
            .map(|&w| Some(index[w as usize]).filter(|&i| i != u32::MAX))
            .collect();
        t.triangles = kept.iter().map(|w| w.map(|i| index[i as usize])).collect();
        // Masses by area.
        let mut area = vec![0.0; t.positions.len()];
        for tri in &t.triangles {
            let p = tri.map(|i| t.positions[i as usize]);
            let a = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
            for &i in tri {
                area[i as usize] += a / 3.0;
            }
        }
        let total: f64 = area.iter().sum();
        t.masses = match (self.mass, self.density) {
            (Some(m), _) => area.iter().map(|a| m * a / total).collect(),
            (None, Some(rho)) => area.iter().map(|a| rho * a).collect(),
            (None, None) => vec![0.0; area.len()],
        };
        // Edges, each with the vertex opposite it in each triangle.
        let mut sides: Vec<([u32; 2], u32)> = Vec::with_capacity(3 * t.triangles.len());
        for &[a, b, c] in &t.triangles {
            for (u, v, o) in [(a, b, c), (b, c, a), (c, a, b)] {
                sides.push(([u.min(v), u.max(v)], o));
            }
        }
        sides.sort_unstable();
        let mut k = 0;
        while k < sides.len() {
            let edge = sides[k].0;
            let n = sides[k..].iter().take_while(|s| s.0 == edge).count();
            t.edges.push(edge);
            match n {
                1 => {}
                2 if sides[k].1 != sides[k + 1].1 => {
                    let (o1, o2) = (sides[k].1, sides[k + 1].1);
                    t.bends.push([o1.min(o2), o1.max(o2)]);
                }
                2 => {}
                _ => t.warnings.push(Issue {
                    location: format!("{at}.triangles"),
                    message: format!(
                        "the edge between particles {} and {} has {n} triangles (non-manifold): \
                         no bending spring across it",
                        edge[0], edge[1]
                    ),
                }),
            }
            k += n;
        }
        t.pinned = vec![false; t.positions.len()];
        for pin in &self.pins {
            match pin {
                MeshPin::Vertices(list) => {
                    for &v in list {
                        if let Some(Some(i)) = t.particle_of.get(v as usize) {
                            t.pinned[*i as usize] = true;
                        }
                    }
                }
                MeshPin::Above(..) | MeshPin::Box(..) => {
                    for (i, x) in t.positions.iter().enumerate() {
                        t.pinned[i] |= pin.holds(*x);
                    }
                }
                MeshPin::Attribute(name, least) => {
                    let values = self.attribute(name).unwrap_or(&[]);
                    for (v, _) in values.iter().enumerate().filter(|(_, w)| *w >= least) {
                        if let Some(Some(i)) = t.particle_of.get(v) {
                            t.pinned[*i as usize] = true;
                        }
                    }
                }
            }
        }
        t
    }
}

impl MeshPin {
    /// Whether a region pin holds a particle at `x` (a vertex list holds none by position).
    pub fn holds(&self, x: DVec3) -> bool {
        match self {
            MeshPin::Vertices(_) | MeshPin::Attribute(..) => false,
            MeshPin::Above(n, d) => DVec3::from(*n).dot(x) >= *d,
            MeshPin::Box(lo, hi) => {
                x.cmpge(DVec3::from(*lo)).all() && x.cmple(DVec3::from(*hi)).all()
            }
        }
    }
}

/// Each vertex's representative: the first vertex within `tolerance` of it (itself if none),
/// found through a hash grid of cells `tolerance` wide (exact positions when it is 0).
fn weld(points: &[DVec3], tolerance: f64) -> Vec<u32> {
    let mut out = Vec::with_capacity(points.len());
    let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    let cell = |p: DVec3| -> [i64; 3] {
        if tolerance > 0.0 {
            (p / tolerance).floor().to_array().map(|c| c as i64)
        } else {
            p.to_array().map(|c| c.to_bits() as i64)
        }
    };
    for (i, &p) in points.iter().enumerate() {
        let c = cell(p);
        let reach = if tolerance > 0.0 { 1 } else { 0 };
        let mut found = None;
        'search: for dx in -reach..=reach {
            for dy in -reach..=reach {
                for dz in -reach..=reach {
                    let key = [c[0] + dx, c[1] + dy, c[2] + dz];
                    for &j in cells.get(&key).into_iter().flatten() {
                        if (points[j as usize] - p).length() <= tolerance {
                            found = Some(j);
                            break 'search;
                        }
                    }
                }
            }
        }
        match found {
            Some(j) => out.push(j),
            None => {
                cells.entry(c).or_default().push(i as u32);
                out.push(i as u32);
            }
        }
    }
    out
}

impl MeshCloth {
    /// Its problems, located under `at` (`meshes[0]`): the counts within `limits` first
    /// (nothing is built past them), then the transform, the indices, the mass, the pins, and
    /// the cloth its topology gives (no triangle left, a region holding no vertex, a material
    /// beyond f32 at its reference mass).
    pub(super) fn check(&self, at: &str, limits: &super::Limits, is: &mut super::validate::Issues) {
        let behaviour = super::behaviour::Behaviour {
            air: self.air,
            tethers: self.tethers,
            limit: self.stretch_limit,
            tearing: self.tearing,
            collide: self.self_collision,
            spacing: None,
        };
        is.behaviour(at, behaviour);
        let before = is.0.len();
        let (n, t) = (self.vertices.len(), self.triangles.len());
        if n as u64 > limits.max_particles {
            is.push(
                format!("{at}.vertices"),
                format!(
                    "{n} vertices; the limit is {} (Limits::max_particles, --max-particles)",
                    limits.max_particles
                ),
            );
            return;
        }
        if t == 0 {
            is.push(
                format!("{at}.triangles"),
                "a mesh needs at least one triangle",
            );
        }
        let tr = &self.transform;
        is.point(format!("{at}.transform.translation"), tr.translation);
        is.rotation(format!("{at}.transform.rotation"), tr.rotation);
        is.size(format!("{at}.transform.scale"), tr.scale);
        is.speed(format!("{at}.velocity"), self.velocity);
        if !(self.weld.is_finite() && self.weld >= 0.0) {
            is.push(
                format!("{at}.weld"),
                format!("must be finite and ≥ 0 (m), got {:?}", self.weld),
            );
        }
        if is.0.len() == before {
            for (k, &v) in self.vertices.iter().enumerate() {
                let placed = tr.apply(v).to_array();
                if v.iter().any(|c| !c.is_finite()) {
                    is.finite(format!("{at}.vertices[{k}]"), v);
                } else {
                    is.point(format!("{at}.vertices[{k}] (placed)"), placed);
                }
            }
        }
        for (k, tri) in self.triangles.iter().enumerate() {
            if let Some(&i) = tri.iter().find(|&&i| i as usize >= n) {
                is.push(
                    format!("{at}.triangles[{k}]"),
                    format!("vertex {i} does not exist ({n} vertices)"),
                );
            }
        }
        match (self.mass, self.density) {
            (Some(_), Some(_)) => is.push(at, "give `mass` or `density`, not both"),
            (Some(m), None) => is.positive(format!("{at}.mass"), m),
            (None, Some(d)) => is.positive(format!("{at}.density"), d),
            (None, None) => is.push(at, "needs `mass` (kg) or `density` (kg/m²)"),
        }
        for (j, pin) in self.pins.iter().enumerate() {
            let pat = format!("{at}.pins[{j}]");
            match pin {
                MeshPin::Vertices(list) => {
                    if let Some(&v) = list.iter().find(|&&v| v as usize >= n) {
                        is.push(pat, format!("vertex {v} does not exist ({n} vertices)"));
                    }
                }
                MeshPin::Above(normal, offset) => {
                    is.finite(format!("{pat}.0"), *normal);
                    if !offset.is_finite() || normal.iter().all(|&c| c == 0.0) {
                        is.push(pat, "needs a non-zero normal and a finite offset");
                    }
                }
                MeshPin::Attribute(name, least) => {
                    if self.attribute(name).is_none() {
                        is.push(
                            pat,
                            format!(
                                "no values of {name}: vertex attributes come from a glTF file's \
                                 primitives (`file: \"….glb\"`)"
                            ),
                        );
                    } else if !least.is_finite() {
                        is.push(pat, format!("needs a finite threshold, got {least:?}"));
                    }
                }
                MeshPin::Box(lo, hi) => {
                    is.finite(format!("{pat}.0"), *lo);
                    is.finite(format!("{pat}.1"), *hi);
                    if (0..3).any(|c| lo[c] > hi[c]) {
                        is.push(pat, format!("min {lo:?} exceeds max {hi:?}"));
                    }
                }
            }
        }
        is.spec(&format!("{at}.stretch"), &self.stretch);
        if let Some(b) = &self.bend {
            is.spec(&format!("{at}.bend"), b);
        }
        if is.0.len() > before {
            return;
        }
        // The cloth it gives.
        let topology = self.topology(at);
        if topology.triangles.is_empty() {
            is.push(
                format!("{at}.triangles"),
                "every triangle has no area once welded: no cloth is left",
            );
            return;
        }
        if let Some(c) = self.self_collision.filter(|c| c.check().is_ok()) {
            let p = &topology.positions;
            let edge = |[a, b]: [u32; 2]| (p[b as usize] - p[a as usize]).length();
            let spacing = topology
                .edges
                .iter()
                .map(|&e| edge(e))
                .fold(f64::MAX, f64::min);
            if let Err(e) = c.check_spacing(spacing) {
                is.push(format!("{at}.self_collision"), e);
            }
        }
        for (j, pin) in self.pins.iter().enumerate() {
            if let MeshPin::Attribute(name, least) = pin {
                if !(self.attribute(name).unwrap_or(&[]).iter()).any(|w| w >= least) {
                    is.push(
                        format!("{at}.pins[{j}]"),
                        format!("no vertex has {name} ≥ {least}"),
                    );
                }
                continue;
            }
            if !matches!(pin, MeshPin::Vertices(_))
                && !topology.positions.iter().any(|&x| pin.holds(x))
            {
                is.push(
                    format!("{at}.pins[{j}]"),
                    "holds no vertex of the placed mesh",
                );
            }
        }
        let m = topology.reference_mass();
        is.spec_between(&format!("{at}.stretch"), &self.stretch, m, m);
        if let Some(b) = &self.bend {
            is.spec_between(&format!("{at}.bend"), b, m, m);
        }
    }
}

impl super::Scene {
    /// The scene index of the particle vertex `v` of mesh `m` welds into, or why there is none
    /// (no such mesh or vertex, or a vertex in no triangle).
    pub(super) fn mesh_particle(&self, m: usize, v: u32) -> Result<u32, String> {
        let mesh = (self.meshes.get(m)).ok_or_else(|| format!("mesh {m} does not exist"))?;
        let sound = |x: &MeshCloth| {
            let n = x.vertices.len();
            x.triangles.iter().flatten().all(|&i| (i as usize) < n)
        };
        if (v as usize) >= mesh.vertices.len() || !sound(mesh) {
            return Err(format!(
                "vertex {v} of mesh {m} does not exist ({} vertices)",
                mesh.vertices.len()
            ));
        }
        let before = self.particles_before(m)?;
        let Some(i) = mesh.topology("").particle_of[v as usize] else {
            return Err(format!("vertex {v} of mesh {m} is in no triangle"));
        };
        Ok((before + u64::from(i)) as u32)
    }

    /// The scene index of the particle each vertex of mesh `m` welds into (`None` for a vertex
    /// in no triangle), in one build of its topology: how a game maps its own mesh's vertices
    /// (a skinned pose, say) onto the simulation's particles, as [`crate::Simulation::drive`]
    /// and [`crate::Simulation::positions`] count them. For a scene that passed validation.
    pub fn mesh_particles(&self, m: usize) -> Result<Vec<Option<u32>>, String> {
        let mesh = (self.meshes.get(m)).ok_or_else(|| format!("mesh {m} does not exist"))?;
        let before = self.particles_before(m)?;
        let t = mesh.topology("");
        Ok((t.particle_of.iter())
            .map(|p| p.map(|i| (before + u64::from(i)) as u32))
            .collect())
    }

    /// The particles the scene builds before mesh `m`'s (explicit, cloths, ropes, earlier
    /// meshes), or why they cannot be counted (an earlier mesh with indices out of range).
    fn particles_before(&self, m: usize) -> Result<u64, String> {
        let mut before = self.particles.len() as u64
            + (self.cloths.iter())
                .map(|c| u64::from(c.resolution.0) * u64::from(c.resolution.1))
                .sum::<u64>()
            + (self.ropes.iter())
                .map(|r| u64::from(r.particles))
                .sum::<u64>();
        for earlier in &self.meshes[..m] {
            let n = earlier.vertices.len();
            if !earlier
                .triangles
                .iter()
                .flatten()
                .all(|&i| (i as usize) < n)
            {
                return Err(format!("an earlier mesh than {m} is not sound"));
            }
            before += earlier.topology("").positions.len() as u64;
        }
        Ok(before)
    }

    /// What the meshes' building drops or finds suspect, located (`meshes[0].triangles[4]: … has
    /// no area once welded: dropped`); not errors. For a scene that passed validation.
    pub fn warnings(&self) -> Vec<Issue> {
        (self.meshes.iter().enumerate())
            .flat_map(|(i, m)| m.topology(&format!("meshes[{i}]")).warnings)
            .collect()
    }
}
