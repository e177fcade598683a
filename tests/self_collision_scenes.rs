//! Self-collision over the shipped scenes and a stack on a collider: the triangle pairs that
//! cross at each frame's end, counted by an exact test (`common::crossing`, not the stage's
//! own query), and the thickness between stacked cloths at rest.

use harmonic::prelude::*;

mod common;

/// The most triangle pairs (sharing no corner) crossing at the end of any frame of `scene`
/// over `frames` frames.
fn most_crossing(scene: &Scene, frames: usize) -> usize {
    let mut sim = Simulation::from_scene(scene).unwrap();
    let triangles = sim.triangles().to_vec();
    (0..frames)
        .map(|_| {
            sim.step().unwrap();
            common::crossing::crossing_list(sim.positions(), &triangles).len()
        })
        .max()
        .unwrap_or(0)
}

fn shipped(name: &str) -> Scene {
    let path = common::repo_root().join("scenes").join(name);
    Scene::parse(&std::fs::read_to_string(&path).unwrap(), name).unwrap()
}

/// `scenes/fold_on_bar.ron`: the cloth folds over the bar, its halves swing against each other
/// and fold onto themselves on the floor; over its 3 s no two triangles cross at any frame's
/// end. Without self-collision thousands do.
#[test]
fn the_fold_on_the_bar_never_crosses_itself() {
    let scene = shipped("fold_on_bar.ron");
    let mut bare = scene.clone();
    bare.cloths[0].self_collision = None;
    let (with, without) = (most_crossing(&scene, 180), most_crossing(&bare, 180));
    println!("most crossing pairs at a frame's end: {with} with self-collision, {without} without");
    assert!(
        without > 100,
        "without self-collision the layers cross: {without}"
    );
    assert_eq!(with, 0);
}

/// `scenes/drape_sphere_folds.ron`: the 128×128 drape with self-collision (12 mm). Over its 3 s,
/// at the end of every frame at most 1 % of the triangle pairs that cross there without
/// self-collision cross, and none once it rests (its last frame). Without it hundreds do.
#[test]
fn the_drapes_folds_stack_instead_of_crossing() {
    let scene = shipped("drape_sphere_folds.ron");
    let mut bare = scene.clone();
    bare.cloths[0].self_collision = None;
    let counts = |scene: &Scene| -> Vec<usize> {
        let mut sim = Simulation::from_scene(scene).unwrap();
        let triangles = sim.triangles().to_vec();
        (0..180)
            .map(|_| {
                sim.step().unwrap();
                common::crossing::crossing_list(sim.positions(), &triangles).len()
            })
            .collect()
    };
    let (with, without) = (counts(&scene), counts(&bare));
    let worst = (with.iter().zip(&without))
        .map(|(&w, &b)| w as f64 / b.max(1) as f64)
        .fold(0.0, f64::max);
    println!(
        "most crossing: {} with self-collision, {} without; worst frame {:.2} %; last {}",
        with.iter().max().unwrap(),
        without.iter().max().unwrap(),
        100.0 * worst,
        with[179]
    );
    assert!(*without.iter().max().unwrap() > 300, "{without:?}");
    assert!(
        worst <= 0.01,
        "worst frame {:.2} %: {with:?}",
        100.0 * worst
    );
    assert_eq!(with[179], 0);
}

/// `scenes/cloth_stack.ron`: three cloths dropped onto a box, 19 mm thick; no two triangles
/// sharing no corner, of one cloth or of two, cross at any frame's end. Without
/// self-collision thousands do.
#[test]
fn the_stack_never_crosses_itself_or_another() {
    let scene = shipped("cloth_stack.ron");
    let mut bare = scene.clone();
    for c in &mut bare.cloths {
        c.self_collision = None;
    }
    let (with, without) = (most_crossing(&scene, 180), most_crossing(&bare, 180));
    println!("most crossing pairs at a frame's end: {with} with self-collision, {without} without");
    assert!(
        without > 100,
        "without self-collision the cloths cross: {without}"
    );
    assert_eq!(with, 0);
}

