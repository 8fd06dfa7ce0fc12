//! Carrying out a sweep: write the runs' scenes, run the pending ones as
//! child processes (`mpmlab sweep-run`, one per run, at most `jobs` at a
//! time, so each run is single-threaded and its peak memory its own), or
//! emit them as a job list; then merge the results into `sweep.csv`, print
//! a summary and draw the charts.

use super::svg::{self, Series, PALETTE};
use super::{estimate, expand, pareto_front, rates, run_scene, to_csv, Folder, Run, RunResult, Vary};
use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

fn io(what: &str, p: &Path, e: std::io::Error) -> String {
    format!("{what} {}: {e}", p.display())
}

/// Write each run's scene and the run order; return the runs.
pub fn prepare(folder: &Folder, base: &str, fixed: &[(String, String)], varies: &[Vary]) -> Result<Vec<Run>, String> {
    let runs = expand(varies);
    for d in [folder.runs(), folder.results()] {
        std::fs::create_dir_all(&d).map_err(|e| io("cannot create", &d, e))?;
    }
    for r in &runs {
        let text = run_scene(base, fixed, r)?;
        let p = folder.run_scene(&r.id);
        // A changed scene (base or fixed settings edited) makes an old
        // result stale: drop it so the run is done again.
        if std::fs::read_to_string(&p).is_ok_and(|old| old != text) {
            let _ = std::fs::remove_file(folder.result(&r.id));
            let _ = remove_row(folder, &r.id);
        }
        std::fs::write(&p, text).map_err(|e| io("cannot write", &p, e))?;
    }
    let order: Vec<&str> = runs.iter().map(|r| r.id.as_str()).collect();
    let p = folder.0.join("runs.txt");
    std::fs::write(&p, order.join("\n") + "\n").map_err(|e| io("cannot write", &p, e))?;
    Ok(runs)
}

/// Drop a run's row from `sweep.csv`.
fn remove_row(folder: &Folder, id: &str) -> std::io::Result<()> {
    let Ok(text) = std::fs::read_to_string(folder.csv()) else {
        return Ok(());
    };
    let rows: Vec<RunResult> = super::from_csv(&text).into_iter().filter(|r| r.id != id).collect();
    std::fs::write(folder.csv(), to_csv(&rows))
}

/// The runs without a result yet (restart: finished runs are not redone).
pub fn pending(folder: &Folder, runs: &[Run]) -> Vec<Run> {
    let done = folder.collect();
    runs.iter().filter(|r| !done.contains_key(&r.id)).cloned().collect()
}

/// The command that runs one run, with absolute paths so that it runs
/// from any working directory.
fn command_line(exe: &Path, folder: &Folder, id: &str, record: bool) -> String {
    let q = |p: &Path| {
        let p = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
        format!("'{}'", p.display().to_string().replace('\'', "'\\''"))
    };
    let rec = if record {
        format!(" --record {}", q(&folder.recording(id)))
    } else {
        String::new()
    };
    format!(
        "{} sweep-run {} --result {}{rec}",
        q(exe),
        q(&folder.run_scene(id)),
        q(&folder.result(id))
    )
}

/// Write `jobs.txt`: one shell command per pending run.
pub fn emit_jobs(folder: &Folder, exe: &Path, runs: &[Run], record: bool) -> Result<std::path::PathBuf, String> {
    if record {
        let d = folder.0.join("recordings");
        std::fs::create_dir_all(&d).map_err(|e| io("cannot create", &d, e))?;
    }
    let lines: Vec<String> = runs.iter().map(|r| command_line(exe, folder, &r.id, record)).collect();
    let p = folder.0.join("jobs.txt");
    std::fs::write(&p, lines.join("\n") + if lines.is_empty() { "" } else { "\n" })
        .map_err(|e| io("cannot write", &p, e))?;
    Ok(p)
}

