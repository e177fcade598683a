//! Cloth from a triangle mesh: welding, masses by area, a spring per edge and across each
//! interior edge, pins, located errors and warnings, and the cloth's motion against physics
//! and against the grid cloth.

use harmonic::prelude::*;
use harmonic::scene::mesh::{MeshCloth, MeshPin};

mod common;

/// A scene with `mesh` (RON) as its one mesh and `extra` fields before it.
fn scene(mesh: &str, extra: &str) -> Result<Scene, harmonic::SceneError> {
    Scene::parse(
        &format!("Scene(dt: 0.01, {extra} meshes: [{mesh}])"),
        "mesh.ron",
    )
}

/// An n×n grid of `size` m in the x–z plane at height `y`, each cell split along one diagonal.
fn grid_mesh(n: u32, size: f64, y: f64) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let d = size / f64::from(n - 1);
    let vertices = (0..n)
        .flat_map(|r| (0..n).map(move |c| [f64::from(c) * d, y, f64::from(r) * d]))
        .collect();
    (vertices, common::grid_triangles(n, n))
}

fn mesh_ron(vertices: &[[f64; 3]], triangles: &[[u32; 3]], rest: &str) -> String {
    let v: Vec<String> = vertices
        .iter()
        .map(|p| format!("({}, {}, {})", p[0], p[1], p[2]))
        .collect();
    format!(
        "(vertices: [{}], triangles: [{}], {rest})",
        v.join(", "),
        common::ron_triangles(triangles)
    )
}

#[test]
fn a_split_seam_welds_and_the_masses_sum_to_the_total() {
    // A unit square of two triangles whose shared diagonal is split: six vertices, four places.
    let text = "(vertices: [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 0), (1, 0, 1), (0, 0, 1)],
                 triangles: [(0, 1, 2), (3, 4, 5)], mass: 1.2,
                 stretch: (stiffness: 100.0), bend: (stiffness: 1.0))";
    let scene = scene(text, "").unwrap();
    let t = scene.meshes[0].topology("meshes[0]");
    assert_eq!(t.positions.len(), 4, "{t:?}");
    assert_eq!(t.particle_of[3], t.particle_of[0]);
    assert_eq!(t.particle_of[4], t.particle_of[2]);
    let total: f64 = t.masses.iter().sum();
    assert!((total - 1.2).abs() < 1e-12, "{total}");
    // Each triangle's third to each corner: the diagonal's ends have two triangles.
    let (corner, diagonal) = (1.2 / 6.0, 1.2 / 3.0);
    for (i, m) in t.masses.iter().enumerate() {
        let want = if i == 0 || i == 2 { diagonal } else { corner };
        assert!((m - want).abs() < 1e-12, "particle {i}: {m}");
    }
    // Four sides and the diagonal; one interior edge, so one bend between the other corners.
    assert_eq!(t.edges.len(), 5);
    assert_eq!(t.bends, vec![[1, 3]]);
    let built = scene.build();
    let sim = Simulation::new(built.world, built.config).unwrap();
    assert_eq!(sim.positions().len(), 4);
    assert_eq!(sim.packed().springs.len(), 6);
    assert!(t.warnings.is_empty(), "{:?}", t.warnings);
}

#[test]
fn a_grid_mesh_has_a_spring_per_edge_and_a_bend_per_interior_edge() {
    let n = 7u32;
    let (v, t) = grid_mesh(n, 1.0, 0.0);
    let text = mesh_ron(
        &v,
        &t,
        "density: 0.2, stretch: (frequency: 20.0), bend: (frequency: 5.0)",
    );
    let scene = scene(&text, "").unwrap();
    let topo = scene.meshes[0].topology("meshes[0]");
    let cells = u64::from((n - 1) * (n - 1));
    let edges = 2 * u64::from(n * (n - 1)) + cells;
    let boundary = 4 * u64::from(n - 1);
    assert_eq!(topo.edges.len() as u64, edges);
    assert_eq!(topo.bends.len() as u64, edges - boundary);
    // Density times area: 0.2 kg/m² over 1 m².
    let total: f64 = topo.masses.iter().sum();
    assert!((total - 0.2).abs() < 1e-12, "{total}");
    // One material: every stretch spring has the stiffness of 20 Hz at the mean mass.
    let built = scene.build();
    let sim = Simulation::new(built.world, built.config).unwrap();
    let m = 0.2 / f64::from(n * n);
    let k = 0.5 * m * (2.0 * std::f64::consts::PI * 20.0_f64).powi(2);
    let stretch = sim
        .packed()
        .springs
        .iter()
        .filter(|s| (s.stiffness - k).abs() < 1e-9 * k);
    assert_eq!(stretch.count() as u64, edges);
    assert!(scene.spring_count() >= edges + edges - boundary);
}

