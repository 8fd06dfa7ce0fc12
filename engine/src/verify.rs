//! `mpmlab verify`: every paper benchmark of `scenarios/` run against the
//! papers' numbers, one row per number: paper value, ours, ratio, the
//! tolerance (and why it is that), pass or fail.
//!
//! The rows are the reference values of the papers' tables and text (B:
//! Bing et al. 2019, C: Cortis et al. 2018, G: Coombs et al., Ghost
//! stabilisation). A row compares in one of four ways ([`Rule`]): to the
//! paper's printed digits, within a relative band, below a bound (where our
//! method's own error floor is above the paper's, the bound and its reason
//! are stated), or a count that must match. The same list writes the
//! tables of `docs/verification.md` (between `verify` markers), so the
//! document cannot drift from what the binary does.
//!
//! Runs are in-process, each scene once per distinct set of edits, in the
//! order the rows need them; `quick` rows (a minute in all) are the ones CI
//! runs.

use crate::report::{StepFailure, StepReport};
use crate::scene::{DirichletKind, DirichletSpec, ExactSpec, Placement, RegionSpec, Scene};
use crate::simulation::Simulation;
use crate::Model;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

mod benchmarks;

/// How a row's value is compared with the paper's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Rule {
    /// `|ours - paper| <= tol`.
    Absolute(f64),
    /// `|ours / paper - 1| <= tol`.
    Relative(f64),
    /// `ours <= bound` (the paper's value is shown for reference).
    AtMost(f64),
    /// `ours >= bound`.
    AtLeast(f64),
}

impl Rule {
    pub fn passes(self, ours: f64, paper: f64) -> bool {
        ours.is_finite()
            && match self {
                Rule::Absolute(t) => (ours - paper).abs() <= t,
                Rule::Relative(t) => (ours / paper - 1.0).abs() <= t,
                Rule::AtMost(b) => ours <= b,
                Rule::AtLeast(b) => ours >= b,
            }
    }

    /// The tolerance as a short text (`abs 5e-8`, `rel 0.02`, `<= 5e-8`).
    pub fn text(self) -> String {
        match self {
            Rule::Absolute(t) => format!("abs {t:.1e}"),
            Rule::Relative(t) => format!("rel {t}"),
            Rule::AtMost(b) => format!("<= {b:.2e}"),
            Rule::AtLeast(b) => format!(">= {b}"),
        }
    }
}

/// One run's outcome: every step report and the final state.
pub struct Outcome {
    pub reports: Vec<StepReport>,
    pub failure: Option<StepFailure>,
    pub sim: Simulation,
    pub wall_s: f64,
}

impl Outcome {
    /// The last report's error norm `name` (NaN when absent).
    pub fn error(&self, name: &str) -> f64 {
        self.reports
            .last()
            .and_then(|r| r.errors.iter().find(|e| e.name == name))
            .map_or(f64::NAN, |e| e.value)
    }

    /// The last report's probe value `probe:key` (NaN when absent).
    pub fn probe(&self, probe: &str, key: &str) -> f64 {
        self.reports
            .last()
            .and_then(|r| r.probes.iter().find(|p| p.name == probe))
            .and_then(|p| p.columns().into_iter().find(|c| c.0 == key))
            .map_or(f64::NAN, |c| c.2)
    }

    /// Steps completed.
    pub fn steps(&self) -> f64 {
        self.reports.len() as f64
    }

    /// Newton iterations over the run.
    pub fn iterations(&self) -> f64 {
        self.reports.iter().map(|r| r.iterations).sum::<usize>() as f64
    }

    /// The displacement of tracked point `k` of the boundary named
    /// `boundary` (or the first boundary for `""`).
    pub fn boundary_point(&self, boundary: &str, k: usize) -> [f64; 2] {
        let bs = &self.sim.model().boundaries;
        let b = if boundary.is_empty() {
            bs.first()
        } else {
            bs.iter().find(|b| b.name == boundary)
        };
        b.and_then(|b| b.points.get(k))
            .map_or([f64::NAN; 2], |&p| self.sim.points().displacement(p))
    }

