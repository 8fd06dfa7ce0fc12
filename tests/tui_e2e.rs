//! The real binary in a pseudo-terminal (util-linux `script` provides it):
//! keys go in, the screen text and the recording come out.

mod common;
use std::io::Write;
use std::process::{Command, Stdio};
use std::time::Duration;

#[test]
fn step_change_delta_redo_and_quit_in_a_terminal() {
    if Command::new("script").arg("--version").output().is_err() {
        eprintln!("skipped: util-linux `script` is not installed");
        return;
    }
    let rrd = common::temp_path("e2e", "rrd");
    let cmd = format!(
        "stty cols 100 rows 30; exec '{}' tui scenarios/block-roller-30.toml --record '{}'",
        env!("CARGO_BIN_EXE_mpmlab"),
        rrd.display()
    );
    let mut child = Command::new("script")
        .args(["-qefc", &cmd, "/dev/null"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("TERM", "xterm-256color")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut keys = child.stdin.take().unwrap();
    let mut press = |k: &str, wait_ms: u64| {
        // A failed write means the program ended: the asserts below say why.
        let _ = keys.write_all(k.as_bytes()).and_then(|_| keys.flush());
        std::thread::sleep(Duration::from_millis(wait_ms));
    };
    std::thread::sleep(Duration::from_millis(800));
    press(" ", 1500); // the load step
    press("d", 300); // delta/h / 10: a parameter change
    press("r", 2000); // redo the step with it
    press("\x1b", 300); // close the comparison
    press("q", 300);
    press("q", 300); // (a second q in case a step still ran)
    drop(keys);
    let out = child.wait_with_output().unwrap();
    // The terminal output with escape sequences (cursor moves between
    // words) turned into spaces, and runs of spaces collapsed.
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
    assert!(
        out.status.success(),
        "{:?}: {} {}",
        out.status,
        String::from_utf8_lossy(&out.stderr),
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