#[test]
fn pins_by_vertex_and_by_region_hold_what_they_name() {
    let (v, t) = grid_mesh(5, 1.0, 2.0);
    let pins =
        "pins: [Vertices([24]), Above((0, 0, -1), -0.01), Box((0.4, 2.9, 0.4), (0.6, 3.1, 0.6))]";
    let rest = format!(
        "mass: 1.0, stretch: (stiffness: 50.0), transform: (translation: (0, 1, 0)), {pins}"
    );
    let scene = scene(&mesh_ron(&v, &t, &rest), "").unwrap();
    let topo = scene.meshes[0].topology("meshes[0]");
    // Placed at y = 3: the row at z = 0 (five vertices), vertex 24, and the box around the
    // centre vertex (12).
    let held: Vec<usize> = (0..topo.pinned.len()).filter(|&i| topo.pinned[i]).collect();
    assert_eq!(held, vec![0, 1, 2, 3, 4, 12, 24]);
    // A region the placed mesh misses is refused.
    let missed = rest.replace(
        "(0.4, 2.9, 0.4), (0.6, 3.1, 0.6)",
        "(0.4, 1.9, 0.4), (0.6, 2.1, 0.6)",
    );
    let err = self::scene(&mesh_ron(&v, &t, &missed), "")
        .unwrap_err()
        .to_string();
    assert!(err.contains("meshes[0].pins[2]: holds no vertex"), "{err}");
    assert_eq!(topo.positions[0].y, 3.0);
    assert!(MeshPin::Above([0.0, 1.0, 0.0], 2.5).holds(topo.positions[7]));
}

#[test]
fn bad_meshes_get_located_errors() {
    let cases = [
        (
            "(vertices: [(0, 0, 0), (1, 0, 0), (0, 1, 0)], triangles: [(0, 1, 3)], mass: 1.0, stretch: (stiffness: 1.0))",
            "meshes[0].triangles[0]",
            "vertex 3 does not exist",
        ),
        (
            "(vertices: [(0, 0, 0)], triangles: [], mass: 1.0, stretch: (stiffness: 1.0))",
            "meshes[0].triangles",
            "at least one triangle",
        ),
        (
            "(vertices: [(0, 0, 0), (1, 0, 0), (2, 0, 0)], triangles: [(0, 1, 2)], mass: 1.0, stretch: (stiffness: 1.0))",
            "meshes[0].triangles",
            "no cloth is left",
        ),
        (
            "(vertices: [(0, 0, 0), (1, 0, 0), (0, 1, 0)], triangles: [(0, 1, 2)], mass: 1.0, density: 2.0, stretch: (stiffness: 1.0))",
            "meshes[0]",
            "not both",
        ),
        (
            "(vertices: [(0, 0, 0), (1, 0, 0), (0, 1, 0)], triangles: [(0, 1, 2)], mass: 1.0, stretch: (stiffness: 1.0), transform: (scale: 0.0))",
            "meshes[0].transform.scale",
            "> 0",
        ),
        (
            "(vertices: [(0, 0, 0), (1, 0, 0), (0, 1, 0)], triangles: [(0, 1, 2)], mass: 1.0, stretch: (stiffness: 1.0), pins: [Vertices([7])])",
            "meshes[0].pins[0]",
            "vertex 7 does not exist",
        ),
        (
            "(vertices: [(0, 0, 0), (1, 0, 0), (0, 1, 0)], triangles: [(0, 1, 2)], mass: 1.0, stretch: (stiffness: 1.0), pins: [Attribute(\"_PIN\", 0.5)])",
            "meshes[0].pins[0]",
            "vertex attributes come from a glTF file",
        ),
        (
            "(vertices: [(0, 0, 0), (1, 0, 0), (0, 1e6, 0)], triangles: [(0, 1, 2)], mass: 1.0, stretch: (stiffness: 1.0))",
            "meshes[0].vertices[2] (placed)",
            "world's bound",
        ),
    ];
    for (text, location, needle) in cases {
        let err = scene(text, "").expect_err(text).to_string();
        assert!(
            err.contains(&format!("{location}: ")) && err.contains(needle),
            "{text}:\n{err}"
        );
    }
}

#[test]
fn dropped_triangles_and_non_manifold_edges_are_warned_by_name() {
    // Triangle 1 repeats a vertex; triangles 2–4 share the edge 0–1 with triangle 0.
    let text = "(vertices: [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (0, -1, 0), (0, 0, -1)],
                 triangles: [(0, 1, 2), (0, 0, 1), (0, 1, 3), (0, 1, 4), (0, 1, 5)], mass: 1.0,
                 stretch: (stiffness: 1.0), bend: (stiffness: 0.1))";
    let scene = scene(text, "").unwrap();
    let warnings = scene.warnings();
    let said: Vec<String> = warnings.iter().map(|w| w.to_string()).collect();
    assert!(
        said.iter()
            .any(|w| w.starts_with("meshes[0].triangles[1]: ") && w.contains("dropped")),
        "{said:?}"
    );
    assert!(
        said.iter()
            .any(|w| w.contains("particles 0 and 1") && w.contains("non-manifold")),
        "{said:?}"
    );
    // No bend across the non-manifold edge.
    assert!(scene.meshes[0].topology("m").bends.is_empty());
}