/// Run `runs` as child processes, `jobs` at a time; `progress` gets a line
/// per finished run. A child that dies without a result gets a failed row.
/// With `record`, each run writes its recording ([`Folder::recording`]).
pub fn execute(
    folder: &Folder,
    exe: &Path,
    runs: &[Run],
    jobs: usize,
    record: bool,
    progress: &(dyn Fn(String) + Sync),
) {
    if record {
        let _ = std::fs::create_dir_all(folder.0.join("recordings"));
    }
    let next = AtomicUsize::new(0);
    let done = Mutex::new(0usize);
    std::thread::scope(|s| {
        for _ in 0..jobs.max(1).min(runs.len().max(1)) {
            s.spawn(|| loop {
                let k = next.fetch_add(1, Ordering::SeqCst);
                let Some(run) = runs.get(k) else { break };
                let result = folder.result(&run.id);
                let mut cmd = Command::new(exe);
                cmd.arg("sweep-run")
                    .arg(folder.run_scene(&run.id))
                    .arg("--result")
                    .arg(&result);
                if record {
                    cmd.arg("--record").arg(folder.recording(&run.id));
                }
                let status = cmd.stdout(std::process::Stdio::null()).status();
                let r = match std::fs::read_to_string(&result)
                    .ok()
                    .and_then(|t| super::from_csv(&t).pop())
                {
                    Some(r) => r,
                    None => {
                        let r = RunResult {
                            id: run.id.clone(),
                            settings: run.settings.clone(),
                            failure: format!("{} ({status:?})", super::DIED),
                            condition: f64::NAN,
                            ..Default::default()
                        };
                        let _ = std::fs::write(&result, to_csv(std::slice::from_ref(&r)));
                        r
                    }
                };
                let mut n = done.lock().expect("progress counter");
                *n += 1;
                progress(format!(
                    "[{}/{}] {}: {}",
                    *n,
                    runs.len(),
                    r.id,
                    if r.completed {
                        format!("completed in {:.3} s", r.wall_s)
                    } else {
                        r.failure.clone()
                    }
                ));
            });
        }
    });
}

/// Merge every result into `sweep.csv` (in run order), draw the charts and
/// return the summary text.
pub fn finish(folder: &Folder, title: &str) -> Result<String, String> {
    let mut all = folder.collect();
    let order: Vec<String> = std::fs::read_to_string(folder.0.join("runs.txt"))
        .map(|t| t.lines().map(str::to_string).collect())
        .unwrap_or_default();
    let mut results: Vec<RunResult> = order.iter().filter_map(|id| all.remove(id)).collect();
    // Without a run list (results gathered from elsewhere) take them all;
    // with one, rows of earlier sweeps in the same folder stay out.
    if order.is_empty() {
        results.extend(all.into_values());
    }
    let h = h_key(&results);
    let est = h.as_deref().map_or(Vec::new(), |h| estimate::estimates(&results, h));
    attach_estimates(&mut results, &est);
    let p = folder.csv();
    std::fs::write(&p, to_csv(&results)).map_err(|e| io("cannot write", &p, e))?;
    let mut charts = draw(folder, title, &results)?;
    let mut s = summary(&results);
    if let (Some(h), false) = (&h, est.is_empty()) {
        let e = folder.0.join("estimates.csv");
        std::fs::write(&e, estimate::to_csv(&est)).map_err(|x| io("cannot write", &e, x))?;
        let _ = write!(s, "\n{}", estimate::summary(&est, h));
        let _ = writeln!(s, "estimates: {}", e.display());
        if let Some(svg) = estimate_chart(title, h, &results, &est) {
            let c = folder.charts().join("estimates_vs_h.svg");
            std::fs::write(&c, svg).map_err(|x| io("cannot write", &c, x))?;
            charts.push(c);
        }
    }
    let rrd = folder.0.join("sweep.rrd");
    crate::record::sweep::record_sweep(&rrd, &s, &results, h_key(&results).as_deref()).map_err(|e| e.to_string())?;
    let _ = writeln!(s, "table: {}", p.display());
    for c in charts {
        let _ = writeln!(s, "chart: {}", c.display());
    }
    let _ = writeln!(
        s,
        "recording: {}  (replay: mpmlab replay {})",
        rrd.display(),
        rrd.display()
    );
    Ok(s)
}

/// Put each estimate's order, extrapolated value and GCI on the row of its
/// finest run (columns `estimate:<quantity>:<order|extrapolated|gci>`).
fn attach_estimates(results: &mut [RunResult], est: &[estimate::Estimate]) {
    for e in estimate::finest(est) {
        if let Some(r) = results.iter_mut().find(|r| r.id == e.ids[0]) {
            for (k, v) in [("order", e.order), ("extrapolated", e.extrapolated), ("gci", e.gci)] {
                r.estimates.push((format!("{}:{k}", e.quantity), v));
            }
        }
    }
}