    /// The mean displacement of the points carrying point loads.
    pub fn loaded_points(&self) -> [f64; 2] {
        let loads = &self.sim.model().point_loads;
        let n = loads.len().max(1) as f64;
        loads.iter().fold([0.0; 2], |a, l| {
            let u = self.sim.points().displacement(l.point);
            [a[0] + u[0] / n, a[1] + u[1] / n]
        })
    }
}

type Edit = Box<dyn Fn(&mut Scene)>;
type Value = Box<dyn Fn(&Outcomes) -> f64>;

/// The outcomes of the runs, by id.
pub struct Outcomes(BTreeMap<String, Outcome>);

impl Outcomes {
    /// The outcome of run `id` (a row is evaluated only once every run it
    /// reads has one).
    pub fn run(&self, id: &str) -> &Outcome {
        match self.0.get(id) {
            Some(o) => o,
            None => unreachable!("rows read only runs that ran"),
        }
    }
}

/// A run a row reads: a shipped scene with edits.
pub struct RunSpec {
    pub id: String,
    pub scene: &'static str,
    edit: Edit,
}

/// One reference number.
pub struct Check {
    /// Paper, section and table or figure (`C 5.2 Table 2`).
    pub benchmark: &'static str,
    /// What is compared.
    pub quantity: String,
    pub paper: f64,
    pub rule: Rule,
    /// Why the tolerance is what it is.
    pub why: &'static str,
    /// In the quick set CI runs.
    pub quick: bool,
    /// The runs it reads, by id.
    pub runs: Vec<String>,
    value: Value,
}

/// A row's result.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub benchmark: String,
    pub quantity: String,
    pub paper: f64,
    pub ours: f64,
    pub tolerance: String,
    pub pass: bool,
    pub why: String,
    /// Why a run the row reads failed, if one did.
    pub failure: Option<String>,
}

impl Row {
    pub fn ratio(&self) -> f64 {
        self.ours / self.paper
    }
}

/// A table of measured values for `docs/verification.md` (no paper value
/// per row: the papers show these as figures), written between the
/// document's `verify:<name>` markers.
pub struct DocTable {
    pub name: &'static str,
    pub runs: Vec<String>,
    render: Box<dyn Fn(&Outcomes) -> String>,
}

/// The benchmark list: the runs and the rows that read them.
pub struct Plan {
    pub runs: Vec<RunSpec>,
    pub checks: Vec<Check>,
    pub tables: Vec<DocTable>,
}

impl Plan {
    fn run(&mut self, id: &str, scene: &'static str, edit: impl Fn(&mut Scene) + 'static) {
        self.runs.push(RunSpec {
            id: id.to_string(),
            scene,
            edit: Box::new(edit),
        });
    }

    #[allow(clippy::too_many_arguments)]
    fn check(
        &mut self,
        benchmark: &'static str,
        quantity: impl Into<String>,
        paper: f64,
        rule: Rule,
        quick: bool,
        why: &'static str,
        runs: &[&str],
        value: impl Fn(&Outcomes) -> f64 + 'static,
    ) {
        self.checks.push(Check {
            benchmark,
            quantity: quantity.into(),
            paper,
            rule,
            why,
            quick,
            runs: runs.iter().map(|s| s.to_string()).collect(),
            value: Box::new(value),
        });
    }
}

/// Deep beam (C 5.2) with `n x n` clipped points on grid `h`, or (`fe`) the
/// bilinear FE analogue on the same grid (2x2 Gauss points, the left side
/// fixed on the grid line). The tests use the same edits.
pub fn deep_beam(h: f64, n: usize, fe: bool) -> impl Fn(&mut Scene) {
    move |s: &mut Scene| {
        s.grid.h = h;
        s.grid.size = [120.0, 220.0];
        s.bodies[0].points_per_cell = n;
        if fe {
            s.ibm.clear();
            s.probes.retain(|p| p.ibm.is_none());
            s.bodies[0].placement = Placement::Gauss;
            s.bodies[0].points_per_cell = 2;
            s.dirichlet.push(DirichletSpec {
                kind: DirichletKind::Fixed,
                x: Some(0.0),
                y: None,
                node: None,
                displacement: None,
                normal_displacement: None,
            });
        }
    }
}

