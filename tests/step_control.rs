//! Automatic step control: the network frequency estimate against a closed form, and every
//! hard case bounded at its default settings although its dt is 8.0625 h_c.

mod common;

use harmonic::internals::step_control;
use harmonic::internals::Packed;
use harmonic::prelude::*;

#[test]
fn network_frequency_matches_the_free_chain_closed_form() {
    // N equal masses in a line, free: ω_k = 2√(κ/m) sin(kπ/(2N)), highest at k = N − 1.
    let (n, k, m) = (10usize, 400.0f64, 0.5f64);
    let particles: String = (0..n)
        .map(|i| format!("(position: ({i}.0, 0.0, 0.0), mass: {m}),"))
        .collect();
    let springs: String = (0..n - 1)
        .map(|i| format!("(a: {i}, b: {}, stiffness: {k}),", i + 1))
        .collect();
    let text = format!(
        "Scene(dt: 0.01, gravity: (0.0, 0.0, 0.0), particles: [{particles}], springs: [{springs}])"
    );
    let scene = Scene::parse(&text, "line").unwrap();
    let p = Packed::gather(&scene.build().world).unwrap();
    let exact =
        2.0 * (k / m).sqrt() * ((n - 1) as f64 * std::f64::consts::PI / (2.0 * n as f64)).sin();
    let est = step_control::network_frequency(&p, 2000);
    println!("ω_max: estimate {est}, exact {exact}");
    assert!((est / exact - 1.0).abs() < 1e-3, "{est} vs {exact}");
}

#[test]
fn aliasing_is_flagged_near_whole_multiples_of_h_c() {
    let scene = Scene::load("scenes/paper_fig3_integer_multiple.ron").unwrap();
    let p = Packed::gather(&scene.build().world).unwrap();
    // κ = π², μ = 1: h_c = 1 s.
    assert_eq!(step_control::aliasing(&p, 2.0, 0.02).map(|a| a.0), Some(0));
    assert_eq!(step_control::aliasing(&p, 3.01, 0.02).map(|a| a.0), Some(0));
    assert_eq!(step_control::aliasing(&p, 2.5, 0.02), None);
    assert_eq!(step_control::aliasing(&p, 0.3, 0.02), None);
}

#[test]
fn unconditionally_stable_integrators_take_one_substep() {
    let mut scene = Scene::load("scenes/hard/chain20_z0_rest.ron").unwrap();
    scene.integrator = Some("implicit-euler".into());
    assert_eq!(Simulation::from_scene(&scene).unwrap().config().substeps, 1);
    scene.integrator = Some("symplectic-euler".into());
    assert!(Simulation::from_scene(&scene).unwrap().config().substeps > 8);
}

#[test]
fn every_hard_case_stays_bounded_with_default_settings() {
    for (path, max_strain, substeps) in common::hard_cases_max_strain(None) {
        let scene = Scene::load(&path).unwrap();
        assert!(
            Simulation::from_scene(&scene)
                .unwrap()
                .step_choice()
                .is_some(),
            "{}: hard cases leave substeps to the controller",
            path.display()
        );
        assert!(
            max_strain < 0.5,
            "{}: max strain {max_strain}",
            path.display()
        );
        println!(
            "{}: {substeps} substeps, max strain {max_strain:.4}",
            path.display()
        );
    }
}

#[test]
fn a_large_grid_seen_through_its_window_gives_the_whole_cloths_frequency() {
    // 160×160: the estimate on the grid kept whole sees a 64×64 window; the same springs one
    // by one give the whole network to the power iteration.
    let scene = harmonic::internals::hanging_cloth(160);
    let world = scene.build().world;
    let whole = Packed::gather(&world).unwrap();
    let grid = Packed::gather_with(
        &world,
        harmonic::internals::buffers::GatherOptions {
            keep_grids: true,
            colouring: false,
        },
    )
    .unwrap();
    assert!(whole.topology.grids.is_empty() && grid.topology.grids.len() == 1);
    let (w, g) = (
        step_control::network_frequency(&whole, 300),
        step_control::network_frequency(&grid, 300),
    );
    println!("ω_max: whole cloth {w}, window {g}");
    assert!((g / w - 1.0).abs() < 0.02, "window {g} vs whole {w}");
    // And the controller makes the same choice from either.
    let (a, b) = (
        step_control::choose(&whole, Integrator::SymplecticEuler, 1.0 / 60.0),
        step_control::choose(&grid, Integrator::SymplecticEuler, 1.0 / 60.0),
    );
    assert!(
        a.substeps.abs_diff(b.substeps) <= a.substeps / 50 + 1,
        "{a:?} vs {b:?}"
    );
}
