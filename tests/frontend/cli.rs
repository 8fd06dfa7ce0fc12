//! The command line as a user meets it: bad scenes are reported with file,
//! line and field; every shipped scene runs.

use crate::common;
use crate::common::{mpmlab, temp_path};
use std::process::Command;

/// The patch scene with `from` replaced by `to`, written to a temp file.
fn broken(from: &str, to: &str) -> common::TempPath {
    let text = std::fs::read_to_string(common::scene_path("patch-compression")).unwrap();
    assert!(text.contains(from), "{from}");
    let path = temp_path("broken", "toml");
    std::fs::write(&path, text.replacen(from, to, 1)).unwrap();
    path
}

fn line_of(path: &std::path::Path, needle: &str) -> usize {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .position(|l| l.contains(needle))
        .unwrap()
        + 1
}

#[test]
fn malformed_scene_names_file_and_line() {
    let p = broken("h = 0.5", "h = 0.5 0.5");
    let (code, _, err) = mpmlab(&["run", p.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    let line = line_of(&p, "h = 0.5 0.5");
    assert!(err.contains(&format!("{}:{line}:", p.display())), "{err}");
}

#[test]
fn unknown_key_is_named() {
    let p = broken("nu = 0.3", "nu = 0.3\nyoung = 5.0");
    let (code, _, err) = mpmlab(&["check", p.to_str().unwrap()]);
    assert_eq!(code, 2);
    let line = line_of(&p, "young = 5.0");
    assert!(err.contains(&format!(":{line}:")) && err.contains("young"), "{err}");
}

#[test]
fn bad_values_are_located() {
    for (from, to, field) in [
        ("E = 1.0e6", "E = -1.0e6", "material[0].E"),
        ("nu = 0.3", "nu = 0.5", "material[0].nu"),
        ("max = [2.25, 2.0]", "max = [4.25, 2.0]", "body[0].region"),
        ("h = 0.5", "h = 0.7", "grid.size"),
        ("material = \"elastic\"", "material = \"steel\"", "body[0].material"),
        ("load_steps = 1", "load_steps = 0", "analysis.load_steps"),
        ("y = 2.0", "y = 2.1", "dirichlet[2].y"),
    ] {
        let p = broken(from, to);
        let (code, _, err) = mpmlab(&["check", p.to_str().unwrap()]);
        assert_eq!(code, 2, "{to}: {err}");
        let line = line_of(&p, to);
        // Field errors point at the key of the offending field, or at the
        // table that holds it for whole-table checks.
        assert!(err.contains(&format!("field `{field}`")), "{to}: {err}");
        if field != "grid.size" && field != "body[0].region" {
            assert!(
                err.contains(&format!("{}:{line}:", p.display())),
                "{to}: expected line {line}: {err}"
            );
        }
    }
}

#[test]
fn every_shipped_scene_runs() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios");
    let mut n = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "toml") {
            let (code, out, err) = mpmlab(&["run", "--quiet", p.to_str().unwrap()]);
            assert_eq!(code, 0, "{}: {out}{err}", p.display());
            assert!(out.contains("summary:"), "{out}");
            n += 1;
        }
    }
    assert!(n >= 3);
}

#[test]
fn list_and_check() {
    let (code, out, _) = mpmlab(&["list"]);
    assert_eq!(code, 0);
    for name in ["column-small-strain", "patch-compression", "fe-equivalence"] {
        assert!(out.contains(name), "{out}");
    }
    let (code, out, _) = mpmlab(&["check", "scenarios/column-small-strain.toml"]);
    assert_eq!(code, 0);
    assert!(out.contains("ok"));
}