/// C 5.3's square moved `a` (mm) across the two cells: region, the four
/// implicit edges and the exact field's origin.
pub fn simple_shear(a: f64) -> impl Fn(&mut Scene) {
    move |s: &mut Scene| {
        s.bodies[0].region = RegionSpec::Rectangle {
            min: [a, 0.0],
            max: [a + 100.0, 100.0],
        };
        s.ibm[0].points = vec![[a, 100.0], [a, 0.0]];
        s.ibm[1].points = vec![[a + 100.0, 0.0], [a + 100.0, 100.0]];
        s.ibm[2].points = vec![[a, 0.0], [a + 100.0, 0.0]];
        s.ibm[3].points = vec![[a + 100.0, 100.0], [a, 100.0]];
        if let Some(ExactSpec::SimpleShear { x0, .. }) = s.exact.as_mut() {
            *x0 = a;
        }
    }
}

/// The column of G 5.4 `cells` tall with penalty `gamma` (Pa).
pub fn column(cells: usize, gamma: f64) -> impl Fn(&mut Scene) {
    move |s: &mut Scene| {
        let h = 50.0 / cells as f64;
        s.grid.h = h;
        s.grid.size = [h, 50.0];
        s.bodies[0].region = RegionSpec::Rectangle {
            min: [0.0, 0.0],
            max: [h, 50.0],
        };
        s.dirichlet[2].x = Some(h);
        s.analysis.gamma_k = gamma;
    }
}

/// Every benchmark row, paper section by paper section (one function of
/// [`benchmarks`] each), in the order the rows are printed.
pub fn plan() -> Plan {
    let mut p = Plan {
        runs: Vec::new(),
        checks: Vec::new(),
        tables: Vec::new(),
    };
    benchmarks::b_square(&mut p);
    benchmarks::c_block(&mut p);
    benchmarks::c_beam(&mut p);
    benchmarks::c_shear(&mut p);
    benchmarks::b_cantilever(&mut p);
    benchmarks::b_plate_neumann(&mut p);
    benchmarks::g_column(&mut p);
    benchmarks::b_plate_dirichlet(&mut p);
    benchmarks::c_footing(&mut p);
    benchmarks::g_beam(&mut p);
    benchmarks::g_dynamics(&mut p);
    benchmarks::newmark(&mut p);
    benchmarks::cook(&mut p);
    p
}

/// Where the shipped scenes are read from.
#[derive(Clone, Copy, Debug)]
pub enum Scenes<'a> {
    /// A folder of `NAME.toml` files (the checkout's `scenarios/`).
    Folder(&'a Path),
    /// `(name, text)` pairs built into the program.
    Builtin(&'a [(&'a str, &'a str)]),
}

impl Scenes<'_> {
    /// The text of scene `name` and the file name its errors cite.
    fn read(&self, name: &str) -> Result<(String, String), String> {
        match self {
            Scenes::Folder(dir) => {
                let path = dir.join(format!("{name}.toml"));
                let file = path.display().to_string();
                let text = std::fs::read_to_string(&path).map_err(|e| format!("{file}: {e}"))?;
                Ok((text, file))
            }
            Scenes::Builtin(list) => list
                .iter()
                .find(|(n, _)| *n == name)
                .map(|(_, text)| (text.to_string(), format!("{name}.toml (built in)")))
                .ok_or_else(|| format!("{name}: no such shipped scene")),
        }
    }
}

/// Run one scene with its edits to the end or the first failure.
fn run_one(spec: &RunSpec, scenes: Scenes, stop: &std::sync::atomic::AtomicBool) -> Result<Outcome, String> {
    let (text, file) = scenes.read(spec.scene)?;
    let mut scene = Scene::parse(&text, &file).map_err(|e| e.to_string())?;
    (spec.edit)(&mut scene);
    let model = Model::build(&scene, &text, &file).map_err(|e| e.to_string())?;
    let mut sim = Simulation::new(model);
    let start = Instant::now();
    let (mut reports, mut failure) = (Vec::new(), None);
    while !sim.finished() {
        if stop.load(std::sync::atomic::Ordering::Relaxed) {
            return Err("interrupted".into());
        }
        match sim.step() {
            Ok(r) => reports.push(r),
            Err(f) => {
                failure = Some(f);
                break;
            }
        }
    }
    Ok(Outcome {
        reports,
        failure,
        sim,
        wall_s: start.elapsed().as_secs_f64(),
    })
}

