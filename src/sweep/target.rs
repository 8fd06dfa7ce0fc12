//! `mpmlab sweep SCENE --target QUANTITY=TOL [--budget SECONDS]`: the
//! cheapest discretisation that meets an error target, found by refining
//! coarse to fine and predicting from the observed order where to stop.
//!
//! The search refines h by halving (from twice the scene's h) in families:
//! the scene's points per cell and twice them (when the scene places points
//! per cell), each with every combination of the `--try` settings (basis,
//! placement, load steps, delta, gamma_K: what the user names). After each run the target's measure is read:
//!
//! - `error:<name>` (a scene with an exact solution): the measured error;
//! - `probe:<name>:<key>` or `energy:<name>`: the relative GCI of the three
//!   finest runs of the family ([`super::estimate`]), trusted only when the
//!   triple converges monotonically with a credible order that the next
//!   coarser triple confirms (so at least four runs; otherwise the family
//!   refines on).
//!
//! With two measures the observed order `p` predicts the cell size that
//! meets the target, `h* = h (TOL / e)^(1/p)`; the next run is the largest
//! halving at or below it (at most three halvings at once), and its
//! predicted measure is reported beside the measured one. A family stops
//! when it meets the target, when the next run's predicted cost (4x per
//! halving in 2D) would overrun the budget, or after a failed run. The
//! answer is the cheapest run (wall time without condition numbers) that
//! meets the target; every run is a row of the sweep folder, so the front
//! it explored is charted and shown by `tui --sweep` like any sweep.

use super::driver;
use super::estimate::{self, Behaviour};
use super::{Folder, RunResult, Vary};
use std::path::Path;

/// What to reach: a quantity and its tolerance.
#[derive(Clone, Debug, PartialEq)]
pub struct Target {
    pub quantity: String,
    pub tol: f64,
}

impl Target {
    /// Parse `error:<name>=TOL`, `probe:<name>:<key>=TOL` or
    /// `energy:<name>=TOL`.
    pub fn parse(s: &str) -> Result<Target, String> {
        if s.matches('=').count() > 1 {
            return Err(format!("`{s}`: expected one QUANTITY=TOL, e.g. error:stress_l2=1e-2"));
        }
        let (q, t) = s
            .rsplit_once('=')
            .ok_or_else(|| format!("`{s}`: expected QUANTITY=TOL, e.g. error:stress_l2=1e-2 or probe:tip:uy=1e-3"))?;
        let tol: f64 = t
            .trim()
            .parse()
            .map_err(|_| format!("`{s}`: the tolerance `{t}` is not a number"))?;
        if !(tol > 0.0 && tol.is_finite()) {
            return Err(format!("`{s}`: the tolerance must be a positive number"));
        }
        let q = q.trim();
        let ok = q.strip_prefix("error:").is_some_and(|n| !n.is_empty())
            || q.strip_prefix("probe:").is_some_and(|n| n.split(':').count() == 2)
            || q.strip_prefix("energy:").is_some_and(|n| !n.is_empty());
        if !ok {
            return Err(format!(
                "`{q}`: the quantity is error:<name> (against the exact solution), probe:<name>:<key> or energy:<name>"
            ));
        }
        Ok(Target {
            quantity: q.to_string(),
            tol,
        })
    }

