//! Sweeps: one scene run over the cross product of settings, each run a
//! row of a CSV file with its cost (wall time by phase, unknowns, Newton
//! iterations, peak memory) and its outcome (completed or where and why it
//! failed, final errors against the exact solution).
//!
//! A sweep lives in a folder:
//!
//! | path | what |
//! |---|---|
//! | `runs/<id>.toml` | the scene of each run, with its settings in a first-line comment |
//! | `results/<id>.csv` | one run's result (header and one row), written by `mpmlab sweep-run` |
//! | `sweep.csv` | every result, in run order: the table to read |
//! | `estimates.csv` | error estimates from three successive refinements of h ([`estimate`]) |
//! | `jobs.txt` | with `--emit-jobs`: one command per run, for GNU parallel or a Slurm array |
//! | `charts/*.svg` | error against wall time (Pareto front marked), error against h, estimated (and true) errors against h, stability map |
//! | `sweep.rrd` | the same as a rerun recording ([`crate::record::sweep`]) |
//!
//! Runs whose result exists are not run again, so an interrupted sweep
//! resumes, and results computed elsewhere are merged by `--collect`.

pub mod driver;
pub mod estimate;
pub mod presets;
pub mod svg;
pub mod target;

use crate::runner::{self, Observer, RunEnd};
use crate::scene::Scene;
use crate::simulation::{Simulation, StepFailure};
use crate::Model;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One varied setting: a key and its values (TOML literals; bare words
/// are strings).
#[derive(Clone, Debug, PartialEq)]
pub struct Vary {
    pub key: String,
    pub values: Vec<String>,
}

impl Vary {
    /// Parse `key=v1,v2,...`.
    pub fn parse(s: &str) -> Result<Vary, String> {
        let (key, values) = s
            .split_once('=')
            .ok_or_else(|| format!("`{s}`: expected key=value1,value2,..."))?;
        let values: Vec<String> = split_values(values);
        if key.trim().is_empty() || values.is_empty() || values.iter().any(|v| v.is_empty()) {
            return Err(format!("`{s}`: expected key=value1,value2,..."));
        }
        Ok(Vary {
            key: key.trim().to_string(),
            values,
        })
    }
}

/// Split on commas outside brackets and quotes (`[1.0, 2.0]` is one value).
fn split_values(s: &str) -> Vec<String> {
    let (mut out, mut cur, mut depth, mut quoted) = (Vec::new(), String::new(), 0i32, false);
    for c in s.chars() {
        match c {
            '"' => quoted = !quoted,
            '[' | '{' if !quoted => depth += 1,
            ']' | '}' if !quoted => depth -= 1,
            ',' if !quoted && depth == 0 => {
                out.push(cur.trim().to_string());
                cur.clear();
                continue;
            }
            _ => {}
        }
        cur.push(c);
    }
    out.push(cur.trim().to_string());
    out
}

/// Scene paths behind the short keys; any other key is a dotted path into
/// the scene (`analysis.max_iterations`, `body.0.basis`; `*` for every
/// element of an array).
pub fn key_paths(key: &str) -> Vec<String> {
    let p: &[&str] = match key {
        "h" => &["grid.h"],
        "ppc" => &["body.*.points_per_cell"],
        "delta_over_h" | "delta" | "gamma_k" | "gamma_m" | "tolerance" | "max_iterations" | "mass"
        | "stress_update" | "velocity_update" | "condition" | "ghost_cells" => {
            return vec![format!("analysis.{key}")];
        }
        "steps" => &["analysis.load_steps"],
        other => return vec![other.to_string()],
    };
    p.iter().map(|s| s.to_string()).collect()
}

/// Two `--vary` that set the same field of the scene (`h` and `grid.h`,
/// `ppc` and `body.0.points_per_cell`, a key given twice): the later
/// would overwrite the earlier in every run while the table labels both,
/// so they are refused, naming both and the field.
pub fn overlapping(varies: &[Vary]) -> Option<String> {
    let meets = |a: &str, b: &str| {
        let (a, b): (Vec<&str>, Vec<&str>) = (a.split('.').collect(), b.split('.').collect());
        a.len() == b.len() && a.iter().zip(&b).all(|(x, y)| x == y || *x == "*" || *y == "*")
    };
    for (i, a) in varies.iter().enumerate() {
        for b in &varies[i + 1..] {
            for pa in key_paths(&a.key) {
                if let Some(pb) = key_paths(&b.key).into_iter().find(|pb| meets(&pa, pb)) {
                    let field = if pa.contains('*') { pb } else { pa };
                    return Some(format!(
                        "--vary {} and --vary {} both set `{field}`: give it once, with all its values",
                        a.key, b.key
                    ));
                }
            }
        }
    }
    None
}

/// Keys whose values are real numbers even when written without a point.
const REAL: &[&str] = &[
    "h",
    "delta_over_h",
    "delta",
    "gamma_k",
    "gamma_m",
    "tolerance",
    "duration",
    "E",
    "nu",
    "density",
];

/// The TOML value of a written setting.
fn value_of(text: &str) -> toml::Value {
    let parsed = format!("v = {text}")
        .parse::<toml::Table>()
        .ok()
        .and_then(|mut t| t.remove("v"));
    parsed.unwrap_or_else(|| toml::Value::String(text.to_string()))
}

/// Set `key` to `value` in a parsed scene.
pub fn apply(scene: &mut toml::Table, key: &str, value: &str) -> Result<(), String> {
    let mut v = value_of(value);
    let last = key.rsplit('.').next().unwrap_or(key);
    if let toml::Value::Integer(i) = v {
        if REAL.contains(&key) || REAL.contains(&last) {
            v = toml::Value::Float(i as f64);
        }
    }
    for path in key_paths(key) {
        let parts: Vec<&str> = path.split('.').collect();
        set(scene, &parts, &v).map_err(|e| format!("{key} = {value}: {e}"))?;
    }
    Ok(())
}

fn set(table: &mut toml::Table, parts: &[&str], v: &toml::Value) -> Result<(), String> {
    let (head, rest) = (parts[0], &parts[1..]);
    if rest.is_empty() {
        table.insert(head.to_string(), v.clone());
        return Ok(());
    }
    let entry = table
        .entry(head.to_string())
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    set_in(entry, rest, v, head)
}

fn set_in(node: &mut toml::Value, parts: &[&str], v: &toml::Value, name: &str) -> Result<(), String> {
    match node {
        toml::Value::Table(t) => set(t, parts, v),
        toml::Value::Array(a) => {
            let (idx, rest) = (parts[0], &parts[1..]);
            let targets: Vec<usize> = if idx == "*" {
                (0..a.len()).collect()
            } else {
                vec![idx
                    .parse::<usize>()
                    .ok()
                    .filter(|&i| i < a.len())
                    .ok_or_else(|| format!("`{name}` has no element {idx}"))?]
            };
            for i in targets {
                if rest.is_empty() {
                    a[i] = v.clone();
                } else {
                    set_in(&mut a[i], rest, v, name)?;
                }
            }
            Ok(())
        }
        _ => Err(format!("`{name}` is not a table")),
    }
}

/// One run of a sweep: its settings in order.
#[derive(Clone, Debug, PartialEq)]
pub struct Run {
    pub id: String,
    pub settings: Vec<(String, String)>,
}

/// The cross product of the varied settings, first key slowest.
pub fn expand(varies: &[Vary]) -> Vec<Run> {
    let mut runs = vec![Vec::new()];
    for v in varies {
        runs = runs
            .into_iter()
            .flat_map(|r: Vec<(String, String)>| {
                v.values.iter().map(move |x| {
                    let mut r = r.clone();
                    r.push((v.key.clone(), x.clone()));
                    r
                })
            })
            .collect();
    }
    runs.into_iter()
        .map(|settings| Run {
            id: run_id(&settings),
            settings,
        })
        .collect()
}

/// A file-name-safe id from settings: `h=0.5_ppc=2`.
fn run_id(settings: &[(String, String)]) -> String {
    let raw: Vec<String> = settings.iter().map(|(k, v)| format!("{k}={v}")).collect();
    let id: String = raw
        .join("_")
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "=._-+".contains(c) {
                c
            } else {
                '-'
            }
        })
        .collect();
    if id.is_empty() {
        "base".into()
    } else {
        id
    }
}

