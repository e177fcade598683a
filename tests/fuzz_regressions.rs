//! Replays the scene fuzz target (tests/fuzz) on its regression corpus, on every shipped scene
//! and on every bad scene: each must answer with a scene, or a located error, without panicking.

use std::path::Path;

fn replay(dir: &str) -> usize {
    let mut n = 0;
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join(dir);
    let mut paths: Vec<_> = std::fs::read_dir(&root)
        .unwrap_or_else(|e| panic!("{}: {e}", root.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .collect();
    paths.sort();
    for path in paths {
        let data = std::fs::read(&path).unwrap();
        match harmonic::scene::exercise(&data) {
            Ok(d) => {
                assert_eq!(
                    d.non_finite,
                    0,
                    "{}: Ok with a non-finite state",
                    path.display()
                );
                eprintln!("{}: ok, {} quarantined", path.display(), d.quarantined);
            }
            Err(e) => {
                let msg = e.to_string();
                assert!(!msg.trim().is_empty(), "{}: an empty error", path.display());
                eprintln!("{}: {}", path.display(), msg.lines().next().unwrap_or(""));
            }
        }
        n += 1;
    }
    n
}

#[test]
fn fuzz_regression_corpus_replays_without_panic() {
    assert!(replay("tests/fuzz/regressions") > 0);
}

#[test]
fn shipped_and_bad_scenes_replay_without_panic() {
    assert!(replay("scenes") >= 10);
    assert!(replay("tests/bad_scenes") >= 20);
}
