//! `mpmlab replay`: a recording in the rerun viewer.

use anyhow::{Context, Result};
use std::path::Path;
use std::process::ExitCode;

/// `mpmlab replay FILE`: a new rerun viewer of its own on a recording, if
/// installed; otherwise the exact command that installs the matching
/// viewer (exit 1).
pub fn replay(file: &Path) -> Result<ExitCode> {
    use mpmlab::record::RERUN_VERSION;
    if !file.is_file() {
        anyhow::bail!("{}: no such recording (a regular file)", file.display());
    }
    let mut magic = [0u8; 4];
    let n = std::fs::File::open(file)
        .and_then(|mut f| std::io::Read::read(&mut f, &mut magic))
        .with_context(|| format!("cannot read {}", file.display()))?;
    if !super::files::is_rrd(&magic[..n]) {
        anyhow::bail!(
            "{} is not a rerun recording (it does not start with RRF)",
            file.display()
        );
    }
    let viewer = std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|d| d.join("rerun"))
            .find(|p| p.is_file())
    });
    let Some(viewer) = viewer else {
        out!(
            "the rerun viewer is not installed; install the version that reads these recordings and open it with:\n  pip install rerun-sdk=={RERUN_VERSION}\n  rerun {}",
            file.display()
        );
        return Ok(ExitCode::from(1));
    };
    // `--new` (rerun's `--port auto`): a viewer of its own, on a free port
    // if the default one is taken. Without it, rerun hands the file to
    // whatever already listens on the default port (another user's
    // viewer, or a process that is no viewer at all).
    let status = std::process::Command::new(&viewer)
        .arg("--new")
        .arg(file)
        .status()
        .with_context(|| format!("cannot start {}", viewer.display()))?;
    Ok(if status.success() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}
