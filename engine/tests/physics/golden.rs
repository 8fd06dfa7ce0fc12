//! Golden summaries: every shipped scene's numbers, step by step, as they
//! were when the file `engine/tests/golden/summaries.txt` was written.
//!
//! This is a regression guard, not a check of the method (the other tests
//! check the numbers against exact solutions and the papers): it proves that
//! a change meant to move code, not numbers (a refactoring of the drivers,
//! a new module layout), moved none. Each scene runs to its end (or its
//! failure) and every stored step's summary is compared with the run's:
//! counts (iterations, sub-steps, cutbacks, unknowns, active cells, ghost
//! faces) and how the run ended exactly, and every number (load factor or
//! time, energies, errors against the exact solution, probes,
//! implicit-boundary reactions and violations, the largest increment, the
//! explicit energy balance) to a relative tolerance of the
//! largest magnitude its kind takes in the scene ([`kind`]): a vector's
//! components at the vector's size (the roller's reaction along it is
//! round-off beside the one across it), energies at the energies', a
//! constraint violation at the step's largest increment, and errors
//! against exact solutions at no less than 1e-12 (an exact method's error
//! is round-off, which the verification bounds by 1e-12).
//!
//! Tolerances, per scene from `kappa`, the largest condition number of the
//! systems its steps solved (stored with the summary):
//! - 1e-9 relative where `kappa <= 1e5`: a reordered sum changes a result
//!   by a few ulps times the condition number of what produced it, far
//!   below 1e-9 there.
//! - `1e-14 kappa` above, capped at 1e-3: a change of summation order moves
//!   a solve by about `eps kappa` (eps = 2.2e-16), and Newton's stopping
//!   test and the steps after it can amplify that a few tens of times.
//!   The cap is still three orders below what a wrong method moves (the
//!   papers' differences between methods are percents).
//!
//! Where round-off decides a scene's path (which Newton iteration meets
//! the tolerance, whether a cycling Newton is cut back), comparing it
//! step by step would fail a right program: writing the file also runs
//! each scene with every material's stiffness and density changed by a
//! few ulps (1e-15 and 1e-14 relative, either sign) and stores, as
//! `robust`, how many steps all of them keep the counts of. Beyond them
//! only the energies are compared, at 3e-2 of their scale. (Found when
//! summing the inertia's blocks with the points' before scattering them
//! moved `impact-incline-implicit`'s iterations from step 16 and its
//! cutbacks from step 20; three scenes are such: `collapse-von-mises`,
//! `rigid-footing-large` and `impact-incline-implicit`, whose plastic
//! and contact steps end where Newton meets its tolerance by a hair or
//! cycles before it is cut back.)
//!
//! Scenes of more than 100 steps (explicit dynamics) store every
//! `ceil(n / 100)`-th step and the last: a changed step changes every step
//! after it.
//!
//! `MPMLAB_GOLDEN=write cargo test --release -p mpmlab-engine --test
//! physics golden::` rewrites the file from the current engine; review its
//! diff like code.

use crate::common::scene_path;
use mpmlab_engine::scene::Scene;
use mpmlab_engine::{Model, Simulation, StepFailure, StepReport};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// One scene's run: per step, the named numbers (empty for a step not
/// stored); how it ended; the largest condition number of its systems.
#[derive(Debug, Default, Clone, PartialEq)]
struct Summary {
    steps: Vec<BTreeMap<String, Value>>,
    end: String,
    kappa: f64,
    /// How many steps keep their counts (iterations, cutbacks, ...) when
    /// every material's stiffness and density move by a few ulps: beyond
    /// them the path is decided by round-off (None: every step).
    robust: Option<usize>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Value {
    Count(usize),
    Number(f64),
}

fn golden_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden/summaries.txt")
}

/// Every shipped scene, by name.
fn shipped() -> Vec<String> {
    let dir = scene_path("x").parent().expect("scenarios").to_path_buf();
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .expect("scenarios/")
        .filter_map(|e| {
            let p = e.ok()?.path();
            (p.extension()? == "toml").then(|| p.file_stem()?.to_str().map(str::to_string))?
        })
        .collect();
    names.sort();
    names
}