    /// Whether the scene `sim` reports the quantity: an error of its exact
    /// solution, a probe's column or an energy of the run's rows; the
    /// refusal lists what it does report.
    pub fn check_against(&self, sim: &crate::Simulation) -> Result<(), String> {
        let q = &self.quantity;
        let (kind, known): (&str, Vec<String>) = if q.starts_with("error:") {
            let names = sim.error_names();
            if names.is_empty() {
                return Err(format!(
                    "`{q}`: the scene has no exact solution to measure an error against; \
                     target a probe (probe:<name>:<key>) or an energy (energy:strain), which are estimated"
                ));
            }
            ("errors", names.into_iter().map(|n| format!("error:{n}")).collect())
        } else if q.starts_with("probe:") {
            let columns: Vec<String> = sim
                .probe_values(None)
                .iter()
                .flat_map(|p| {
                    p.columns()
                        .into_iter()
                        .map(move |(k, _, _)| format!("probe:{}:{k}", p.name))
                })
                .collect();
            if columns.is_empty() {
                return Err(format!("`{q}`: the scene has no probes ([[probe]] in the scene)"));
            }
            ("probe columns", columns)
        } else {
            (
                "energies",
                ["strain", "external_work"]
                    .iter()
                    .map(|n| format!("energy:{n}"))
                    .collect(),
            )
        };
        if known.iter().any(|k| k == q) {
            return Ok(());
        }
        Err(format!(
            "`{q}` is not reported by this scene; its {kind}: {}",
            known.join(", ")
        ))
    }

    /// Measured against the exact solution (else estimated).
    pub fn is_exact(&self) -> bool {
        self.quantity.starts_with("error:")
    }
}

/// One run of the search.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    pub id: String,
    pub h: f64,
    pub ppc: Option<usize>,
    /// Wall time without condition numbers (s); NaN for a failed run.
    pub cost: f64,
    /// The target's measure after the run (NaN where there is none yet).
    pub measure: f64,
    /// What the previous runs predicted for it (NaN: no prediction).
    pub predicted: f64,
    /// Why the measure is missing or not trusted, if it is.
    pub note: String,
}

/// The search's outcome.
#[derive(Clone, Debug, PartialEq)]
pub struct Found {
    pub target: Target,
    pub steps: Vec<Step>,
    /// Index in `steps` of the cheapest run meeting the target.
    pub best: Option<usize>,
    /// Why the search ended.
    pub ended: String,
}

/// The measure of `target` for the last run of `family` (completed runs,
/// coarse to fine), with a note when it is missing or not trusted.
pub fn measure(target: &Target, family: &[RunResult]) -> (f64, String) {
    let Some(last) = family.last() else {
        return (f64::NAN, "no run".into());
    };
    if let Some(name) = target.quantity.strip_prefix("error:") {
        return match last.errors.iter().find(|(n, _)| n == name) {
            Some((_, v)) => (*v, String::new()),
            None => (f64::NAN, format!("the run reports no error `{name}`")),
        };
    }
    if family.len() < 3 {
        return (f64::NAN, "an estimate needs three refinements".into());
    }
    let est = estimate::estimates(family, "h");
    let finest = estimate::finest(&est);
    match finest.iter().find(|e| e.quantity == target.quantity) {
        None => (f64::NAN, format!("the run reports no `{}`", target.quantity)),
        Some(e) if matches!(e.behaviour, Behaviour::Monotone | Behaviour::Resolved) => {
            (e.relative_gci(), String::new())
        }
        Some(e) => (
            f64::NAN,
            format!("not trusted: the last three runs are {}", e.behaviour.label()),
        ),
    }
}

/// The next cell size after `h` with measure `e` at observed order `p`:
/// the largest halving of `h` (1 to 3 of them) whose predicted measure
/// `e (h'/h)^p` meets `tol`, else three halvings; with the prediction.
pub fn next_h(h: f64, e: f64, p: f64, tol: f64) -> (f64, f64) {
    let predict = |k: i32| e * 0.5f64.powi(k).powf(p);
    let k = (1..=3).find(|&k| predict(k) <= tol).unwrap_or(3);
    (h * 0.5f64.powi(k), predict(k))
}

/// A family of the search: points per cell (if the scene places them per
/// cell) and the tried settings it holds fixed.
type Family = (Option<usize>, Vec<(String, String)>);