/// Run the checks (`quick`: only those CI runs) with the scenes of `scenes`;
/// `progress` hears of every run. A run that cannot be built or stops
/// early fails the rows that read it, with the reason.
/// What `verify` found: the rows, and the measured tables as
/// `(name, Markdown)` (not in the quick set).
pub struct Verified {
    pub rows: Vec<Row>,
    pub tables: Vec<(&'static str, String)>,
}

pub fn verify(
    scenes: Scenes,
    quick: bool,
    stop: &std::sync::atomic::AtomicBool,
    progress: &mut dyn FnMut(&str),
) -> Verified {
    let plan = plan();
    let checks: Vec<&Check> = plan.checks.iter().filter(|c| c.quick || !quick).collect();
    let tables: Vec<&DocTable> = plan.tables.iter().filter(|_| !quick).collect();
    let mut outcomes = Outcomes(BTreeMap::new());
    let mut errors: BTreeMap<String, String> = BTreeMap::new();
    for spec in &plan.runs {
        if !checks.iter().any(|c| c.runs.contains(&spec.id)) && !tables.iter().any(|t| t.runs.contains(&spec.id)) {
            continue;
        }
        match run_one(spec, scenes, stop) {
            Ok(o) => {
                progress(&format!(
                    "ran {} ({}): {} steps in {:.2} s{}",
                    spec.id,
                    spec.scene,
                    o.reports.len(),
                    o.wall_s,
                    o.failure.as_ref().map_or(String::new(), |f| format!(
                        ", then: {}",
                        f.to_string().replace('\n', " ")
                    ))
                ));
                outcomes.0.insert(spec.id.clone(), o);
            }
            Err(e) => {
                progress(&format!("{}: {e}", spec.id));
                errors.insert(spec.id.clone(), e);
            }
        }
    }
    let rows = checks
        .iter()
        .map(|c| {
            let missing = c.runs.iter().find(|id| !outcomes.0.contains_key(*id)).map(|id| {
                let why = errors.get(id).map_or("not run", String::as_str);
                format!("{id}: {why}")
            });
            let ours = if missing.is_some() {
                f64::NAN
            } else {
                (c.value)(&outcomes)
            };
            let failed_run = c.runs.iter().find_map(|id| {
                let f = outcomes.0.get(id)?.failure.as_ref()?;
                Some(format!("{id}: {}", f.to_string().replace('\n', " ")))
            });
            Row {
                benchmark: c.benchmark.to_string(),
                quantity: c.quantity.clone(),
                paper: c.paper,
                ours,
                tolerance: c.rule.text(),
                pass: c.rule.passes(ours, c.paper),
                why: c.why.to_string(),
                failure: missing.or(failed_run),
            }
        })
        .collect();
    let tables = tables
        .iter()
        .filter(|t| t.runs.iter().all(|id| outcomes.0.contains_key(id)))
        .map(|t| (t.name, (t.render)(&outcomes)))
        .collect();
    Verified { rows, tables }
}

fn num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.6e}")
    } else {
        "-".into()
    }
}

/// The text table `verify` prints.
pub fn table(rows: &[Row]) -> String {
    use std::fmt::Write;
    let mut s = format!(
        "{:<22} {:<62} {:>13} {:>13} {:>9} {:>11}  pass\n",
        "benchmark", "quantity", "paper", "ours", "ratio", "tolerance"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:<22} {:<62} {:>13} {:>13} {:>9} {:>11}  {}",
            r.benchmark,
            r.quantity,
            format!("{:.4e}", r.paper),
            num(r.ours),
            if r.ratio().is_finite() {
                format!("{:.4}", r.ratio())
            } else {
                "-".into()
            },
            r.tolerance,
            if r.pass { "yes" } else { "NO" }
        );
        if !r.pass {
            if let Some(f) = &r.failure {
                let _ = writeln!(s, "    {f}");
            }
        }
    }
    let passed = rows.iter().filter(|r| r.pass).count();
    let _ = writeln!(s, "{passed} of {} rows pass", rows.len());
    s
}

