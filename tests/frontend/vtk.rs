//! `mpmlab run --vtk DIR`: the ParaView series read back by readers that
//! share no code with the writer (meshio for the points, Python's XML
//! parser for the collections, boundaries and grid: `tests/frontend/vtk_read.py`)
//! and by vtkio's own reader, and compared with the engine's state at
//! every step, run in this process from the same scene text.
//!
//! Without python3 and meshio these tests fail when `CI` is set (`.ci/run`
//! installs meshio) and are skipped with a message otherwise.

use crate::common;
use crate::common::mpmlab;
use mpmlab::field::Field;
use mpmlab::scene::Scene;
use mpmlab::{Model, Simulation};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A fresh folder for a test's files.
fn temp_dir(stem: &str) -> common::TempPath {
    let d = common::temp_path(&format!("vtk-{stem}"), "d");
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Write `text` as a scene in `dir` and run it with a series into
/// `dir/series` every `every` steps: the folder, exit code, stdout, stderr.
fn run_series(dir: &Path, text: &str, every: usize) -> (PathBuf, i32, String, String) {
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, text).unwrap();
    let out = dir.join("series");
    let every = every.to_string();
    let (code, stdout, err) = mpmlab(&[
        "run",
        scene.to_str().unwrap(),
        "--quiet",
        "--vtk",
        out.to_str().unwrap(),
        "--vtk-every",
        &every,
    ]);
    (out, code, stdout, err)
}

/// A shipped scene's text with replacements (each must apply).
fn scene_text(name: &str, edits: &[(&str, &str)]) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("scenarios/{name}.toml"));
    let mut text = std::fs::read_to_string(path).unwrap();
    for (from, to) in edits {
        assert!(text.contains(from), "{name}: {from}");
        text = text.replacen(from, to, 1);
    }
    text
}

fn simulation(text: &str) -> Simulation {
    let scene = Scene::parse(text, "test").unwrap();
    Simulation::new(Model::build(&scene, text, "test").unwrap())
}

/// A polyline read back: its cell data (`name=value,...`) and its points.
type Line = (String, Vec<[f64; 2]>);

/// What `tests/frontend/vtk_read.py` found in a folder.
#[derive(Default, Debug)]
struct Read {
    /// kind -> [(step, timestep)] in collection order.
    pvd: BTreeMap<String, Vec<(usize, f64)>>,
    points: BTreeMap<usize, usize>,
    /// (step, array name) -> values, flattened.
    arrays: BTreeMap<(usize, String), Vec<f64>>,
    /// (kind, step) -> polylines: (cell data, points).
    lines: BTreeMap<(String, usize), Vec<Line>>,
    /// step -> (nx, ny, active cells, x0, y0, h).
    grid: BTreeMap<usize, (usize, usize, usize, f64, f64, f64)>,
    nonfinite: usize,
}

/// Read `dir` with the independent readers; `None` (skip) when python3 or
/// meshio is missing outside CI.
fn read(dir: &Path) -> Option<Read> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/frontend/vtk_read.py");
    let out = Command::new("python3").arg(&script).arg(dir).output();
    let missing = match &out {
        Err(e) => Some(format!("python3 cannot be started: {e}")),
        Ok(o) if o.status.code() == Some(3) => Some(String::from_utf8_lossy(&o.stderr).into_owned()),
        Ok(_) => None,
    };
    if let Some(why) = missing {
        assert!(
            std::env::var_os("CI").is_none(),
            "the VTK files are checked with python3 and meshio: {why} (.ci/run installs them with `python3 -m pip install meshio`)"
        );
        eprintln!("skipped: {why}");
        return None;
    }
    let out = out.unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mut r = Read::default();
    for line in String::from_utf8(out.stdout).unwrap().lines() {
        let w: Vec<&str> = line.split(' ').collect();
        let f = |s: &str| s.parse::<f64>().unwrap();
        let u = |s: &str| s.parse::<usize>().unwrap();
        match w[0] {
            "pvd" => r.pvd.entry(w[1].into()).or_default().push((u(w[2]), f(w[3]))),
            "points" => {
                r.points.insert(u(w[1]), u(w[2]));
            }
            "array" => {
                r.arrays
                    .insert((u(w[1]), w[2].into()), w[3..].iter().map(|s| f(s)).collect());
            }
            "line" => {
                let pts = w[5..].chunks(2).map(|c| [f(c[0]), f(c[1])]).collect();
                r.lines
                    .entry((w[1].into(), u(w[2])))
                    .or_default()
                    .push((w[4].into(), pts));
            }
            "grid" => {
                r.grid
                    .insert(u(w[1]), (u(w[2]), u(w[3]), u(w[4]), f(w[5]), f(w[6]), f(w[7])));
            }
            "nonfinite" => r.nonfinite = u(w[1]),
            _ => {}
        }
    }
    Some(r)
}