fn count(m: &mut BTreeMap<String, Value>, k: &str, v: usize) {
    m.insert(k.to_string(), Value::Count(v));
}

fn number(m: &mut BTreeMap<String, Value>, k: String, v: f64) {
    m.insert(k, Value::Number(v));
}

/// The numbers of one step's report.
fn of_report(r: &StepReport) -> BTreeMap<String, Value> {
    let mut m = BTreeMap::new();
    count(&mut m, "iterations", r.iterations);
    count(&mut m, "unknowns", r.unknowns);
    count(&mut m, "active_cells", r.active_cells);
    count(&mut m, "ghost_faces", r.ghost_faces);
    count(&mut m, "cutbacks", r.cutbacks().len());
    number(&mut m, "load_factor".into(), r.load_factor);
    number(&mut m, "max_increment".into(), r.max_increment);
    let e = &r.energy;
    number(&mut m, "energy.strain".into(), e.strain);
    number(&mut m, "energy.external_work".into(), e.external_work);
    number(&mut m, "energy.plastic".into(), e.plastic_dissipation);
    number(&mut m, "energy.kinetic".into(), e.kinetic);
    number(&mut m, "energy.ghost".into(), e.ghost);
    for err in &r.errors {
        number(&mut m, format!("error.{}", err.name), err.value);
    }
    for p in &r.probes {
        for (key, _, v) in p.columns() {
            number(&mut m, format!("probe.{}.{key}", p.name), v);
        }
    }
    for b in &r.ibm {
        number(&mut m, format!("ibm.{}.fx", b.name), b.reaction[0]);
        number(&mut m, format!("ibm.{}.fy", b.name), b.reaction[1]);
        number(&mut m, format!("ibm.{}.violation", b.name), b.violation);
    }
    if let Some(s) = &r.solver {
        count(&mut m, "substeps", s.substeps);
    }
    // The explicit momentum is left out: two bodies colliding head-on
    // carry none, and its round-off (1e-14 kg m/s) has no scale to be
    // measured against in the report.
    if let Some(d) = &r.dynamics {
        count(&mut m, "substeps", d.substeps);
        number(&mut m, "time".into(), d.time);
        number(&mut m, "dt".into(), d.dt);
        number(&mut m, "energy_error".into(), d.energy_error);
    }
    m
}

/// The failure's kind and step, e.g. `NotConverged@13`.
fn of_failure(f: &StepFailure) -> String {
    let kind = format!("{f:?}");
    let kind = kind.split([' ', '{', '(']).next().unwrap_or("?");
    format!("{kind}@{}", f.step())
}

/// Run a shipped scene to its end or its first failure.
fn run(name: &str) -> Summary {
    run_perturbed(name, 0.0)
}

/// Run a shipped scene with every material's `E` and density scaled by
/// `1 + eps`.
fn run_perturbed(name: &str, eps: f64) -> Summary {
    let text = std::fs::read_to_string(scene_path(name)).expect("scene file");
    let mut scene = Scene::parse(&text, name).unwrap_or_else(|e| panic!("{name}: {e}"));
    for m in &mut scene.materials {
        m.e *= 1.0 + eps;
        m.density *= 1.0 + eps;
    }
    let mut sim = Simulation::new(Model::build(&scene, &text, name).unwrap_or_else(|e| panic!("{name}: {e}")));
    let mut s = Summary::default();
    while !sim.finished() {
        match sim.step() {
            Ok(r) => {
                if let Some(c) = r.condition.filter(|c| c.value.is_finite()) {
                    s.kappa = s.kappa.max(c.value);
                }
                s.steps.push(of_report(&r));
            }
            Err(f) => {
                s.end = of_failure(&f);
                return s;
            }
        }
    }
    s.end = "finished".into();
    s
}