/// The stack with the springs, the search and the pass over the candidates on the GPU
/// (`device_collide_pass`; its colliders are cuboids, so the contacts run there too): no
/// triangles cross at any frame's end, as on the CPU.
#[test]
fn the_stack_never_crosses_on_the_gpu() {
    if common::gpu_or_skip(harmonic::internals::gpu::GpuContext::shared(true)).is_none() {
        return;
    }
    let mut scene = shipped("cloth_stack.ron");
    scene.backend = Some("gpu".into());
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let config = SimConfig {
        device_collide_pass: true,
        ..*sim.config()
    };
    sim.set_config(config).unwrap();
    let triangles = sim.triangles().to_vec();
    let with = (0..180)
        .map(|frame| {
            sim.step().unwrap();
            if frame == 0 {
                let schedule = sim.schedule().to_string();
                assert!(
                    schedule.contains("self-collision (on the GPU)"),
                    "{schedule}"
                );
            }
            common::crossing::crossing_list(sim.positions(), &triangles).len()
        })
        .max()
        .unwrap_or(0);
    println!("gpu: most crossing pairs at a frame's end: {with}");
    assert_eq!(with, 0);
}

/// `scenes/ring_pull.ron`: a tablecloth pulled through a ring bunches into folds pressed
/// through it, edges against edges (`edges: true`), 12 mm thick: no two triangles sharing no
/// corner cross at any frame's end. Without self-collision thousands do.
#[test]
fn the_ring_keeps_folds_apart_edge_against_edge() {
    let scene = shipped("ring_pull.ron");
    assert!(scene.cloths[0].self_collision.unwrap().edges);
    let mut bare = scene.clone();
    bare.cloths[0].self_collision = None;
    let (with, without) = (most_crossing(&scene, 150), most_crossing(&bare, 150));
    println!("most crossing pairs at a frame's end: {with} with self-collision, {without} without");
    assert!(
        without > 100,
        "without self-collision the folds cross: {without}"
    );
    assert_eq!(with, 0);
}

/// Two 12×12 sheets (45 mm spacing, 20 mm thick) dropped onto a box, the upper 10 cm above the
/// lower: the lower comes to rest on the box at the contact thickness, the upper on the lower
/// at the self-collision thickness, within 2.5 % of it (the lower layer, which the box holds,
/// pushes as ten times heavier; pushing as itself, the pair pushes it into the box each
/// substep, the box pushes it back, and the upper one sinks to 0.6 mm under the thickness).
#[test]
fn two_sheets_stack_on_a_box_a_thickness_apart() {
    let sheet = |y: f64| {
        format!(
            "(origin: (-0.25, {y}, -0.25), size: (0.5, 0.5), resolution: (12, 12), mass: 0.1,
              plane: Horizontal, structural: (frequency: 20.0, damping_ratio: 0.3),
              shear: Some((frequency: 20.0, damping_ratio: 0.3)),
              self_collision: Some((thickness: 0.02, friction: 0.5)))"
        )
    };
    let text = format!(
        "Scene(dt: 0.016666666666666666, substeps: 8, integrator: \"symplectic-euler\",
          cloths: [{}, {}],
          bodies: [(kind: Fixed, shape: Cuboid(half_extents: (0.4, 0.1, 0.4)), position: (0.0, -0.1, 0.0))],
          contact: (thickness: 0.005, friction: 0.5, kinetic_friction: 0.4))",
        sheet(0.02),
        sheet(0.12)
    );
    let mut sim = Simulation::from_scene(&Scene::parse(&text, "stack.ron").unwrap()).unwrap();
    for _ in 0..240 {
        sim.step().unwrap();
    }
    let x = sim.positions();
    let band = |r: std::ops::Range<usize>| {
        x[r].iter()
            .map(|p| p.y)
            .fold((f64::MAX, f64::MIN), |(lo, hi), y| (lo.min(y), hi.max(y)))
    };
    let (lower, upper) = (band(0..144), band(144..288));
    let a = sim.diagnostics().audit;
    println!(
        "lower {:.5} .. {:.5} m, upper {:.5} .. {:.5} m (contact 0.005, thickness 0.02); residual {:.3e} J, contacts {:.3e} J",
        lower.0, lower.1, upper.0, upper.1, a.residual, a.contacts
    );
    assert!(
        (lower.0 - 0.005).abs() < 5e-4 && (lower.1 - 0.005).abs() < 5e-4,
        "{lower:?}"
    );
    let gap = (upper.0 - lower.1, upper.1 - lower.0);
    assert!(gap.0 > 0.0195 && gap.1 < 0.0205, "{gap:?}");
    assert!(sim.diagnostics().failure.is_none());
}

