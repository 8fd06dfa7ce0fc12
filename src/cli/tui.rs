//! `mpmlab tui` (and `mpmlab` with no arguments): a scene stepped in the
//! terminal UI, recorded unless `--no-record`; or a sweep folder's view.

use super::args::{limits, TuiArgs};
use super::common::{fail, load, use_threads};
use super::files::check_record_target;
use anyhow::{Context, Result};
use mpmlab::model::Limits;
use mpmlab::record::Recorder;
use mpmlab::scene::Scene;
use mpmlab::simulation::Simulation;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The scene opened by `mpmlab` with no arguments (also built in, so the
/// command works from any directory).
const DEFAULT_SCENE: &str = "scenarios/column-small-strain.toml";

/// `mpmlab tui`: exit 0 when the UI is left, 2 for bad arguments or
/// scenes, 3 when the recording cannot be created.
pub fn tui(a: &TuiArgs) -> Result<ExitCode> {
    if let Some(dir) = &a.sweep {
        return sweep_view(dir);
    }
    let (scene, resume) = (a.scene.as_deref(), a.resume.as_deref());
    if resume.is_some() && scene.is_none() {
        return Ok(fail(2, "--resume needs the scene file the checkpoint was written for"));
    }
    if let Some(r) = &a.record {
        if let Err(e) = check_record_target(r, scene, a.force) {
            return Ok(fail(2, e));
        }
    }
    let (mut sim, text) = match open_scene(scene, &limits(a.max_memory))? {
        Ok(s) => s,
        Err(code) => return Ok(code),
    };
    if let Err(code) = use_threads(&mut sim, a.threads, true) {
        return Ok(code);
    }
    if let Some(file) = resume {
        if let Err(e) = sim.resume_from(file, &text) {
            return Ok(fail(2, e));
        }
    }
    let recorder = if a.no_record {
        None
    } else {
        match open_recorder(a, &sim, &text)? {
            Ok(r) => Some(r),
            Err(code) => return Ok(code),
        }
    };
    let path = recorder.as_ref().map(|r| r.path().display().to_string());
    mpmlab::tui::run(sim, text, recorder).context("terminal UI")?;
    if let Some(p) = path {
        out!("recording: {p}  (replay: mpmlab replay {p})");
    }
    Ok(ExitCode::SUCCESS)
}

/// The scene to step: the one given; else, in a folder with the shipped
/// scenes, the one picked (on a terminal) or the default; else the
/// built-in default. `Ok(Err(code))`: exit with `code` (0 when the user
/// quit the picker).
fn open_scene(scene: Option<&Path>, limits: &Limits) -> Result<Result<(Simulation, String), ExitCode>> {
    Ok(match scene {
        Some(p) => load(p, limits),
        None if Path::new(DEFAULT_SCENE).exists() => {
            // The scene picker, the default highlighted (only on a terminal).
            use std::io::IsTerminal;
            let path = if std::io::stdin().is_terminal() {
                match pick_scene(Path::new("scenarios"))? {
                    Some(p) => p,
                    None => return Ok(Err(ExitCode::SUCCESS)),
                }
            } else {
                PathBuf::from(DEFAULT_SCENE)
            };
            load(&path, limits)
        }
        None => match mpmlab::shipped::text("column-small-strain") {
            Some(text) => Simulation::from_scene_text(text, DEFAULT_SCENE)
                .map(|s| (s, text.to_string()))
                .map_err(|e| fail(2, e)),
            None => Err(fail(2, "the default scene is not built into this program")),
        },
    })
}

/// The recording of a TUI session: `--record` or
/// `recordings/<scene>-<time>.rrd`, with the recording flags over the
/// scene's settings. `Ok(Err(code))`: exit 2 for settings the scene does
/// not allow, 3 when the file cannot be created.
fn open_recorder(a: &TuiArgs, sim: &Simulation, text: &str) -> Result<Result<Recorder, ExitCode>> {
    let path = a.record.clone().unwrap_or_else(|| {
        PathBuf::from(format!(
            "recordings/{}-{}.rrd",
            mpmlab::output::safe_stem(&sim.model().name),
            timestamp()
        ))
    });
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let settings = match a.cadence.settings(sim) {
        Ok(s) => s,
        Err(e) => return Ok(Err(fail(2, e))),
    };
    let r = match a.cadence.create(&path, text, sim, settings, a.force) {
        Ok(r) => r,
        Err(e) => return Ok(Err(fail(3, e))),
    };
    if let Some(f) = &a.resume {
        let _ = r.event(
            &format!(
                "resumed from checkpoint {} at step {}: this recording is a branch from there",
                f.display(),
                sim.step_index()
            ),
            "INFO",
        );
    }
    Ok(Ok(r))
}

/// `mpmlab tui --sweep DIR`: the sweep view.
fn sweep_view(dir: &Path) -> Result<ExitCode> {
    if !dir.join("runs.txt").exists() && !dir.join("sweep.csv").exists() {
        anyhow::bail!("{} is not a sweep folder (no runs.txt or sweep.csv)", dir.display());
    }
    let folder = mpmlab::sweep::Folder(dir.to_path_buf());
    let title = dir
        .file_name()
        .map_or("sweep".into(), |n| n.to_string_lossy().into_owned());
    mpmlab::tui::sweep::run(&folder, &title).context("terminal")?;
    Ok(ExitCode::SUCCESS)
}

/// Now (UTC) as `YYYYMMDD-HHMMSS`, for recording names.
fn timestamp() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}{m:02}{d:02}-{:02}{:02}{:02}",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// The scenes of `dir` in the picker; `None` when the user quits.
fn pick_scene(dir: &Path) -> Result<Option<PathBuf>> {
    use mpmlab::tui::picker::{pick, Entry, Picker};
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    paths.sort();
    let entries: Vec<Entry> = paths
        .into_iter()
        .filter_map(|path| {
            let text = mpmlab::scene::read_scene_text(&path).ok()?;
            let s = Scene::parse(&text, &path.display().to_string()).ok()?;
            Some(Entry {
                path,
                name: s.scene.name,
                description: s.scene.description.split_whitespace().collect::<Vec<_>>().join(" "),
            })
        })
        .collect();
    let default = entries
        .iter()
        .position(|e| e.path == Path::new(DEFAULT_SCENE))
        .unwrap_or(0);
    let picker = Picker {
        entries,
        selected: default,
        default,
    };
    Ok(pick(picker).context("terminal UI")?.map(|e| e.path))
}
