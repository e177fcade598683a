//! Huge scenes are refused from their description, before the engine allocates for them, and
//! the limits can be raised.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use harmonic::scene::Limits;
use harmonic::{Scene, SceneError, SimError, Simulation};

/// Tracks the most bytes live at once, per thread: the tests of this file run side by side,
/// and each measures only its own allocations.
struct Peak;
thread_local! {
    static LIVE: Cell<isize> = const { Cell::new(0) };
    static PEAK: Cell<isize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Peak {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let size = layout.size() as isize;
        let _ = LIVE.try_with(|live| {
            live.set(live.get() + size);
            let _ = PEAK.try_with(|peak| peak.set(peak.get().max(live.get())));
        });
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        let _ = LIVE.try_with(|live| live.set(live.get() - layout.size() as isize));
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Peak = Peak;

fn cloth(n: u64) -> String {
    format!(
        "Scene(dt: 0.01, cloths: [(origin: (0.0, 0.0, 0.0), size: (1.0, 1.0), resolution: ({n}, {n}), \
         mass: 1.0, structural: (stiffness: 100.0), shear: Some((stiffness: 10.0)), bend: Some((stiffness: 1.0)))])"
    )
}

fn messages(e: SceneError) -> String {
    e.to_string()
}

#[test]
fn huge_generators_are_refused_before_allocating() {
    for (n, what) in [(1_000_000u64, "particles"), (40_000, "particles")] {
        let text = cloth(n);
        let before = LIVE.with(Cell::get);
        PEAK.with(|p| p.set(before));
        let err = Scene::parse(&text, "huge.ron").unwrap_err();
        let peak = PEAK.with(Cell::get) - before;
        let msg = messages(err);
        assert!(msg.contains(&format!("asks for {} {what}", n * n)), "{msg}");
        assert!(msg.contains("the limit is 4194304"), "{msg}");
        // Parsing and validating the description; the cloth itself would be gigabytes.
        assert!(peak < 1 << 20, "{peak} bytes allocated to refuse it");
    }
    // 10⁹ particles of one rope: refused the same way.
    let rope = "Scene(dt: 0.01, ropes: [(start: (0.0, 0.0, 0.0), end: (1.0, 0.0, 0.0), \
                particles: 1000000000, mass: 1.0, spring: (stiffness: 10.0))])";
    let msg = messages(Scene::parse(rope, "rope.ron").unwrap_err());
    assert!(msg.contains("asks for 1000000000 particles"), "{msg}");
}

#[test]
fn spring_and_substep_limits_are_checked() {
    let tight = Limits {
        max_particles: 1 << 20,
        max_springs: 1000,
        max_substeps: 8,
        ..Limits::DEFAULT
    };
    // 20×20 with shear and bend: 2·19·20 + 2·19² + 2·18·20 = 760 + 722 + 720 springs.
    let msg = messages(Scene::parse_with(&cloth(20), "c.ron", &tight).unwrap_err());
    assert!(
        msg.contains("asks for 2202 springs; the limit is 1000"),
        "{msg}"
    );
    let scene = Scene::parse(&cloth(20), "c.ron").unwrap();
    let sim = Simulation::from_scene(&scene).unwrap();
    assert_eq!(
        sim.packed().spring_count(),
        2202,
        "spring_count matches the build"
    );

    let text =
        "Scene(dt: 0.01, substeps: Some(100), particles: [(position: (0.0, 0.0, 0.0), mass: 1.0)])";
    let msg = messages(Scene::parse_with(text, "s.ron", &tight).unwrap_err());
    assert!(
        msg.contains("substeps: 100 per frame; the limit is 8"),
        "{msg}"
    );
}

#[test]
fn limits_can_be_raised_and_bind_scenes_built_in_code() {
    let text = cloth(100);
    let low = Limits {
        max_particles: 5000,
        ..Limits::DEFAULT
    };
    assert!(Scene::parse_with(&text, "c.ron", &low).is_err());
    let scene = Scene::parse(&text, "c.ron").unwrap();
    // A scene that passed one limit is still checked against the simulation's.
    match Simulation::from_scene_with(&scene, &low) {
        Err(SimError::InvalidScene(issues)) => {
            assert_eq!(issues[0].location, "scene");
            assert!(issues[0].message.contains("asks for 10000 particles"));
        }
        other => panic!("expected InvalidScene, got {:?}", other.map(|_| ())),
    }
    assert_eq!(
        Simulation::from_scene(&scene)
            .unwrap()
            .packed()
            .particle_count(),
        10_000
    );
    // A scene built in code with a bad field gets the file's located error, not a panic.
    let mut bad = scene.clone();
    bad.cloths[0].mass = f64::NAN;
    match Simulation::from_scene(&bad) {
        Err(SimError::InvalidScene(issues)) => assert_eq!(issues[0].location, "cloths[0].mass"),
        other => panic!("expected InvalidScene, got {:?}", other.map(|_| ())),
    }
}