/// Where a search starts: the scene's cell size and, where its bodies
/// place points per cell, their number; and the other settings to try,
/// each value a family of its own (`--try KEY=V1,V2`: basis, placement,
/// load steps, delta, gamma_K, ...).
#[derive(Clone, Debug, PartialEq)]
pub struct Start {
    pub h: f64,
    pub ppc: Option<usize>,
    pub tries: Vec<Vary>,
}

/// Search `base` (the scene's text) from `start` for the cheapest run
/// that meets `target` within `budget_s` seconds of runs.
pub fn search(
    folder: &Folder,
    exe: &Path,
    base: &str,
    start: Start,
    target: &Target,
    budget_s: f64,
    progress: &(dyn Fn(String) + Sync),
) -> Result<Found, String> {
    let (scene_h, scene_ppc) = (start.h, start.ppc);
    let ppcs: Vec<Option<usize>> = match scene_ppc {
        Some(p) => vec![Some(p), Some(2 * p)],
        None => vec![None],
    };
    // Every points-per-cell option with every combination of the tries.
    let others = super::expand(&start.tries);
    let families: Vec<Family> = ppcs
        .iter()
        .flat_map(|p| {
            let settings: Vec<Vec<(String, String)>> = if others.is_empty() {
                vec![Vec::new()]
            } else {
                others.iter().map(|r| r.settings.clone()).collect()
            };
            settings.into_iter().map(move |s| (*p, s))
        })
        .collect();
    let mut steps: Vec<Step> = Vec::new();
    let mut order: Vec<String> = Vec::new();
    let mut spent = 0.0;
    let mut ended = String::from("every family met the target or stopped");
    for (ppc, tried) in families {
        let mut h = 2.0 * scene_h;
        let mut predicted = f64::NAN;
        let mut family: Vec<RunResult> = Vec::new();
        let mut measures: Vec<(f64, f64)> = Vec::new();
        loop {
            let mut varies = vec![Vary {
                key: "h".into(),
                values: vec![format!("{h:?}")],
            }];
            if let Some(p) = ppc {
                varies.push(Vary {
                    key: "ppc".into(),
                    values: vec![p.to_string()],
                });
            }
            varies.extend(tried.iter().map(|(k, v)| Vary {
                key: k.clone(),
                values: vec![v.clone()],
            }));
            let runs = driver::prepare(folder, base, &[], &varies)?;
            for r in &runs {
                if !order.contains(&r.id) {
                    order.push(r.id.clone());
                }
            }
            // Every run of the search in runs.txt, so the folder is a sweep.
            let p = folder.0.join("runs.txt");
            std::fs::write(&p, order.join("\n") + "\n").map_err(|e| format!("cannot write {}: {e}", p.display()))?;
            let todo = driver::pending(folder, &runs);
            driver::execute(folder, exe, &todo, 1, false, progress);
            let Some(r) = runs.first().and_then(|r| folder.collect().remove(&r.id)) else {
                return Err("a run of the search left no result".into());
            };
            spent += r.wall_s.max(0.0);
            if !r.completed {
                steps.push(Step {
                    id: r.id.clone(),
                    h,
                    ppc,
                    cost: f64::NAN,
                    measure: f64::NAN,
                    predicted,
                    note: format!("failed: {}", r.failure),
                });
                // A coarse run the scene rejects (h that does not divide the
                // grid, points outside) is skipped; a failure after that ends
                // the family.
                if family.is_empty() && h > scene_h {
                    h *= 0.5;
                    continue;
                }
                break;
            }
            let cost = r.cost();
            family.push(r.clone());
            let (m, note) = measure(target, &family);
            steps.push(Step {
                id: r.id.clone(),
                h,
                ppc,
                cost,
                measure: m,
                predicted,
                note,
            });
            if m <= target.tol {
                break;
            }
            if m.is_finite() {
                measures.push((h, m));
            }
            // The order from the last two measures, else halve.
            let (next, pred) = match measures.as_slice() {
                [.., (h1, e1), (h2, e2)] if e1 > e2 && *e2 > 0.0 => {
                    let p = (e1 / e2).ln() / (h1 / h2).ln();
                    next_h(h, m, p, target.tol)
                }
                _ => (0.5 * h, f64::NAN),
            };
            // Cost grows about 4x per halving in 2D.
            let halvings = (h / next).log2().round() as i32;
            let next_cost = cost * 4f64.powi(halvings);
            if spent + next_cost > budget_s {
                ended = format!(
                    "budget: the next run (h = {next}) would take about {next_cost:.1} s, {:.1} s of {budget_s} s spent",
                    spent
                );
                break;
            }
            h = next;
            predicted = pred;
        }
    }
    let best = (0..steps.len())
        .filter(|&i| steps[i].measure <= target.tol && steps[i].cost.is_finite())
        .min_by(|&a, &b| steps[a].cost.total_cmp(&steps[b].cost));
    Ok(Found {
        target: target.clone(),
        steps,
        best,
        ended,
    })
}

