//! The research integrators conserve momentum to round-off without gravity or pins, as the
//! engine's do (tests/conservation.rs), on random networks with springs in all three damping
//! regimes (`harmonic-paper`: ζ < 0.7, where its printed equations are defined).

use harmonic::glam::DVec3;
use harmonic::internals::buffers::Packed;
use harmonic::internals::metrics;
use harmonic::Scene;
use harmonic_lab::research::{Method, Stepper};

/// splitmix64, seeded: the same networks on every run.
struct Rng(u64);
impl Rng {
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        let u = ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * u
    }
}

fn random_network(rng: &mut Rng, method: Method) -> Packed {
    let n = 24;
    let mut particles = String::new();
    for _ in 0..n {
        let mut r = || rng.range(-1.0, 1.0);
        let (x, y, z, u, v, w) = (r(), r(), r(), r(), r(), r());
        let m = rng.range(0.1, 10.0);
        particles += &format!("(position: ({x}, {y}, {z}), velocity: ({u}, {v}, {w}), mass: {m}),");
    }
    let mut springs = String::new();
    for k in 0..60 {
        let a = k % n;
        let b = (a + 1 + (rng.range(0.0, 1.0) * (n - 1) as f64) as usize) % n;
        let zeta = if method == Method::HARMONIC_PAPER {
            rng.range(0.0, 0.6)
        } else {
            [0.1, 1.0, 3.0][k % 3]
        };
        let f = rng.range(0.5, 3.0);
        springs += &format!("(a: {a}, b: {b}, frequency: {f}, damping_ratio: {zeta}),");
    }
    let text = format!(
        "Scene(dt: 0.002, gravity: (0.0, 0.0, 0.0), particles: [{particles}], springs: [{springs}])"
    );
    let scene = Scene::parse(&text, "random").unwrap();
    Packed::gather(&scene.build().world).unwrap()
}

#[test]
fn research_integrators_conserve_momentum_to_round_off() {
    let mut rng = Rng(0x5eed);
    for method in Method::ALL.into_iter().filter(|m| m.engine().is_none()) {
        let mut p = random_network(&mut rng, method);
        let p0 = metrics::momentum(&p);
        let scale: f64 = (0..p.particle_count())
            .map(|i| p.mass(i) * p.v[i].length())
            .sum();
        let mut stepper = Stepper::new(method, false, DVec3::ZERO);
        for _ in 0..300 {
            stepper.substep(&mut p, 0.002).unwrap();
        }
        let drift = (metrics::momentum(&p) - p0).length() / scale;
        println!("{method}: momentum drift {drift:.2e} of Σ m|v|");
        assert!(drift < 1e-12, "{method}: momentum drifted by {drift:e}");
    }
}