/// First line of a run's scene file: its id and settings, so that a result
/// computed anywhere carries them.
const HEADER: &str = "# mpmlab-sweep-run: ";

/// The scene text of a run: `base` with `fixed` and the run's settings applied.
pub fn run_scene(base: &str, fixed: &[(String, String)], run: &Run) -> Result<String, String> {
    let mut t: toml::Table = base.parse().map_err(|e| format!("the base scene: {e}"))?;
    for (k, v) in fixed.iter().chain(&run.settings) {
        apply(&mut t, k, v)?;
    }
    let body = toml::to_string(&t).map_err(|e| e.to_string())?;
    // Whitespace separates the settings in the header: values lose theirs
    // (`[1.0, 2.0]` -> `[1.0,2.0]`, the same TOML value).
    let settings: Vec<String> = run
        .settings
        .iter()
        .map(|(k, v)| format!("{k}={}", v.split_whitespace().collect::<String>()))
        .collect();
    Ok(format!("{HEADER}id={} {}\n{body}", run.id, settings.join(" ")))
}

/// The id and settings in a run's scene file header.
fn read_header(text: &str) -> (String, Vec<(String, String)>) {
    let line = text.lines().next().unwrap_or("");
    let Some(rest) = line.strip_prefix(HEADER) else {
        return ("base".into(), Vec::new());
    };
    let mut id = "base".to_string();
    let mut settings = Vec::new();
    for kv in rest.split_whitespace() {
        if let Some((k, v)) = kv.split_once('=') {
            if k == "id" {
                id = v.to_string();
            } else {
                settings.push((k.to_string(), v.to_string()));
            }
        }
    }
    (id, settings)
}

