//! Tearing (`tearing:` per cloth): a spring breaks past its stretch, checked against a hanging
//! mass's fall (closed forms before and after the break), the energy the spring held, the
//! triangles left, both back ends, and 1 and 2 threads.

use harmonic::prelude::*;
use harmonic::StageKind;

mod common;

/// A 2×2 cloth pinned along its top edge, structural springs only: two masses of 0.1 kg, each
/// on one vertical spring of `k` = 1.635 N/m (static stretch `m g / k` = 0.6 of its 1 m), joined
/// by an unstretched horizontal spring; released at rest, unstretched.
fn two_masses(backend: &str, tearing: &str) -> Scene {
    Scene::parse(
        &format!(
            "Scene(dt: 0.01, substeps: 20, integrator: \"symplectic-euler\", backend: \"{backend}\",
              cloths: [(origin: (0.0, 0.0, 0.0), size: (1.0, 1.0), resolution: (2, 2), mass: 0.4,
                structural: (stiffness: 1.635), pins: [TopEdge] {tearing})])"
        ),
        "two.ron",
    )
    .unwrap()
}

const K: f64 = 1.635;
const M: f64 = 0.1;
const G: f64 = 9.81;

/// Undamped, each mass swings about 0.6 m below its rest; its spring passes 0.5 of its length
/// at `t = acos(1 − 0.5/0.6)/ω`, and breaks at the end of that frame. Both vertical springs
/// break in the same frame and are reported; the pair then falls freely (its velocity gains
/// `g dt` a frame exactly); the energy booked as torn is what the springs held at the break;
/// the cloth has no triangle left.
fn hanging_masses_tear(backend: &str) -> Option<Vec<harmonic::Tear>> {
    if backend == "gpu"
        && common::gpu_or_skip(harmonic::internals::gpu::GpuContext::shared(true)).is_none()
    {
        return None;
    }
    let mut sim =
        Simulation::from_scene(&two_masses(backend, ", tearing: Some((stretch: 0.5))")).unwrap();
    assert!(sim.schedule().has(StageKind::Tearing), "{}", sim.schedule());
    assert_eq!(sim.triangles().len(), 2);
    let omega = (K / M).sqrt();
    let t_break = (1.0f64 - 0.5 / 0.6).acos() / omega;
    let frame = (t_break / 0.01).ceil() as u64;
    let mut tears = Vec::new();
    let mut at = None;
    for _ in 0..frame + 20 {
        sim.step().unwrap();
        if !sim.torn().is_empty() {
            assert!(at.is_none(), "{backend}: one frame of breaks");
            at = Some(sim.steps() - 1);
            tears = sim.torn().to_vec();
            let a = sim.diagnostics().audit;
            // The springs' energy at the frame's end: ½ k δ² each, δ from the positions.
            let x = sim.positions();
            let held: f64 = [(0, 2), (1, 3)]
                .iter()
                .map(|&(p, q)| 0.5 * K * ((x[q] - x[p]).length() - 1.0).powi(2))
                .sum();
            println!(
                "{backend}: broke in frame {}, held {held:.9} J, booked {:.9} J",
                at.unwrap(),
                a.torn
            );
            assert!((a.torn - held).abs() < 1e-12 * held.max(1.0), "{a:?}");
        }
    }
    println!("{backend}: the springs' stretch passes 0.5 at {t_break:.5} s, in frame {frame}");
    assert_eq!(
        at,
        Some(frame - 1),
        "{backend}: the frame the stretch passed 0.5"
    );
    assert!(
        sim.triangles().is_empty(),
        "{backend}: {:?}",
        sim.triangles()
    );
    // Free fall since: the pair's mean velocity gains g dt a frame.
    let v0 = (sim.velocities()[2] + sim.velocities()[3]).y / 2.0;
    for _ in 0..10 {
        sim.step().unwrap();
    }
    let v1 = (sim.velocities()[2] + sim.velocities()[3]).y / 2.0;
    // The device's f32 velocities: a few ulps of 5 m/s a substep.
    let tol = if backend == "gpu" { 1e-3 } else { 1e-12 };
    assert!(
        (v1 - v0 + 10.0 * 0.01 * G).abs() < tol,
        "{backend}: {v0} → {v1}"
    );
    let a = sim.diagnostics().audit;
    assert!(sim.diagnostics().failure.is_none());
    println!(
        "{backend}: torn {:.6e} J, residual {:+.3e} J",
        a.torn, a.residual
    );
    Some(tears)
}