/// Estimated error (the fine run's `|phi - phi_ext|` of each triple)
/// against h per quantity, with the true error where the scene knows the
/// exact value: the chart that shows where the estimate can be trusted.
fn estimate_chart(title: &str, h: &str, results: &[RunResult], est: &[estimate::Estimate]) -> Option<String> {
    let mut quantities: Vec<(&str, &str)> = Vec::new();
    for e in est.iter().filter(|e| e.error.is_finite() && e.error > 0.0) {
        if !quantities.contains(&(e.group.as_str(), e.quantity.as_str())) {
            quantities.push((&e.group, &e.quantity));
        }
    }
    // Those with an exact value first; at most six curves of each kind.
    quantities.sort_by_key(|(g, q)| {
        !est.iter()
            .any(|e| e.group == *g && e.quantity == *q && e.exact.is_some())
    });
    quantities.truncate(6);
    let mut series = Vec::new();
    for (k, (g, q)) in quantities.iter().enumerate() {
        let name = if *g == "runs" {
            q.to_string()
        } else {
            format!("{g} {q}")
        };
        let color = PALETTE[k % PALETTE.len()];
        let mut pts: Vec<(f64, f64, String)> = est
            .iter()
            .filter(|e| e.group == *g && e.quantity == *q && e.error.is_finite() && e.error > 0.0)
            .map(|e| {
                (
                    e.h[0],
                    e.error,
                    format!("{}: estimated {:.3e} ({})", e.ids[0], e.error, e.behaviour.label()),
                )
            })
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        series.push(Series {
            name: format!("{name} estimated"),
            points: pts,
            color,
            line: true,
        });
        let truth: Vec<(f64, f64, String)> = super::groups_without(results, h)
            .into_iter()
            .filter(|(label, _)| label == g)
            .flat_map(|(_, runs)| runs)
            .filter_map(|r| {
                let v = r.quantities().into_iter().find(|(n, _)| n == q)?.1;
                let t = (v - r.exact_value(q)?).abs();
                let x = r.setting(h)?;
                (t > 0.0).then(|| (x, t, format!("{}: true error {t:.3e}", r.id)))
            })
            .collect();
        if !truth.is_empty() {
            series.push(Series {
                name: format!("{name} true"),
                points: truth,
                color,
                line: false,
            });
        }
    }
    if series.is_empty() {
        return None;
    }
    Some(svg::chart(
        &format!("{title}: estimated error against {h} (lines) and true error (dots)"),
        h,
        "error",
        &series,
        true,
        true,
    ))
}

/// The summary table, observed rates and the Pareto front.
pub fn summary(results: &[RunResult]) -> String {
    let mut s = String::new();
    let errors: Vec<String> = results
        .iter()
        .find(|r| !r.errors.is_empty())
        .map(|r| r.errors.iter().map(|e| e.0.clone()).collect())
        .unwrap_or_default();
    let _ = write!(
        s,
        "{:<36} {:>18} {:>9} {:>8} {:>6} {:>10}",
        "run", "outcome", "wall s", "unknowns", "iters", "cond"
    );
    for e in &errors {
        let _ = write!(s, " {e:>18}");
    }
    s.push('\n');
    for r in results {
        let outcome = if r.completed {
            "completed".to_string()
        } else if r.failed_step > 0 {
            format!("fails at step {}", r.failed_step)
        } else {
            "invalid".to_string()
        };
        let _ = write!(
            s,
            "{:<36} {:>18} {:>9.3} {:>8} {:>6} {:>10}",
            r.id,
            outcome,
            r.wall_s,
            r.unknowns,
            r.iterations,
            if r.condition.is_finite() {
                format!("{:.2e}", r.condition)
            } else {
                "-".into()
            }
        );
        for e in &errors {
            match r.errors.iter().find(|x| &x.0 == e) {
                Some((_, v)) => {
                    let _ = write!(s, " {v:>18.4e}");
                }
                None => {
                    let _ = write!(s, " {:>18}", "-");
                }
            }
        }
        s.push('\n');
        if !r.completed && !r.failure.is_empty() {
            let _ = writeln!(s, "    {}", r.failure);
        }
    }
    if let Some(h) = h_key(results) {
        let rs = rates(results, &h);
        if !rs.is_empty() {
            let _ = writeln!(s, "\nobserved rates log(e1/e2)/log(h1/h2):");
            for (group, h1, h2, name, rate) in rs {
                let _ = writeln!(s, "  {group:<28} {h}: {h1} -> {h2}  {name:<24} {rate:.3}");
            }
        }
    }
    let pts: Vec<(f64, f64)> = results
        .iter()
        .map(|r| {
            if r.completed {
                (r.cost(), r.error().unwrap_or(f64::NAN))
            } else {
                (f64::NAN, f64::NAN)
            }
        })
        .collect();
    let front = pareto_front(&pts);
    if !front.is_empty() {
        let names: Vec<&str> = front.iter().map(|&i| results[i].id.as_str()).collect();
        let _ = writeln!(
            s,
            "\nPareto front (wall time without condition numbers, {}): {}",
            errors[0],
            names.join(", ")
        );
    }
    s
}

/// The setting that plays the role of the cell size, if varied.
fn h_key(results: &[RunResult]) -> Option<String> {
    let keys: Vec<&String> = results.iter().flat_map(|r| r.settings.iter().map(|(k, _)| k)).collect();
    ["h", "grid.h"]
        .iter()
        .find(|k| keys.iter().any(|x| x == *k))
        .map(|k| k.to_string())
}

