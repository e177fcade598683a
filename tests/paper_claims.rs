//! The paper's claims about the closed form, checked (MATH note 1). Its printed equations'
//! errors are checked in the lab, which runs `harmonic-paper` (benches/lab/tests/paper_claims.rs).

mod common;
use common::*;

/// Fig. 3: at h = n·h_c an isolated undamped spring's impulse is μ δ̇0 (1 − (−1)ⁿ): zero at
/// even n (the pair drifts on), a reversal of the stretch rate at odd n.
#[test]
fn integer_multiples_of_h_c_give_zero_or_reversing_impulse() {
    for n in 1..=6u32 {
        let (mut sim, _, _) = pair(2.0, 2.0, 0.0, n as f64, 0.0, 1.0, false, "harmonic");
        let (_, v0) = stretch(&sim);
        sim.step().unwrap();
        // Relative velocity along the axis after one step (direction may not flip: δ stays small).
        let v = sim.velocities();
        let rel = (v[1] - v[0]).x;
        let expected = if n % 2 == 0 { v0 } else { -v0 };
        assert!(
            (rel - expected).abs() < 1e-9,
            "n = {n}: relative velocity {rel}, expected {expected}"
        );
    }
}
