//! The terminal UI: the engine runs on its own thread, the UI thread draws
//! and reads keys, and they talk over channels, so the screen stays
//! responsive while a step computes.
//!
//! - [`app`]: state and actions (no terminal);
//! - [`draw`]: pure rendering of an [`app::App`];
//! - this module: the event loop and the engine thread.

pub mod app;
pub mod draw;
pub mod picker;
pub mod sweep;

use crate::field::Field;
use crate::record::Recorder;
use crate::runner;
use crate::simulation::Simulation;
use crate::units::Quantity;
use app::{Action, App, Command, Update, View};
use ratatui::crossterm::event::{
    self, DisableMouseCapture, EnableMouseCapture, Event, KeyCode, KeyEventKind, MouseEventKind,
};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::Duration;

/// Map a key to an action.
pub fn action_for(code: KeyCode) -> Option<Action> {
    match code {
        KeyCode::Char(' ') => Some(Action::Step),
        KeyCode::Char('?') => Some(Action::ToggleHelp),
        KeyCode::Char('f') => Some(Action::NextField),
        KeyCode::Char('c') => Some(Action::ToggleControlPoints),
        KeyCode::Char('G') => Some(Action::RaiseGammaK),
        KeyCode::Char('g') => Some(Action::LowerGammaK),
        KeyCode::Char('0') => Some(Action::ToggleGhost),
        KeyCode::Char('D') => Some(Action::RaiseDelta),
        KeyCode::Char('d') => Some(Action::LowerDelta),
        KeyCode::Char('M') => Some(Action::RaiseGammaM),
        KeyCode::Char('m') => Some(Action::LowerGammaM),
        KeyCode::Enter => Some(Action::RunPause),
        KeyCode::Char('+') | KeyCode::Char('=') => Some(Action::ZoomIn),
        KeyCode::Char('-') => Some(Action::ZoomOut),
        KeyCode::Char('z') => Some(Action::ResetView),
        KeyCode::Left | KeyCode::Char('h') => Some(Action::PanLeft),
        KeyCode::Right | KeyCode::Char('l') => Some(Action::PanRight),
        KeyCode::Up | KeyCode::Char('k') => Some(Action::PanUp),
        KeyCode::Down | KeyCode::Char('j') => Some(Action::PanDown),
        KeyCode::Char('v') => Some(Action::NextChart),
        KeyCode::Char('p') => Some(Action::NextProbeY),
        KeyCode::Char('w') => Some(Action::Checkpoint),
        KeyCode::Char('V') => Some(Action::ToggleVtk),
        KeyCode::Char('P') => Some(Action::NextProbeX),
        KeyCode::Char('r') => Some(Action::Redo),
        KeyCode::Char('x') => Some(Action::Cancel),
        KeyCode::Char('T') => Some(Action::RaiseTolerance),
        KeyCode::Char('t') => Some(Action::LowerTolerance),
        KeyCode::Char(':') => Some(Action::OpenInput),
        KeyCode::Char('#') => Some(Action::ToggleGrid),
        KeyCode::Char('a') => Some(Action::ToggleActive),
        KeyCode::Char('o') => Some(Action::ToggleGhostFaces),
        KeyCode::Char('L') => Some(Action::ToggleLegend),
        KeyCode::Esc => Some(Action::CloseOverlay),
        KeyCode::Char('q') => Some(Action::Quit),
        _ => None,
    }
}

/// Apply new parameters (from the next step), log the change as a
/// recording event and tell the UI.
fn set_params(
    sim: &mut Simulation,
    recorder: &mut Option<Recorder>,
    updates: &mpsc::Sender<Update>,
    params: crate::simulation::Params,
    event: &str,
) {
    sim.set_params(params.clone());
    for m in runner::note(&mut [recorder], event, "INFO") {
        let _ = updates.send(Update::Message(m));
    }
    let _ = updates.send(Update::Params(params));
}

/// The parameters with a `Set...` command's change, and the change in
/// words (`None` for any other command).
fn changed_params(sim: &Simulation, cmd: &Command) -> Option<(crate::simulation::Params, String)> {
    let mut params = sim.params().clone();
    let what = match *cmd {
        Command::SetGammaK(g) => {
            params.gamma_k = g;
            format!("gamma_K = {g:e} {}", sim.model().units.of(Quantity::Stress))
        }
        Command::SetDeltaOverH(d) => {
            params.delta_over_h = d;
            format!("delta/h = {d:e}")
        }
        Command::SetGammaM(g) => {
            params.gamma_m = g;
            format!("gamma_M = {g:e} {}", sim.model().units.of(Quantity::Density))
        }
        Command::SetTolerance(t) => {
            params.tolerance = t;
            format!("tolerance = {t:e}")
        }
        Command::SetMaxIterations(n) => {
            params.max_iterations = n;
            format!("max_iterations = {n}")
        }
        _ => return None,
    };
    Some((params, what))
}