/// The stored file: per scene its summary.
fn read_golden() -> BTreeMap<String, Summary> {
    let text = std::fs::read_to_string(golden_path()).unwrap_or_default();
    let mut out: BTreeMap<String, Summary> = BTreeMap::new();
    for (i, line) in text.lines().enumerate() {
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split('\t').collect();
        let bad = || format!("{}:{}: cannot read `{line}`", golden_path().display(), i + 1);
        if f.len() < 3 {
            panic!("{}", bad());
        }
        let e = out.entry(f[0].to_string()).or_default();
        match f[1] {
            "end" => e.end = f[2].to_string(),
            "kappa" => e.kappa = f[2].parse().unwrap_or_else(|_| panic!("{}", bad())),
            "robust" => e.robust = Some(f[2].parse().unwrap_or_else(|_| panic!("{}", bad()))),
            "steps" => {
                let n: usize = f[2].parse().unwrap_or_else(|_| panic!("{}", bad()));
                e.steps.resize(n, BTreeMap::new());
            }
            step => {
                let step: usize = step.parse().unwrap_or_else(|_| panic!("{}", bad()));
                let v = f.get(3).unwrap_or_else(|| panic!("{}", bad()));
                let value = match v.strip_prefix('#') {
                    Some(c) => Value::Count(c.parse().unwrap_or_else(|_| panic!("{}", bad()))),
                    None => Value::Number(v.parse().unwrap_or_else(|_| panic!("{}", bad()))),
                };
                let slot = e
                    .steps
                    .get_mut(step.wrapping_sub(1))
                    .unwrap_or_else(|| panic!("{}", bad()));
                slot.insert(f[2].to_string(), value);
            }
        }
    }
    out
}

fn write_golden(all: &BTreeMap<String, Summary>) {
    let mut text = String::from(
        "# Golden summaries of every shipped scene (engine/tests/physics/golden.rs).\n\
         # scene<TAB>step<TAB>quantity<TAB>value (#n: a count); per scene `end`,\n\
         # `kappa` (the largest condition number) and `steps` (completed steps);\n\
         # `robust`: the steps whose counts changes of a few ulps in the materials keep,\n\
         # for a scene whose later path round-off decides.\n",
    );
    for (name, s) in all {
        let n = s.steps.len();
        text += &format!(
            "{name}\tend\t{}\n{name}\tkappa\t{:e}\n{name}\tsteps\t{n}\n",
            s.end, s.kappa
        );
        if let Some(k) = s.robust {
            text += &format!("{name}\trobust\t{k}\n");
        }
        let stride = n.div_ceil(100).max(1);
        for (i, step) in s.steps.iter().enumerate() {
            if (i + 1) % stride != 0 && i + 1 != n {
                continue;
            }
            for (k, v) in step {
                let v = match v {
                    Value::Count(c) => format!("#{c}"),
                    Value::Number(x) => format!("{x:e}"),
                };
                text += &format!("{name}\t{}\t{k}\t{v}\n", i + 1);
            }
        }
    }
    std::fs::create_dir_all(golden_path().parent().expect("a folder")).expect("tests/golden/");
    std::fs::write(golden_path(), text).expect("the golden file");
}

/// The relative tolerance of a scene: see the module's documentation.
fn tolerance(kappa: f64) -> f64 {
    if kappa <= 1e5 {
        1e-9
    } else {
        (1e-14 * kappa).clamp(1e-9, 1e-3)
    }
}

/// The kind of a quantity, whose largest magnitude in a scene is the scale
/// its values are compared at: the components of a vector together
/// (`ibm.left.fx` and `.fy`; a probe's displacement, stress or force),
/// every energy with the others and the energy balance,
/// an implicit boundary's violation with the largest increment; anything
/// else by itself.
fn kind(key: &str) -> String {
    let (head, last) = key.rsplit_once('.').unwrap_or(("", key));
    match last {
        "fx" | "fy" => format!("{head}.f"),
        "ux" | "uy" => format!("{head}.u"),
        "sxx" | "syy" | "sxy" => format!("{head}.s"),
        _ if head == "energy" || key == "energy_error" => "energy".into(),
        "violation" | "max_increment" => "increment".into(),
        _ => key.into(),
    }
}

