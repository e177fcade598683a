//! The `harmonic` binary end to end.

use std::process::Command;

fn harmonic(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_harmonic"))
        .args(args)
        .output()
        .expect("runs")
}

#[test]
fn run_prints_a_summary_and_writes_the_trajectory() {
    let dir = std::env::temp_dir().join(format!("harmonic-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("chain.csv");
    let out = harmonic(&[
        "run",
        "scenes/chain.ron",
        "--steps",
        "20",
        "--every",
        "5",
        "--trajectory",
        csv.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for needle in [
        "21 particles, 20 springs",
        "h/h_c of the stiffest spring",
        "steps: 20 frame(s), 160 substep(s)",
        "max strain",
        "energy: start",
        "non-finite: none",
        "\nschedule: gravity → integrate (symplectic-euler, 8 substeps) → quarantine\n",
    ] {
        assert!(
            stdout.contains(needle),
            "summary lacks {needle:?}:\n{stdout}"
        );
    }
    // Each stage's share of the frame time, the shares summing to 100 %.
    let shares = stdout
        .lines()
        .find_map(|l| l.strip_prefix("frame time: "))
        .and_then(|l| l.split_once(" by stage: "))
        .map(|(_, s)| s)
        .unwrap_or_else(|| panic!("no frame time line:\n{stdout}"));
    let mut total = 0.0;
    for part in shares.split(", ") {
        let (name, share) = part.split_once(' ').expect("name share");
        assert!(
            ["integrate", "quarantine", "audit", "gather", "scatter"].contains(&name),
            "{name} in {shares}"
        );
        total += share
            .trim_end_matches(" %")
            .parse::<f64>()
            .expect("a share");
    }
    assert!((total - 100.0).abs() < 0.1, "{shares}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("step,time,particle,x,y,z,vx,vy,vz"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|f| f.parse().unwrap()).collect())
        .collect();
    // Steps 0, 5, 10, 15, 20, 21 particles each, in scene order.
    assert_eq!(rows.len(), 5 * 21);
    assert_eq!(rows[0][..3], [0.0, 0.0, 0.0]);
    assert_eq!(rows[21][..3], [5.0, 0.005, 0.0]);
    assert_eq!(rows[22][2], 1.0);
    // Particle 0 is the pinned start; particle 20 the free end at x = 1 m.
    assert_eq!(rows[0][3..6], [0.0, 0.0, 0.0]);
    assert!((rows[20][3] - 1.0).abs() < 1e-12);
    // The free end falls.
    assert!(rows[4 * 21 + 20][4] < 0.0);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn run_reports_a_blow_up_with_a_non_zero_exit() {
    // At the paper's one step per frame; by default step control subdivides and it stays bounded.
    let run = |limit: &[&str]| {
        let mut args = vec![
            "run",
            "scenes/paper_fig1_near_rigid.ron",
            "--steps",
            "600",
            "--substeps",
            "1",
        ];
        args.extend(limit);
        harmonic(&args)
    };
    // The strain limit stops it while it is still finite ...
    let out = run(&["--energy-limit", "inf"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("run failed at frame"), "{stderr}");
    assert!(stderr.contains("strain limit"), "{stderr}");
    // ... and without it the state goes non-finite and is quarantined.
    let out = run(&["--strain-limit", "inf", "--energy-limit", "inf"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("went non-finite and were quarantined"),
        "{stderr}"
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("particle(s) quarantined"), "{stdout}");
    let auto = harmonic(&["run", "scenes/paper_fig1_near_rigid.ron", "--steps", "60"]);
    let stdout = String::from_utf8_lossy(&auto.stdout);
    assert!(auto.status.success(), "{stdout}");
    assert!(stdout.contains("substeps: automatic,"), "{stdout}");
}

#[test]
fn overrides_apply() {
    let out = harmonic(&[
        "run",
        "scenes/explicit_pair.ron",
        "--seconds",
        "0.1",
        "--dt",
        "0.002",
        "--substeps",
        "2",
        "--integrator",
        "symplectic-euler",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    assert!(
        stdout.contains("integrator: symplectic-euler, dt 0.002 s, 2 substep(s)"),
        "{stdout}"
    );
    assert!(
        stdout.contains("steps: 50 frame(s), 100 substep(s)"),
        "{stdout}"
    );
    // A research integrator is the lab's: refused, with where to find it.
    for name in harmonic::RESEARCH_INTEGRATORS {
        let research = harmonic(&[
            "run",
            "scenes/explicit_pair.ron",
            "--seconds",
            "0.1",
            "--integrator",
            name,
        ]);
        let stderr = String::from_utf8_lossy(&research.stderr);
        assert_eq!(research.status.code(), Some(2), "{name}: {stderr}");
        assert!(
            stderr.contains(&format!("integrator `{name}` is a research variant"))
                && stderr.contains(&format!("harmonic-lab bench --integrators {name}")),
            "{stderr}"
        );
    }
    let bad = harmonic(&[
        "run",
        "scenes/explicit_pair.ron",
        "--integrator",
        "leapfrog",
    ]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("unknown integrator `leapfrog`"));
}

/// At one substep per frame one of the hanging cloth's springs sits at 2 h_c: the closed
/// form's impulse vanishes there, and the run says so, but only for the closed form.
#[test]
fn the_aliasing_warning_is_for_the_closed_form_only() {
    let warns = |integrator: &str| {
        let out = harmonic(&[
            "run",
            "scenes/hanging_cloth.ron",
            "--steps",
            "1",
            "--substeps",
            "1",
            "--integrator",
            integrator,
        ]);
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(stdout.contains("h = 1.6667e-2 s"), "{integrator}: {stdout}");
        stdout.contains("within 2 % of a whole multiple of h_c")
    };
    for closed_form in ["harmonic", "harmonic-gs"] {
        assert!(warns(closed_form), "{closed_form} is not warned");
    }
    for other in ["symplectic-euler", "implicit-euler", "theta-mg", "xpbd"] {
        assert!(
            !warns(other),
            "{other} is warned of the closed form's aliasing"
        );
    }
}

#[test]
fn check_locates_errors_and_fails() {
    let out = harmonic(&[
        "check",
        "scenes/chain.ron",
        "tests/bad_scenes/spring_end_missing.ron",
        "tests/bad_scenes/unknown_field.ron",
    ]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(
            "tests/bad_scenes/spring_end_missing.ron: springs[0].b: particle 5 does not exist"
        ),
        "{stderr}"
    );
    assert!(
        stderr.contains("tests/bad_scenes/unknown_field.ron:5:28:"),
        "{stderr}"
    );
    assert!(stderr.contains("2 of 3 scene(s) invalid"), "{stderr}");
    assert!(String::from_utf8_lossy(&out.stdout)
        .contains("scenes/chain.ron: ok (21 particles, 3000 frame(s) for `run`)"));
    let missing = harmonic(&["check", "scenes/does_not_exist.ron"]);
    assert_eq!(missing.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&missing.stderr).contains("scenes/does_not_exist.ron: cannot read")
    );
}

#[test]
fn backend_choice_on_the_command_line() {
    let out = harmonic(&[
        "run",
        "scenes/chain.ron",
        "--steps",
        "2",
        "--backend",
        "cuda",
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown backend `cuda`"));

    // auto never fails for want of a GPU; it names what it ran on.
    let out = harmonic(&[
        "run",
        "scenes/chain.ron",
        "--steps",
        "2",
        "--backend",
        "auto",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(stdout.contains("backend: "), "{stdout}");

    // gpu: runs on an adapter, or says clearly why not.
    let out = harmonic(&[
        "run",
        "scenes/hanging_cloth.ron",
        "--seconds",
        "0.1",
        "--backend",
        "gpu",
    ]);
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    if out.status.success() {
        assert!(stdout.contains("backend: gpu, adapter "), "{stdout}");
        assert!(stdout.contains("non-finite: none"), "{stdout}");
    } else {
        assert!(
            std::env::var_os("HARMONIC_REQUIRE_GPU").is_none(),
            "{stdout}\n{stderr}"
        );
        assert!(stderr.contains("no GPU adapter"), "{stderr}");
    }

    // An integrator without a GPU kernel is refused by name.
    let out = harmonic(&[
        "run",
        "scenes/chain.ron",
        "--steps",
        "2",
        "--backend",
        "gpu",
        "--integrator",
        "implicit-euler",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("implicit-euler has no GPU kernel"),
        "{stderr}"
    );
}
