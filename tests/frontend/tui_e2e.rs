//! The real binary in a pseudo-terminal (util-linux `script` provides it):
//! keys go in, the screen text and the recording come out.

use crate::common;
use std::io::Write;
use std::process::{Command, Stdio};
use std::time::Duration;

/// A key to press and what the screen must show after it before the next
/// key goes in (`None`: nothing to wait for, as for the last `q`).
type Key<'a> = (&'a str, Option<&'a str>);

/// The longest a session waits for what it expects before it fails: a
/// guard against a hang, not a pace (every key waits for its text).
const PATIENCE: Duration = Duration::from_secs(120);

/// Run the binary's TUI with `args` in a pseudo-terminal in `dir`: wait for
/// its first screen to show `first`, then press each key and wait until
/// the screen drawn after it shows the text it names. The exit status and
/// the screen text (escape sequences as spaces, runs of spaces collapsed).
fn session(dir: &std::path::Path, args: &str, first: &str, keys: &[Key]) -> (std::process::ExitStatus, String, String) {
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
    let output = std::sync::Arc::new(std::sync::Mutex::new(Vec::<u8>::new()));
    let reader = {
        let (output, mut stdout) = (output.clone(), child.stdout.take().unwrap());
        std::thread::spawn(move || {
            use std::io::Read;
            let mut buf = [0u8; 4096];
            while let Ok(n) = stdout.read(&mut buf) {
                if n == 0 {
                    break;
                }
                output.lock().unwrap().extend_from_slice(&buf[..n]);
            }
        })
    };
    let seen = || output.lock().unwrap().len();
    wait_for(&output, 0, first);
    for (k, expect) in keys {
        let from = seen();
        let _ = input.write_all(k.as_bytes()).and_then(|_| input.flush());
        if let Some(text) = expect {
            wait_for(&output, from, text);
        }
    }
    drop(input);
    let status = child.wait().unwrap();
    reader.join().unwrap();
    let mut err = String::new();
    if let Some(mut e) = child.stderr.take() {
        use std::io::Read;
        let _ = e.read_to_string(&mut err);
    }
    let raw = output.lock().unwrap().clone();
    (status, screen_text(&raw), err)
}

/// Wait until the screen, as the terminal shows it after the output up to
/// now, shows `text` (and did not already before byte `from`, when the key
/// went in); fail naming it after [`PATIENCE`].
fn wait_for(output: &std::sync::Mutex<Vec<u8>>, from: usize, text: &str) {
    let until = std::time::Instant::now() + PATIENCE;
    let before = terminal(&output.lock().unwrap()[..from]);
    loop {
        let screen = terminal(&output.lock().unwrap());
        if screen.contains(text) && (screen != before || !before.contains(text)) {
            return;
        }
        assert!(
            std::time::Instant::now() < until,
            "the screen never showed `{text}`; it shows:\n{screen}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The 100 x 30 screen a terminal shows after `raw`: the cursor moves and
/// clears ratatui sends (it redraws only the cells that changed, so the
/// text of a line is only whole on the screen), colours ignored; rows
/// with runs of spaces collapsed, joined by newlines.
fn terminal(raw: &[u8]) -> String {
    let (w, h) = (100usize, 30usize);
    let mut grid = vec![vec![' '; w]; h];
    let (mut row, mut col) = (0usize, 0usize);
    let text = String::from_utf8_lossy(raw);
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '\x1b' => match chars.next() {
                Some('[') => {
                    let mut params = String::new();
                    let mut last = ' ';
                    for d in chars.by_ref() {
                        if ('\x40'..='\x7e').contains(&d) {
                            last = d;
                            break;
                        }
                        params.push(d);
                    }
                    let nums: Vec<usize> = params
                        .trim_start_matches('?')
                        .split(';')
                        .map(|p| p.parse().unwrap_or(0))
                        .collect();
                    let n = |i: usize| nums.get(i).copied().filter(|&v| v > 0).unwrap_or(1);
                    match last {
                        'H' | 'f' => (row, col) = (n(0) - 1, n(1) - 1),
                        'A' => row = row.saturating_sub(n(0)),
                        'B' => row += n(0),
                        'C' => col += n(0),
                        'D' => col = col.saturating_sub(n(0)),
                        'G' => col = n(0) - 1,
                        'J' if nums.first() == Some(&2) => grid.iter_mut().for_each(|r| r.fill(' ')),
                        'K' if row < h => grid[row][col.min(w)..].fill(' '),
                        _ => {}
                    }
                }
                Some(']') => {
                    // An operating-system command, to BEL or ESC \.
                    while let Some(d) = chars.next() {
                        if d == '\x07' || (d == '\x1b' && chars.next_if_eq(&'\\').is_some()) {
                            break;
                        }
                    }
                }
                _ => {}
            },
            '\r' => col = 0,
            '\n' => row += 1,
            '\x08' => col = col.saturating_sub(1),
            c if c.is_control() => {}
            c => {
                if row < h && col < w {
                    grid[row][col] = c;
                }
                col += 1;
            }
        }
    }
    grid.iter()
        .map(|r| {
            r.iter()
                .collect::<String>()
                .split_whitespace()
                .collect::<Vec<_>>()
                .join(" ")
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Terminal output as screen text: escape sequences as spaces, runs of
/// spaces collapsed.
fn screen_text(raw: &[u8]) -> String {
    let raw = String::from_utf8_lossy(raw);
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
    screen.split_whitespace().collect::<Vec<_>>().join(" ")
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
        ("V", Some("ParaView series:")),
        (" ", Some("step 1/20")),
        (" ", Some("step 2/20")),
        ("w", Some("checkpoint of step 2")),
        ("V", Some("ParaView series closed")),
        ("q", None),
    ];
    let (status, screen, err) = session(&dir, &format!("'{s}' --no-record"), "rigid-footing", &keys);
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
    let (status, screen, err) = session(&dir, &args, "step 2/20", &[(" ", Some("step 3/20")), ("q", None)]);
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
        (" ", Some("step 1/1")),             // the load step
        ("d", Some("delta/h = 1.0e-7")),     // delta/h / 10: a parameter change
        ("r", Some("redo: before / after")), // redo the step with it
        ("\x1b", Some("step 1/1")),          // close the comparison
        ("q", None),
    ];
    let (status, screen, err) = session(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")),
        &format!("scenarios/block-roller-30.toml --record '{}'", rrd.display()),
        "block-roller-30",
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