/// Differences between a run and its golden summary, one line each.
fn compare(name: &str, now: &Summary, gold: &Summary) -> Vec<String> {
    let tol = tolerance(gold.kappa);
    let mut out = Vec::new();
    if now.end != gold.end {
        out.push(format!("{name}: ended `{}`, golden `{}`", now.end, gold.end));
    }
    if now.steps.len() != gold.steps.len() {
        out.push(format!(
            "{name}: {} steps, golden {}",
            now.steps.len(),
            gold.steps.len()
        ));
    }
    // The scale of each kind of quantity: its largest magnitude over the
    // scene.
    let mut scale: BTreeMap<String, f64> = BTreeMap::new();
    for step in &gold.steps {
        for (k, v) in step {
            if let Value::Number(x) = v {
                let s = scale.entry(kind(k)).or_insert(0.0);
                *s = s.max(x.abs());
            }
        }
    }
    let scale_of = |k: &str| {
        let s = scale.get(&kind(k)).copied().unwrap_or(0.0);
        if k.starts_with("error.") {
            s.max(1e-12 / tol)
        } else {
            s
        }
    };
    for (i, (g, n)) in gold.steps.iter().zip(&now.steps).enumerate() {
        if g.is_empty() {
            continue;
        }
        // Beyond its robust steps a scene's path is round-off's: only its
        // energies (not their balance, which measures the path) are
        // compared, at 3e-2 of their scale. Another summation order moved
        // the impact scene's plastic dissipation by 1.1% of that scale and
        // its balance by 1.9% at its end; a wrong method moves the
        // energies by more (the papers' methods differ by percents of
        // the work, plastic collapse loads by 5-15%).
        let decided = gold.robust.is_none_or(|k| i < k);
        if !decided {
            for (k, gv) in g.iter().filter(|(k, _)| k.starts_with("energy.")) {
                if let (Value::Number(a), Some(Value::Number(b))) = (gv, n.get(k)) {
                    if (a - b).abs() > 3e-2 * scale_of(k) {
                        out.push(format!(
                            "{name} step {} (path decided by round-off): {k} = {b:e}, golden {a:e} (3e-2 of {:e})",
                            i + 1,
                            scale_of(k)
                        ));
                    }
                }
            }
            continue;
        }
        if g.keys().ne(n.keys()) {
            out.push(format!("{name} step {}: quantities differ", i + 1));
            continue;
        }
        for (k, gv) in g {
            let ok = match (gv, &n[k]) {
                (Value::Count(a), Value::Count(b)) => a == b,
                (Value::Number(a), Value::Number(b)) if a.is_nan() => b.is_nan(),
                (Value::Number(a), Value::Number(b)) => (a - b).abs() <= tol * scale_of(k),
                _ => false,
            };
            if !ok {
                out.push(format!(
                    "{name} step {}: {k} = {:?}, golden {:?} (relative tolerance {tol:e} of {:e})",
                    i + 1,
                    n[k],
                    gv,
                    scale_of(k)
                ));
            }
        }
    }
    out
}

/// The steps of `run` whose counts every one of a few changes of a few
/// ulps (relative 1e-15 and 1e-14, either sign) in every material's
/// stiffness and density keeps, when a changed run's counts differ
/// somewhere (else None: the whole path is the method's).
fn robust_steps(name: &str, run: &Summary) -> Option<usize> {
    let counts = |m: &BTreeMap<String, Value>| -> Vec<(String, usize)> {
        m.iter()
            .filter_map(|(k, v)| match v {
                Value::Count(c) => Some((k.clone(), *c)),
                Value::Number(_) => None,
            })
            .collect()
    };
    [1e-15, -1e-15, 1e-14, -1e-14]
        .iter()
        .filter_map(|&eps| {
            let other = run_perturbed(name, eps);
            let first = run
                .steps
                .iter()
                .zip(&other.steps)
                .position(|(a, b)| counts(a) != counts(b));
            match first {
                Some(i) => Some(i),
                None if run.steps.len() != other.steps.len() || run.end != other.end => {
                    Some(run.steps.len().min(other.steps.len()))
                }
                None => None,
            }
        })
        .min()
}

