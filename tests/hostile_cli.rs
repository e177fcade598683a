//! The `harmonic` binary given what a hostile user would give it: every such run ends quickly
//! with exit 2 and a message naming the flag or entry, never a hang, a flood of files, an
//! overwritten input or a success.

use std::path::PathBuf;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Runs the binary, killing it (and failing) after 60 s: a hang is a failure, not a stall.
fn harmonic(args: &[&str]) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_harmonic"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("runs");
    let start = Instant::now();
    while child.try_wait().expect("waits").is_none() {
        if start.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("harmonic {args:?} still running after 60 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().expect("output")
}

/// Asserts exit 2 with every needle in stderr.
fn refused(args: &[&str], needles: &[&str]) {
    let out = harmonic(args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
    for n in needles {
        assert!(
            stderr.contains(n),
            "{args:?}: stderr lacks {n:?}:\n{stderr}"
        );
    }
    assert!(stderr.len() < 1000, "{args:?}: a long message:\n{stderr}");
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("harmonic-hostile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn scene_file(name: &str, text: &str) -> PathBuf {
    let path = temp(name);
    std::fs::write(&path, text).unwrap();
    path
}

const CHAIN: &str = "scenes/chain.ron";

#[test]
fn a_run_time_that_is_not_positive_is_refused() {
    for t in ["NaN", "-1", "0"] {
        refused(
            &["run", CHAIN, &format!("--seconds={t}")],
            &["--seconds", "finite and > 0"],
        );
    }
    refused(&["run", CHAIN, "--steps", "0"], &["--steps 0"]);
    refused(&["run", CHAIN, "--dt=-1"], &["time step"]);
}

#[test]
fn unbounded_runs_are_refused_before_they_start() {
    refused(
        &["run", CHAIN, "--seconds=inf"],
        &["--seconds", "finite and > 0"],
    );
    refused(
        &["run", CHAIN, "--dt=1e-300"],
        &["3e300 frames", "the limit is 1000000", "--max-frames"],
    );
    refused(
        &["run", CHAIN, "--steps", "1000001"],
        &["--steps", "--max-frames"],
    );
    let tiny = scene_file(
        "tiny_dt.ron",
        &std::fs::read_to_string(CHAIN)
            .unwrap()
            .replace("dt: 0.001", "dt: 1e-12"),
    );
    refused(
        &["run", tiny.to_str().unwrap()],
        &["seconds", "3000000000000.0 frames"],
    );
    let long = scene_file(
        "long.ron",
        &std::fs::read_to_string(CHAIN)
            .unwrap()
            .replace("seconds: 3.0", "seconds: 1e300"),
    );
    refused(
        &["run", long.to_str().unwrap()],
        &["seconds", "1e303 frames"],
    );
    // The flag is held to the same limit as a scene's substeps.
    refused(
        &["run", CHAIN, "--substeps", "1000000000"],
        &["--substeps 1000000000", "--max-substeps"],
    );
    refused(&["run", CHAIN, "--substeps", "0"], &["--substeps 0"]);
    // Raised limits run.
    let out = harmonic(&["run", CHAIN, "--steps", "3", "--max-frames", "3"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_run_off_a_terminal_prints_plain_progress_lines() {
    let out = harmonic(&["run", CHAIN, "--steps", "40"]);
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("progress:"))
        .collect();
    assert_eq!(lines.len(), 10, "{stderr}");
    assert!(
        lines[0].starts_with("progress: frame 4 of 40 (10 %)"),
        "{stderr}"
    );
    assert!(
        lines[9].starts_with("progress: frame 40 of 40 (100 %)"),
        "{stderr}"
    );
}

#[test]
fn the_trajectory_never_overwrites_the_scene() {
    let text = std::fs::read_to_string(CHAIN).unwrap();
    let scene = scene_file("mine.ron", &text);
    let s = scene.to_str().unwrap();
    refused(
        &["run", s, "--steps", "2", "--trajectory", s],
        &["--trajectory", "the scene being run"],
    );
    assert_eq!(
        std::fs::read_to_string(&scene).unwrap(),
        text,
        "the scene was written over"
    );
}

#[cfg(feature = "gpu")]
#[test]
fn render_refuses_absurd_pictures_before_drawing() {
    // Checked before an adapter is asked for: these need no GPU.
    refused(
        &[
            "render",
            CHAIN,
            "--frames",
            "4294967295",
            "--seconds",
            "0.01",
        ],
        &["--frames 4294967295", "1 to 10 pictures"],
    );
    for scale in ["0", "-1", "NaN"] {
        refused(
            &["render", CHAIN, &format!("--strain-scale={scale}")],
            &["--strain-scale", "finite and > 0"],
        );
    }
    for size in ["0x0", "800x0", "100000x10", "big"] {
        refused(
            &["render", CHAIN, "--size", size],
            &["--size", "from 1 to 8192"],
        );
    }
    refused(
        &["render", CHAIN, "--seconds=NaN"],
        &["--seconds", "finite and > 0"],
    );
}
