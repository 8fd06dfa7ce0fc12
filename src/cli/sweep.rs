//! `mpmlab sweep` (plan, run or emit, collect) and `mpmlab sweep-run`
//! (one run of a sweep).

use super::args::SweepArgs;
use super::common::load;
use super::target::target_search;
use super::validate::validate_runs;
use anyhow::{Context, Result};
use mpmlab::model::Limits;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// `mpmlab sweep --collect DIR`: merge the results, warn about runs
/// without a result and failed runs; exit 1 when nothing was collected.
fn collect(dir: &Path) -> Result<ExitCode> {
    use mpmlab::sweep::{driver, Folder};
    let folder = Folder(dir.to_path_buf());
    let order: Vec<String> = std::fs::read_to_string(dir.join("runs.txt"))
        .map(|t| t.lines().filter(|l| !l.is_empty()).map(str::to_string).collect())
        .unwrap_or_default();
    if !dir.is_dir() || (order.is_empty() && !folder.results().is_dir() && !folder.csv().is_file()) {
        eprintln!(
            "error: {} is not a sweep folder (no runs.txt, results/ or sweep.csv)",
            dir.display()
        );
        return Ok(ExitCode::from(2));
    }
    let found = folder.collect();
    // A result file that does not read as one is named as damaged, not
    // passed over as a run not done.
    let (damaged, missing): (Vec<&String>, Vec<&String>) = order
        .iter()
        .filter(|id| !found.contains_key(*id))
        .partition(|id| folder.result(id).exists());
    if !damaged.is_empty() {
        eprintln!(
            "warning: {} result file{} cannot be read (damaged; the run is done again by the sweep): {}",
            damaged.len(),
            if damaged.len() == 1 { "" } else { "s" },
            damaged
                .iter()
                .map(|id| folder.result(id).display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let listed = |ids: &[&String]| {
        let mut s = ids.iter().take(10).map(|s| s.as_str()).collect::<Vec<_>>().join(", ");
        if ids.len() > 10 {
            s.push_str(&format!(", ... ({} more)", ids.len() - 10));
        }
        s
    };
    if !missing.is_empty() {
        eprintln!(
            "warning: {} of {} runs have no result (not run yet, or their process died): {}",
            missing.len(),
            order.len(),
            listed(&missing)
        );
    }
    let collected: Vec<_> = if order.is_empty() {
        found.values().collect()
    } else {
        order.iter().filter_map(|id| found.get(id)).collect()
    };
    let failed: Vec<&String> = collected.iter().filter(|r| !r.completed).map(|r| &r.id).collect();
    if !failed.is_empty() {
        eprintln!(
            "warning: {} of {} collected runs did not complete: {}",
            failed.len(),
            collected.len(),
            listed(&failed)
        );
    }
    if collected.is_empty() {
        eprintln!("error: nothing to collect in {}: no run has a result", dir.display());
        return Ok(ExitCode::from(1));
    }
    let title = dir
        .file_name()
        .map_or("sweep".into(), |n| n.to_string_lossy().into_owned());
    out!("{}", driver::finish(&folder, &title).map_err(anyhow::Error::msg)?);
    Ok(ExitCode::SUCCESS)
}

/// `mpmlab sweep`: plan, run (or emit) and summarise. Exit 2 for bad
/// arguments or scenes, including any run whose settings make an invalid
/// scene (checked before anything runs); failed runs are rows of the
/// table, not errors.
pub fn sweep(a: SweepArgs) -> Result<ExitCode> {
    use mpmlab::sweep::{driver, expand, presets, Folder, Vary};
    if let Some(dir) = a.collect {
        return collect(&dir);
    }
    let (name, path, fixed, mut varies) = match (&a.preset, &a.scene) {
        (Some(p), _) => {
            let pr = presets::preset(p)
                .with_context(|| format!("no preset `{p}`; presets: {}", presets::NAMES.join(", ")))?;
            out!("preset `{}`: {}", pr.name, pr.about);
            let path = PathBuf::from("scenarios").join(format!("{}.toml", pr.scene));
            (pr.name.to_string(), path, pr.fixed, pr.vary)
        }
        (None, Some(s)) => (
            s.file_stem()
                .map_or("sweep".into(), |n| n.to_string_lossy().into_owned()),
            s.clone(),
            Vec::new(),
            Vec::new(),
        ),
        (None, None) => anyhow::bail!("give a scene file, --preset NAME or --collect DIR"),
    };
    if a.target.is_none() && !a.tries.is_empty() {
        eprintln!("error: --try needs --target QUANTITY=VALUE (it sets where the target search starts)");
        return Ok(ExitCode::from(2));
    }
    if let Some(t) = &a.target {
        return match parse_tries(&a.tries) {
            Ok(tries) => target_search(&name, &path, a.out.clone(), t, a.budget, tries, a.force),
            Err(e) => {
                eprintln!("error: {e}");
                Ok(ExitCode::from(2))
            }
        };
    }
    for v in &a.vary {
        varies.push(Vary::parse(v).map_err(anyhow::Error::msg)?);
    }
    if varies.is_empty() {
        anyhow::bail!("nothing to vary: give --vary KEY=V1,V2,...");
    }
    if let Some(e) = mpmlab::sweep::overlapping(&varies) {
        eprintln!("error: {e}");
        return Ok(ExitCode::from(2));
    }
    if a.estimate {
        let sizes = |v: &Vary| {
            let mut x: Vec<String> = v.values.clone();
            x.sort();
            x.dedup();
            x.len()
        };
        if !varies
            .iter()
            .any(|v| (v.key == "h" || v.key == "grid.h") && sizes(v) >= 3)
        {
            eprintln!("error: --estimate needs a refinement study: --vary h=V1,V2,V3 (three or more cell sizes)");
            return Ok(ExitCode::from(2));
        }
    }
    // The base scene must be valid before anything is written.
    let base = match mpmlab::scene::read_scene_text(&path) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(2));
        }
    };
    if let Err(code) = load(&path, &Limits::default()) {
        return Ok(code);
    }
    if let Err(e) = validate_runs(&base, &fixed, &expand(&varies)) {
        eprintln!("error: --vary: {e}");
        return Ok(ExitCode::from(2));
    }
    let folder = Folder(a.out.unwrap_or_else(|| PathBuf::from("sweeps").join(&name)));
    if let Err(e) = folder.check_ours(a.force) {
        eprintln!("error: {e}");
        return Ok(ExitCode::from(2));
    }
    let runs = driver::prepare(&folder, &base, &fixed, &varies).map_err(anyhow::Error::msg)?;
    let todo = driver::pending(&folder, &runs);
    let exe = std::env::current_exe().context("cannot find the mpmlab executable")?;
    out!(
        "sweep `{name}` in {}: {} runs, {} already done",
        folder.0.display(),
        runs.len(),
        runs.len() - todo.len()
    );
    if a.emit_jobs {
        let p = driver::emit_jobs(&folder, &exe, &todo, a.record).map_err(anyhow::Error::msg)?;
        let p = std::path::absolute(&p).unwrap_or(p);
        out!(
            "wrote {} commands to {} (absolute paths: run them from any directory, e.g. `parallel < {}`), then `mpmlab sweep --collect {}`",
            todo.len(),
            p.display(),
            p.display(),
            folder.0.display()
        );
        return Ok(ExitCode::SUCCESS);
    }
    driver::execute(&folder, &exe, &todo, usize::from(a.jobs), a.record, &|line| {
        out!("{line}")
    });
    out!("{}", driver::finish(&folder, &name).map_err(anyhow::Error::msg)?);
    if a.estimate {
        if let Err(e) = sizes_completed(&folder, &runs) {
            eprintln!("error: --estimate: {e}");
            return Ok(ExitCode::from(1));
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The `--try` settings of a target search: parsed, none of the settings
/// the search sets itself (h and points per cell), none given twice (a
/// setting given twice would label runs with a value they did not use).
fn parse_tries(given: &[String]) -> Result<Vec<mpmlab::sweep::Vary>, String> {
    use mpmlab::sweep::{overlapping, Vary};
    let tries = given
        .iter()
        .map(|t| Vary::parse(t).map_err(|e| format!("--try {e}")))
        .collect::<Result<Vec<_>, _>>()?;
    let own = [Vary::parse("h=1")?, Vary::parse("ppc=1")?];
    if let Some(t) = tries
        .iter()
        .find(|t| own.iter().any(|o| overlapping(&[o.clone(), (*t).clone()]).is_some()))
    {
        return Err(format!(
            "--try {}: the target search refines h and points per cell itself; \
             --try sets the other settings it compares (basis, placement, steps, delta, gamma_k)",
            t.key
        ));
    }
    match overlapping(&tries) {
        Some(e) => Err(e.replace("--vary", "--try")),
        None => Ok(tries),
    }
}

/// Whether runs at three cell sizes or more completed (an estimate needs
/// them; failed runs can leave fewer, which is said, not passed over).
fn sizes_completed(folder: &mpmlab::sweep::Folder, runs: &[mpmlab::sweep::Run]) -> Result<(), String> {
    let done = folder.collect();
    let mut sizes: Vec<&str> = runs
        .iter()
        .filter(|r| done.get(&r.id).is_some_and(|d| d.completed))
        .filter_map(|r| r.settings.iter().find(|(k, _)| k == "h" || k == "grid.h"))
        .map(|(_, v)| v.as_str())
        .collect();
    sizes.sort_unstable();
    sizes.dedup();
    if sizes.len() >= 3 {
        return Ok(());
    }
    Err(format!(
        "runs at only {} cell size{} completed ({}); an estimate needs three (the failed runs are in the table)",
        sizes.len(),
        if sizes.len() == 1 { "" } else { "s" },
        if sizes.is_empty() {
            "none".to_string()
        } else {
            format!("h = {}", sizes.join(", "))
        }
    ))
}

/// `mpmlab sweep-run`: one run, its result row to `result`.
pub fn sweep_run(scene: &Path, result: &Path, record: Option<&Path>) -> Result<ExitCode> {
    let r = mpmlab::sweep::run_file_recorded(scene, record);
    if let Some(dir) = result.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    std::fs::write(result, mpmlab::sweep::to_csv(std::slice::from_ref(&r)))
        .with_context(|| format!("cannot write {}", result.display()))?;
    Ok(ExitCode::SUCCESS)
}
