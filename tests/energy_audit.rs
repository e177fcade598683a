//! The energy audit against closed forms: an exact step books no residual, a damper books its
//! textbook loss, symplectic Euler's residual is the oscillation its invariant predicts, and
//! a cloth resting on a collider books its contacts, not a residual.

mod common;

use common::{pair, stretch, textbook};
use harmonic::prelude::*;

fn run(sim: &mut Simulation, frames: usize) -> Vec<harmonic::EnergyAudit> {
    (0..frames)
        .map(|_| {
            sim.step().unwrap();
            sim.diagnostics().audit
        })
        .collect()
}

#[test]
fn the_exact_step_of_an_undamped_spring_books_round_off() {
    for &ratio in &[0.1, 0.7, 3.3] {
        let (mut sim, _, _) = pair(1.0, 2.0, 0.0, ratio, 0.3, -1.0, true, "harmonic");
        let books = run(&mut sim, 500);
        let scale = books[0].scale;
        let worst = books.iter().map(|b| b.residual.abs()).fold(0.0, f64::max);
        assert!(
            worst < 1e-12 * scale,
            "h/h_c {ratio}: |R| = {worst:e} of {scale:e} J"
        );
        // The plain `x += h v` drift makes an O(ωh) error in the same step.
        let (mut plain, _, _) = pair(1.0, 2.0, 0.0, ratio.min(0.3), 0.3, -1.0, false, "harmonic");
        let books = run(&mut plain, 500);
        let worst = books.iter().map(|b| b.residual.abs()).fold(0.0, f64::max);
        assert!(worst > 1e-6 * scale, "plain drift books {worst:e}");
    }
}

#[test]
fn a_damper_books_the_textbook_loss() {
    // The exact step of one damped spring: its energy follows the textbook to round-off, so
    // the books close on it exactly; the dampers' line, their discrete work over the step's
    // mean rate over each step, is the textbook loss to O((ωh)²) (the midpoint rule).
    for &zeta in &[0.05, 1.0, 4.0] {
        let (ma, mb) = (1.0, 2.0);
        let (d0, v0) = (0.3, -1.0);
        let (mut sim, w0, alpha) = pair(ma, mb, zeta, 0.005, d0, v0, true, "harmonic");
        let mu = ma * mb / (ma + mb);
        let k = mu * w0 * w0;
        let energy = |(d, r): (f64, f64)| 0.5 * mu * r * r + 0.5 * k * d * d;
        let e0 = energy((d0, v0));
        let dt = sim.config().dt;
        for n in 1..=4000 {
            sim.step().unwrap();
            let t = n as f64 * dt;
            let loss = e0 - energy(textbook(w0 * w0, alpha, t, d0, v0));
            let books = sim.diagnostics().audit;
            assert!(
                (books.damping - loss).abs() <= 1e-3 * loss.max(1e-3 * e0),
                "ζ {zeta}, frame {n}: booked {:e}, textbook {loss:e}",
                books.damping
            );
            // What the dampers' line leaves is the residual: together, the textbook's loss.
            assert!(
                (books.damping - books.residual - loss).abs() <= 1e-9 * e0,
                "ζ {zeta}: {books:?}"
            );
        }
    }
}

#[test]
fn symplectic_euler_books_the_oscillation_its_invariant_predicts() {
    // v' = v − hω²x, x' = x + hv' keeps v² + ω²x² − hω²xv exactly, so with μ the reduced mass
    // E_n − E_0 = ½ μ h ω² (x_n v_n − x_0 v_0) in the stretch δ and its rate: bounded by about
    // ωh/2 of E, oscillating at twice the spring's frequency, never drifting.
    let (ma, mb) = (1.0, 2.0);
    let mu = ma * mb / (ma + mb);
    let (mut sim, w0, _) = pair(ma, mb, 0.0, 0.05, 0.3, -1.0, false, "symplectic-euler");
    let h = sim.config().h();
    let (d0, r0) = stretch(&sim);
    let e0 = 0.5 * mu * r0 * r0 + 0.5 * mu * w0 * w0 * d0 * d0;
    let (mut lo, mut hi) = (0.0f64, 0.0f64);
    for _ in 0..2000 {
        sim.step().unwrap();
        let (d, r) = stretch(&sim);
        let predicted = 0.5 * mu * h * w0 * w0 * (d * r - d0 * r0);
        let booked = sim.diagnostics().audit.residual;
        assert!(
            (booked - predicted).abs() < 1e-9 * e0,
            "booked {booked:e}, predicted {predicted:e}"
        );
        (lo, hi) = (lo.min(booked), hi.max(booked));
    }
    let bound = 0.5 * w0 * h * e0;
    // E_n − E_0 swings over a range of ωh·E (less the start's offset), both ways.
    assert!(
        lo < 0.0 && hi > 0.0 && hi - lo > 1.9 * bound && hi - lo < 2.1 * bound,
        "{lo:e}..{hi:e}, ωh/2·E = {bound:e}"
    );
}