/// The outcome and cost of one run: a row of `sweep.csv`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunResult {
    pub id: String,
    pub settings: Vec<(String, String)>,
    pub completed: bool,
    pub steps_done: usize,
    pub steps_total: usize,
    /// The failed step (0: none).
    pub failed_step: usize,
    /// Why the run stopped early, or why the scene was rejected.
    pub failure: String,
    /// Wall time of all steps, and by phase (s).
    pub wall_s: f64,
    pub assembly_s: f64,
    pub factorisation_s: f64,
    pub solve_s: f64,
    pub condition_s: f64,
    /// The other phases of the steps (s): every phase is accounted for.
    pub mapping_s: f64,
    pub pattern_s: f64,
    pub update_s: f64,
    /// Negative pivots of the last tangent (its inertia; -1 when unknown).
    pub negative_pivots: i64,
    /// Load-step cutbacks over the run.
    pub cutbacks: usize,
    /// Unknowns of the last step.
    pub unknowns: usize,
    /// Newton iterations over all steps (linear steps count one).
    pub iterations: usize,
    /// Peak resident memory of the process that ran it (kB; 0 when unknown).
    pub peak_rss_kb: u64,
    /// How many runs the times are the fastest of (short runs repeat,
    /// [`SHORT_RUN_S`]).
    pub repeats: usize,
    /// Condition number of the last step (NaN when not computed).
    pub condition: f64,
    /// Errors against the exact solution after the last completed step.
    pub errors: Vec<(String, f64)>,
    /// The scene's probes after the last completed step, as
    /// `(<name>:<key>, value)` (columns `probe:<name>:<key>`).
    pub probes: Vec<(String, f64)>,
    /// Strain energy and external work after the last completed step, as
    /// `(strain | external_work, value)` (columns `energy:<name>`).
    pub energies: Vec<(String, f64)>,
    /// Exact values of quantities where the scene has an exact solution:
    /// a point probe's field at the position it asks for, keyed as the
    /// quantity (`probe:<name>:<key>`; columns `exact:probe:<name>:<key>`).
    pub exact: Vec<(String, f64)>,
    /// Error estimates of the finest run of a refinement triple
    /// ([`estimate`]), as `(<quantity>:<order|extrapolated|gci>, value)`
    /// (columns `estimate:...`; derived by the sweep, not read back).
    pub estimates: Vec<(String, f64)>,
    /// The run's recording (`sweep --record`): bytes, bytes per step and
    /// per point per step holding points (columns only when recorded).
    pub record_bytes: u64,
    pub record_bytes_per_step: f64,
    pub record_bytes_per_point: f64,
}

/// The columns of a recorded run, after the errors.
pub const RECORD_COLUMNS: [&str; 3] = ["record_bytes", "record_bytes_per_step", "record_bytes_per_point"];

pub use crate::procfs::peak_resident_kb as peak_rss_kb;

/// Run the scene file of one run in this process, to the end or the first
/// failure.
pub fn run_file(path: &Path) -> RunResult {
    run_file_recorded(path, None)
}

/// [`run_file`], recorded to `record` (with the scene's `[record]`
/// settings) when given; the row then holds the recording's size.
pub fn run_file_recorded(path: &Path, record: Option<&Path>) -> RunResult {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let file = path.display().to_string();
    let mut r = run_text(&text, &file, record);
    // A run of milliseconds is timed mostly by the machine's noise, which
    // would then decide the Pareto front: time short runs (unrecorded) as
    // the fastest of up to REPEATS.
    if r.completed && record.is_none() {
        while r.repeats < REPEATS && r.wall_s < SHORT_RUN_S {
            let again = run_text(&text, &file, None);
            if again.completed && again.wall_s < r.wall_s {
                r.take_timings(&again);
            }
            r.repeats += 1;
        }
    }
    r.peak_rss_kb = peak_rss_kb();
    r
}

