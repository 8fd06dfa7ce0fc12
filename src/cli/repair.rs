//! `mpmlab repair`: a recording cut short made whole again.

use super::files::{check_output_target, is_rrd};
use std::path::Path;
use std::process::ExitCode;

/// `mpmlab repair IN OUT`: 0 repaired (or copied, when IN was complete),
/// 2 bad arguments or an IN that is not a recording or holds nothing
/// whole, 3 OUT cannot be written.
pub fn repair(input: &Path, output: &Path, force: bool) -> ExitCode {
    use mpmlab::record::repair::RepairError;
    if mpmlab::output::same_file(input, output) {
        eprintln!(
            "error: the output {} is the input itself; give another path (the input is left as it is)",
            output.display()
        );
        return ExitCode::from(2);
    }
    if let Err(e) = check_output_target(
        "output",
        output,
        None,
        force,
        "a rerun recording",
        "repaired.rrd",
        is_rrd,
    ) {
        eprintln!("error: {e}");
        return ExitCode::from(2);
    }
    let limit = match decodable(input) {
        Ok(limit) => limit,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    match mpmlab::record::repair::repair(input, output, force, limit) {
        Ok(r) => {
            out!("repaired {} into {}: {r}", input.display(), output.display());
            ExitCode::SUCCESS
        }
        Err(e @ RepairError::Write { .. }) => {
            eprintln!("error: {e}");
            ExitCode::from(3)
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}

/// How many messages of `input` decode without the decoder ending the
/// process: [`mpmlab::record::repair::probe`] run in a child process (an
/// allocation of petabytes that a damaged length asks arrow for aborts
/// the process, which no guard in it can catch). `None` when the child
/// got through; else the count and the reason, naming the message.
fn decodable(input: &Path) -> Result<Option<(usize, String)>, String> {
    let exe = std::env::current_exe().map_err(|e| format!("cannot find the mpmlab executable: {e}"))?;
    let out = std::process::Command::new(exe)
        .arg("repair-probe")
        .arg(input)
        .stdin(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .output()
        .map_err(|e| format!("cannot start the decoding check: {e}"))?;
    if out.status.success() {
        return Ok(None);
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let k = text
        .lines()
        .filter_map(|l| l.strip_prefix("ok ").and_then(|n| n.trim().parse::<usize>().ok()))
        .next_back()
        .unwrap_or(0);
    let bytes = mpmlab::record::repair::message_bytes(input, k + 1)
        .map_or(String::new(), |(a, b)| format!(" (bytes {a}..{b})"));
    Ok(Some((
        k,
        format!("message {}{bytes} does not decode: the decoder aborted on it", k + 1),
    )))
}

/// `mpmlab repair-probe IN`: [`mpmlab::record::repair::probe`] on stdout;
/// exit 0 when every message was tried, 2 when IN is not a recording.
pub fn probe(input: &Path) -> ExitCode {
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    match mpmlab::record::repair::probe(input, &mut out) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}
