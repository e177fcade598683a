//! The `harmonic` binary given what a hostile user would give it: every such run ends quickly
//! with exit 2 and a message naming the flag or entry, never a hang, a flood of files, an
//! overwritten input or a success.

use std::path::PathBuf;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Runs the binary, killing it (and failing) after 60 s: a hang is a failure, not a stall.
fn harmonic(args: &[&str]) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_harmonic"));
    command.args(args).stdout(Stdio::piped());
    within_a_minute(command, args)
}

/// Runs `command` with its stderr piped, killing it (and failing) after 60 s.
fn within_a_minute(mut command: Command, args: &[&str]) -> Output {
    let mut child = command.stderr(Stdio::piped()).spawn().expect("runs");
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

/// Runs the binary under a 4 GiB address-space limit (a run that would take more fails here
/// instead of taking the machine down), with its stdout sent to `stdout`.
fn capped(args: &[&str], stdout: Stdio) -> Output {
    let mut command = Command::new("sh");
    command
        .arg("-c")
        .arg("ulimit -v 4194304; exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_harmonic"))
        .args(args)
        .stdout(stdout);
    within_a_minute(command, args)
}

#[test]
fn a_reader_that_stops_reading_ends_the_run_quietly() {
    use std::io::{BufRead, BufReader};
    let mut child = Command::new(env!("CARGO_BIN_EXE_harmonic"))
        .args(["run", CHAIN])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("runs");
    // `| head -1`: one line, then the pipe closes.
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(first.starts_with("scene: "), "{first}");
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!stderr.contains("error"), "{stderr}");
    // The shell's status for a broken pipe: not a success, not a crash (101).
    assert_eq!(out.status.code(), Some(141), "{stderr}");
}

