//! Criterion bench on the 128×128 hanging cloth (16,384 particles, 97,026 springs): one
//! substep of each integrator (throughput in springs per substep), and one 60 Hz frame with
//! the run-time edits a game makes (a drag, a pin set and freed) beside the same edits made
//! as a World change, which re-gathers everything.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use harmonic::glam::DVec3;
use harmonic::internals::buffers::Packed;
use harmonic::Integrator;
use harmonic_lab::research::{Method, Stepper};

fn substep(c: &mut Criterion) {
    let scene = harmonic::internals::hanging_cloth(128);
    let packed = Packed::gather(&scene.build().world).unwrap();
    let mut group = c.benchmark_group("substep/cloth128");
    group.throughput(Throughput::Elements(packed.spring_count() as u64));
    for integrator in [
        Method::Engine(Integrator::Harmonic),
        Method::Engine(Integrator::SymplecticEuler),
        Method::Engine(Integrator::ExplicitEuler),
        Method::HARMONIC_PAPER,
    ] {
        let mut p = packed.clone();
        let mut solver = Stepper::new(integrator, false, DVec3::new(0.0, -9.81, 0.0));
        solver.prepare(&p, scene.dt).unwrap();
        group.bench_function(integrator.name(), |b| {
            b.iter(|| solver.substep(&mut p, scene.dt).unwrap())
        });
    }
    // The per-frame strain check beside them, on the grid form the default integrator steps.
    let grid = harmonic::internals::buffers::Packed::gather_with(
        &scene.build().world,
        harmonic::internals::buffers::GatherOptions {
            keep_grids: true,
            colouring: false,
        },
    )
    .unwrap();
    group.bench_function("strain check (one per frame)", |b| {
        b.iter(|| harmonic::internals::metrics::beyond(&grid, 10.0))
    });
    group.bench_function("stretch (Diagnostics)", |b| {
        b.iter(|| harmonic::internals::metrics::stretch(&grid))
    });
    group.finish();
}

fn edits(c: &mut Criterion) {
    use harmonic::Simulation;
    let scene = harmonic::internals::hanging_cloth(128);
    let mut group = c.benchmark_group("frame/cloth128");
    group.sample_size(10);
    // A drag of a few millimetres about the particle's start, as a hand moves it per frame.
    let x0 = Simulation::from_scene(&scene).unwrap().positions()[8000];
    let at =
        |f: u64| x0 + 0.005 * DVec3::new((f as f64 * 0.05).sin(), 0.0, (f as f64 * 0.05).cos());
    type Edit = fn(&mut Simulation, u64, DVec3);
    let cases: [(&str, Edit); 4] = [
        ("no edit", |_, _, _| {}),
        ("drag (grab)", |sim, _, at| sim.grab(8000, at).unwrap()),
        ("drag (World change)", |sim, _, at| {
            let e = sim.particle_entity(8000).unwrap();
            let world = sim.world_mut();
            let _ = world.insert_one(e, harmonic::Pin);
            let mut p = world.get::<&mut harmonic::Particle>(e).unwrap();
            p.position = at;
            p.velocity = DVec3::ZERO;
        }),
        ("pin set or freed", |sim, f, _| {
            if f % 2 == 0 {
                sim.pin(8000).unwrap();
            } else {
                sim.unpin(8000).unwrap();
            }
        }),
    ];
    for (name, edit) in cases {
        let mut sim = Simulation::from_scene(&scene).unwrap();
        sim.step().unwrap();
        let mut f = 0u64;
        group.bench_function(name, |b| {
            b.iter(|| {
                f += 1;
                edit(&mut sim, f, at(f));
                sim.step().unwrap();
            })
        });
    }
    group.finish();
}

criterion_group!(benches, substep, edits);
criterion_main!(benches);