#[test]
fn a_free_mesh_falls_as_its_centre_of_mass_must() {
    // Springs are internal forces: whatever the cloth does, its centre of mass falls as
    // ½ g t², and its momentum is m g t.
    let (mut v, t) = grid_mesh(6, 0.5, 1.0);
    v[7][1] += 0.05; // a wrinkle, so the springs work
    let text = mesh_ron(
        &v,
        &t,
        "mass: 0.3, stretch: (frequency: 15.0, damping_ratio: 0.1), bend: (frequency: 4.0)",
    );
    let extra = "gravity: (0.0, -9.81, 0.0), substeps: 8, integrator: \"symplectic-euler\",";
    let scene = scene(&text, extra).unwrap();
    let built = scene.build();
    let mut sim = Simulation::new(built.world, built.config).unwrap();
    let masses: Vec<f64> = (0..sim.positions().len())
        .map(|i| sim.packed().mass(i))
        .collect();
    let total: f64 = masses.iter().sum();
    let centre = |sim: &Simulation| {
        sim.positions()
            .iter()
            .zip(&masses)
            .map(|(x, m)| *x * *m)
            .sum::<DVec3>()
            / total
    };
    let c0 = centre(&sim);
    let frames = 30;
    for _ in 0..frames {
        sim.step().unwrap();
    }
    let time = 0.01 * f64::from(frames);
    let fall = c0.y - centre(&sim).y;
    // Symplectic Euler's fall over k steps of h: ½ g t² + ½ g h t.
    let h = 0.01 / 8.0;
    let want = 0.5 * 9.81 * time * time + 0.5 * 9.81 * h * time;
    assert!((fall - want).abs() < 1e-9, "fell {fall} m, want {want} m");
    let momentum = harmonic::internals::metrics::momentum(sim.packed());
    assert!(
        (momentum.y + total * 9.81 * time).abs() < 1e-9 * total,
        "{momentum:?}"
    );
}

#[test]
fn a_hanging_mesh_comes_to_rest_holding_its_weight() {
    // A 16×16 mesh of 1 m and 0.2 kg hanging in the x–y plane from its top edge, heavily
    // damped: at rest, the springs into the pinned row carry the free particles' weight; and
    // the grid cloth of the same material (its own springs: both diagonals, second neighbours)
    // hangs to nearly the same shape.
    let n = 16u32;
    let d = 1.0 / f64::from(n - 1);
    let v: Vec<[f64; 3]> = (0..n)
        .flat_map(|r| (0..n).map(move |c| [f64::from(c) * d, 2.0 - f64::from(r) * d, 0.0]))
        .collect();
    let (_, t) = grid_mesh(n, 1.0, 0.0);
    let material = "(frequency: 20.0, damping_ratio: 1.0)";
    let rest = format!(
        "mass: 0.2, stretch: {material}, bend: (frequency: 5.0, damping_ratio: 1.0), \
         pins: [Above((0, 1, 0), 1.999)]"
    );
    let fixed = "substeps: 40, integrator: \"symplectic-euler\",";
    let mesh = scene(&mesh_ron(&v, &t, &rest), fixed).unwrap();
    let grid = Scene::parse(
        &format!(
            "Scene(dt: 0.01, {fixed} cloths: [(origin: (0.0, 2.0, 0.0), size: (1.0, 1.0),
               resolution: (16, 16), mass: 0.2, structural: {material}, shear: {material},
               bend: (frequency: 5.0, damping_ratio: 1.0), pins: [TopEdge])])"
        ),
        "grid",
    )
    .unwrap();
    // The springs' pull on the pinned particles, upward: what holds the cloth.
    let held = |sim: &Simulation| {
        let p = sim.packed();
        let mut held = 0.0;
        for s in &p.springs {
            let (a, b) = (s.a as usize, s.b as usize);
            let (pa, pb) = (p.inv_mass[a] == 0.0, p.inv_mass[b] == 0.0);
            if pa == pb {
                continue;
            }
            let (pin, free) = if pa { (a, b) } else { (b, a) };
            let axis = p.x[free] - p.x[pin];
            let rate = (p.v[free] - p.v[pin]).dot(axis.normalize());
            let pull = s.stiffness * (axis.length() - s.rest) + s.damping * rate;
            held += pull * axis.normalize().dot(DVec3::NEG_Y);
        }
        held
    };
    // Its slow swing averaged out: the mean pull over the last 3 s of 6.
    let settle = |s: &Scene| {
        let mut sim = Simulation::from_scene(s).unwrap();
        let mut sum = 0.0;
        for k in 0..600 {
            sim.step().unwrap();
            if k >= 300 {
                sum += held(&sim);
            }
        }
        (sim, sum / 300.0)
    };
    let (sim, held) = settle(&mesh);
    let p = sim.packed();
    let weight: f64 = (0..p.particle_count())
        .filter(|&i| p.inv_mass[i] != 0.0)
        .map(|i| p.mass(i) * 9.81)
        .sum();
    println!("held {held:.6} N on average against a weight of {weight:.6} N");
    assert!(
        (held / weight - 1.0).abs() < 1e-2,
        "held {held} N, weight {weight} N"
    );
    let (grid, _) = settle(&grid);
    let rms = harmonic::internals::metrics::rms(sim.positions(), grid.positions());
    let sag = 1.0
        - sim
            .positions()
            .iter()
            .map(|x| x.y)
            .fold(f64::INFINITY, f64::min);
    println!(
        "at rest: RMS {rms:.4} m from the grid cloth; the mesh's lowest point {sag:.4} m below 1 m"
    );
    // Different springs (one diagonal, bends across edges), masses by area, and a slow swing
    // not yet damped: 0.050 m measured, against a sag of 0.124 m.
    assert!(
        rms < 0.075,
        "the mesh hangs {rms} m (RMS) from the grid cloth"
    );
}

