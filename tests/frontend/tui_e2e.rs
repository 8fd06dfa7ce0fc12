//! The real binary in a pseudo-terminal (util-linux `script` provides it):
//! keys go in, the screen text and the recording come out.

use crate::common;
use std::io::Write;
use std::process::{Command, Stdio};
use std::time::Duration;

/// Run the binary's TUI with `args` in a pseudo-terminal in `dir`, press
/// `keys` (each with its wait in ms); the exit status and the screen text
/// (escape sequences as spaces, runs of spaces collapsed).
fn session(dir: &std::path::Path, args: &str, keys: &[(&str, u64)]) -> (std::process::ExitStatus, String, String) {
    let cmd = format!(
        "stty cols 100 rows 30; exec '{}' tui {args}",
        env!("CARGO_BIN_EXE_mpmlab")
    );
    let mut child = Command::new("script")
        .args(["-qefc", &cmd, "/dev/null"])
        .current_dir(dir)
        .env("TERM", "xterm-256color")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut input = child.stdin.take().unwrap();
    std::thread::sleep(Duration::from_millis(800));
    for (k, wait_ms) in keys {
        let _ = input.write_all(k.as_bytes()).and_then(|_| input.flush());
        std::thread::sleep(Duration::from_millis(*wait_ms));
    }
    drop(input);
    let out = child.wait_with_output().unwrap();
    let raw = String::from_utf8_lossy(&out.stdout);
    let mut screen = String::new();
    let mut chars = raw.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '\x1b' {
            if chars.peek() == Some(&'[') {
                chars.next();
                for d in chars.by_ref() {
                    if d.is_ascii_alphabetic() || d == '~' {
                        break;
                    }
                }
            }
            screen.push(' ');
        } else {
            screen.push(c);
        }
    }
    let screen = screen.split_whitespace().collect::<Vec<_>>().join(" ");
    (out.status, screen, String::from_utf8_lossy(&out.stderr).into_owned())
}

/// `V` writes a ParaView series from the current step, `w` a checkpoint;
/// `run --resume` continues the checkpoint to the end of the uninterrupted
/// run, and `tui --resume` opens it and records where it branched from.
#[test]
fn checkpoint_and_paraview_series_from_the_terminal() {
    if !has_script() {
        return;
    }
    let dir = common::temp_path("e2e-ckpt", "d");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let scene = common::scene_path("rigid-footing");
    let s = scene.display();
    let keys = [
        ("V", 800),
        (" ", 1200),
        (" ", 1200),
        ("w", 800),
        ("V", 800),
        ("q", 300),
        ("q", 300),
    ];
    let (status, screen, err) = session(&dir, &format!("'{s}' --no-record"), &keys);
    assert!(status.success(), "{status:?} {err} {screen}");
    assert!(screen.contains("step 2/20"), "{screen}");
    // The series: the state it started from and the two steps.
    let pvd = std::fs::read_to_string(dir.join("vtk/rigid-footing-from-step-0/points.pvd")).unwrap();
    assert_eq!(pvd.matches("<DataSet").count(), 3, "{pvd}");
    // The checkpoint of step 2 continues to where the whole run ends.
    let ck = dir.join("checkpoints/rigid-footing-step-000002.ckpt");
    assert!(ck.exists(), "{screen}");
    let (code, whole, e) = common::mpmlab(&["run", &s.to_string(), "--quiet"]);
    assert_eq!(code, 0, "{e}");
    let (code, resumed, e) = common::mpmlab(&["run", &s.to_string(), "--quiet", "--resume", ck.to_str().unwrap()]);
    assert_eq!(code, 0, "{e}");
    let last_probe = |out: &str| {
        out.lines()
            .find(|l| l.starts_with("probe `footing`"))
            .map(str::to_string)
    };
    assert!(last_probe(&whole).is_some(), "{whole}");
    assert_eq!(last_probe(&whole), last_probe(&resumed));
    // The TUI opens it at step 2; its recording says where it came from.
    let rrd = dir.join("branch.rrd");
    let args = format!("'{s}' --resume '{}' --record '{}'", ck.display(), rrd.display());
    let (status, screen, err) = session(&dir, &args, &[(" ", 1500), ("q", 300), ("q", 300)]);
    assert!(status.success(), "{status:?} {err} {screen}");
    assert!(screen.contains("step 3/20"), "{screen}");
    let ev = common::events(&rrd);
    assert!(
        ev.iter()
            .any(|e| e.starts_with("resumed from checkpoint") && e.contains("at step 2")),
        "{ev:?}"
    );
}

#[test]
fn step_change_delta_redo_and_quit_in_a_terminal() {
    if !has_script() {
        return;
    }
    let rrd = common::temp_path("e2e", "rrd");
    let keys = [
        (" ", 1500),   // the load step
        ("d", 300),    // delta/h / 10: a parameter change
        ("r", 2000),   // redo the step with it
        ("\x1b", 300), // close the comparison
        ("q", 300),
        ("q", 300), // (a second q in case a step still ran)
    ];
    let (status, screen, err) = session(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")),
        &format!("scenarios/block-roller-30.toml --record '{}'", rrd.display()),
        &keys,
    );
    assert!(
        status.success(),
        "{status:?}: {err} {}",
        &screen[..screen.len().min(2000)]
    );
    assert!(screen.contains("block-roller-30"), "{screen}");
    assert!(screen.contains("step 1/1"), "{screen}");
    assert!(screen.contains("redo: before / after"), "{screen}");
    let ev = common::events(&rrd);
    let _ = std::fs::remove_file(&rrd);
    assert!(ev.iter().any(|e| e.starts_with("parameter: delta/h = 1e-7")), "{ev:?}");
    assert!(ev.iter().any(|e| e.starts_with("redo of step 1")), "{ev:?}");
    assert!(ev.iter().any(|e| e.contains("end of interactive session")), "{ev:?}");
}

/// Whether util-linux `script` (the pseudo-terminal these tests type into)
/// can be started: under CI its absence fails the test with its name
/// (`.ci/run` installs it), elsewhere the test is skipped with a message.
fn has_script() -> bool {
    if let Err(e) = Command::new("script").arg("--version").output() {
        assert!(
            std::env::var_os("CI").is_none(),
            "the terminal tests need util-linux `script`: {e} (.ci/run installs Debian's bsdutils)"
        );
        eprintln!("skipped: util-linux `script` is not installed: {e}");
        return false;
    }
    true
}