/// Runs shorter than this (s) are repeated and timed as the fastest.
pub const SHORT_RUN_S: f64 = 0.5;
/// Most runs a short run's time is the fastest of.
pub const REPEATS: usize = 5;

/// One run of a scene's text, to the end or the first failure.
fn run_text(text: &str, file: &str, record: Option<&Path>) -> RunResult {
    let (id, settings) = read_header(text);
    let mut r = RunResult {
        id,
        settings,
        condition: f64::NAN,
        repeats: 1,
        ..Default::default()
    };
    let sim = Scene::parse(text, file).and_then(|s| Model::build(&s, text, file));
    let mut sim = match sim {
        Ok(m) => Simulation::new(m),
        Err(e) => {
            r.failure = format!("bad scene: {e}");
            r.peak_rss_kb = peak_rss_kb();
            return r;
        }
    };
    r.steps_total = sim.load_steps();
    let start = Instant::now();
    let never = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let mut recorder = match record.map(|p| crate::record::Recorder::create(p, text, &sim, false)) {
        Some(Err(e)) => {
            r.failure = format!("recording: {e}");
            return r;
        }
        Some(Ok(rec)) => Some(rec),
        None => None,
    };
    let mut lost = Vec::new();
    match runner::run(&mut sim, &mut [&mut r, &mut recorder], &never, &mut lost) {
        RunEnd::Failed(f) => {
            r.failed_step = f.step();
            r.failure = one_line(&f);
        }
        // The recording could not be written: the run stopped there.
        RunEnd::OutputFailed { after } => r.failure = format!("after step {after}: {}", lost.join("; ")),
        RunEnd::Finished | RunEnd::Stopped { .. } => {}
    }
    if let Some(mut rec) = recorder {
        let _ = rec.log_final_state(&sim);
        match rec.finish() {
            Ok(size) => {
                r.record_bytes = size.bytes;
                r.record_bytes_per_step = size.bytes_per_step();
                r.record_bytes_per_point = size.bytes_per_point_frame();
            }
            Err(e) if r.failure.is_empty() => r.failure = format!("recording: {e}"),
            Err(_) => {}
        }
    }
    r.wall_s = start.elapsed().as_secs_f64();
    r.completed = sim.finished() && r.failed_step == 0;
    r
}

/// A run's row follows its steps through the runner.
impl Observer for RunResult {
    fn stepped(&mut self, sim: &Simulation, rep: &crate::simulation::StepReport) -> Option<String> {
        let t = rep.timings;
        self.assembly_s += t.assembly;
        self.factorisation_s += t.factorisation;
        self.solve_s += t.solve;
        self.condition_s += t.condition;
        self.mapping_s += t.mapping;
        self.pattern_s += t.pattern;
        self.update_s += t.update;
        if let Some(s) = &rep.solver {
            self.negative_pivots = s.negative_pivots.map_or(-1, |n| n as i64);
        }
        self.cutbacks += rep.cutbacks().len();
        self.unknowns = rep.unknowns;
        self.iterations += rep.iterations.max(1);
        self.condition = rep.condition.map_or(f64::NAN, |c| c.value);
        self.errors = rep.errors.iter().map(|e| (e.name.to_string(), e.value)).collect();
        self.probes = rep
            .probes
            .iter()
            .flat_map(|p| p.columns().into_iter().map(|(k, _, v)| (format!("{}:{k}", p.name), v)))
            .collect();
        self.energies = vec![
            ("strain".into(), rep.energy.strain),
            ("external_work".into(), rep.energy.external_work),
        ];
        self.exact = exact_probes(sim.model(), rep.load_factor);
        self.steps_done = rep.step;
        None
    }
}

/// The exact values of a model's point probes at `load_factor`, keyed
/// `probe:<name>:<key>` (none without an exact solution; components the
/// solution does not give are left out).
fn exact_probes(model: &Model, load_factor: f64) -> Vec<(String, f64)> {
    let Some(exact) = &model.exact else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for p in &model.probes {
        let Some(at) = p.at else { continue };
        let (s, u) = exact.fields(at, load_factor);
        for (k, v) in [("ux", u[0]), ("uy", u[1]), ("sxx", s[0]), ("syy", s[1]), ("sxy", s[2])] {
            if v.is_finite() {
                out.push((format!("probe:{}:{k}", p.name), v));
            }
        }
    }
    out
}

fn one_line(f: &StepFailure) -> String {
    f.to_string().replace('\n', " ")
}