/// The search's report: the path of each family and the answer.
pub fn report(f: &Found) -> String {
    use std::fmt::Write;
    let what = if f.target.is_exact() {
        "measured against the exact solution"
    } else {
        "relative GCI of the three finest runs of a family"
    };
    let mut s = format!("target: {} <= {:e} ({what})\n", f.target.quantity, f.target.tol);
    let _ = writeln!(
        s,
        "  {:<24} {:>10} {:>5} {:>10} {:>12} {:>12}  note",
        "run", "h", "ppc", "cost s", "predicted", "measure"
    );
    let g = |v: f64| if v.is_finite() { format!("{v:.3e}") } else { "-".into() };
    for (i, st) in f.steps.iter().enumerate() {
        let _ = writeln!(
            s,
            "{} {:<24} {:>10} {:>5} {:>10} {:>12} {:>12}  {}",
            if Some(i) == f.best { "*" } else { " " },
            st.id,
            st.h,
            st.ppc.map_or("-".into(), |p| p.to_string()),
            if st.cost.is_finite() {
                format!("{:.4}", st.cost)
            } else {
                "-".into()
            },
            g(st.predicted),
            g(st.measure),
            st.note
        );
    }
    match f.best {
        Some(i) => {
            let b = &f.steps[i];
            let _ = writeln!(
                s,
                "cheapest meeting the target: {} ({:.4} s; {} {:.3e}{})",
                b.id,
                b.cost,
                f.target.quantity,
                b.measure,
                if b.predicted.is_finite() {
                    format!(", predicted {:.3e}", b.predicted)
                } else {
                    String::new()
                }
            );
        }
        None => {
            let _ = writeln!(s, "no run met the target ({})", f.ended);
        }
    }
    let _ = writeln!(s, "search ended: {}", f.ended);
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets_parse_and_bad_ones_say_why() {
        let t = Target::parse("probe:tip:uy=1e-3").unwrap();
        assert_eq!((t.quantity.as_str(), t.tol), ("probe:tip:uy", 1e-3));
        assert!(Target::parse("error:stress_l2=0.01").unwrap().is_exact());
        assert!(Target::parse("stress_l2=0.01").unwrap_err().contains("error:<name>"));
        assert!(Target::parse("error:stress_l2=-1").unwrap_err().contains("positive"));
        assert!(Target::parse("error:stress_l2").unwrap_err().contains("QUANTITY=TOL"));
    }

    #[test]
    fn the_next_cell_size_is_the_largest_halving_that_meets_the_target() {
        // First order, error 0.1 at h = 1: 0.05 meets 0.06 after one halving.
        assert_eq!(next_h(1.0, 0.1, 1.0, 0.06), (0.5, 0.05));
        // Second order, 0.1 -> 0.004 needs 0.1/16 = 0.00625 > 0.004: three.
        let (h, p) = next_h(1.0, 0.1, 2.0, 0.004);
        assert_eq!(h, 0.125);
        assert!((p - 0.1 / 64.0).abs() < 1e-15);
    }
}