#[test]
fn the_render_draws_the_mesh_triangles() {
    let (v, t) = grid_mesh(4, 1.0, 0.0);
    let text = mesh_ron(&v, &t, "mass: 1.0, stretch: (stiffness: 10.0)");
    let scene = Scene::parse(
        &format!(
            "Scene(dt: 0.01, particles: [(position: (5, 5, 5), mass: 1.0)], meshes: [{text}])"
        ),
        "m",
    )
    .unwrap();
    let sim = Simulation::from_scene(&scene).unwrap();
    // After the one explicit particle: the mesh's triangles, shifted by one.
    let want: Vec<[u32; 3]> = t.iter().map(|t| t.map(|i| i + 1)).collect();
    assert_eq!(sim.triangles(), &want[..]);
    assert_eq!(scene.build().triangles(), want);
    let _: &MeshCloth = &scene.meshes[0];
}

/// The swallow-tail flag (a mesh: general springs over the CSR lists) on the GPU against the
/// CPU, 30 frames of 24 fixed substeps each (its stability floor is 17): f32 against f64, within `4 ε₃₂ · travel · substeps`
/// (positions on the device are compensated pairs, so rounding is relative to the motion).
#[cfg(feature = "gpu")]
#[test]
fn a_mesh_cloth_on_the_gpu_matches_the_cpu() {
    let Some(_ctx) = common::gpu_or_skip(harmonic::internals::gpu::GpuContext::shared(true)) else {
        return;
    };
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut scene = Scene::load(root.join("scenes/swallowtail_flag.ron")).unwrap();
    scene.substeps = Some(24);
    scene.integrator = Some("symplectic-euler".into());
    let run = |backend: harmonic::Backend| {
        let built = scene.build();
        let config = SimConfig {
            backend,
            ..built.config
        };
        let mut sim = Simulation::new(built.world, config).unwrap();
        let start = sim.packed().x.clone();
        for _ in 0..30 {
            sim.step().unwrap();
        }
        (start, sim.positions().to_vec())
    };
    let (start, cpu) = run(harmonic::Backend::Cpu);
    let (_, gpu) = run(harmonic::Backend::Gpu);
    let travel = (start.iter().zip(&cpu))
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0, f64::max);
    let worst = (cpu.iter().zip(&gpu))
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0, f64::max);
    let tolerance = 4.0 * f64::from(f32::EPSILON) * travel * 720.0;
    println!("max |Δx| {worst:.2e} m, tolerance {tolerance:.2e} m, travel {travel:.3} m");
    assert!(travel.is_finite() && travel > 0.1, "travel {travel}");
    assert!(
        worst <= tolerance,
        "max |Δx| {worst:.2e} m past {tolerance:.2e} m"
    );
}

#[test]
fn an_obj_file_beside_the_scene_is_read_and_its_seam_welded() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let scene = Scene::load(root.join("scenes/round_tablecloth.ron")).unwrap();
    let mesh = &scene.meshes[0];
    // A centre and 12 rings of 48 vertices, each ring's first repeated at 2π; a fan of 48
    // triangles and 11 rings of 48 quads, two triangles each.
    assert_eq!(mesh.vertices.len(), 1 + 12 * 49);
    assert_eq!(mesh.triangles.len(), 48 + 11 * 48 * 2);
    let t = mesh.topology("meshes[0]");
    assert_eq!(t.positions.len(), 1 + 12 * 48, "the seam's copies weld");
    let total: f64 = t.masses.iter().sum();
    assert!((total - 0.4).abs() < 1e-12, "{total}");
    // The disc's area, π r² of its 48-gon: the outer ring's mass share follows the area.
    assert!(t.warnings.is_empty(), "{:?}", t.warnings);
    // Every interior edge has a bend; the rim's 48 edges do not.
    assert_eq!(t.edges.len() - t.bends.len(), 48);
}