/// The fixed columns of `sweep.csv`, after `id` and the settings.
pub const COLUMNS: &[&str] = &[
    "completed",
    "steps_done",
    "steps_total",
    "failed_step",
    "failure",
    "wall_s",
    "assembly_s",
    "factorisation_s",
    "solve_s",
    "condition_s",
    "unknowns",
    "iterations",
    "peak_rss_kb",
    "condition",
    "mapping_s",
    "pattern_s",
    "update_s",
    "negative_pivots",
    "cutbacks",
    "repeats",
];

fn num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:e}")
    } else {
        String::new()
    }
}

impl RunResult {
    /// Column names and values: `id`, `set:<key>` per setting, [`COLUMNS`],
    /// `error:<name>` per error.
    pub fn fields(&self) -> Vec<(String, String)> {
        let mut f = vec![("id".to_string(), self.id.clone())];
        for (k, v) in &self.settings {
            f.push((format!("set:{k}"), v.clone()));
        }
        let vals = [
            self.completed.to_string(),
            self.steps_done.to_string(),
            self.steps_total.to_string(),
            self.failed_step.to_string(),
            self.failure.clone(),
            num(self.wall_s),
            num(self.assembly_s),
            num(self.factorisation_s),
            num(self.solve_s),
            num(self.condition_s),
            self.unknowns.to_string(),
            self.iterations.to_string(),
            self.peak_rss_kb.to_string(),
            num(self.condition),
            num(self.mapping_s),
            num(self.pattern_s),
            num(self.update_s),
            self.negative_pivots.to_string(),
            self.cutbacks.to_string(),
            self.repeats.to_string(),
        ];
        for (c, v) in COLUMNS.iter().zip(vals) {
            f.push((c.to_string(), v));
        }
        for (n, v) in &self.errors {
            f.push((format!("error:{n}"), num(*v)));
        }
        for (n, v) in &self.probes {
            f.push((format!("probe:{n}"), num(*v)));
        }
        for (n, v) in &self.energies {
            f.push((format!("energy:{n}"), num(*v)));
        }
        for (n, v) in &self.exact {
            f.push((format!("exact:{n}"), num(*v)));
        }
        for (n, v) in &self.estimates {
            f.push((format!("estimate:{n}"), num(*v)));
        }
        if self.record_bytes > 0 {
            let vals = [
                self.record_bytes.to_string(),
                num(self.record_bytes_per_step),
                num(self.record_bytes_per_point),
            ];
            for (c, v) in RECORD_COLUMNS.iter().zip(vals) {
                f.push((c.to_string(), v));
            }
        }
        f
    }

    /// Read back from named fields (missing numbers are NaN or 0).
    pub fn from_fields(f: &BTreeMap<String, String>, order: &[String]) -> RunResult {
        let s = |k: &str| f.get(k).cloned().unwrap_or_default();
        let x = |k: &str| s(k).parse::<f64>().unwrap_or(f64::NAN);
        let n = |k: &str| s(k).parse::<usize>().unwrap_or(0);
        RunResult {
            id: s("id"),
            settings: order
                .iter()
                .filter_map(|c| c.strip_prefix("set:").map(|k| (k.to_string(), s(c))))
                .filter(|(_, v)| !v.is_empty())
                .collect(),
            completed: s("completed") == "true",
            steps_done: n("steps_done"),
            steps_total: n("steps_total"),
            failed_step: n("failed_step"),
            failure: s("failure"),
            wall_s: x("wall_s"),
            assembly_s: x("assembly_s"),
            factorisation_s: x("factorisation_s"),
            solve_s: x("solve_s"),
            condition_s: x("condition_s"),
            unknowns: n("unknowns"),
            iterations: n("iterations"),
            peak_rss_kb: s("peak_rss_kb").parse().unwrap_or(0),
            condition: x("condition"),
            mapping_s: x("mapping_s"),
            pattern_s: x("pattern_s"),
            update_s: x("update_s"),
            negative_pivots: s("negative_pivots").parse().unwrap_or(-1),
            cutbacks: n("cutbacks"),
            repeats: n("repeats").max(1),
            errors: order
                .iter()
                .filter_map(|c| c.strip_prefix("error:").map(|k| (k.to_string(), x(c))))
                .filter(|(_, v)| !v.is_nan())
                .collect(),
            probes: order
                .iter()
                .filter_map(|c| c.strip_prefix("probe:").map(|k| (k.to_string(), x(c))))
                .filter(|(_, v)| !v.is_nan())
                .collect(),
            energies: prefixed(f, order, "energy:"),
            exact: prefixed(f, order, "exact:"),
            estimates: Vec::new(),
            record_bytes: s("record_bytes").parse().unwrap_or(0),
            record_bytes_per_step: x("record_bytes_per_step"),
            record_bytes_per_point: x("record_bytes_per_point"),
        }
    }