#[test]
fn a_full_disk_on_stdout_is_an_error_message() {
    let full = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .unwrap();
    for args in [&["check", CHAIN][..], &["run", CHAIN, "--steps", "2"]] {
        let out = capped(args, Stdio::from(full.try_clone().unwrap()));
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(
            stderr.contains("writing to standard output") && stderr.contains("No space left"),
            "{args:?}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

#[test]
fn endless_and_special_files_are_refused_by_name() {
    let fifo = temp("fifo.ron");
    let _ = std::fs::remove_file(&fifo);
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let dir = temp("a_folder.ron");
    std::fs::create_dir_all(&dir).unwrap();
    for (path, what) in [
        ("/dev/zero", "a device, pipe or socket"),
        ("/dev/urandom", "a device, pipe or socket"),
        (fifo.to_str().unwrap(), "a device, pipe or socket"),
        (dir.to_str().unwrap(), "a directory"),
    ] {
        let out = capped(&["check", path], Stdio::piped());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{path}: {stderr}");
        assert!(
            stderr.contains(&format!("{path}: not a regular file but {what}")),
            "{path}: {stderr}"
        );
    }
}

#[test]
fn a_scene_larger_than_the_read_limit_is_refused_unread() {
    let big = temp("big.ron");
    let f = std::fs::File::create(&big).unwrap();
    // Sparse: no disk used.
    f.set_len(harmonic::scene::MAX_FILE_BYTES + 1).unwrap();
    drop(f);
    let out = capped(&["check", big.to_str().unwrap()], Stdio::piped());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("larger than 268435456 bytes"), "{stderr}");
    let _ = std::fs::remove_file(&big);
}

#[test]
fn the_trajectory_never_overwrites_the_scene_through_a_hard_link() {
    let text = std::fs::read_to_string(CHAIN).unwrap();
    let scene = scene_file("linked.ron", &text);
    let link = temp("hard_link.ron");
    let _ = std::fs::remove_file(&link);
    std::fs::hard_link(&scene, &link).unwrap();
    refused(
        &[
            "run",
            scene.to_str().unwrap(),
            "--steps",
            "2",
            "--trajectory",
            link.to_str().unwrap(),
        ],
        &["--trajectory", "the scene being run"],
    );
    assert_eq!(std::fs::read_to_string(&scene).unwrap(), text);
}

#[test]
fn a_blown_up_run_prints_its_magnitudes_with_an_exponent() {
    // A stiff chain under explicit Euler with one substep and both limits off (so the run
    // goes on, as asked): its energy and strain reach about 1e88 %.
    let out = harmonic(&[
        "run",
        CHAIN,
        "--integrator",
        "explicit-euler",
        "--substeps",
        "1",
        "--dt",
        "0.01",
        "--steps",
        "40",
        "--energy-limit",
        "inf",
        "--strain-limit",
        "inf",
    ]);
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(text.contains("e88 %"), "{text}");
    let longest = text
        .split(|c: char| !c.is_ascii_digit())
        .map(str::len)
        .max()
        .unwrap_or(0);
    assert!(longest < 20, "a number of {longest} digits:\n{text}");
}

#[cfg(feature = "gpu")]
#[test]
fn render_refuses_what_it_cannot_write_before_drawing() {
    // Checked before an adapter is asked for: these need no GPU. A 32768² sheet is 4 GiB.
    let out = capped(
        &[
            "render",
            CHAIN,
            "--out",
            temp("sheet").to_str().unwrap(),
            "--size",
            "8192x8192",
            "--seconds",
            "0.02",
            "--frames",
            "16",
            "--sheet",
        ],
        Stdio::piped(),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    for needle in ["--sheet", "32768x32768", "lower --size or --frames"] {
        assert!(stderr.contains(needle), "{stderr}");
    }
    let file = scene_file("not_a_folder", "");
    refused(
        &["render", CHAIN, "--out", file.to_str().unwrap()],
        &["--out", "not a directory"],
    );
    refused(
        &["render", CHAIN, "--strain-scale", "1e308"],
        &["--strain-scale 1e308"],
    );
}

#[cfg(feature = "gpu")]
#[test]
fn a_headless_render_prints_no_window_system_noise() {
    let dir = temp("quiet");
    let out = Command::new(env!("CARGO_BIN_EXE_harmonic"))
        .args([
            "render",
            CHAIN,
            "--out",
            dir.to_str().unwrap(),
            "--size",
            "64x48",
        ])
        .args(["--seconds", "0.01"])
        // A headless machine: no session, so nothing to find a display in.
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("NODEVICE_SELECT")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        assert!(
            std::env::var_os("HARMONIC_REQUIRE_GPU").is_none(),
            "{stderr}"
        );
        assert!(stderr.contains("no GPU adapter"), "{stderr}");
        return;
    }
    assert!(!stderr.contains("XDG_RUNTIME_DIR"), "{stderr}");
    assert!(!stderr.lines().any(|l| l.starts_with("error")), "{stderr}");
}

#[test]
fn a_run_of_days_is_refused_and_a_slow_run_speaks_within_seconds() {
    // Each bound alone admits it: 10⁶ frames, 10⁵ substeps a frame.
    refused(
        &["run", CHAIN, "--steps", "1000000", "--substeps", "100000"],
        &["1.000e11 substeps", "--max-run-substeps"],
    );
    // Raised, the run starts; its first progress line comes within seconds, long before a
    // tenth of it is done.
    use std::io::{BufRead, BufReader};
    let start = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_harmonic"))
        .args(["run", CHAIN, "--steps", "1000000", "--substeps", "20000"])
        .args(["--max-run-substeps", "100000000000"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stderr.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let waited = start.elapsed();
    let _ = child.kill();
    let _ = child.wait();
    assert!(line.starts_with("progress: frame "), "{line}");
    assert!(waited < Duration::from_secs(5), "{waited:?}: {line}");
}

#[test]
fn a_run_shorter_than_one_frame_is_refused() {
    refused(
        &["run", CHAIN, "--seconds", "1e-300"],
        &["--seconds", "shorter than one frame"],
    );
    let long_dt = scene_file(
        "long_dt.ron",
        &std::fs::read_to_string(CHAIN)
            .unwrap()
            .replace("dt: 0.001", "dt: 10.0")
            .replace("seconds: 3.0", "seconds: 1.0"),
    );
    refused(
        &["run", long_dt.to_str().unwrap()],
        &["seconds", "shorter than one frame (dt 10.0 s)"],
    );
}

#[test]
fn check_refuses_what_run_refuses_before_its_first_frame_in_the_same_words() {
    let chain = std::fs::read_to_string(CHAIN).unwrap();
    for (name, text, needle) in [
        (
            "long.ron",
            chain.replace("seconds: 3.0", "seconds: 1e300"),
            "seconds",
        ),
        (
            "tiny.ron",
            chain.replace("dt: 0.001", "dt: 1e-12"),
            "seconds",
        ),
        (
            "work.ron",
            chain
                .replace("substeps: 8", "substeps: 100000")
                .replace("seconds: 3.0", "seconds: 1000.0"),
            "--max-run-substeps",
        ),
    ] {
        let path = scene_file(name, &text);
        let p = path.to_str().unwrap();
        let check = harmonic(&["check", p]);
        let run = harmonic(&["run", p]);
        let (c, r) = (
            String::from_utf8_lossy(&check.stderr),
            String::from_utf8_lossy(&run.stderr),
        );
        assert_eq!(check.status.code(), Some(2), "{name}: {c}");
        assert_eq!(run.status.code(), Some(2), "{name}: {r}");
        assert!(
            c.contains(needle) && r.contains(needle),
            "{name}:\n{c}\n{r}"
        );
        // The same message, from the same code: check's line names the file, run's is the
        // error itself.
        let message = |s: &str| {
            let at = s.find("the scene's seconds").expect("names the entry");
            s[at..].lines().next().unwrap().to_string()
        };
        assert_eq!(message(&c), message(&r), "{name}");
        assert!(c.contains(&format!("{p}: the scene's seconds")), "{c}");
    }
}

#[test]
fn a_scene_naming_a_research_integrator_is_pointed_to_the_lab() {
    let path = scene_file(
        "research.ron",
        "Scene(dt: 0.01, integrator: \"harmonic-sgs\",
           particles: [(position: (0.0, 0.0, 0.0), mass: 0.0), (position: (1.0, 0.0, 0.0), mass: 1.0)],
           springs: [(a: 0, b: 1, stiffness: 100.0)])",
    );
    let path = path.to_str().unwrap();
    for command in ["check", "run"] {
        refused(
            &[command, path],
            &[
                "research.ron",
                "integrator",
                "`harmonic-sgs` is a research variant",
                "harmonic-lab bench --integrators harmonic-sgs",
            ],
        );
    }
}

#[test]
fn the_trajectory_never_overwrites_a_mesh_file_the_scene_reads() {
    let dir = temp("mesh-link");
    std::fs::create_dir_all(&dir).unwrap();
    let obj = dir.join("square.obj");
    let text = "v 0 1 0\nv 1 1 0\nv 1 0 0\nv 0 0 0\nf 1 2 3 4\n";
    std::fs::write(&obj, text).unwrap();
    let scene = dir.join("scene.ron");
    std::fs::write(
        &scene,
        "Scene(dt: 0.01, seconds: 0.02, meshes: [(file: \"square.obj\", mass: 0.1,
           stretch: (frequency: 5.0), pins: [Vertices([0])])])",
    )
    .unwrap();
    let link = dir.join("link.obj");
    let _ = std::fs::remove_file(&link);
    std::fs::hard_link(&obj, &link).unwrap();
    let (scene, link) = (scene.to_str().unwrap(), link.to_str().unwrap());
    refused(
        &["run", scene, "--trajectory", link],
        &["--trajectory", "a mesh file the scene reads"],
    );
    assert_eq!(std::fs::read_to_string(&obj).unwrap(), text);
}