#[test]
fn hanging_masses_tear_where_their_springs_pass_the_stretch() {
    let cpu = hanging_masses_tear("cpu").unwrap();
    let ends: Vec<(usize, usize)> = cpu.iter().map(|t| (t.a.min(t.b), t.a.max(t.b))).collect();
    assert_eq!(ends, [(0, 2), (1, 3)]);
    if let Some(gpu) = hanging_masses_tear("gpu") {
        assert_eq!(gpu, cpu, "the GPU tears the same springs in the same frame");
    }
}

/// A simulation made from a World (as `harmonic run` makes it, a scene built then handed to
/// `with_props`) lists that World's cloths, so its breaks are reported as a scene's are.
#[test]
fn a_simulation_made_from_a_world_reports_its_breaks() {
    let scene = two_masses("cpu", ", tearing: Some((stretch: 0.5))");
    let built = scene.build();
    let mut sim = Simulation::with_props(built.world, built.config, built.props).unwrap();
    let mut from_scene = Simulation::from_scene(&scene).unwrap();
    assert_eq!(
        sim.cloths().collect::<Vec<_>>(),
        from_scene.cloths().collect::<Vec<_>>()
    );
    let (mut tears, mut want) = (Vec::new(), Vec::new());
    for _ in 0..40 {
        sim.step().unwrap();
        from_scene.step().unwrap();
        tears.extend_from_slice(sim.torn());
        want.extend_from_slice(from_scene.torn());
    }
    assert_eq!(want.len(), 2, "the scene's two springs break");
    assert_eq!(tears, want);
}

/// Below its stretch (the springs swing to 1.2 of their length) a tearable cloth runs as the cloth that cannot tear (its springs one by
/// one instead of a grid pass: the same sums in another order).
#[test]
fn a_cloth_short_of_its_stretch_does_not_tear() {
    let mut plain = Simulation::from_scene(&two_masses("cpu", "")).unwrap();
    let mut strong =
        Simulation::from_scene(&two_masses("cpu", ", tearing: Some((stretch: 1.5))")).unwrap();
    for _ in 0..300 {
        plain.step().unwrap();
        strong.step().unwrap();
        assert!(strong.torn().is_empty());
    }
    let apart = (plain.positions().iter().zip(strong.positions()))
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0, f64::max);
    assert!(apart < 1e-12, "{apart}");
    assert_eq!(strong.diagnostics().audit.torn, 0.0);
    assert_eq!(strong.triangles().len(), 2);
}

/// The torn sheet's surface, read from the World: the particles' total mass, and the
/// triangles left that fewer than two springs hold (nothing keeps their corners together).
fn surface(sim: &Simulation) -> (f64, usize) {
    let world = sim.world();
    let mut index = std::collections::HashMap::new();
    let mut mass = 0.0;
    for (e, (i, p)) in world
        .query::<(hecs::Entity, (&harmonic::SceneIndex, &Particle))>()
        .iter()
    {
        index.insert(e, i.0);
        mass += p.mass;
    }
    let sprung: std::collections::HashSet<(u32, u32)> = world
        .query::<&harmonic::Spring>()
        .iter()
        .map(|s| (index[&s.a], index[&s.b]))
        .flat_map(|(a, b)| [(a, b), (b, a)])
        .collect();
    let loose = (sim.triangles().iter())
        .filter(|&&[a, b, c]| {
            let edges = [(a, b), (b, c), (c, a)];
            edges.iter().filter(|e| sprung.contains(e)).count() < 2
        })
        .count();
    (mass, loose)
}

