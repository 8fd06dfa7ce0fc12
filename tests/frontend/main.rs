//! The front end's tests in one test binary (`cargo test --release -p
//! mpmlab --test frontend`; one module with `... --test frontend vtk::`):
//! the command line, hostile input, outputs, recordings, sweeps, the TUI
//! and ParaView files. One binary instead of eight: each test binary links
//! the front end's whole dependency tree (the rerun SDK among them), so a
//! change relinks one binary, not eight.

#[path = "../common/mod.rs"]
mod common;

mod cli;
mod hostile;
mod outputs;
mod recording;
mod sweep;
mod tui;
mod tui_e2e;
mod vtk;
