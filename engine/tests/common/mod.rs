//! Helpers shared by the integration tests of both crates: the engine's
//! (`engine/tests/physics`) and, through `tests/common`, the front end's.
#![allow(dead_code)]

use mpmlab_engine::scene::Scene;
use mpmlab_engine::{Model, Simulation, StepReport};
use std::path::PathBuf;

/// Path of a shipped scene (the workspace's `scenarios/`, whichever crate
/// the test belongs to).
pub fn scene_path(name: &str) -> PathBuf {
    let crate_dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let scenarios = crate_dir
        .ancestors()
        .map(|d| d.join("scenarios"))
        .find(|d| d.is_dir())
        .expect("a `scenarios` folder above the crate");
    scenarios.join(format!("{name}.toml"))
}

/// Parse a shipped scene, let `edit` change it, build and return the simulation.
pub fn sim_with(name: &str, edit: impl FnOnce(&mut Scene)) -> Simulation {
    let path = scene_path(name);
    let text = std::fs::read_to_string(&path).unwrap();
    let mut scene = Scene::parse(&text, name).unwrap();
    edit(&mut scene);
    Simulation::new(Model::build(&scene, &text, name).unwrap())
}

/// Run every load step, panicking on failure.
pub fn run_all(sim: &mut Simulation) -> StepReport {
    let mut last = None;
    while !sim.finished() {
        last = Some(sim.step().unwrap_or_else(|f| panic!("{f}")));
    }
    last.unwrap()
}

pub fn error(r: &StepReport, name: &str) -> f64 {
    r.errors
        .iter()
        .find(|e| e.name == name)
        .unwrap_or_else(|| panic!("no error `{name}`"))
        .value
}