/// The fold on the bar after `pre` frames (about 1.5 s), its two halves hanging either side
/// of the bar (the +z one nearly plumb about 1 cm from it, the other slanting away from it 2.5
/// to 13 cm), `edges` on or off: the game moves the +z half's hanging band (12 to 24 cm up) by
/// `dz` along z (through the World), into and through the other half. Returns the crossing
/// pairs apart at rest at the end of each of the `frames` frames after the move.
fn teleport_through(pre: usize, dz: f64, frames: usize, edges: bool) -> Vec<usize> {
    let mut scene = shipped("fold_on_bar.ron");
    if let Some(layer) = scene.cloths[0].self_collision.as_mut() {
        layer.edges = edges;
    }
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let triangles = sim.triangles().to_vec();
    let rest = sim.positions().to_vec();
    for _ in 0..pre {
        sim.step().unwrap();
    }
    let x = sim.positions().to_vec();
    let band: Vec<usize> = (0..x.len())
        .filter(|&i| (0.12..0.24).contains(&x[i].y) && x[i].z > 0.0)
        .collect();
    assert!(band.len() > 100, "{}", band.len());
    for &i in &band {
        let e = sim.particle_entity(i).unwrap();
        sim.world_mut().get::<&mut Particle>(e).unwrap().position.z += dz;
    }
    let apart = 2.0 * 0.008;
    (0..frames)
        .map(|_| {
            sim.step().unwrap();
            let list = common::crossing::crossing_list(sim.positions(), &triangles);
            (list.iter())
                .filter(|&&(a, b)| {
                    common::crossing::apart_at_rest(&rest, triangles[a], triangles[b], apart)
                })
                .count()
        })
        .collect()
}

/// A cloth pushed through itself by the game untangles: the first substep after the move tests
/// each particle's path, and each edge's, from where the stage left them, and those the move
/// carried through the other half go back to their side. Moved 6 cm at four moments of the
/// halves' swing, with `edges`: no two triangles apart along the cloth cross at the end of any
/// of the 10 frames after. Particles against triangles alone leave some locked edge through
/// edge (the stretched triangles at the band's rim cross the other half with no corner
/// passing through a face). Moved further than ten thicknesses, particles are taken as placed
/// there (not swept) and the cloth stays tangled.
#[test]
fn a_cloth_pushed_through_itself_untangles() {
    let starts = [80, 86, 92, 96];
    let swept: Vec<Vec<usize>> = (starts.iter())
        .map(|&pre| teleport_through(pre, -0.06, 10, true))
        .collect();
    println!("moved 6 cm at frames {starts:?}, with edges: crossing pairs apart at rest after each frame {swept:?}");
    assert!(swept.iter().flatten().all(|&c| c == 0));
    let faces: Vec<Vec<usize>> = (starts.iter())
        .map(|&pre| teleport_through(pre, -0.06, 10, false))
        .collect();
    println!("without edges: {faces:?}");
    assert!(
        faces.iter().any(|f| f[9] > 0),
        "particles against triangles alone leave some locked"
    );
    let placed = teleport_through(90, -0.2, 10, false);
    println!("moved 20 cm, past the reach: {placed:?}");
    assert!(
        placed.iter().all(|&c| c > 100),
        "placed, not swept: it stays tangled"
    );
}
