//! The engine's tests in one test binary (`cargo test --release -p
//! mpmlab-engine --test physics`; one module with `... --test physics
//! ibm::`): the method's mathematics, every paper scene and the operators.
//! One binary instead of fourteen: each test binary links the engine's
//! whole dependency tree, so a change to the engine relinks one binary, not
//! fourteen, which is what makes CI's rebuild and a mutation run's build
//! short.

#[path = "../common/mod.rs"]
mod common;

mod basis;
mod boundary_scenes;
mod bspline;
mod column;
mod dynamics;
mod engine;
mod exact;
mod fe_equivalence;
mod finite;
mod golden;
mod hencky;
mod ibm;
mod locking;
mod newmark;
mod operators;
mod patch;
mod points;
mod probes;
mod threads;
