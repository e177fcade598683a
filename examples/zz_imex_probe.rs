use harmonic::buffers::Packed;
use harmonic::integrate::Integrator;
use harmonic::stability::*;
fn main() {
    let zero_g = |mut s: harmonic::scene::Scene| {
        s.gravity = [0.0; 3];
        s
    };
    for z in [0.0, 0.2, 1.0, 2.0] {
        let systems = vec![
            ("pair", pair(1.0, z, false, Start::Equilibrium).0),
            ("chain20", zero_g(chain(20, z, Start::Rest).0)),
            ("cloth8", zero_g(cloth(8, z))),
            ("cloth16", zero_g(cloth(16, z))),
        ];
        for (name, sc) in systems {
            let p = Packed::gather(&sc.build().world).unwrap();
            let se = threshold(&p, Integrator::SymplecticEuler, false, 4.0);
            let im = threshold(&p, Integrator::Imex, false, 4.0);
            let gs = threshold(&p, Integrator::HarmonicGs, false, 4.0);
            println!("zeta {z} {name}: SE {se:?} imex {im:?} gs {gs:?}");
        }
    }
}
