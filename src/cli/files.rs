//! Output targets: whether a file given to `--record`, `--csv` or
//! `repair` may be written, before anything is.

use std::path::Path;

/// Whether `record` may be written: not the scene itself, not a
/// directory or a special file (`--force` or not), and, when it exists
/// and is not empty, a rerun recording (its first bytes `RRF0`..`RRF2`)
/// unless `force`. Refusals are bad arguments (exit 2); nothing has been
/// written.
pub fn check_record_target(record: &Path, scene: Option<&Path>, force: bool) -> Result<(), String> {
    check_output_target("--record", record, scene, force, "a rerun recording", "run.rrd", is_rrd)
}

/// Whether `csv` may be written: as [`check_record_target`], for a step
/// table (its first bytes `step,`).
pub fn check_csv_target(csv: &Path, scene: Option<&Path>, force: bool) -> Result<(), String> {
    let ours = |m: &[u8]| m.starts_with(b"step,");
    check_output_target("--csv", csv, scene, force, "a step table", "run.csv", ours)
}

/// Whether a file's first bytes are those of a rerun recording.
pub fn is_rrd(magic: &[u8]) -> bool {
    [b"RRF0", b"RRF1", b"RRF2"].iter().any(|x| magic.starts_with(&x[..]))
}

/// Whether the output file `path` of option `flag` may be written: not
/// the scene itself (by identity), not a directory or a special file,
/// and, when it exists and is not empty, a file of its kind (`ours` of
/// its first bytes) unless `force`.
pub fn check_output_target(
    flag: &str,
    path: &Path,
    scene: Option<&Path>,
    force: bool,
    kind: &str,
    example: &str,
    ours: impl Fn(&[u8]) -> bool,
) -> Result<(), String> {
    // The scene by identity (through `./`, symlinks, hard links), and
    // never replaced, --force or not.
    if let Some(scene) = scene {
        if mpmlab::output::same_file(path, scene) {
            return Err(format!(
                "{flag} {} is the scene file itself; give another path (--force never replaces the scene)",
                path.display()
            ));
        }
    }
    let Ok(meta) = std::fs::metadata(path) else {
        return Ok(());
    };
    if meta.is_dir() {
        return Err(format!(
            "{flag} {} is a directory; give a file path such as {}",
            path.display(),
            path.join(example).display()
        ));
    }
    // Devices, FIFOs and sockets are never replaced.
    if let Some(why) = mpmlab::output::not_replaceable(path) {
        return Err(format!("{flag} {why}"));
    }
    if force {
        return Ok(());
    }
    let mut magic = [0u8; 8];
    use std::io::Read as _;
    let n = std::fs::File::open(path)
        .and_then(|mut f| f.read(&mut magic))
        .map_err(|e| {
            format!(
                "{flag} {}: cannot read the existing file: {}",
                path.display(),
                mpmlab::scene::io_reason(&e)
            )
        })?;
    if n == 0 || ours(&magic[..n]) {
        return Ok(());
    }
    Err(format!(
        "{flag} {} exists and is not {kind}; refusing to overwrite it (choose another path, or --force)",
        path.display()
    ))
}
