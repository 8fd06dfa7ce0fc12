//! # mpmlab: the implicit material point method with boundaries that do not follow the grid
//!
//! The engine (scenes, models, the step, solvers, checkpoints, the runner)
//! is the `mpmlab-engine` crate, re-exported here under the same paths
//! (`mpmlab::scene`, `mpmlab::Simulation`, ...). This crate holds what
//! follows a run: the terminal UI ([`tui`]), the rerun recorder
//! ([`record`]), the ParaView series ([`vtk`]), the probes' CSV files
//! ([`csv`]), how output files are written safely ([`output`]) and
//! parameter sweeps ([`sweep`]), with the formatters they share
//! ([`format`]). They only read reports and state through
//! [`runner::Observer`]; the engine cannot import them (it does not depend
//! on this crate or its libraries).

// Every public module and item of the engine, so a module the engine
// adds is here without a list to keep.
pub use mpmlab_engine::*;

pub mod colormap;
pub mod csv;
pub mod format;
pub mod output;
pub mod record;
pub mod shipped;
pub mod sweep;
pub mod tui;
pub mod vtk;
