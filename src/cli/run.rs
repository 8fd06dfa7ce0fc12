//! `mpmlab run`: a scene headless, with its step table, summary and
//! outputs (recording, CSV, checkpoints, ParaView series).

use super::args::{limits, RunArgs};
use super::common::{fail, load, stop_on_signals, use_threads};
use super::files::{check_csv_target, check_record_target};
use super::summary;
use super::table::Table;
use anyhow::Result;
use mpmlab::checkpoint::Checkpointer;
use mpmlab::csv::CsvWriter;
use mpmlab::record::Recorder;
use mpmlab::runner::RunEnd;
use mpmlab::simulation::Simulation;
use mpmlab::units::Quantity;
use mpmlab::vtk::VtkExport;
use std::process::ExitCode;

/// Exit 0 when every step ran, 1 when a step failed, 2 for bad arguments
/// or scenes, 3 when an output cannot be written, 130 when interrupted.
pub fn run(args: &RunArgs) -> Result<ExitCode> {
    Ok(check_args(args)
        .and_then(|()| run_checked(args))
        .unwrap_or_else(|code| code))
}

/// The flags that go together and the output files that may be written,
/// before the scene is loaded (exit 2).
fn check_args(args: &RunArgs) -> Result<(), ExitCode> {
    let (path, record, force) = (args.scene.as_path(), args.record.as_deref(), args.force);
    if force && record.is_none() && args.csv.is_none() && args.checkpoint.is_none() && args.vtk.vtk.is_none() {
        return Err(fail(
            2,
            "--force needs --record FILE, --csv FILE, --checkpoint DIR or --vtk DIR",
        ));
    }
    if record.is_none() && args.cadence.given() {
        return Err(fail(
            2,
            "--record-every, --record-dt, --record-fields and --record-sync need --record FILE",
        ));
    }
    if let Some(r) = record {
        check_record_target(r, Some(path), force).map_err(|e| fail(2, e))?;
    }
    if let Some(c) = &args.csv {
        check_csv_target(c, Some(path), force).map_err(|e| fail(2, e))?;
        if record.is_some_and(|r| mpmlab::output::same_file(r, c)) {
            return Err(fail(2, "--csv and --record name the same file"));
        }
    }
    Ok(())
}

fn run_checked(args: &RunArgs) -> Result<ExitCode, ExitCode> {
    let (mut sim, text) = start(args)?;
    let mut outputs = Outputs::open(args, &sim, &text)?;
    print_scene(&sim);
    let mut table = Table::new(args.quiet);
    let mut code = step_all(&mut sim, &mut outputs, &mut table);
    summary::print(&sim, &table);
    outputs.finish(args, &sim, &mut code);
    Ok(code)
}

/// The scene loaded, its threads started and, with `--resume`, its state
/// that of the checkpoint.
fn start(args: &RunArgs) -> Result<(Simulation, String), ExitCode> {
    let (mut sim, text) = load(&args.scene, &limits(args.max_memory))?;
    use_threads(&mut sim, args.threads, args.quiet)?;
    if let Some(file) = &args.resume {
        let step = sim.resume_from(file, &text).map_err(|e| fail(2, e))?;
        out!("resumed from {} at step {step}", file.display());
    }
    Ok((sim, text))
}

/// `scene `name`: grid ...`: what is about to run.
fn print_scene(sim: &Simulation) {
    let m = sim.model();
    let u = m.units;
    out!(
        "scene `{}`: grid {}x{} h={} {}, {} points, {} {} steps; {}",
        m.name,
        m.grid.nx,
        m.grid.ny,
        m.grid.h,
        u.of(Quantity::Length),
        sim.points().len(),
        m.analysis.load_steps,
        if sim.time().is_some() { "time" } else { "load" },
        u.describe()
    );
    // The von Mises strength in the three ways of saying it, so a reader
    // of the key they gave sees what the others are.
    for mat in &m.materials {
        if let Some(st) = mat.strength {
            let [r, s, c] = st.all();
            let p = u.of(Quantity::Stress);
            out!(
                "material `{}`: von Mises, {} given: rho_y = sqrt(2 J2) = {r:.6e} {p}, sigma_y (uniaxial) = {s:.6e} {p}, c_u (shear) = {c:.6e} {p}",
                mat.name,
                st.key()
            );
        }
    }
}

/// What a run writes besides the table, each only when asked for.
struct Outputs {
    checkpoints: Option<Checkpointer>,
    recorder: Option<Recorder>,
    csv: Option<CsvWriter>,
    vtk: Option<VtkExport>,
}