/// Compare an array read back with the engine's values. The arrays are
/// written as binary Float64, which round-trips exactly, so the only
/// difference allowed is between two runs of the same scene (this process
/// and the `mpmlab` process): 1e-12 relative to the array's largest value.
fn same(what: &str, read: &[f64], engine: &[f64]) {
    assert_eq!(read.len(), engine.len(), "{what}: length");
    let scale = engine.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
    for (i, (a, b)) in read.iter().zip(engine).enumerate() {
        assert!((a - b).abs() <= 1e-12 * scale, "{what}[{i}]: read {a}, engine {b}");
    }
}

/// Everything the engine holds at its current step against what was read.
fn check_state(r: &Read, sim: &Simulation) {
    let step = sim.step_index();
    let pts = sim.points();
    assert_eq!(r.points.get(&step), Some(&pts.len()), "points at step {step}");
    let arr = |name: &str| {
        r.arrays
            .get(&(step, name.to_string()))
            .unwrap_or_else(|| panic!("no array {name} at step {step}"))
    };
    let xs: Vec<f64> = pts.x.iter().map(|x| x[0]).collect();
    let ys: Vec<f64> = pts.x.iter().map(|x| x[1]).collect();
    same("x", arr("x"), &xs);
    same("y", arr("y"), &ys);
    assert!(arr("z").iter().all(|&z| z == 0.0));
    for f in Field::ALL {
        same(f.key(), arr(f.key()), &f.values(sim));
    }
    let u: Vec<f64> = (0..pts.len())
        .flat_map(|p| {
            let d = pts.displacement(p);
            [d[0], d[1], 0.0]
        })
        .collect();
    same("displacement", arr("displacement"), &u);
    // Quasi-static runs keep no velocities: the file holds zeros.
    let v: Vec<f64> = (0..pts.len())
        .flat_map(|p| {
            let v = pts.velocity(p);
            [v[0], v[1], 0.0]
        })
        .collect();
    same("velocity", arr("velocity"), &v);
    // The stress tensor's in-plane components, row-major (xx, xy, yx, yy).
    let stress = arr("stress");
    for (k, (c, i)) in [(0, 0), (1, 2), (3, 2), (4, 1)].into_iter().enumerate() {
        let read: Vec<f64> = stress.iter().skip(c).step_by(9).copied().collect();
        let engine: Vec<f64> = pts.stress.iter().map(|s| s[i]).collect();
        same(&format!("stress component {k}"), &read, &engine);
    }
    same("volume", arr("volume"), &pts.vol);
    same("mass", arr("mass"), &pts.mass);
    let body: Vec<f64> = pts.body.iter().map(|&b| b as f64).collect();
    same("body", arr("body"), &body);

    let g = &sim.model().grid;
    let (nx, ny, active, x0, y0, h) = r.grid[&step];
    assert_eq!(
        (nx, ny, active),
        (g.nx, g.ny, sim.active_cells().len()),
        "grid at step {step}"
    );
    assert_eq!((x0, y0, h), (g.origin[0], g.origin[1], g.h));

    // B-spline boundaries: 16 samples per segment through the current points.
    if !sim.model().boundaries.is_empty() {
        let lines = &r.lines[&("boundaries".to_string(), step)];
        let splines: Vec<_> = sim.boundary_splines().into_iter().filter_map(|(_, s)| s).collect();
        assert_eq!(lines.len(), splines.len());
        for ((_, read), s) in lines.iter().zip(&splines) {
            let engine = s.sample(mpmlab::vtk::SAMPLES_PER_SEGMENT);
            assert_eq!(read.len(), s.segments.len() * 16 + 1);
            same("boundary curve", &read.concat(), &engine.concat());
        }
    }
    if !sim.model().ibm.is_empty() {
        let lines = &r.lines[&("ibm".to_string(), step)];
        let ibm = sim.ibm_boundaries();
        assert_eq!(lines.len(), ibm.len());
        for (i, ((data, read), b)) in lines.iter().zip(&ibm).enumerate() {
            assert_eq!(data, &format!("boundary={i}"));
            same("implicit boundary", &read.concat(), &b.points.concat());
        }
    }
}

