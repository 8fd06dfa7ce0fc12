//! The `mpmlab` command line: run scenes headless, check them, list them,
//! or step them in the terminal UI. Each command is a module of [`cli`].

mod cli;

use clap::Parser;
use cli::args::{limits, Cli, Cmd, TuiArgs};
use std::process::ExitCode;

/// Exit codes: 0 success, 1 a step failed, 2 bad input, 3 an output cannot
/// be created or written (the run stops after the step),
/// 130 interrupted (Ctrl-C or SIGTERM; the recording is closed cleanly; a
/// second signal ends the process at once, and `mpmlab repair` closes the
/// recording it leaves).
fn main() -> ExitCode {
    let result = match Cli::parse().command {
        Some(Cmd::Run(args)) => cli::run::run(&args),
        Some(Cmd::Check { scene, max_memory }) => cli::check::check(&scene, &limits(max_memory)),
        Some(Cmd::List { dir }) => cli::check::list(&dir),
        Some(Cmd::Sweep(args)) => cli::sweep::sweep(args),
        Some(Cmd::SweepRun { scene, result, record }) => cli::sweep::sweep_run(&scene, &result, record.as_deref()),
        Some(Cmd::Replay { recording }) => cli::replay::replay(&recording),
        Some(Cmd::Verify(args)) => cli::verify::verify(&args),
        Some(Cmd::Repair { input, output, force }) => Ok(cli::repair::repair(&input, &output, force)),
        Some(Cmd::Tui(args)) => cli::tui::tui(&args),
        Some(Cmd::RepairProbe { input }) => Ok(cli::repair::probe(&input)),
        None => cli::tui::tui(&TuiArgs::default()),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