#[test]
fn a_stiff_pendulum_under_symplectic_euler_stays_bounded() {
    // A 1 kg bob on a stiff 1 m spring from horizontal: the residual swings with the motion
    // (about ωh/2 of the energy in the spring's own mode, and the pendulum's O(h) part) and
    // the last swings' peaks are no larger than the first ones'.
    let text = r#"Scene(dt: 0.004, substeps: 4, integrator: "symplectic-euler",
        particles: [(position: (0.0, 0.0, 0.0), mass: 1.0, pinned: true),
                    (position: (1.0, 0.0, 0.0), mass: 1.0)],
        springs: [(a: 0, b: 1, stiffness: 1e4, rest_length: 1.0)])"#;
    let mut sim = Simulation::from_scene(&Scene::parse(text, "pendulum").unwrap()).unwrap();
    let books = run(&mut sim, 5000); // 20 s, about ten swings
    let scale = books[0].scale;
    let peak = |b: &[harmonic::EnergyAudit]| b.iter().map(|a| a.residual.abs()).fold(0.0, f64::max);
    let (first, last) = (peak(&books[..1000]), peak(&books[4000..]));
    assert!(first < 0.01 * scale, "{first:e} of {scale:e}");
    assert!(
        last < 1.5 * first,
        "drift: first swings {first:e}, last {last:e}"
    );
    assert!(books.iter().any(|b| b.residual > 0.0) && books.iter().any(|b| b.residual < 0.0));
}

#[test]
fn implicit_euler_books_numerical_damping_as_negative() {
    let (mut sim, _, _) = pair(1.0, 2.0, 0.0, 0.5, 0.3, -1.0, false, "implicit-euler");
    let books = run(&mut sim, 200);
    let last = books.last().unwrap();
    assert!(last.residual < -0.1 * last.scale, "{last:?}");
    assert_eq!(last.damping, 0.0);
}

#[test]
fn a_cloth_resting_on_a_box_books_its_landing_on_the_contacts() {
    // Dropped 0.2 m onto a box: the landing's loss is booked on the contacts (and dampers),
    // and once it rests each substep's push-out books what it restores. What stays in the
    // residual is the step's own error on the held particles, their fall into the box in the
    // substep: −½ m |g|² h² each under symplectic Euler, numerical damping, as MATH.md's
    // audit defines it (the peak residual, what the limit watches, stays near zero).
    let text = r#"Scene(dt: 0.005, substeps: 8,
        cloths: [(origin: (-0.5, 0.5, -0.5), size: (1.0, 1.0), resolution: (12, 12),
                  plane: Horizontal, mass: 0.5, structural: (stiffness: 300.0, damping: 0.05),
                  shear: Some((stiffness: 300.0, damping: 0.05)))],
        bodies: [(kind: Fixed, shape: Cuboid(half_extents: (1.0, 0.3, 1.0)),
                  position: (0.0, 0.0, 0.0))])"#;
    let mut sim = Simulation::from_scene(&Scene::parse(text, "rest").unwrap()).unwrap();
    let books = run(&mut sim, 800);
    let last = books.last().unwrap();
    let fall = 0.5 * 9.81 * 0.2;
    assert!(last.contacts > 0.3 * fall, "{last:?}");
    assert!(last.relative_peak() < 1e-3, "{last:?}");
    let h: f64 = 0.005 / 8.0;
    let per_frame = -8.0 * 0.5 * 0.5 * 9.81f64.powi(2) * h * h;
    let measured = (last.residual - books[399].residual) / 400.0;
    assert!(
        (measured / per_frame - 1.0).abs() < 0.05,
        "at rest the residual moves {measured:e} J per frame, theory {per_frame:e}"
    );
}

#[test]
fn energy_made_past_the_limit_is_a_failure() {
    // The stiff chain of tests/blow_up.rs with the energy limit on: reported by its energy
    // before any spring passes the strain limit.
    let text = r#"Scene(dt: 0.1, substeps: 1, integrator: "explicit-euler",
        ropes: [(start: (0.0, 0.0, 0.0), end: (1.0, 0.0, 0.0), particles: 3, mass: 0.3,
                 spring: (stiffness: 1e6))])"#;
    let mut sim = Simulation::from_scene(&Scene::parse(text, "stiff").unwrap()).unwrap();
    let failure = (0..20)
        .find_map(|_| sim.step().unwrap().failure)
        .expect("reported");
    let harmonic::Failure::Energy {
        frame,
        created,
        scale,
        limit,
        integrator,
        ..
    } = failure
    else {
        panic!("{failure:?}")
    };
    assert!(frame <= 2 && created > limit * scale, "{failure}");
    assert_eq!(integrator, Integrator::ExplicitEuler);
    assert!(failure.to_string().contains("energy limit"), "{failure}");
    // Stepped at automatic substeps the same chain makes none.
    let safe = text
        .replace("substeps: 1, ", "")
        .replace("dt: 0.1", "dt: 0.001");
    let mut sim = Simulation::from_scene(&Scene::parse(&safe, "safe").unwrap()).unwrap();
    for _ in 0..200 {
        assert_eq!(sim.step().unwrap().failure, None);
    }
}

#[test]
fn the_books_are_the_same_on_one_and_two_threads() {
    let text = harmonic::internals::hanging_cloth(72);
    let books = |threads| {
        common::on_threads(threads, || {
            let mut sim = Simulation::from_scene(&text).unwrap();
            run(&mut sim, 5).last().copied().unwrap()
        })
    };
    assert_eq!(books(1), books(2));
}