/// Run one scene and compare it with its golden summary (or store it).
fn check(name: &str) {
    let mut now = run(name);
    if std::env::var("MPMLAB_GOLDEN").as_deref() == Ok("write") {
        now.robust = robust_steps(name, &now);
        // Scenes write one at a time (the harness runs tests in parallel).
        static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
        let _guard = LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let mut all = read_golden();
        all.insert(name.to_string(), now);
        write_golden(&all);
        return;
    }
    let all = read_golden();
    let gold = all
        .get(name)
        .unwrap_or_else(|| panic!("{name}: no golden summary (write it: see golden.rs)"));
    let diffs = compare(name, &now, gold);
    assert!(diffs.is_empty(), "{} differences:\n{}", diffs.len(), diffs.join("\n"));
}

/// The golden file holds exactly the shipped scenes: a new scene without a
/// summary, or a summary of a scene that is gone, fails here rather than
/// being skipped.
#[test]
fn golden_file_covers_every_shipped_scene() {
    if std::env::var("MPMLAB_GOLDEN").as_deref() == Ok("write") {
        return;
    }
    let stored: Vec<String> = read_golden().into_keys().collect();
    assert_eq!(stored, shipped(), "scenes in the golden file against scenarios/");
}

macro_rules! golden {
    ($($test:ident => $scene:literal,)*) => {
        $(
            #[test]
            fn $test() {
                check($scene);
            }
        )*
        /// Every shipped scene has its test above.
        #[test]
        fn every_shipped_scene_has_a_golden_test() {
            let mut listed = vec![$($scene.to_string()),*];
            listed.sort();
            assert_eq!(listed, shipped());
        }
    };
}

golden! {
    axial_vibration_implicit => "axial-vibration-implicit",
    block_roller_0 => "block-roller-0",
    block_roller_30 => "block-roller-30",
    block_roller_45 => "block-roller-45",
    block_roller_90 => "block-roller-90",
    block_roller_finite_aligned => "block-roller-finite-aligned",
    block_roller_finite => "block-roller-finite",
    cantilever_follower_pressure_finite => "cantilever-follower-pressure-finite",
    cantilever_follower_pressure => "cantilever-follower-pressure",
    collapse_von_mises => "collapse-von-mises",
    column_self_weight => "column-self-weight",
    column_small_strain => "column-small-strain",
    cook_membrane => "cook-membrane",
    cook_membrane_incompressible => "cook-membrane-incompressible",
    deep_beam_self_weight => "deep-beam-self-weight",
    elastic_beam_ghost => "elastic-beam-ghost",
    fe_equivalence => "fe-equivalence",
    impact_incline_implicit => "impact-incline-implicit",
    incline_slide_implicit => "incline-slide-implicit",
    funnel => "funnel",
    ghost_collision_elastic => "ghost-collision-elastic",
    ghost_collision_implicit => "ghost-collision-implicit",
    ghost_collision_plastic => "ghost-collision-plastic",
    patch_compression => "patch-compression",
    plate_hole_dirichlet => "plate-hole-dirichlet",
    plate_hole_neumann_clipped => "plate-hole-neumann-clipped",
    plate_hole_neumann => "plate-hole-neumann",
    rigid_footing_large => "rigid-footing-large",
    rigid_footing => "rigid-footing",
    simple_shear_sweep => "simple-shear-sweep",
    slender_cantilever_0 => "slender-cantilever-0",
    slender_cantilever_45 => "slender-cantilever-45",
    slender_cantilever_90 => "slender-cantilever-90",
    slender_cantilever_finite_0 => "slender-cantilever-finite-0",
    slender_cantilever_finite_45 => "slender-cantilever-finite-45",
    square_traction_aligned => "square-traction-aligned",
    square_traction_ibm_0 => "square-traction-ibm-0",
    square_traction_ibm_45 => "square-traction-ibm-45",
    square_traction_ibm_60 => "square-traction-ibm-60",
    stretching_ghost => "stretching-ghost",
    stretching_ghost_implicit => "stretching-ghost-implicit",
    thick_cylinder_converging => "thick-cylinder-converging",
    thick_cylinder => "thick-cylinder",
    translating_domain => "translating-domain",
    translating_ghost => "translating-ghost",
    two_materials_roller => "two-materials-roller",
}
