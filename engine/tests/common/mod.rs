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

/// `scene` in other units of length: every length and position times `f`,
/// every prescribed displacement with them; stresses, tractions and moduli
/// unchanged, so strains and stresses are those of the original and its
/// displacements those times `f`. For the regions, supports, boundaries and
/// exact solutions the unit tests scale; anything else (gravity, whose
/// stresses grow with length) panics rather than being left unscaled.
pub fn scale_lengths(scene: &mut Scene, f: f64) {
    use mpmlab_engine::scene::{ExactSpec, RegionSpec};
    let p = |x: [f64; 2]| [f * x[0], f * x[1]];
    fn region(r: &mut RegionSpec, f: f64) {
        let p = |x: &mut [f64; 2]| *x = [f * x[0], f * x[1]];
        match r {
            RegionSpec::Rectangle { min, max } => {
                p(min);
                p(max);
            }
            RegionSpec::Polygon { vertices } => vertices.iter_mut().for_each(p),
            RegionSpec::Rotated {
                about, region: inner, ..
            } => {
                p(about);
                region(inner, f);
            }
            other => panic!("scale_lengths: region {other:?} is not scaled"),
        }
    }
    assert!(
        scene.loads.gravity.is_none() && scene.loads.point.is_empty(),
        "scale_lengths: loads are not scaled"
    );
    scene.grid.origin = p(scene.grid.origin);
    scene.grid.size = p(scene.grid.size);
    scene.grid.h *= f;
    for b in &mut scene.bodies {
        region(&mut b.region, f);
    }
    for b in &mut scene.boundaries {
        if let Some(points) = &mut b.points {
            points.iter_mut().for_each(|x| *x = p(*x));
        }
    }
    for d in &mut scene.dirichlet {
        d.x = d.x.map(|x| f * x);
        d.y = d.y.map(|y| f * y);
        d.node = d.node.map(p);
        d.displacement = d.displacement.map(p);
        d.normal_displacement = d.normal_displacement.map(|u| f * u);
    }
    for b in &mut scene.ibm {
        b.points.iter_mut().for_each(|x| *x = p(*x));
        b.displacement = b.displacement.map(p);
        b.normal_displacement = b.normal_displacement.map(|u| f * u);
    }
    match &mut scene.exact {
        None => {}
        Some(ExactSpec::ConfinedY { base, about, .. }) => {
            *base *= f;
            *about = p(*about);
        }
        Some(other) => panic!("scale_lengths: exact solution {other:?} is not scaled"),
    }
    scene.probes.clear();
}

/// A cutback's sub-increment `part = (from, to)` of the increment
/// `whole = (start, size)` (load factor or time): it spans `size / 2^j`
/// with `1 <= j <= max_depth`, starts on that binary grid from `start`
/// (both to `tol`, relative to the part) and stays inside the increment
/// (to round-off, 1e-12 of `size`). Halving from the last good state
/// gives nothing else.
pub fn assert_binary_part(part: (f64, f64), whole: (f64, f64), max_depth: usize, tol: f64, what: &str) {
    let ((from, to), (start, size)) = (part, whole);
    let j = (size / (to - from)).log2();
    let k = (from - start) / (to - from);
    assert!(
        (j - j.round()).abs() < tol && (1.0..=max_depth as f64).contains(&j.round()),
        "{what}: {from} -> {to} is not {size} / 2^j, j <= {max_depth}"
    );
    assert!(
        (k - k.round()).abs() < tol && from >= start - 1e-12 * size && to <= start + size + 1e-12 * size,
        "{what}: {from} -> {to} is not on {size} / 2^j's grid from {start}"
    );
}

/// How many saved failure seeds proptest loads for the test module at
/// `source` (its `file!()`), the way a run of its `proptest!` tests loads
/// them before new cases: from `proptest-regressions/` beside the test
/// binary's `main.rs` folder (`engine/tests/proptest-regressions/NAME.txt`).
pub fn saved_seeds(source: &'static str) -> usize {
    use proptest::test_runner::{FailurePersistence, FileFailurePersistence};
    FileFailurePersistence::SourceParallel("proptest-regressions")
        .load_persisted_failures2(Some(source))
        .len()
}

/// Every field a step updates, per point, as bits: equal vectors are the
/// same state bit for bit. A field a kind of run does not keep (velocities
/// in a quasi-static run, GIMP domains of standard points) is empty and
/// adds nothing.
pub fn point_bits(sim: &Simulation) -> Vec<u64> {
    let p = sim.points();
    let mut bits = Vec::new();
    for i in 0..p.len() {
        let pairs = [p.x.get(i), p.v.get(i), p.lp.get(i)];
        let tensors = [
            p.stress.get(i).map(|v| &v[..]),
            p.strain.get(i).map(|v| &v[..]),
            p.def_grad.get(i).map(|v| &v[..]),
            p.b_e.get(i).map(|v| &v[..]),
        ];
        let scalars = [p.vol.get(i), p.szz.get(i), p.dissipation.get(i)];
        let values = pairs
            .into_iter()
            .flatten()
            .flat_map(|v| v.iter())
            .chain(tensors.into_iter().flatten().flatten())
            .chain(scalars.into_iter().flatten());
        bits.extend(values.map(|v| v.to_bits()));
        bits.extend(p.yielding.get(i).map(|&y| y as u64));
    }
    bits
}