#[test]
fn run_prints_a_table_and_records() {
    let rrd = temp_path("cli", "rrd");
    let (code, out, err) = mpmlab(&[
        "run",
        "scenarios/column-small-strain.toml",
        "--record",
        rrd.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("residual") && out.contains("syy_normalised") && out.contains("summary:"),
        "{out}"
    );
    assert!(std::fs::metadata(&rrd).unwrap().len() > 1000);
    let _ = std::fs::remove_file(rrd);
}

#[test]
fn unwritable_recording_is_a_clear_error() {
    let (code, _, err) = mpmlab(&[
        "run",
        "scenarios/patch-compression.toml",
        "--record",
        "/nonexistent-dir/x.rrd",
    ]);
    assert_eq!(code, 3);
    assert!(
        err.contains("/nonexistent-dir") && err.contains("does not exist"),
        "{err}"
    );
}

#[test]
fn replay_opens_the_viewer_or_says_how_to_install_it() {
    let rrd = temp_path("replay", "rrd");
    let (code, _, err) = mpmlab(&[
        "run",
        "scenarios/patch-compression.toml",
        "--quiet",
        "--record",
        rrd.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let run = |path: &str| {
        let out = Command::new(env!("CARGO_BIN_EXE_mpmlab"))
            .args(["replay", rrd.to_str().unwrap()])
            .env("PATH", path)
            .output()
            .unwrap();
        (
            out.status.code().unwrap_or(-1),
            String::from_utf8_lossy(&out.stdout).into_owned(),
        )
    };
    // No viewer on PATH: the exact install command for the matching version.
    let empty = temp_path("nopath", "d");
    std::fs::create_dir_all(&empty).unwrap();
    let (code, out) = run(empty.to_str().unwrap());
    assert_eq!(code, 1);
    assert!(
        out.contains("pip install rerun-sdk==0.36.3") && out.contains(rrd.to_str().unwrap()),
        "{out}"
    );
    // A viewer on PATH is started with the file, as a new viewer of its
    // own (`--new`), even while something listens on rerun's default port
    // (9876): rerun would otherwise hand the file to that process.
    let _busy = std::net::TcpListener::bind("127.0.0.1:9876");
    let fake = empty.join("rerun");
    let log = empty.join("args");
    std::fs::write(&fake, format!("#!/bin/sh\necho \"$@\" > '{}'\n", log.display())).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).unwrap();
    let (code, _) = run(&format!("{}:/usr/bin:/bin", empty.display()));
    assert_eq!(code, 0);
    assert_eq!(
        std::fs::read_to_string(&log).unwrap().trim(),
        format!("--new {}", rrd.to_str().unwrap())
    );
    let _ = std::fs::remove_dir_all(&empty);
    let _ = std::fs::remove_file(&rrd);
}

#[test]
fn a_failed_run_leaves_a_readable_recording() {
    // The plain GIMP beam (h = 0.25, 2x2 points) fails (G Table 5: after
    // 11 steps; round-off picks the step, see `docs/verification.md`):
    // exit code 1, and the file holds every step before the one the
    // message names, and the failure.
    let scene = temp_path("beam0", "toml");
    let text = std::fs::read_to_string(common::scene_path("elastic-beam-ghost"))
        .unwrap()
        .replace("h = 0.5", "h = 0.25")
        .replace("gamma_k = 12.0e6", "gamma_k = 0.0");
    std::fs::write(&scene, text).unwrap();
    let rrd = temp_path("failed", "rrd");
    let (code, _, err) = mpmlab(&[
        "run",
        scene.to_str().unwrap(),
        "--quiet",
        "--record",
        rrd.to_str().unwrap(),
    ]);
    assert_eq!(code, 1, "{err}");
    let k = common::failed_step(&err);
    let chunks = common::read_chunks(&rrd);
    let steps: std::collections::BTreeSet<i64> = chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/points")
        .flat_map(|c| {
            c.timelines()
                .get(&rerun::TimelineName::from("step"))
                .map(|t| t.times_raw().to_vec())
                .unwrap_or_default()
        })
        .collect();
    assert_eq!(steps, (0..k as i64).collect());
    let events = common::events(&rrd);
    assert!(
        events.iter().any(|e| e.contains(&format!("step {k} failed"))),
        "{events:?}"
    );
    let _ = std::fs::remove_file(&rrd);
    let _ = std::fs::remove_file(&scene);
}

#[test]
fn record_cadence_flags_and_the_size_report() {
    // Points every 4 of 10 steps: 0, 4, 8 and the last; the end of the run
    // reports the recording's size per step and per point.
    let dir = temp_path("cli-cadence", "d");
    std::fs::create_dir_all(&dir).unwrap();
    let scene = dir.join("short.toml");
    let text = std::fs::read_to_string("scenarios/ghost-collision-elastic.toml")
        .unwrap()
        .replace("duration = 3.5", "duration = 0.035")
        .replace("load_steps = 1000", "load_steps = 10");
    std::fs::write(&scene, text).unwrap();
    let rrd = dir.join("short.rrd");
    let (s, r) = (scene.to_str().unwrap(), rrd.to_str().unwrap());
    let (code, out, err) = mpmlab(&[
        "run",
        s,
        "--quiet",
        "--record",
        r,
        "--record-every",
        "4",
        "--record-fields",
        "speed,sigma_xx",
    ]);
    assert_eq!(code, 0, "{err}");
    let line = out
        .lines()
        .find(|l| l.starts_with("recording size:"))
        .unwrap_or_else(|| panic!("{out}"));
    assert!(
        line.contains("10 steps") && line.contains("points at 4 of them") && line.contains("B per point"),
        "{line}"
    );
    // A time cadence is for explicit dynamics only; the flags need --record.
    let (code, _, err) = mpmlab(&[
        "run",
        "scenarios/patch-compression.toml",
        "--record",
        r,
        "--record-dt",
        "0.1",
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--record-dt") && err.contains("explicit-dynamics"),
        "{err}"
    );
    let (code, _, err) = mpmlab(&["run", s, "--record-every", "2"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("need --record"), "{err}");
    let (code, _, err) = mpmlab(&["run", s, "--record", r, "--record-fields", "colour"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("unknown field `colour`"), "{err}");
    // The flush period: seconds from 0 to a day, with --record only.
    let (code, _, err) = mpmlab(&["run", s, "--record-sync", "0"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("need --record"), "{err}");
    for bad in ["-1", "nan", "1e9", "soon"] {
        let arg = format!("--record-sync={bad}");
        let (code, _, err) = mpmlab(&["run", s, "--record", r, &arg]);
        assert_eq!(code, 2, "{bad}: {err}");
        assert!(err.contains("--record-sync"), "{bad}: {err}");
    }
    let (code, _, err) = mpmlab(&["run", s, "--quiet", "--record", r, "--record-sync", "0"]);
    assert_eq!(code, 0, "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_thread_count_beyond_what_is_started_is_refused_at_once() {
    // Threads start one by one: 100000 took minutes before anything ran.
    // Refused before the run, with the limit and the machine's cores; the
    // limit itself is accepted.
    let s = "scenarios/ghost-collision-elastic.toml";
    let (code, _, err) = mpmlab(&["run", s, "--threads", "100000", "--quiet"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--threads: 100000 threads is more than the 256 this program starts"),
        "{err}"
    );
    let (code, _, err) = mpmlab(&["tui", s, "--threads", "100000"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("more than the 256"), "{err}");
    let mut sim = common::sim_with("ghost-collision-elastic", |_| {});
    assert_eq!(
        sim.set_threads(mpmlab::Simulation::MAX_THREADS),
        Ok(mpmlab::Simulation::MAX_THREADS)
    );
}

#[test]
fn verify_runs_from_any_folder_with_the_scenes_built_in() {
    // Outside the checkout there is no ./scenarios: the quick set runs on
    // the copies built into the program, and says so; a --scenes folder
    // that is not there is refused by name.
    let dir = common::temp_path("verify-elsewhere", "d");
    std::fs::create_dir_all(&dir).unwrap();
    let run = |args: &[&str]| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_mpmlab"))
            .args(args)
            .current_dir(&dir)
            .output()
            .unwrap();
        (
            out.status.code().unwrap_or(-1),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, out, err) = run(&["verify", "--quick"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(err.contains("built into this program"), "{err}");
    let last = out.lines().rev().find(|l| l.contains("rows pass")).unwrap_or_default();
    let n: Vec<&str> = last.split_whitespace().collect();
    assert!(n.len() > 3 && n[0] == n[2] && n[0] != "0", "{out}");
    let (code, _, err) = run(&["verify", "--quick", "--scenes", "no-such-folder"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--scenes no-such-folder: no such folder of scenes"),
        "{err}"
    );
}

#[test]
fn verify_passes_and_the_docs_hold_its_numbers() {
    // `mpmlab verify` (the full set: about 30 s in release): every paper
    // row within its tolerance, as CSV with the documented columns.
    let csv = common::temp_path("verify", "csv");
    let (code, out, err) = mpmlab(&["verify", "--csv", csv.to_str().unwrap()]);
    assert_eq!(code, 0, "{out}{err}");
    let rows = mpmlab::sweep::parse_csv(&std::fs::read_to_string(&csv).unwrap());
    let _ = std::fs::remove_file(&csv);
    assert_eq!(
        rows[0],
        [
            "benchmark",
            "quantity",
            "paper",
            "ours",
            "ratio",
            "tolerance",
            "pass",
            "why"
        ]
    );
    assert!(rows.len() > 35, "{out}");
    assert!(rows[1..].iter().all(|r| r[6] == "true"), "{out}");
    // docs/verification.md holds the table `verify --write-docs` wrote:
    // each row there must show the number this binary computes, to the 4
    // digits compared (values below 1e-12 are round-off and may differ
    // between machines).
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/verification.md")).unwrap();
    let begin = doc
        .find("<!-- verify:rows:begin")
        .expect("generated table in docs/verification.md");
    let table = &doc[begin..doc.find("<!-- verify:rows:end -->").unwrap()];
    for r in &rows[1..] {
        let line = table
            .lines()
            .find(|l| l.starts_with(&format!("| {} | {} |", r[0], r[1])))
            .unwrap_or_else(|| panic!("{} / {} not in docs/verification.md", r[0], r[1]));
        let documented: f64 = line.split('|').nth(4).unwrap().trim().parse().unwrap();
        let ours: f64 = r[3].parse().unwrap();
        assert!(
            (documented - ours).abs() <= 5e-4 * ours.abs() || ours.abs() < 1e-12,
            "{line}: this binary gives {ours:e}"
        );
    }
}
