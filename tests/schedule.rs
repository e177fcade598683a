//! The frame as a schedule: the stages a scene runs are listed from the scene (a stage it does
//! not need is not there), timed per kind, and named the same in ARCHITECTURE's "A frame".

use harmonic::prelude::*;
use harmonic::rapier3d::prelude::*;
use harmonic::{Schedule, StageKind};

fn load(name: &str) -> Simulation {
    Simulation::load(format!("{}/scenes/{name}", env!("CARGO_MANIFEST_DIR")))
        .unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn kinds(s: &Schedule) -> Vec<StageKind> {
    s.stages().iter().map(|s| s.kind).collect()
}

const FALLING_CLOTH: &str = r#"Scene(
    dt: 0.004, gravity: (0.0, 0.0, 0.0),
    cloths: [(origin: (-0.3, 0.3, -1.0), size: (0.6, 0.6), resolution: (8, 8), plane: Vertical,
              mass: 0.5, structural: (frequency: 60.0, damping_ratio: 0.2), velocity: (0.0, 0.0, 3.0))],
)"#;

#[test]
fn a_scene_lists_only_the_stages_it_needs() {
    use StageKind::*;
    let mut chain = load("chain.ron");
    assert_eq!(kinds(chain.schedule()), [Gravity, Integrate, Quarantine]);
    assert_eq!(
        chain.schedule().to_string(),
        "gravity → integrate (symplectic-euler, 8 substeps) → quarantine"
    );
    chain.step().expect("steps");
    assert!(!chain.schedule().has(Contacts));

    let drape = load("drape_sphere.ron");
    assert_eq!(
        kinds(drape.schedule()),
        [Gravity, Integrate, Contacts, Quarantine]
    );

    // No gravity: no gravity stage; the caller's sets bring the contact stage with them.
    let scene = Scene::parse(FALLING_CLOTH, "falling cloth").expect("parses");
    let mut sim = Simulation::from_scene(&scene).expect("builds");
    assert_eq!(kinds(sim.schedule()), [Integrate, Quarantine]);
    let mut world = PhysicsWorld::new();
    world.insert(RigidBodyBuilder::fixed(), ColliderBuilder::ball(0.1));
    sim.step_with(&mut world.bodies, &world.colliders)
        .expect("steps");
    assert_eq!(kinds(sim.schedule()), [Integrate, Contacts, Quarantine]);
    // A plain step afterwards does not couple: no contact stage in that frame.
    sim.step().expect("steps");
    assert_eq!(kinds(sim.schedule()), [Integrate, Quarantine]);
    assert!(sim.stats().stages[Contacts].is_zero());
}

/// The list is in frame order: every kind in `StageKind::ALL`'s order, forces before the
/// integrate stage and projections after it, each kind once.
#[test]
fn every_list_keeps_the_frame_order() {
    let scene = Scene::parse(FALLING_CLOTH, "falling cloth").expect("parses");
    let mut lists = vec![
        load("chain.ron"),
        load("drape_sphere.ron"),
        load("cape.ron"),
    ];
    lists.push(Simulation::from_scene(&scene).expect("builds"));
    for sim in &mut lists {
        let n = sim.positions().len();
        sim.set_forces(&vec![DVec3::X; n])
            .expect("one per particle");
        sim.step().expect("steps");
        let order = |k: &StageKind| StageKind::ALL.iter().position(|a| a == k);
        let kinds = kinds(sim.schedule());
        assert!(
            kinds.windows(2).all(|w| order(&w[0]) < order(&w[1])),
            "{kinds:?}"
        );
        assert!(kinds.windows(2).all(|w| w[0].place() <= w[1].place()));
        assert_eq!(
            kinds
                .iter()
                .filter(|k| k.place() == harmonic::Place::Integrate)
                .count(),
            1
        );
    }
}

#[test]
fn the_listing_follows_the_substeps_and_the_settings() {
    let mut sim = load("hanging_cloth.ron");
    for _ in 0..3 {
        sim.step().expect("steps");
        let n = sim.config().substeps;
        let listed = sim.schedule().to_string();
        assert!(
            listed.contains(&format!("({}, {n} substeps)", sim.config().integrator)),
            "{listed} lists other substeps than the next frame's {n}"
        );
    }
    let config = SimConfig {
        gravity: DVec3::ZERO,
        ..*sim.config()
    };
    sim.set_config(config).expect("a sound config");
    assert!(
        !sim.schedule().has(StageKind::Gravity),
        "{}",
        sim.schedule()
    );
}

#[test]
fn each_stage_kind_is_timed_and_the_frame_is_their_sum() {
    let mut sim = load("drape_sphere.ron");
    let s = *sim.step().expect("steps");
    for kind in [StageKind::Integrate, StageKind::Contacts] {
        assert!(!s.stages[kind].is_zero(), "{kind:?} not timed: {s:?}");
    }
    // Fused into the integrate kernel: no time of its own.
    assert!(s.stages[StageKind::Gravity].is_zero());
    let parts = s.gather + s.stages.iter().map(|(_, t)| t).sum::<std::time::Duration>();
    assert!(s.device.is_zero(), "no device on the CPU");
    assert_eq!(s.total(), parts + s.audit_time + s.scatter);
}

#[test]
fn timers_switched_off_read_no_stage_time_and_change_nothing() {
    let (mut timed, mut untimed) = (load("drape_sphere.ron"), load("drape_sphere.ron"));
    untimed.set_timers(false);
    for _ in 0..5 {
        timed.step().expect("steps");
        let s = *untimed.step().expect("steps");
        assert!(
            s.stages.total().is_zero() && s.audit_time.is_zero(),
            "{s:?}"
        );
    }
    assert!(!timed.stats().stages.total().is_zero());
    assert_eq!(timed.positions(), untimed.positions());
    assert_eq!(timed.stats().audit, untimed.stats().audit);
}

/// The stage names in ARCHITECTURE's "A frame" diagram, in order.
fn documented_stages() -> Vec<String> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/src/ARCHITECTURE.md");
    let text = std::fs::read_to_string(path).expect("ARCHITECTURE.md");
    let section = text
        .split("\n## A frame\n")
        .nth(1)
        .and_then(|s| s.split("\n## ").next())
        .expect("a section \"A frame\"");
    section
        .lines()
        .filter_map(|l| {
            let (_, rest) = l.split_once("─ ")?;
            rest.split_whitespace().next().map(str::to_string)
        })
        .collect()
}

#[test]
fn architecture_names_the_stages_the_code_runs() {
    let code: Vec<String> = StageKind::ALL
        .iter()
        .map(|k| k.name().to_string())
        .collect();
    assert_eq!(documented_stages(), code);
}
