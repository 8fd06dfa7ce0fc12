//! # mpmlab's engine: the implicit material point method with boundaries that do not follow the grid
//!
//! A scene file (TOML) becomes a [`scene::Scene`], is validated into a
//! [`model::Model`] (grid, materials, bodies filled with material points,
//! boundary conditions, loads), and a [`simulation::Simulation`] advances it
//! one load step at a time. Each step:
//!
//! 1. map the points to the grid (stencils of the standard or GIMP basis,
//!    active nodes, dof numbering) — [`assembly::Mapping`];
//! 2. assemble the reduced stiffness and the out-of-balance force — [`assembly::Pattern`];
//! 3. factorise (sparse Cholesky, faer) — [`linalg`];
//! 4. solve for the nodal increments, check the residual;
//! 5. update point strains, stresses, positions and volumes, forget the grid.
//!
//! A step returns a [`simulation::StepReport`] (residuals, timings, energies,
//! condition number, errors against the exact solution) or a
//! [`simulation::StepFailure`]. Observers — the terminal UI, the rerun
//! recorder and the ParaView series of the `mpmlab` crate, and the tests —
//! follow a run through [`runner::Observer`] and only read reports and
//! state. This crate does not depend on them or on their libraries
//! (ratatui, rerun, vtkio, clap): the compiler keeps the engine apart.

pub mod assembly;
pub mod basis;
pub mod boundary;
pub mod bulk;
pub mod checkpoint;
mod cutback;
pub mod dynamics;
pub mod exact;
pub mod field;
pub mod geometry;
pub mod ghost;
pub mod grid;
pub mod ibm;
mod implicit;
pub mod kinematics;
pub mod linalg;
pub mod linear;
pub mod material;
pub mod model;
mod newmark;
mod newton;
pub mod points;
pub mod probe;
pub mod procfs;
pub mod quadrature;
pub mod report;
pub mod runner;
pub mod scene;
pub mod simulation;
pub mod solver;
pub mod state;
pub mod units;
mod vector_state;
pub mod verify;

pub use model::Model;
pub use simulation::{Params, Simulation, Snapshot, StepFailure, StepReport};
