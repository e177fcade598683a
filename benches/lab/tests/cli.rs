//! The `harmonic-lab` binary end to end.

use std::process::Command;

fn harmonic_lab(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_harmonic-lab"))
        .args(args)
        .output()
        .expect("runs")
}

#[test]
fn bench_runs_only_what_is_selected() {
    let dir = std::env::temp_dir().join(format!("harmonic-bench-{}", std::process::id()));
    let out = harmonic_lab(&[
        "bench",
        "--quick",
        "--scenes",
        "chain20",
        "--integrators",
        "symplectic-euler,theta-mg",
        "--steps",
        "1500,3000",
        "--repeats",
        "1",
        "--out",
        dir.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = std::fs::read_to_string(dir.join("bench.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    // Two integrators at two steps, plus any edge the bisection finds between them.
    assert!(rows.len() >= 4, "{csv}");
    for row in &rows {
        assert!(row.starts_with("chain20,"), "{row}");
        assert!(
            row.contains(",symplectic-euler,") || row.contains(",theta-mg,"),
            "{row}"
        );
    }
    for name in ["symplectic-euler", "theta-mg"] {
        for steps in ["1500", "3000"] {
            assert!(
                rows.iter()
                    .any(|r| r.contains(&format!(",{name},{steps},"))),
                "{name} at {steps}: {csv}"
            );
        }
    }
    assert!(
        !stdout.contains("cloth16") && !stdout.contains("rapier"),
        "{stdout}"
    );
    assert!(dir.join("chain20.svg").exists() && !dir.join("cloth16.svg").exists());
    let _ = std::fs::remove_dir_all(&dir);

    let unknown = harmonic_lab(&["bench", "--quick", "--scenes", "cloth128"]);
    assert_eq!(unknown.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&unknown.stderr);
    assert!(
        stderr.contains("--scenes cloth128: the bench's scenes are chain20, cloth16"),
        "{stderr}"
    );
    let zero = harmonic_lab(&["bench", "--steps", "0"]);
    assert_eq!(zero.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&zero.stderr).contains("--steps"));
    let bad = harmonic_lab(&["bench", "--integrators", "leapfrog"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("unknown integrator `leapfrog`"));
}

#[test]
fn throughput_refuses_cloths_it_cannot_time() {
    for (args, needle) in [
        (&["--size", "0"][..], "--size 0"),
        (&["--size", "1"][..], "--size 1"),
        (
            &["--size", "100000"][..],
            "the engine's default particle limit",
        ),
        (&["--size", "2048", "--cloths", "2"][..], "--cloths 2"),
        (&["--repeats", "0"][..], "--repeats 0"),
        (&["--substeps", "0"][..], "--substeps 0"),
    ] {
        let out = harmonic_lab(&[&["throughput"][..], args].concat());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
    }
    let out = harmonic_lab(&["bench", "--repeats", "0"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--repeats 0"));
}

/// The game-cost comparison refuses counts that would run nothing or for hours, by name.
#[test]
fn game_cost_refuses_empty_and_endless_rounds() {
    for (args, needle) in [
        (&["--frames", "0"][..], "--frames 0"),
        (&["--rounds", "0"][..], "--rounds 0"),
        (&["--rounds", "1000"][..], "--rounds: at most 100"),
    ] {
        let out = harmonic_lab(&[&["game-cost"][..], args].concat());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
    }
}

/// Runs the lab, killing it (and failing) after 60 s.
fn timed(args: &[&str]) -> std::process::Output {
    use std::process::Stdio;
    use std::time::{Duration, Instant};
    let mut child = Command::new(env!("CARGO_BIN_EXE_harmonic-lab"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("runs");
    let start = Instant::now();
    while child.try_wait().expect("waits").is_none() {
        if start.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("harmonic-lab {args:?} still running after 60 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().expect("output")
}

#[test]
fn absurd_factors_and_durations_are_refused_not_panicked_on() {
    let dir = std::env::temp_dir().join(format!("harmonic-lab-hostile-{}", std::process::id()));
    let bench = |stiffen: &str| {
        harmonic_lab(&[
            "bench",
            "--quick",
            "--scenes",
            "chain20",
            "--integrators",
            "harmonic",
            "--stiffen",
            stiffen,
            "--out",
            dir.to_str().unwrap(),
        ])
    };
    for (stiffen, needle) in [
        ("1e6", "the RK4 reference would need more than 100000 steps"),
        ("1e308", "stiffness: must be finite"),
    ] {
        let out = bench(stiffen);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "--stiffen {stiffen}: {stderr}");
        assert!(stderr.contains("--stiffen"), "{stderr}");
        assert!(stderr.contains(needle), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
    for seconds in ["NaN", "0", "inf", "-1"] {
        // Killed after 60 s: a hang (the suite over an endless case) fails here.
        let out = timed(&["stability", &format!("--seconds={seconds}")]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "--seconds {seconds}: {stderr}");
        assert!(stderr.contains("--seconds"), "{stderr}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_baseline_holds_its_own_bits_and_names_a_change() {
    let dir = std::env::temp_dir().join(format!("harmonic-baseline-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("baseline.txt");
    let f = file.to_str().unwrap();
    let scenes = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes");
    let baseline = |how: &str| {
        harmonic_lab(&[
            "baseline",
            how,
            f,
            "--scenes",
            scenes,
            "--only",
            "scenes/chain.ron",
        ])
    };
    // One shipped scene: quick, and the same bits run again.
    let write = baseline("--write");
    assert!(
        write.status.success(),
        "{}",
        String::from_utf8_lossy(&write.stderr)
    );
    let check = baseline("--check");
    let stdout = String::from_utf8_lossy(&check.stdout);
    assert!(
        check.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&check.stderr)
    );
    assert!(stdout.contains("1 runs, the same bits"), "{stdout}");
    // One frame's state changed in the record: named, with its frame, and exit 2.
    let text = std::fs::read_to_string(&file).unwrap();
    let states = text.lines().find(|l| l.contains("\tstates\t")).unwrap();
    let hashes: Vec<&str> = states.rsplit('\t').next().unwrap().split(',').collect();
    assert_eq!(hashes.len(), 150);
    let changed = states.replacen(hashes[40], "0000000000000000", 1);
    std::fs::write(&file, text.replace(states, &changed)).unwrap();
    let check = baseline("--check");
    let stdout = String::from_utf8_lossy(&check.stdout);
    assert_eq!(check.status.code(), Some(2));
    assert!(
        stdout.contains("scenes/chain.ron: states differ first at frame 40"),
        "{stdout}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