#[test]
fn bad_mesh_files_get_located_errors() {
    let dir = std::env::temp_dir().join(format!("harmonic-mesh-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("dir.obj")).unwrap();
    std::fs::write(
        dir.join("broken.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 zz\nf 1 2 3\n",
    )
    .unwrap();
    std::fs::write(dir.join("cloth.stl"), "solid\n").unwrap();
    let cases = [
        ("file: \"missing.obj\"", "missing.obj"),
        (
            "file: \"cloth.stl\"",
            "only Wavefront OBJ (.obj) and glTF 2.0 (.gltf, .glb)",
        ),
        ("file: \"dir.obj\"", "a directory"),
        ("file: \"broken.obj\"", "not a readable OBJ file"),
        (
            "file: \"broken.obj\", vertices: [(0, 0, 0)], triangles: [(0, 0, 0)]",
            "not both",
        ),
    ];
    for (fields, needle) in cases {
        let text =
            format!("Scene(dt: 0.01, meshes: [({fields}, mass: 1.0, stretch: (stiffness: 1.0))])");
        let err = Scene::parse(&text, dir.join("scene.ron"))
            .expect_err(fields)
            .to_string();
        assert!(
            err.contains("meshes[0].file: ") && err.contains(needle),
            "{fields}:\n{err}"
        );
    }
}

#[test]
fn a_mesh_vertex_hangs_on_a_body() {
    // A small square mesh held by one corner at a point of a kinematic body that moves along
    // +x at 0.5 m/s: the corner follows the body; the cloth hangs from it.
    let text = "Scene(dt: 0.01, substeps: 20, integrator: \"symplectic-euler\",
        meshes: [(vertices: [(0, 2, 0), (0.3, 2, 0), (0.3, 1.7, 0), (0, 1.7, 0), (0, 2, 0)],
                  triangles: [(0, 1, 2), (4, 2, 3)], mass: 0.05,
                  stretch: (frequency: 20.0, damping_ratio: 0.5))],
        bodies: [(kind: Kinematic, shape: Ball(radius: 0.05), position: (0, 2.1, 0),
                  velocity: (0.5, 0, 0))],
        attachments: [(particle: Mesh(0, 4), body: 0, local: (0, -0.1, 0))])";
    let scene = Scene::parse(text, "attached.ron").unwrap();
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..50 {
        sim.step().unwrap();
    }
    // Vertex 4 welds into particle 0; after 0.5 s the body is at x = 0.25.
    let corner = sim.positions()[0];
    assert!(
        (corner - DVec3::new(0.25, 2.0, 0.0)).length() < 1e-3,
        "{corner:?}"
    );
    assert!(
        sim.positions()[2].y < 1.75,
        "the cloth hangs from its corner"
    );
    // A vertex that does not exist is a located error.
    let bad = text.replace("Mesh(0, 4)", "Mesh(0, 9)");
    let err = Scene::parse(&bad, "attached.ron").unwrap_err().to_string();
    assert!(
        err.contains("attachments[0].particle: vertex 9 of mesh 0 does not exist"),
        "{err}"
    );
}

#[test]
fn removing_a_cloth_before_a_mesh_keeps_the_mesh_drawn() {
    let (v, t) = grid_mesh(3, 0.5, 3.0);
    let text = format!(
        "Scene(dt: 0.01, cloths: [(origin: (0, 1, 0), size: (1, 1), resolution: (4, 4),
           mass: 0.1, structural: (stiffness: 10.0), pins: [TopEdge])],
         meshes: [{}])",
        mesh_ron(&v, &t, "mass: 0.1, stretch: (stiffness: 10.0)")
    );
    let scene = Scene::parse(&text, "two.ron").unwrap();
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let (id, _) = sim.cloths().next().unwrap();
    sim.remove_cloth(id).unwrap();
    sim.step().unwrap();
    // The cloth's 16 particles are gone: the mesh's are 0..9 and its triangles index them.
    assert_eq!(sim.positions().len(), 9);
    assert_eq!(sim.triangles(), &t[..]);
    assert!((sim.positions()[0].y - 3.0).abs() < 0.01);
}