    /// Take the times of `other`, a faster run of the same scene.
    fn take_timings(&mut self, other: &RunResult) {
        self.wall_s = other.wall_s;
        self.assembly_s = other.assembly_s;
        self.factorisation_s = other.factorisation_s;
        self.solve_s = other.solve_s;
        self.condition_s = other.condition_s;
        self.mapping_s = other.mapping_s;
        self.pattern_s = other.pattern_s;
        self.update_s = other.update_s;
    }

    /// The cost charts and the Pareto front use: wall time without the
    /// condition numbers, a diagnostic the solution does not need (s).
    pub fn cost(&self) -> f64 {
        (self.wall_s - self.condition_s.max(0.0)).max(0.0)
    }

    /// The first error measure, the one charts and the Pareto front use.
    pub fn error(&self) -> Option<f64> {
        self.errors.first().map(|e| e.1).filter(|e| e.is_finite())
    }

    /// The quantities a refinement study can estimate the error of:
    /// probes (`probe:<name>:<key>`) and energies (`energy:<name>`).
    pub fn quantities(&self) -> Vec<(String, f64)> {
        let probes = self.probes.iter().map(|(n, v)| (format!("probe:{n}"), *v));
        let energies = self.energies.iter().map(|(n, v)| (format!("energy:{n}"), *v));
        probes.chain(energies).filter(|(_, v)| v.is_finite()).collect()
    }

    /// The exact value of a quantity of [`RunResult::quantities`], if known.
    pub fn exact_value(&self, quantity: &str) -> Option<f64> {
        self.exact.iter().find(|(n, _)| n == quantity).map(|(_, v)| *v)
    }

    /// A setting's value as a number.
    pub fn setting(&self, key: &str) -> Option<f64> {
        self.settings
            .iter()
            .find(|(k, _)| k == key)
            .and_then(|(_, v)| v.parse().ok())
    }
}

/// The numeric columns of a row that begin with `prefix`, without it.
fn prefixed(f: &BTreeMap<String, String>, order: &[String], prefix: &str) -> Vec<(String, f64)> {
    order
        .iter()
        .filter_map(|c| {
            let k = c.strip_prefix(prefix)?;
            let v = f.get(c)?.parse::<f64>().ok()?;
            Some((k.to_string(), v))
        })
        .collect()
}

/// One CSV field, quoted when it must be.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// Parse CSV text (RFC 4180 quoting) into rows of fields.
pub fn parse_csv(text: &str) -> Vec<Vec<String>> {
    let (mut rows, mut row, mut field) = (Vec::new(), Vec::new(), String::new());
    let mut chars = text.chars().peekable();
    let mut quoted = false;
    while let Some(c) = chars.next() {
        match (quoted, c) {
            (true, '"') if chars.peek() == Some(&'"') => {
                field.push('"');
                chars.next();
            }
            (true, '"') => quoted = false,
            (true, c) => field.push(c),
            (false, '"') => quoted = true,
            (false, ',') => row.push(std::mem::take(&mut field)),
            (false, '\n') => {
                row.push(std::mem::take(&mut field));
                rows.push(std::mem::take(&mut row));
            }
            (false, '\r') => {}
            (false, c) => field.push(c),
        }
    }
    if !field.is_empty() || !row.is_empty() {
        row.push(field);
        rows.push(row);
    }
    rows
}

/// CSV text of results: the union of their columns, in first-seen order.
pub fn to_csv(results: &[RunResult]) -> String {
    let mut columns: Vec<String> = Vec::new();
    let rows: Vec<Vec<(String, String)>> = results.iter().map(|r| r.fields()).collect();
    for row in &rows {
        for (c, _) in row {
            if !columns.contains(c) {
                columns.push(c.clone());
            }
        }
    }
    // Settings first, errors last, whatever order runs brought them in.
    let rank = |c: &String| {
        if c == "id" {
            0
        } else if c.starts_with("set:") {
            1
        } else if c.starts_with("error:") {
            3
        } else if c.starts_with("probe:") {
            4
        } else if c.starts_with("energy:") {
            5
        } else if c.starts_with("exact:") {
            6
        } else if c.starts_with("estimate:") {
            7
        } else {
            2
        }
    };
    columns.sort_by_key(rank);
    let mut out = columns.iter().map(|c| csv_field(c)).collect::<Vec<_>>().join(",");
    out.push('\n');
    for row in rows {
        let m: BTreeMap<_, _> = row.into_iter().collect();
        let line: Vec<String> = columns
            .iter()
            .map(|c| csv_field(m.get(c).map_or("", String::as_str)))
            .collect();
        out.push_str(&line.join(","));
        out.push('\n');
    }
    out
}