impl Outputs {
    /// Every output created (exit 3 when one cannot be; exit 2 for
    /// recording settings the scene does not allow).
    fn open(args: &RunArgs, sim: &Simulation, text: &str) -> Result<Outputs, ExitCode> {
        let settings = args.cadence.settings(sim).map_err(|e| fail(2, e))?;
        let checkpoints = match &args.checkpoint {
            Some(dir) => {
                let every = args.checkpoint_every.map_or(usize::MAX, |n| n as usize);
                Some(Checkpointer::create(dir, every, text, args.force).map_err(|e| fail(3, e))?)
            }
            None => None,
        };
        let recorder = match &args.record {
            Some(p) => {
                let r = args
                    .cadence
                    .create(p, text, sim, settings, args.force)
                    .map_err(|e| fail(3, e))?;
                if let Some(f) = &args.resume {
                    let _ = r.event(
                        &format!("resumed from checkpoint {} at step {}", f.display(), sim.step_index()),
                        "INFO",
                    );
                }
                Some(r)
            }
            None => None,
        };
        let csv = match &args.csv {
            Some(p) => match CsvWriter::create(p, sim, args.force) {
                Ok(c) => Some(c),
                Err(e) => {
                    // Nothing was recorded yet: the old file stays.
                    if let Some(r) = recorder {
                        r.discard();
                    }
                    return Err(fail(3, e));
                }
            },
            None => None,
        };
        let vtk = match args.vtk.open(sim, args.force) {
            Ok(v) => v,
            Err(code) => {
                if let Some(r) = recorder {
                    r.discard();
                }
                if let Some(c) = csv {
                    c.discard();
                }
                return Err(code);
            }
        };
        Ok(Outputs {
            checkpoints,
            recorder,
            csv,
            vtk,
        })
    }

    /// The closing lines: where the checkpoint, table, recording and series
    /// are; exit 3 when the recording or the series cannot be finished.
    fn finish(self, args: &RunArgs, sim: &Simulation, code: &mut ExitCode) {
        if let (Some(c), Some(dir)) = (&self.checkpoints, &args.checkpoint) {
            if let Some(step) = c.last() {
                let f = dir.join(mpmlab::checkpoint::file_name(step));
                out!(
                    "checkpoint: {} (resume: mpmlab run {} --resume {})",
                    f.display(),
                    args.scene.display(),
                    f.display()
                );
            }
        }
        if let Some(c) = self.csv {
            let p = c.path().display().to_string();
            match c.finish() {
                Ok(()) => out!("step table: {p}"),
                Err(e) => *code = fail(3, e),
            }
        }
        if let Some(rec) = self.recorder {
            finish_recording(rec, sim, code);
        }
        if let Some(v) = self.vtk {
            match v.finish(sim) {
                Ok(summary) => out!("vtk: {summary}"),
                Err(e) => *code = fail(3, e),
            }
        }
    }
}

/// The last state and how the run ended into the recording, then its
/// footer; exit 3 when it cannot be written.
fn finish_recording(mut rec: Recorder, sim: &Simulation, code: &mut ExitCode) {
    let p = rec.path().display().to_string();
    // The last state reached, whatever the cadence.
    let _ = rec.log_final_state(sim);
    let _ = rec.event(
        if *code == ExitCode::SUCCESS {
            "run complete"
        } else {
            "run ended early"
        },
        "INFO",
    );
    match rec.finish() {
        Ok(size) => {
            out!("recording: {p}  (replay: mpmlab replay {p})");
            out!("recording size: {size}");
        }
        Err(e) => *code = fail(3, e),
    }
}

/// Every step (until one fails or a signal stops the run), through the
/// outputs and the table; the exit status so far.
fn step_all(sim: &mut Simulation, o: &mut Outputs, table: &mut Table) -> ExitCode {
    let mut code = ExitCode::SUCCESS;
    // Ctrl-C or SIGTERM: cancel the running step, keep the last good state
    // and close the recording; a second one ends the process at once.
    let stop = stop_on_signals();
    let mut detached = Vec::new();
    let end = mpmlab::runner::run(
        sim,
        // The recorder first: a printed step line means the step is in the
        // file (`Recorder::sync`), whatever happens to the process next.
        &mut [&mut o.recorder, table, &mut o.csv, &mut o.checkpoints, &mut o.vtk],
        &stop,
        &mut detached,
    );
    for d in &detached {
        eprintln!("error: {d}");
        code = ExitCode::from(3);
    }
    match end {
        RunEnd::Finished => {}
        RunEnd::OutputFailed { after } => {
            let text = format!("an output cannot be written: the run stops after step {after}");
            eprintln!("{text}");
            if let Some(rec) = o.recorder.as_mut() {
                let _ = rec.event(&text, "ERROR");
            }
            code = ExitCode::from(3);
        }
        RunEnd::Failed(f) => code = fail(1, f),
        RunEnd::Stopped { after } => {
            // The last good state, to resume from.
            if let Some(c) = o.checkpoints.as_mut() {
                match c.write(sim) {
                    Ok(p) => eprintln!("checkpoint of step {after}: {}", p.display()),
                    Err(e) => eprintln!("error: {e}"),
                }
            }
            let text = format!("interrupted after step {after}: the run stops here");
            eprintln!("{text}");
            if let Some(rec) = o.recorder.as_mut() {
                let _ = rec.event(&text, "WARN");
            }
            code = ExitCode::from(130);
        }
    }
    code
}