#[test]
fn a_mesh_is_added_and_removed_at_run_time() {
    let grid = Scene::parse(
        "Scene(dt: 0.01, cloths: [(origin: (0, 1, 0), size: (1, 1), resolution: (4, 4),
           mass: 0.1, structural: (stiffness: 10.0), pins: [TopEdge])])",
        "grid.ron",
    )
    .unwrap();
    let mut sim = Simulation::from_scene(&grid).unwrap();
    let grid_triangles = sim.triangles().to_vec();
    let (v, t) = grid_mesh(3, 0.5, 3.0);
    let text = mesh_ron(
        &v,
        &t,
        "mass: 0.1, stretch: (stiffness: 10.0), pins: [Vertices([0])]",
    );
    let mesh: MeshCloth = scene(&text, "").unwrap().meshes[0].clone();
    let id = sim.add_mesh(&mesh).unwrap();
    sim.step().unwrap();
    // After the grid's 16 particles: the mesh's 9, its triangles shifted by 16.
    assert_eq!(sim.positions().len(), 25);
    let mut want = grid_triangles.clone();
    want.extend(t.iter().map(|t| t.map(|i| i + 16)));
    assert_eq!(sim.triangles(), &want[..]);
    assert_eq!(
        sim.cloths().map(|(_, r)| r).collect::<Vec<_>>(),
        vec![0..16, 16..25]
    );
    assert_eq!(
        sim.positions()[16],
        DVec3::new(0.0, 3.0, 0.0),
        "its pin holds"
    );
    sim.remove_cloth(id).unwrap();
    sim.step().unwrap();
    assert_eq!(sim.positions().len(), 16);
    assert_eq!(sim.triangles(), &grid_triangles[..]);
    // An invalid mesh is refused by name.
    let mut bad = mesh;
    bad.triangles.push([0, 1, 99]);
    let err = sim.add_mesh(&bad).unwrap_err().to_string();
    assert!(
        err.contains("add_mesh") && err.contains("vertex 99 does not exist"),
        "{err}"
    );
}

/// A glTF document of one quad (two triangles, u16 indices, a custom `_PIN` weight of 1 at
/// vertices 0 and 3) on a node translated by `(0, 2, 0)` and scaled by 2, with its buffer at
/// `uri`; and the buffer's bytes.
fn quad_gltf(uri: &str) -> (String, Vec<u8>) {
    let positions: [[f32; 3]; 4] = [
        [0.0, 0.0, 0.0],
        [0.5, 0.0, 0.0],
        [0.5, 0.0, 0.5],
        [0.0, 0.0, 0.5],
    ];
    let indices: [u16; 6] = [0, 1, 2, 0, 2, 3];
    let mut bin: Vec<u8> = positions
        .iter()
        .flatten()
        .flat_map(|c| c.to_le_bytes())
        .collect();
    bin.extend(indices.iter().flat_map(|i| i.to_le_bytes()));
    bin.extend([1.0f32, 0.0, 0.0, 1.0].iter().flat_map(|w| w.to_le_bytes()));
    let uri = if uri.is_empty() {
        String::new()
    } else {
        format!(r#""uri": "{uri}", "#)
    };
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
          "nodes": [{{"mesh": 0, "translation": [0, 2, 0], "scale": [2, 2, 2]}}],
          "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "_PIN": 2}}, "indices": 1}}]}}],
          "buffers": [{{{uri}"byteLength": 76}}],
          "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
                          {{"buffer": 0, "byteOffset": 48, "byteLength": 12}},
                          {{"buffer": 0, "byteOffset": 60, "byteLength": 16}}],
          "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                          "min": [0, 0, 0], "max": [0.5, 0, 0.5]}},
                        {{"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}},
                        {{"bufferView": 2, "componentType": 5126, "count": 4, "type": "SCALAR"}}]}}"#
    );
    (json, bin)
}

/// A `.glb`: the header, the JSON chunk padded with spaces, the binary chunk with zeros.
fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut j = json.as_bytes().to_vec();
    j.resize(j.len().div_ceil(4) * 4, b' ');
    let mut b = bin.to_vec();
    b.resize(b.len().div_ceil(4) * 4, 0);
    let total = 12 + 8 + j.len() + 8 + b.len();
    let mut out = b"glTF".to_vec();
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((j.len() as u32).to_le_bytes());
    out.extend(0x4E4F_534Au32.to_le_bytes());
    out.extend(j);
    out.extend((b.len() as u32).to_le_bytes());
    out.extend(0x004E_4942u32.to_le_bytes());
    out.extend(b);
    out
}