/// Results from CSV text written by [`to_csv`].
pub fn from_csv(text: &str) -> Vec<RunResult> {
    let rows = parse_csv(text);
    let Some((header, body)) = rows.split_first() else {
        return Vec::new();
    };
    body.iter()
        .filter(|r| r.len() == header.len())
        .map(|r| {
            let m: BTreeMap<String, String> = header.iter().cloned().zip(r.iter().cloned()).collect();
            RunResult::from_fields(&m, header)
        })
        .collect()
}

/// Indices of the runs on the Pareto front of (wall time, error): no other
/// run is at least as fast and at least as accurate and better in one.
/// Runs without a finite time and error are not candidates.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let ok = |p: &(f64, f64)| p.0.is_finite() && p.1.is_finite();
    (0..points.len())
        .filter(|&i| ok(&points[i]))
        .filter(|&i| {
            let (t, e) = points[i];
            !points
                .iter()
                .any(|q| ok(q) && q.0 <= t && q.1 <= e && (q.0 < t || q.1 < e))
        })
        .collect()
}

/// Completed runs that set `key`, grouped by every other setting (in
/// first-seen order; label `k=v k2=v2`, or `runs` when `key` is the only
/// setting), each group ordered by `key` from largest to smallest.
pub fn groups_without<'a>(results: &'a [RunResult], key: &str) -> Vec<(String, Vec<&'a RunResult>)> {
    let mut groups: Vec<(String, Vec<&RunResult>)> = Vec::new();
    for r in results.iter().filter(|r| r.completed && r.setting(key).is_some()) {
        let label: Vec<String> = r
            .settings
            .iter()
            .filter(|(k, _)| k != key)
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        let label = if label.is_empty() {
            "runs".to_string()
        } else {
            label.join(" ")
        };
        match groups.iter_mut().find(|g| g.0 == label) {
            Some(g) => g.1.push(r),
            None => groups.push((label, vec![r])),
        }
    }
    for g in &mut groups {
        g.1.sort_by(|a, b| b.setting(key).partial_cmp(&a.setting(key)).unwrap());
    }
    groups
}

/// Observed convergence rates `log(e1/e2) / log(h1/h2)` between successive
/// refinements of `h`, in each group of runs that share every other
/// setting: `(group label, h1, h2, error name, rate)`.
pub fn rates(results: &[RunResult], h_key: &str) -> Vec<(String, f64, f64, String, f64)> {
    let mut out = Vec::new();
    for (label, g) in groups_without(results, h_key) {
        for w in g.windows(2) {
            let (h1, h2) = (w[0].setting(h_key).unwrap(), w[1].setting(h_key).unwrap());
            for (name, e1) in &w[0].errors {
                let Some((_, e2)) = w[1].errors.iter().find(|(n, _)| n == name) else {
                    continue;
                };
                if *e1 > 0.0 && *e2 > 0.0 && h1 != h2 {
                    out.push((label.clone(), h1, h2, name.clone(), (e1 / e2).ln() / (h1 / h2).ln()));
                }
            }
        }
    }
    out
}

/// How the row of a run whose process died without a result begins.
pub const DIED: &str = "the run process ended without a result";

/// Where a sweep keeps its files.
pub struct Folder(pub PathBuf);

/// What a sweep writes in its folder: anything else is the user's.
const SWEEP_ENTRIES: &[&str] = &[
    "runs",
    "results",
    "recordings",
    "charts",
    "runs.txt",
    "sweep.csv",
    "estimates.csv",
    "sweep.rrd",
    "jobs.txt",
];

impl Folder {
    /// Whether the sweep may write here: a folder that does not exist or
    /// is empty, or one a sweep made (its `runs/` and `results/`, nothing
    /// but what a sweep writes), which it goes on with. A folder of other
    /// files (a user's `sweep.csv` or `charts/` among them) is refused
    /// unless `force`; a file is refused always.
    pub fn check_ours(&self, force: bool) -> Result<(), String> {
        let d = &self.0;
        if d.exists() && !d.is_dir() {
            return Err(format!("--out {} is not a folder", d.display()));
        }
        let (foreign, any) = crate::output::foreign_entries(d, SWEEP_ENTRIES);
        if !any || force {
            return Ok(());
        }
        let made = self.runs().is_dir() && self.results().is_dir();
        if foreign.is_empty() && made {
            return Ok(());
        }
        Err(format!(
            "--out {} holds files that are not a sweep's ({}): a sweep there would replace or mix with them; \
             choose another folder, or --force",
            d.display(),
            if foreign.is_empty() {
                "no runs/ and results/ of an earlier sweep".to_string()
            } else {
                crate::output::some_of(&foreign)
            }
        ))
    }