/// `w`: a checkpoint of the current state into `checkpoints/`; what
/// happened, in words.
fn write_checkpoint(sim: &Simulation, scene_text: &str) -> String {
    let dir = std::path::Path::new("checkpoints");
    let path = dir.join(format!(
        "{}-step-{:06}.ckpt",
        crate::output::safe_stem(&sim.model().name),
        sim.step_index()
    ));
    let result = std::fs::create_dir_all(dir)
        .map_err(|e| format!("cannot create {}: {e}", dir.display()))
        .and_then(|_| sim.save_checkpoint(&path, scene_text).map_err(|e| e.to_string()));
    match result {
        Ok(()) => format!(
            "checkpoint of step {} written to {} (continue from it: mpmlab tui SCENE --resume {})",
            sim.step_index(),
            path.display(),
            path.display()
        ),
        Err(e) => e,
    }
}

/// `V`: start a ParaView series from the current step, or close the one
/// being written; what happened, in words.
fn toggle_vtk(sim: &Simulation, vtk: &mut Option<crate::vtk::VtkExport>) -> String {
    match vtk.take() {
        Some(v) => match v.finish(sim) {
            Ok(summary) => format!("ParaView series closed: {summary}"),
            Err(e) => e.to_string(),
        },
        None => {
            let dir = std::path::PathBuf::from(format!(
                "vtk/{}-from-step-{}",
                crate::output::safe_stem(&sim.model().name),
                sim.step_index()
            ));
            match crate::vtk::VtkExport::create(&dir, sim, 1, false) {
                Ok(v) => {
                    *vtk = Some(v);
                    format!(
                        "ParaView series: every step from here into {} (V stops; open points.pvd)",
                        dir.display()
                    )
                }
                Err(e) => e.to_string(),
            }
        }
    }
}

/// The engine thread: steps the simulation, records, reports back.
fn engine(
    mut sim: Simulation,
    scene_text: String,
    mut recorder: Option<Recorder>,
    commands: mpsc::Receiver<Command>,
    updates: mpsc::Sender<Update>,
    cancel: Arc<AtomicBool>,
) {
    // Stream residuals to the UI; the UI's cancel flag stops a step.
    {
        let (tx, cancel) = (updates.clone(), cancel.clone());
        sim.set_progress(Some(Box::new(move |p| {
            let _ = tx.send(Update::Progress(p.clone()));
            !cancel.load(Ordering::SeqCst)
        })));
    }
    sim.set_cancel(Some(cancel.clone()));
    let mut field = Field::SigmaYy;
    // A ParaView series the user asked for (`V`), written step by step.
    let mut vtk: Option<crate::vtk::VtkExport> = None;
    // The state before the last step and that step's outcome, for redo.
    let mut before: Option<(crate::simulation::Snapshot, Option<app::Outcome>)> = None;
    let tell = |updates: &mpsc::Sender<Update>, detached: Vec<String>| {
        for m in detached {
            let _ = updates.send(Update::Message(m));
        }
    };
    while let Ok(cmd) = commands.recv() {
        match cmd {
            Command::Cancel => {}
            Command::Step => {
                cancel.store(false, Ordering::SeqCst);
                let snap = sim.snapshot();
                let s = runner::step(&mut sim, &mut [&mut recorder, &mut vtk]);
                tell(&updates, s.detached);
                before = Some((snap, Some(s.result.clone())));
                let _ = updates.send(match s.result {
                    Ok(report) => Update::Stepped(Box::new(report), Box::new(View::of(&sim, field))),
                    Err(failure) => Update::Failed(failure),
                });
            }
            Command::Redo => {
                let Some((snap, Some(old))) = before.take() else {
                    let _ = updates.send(Update::Message("no step to redo".into()));
                    continue;
                };
                sim.restore(&snap);
                cancel.store(false, Ordering::SeqCst);
                let p = sim.params();
                let text = format!(
                    "redo of step {} with gamma_K = {:e}, delta/h = {:e}, gamma_M = {:e}, tolerance = {:e}",
                    sim.step_index() + 1,
                    p.gamma_k,
                    p.delta_over_h,
                    p.gamma_m,
                    p.tolerance
                );
                tell(&updates, runner::note(&mut [&mut recorder], &text, "INFO"));
                let s = runner::step(&mut sim, &mut [&mut recorder, &mut vtk]);
                tell(&updates, s.detached);
                let new = s.result;
                before = Some((snap, Some(new.clone())));
                let _ = updates.send(Update::Redone(Box::new((old, new)), Box::new(View::of(&sim, field))));
            }
            Command::SetField(f) => {
                field = f;
                let _ = updates.send(Update::View(Box::new(View::of(&sim, field))));
            }
            Command::SetGammaK(_)
            | Command::SetDeltaOverH(_)
            | Command::SetGammaM(_)
            | Command::SetTolerance(_)
            | Command::SetMaxIterations(_) => {
                let Some((params, what)) = changed_params(&sim, &cmd) else {
                    continue; // not a parameter (matched above)
                };
                let text = format!("parameter: {what} from step {}", sim.step_index() + 1);
                set_params(&mut sim, &mut recorder, &updates, params, &text);
            }
            Command::Checkpoint => {
                let text = write_checkpoint(&sim, &scene_text);
                tell(&updates, runner::note(&mut [&mut recorder], &text, "INFO"));
                let _ = updates.send(Update::Message(text));
            }
            Command::ToggleVtk => {
                let text = toggle_vtk(&sim, &mut vtk);
                tell(&updates, runner::note(&mut [&mut recorder], &text, "INFO"));
                let _ = updates.send(Update::Message(text));
            }
            Command::Quit => break,
        }
    }
    if let Some(v) = vtk {
        let _ = v.finish(&sim);
    }
    if let Some(mut rec) = recorder {
        // The state the session ended on, whatever the cadence.
        let _ = rec.log_final_state(&sim);
        let _ = rec.event("end of interactive session", "INFO");
        let _ = rec.finish();
    }
}