#[test]
fn gltf_files_are_read_and_placed_by_their_node() {
    let dir = std::env::temp_dir().join(format!("harmonic-gltf-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (json, bin) = quad_gltf("quad.bin");
    std::fs::write(dir.join("quad.gltf"), &json).unwrap();
    std::fs::write(dir.join("quad.bin"), &bin).unwrap();
    let (json_glb, _) = quad_gltf("");
    std::fs::write(dir.join("quad.glb"), glb(&json_glb, &bin)).unwrap();
    let (embedded, _) = quad_gltf("data:application/octet-stream;base64,AAAA");
    std::fs::write(dir.join("embedded.gltf"), embedded).unwrap();
    let load_with = |file: &str, pins: &str| {
        let text = format!(
            "Scene(dt: 0.01, meshes: [(file: \"{file}\", mass: 0.1, stretch: (stiffness: 10.0), pins: [{pins}])])"
        );
        Scene::parse(&text, dir.join("scene.ron"))
    };
    let load = |file: &str| load_with(file, "");
    for file in ["quad.gltf", "quad.glb"] {
        let scene = load(file).unwrap_or_else(|e| panic!("{file}: {e}"));
        let m = &scene.meshes[0];
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]], "{file}");
        // The node scales by 2 and lifts by 2.
        assert_eq!(m.vertices[2], [1.0, 2.0, 1.0], "{file}");
        let t = m.topology("m");
        assert!((t.masses.iter().sum::<f64>() - 0.1).abs() < 1e-12);
    }
    // Pins painted as a vertex attribute.
    let scene = load_with("quad.glb", "Attribute(\"_PIN\", 0.5)").unwrap();
    let t = scene.meshes[0].topology("m");
    assert_eq!(t.pinned, vec![true, false, false, true]);
    for (pins, needle) in [
        (
            "Attribute(\"_PIN\", 2.0)",
            "meshes[0].pins[0]: no vertex has _PIN ≥ 2",
        ),
        ("Attribute(\"_WEIGHT\", 0.5)", "meshes[0].file: "),
    ] {
        let err = load_with("quad.glb", pins).unwrap_err().to_string();
        assert!(err.contains(needle), "{pins}: {err}");
    }
    let err = load("embedded.gltf").unwrap_err().to_string();
    assert!(
        err.contains("meshes[0].file: ") && err.contains("embedded (base64) buffer"),
        "{err}"
    );
    std::fs::write(dir.join("broken.glb"), b"glTF not really").unwrap();
    let err = load("broken.glb").unwrap_err().to_string();
    assert!(err.contains("not a readable glTF"), "{err}");
}

#[test]
fn a_meshs_pins_hang_on_the_body_it_names() {
    // A vertical 5×5 mesh whose top edge (y ≥ 1.99) hangs on a kinematic body moving along +x
    // at 0.5 m/s: after 0.5 s each of those vertices is 0.25 m along, in the body's f32 frame.
    let n = 5;
    let d = 0.3 / f64::from(n - 1);
    let vertices: Vec<[f64; 3]> = (0..n)
        .flat_map(|r| (0..n).map(move |c| [f64::from(c) * d, 2.0 - f64::from(r) * d, 0.0]))
        .collect();
    let (_, triangles) = grid_mesh(n, 0.3, 0.0);
    let mesh = mesh_ron(
        &vertices,
        &triangles,
        "mass: 0.05, stretch: (frequency: 20.0, damping_ratio: 0.5), \
         pins: [Above((0.0, 1.0, 0.0), 1.99)], pinned_to: Some(0)",
    );
    let body = "bodies: [(kind: Kinematic, shape: Ball(radius: 0.05), position: (0, 2.2, 0), \
                velocity: (0.5, 0, 0))],";
    let hung = scene(
        &mesh,
        &format!("substeps: 20, integrator: \"symplectic-euler\", {body}"),
    )
    .expect("valid");
    let mut sim = Simulation::from_scene(&hung).unwrap();
    let start = sim.positions().to_vec();
    for _ in 0..50 {
        sim.step().unwrap();
    }
    for (i, (x, x0)) in sim
        .positions()
        .iter()
        .zip(&start)
        .enumerate()
        .take(n as usize)
    {
        let miss = (*x - (*x0 + DVec3::new(0.25, 0.0, 0.0))).length();
        assert!(
            miss < 1e-5,
            "top vertex {i} is {miss:e} m off the body's point"
        );
    }
    assert!(
        sim.positions()[(n * n - 1) as usize].x < start[(n * n - 1) as usize].x + 0.25,
        "the free cloth trails the body"
    );
    // A body that does not exist, or no pins to hang, is a located error.
    let bad = |mesh: &str| {
        scene(mesh, &format!("substeps: 20, {body}"))
            .unwrap_err()
            .to_string()
    };
    let e = bad(&mesh.replace("pinned_to: Some(0)", "pinned_to: Some(3)"));
    assert!(
        e.contains("meshes[0].pinned_to: body 3 does not exist (1 bodies)"),
        "{e}"
    );
    let e = bad(&mesh.replace("pins: [Above((0.0, 1.0, 0.0), 1.99)], ", ""));
    assert!(
        e.contains("meshes[0].pinned_to: the mesh has no pins"),
        "{e}"
    );
}

#[test]
fn the_shipped_skirt_welds_its_seam_shut() {
    // 12 rings of 37 vertices, the last of each on the first: 12 × 36 particles, and the band
    // closed (every particle has neighbours on both sides: no boundary column at the seam).
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let scene = Scene::load(root.join("scenes/skirt.ron")).unwrap();
    let built = scene.build();
    let particles = built.world.query::<&Particle>().iter().count();
    assert_eq!(particles, 12 * 36);
    let sim = Simulation::from_scene(&scene).unwrap();
    let springs = sim.packed().all_springs().count();
    // Stretch: 36 per ring (closed) + 36 × 11 down + 36 × 11 diagonals; bends across every
    // interior edge: the edges not on the top or bottom ring.
    let edges = 36 * 12 + 36 * 11 * 2;
    let interior = edges - 2 * 36;
    assert_eq!(springs, edges + interior);
}