/// Write the charts; return their paths.
fn draw(folder: &Folder, title: &str, results: &[RunResult]) -> Result<Vec<std::path::PathBuf>, String> {
    let dir = folder.charts();
    std::fs::create_dir_all(&dir).map_err(|e| io("cannot create", &dir, e))?;
    let mut written = Vec::new();
    let mut put = |name: &str, text: String| -> Result<(), String> {
        let p = dir.join(name);
        std::fs::write(&p, text).map_err(|e| io("cannot write", &p, e))?;
        written.push(p);
        Ok(())
    };
    let error_name = results
        .iter()
        .find_map(|r| r.errors.first().map(|e| e.0.clone()))
        .unwrap_or_else(|| "error".into());
    let done: Vec<&RunResult> = results.iter().filter(|r| r.completed && r.error().is_some()).collect();
    if !done.is_empty() {
        let pts: Vec<(f64, f64)> = done.iter().map(|r| (r.cost(), r.error().unwrap())).collect();
        let mut front: Vec<usize> = pareto_front(&pts);
        front.sort_by(|&a, &b| pts[a].0.partial_cmp(&pts[b].0).unwrap());
        let tip = |r: &RunResult| format!("{}: {:.3e} s, {:.3e}", r.id, r.cost(), r.error().unwrap());
        let series = vec![
            Series {
                name: "runs".into(),
                points: done.iter().map(|r| (r.cost(), r.error().unwrap(), tip(r))).collect(),
                color: "#1f77b4",
                line: false,
            },
            Series {
                name: "Pareto front".into(),
                points: front.iter().map(|&i| (pts[i].0, pts[i].1, tip(done[i]))).collect(),
                color: "#d62728",
                line: true,
            },
        ];
        put(
            "error_vs_time.svg",
            svg::chart(
                &format!("{title}: {error_name} against wall time"),
                "wall time without condition numbers (s)",
                &error_name,
                &series,
                true,
                true,
            ),
        )?;
        if let Some(h) = h_key(results) {
            let groups = super::groups_without(results, &h);
            let series: Vec<Series> = groups
                .into_iter()
                .enumerate()
                .map(|(k, (label, g))| {
                    let (first, last) = (g[0], g[g.len() - 1]);
                    let rate = match (first.setting(&h), last.setting(&h), first.error(), last.error()) {
                        (Some(h1), Some(h2), Some(e1), Some(e2)) if h1 != h2 && e1 > 0.0 && e2 > 0.0 => {
                            format!(" (rate {:.2})", (e1 / e2).ln() / (h1 / h2).ln())
                        }
                        _ => String::new(),
                    };
                    Series {
                        name: format!("{label}{rate}"),
                        points: g
                            .iter()
                            .filter_map(|r| Some((r.setting(&h)?, r.error()?, tip(r))))
                            .collect(),
                        color: PALETTE[k % PALETTE.len()],
                        line: true,
                    }
                })
                .collect();
            put(
                "error_vs_h.svg",
                svg::chart(
                    &format!("{title}: {error_name} against h"),
                    "h",
                    &error_name,
                    &series,
                    true,
                    true,
                ),
            )?;
        }
    }
    // One varied setting other than h (delta/h, gamma): error and condition
    // number against it, as C Fig. 13 and G Table 4 show them.
    let keys: Vec<&String> = results
        .first()
        .map(|r| r.settings.iter().map(|(k, _)| k).collect())
        .unwrap_or_default();
    if let [key] = keys.as_slice() {
        if Some((*key).clone()) != h_key(results) && results.iter().all(|r| r.setting(key).is_some()) {
            let log_x = results.iter().all(|r| r.setting(key).is_some_and(|v| v > 0.0));
            let by = |f: &dyn Fn(&RunResult) -> Option<f64>| -> Vec<(f64, f64, String)> {
                let mut v: Vec<(f64, f64, String)> = results
                    .iter()
                    .filter(|r| r.completed)
                    .filter_map(|r| Some((r.setting(key)?, f(r)?, r.id.clone())))
                    .collect();
                v.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
                v
            };
            let error = by(&|r| r.error());
            let cond = by(&|r| Some(r.condition).filter(|c| c.is_finite()));
            for (name, pts, label) in [
                ("error", error, error_name.clone()),
                ("condition", cond, "condition number".into()),
            ] {
                if pts.is_empty() {
                    continue;
                }
                let series = [Series {
                    name: label.clone(),
                    points: pts,
                    color: "#1f77b4",
                    line: true,
                }];
                put(
                    &format!("{name}_vs_{}.svg", key.replace('.', "_")),
                    svg::chart(
                        &format!("{title}: {label} against {key}"),
                        key,
                        &label,
                        &series,
                        log_x,
                        true,
                    ),
                )?;
            }
        }
    }
    put(
        "stability.svg",
        svg::stability_map(&format!("{title}: which runs complete"), results),
    )?;
    Ok(written)
}