/// Run the TUI on a simulation until the user quits. `recorder` receives
/// every step. The terminal is restored on exit and on panic.
/// `scene_text` is the scene file's text (checkpoints, `w`, keep its hash).
pub fn run(sim: Simulation, scene_text: String, recorder: Option<Recorder>) -> std::io::Result<()> {
    let mut app = App::new(
        &sim,
        recorder.as_ref().map(|r| {
            format!(
                "{} (written as .partial until the session ends; points {})",
                r.path().display(),
                r.points_cadence()
            )
        }),
    );
    let (cmd_tx, cmd_rx) = mpsc::channel();
    let cancel = Arc::new(AtomicBool::new(false));
    let (up_tx, up_rx) = mpsc::channel();
    let worker = std::thread::Builder::new().name("mpmlab-engine".into()).spawn({
        let cancel = cancel.clone();
        move || engine(sim, scene_text, recorder, cmd_rx, up_tx, cancel)
    })?;
    // ratatui::init installs a panic hook that restores the terminal.
    let mut terminal = ratatui::init();
    let _ = ratatui::crossterm::execute!(std::io::stdout(), EnableMouseCapture);
    let result = (|| -> std::io::Result<()> {
        // Redraw only when something changed: an update or an input.
        let mut dirty = true;
        while !app.quit {
            while let Ok(u) = up_rx.try_recv() {
                // A caught engine panic has run ratatui's panic hook, which
                // restored the terminal: take it back.
                let reinit = match &u {
                    Update::Failed(f) => matches!(f, crate::simulation::StepFailure::Internal { .. }),
                    Update::Redone(o, _) => matches!(o.1, Err(crate::simulation::StepFailure::Internal { .. })),
                    _ => false,
                };
                app.update(u);
                dirty = true;
                if reinit {
                    terminal = ratatui::init();
                    let _ = ratatui::crossterm::execute!(std::io::stdout(), EnableMouseCapture);
                }
            }
            if let Some(cmd) = app.pending() {
                let _ = cmd_tx.send(cmd);
            }
            if dirty {
                terminal.draw(|f| draw::draw(f, &app))?;
                dirty = false;
            }
            // While running, come back quickly for the next step's update.
            let wait = if app.running { 2 } else { 50 };
            if event::poll(Duration::from_millis(wait))? {
                dirty = true;
                let action = match event::read()? {
                    // The parameter prompt takes the keys while it is open.
                    Event::Key(k) if k.kind == KeyEventKind::Press && app.input.is_some() => match k.code {
                        KeyCode::Char(c) => Some(Action::Type(c)),
                        KeyCode::Backspace => Some(Action::Backspace),
                        KeyCode::Enter => Some(Action::Submit),
                        KeyCode::Esc => Some(Action::CloseOverlay),
                        _ => None,
                    },
                    Event::Key(k) if k.kind == KeyEventKind::Press => action_for(k.code),
                    // The mouse wheel zooms the canvas.
                    Event::Mouse(m) => match m.kind {
                        MouseEventKind::ScrollUp => Some(Action::ZoomIn),
                        MouseEventKind::ScrollDown => Some(Action::ZoomOut),
                        _ => None,
                    },
                    _ => None,
                };
                match action.and_then(|a| app.apply(a)) {
                    // The engine is busy with the step: tell it through the flag.
                    Some(Command::Cancel) => cancel.store(true, Ordering::SeqCst),
                    Some(cmd) => {
                        let _ = cmd_tx.send(cmd);
                    }
                    None => {}
                }
            }
        }
        Ok(())
    })();
    let _ = ratatui::crossterm::execute!(std::io::stdout(), DisableMouseCapture);
    ratatui::restore();
    // Stop a running step at its next residual, then close the recording.
    cancel.store(true, Ordering::SeqCst);
    let _ = cmd_tx.send(Command::Quit);
    drop(cmd_tx);
    let _ = worker.join();
    result
}