/// A vertical n×n grid cloth of 1 m and 1 kg hanging from its top corners, and the same grid as
/// a mesh (vertices row-major from the top, as the cloth numbers its particles).
fn grid_cloth_and_mesh(n: u32) -> (Scene, Scene) {
    let common =
        "dt: 0.004, substeps: 8, integrator: \"symplectic-euler\", gravity: (0.0, -9.81, 0.0)";
    let material = "(frequency: 30.0, damping_ratio: 0.3)";
    let cloth = Scene::parse(
        &format!(
            "Scene({common}, cloths: [(origin: (-0.5, 1.0, 0.0), size: (1.0, 1.0), resolution: ({n}, {n}),
              mass: 1.0, structural: {material}, shear: Some({material}),
              bend: Some((frequency: 3.0, damping_ratio: 0.3)), pins: [TopLeft, TopRight])])"
        ),
        "grid.ron",
    )
    .unwrap();
    let d = 1.0 / f64::from(n - 1);
    let vertices: Vec<[f64; 3]> = (0..n)
        .flat_map(|r| (0..n).map(move |c| [-0.5 + f64::from(c) * d, 1.0 - f64::from(r) * d, 0.0]))
        .collect();
    let (_, triangles) = grid_mesh(n, 1.0, 0.0);
    let mesh = mesh_ron(
        &vertices,
        &triangles,
        &format!(
            "mass: 1.0, stretch: {material}, bend: Some((frequency: 3.0, damping_ratio: 0.3)), \
             pins: [Vertices([0, {}])]",
            n - 1
        ),
    );
    let mesh = Scene::parse(&format!("Scene({common}, meshes: [{mesh}])"), "mesh.ron").unwrap();
    (cloth, mesh)
}

/// Given the grid cloth's exact springs and masses, a mesh laid out as the grid runs the grid
/// cloth's trajectory (its springs stepped as general springs, the grid's by the grid pass) to
/// 1e-9 m (3.5e-16 m measured). With its own springs (one per edge, one across each interior
/// edge) it stays within 25 cm of the grid cloth over 2 s of falling to a 1.08 m sag, 15 cm
/// root-mean-square (20 cm and 14 cm measured): a different spring net, with one diagonal per
/// cell, not two (its free corners shear sideways), bends across edges instead of to the second
/// neighbours, and masses lumped by area.
#[test]
fn a_grid_mesh_runs_the_grid_cloths_trajectory() {
    let n = 12;
    let (cloth, mesh) = grid_cloth_and_mesh(n);
    let mut grid = Simulation::from_scene(&cloth).unwrap();
    let springs: Vec<_> = grid.packed().all_springs().collect();
    let mut built = mesh.build();
    let by_index: std::collections::HashMap<u32, hecs::Entity> = built
        .world
        .query::<(hecs::Entity, &harmonic::SceneIndex)>()
        .iter()
        .map(|(e, i)| (i.0, e))
        .collect();
    let own: Vec<hecs::Entity> = built
        .world
        .query::<(hecs::Entity, &harmonic::Spring)>()
        .iter()
        .map(|(e, _)| e)
        .collect();
    for e in own {
        built.world.despawn(e).unwrap();
    }
    for s in &springs {
        built.world.spawn((harmonic::Spring {
            a: by_index[&s.a],
            b: by_index[&s.b],
            rest_length: s.rest,
            stiffness: s.stiffness,
            damping: s.damping,
        },));
    }
    let m = 1.0 / f64::from(n * n);
    for p in built.world.query_mut::<&mut Particle>() {
        p.mass = m;
    }
    let mut given = Simulation::new(built.world, built.config).unwrap();
    let mut own = Simulation::from_scene(&mesh).unwrap();
    assert_eq!(
        given.positions(),
        grid.positions(),
        "the same particles in the same order"
    );
    let apart = |a: &Simulation, b: &Simulation| -> Vec<f64> {
        (a.positions().iter().zip(b.positions()))
            .map(|(x, y)| (*x - *y).length())
            .collect()
    };
    let (mut exact, mut worst, mut rms) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..500 {
        grid.step().unwrap();
        given.step().unwrap();
        own.step().unwrap();
        exact = apart(&given, &grid).into_iter().fold(exact, f64::max);
        let d = apart(&own, &grid);
        worst = d.iter().copied().fold(worst, f64::max);
        rms = rms.max((d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt());
    }
    let sag = grid
        .positions()
        .iter()
        .map(|x| 1.0 - x.y)
        .fold(0.0, f64::max);
    println!("given the grid's springs: {exact:e} m apart; its own: {worst} m, rms {rms} m (sag {sag} m)");
    assert!(exact < 1e-9, "{exact:e} m from the grid cloth");
    assert!(
        worst < 0.25 && rms < 0.15,
        "{worst} m ({rms} m rms) from the grid cloth"
    );
}