/// Each cloth's records kept per particle cover its particles, new ones included: its
/// collision layer has a rest place for each, and every free particle has tethers (where the
/// cloth has any), every pinned one none.
fn cloth_records_are_whole(sim: &Simulation) {
    let world = sim.world();
    let pinned: std::collections::HashSet<u32> = world
        .query::<(&harmonic::SceneIndex, &harmonic::Pin)>()
        .iter()
        .map(|(i, _)| i.0)
        .collect();
    for (e, s) in world
        .query::<(hecs::Entity, &harmonic::MeshSurface)>()
        .iter()
    {
        if let Ok(l) = world.get::<&harmonic::Layer>(e) {
            assert_eq!(l.rest.len() as u32, s.count, "the layer's rest places");
        }
        if let Ok(t) = world.get::<&harmonic::Tethers>(e) {
            let tied: std::collections::BTreeSet<u32> =
                t.links.iter().map(|l| t.first + l.0).collect();
            let free: std::collections::BTreeSet<u32> = (s.first..s.first + s.count)
                .filter(|i| !pinned.contains(i))
                .collect();
            assert_eq!(tied, free, "the tethered particles are the free ones");
        }
    }
}

/// A ball falls through the torn sheet (`scenes/torn_sheet.ron`) on `backend` and `threads`:
/// at every frame the mass stays the sheet's and every triangle left is held by two springs;
/// where a broken spring was an edge of two triangles, the surface mostly opened there (the
/// two hold different copies of an end). The end positions, the breaks, the triangles left.
#[allow(clippy::type_complexity)]
fn tear_the_sheet(
    backend: &str,
    threads: usize,
    edit: impl Fn(&mut Scene),
) -> (Vec<DVec3>, Vec<harmonic::Tear>, Vec<[u32; 3]>) {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/torn_sheet.ron");
    let mut scene = Scene::load(path).unwrap();
    scene.backend = Some(backend.into());
    edit(&mut scene);
    common::on_threads(threads, || {
        let mut sim = Simulation::from_scene(&scene).unwrap();
        let (triangles, particles) = (sim.triangles().len(), sim.positions().len());
        let (mass, _) = surface(&sim);
        let mut tears = Vec::new();
        for _ in 0..90 {
            sim.step().unwrap();
            tears.extend_from_slice(sim.torn());
            // What a game draws between steps agrees: every corner is a particle it has.
            let n = sim.positions().len() as u32;
            assert!(sim.triangles().iter().flatten().all(|&i| i < n));
            assert_eq!(sim.render(1.0).positions.len(), n as usize);
            let (m, loose) = surface(&sim);
            assert!(
                (m - mass).abs() < 1e-12 * mass,
                "{backend}: mass {mass} → {m}"
            );
            assert_eq!(loose, 0, "{backend}: triangles no spring pair holds");
        }
        cloth_records_are_whole(&sim);
        let left = sim.triangles().to_vec();
        let a = sim.diagnostics().audit;
        assert!(sim.diagnostics().failure.is_none(), "{a:?}");
        let shared = |p: u32, q: u32| {
            let has = |t: &&[u32; 3]| t.contains(&p) && t.contains(&q);
            left.iter().filter(has).count()
        };
        let edges = tears.iter().filter(|t| shared(t.a as u32, t.b as u32) > 0);
        let closed = edges.filter(|t| shared(t.a as u32, t.b as u32) > 1).count();
        let added = sim.positions().len() - particles;
        println!(
            "{backend}, {threads} thread(s): {} springs broke, {closed} of their edges still \
             between two triangles; {} of {triangles} triangles left, {added} particles added; \
             torn {:.4e} J, edits {:+.3e} J, residual {:+.3e} J of {:.3e} J",
            tears.len(),
            left.len(),
            a.torn,
            a.edits,
            a.residual,
            a.scale
        );
        assert!(tears.len() > 10, "{backend}: the ball tears the sheet");
        assert!(added > 0, "{backend}: the surface opened");
        assert!(left.len() < triangles);
        assert!(closed * 10 < tears.len(), "{backend}: {closed}");
        assert!(a.torn > 0.0);
        // The device books no dampers' work (the sheet's ζ = 0.3): its residual holds them.
        if backend == "cpu" {
            assert!(a.residual.abs() < 0.05 * a.scale, "{a:?}");
        }
        (sim.positions().to_vec(), tears, left)
    })
}

