//! What every command that runs a scene does first: load it within the
//! memory budget, start its threads, and stop cleanly on a signal.

use mpmlab::model::Limits;
use mpmlab::scene::Scene;
use mpmlab::simulation::Simulation;
use mpmlab::Model;
use std::path::Path;
use std::process::ExitCode;

/// `error: {e}` on stderr and the exit status `code` (2 bad input, 3 an
/// output that cannot be written).
pub fn fail(code: u8, e: impl std::fmt::Display) -> ExitCode {
    eprintln!("error: {e}");
    ExitCode::from(code)
}

/// A flag set by the first SIGINT or SIGTERM; a second one ends the process
/// at once with status 130. Handed to [`mpmlab::runner::run`], which cancels
/// the running step when it is set.
pub fn stop_on_signals() -> std::sync::Arc<std::sync::atomic::AtomicBool> {
    let flag = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        let _ = signal_hook::flag::register_conditional_shutdown(sig, 130, flag.clone());
        let _ = signal_hook::flag::register(sig, flag.clone());
    }
    flag
}

/// `--threads`: start them, say so (unless `quiet`), or exit 2 naming why not.
pub fn use_threads(sim: &mut Simulation, threads: Option<usize>, quiet: bool) -> Result<(), ExitCode> {
    let Some(n) = threads else { return Ok(()) };
    match sim.set_threads(n) {
        Ok(k) if !quiet => {
            use mpmlab::scene::AnalysisKind;
            let work = match sim.model().analysis.kind {
                AnalysisKind::ExplicitDynamics => "the points' material updates",
                AnalysisKind::QuasiStaticLinear => "the tangent's blocks (the factorisation and solve run on one)",
                _ => "the points' material updates and the tangent's blocks (the factorisation and solve run on one)",
            };
            println!("threads: {k} for {work}");
            Ok(())
        }
        Ok(_) => Ok(()),
        Err(e) => Err(fail(2, format!("--threads: {e}"))),
    }
}

/// The scene at `path` and its text; exit 2 (the cause on stderr) when it
/// cannot be read, parsed or built within `limits`.
pub fn load(path: &Path, limits: &Limits) -> Result<(Simulation, String), ExitCode> {
    let (scene, text) = Scene::load(path).map_err(|e| fail(2, e))?;
    let model = Model::build_with(&scene, &text, &path.display().to_string(), limits).map_err(|e| fail(2, e))?;
    Ok((Simulation::new(model), text))
}