/// CSV: `benchmark,quantity,paper,ours,ratio,tolerance,pass,why`.
pub fn csv(rows: &[Row]) -> String {
    let q = |s: &str| {
        if s.contains([',', '"', '\n']) {
            format!("\"{}\"", s.replace('"', "\"\""))
        } else {
            s.to_string()
        }
    };
    let mut s = String::from("benchmark,quantity,paper,ours,ratio,tolerance,pass,why\n");
    for r in rows {
        let f = |v: f64| if v.is_finite() { format!("{v:e}") } else { String::new() };
        s.push_str(
            &[
                q(&r.benchmark),
                q(&r.quantity),
                f(r.paper),
                f(r.ours),
                f(r.ratio()),
                q(&r.tolerance),
                r.pass.to_string(),
                q(&r.why),
            ]
            .join(","),
        );
        s.push('\n');
    }
    s
}

/// The Markdown table written into `docs/verification.md`.
pub fn markdown(rows: &[Row]) -> String {
    let mut s = String::from(
        "| benchmark | quantity | paper | ours | ratio | tolerance | pass | why this tolerance |\n|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {:.4e} | {} | {} | {} | {} | {} |\n",
            r.benchmark,
            r.quantity.replace('|', "/"),
            r.paper,
            num(r.ours),
            if r.ratio().is_finite() {
                format!("{:.4}", r.ratio())
            } else {
                "-".into()
            },
            r.tolerance,
            if r.pass { "yes" } else { "**no**" },
            r.why.replace('|', "/"),
        ));
    }
    s
}

/// The markers around generated section `name` of `docs/verification.md`
/// (`rows` for the benchmark rows, a [`DocTable`]'s name for its table).
pub fn markers(name: &str) -> (String, String) {
    (
        format!("<!-- verify:{name}:begin (written by `mpmlab verify --write-docs`; do not edit by hand) -->"),
        format!("<!-- verify:{name}:end -->"),
    )
}

/// `doc` with the text between section `name`'s markers replaced by
/// `table` (appended with both markers when absent).
pub fn replace_section(doc: &str, name: &str, table: &str) -> String {
    let (begin, end) = markers(name);
    match (doc.find(&begin), doc.find(&end)) {
        (Some(b), Some(e)) if e > b => format!("{}{begin}\n{table}{}", &doc[..b], &doc[e..]),
        _ => format!("{doc}\n{begin}\n{table}{end}\n"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rules_compare_as_documented() {
        assert!(Rule::Relative(0.02).passes(2.85, 2.822) && !Rule::Relative(0.001).passes(2.85, 2.822));
        assert!(Rule::Absolute(1e-9).passes(1.0 + 5e-10, 1.0) && !Rule::Absolute(1e-9).passes(1.0 + 2e-9, 1.0));
        assert!(Rule::AtMost(5e-8).passes(1e-8, 1.5e-9) && !Rule::AtMost(5e-8).passes(6e-8, 1.5e-9));
        assert!(!Rule::AtLeast(1.7).passes(f64::NAN, 2.0));
    }

    #[test]
    fn the_docs_section_is_replaced_in_place() {
        let (b, e) = markers("rows");
        let doc = format!("a\n{b}\nold\n{e}\nb\n");
        let new = replace_section(&doc, "rows", "new\n");
        assert_eq!(new, format!("a\n{b}\nnew\n{e}\nb\n"));
        assert!(replace_section("a\n", "rows", "t\n").ends_with(&format!("{b}\nt\n{e}\n")));
    }

    #[test]
    fn every_row_reads_runs_that_exist() {
        let p = plan();
        for c in &p.checks {
            for id in &c.runs {
                assert!(p.runs.iter().any(|r| &r.id == id), "{}: {id}", c.quantity);
            }
        }
        for t in &p.tables {
            for id in &t.runs {
                assert!(p.runs.iter().any(|r| &r.id == id), "{}: {id}", t.name);
            }
        }
        let mut ids: Vec<&str> = p.runs.iter().map(|r| r.id.as_str()).collect();
        ids.sort();
        let n = ids.len();
        ids.dedup();
        assert_eq!(ids.len(), n, "run ids are unique");
    }
}
