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
    match mpmlab::record::repair::repair(input, output, force) {
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
