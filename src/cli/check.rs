//! `mpmlab check` and `mpmlab list`: scenes looked at, not run.

use super::common::load;
use anyhow::{Context, Result};
use mpmlab::model::Limits;
use mpmlab::scene::Scene;
use mpmlab::units::Quantity;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// `mpmlab check SCENE`: the scene builds within the memory budget (exit 0;
/// 2 with the cause when it does not).
pub fn check(path: &Path, limits: &Limits) -> Result<ExitCode> {
    let (sim, _) = match load(path, limits) {
        Ok(s) => s,
        Err(code) => return Ok(code),
    };
    let m = sim.model();
    out!(
        "{}: ok — scene `{}`, grid {}x{} (h = {} {}), {}, {} points, {} {} steps, memory estimate within the {} budget",
        path.display(),
        m.name,
        m.grid.nx,
        m.grid.ny,
        mpmlab::scene::number(m.grid.h),
        m.units.of(Quantity::Length),
        match m.bodies.len() {
            1 => "1 body".to_string(),
            n => format!("{n} bodies"),
        },
        sim.points().len(),
        m.analysis.load_steps,
        if sim.time().is_some() { "time" } else { "load" },
        mpmlab::model::bytes(limits.max_memory)
    );
    Ok(ExitCode::SUCCESS)
}

/// `mpmlab list DIR`: every scene file of `dir` with its description (or
/// why it is invalid).
pub fn list(dir: &Path) -> Result<ExitCode> {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    entries.sort();
    for p in entries {
        let file = p.display().to_string();
        match mpmlab::scene::read_scene_text(&p)
            .and_then(|t| Scene::parse(&t, &file))
            .map_err(|e| e.to_string())
        {
            Ok(s) => {
                let desc = s.scene.description.split_whitespace().collect::<Vec<_>>().join(" ");
                out!("{:<28} {}", s.scene.name, desc);
            }
            Err(e) => out!("{:<28} (invalid: {e})", file),
        }
    }
    Ok(ExitCode::SUCCESS)
}
