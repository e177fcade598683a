//! Every shipped scene loads and runs; every bad scene gives its expected, located error.

use std::path::{Path, PathBuf};

use harmonic::{Scene, Simulation};

fn ron_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(ron_files(&path));
        } else if path.extension().is_some_and(|e| e == "ron") {
            out.push(path);
        }
    }
    out.sort();
    out
}

#[test]
fn every_shipped_scene_loads_and_steps() {
    let files = ron_files(Path::new("scenes"));
    assert!(
        files.len() >= 8,
        "expected the shipped scenes, found {files:?}"
    );
    for path in files {
        let mut sim = Simulation::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        for _ in 0..5 {
            // A scene that demonstrates a blow-up quarantines what went non-finite.
            if let Err(e) = sim.step() {
                panic!("{}: {e}", path.display());
            }
        }
        assert!(
            sim.positions().iter().all(|x| x.is_finite()),
            "{}: World holds non-finite state",
            path.display()
        );
    }
}

#[test]
fn bad_scenes_give_their_expected_located_errors() {
    let files = ron_files(Path::new("tests/bad_scenes"));
    assert!(files.len() >= 20);
    for path in files {
        let text = std::fs::read_to_string(&path).unwrap();
        let expect = text
            .lines()
            .next()
            .and_then(|l| l.strip_prefix("// expect: "))
            .unwrap_or_else(|| panic!("{}: first line must be `// expect: …`", path.display()));
        let err = match Scene::load(&path) {
            Ok(_) => panic!(
                "{}: loaded, expected an error containing {expect:?}",
                path.display()
            ),
            Err(e) => e.to_string(),
        };
        println!("{err}");
        assert!(
            err.contains(expect),
            "{}: error {err:?} does not contain {expect:?}",
            path.display()
        );
        assert!(
            err.starts_with(&path.display().to_string()),
            "error must name the file: {err}"
        );
    }
}

/// Every shipped mesh scene runs a second with its energy booked: the steps make no energy
/// beyond 1 % of the scene's scale (the audit's peak residual) and no failure is reported.
#[test]
fn every_mesh_scene_runs_a_second_with_its_energy_booked() {
    let mut meshes = 0;
    for path in ron_files(Path::new("scenes")) {
        let scene = harmonic::Scene::load(&path).unwrap();
        if scene.meshes.is_empty() {
            continue;
        }
        meshes += 1;
        let mut sim = Simulation::from_scene(&scene).unwrap();
        let frames = (1.0 / scene.dt).round() as usize;
        for _ in 0..frames {
            sim.step().unwrap();
        }
        let d = sim.diagnostics();
        println!(
            "{}: peak residual {:.2e} of the scale, residual {:.2e}",
            path.display(),
            d.audit.relative_peak(),
            d.audit.relative_residual()
        );
        assert!(d.failure.is_none(), "{}: {:?}", path.display(), d.failure);
        assert!(
            d.audit.relative_peak() <= 0.01,
            "{}: {:?}",
            path.display(),
            d.audit
        );
    }
    assert!(meshes >= 4, "the cape, skirt, flag and tablecloth");
}
