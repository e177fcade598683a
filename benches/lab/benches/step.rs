//! Criterion bench: one substep of each integrator on the 128×128 hanging cloth
//! (16,384 particles, 97,026 springs). Throughput is reported in springs per substep.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use harmonic::glam::DVec3;
use harmonic::internals::buffers::Packed;
use harmonic::internals::integrate::{Integrator, Solver};

fn substep(c: &mut Criterion) {
    let scene = harmonic::internals::hanging_cloth(128);
    let packed = Packed::gather(&scene.build().world).unwrap();
    let mut group = c.benchmark_group("substep/cloth128");
    group.throughput(Throughput::Elements(packed.spring_count() as u64));
    for integrator in [
        Integrator::Harmonic,
        Integrator::SymplecticEuler,
        Integrator::ExplicitEuler,
        Integrator::HarmonicPaper,
    ] {
        let mut p = packed.clone();
        let mut solver = Solver::new(integrator, false, DVec3::new(0.0, -9.81, 0.0));
        solver.prepare(&p, scene.dt).unwrap();
        group.bench_function(integrator.name(), |b| {
            b.iter(|| solver.substep(&mut p, scene.dt).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, substep);
criterion_main!(benches);