#[test]
fn every_step_of_a_run_reads_back_as_the_engine_state() {
    // The deep beam has a B-spline boundary and an implicit boundary;
    // three load steps make a series of four states (0..=3).
    let dir = temp_dir("beam");
    let text = scene_text("deep-beam-self-weight", &[("load_steps = 1", "load_steps = 3")]);
    let scene = dir.join("beam.toml");
    std::fs::write(&scene, &text).unwrap();
    let out = dir.join("series");
    let (code, stdout, err) = mpmlab(&[
        "run",
        scene.to_str().unwrap(),
        "--quiet",
        "--vtk",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("vtk: ") && stdout.contains("4 states"), "{stdout}");
    let Some(r) = read(&out) else { return };
    assert_eq!(r.nonfinite, 0);
    for kind in ["points", "grid", "boundaries", "ibm"] {
        let expect: Vec<(usize, f64)> = (0..=3).map(|k| (k, k as f64 / 3.0)).collect();
        assert_eq!(r.pvd[kind], expect, "{kind}.pvd: steps and load factors");
    }
    let mut sim = simulation(&text);
    check_state(&r, &sim);
    while !sim.finished() {
        sim.step().unwrap();
        check_state(&r, &sim);
    }
    // The support on the left (implicit) and the tip (B-spline), both read.
    assert_eq!(r.lines[&("boundaries".to_string(), 3)].len(), 1);
    assert_eq!(r.lines[&("ibm".to_string(), 3)].len(), 1);

    // vtkio's own reader agrees on the last points file.
    let vtk = vtkio::Vtk::import(out.join("points/000003.vtu")).unwrap();
    let vtkio::model::DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
        panic!("not an unstructured grid")
    };
    let vtkio::model::Piece::Inline(piece) = &pieces[0] else {
        panic!("not inline")
    };
    assert_eq!(piece.num_points(), sim.points().len());
    let syy = piece
        .data
        .point
        .iter()
        .find_map(|a| match a {
            vtkio::model::Attribute::DataArray(d) if d.name == "sigma_yy" => d.data.clone().into_vec::<f64>(),
            _ => None,
        })
        .unwrap();
    same("sigma_yy (vtkio)", &syy, &Field::SigmaYy.values(&sim));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn explicit_dynamics_series_is_on_simulated_time_at_a_cadence() {
    // 10 explicit steps of 3.5 ms, every 4th written: 0, 4, 8 and the
    // last (10); timestep = simulated time.
    let dir = temp_dir("explicit");
    let text = scene_text(
        "ghost-collision-elastic",
        &[
            ("duration = 3.5", "duration = 0.035"),
            ("load_steps = 1000", "load_steps = 10"),
        ],
    );
    let (out, code, stdout, err) = run_series(&dir, &text, 4);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("4 states"), "{stdout}");
    let Some(r) = read(&out) else { return };
    let steps: Vec<usize> = r.pvd["points"].iter().map(|s| s.0).collect();
    assert_eq!(steps, [0, 4, 8, 10]);
    let mut sim = simulation(&text);
    for (step, t) in &r.pvd["points"] {
        while sim.step_index() < *step {
            sim.step().unwrap();
        }
        // The time the engine reports, to the last bit of its product.
        assert_eq!(Some(*t), sim.time(), "timestep of step {step}");
        check_state(&r, &sim);
    }
    // The bodies move: the velocities compared above are not all zero.
    assert!(r.arrays[&(10, "speed".to_string())].iter().any(|&v| v > 0.0));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_failed_run_ends_its_series_on_the_last_good_state() {
    // The plain GIMP beam (h = 0.25, 2x2 points) fails at a step round-off
    // picks (see `a_failed_run_leaves_a_readable_recording` in
    // tests/frontend/cli.rs): written every 5 steps, the series holds the
    // multiples of 5 before it and the last good step, and no value of
    // the failed step.
    let dir = temp_dir("failed");
    let text = scene_text(
        "elastic-beam-ghost",
        &[("h = 0.5", "h = 0.25"), ("gamma_k = 12.0e6", "gamma_k = 0.0")],
    );
    let (out, code, _, err) = run_series(&dir, &text, 5);
    assert_eq!(code, 1, "{err}");
    let k = common::failed_step(&err);
    let Some(r) = read(&out) else { return };
    let steps: Vec<usize> = r.pvd["points"].iter().map(|s| s.0).collect();
    let mut expected: Vec<usize> = (0..k).step_by(5).collect();
    if !(k - 1).is_multiple_of(5) {
        expected.push(k - 1);
    }
    assert_eq!(steps, expected);
    assert_eq!(r.nonfinite, 0);
    let mut sim = simulation(&text);
    while sim.step_index() < k - 1 {
        sim.step().unwrap();
    }
    check_state(&r, &sim);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_folder_that_cannot_be_written_is_named_with_its_cause() {
    // A file where the folder should be: exit 3, the path and the cause
    // named, the file left as it was.
    let dir = temp_dir("bad");
    let file = dir.join("not-a-folder");
    std::fs::write(&file, "keep").unwrap();
    let (code, _, err) = mpmlab(&[
        "run",
        "scenarios/patch-compression.toml",
        "--vtk",
        file.to_str().unwrap(),
    ]);
    assert_eq!(code, 3, "{err}");
    assert!(
        err.contains(file.to_str().unwrap()) && err.contains("not a directory"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "keep");
    // A folder under a file: the operating system's cause.
    let below = file.join("series");
    let (code, _, err) = mpmlab(&[
        "run",
        "scenarios/patch-compression.toml",
        "--vtk",
        below.to_str().unwrap(),
    ]);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains(below.to_str().unwrap()), "{err}");
    // A cadence of 0 is refused by the argument parser; --vtk-every needs --vtk.
    let (code, _, _) = mpmlab(&[
        "run",
        "scenarios/patch-compression.toml",
        "--vtk",
        "x",
        "--vtk-every",
        "0",
    ]);
    assert_eq!(code, 2);
    let (code, _, _) = mpmlab(&["run", "scenarios/patch-compression.toml", "--vtk-every", "2"]);
    assert_eq!(code, 2);
    let _ = std::fs::remove_dir_all(&dir);
}