/// The torn sheet opens along its tear: the same breaks and bits on 1 and 2 threads; the mass
/// kept, every triangle left held by two springs; the books close.
#[test]
fn a_falling_ball_tears_the_sheet_the_same_on_1_and_2_threads() {
    let one = tear_the_sheet("cpu", 1, |_| ());
    let two = tear_the_sheet("cpu", 2, |_| ());
    assert_eq!(one.0, two.0, "the same bits on 1 and 2 threads");
    assert_eq!(one.1, two.1);
    assert_eq!(one.2, two.2);
}

/// Two torn sheets side by side, each under its own ball: the first one's new particles go
/// after its own and move the second's up, so at every frame each sheet's particles (by its
/// range) keep the sheet's mass, its triangles stay within its range, and each break names
/// two particles of its own sheet that are far apart (past the tearing stretch of a cell).
#[test]
fn two_torn_sheets_keep_their_own_particles() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/torn_sheet.ron");
    let mut scene = Scene::load(path).unwrap();
    let mut second = scene.cloths[0].clone();
    second.origin[0] += 1.5;
    scene.cloths.push(second);
    let mut ball = scene.bodies[0].clone();
    ball.position[0] += 1.5;
    scene.bodies.push(ball);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let mass_of = |sim: &Simulation, r: std::ops::Range<usize>| -> f64 {
        let world = sim.world();
        let mut q = world.query::<(&harmonic::SceneIndex, &Particle)>();
        q.iter()
            .filter(|(i, _)| r.contains(&(i.0 as usize)))
            .map(|(_, p)| p.mass)
            .sum()
    };
    let (mut tears, mut grown) = (0, [0usize; 2]);
    for _ in 0..60 {
        sim.step().unwrap();
        let cloths: Vec<_> = sim.cloths().collect();
        assert_eq!(cloths.len(), 2);
        for (k, (_, r)) in cloths.iter().enumerate() {
            let m = mass_of(&sim, r.clone());
            assert!((m - 0.3).abs() < 1e-12, "sheet {k}: {m} kg in {r:?}");
            grown[k] = r.len() - 1024;
        }
        let x = sim.positions();
        for t in sim.torn() {
            let r = &cloths.iter().find(|c| c.0 == t.cloth).unwrap().1;
            assert!(r.contains(&t.a) && r.contains(&t.b), "{t:?} outside {r:?}");
            // A structural or shear spring of a 1/31 m cell, broken past 1.4 of its length.
            assert!(x[t.a].distance(x[t.b]) > 1.4 / 31.0, "{t:?}");
            tears += 1;
        }
        let world = sim.world();
        for s in world.query::<&harmonic::MeshSurface>().iter() {
            assert!(s.triangles.iter().flatten().all(|&i| i < s.count));
        }
    }
    println!("two sheets: {tears} breaks, {grown:?} particles added");
    assert!(tears > 20 && grown[0] > 0 && grown[1] > 0, "both tear open");
}

/// The same on the GPU: its particles grow as the surface opens, and what holds on the CPU
/// holds there.
#[test]
fn the_sheet_tears_open_on_the_gpu() {
    if common::gpu_or_skip(harmonic::internals::gpu::GpuContext::shared(true)).is_none() {
        return;
    }
    tear_the_sheet("gpu", 2, |_| ());
}

/// A torn sheet with tethers and self-collision: each new particle gets its vertex's tethers
/// and rest place, so the pieces stay tethered and colliding (checked in the run's World).
#[test]
fn a_torn_sheets_copies_keep_their_tethers_and_layer() {
    let (_, tears, _) = tear_the_sheet("cpu", 2, |s| {
        s.cloths[0].tethers = Some(harmonic::TetherSpec {
            slack: 0.6,
            anchors: 1,
        });
        s.cloths[0].self_collision = Some(harmonic::SelfCollision {
            thickness: 0.005,
            friction: 0.5,
            kinetic_friction: 0.4,
            edges: false,
        });
    });
    assert!(!tears.is_empty());
}
