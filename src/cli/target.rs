//! `mpmlab sweep SCENE --target Q=TOL`: the cheapest discretisation
//! meeting an error target.

use super::common::load;
use super::validate::validate_runs;
use anyhow::{Context, Result};
use mpmlab::model::Limits;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// `mpmlab sweep SCENE --target Q=TOL`: the cheapest run meeting a target
/// (exit 0 when one does, 1 when none did within the budget).
pub fn target_search(
    name: &str,
    path: &Path,
    out: Option<PathBuf>,
    target: &str,
    budget: f64,
    tries: Vec<mpmlab::sweep::Vary>,
    force: bool,
) -> Result<ExitCode> {
    use mpmlab::scene::Placement;
    use mpmlab::sweep::{driver, target, Folder};
    let t = match target::Target::parse(target) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: --target {e}");
            return Ok(ExitCode::from(2));
        }
    };
    if !(budget > 0.0 && budget.is_finite()) {
        eprintln!("error: --budget must be a positive number of seconds");
        return Ok(ExitCode::from(2));
    }
    let base = match mpmlab::scene::read_scene_text(path) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(2));
        }
    };
    let scene = match mpmlab::scene::Scene::parse(&base, &path.display().to_string()) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(2));
        }
    };
    let sim = match load(path, &Limits::default()) {
        Ok((sim, _)) => sim,
        Err(code) => return Ok(code),
    };
    if let Err(e) = t.check_against(&sim) {
        eprintln!("error: --target {e}");
        return Ok(ExitCode::from(2));
    }
    drop(sim);
    if !tries.is_empty() {
        if let Err(e) = validate_runs(&base, &[], &mpmlab::sweep::expand(&tries)) {
            eprintln!("error: --try: {e}");
            return Ok(ExitCode::from(2));
        }
    }
    // Points per cell is a setting of the search only where every body
    // places its points per cell.
    let ppc = scene
        .bodies
        .iter()
        .all(|b| b.lattice.is_none() && b.placement != Placement::Polar)
        .then(|| scene.bodies.first().map(|b| b.points_per_cell))
        .flatten();
    let folder = Folder(out.unwrap_or_else(|| PathBuf::from("sweeps").join(format!("{name}-target"))));
    if let Err(e) = folder.check_ours(force) {
        eprintln!("error: {e}");
        return Ok(ExitCode::from(2));
    }
    let exe = std::env::current_exe().context("cannot find the mpmlab executable")?;
    out!(
        "searching {} for {} <= {:e} within {budget} s of runs, in {}",
        path.display(),
        t.quantity,
        t.tol,
        folder.0.display()
    );
    let found = target::search(
        &folder,
        &exe,
        &base,
        target::Start {
            h: scene.grid.h,
            ppc,
            tries,
        },
        &t,
        budget,
        &|line| out!("{line}"),
    )
    .map_err(anyhow::Error::msg)?;
    out!("{}", driver::finish(&folder, name).map_err(anyhow::Error::msg)?);
    out!("{}", target::report(&found));
    Ok(if found.best.is_some() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}