    pub fn runs(&self) -> PathBuf {
        self.0.join("runs")
    }
    pub fn results(&self) -> PathBuf {
        self.0.join("results")
    }
    pub fn run_scene(&self, id: &str) -> PathBuf {
        self.runs().join(format!("{id}.toml"))
    }
    /// A run's recording (`sweep --record`).
    pub fn recording(&self, id: &str) -> PathBuf {
        self.0.join("recordings").join(format!("{id}.rrd"))
    }
    pub fn result(&self, id: &str) -> PathBuf {
        self.results().join(format!("{id}.csv"))
    }
    pub fn csv(&self) -> PathBuf {
        self.0.join("sweep.csv")
    }
    pub fn charts(&self) -> PathBuf {
        self.0.join("charts")
    }

    /// Every result in `results/` and `sweep.csv`, by id (a result file
    /// wins over an older row of the table). Rows of runs whose process
    /// died without a result are left out, so they run again.
    pub fn collect(&self) -> BTreeMap<String, RunResult> {
        let mut all = BTreeMap::new();
        if let Ok(t) = std::fs::read_to_string(self.csv()) {
            for r in from_csv(&t) {
                all.insert(r.id.clone(), r);
            }
        }
        if let Ok(dir) = std::fs::read_dir(self.results()) {
            for e in dir.flatten() {
                if let Ok(t) = std::fs::read_to_string(e.path()) {
                    for r in from_csv(&t) {
                        all.insert(r.id.clone(), r);
                    }
                }
            }
        }
        all.retain(|_, r| !r.failure.starts_with(DIED));
        all
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_of_a_synthetic_set() {
        // (time, error): 0 and 2 and 4 are on the front; 1 is slower and
        // worse than 0; 3 is dominated by 2; 5 has no error.
        let pts = [
            (1.0, 1e-2),
            (2.0, 2e-2),
            (3.0, 1e-3),
            (4.0, 1e-3),
            (10.0, 1e-5),
            (0.5, f64::NAN),
        ];
        assert_eq!(pareto_front(&pts), vec![0, 2, 4]);
    }

    #[test]
    fn csv_round_trip_with_quotes() {
        let r = RunResult {
            id: "h=0.5".into(),
            settings: vec![("h".into(), "0.5".into())],
            failure: "step 3 failed: residual \"big\", 1e-3".into(),
            errors: vec![("stress_l2".into(), 0.125)],
            condition: f64::NAN,
            ..Default::default()
        };
        let back = from_csv(&to_csv(std::slice::from_ref(&r)));
        assert_eq!(back.len(), 1);
        assert_eq!(back[0].failure, r.failure);
        assert_eq!(back[0].errors, r.errors);
        assert_eq!(back[0].settings, r.settings);
    }

    #[test]
    fn settings_reach_the_scene() {
        let mut t: toml::Table = "[grid]\nh = 1.0\n[[body]]\npoints_per_cell = 1\n[[body]]\npoints_per_cell = 1\n[analysis]\nload_steps = 1\n"
            .parse()
            .unwrap();
        apply(&mut t, "h", "1").unwrap();
        apply(&mut t, "ppc", "3").unwrap();
        apply(&mut t, "gamma_k", "5").unwrap();
        apply(&mut t, "mass", "lumped").unwrap();
        assert_eq!(t["grid"]["h"].as_float(), Some(1.0));
        assert_eq!(t["body"][1]["points_per_cell"].as_integer(), Some(3));
        assert_eq!(t["analysis"]["gamma_k"].as_float(), Some(5.0));
        assert_eq!(t["analysis"]["mass"].as_str(), Some("lumped"));
        assert!(apply(&mut t, "body.7.basis", "gimp").is_err());
        assert_eq!(Vary::parse("size=[1.0, 2.0],[3.0, 4.0]").unwrap().values.len(), 2);
        // Two settings of one field are refused, by any spelling.
        let v = |s: &str| Vary::parse(s).unwrap();
        for (a, b, field) in [
            ("h=0.5", "h=0.25", "grid.h"),
            ("h=0.5", "grid.h=0.25", "grid.h"),
            ("ppc=2", "body.0.points_per_cell=4", "body.0.points_per_cell"),
            ("gamma_k=0,1e6", "analysis.gamma_k=1e3", "analysis.gamma_k"),
        ] {
            let e = overlapping(&[v(a), v(b)]).unwrap_or_else(|| panic!("{a} {b}"));
            assert!(e.contains(&format!("`{field}`")), "{e}");
        }
        assert_eq!(
            overlapping(&[v("h=0.5,0.25"), v("ppc=2,3"), v("body.0.basis=gimp")]),
            None
        );
    }
}
