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

/// The torn sheet: a ball falls through a sheet held at its edges and tears it; the same
/// breaks and bits on 1 and 2 threads; no triangle left has a broken spring as an edge; the
/// books close.
#[test]
fn a_falling_ball_tears_the_sheet_the_same_on_1_and_2_threads() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/torn_sheet.ron");
    let runs: Vec<_> = [1, 2]
        .map(|threads| {
            common::on_threads(threads, || {
                let mut sim = Simulation::load(path).unwrap();
                let triangles = sim.triangles().len();
                let mut tears = Vec::new();
                for _ in 0..90 {
                    sim.step().unwrap();
                    tears.extend_from_slice(sim.torn());
                }
                let left = sim.triangles().to_vec();
                let a = sim.diagnostics().audit;
                assert!(sim.diagnostics().failure.is_none(), "{a:?}");
                (sim.positions().to_vec(), tears, triangles, left, a)
            })
        })
        .into();
    let (x, tears, triangles, left, a) = &runs[0];
    println!(
        "{} springs broke; {} of {triangles} triangles left; torn {:.4e} J, residual {:+.3e} J of {:.3e} J",
        tears.len(),
        left.len(),
        a.torn,
        a.residual,
        a.scale
    );
    assert!(tears.len() > 10, "the ball tears the sheet");
    assert!(left.len() < *triangles);
    for t in tears {
        let (p, q) = (t.a as u32, t.b as u32);
        let edge = |u: u32, v: u32| (u, v) == (p, q) || (u, v) == (q, p);
        assert!(
            !left
                .iter()
                .any(|&[i, j, k]| edge(i, j) || edge(j, k) || edge(k, i)),
            "a triangle left on broken spring {p}–{q}"
        );
    }
    assert!(a.torn > 0.0);
    assert!(a.residual.abs() < 0.05 * a.scale, "{a:?}");
    assert_eq!(x, &runs[1].0, "the same bits on 1 and 2 threads");
    assert_eq!(tears, &runs[1].1);
}

#[test]
fn bad_tearing_is_refused_by_name() {
    for (cloth, message) in [
        (
            "tearing: Some((stretch: 0.0))",
            "cloths[0].tearing: stretch must be finite and > 0, got 0.0",
        ),
        (
            "tearing: Some((stretch: 0.1)), stretch_limit: Some((stretch: 0.2))",
            "cloths[0].tearing: stretch 0.1 must be past the stretch limit's 0.2",
        ),
    ] {
        let text = format!(
            "Scene(dt: 0.01, cloths: [(origin: (0.0, 0.0, 0.0), size: (1.0, 1.0),
              resolution: (4, 4), mass: 1.0, structural: (frequency: 5.0), {cloth})])"
        );
        let e = Scene::parse(&text, "bad.ron").unwrap_err().to_string();
        assert!(e.contains(message), "{e}");
    }
}
