//! `mpmlab verify`: every paper benchmark against the papers' numbers.

use super::args::VerifyArgs;
use super::common::stop_on_signals;
use anyhow::{Context, Result};
use std::process::ExitCode;

/// `mpmlab verify`: the papers' numbers against ours. Exit 0 when every
/// row passes, 1 when one fails, 130 when interrupted.
pub fn verify(a: &VerifyArgs) -> Result<ExitCode> {
    use mpmlab::verify::{self, Scenes};
    let here = std::path::Path::new("scenarios");
    let scenes = match &a.scenes {
        Some(dir) if !dir.is_dir() => {
            eprintln!("error: --scenes {}: no such folder of scenes", dir.display());
            return Ok(ExitCode::from(2));
        }
        Some(dir) => Scenes::Folder(dir),
        None if here.is_dir() => Scenes::Folder(here),
        None => {
            eprintln!(
                "scenes: the {} built into this program (no ./scenarios here; --scenes DIR reads others)",
                mpmlab::shipped::SHIPPED.len()
            );
            Scenes::Builtin(mpmlab::shipped::SHIPPED)
        }
    };
    if a.quick && a.write_docs.is_some() {
        eprintln!("error: --write-docs needs the full set (without --quick)");
        return Ok(ExitCode::from(2));
    }
    let stop = stop_on_signals();
    let verify::Verified { rows, tables } = verify::verify(scenes, a.quick, &stop, &mut |line| eprintln!("{line}"));
    if stop.load(std::sync::atomic::Ordering::Relaxed) {
        eprintln!("interrupted");
        return Ok(ExitCode::from(130));
    }
    out!("{}", verify::table(&rows));
    if let Some(p) = &a.csv {
        std::fs::write(p, verify::csv(&rows)).with_context(|| format!("cannot write {}", p.display()))?;
        out!("csv: {}", p.display());
    }
    if let Some(p) = &a.write_docs {
        let doc = std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?;
        let mut doc = verify::replace_section(&doc, "rows", &verify::markdown(&rows));
        for (name, table) in &tables {
            doc = verify::replace_section(&doc, name, table);
        }
        std::fs::write(p, doc).with_context(|| format!("cannot write {}", p.display()))?;
        out!("table written into {}", p.display());
    }
    Ok(if rows.iter().all(|r| r.pass) {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}
