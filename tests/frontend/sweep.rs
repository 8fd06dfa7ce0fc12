//! `mpmlab sweep` end to end: the CSV, observed rates, restart, failed runs
//! as rows, emitted jobs collected, and the SVG charts read back.

use crate::common;
use crate::common::{mpmlab, temp_path};
use mpmlab::sweep::{from_csv, rates, RunResult};
use std::path::Path;
use std::process::Command;

fn table(dir: &Path) -> Vec<RunResult> {
    from_csv(&std::fs::read_to_string(dir.join("sweep.csv")).unwrap())
}

fn error(r: &RunResult, name: &str) -> f64 {
    r.errors.iter().find(|e| e.0 == name).unwrap().1
}

/// Count `needle` in `hay`.
fn count(hay: &str, needle: &str) -> usize {
    hay.matches(needle).count()
}

fn column_sweep(dir: &Path, jobs: &str) -> (i32, String, String) {
    mpmlab(&[
        "sweep",
        "scenarios/column-small-strain.toml",
        "--vary",
        "h=1.0,0.5,0.25",
        "--vary",
        "ppc=2",
        "--jobs",
        jobs,
        "--out",
        dir.to_str().unwrap(),
    ])
}

#[test]
fn small_sweep_table_rates_restart_and_charts() {
    let dir = temp_path("sweep", "d");
    let (code, out, err) = column_sweep(&dir, "2");
    assert_eq!(code, 0, "{out}{err}");
    let rows = table(&dir);
    assert_eq!(rows.len(), 3, "{out}");
    // Stable column names: id, the settings, the fixed columns, the errors.
    let header = std::fs::read_to_string(dir.join("sweep.csv")).unwrap();
    let header = header.lines().next().unwrap();
    assert!(
        header.starts_with("id,set:h,set:ppc,completed,steps_done,steps_total,failed_step,failure,wall_s,assembly_s,factorisation_s,solve_s,condition_s,unknowns,iterations,peak_rss_kb,condition,mapping_s,pattern_s,update_s,negative_pivots,cutbacks,repeats,error:"),
        "{header}"
    );
    // Values: the G (31) error of the confined column is exactly h/(4H)
    // (engine/tests/physics/column.rs): 2.5e-2, 1.25e-2, 6.25e-3 for H = 10 m.
    for (r, e) in rows.iter().zip([2.5e-2, 1.25e-2, 6.25e-3]) {
        assert!(r.completed && r.failure.is_empty(), "{r:?}");
        assert!((error(r, "syy_normalised") / e - 1.0).abs() < 1e-9, "{r:?}");
        assert!(r.wall_s > 0.0 && r.unknowns > 0 && r.iterations == 1);
        // Millisecond runs are timed as the fastest of several (else the
        // machine's noise would decide the Pareto front).
        assert_eq!(r.repeats, mpmlab::sweep::REPEATS, "{r:?}");
    }
    assert_eq!(
        rows[0].settings,
        vec![("h".into(), "1.0".into()), ("ppc".into(), "2".into())]
    );
    // Observed rates between successive refinements: exactly first order.
    let r: Vec<f64> = rates(&rows, "h")
        .into_iter()
        .filter(|x| x.3 == "syy_normalised")
        .map(|x| x.4)
        .collect();
    assert_eq!(r.len(), 2);
    assert!(r.iter().all(|x| (x - 1.0).abs() < 1e-9), "{r:?}");
    assert!(out.contains("observed rates") && out.contains("Pareto front"), "{out}");

    // Restart: nothing is run again; the results are untouched.
    let result = dir.join("results").join("h=0.5_ppc=2.csv");
    let before = std::fs::read_to_string(&result).unwrap();
    let (code, out, _) = column_sweep(&dir, "1");
    assert_eq!(code, 0);
    assert!(out.contains("3 runs, 3 already done"), "{out}");
    assert_eq!(std::fs::read_to_string(&result).unwrap(), before);
    assert_eq!(table(&dir).len(), 3);

    // Charts: one circle per completed run in the scatter series, one line
    // per group against h, one cell per run in the stability map.
    let svg = std::fs::read_to_string(dir.join("charts/error_vs_time.svg")).unwrap();
    let runs = svg.split(r#"data-name="Pareto front""#).next().unwrap();
    assert_eq!(count(runs, "<circle") - 1, 3, "three points plus the legend dot");
    assert!(svg.contains(r#"data-name="Pareto front""#));
    let svg = std::fs::read_to_string(dir.join("charts/error_vs_h.svg")).unwrap();
    assert!(svg.contains("rate 1.00"), "{svg}");
    assert_eq!(count(&svg, "<polyline"), 1);
    let svg = std::fs::read_to_string(dir.join("charts/stability.svg")).unwrap();
    assert_eq!(count(&svg, r#"data-completed="true""#), 3);

    // The same in a rerun recording: per-run scalars on the `run` timeline
    // and the charts as 2D entities.
    let positions = rerun::Points2D::descriptor_positions().component;
    let scalars = rerun::Scalars::descriptor_scalars().component;
    let mut points = std::collections::BTreeMap::new();
    let mut wall = Vec::new();
    for chunk in common::read_chunks(&dir.join("sweep.rrd")) {
        let e = chunk.entity_path().to_string();
        for p in chunk.iter_slices::<[f32; 2]>(positions) {
            *points.entry(e.clone()).or_insert(0) += p.len();
        }
        if e == "/runs/wall_s" {
            wall.extend(chunk.iter_slices::<f64>(scalars).map(|v| v[0]));
        }
        points.entry(e).or_insert(0);
    }
    assert_eq!(points.get("/charts/error_vs_time/runs"), Some(&3), "{points:?}");
    assert_eq!(points.get("/charts/stability"), Some(&3), "{points:?}");
    assert_eq!(points.get("/charts/error_vs_h/ppc_2/points"), Some(&3), "{points:?}");
    assert!(points.contains_key("/sweep/summary") && points.contains_key("/charts/error_vs_time/pareto"));
    let mut expected: Vec<f64> = rows.iter().map(|r| r.wall_s).collect();
    let mut got = wall.clone();
    expected.sort_by(f64::total_cmp);
    got.sort_by(f64::total_cmp);
    // The CSV holds the times with six significant digits (%e formatting).
    assert_eq!(got.len(), 3);
    for (a, b) in got.iter().zip(&expected) {
        assert!((a / b - 1.0).abs() < 1e-5, "{got:?} {expected:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_failed_run_is_a_row_with_its_reason() {
    let dir = temp_path("sweep-fail", "d");
    let (code, out, err) = mpmlab(&[
        "sweep",
        "scenarios/patch-compression.toml",
        "--vary",
        "tolerance=1e-8,1e-30",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let rows = table(&dir);
    assert_eq!(rows.len(), 2);
    assert!(rows[0].completed);
    let f = &rows[1];
    assert!(!f.completed && f.failed_step == 1, "{f:?}");
    assert!(f.failure.contains("above tolerance"), "{f:?}");
    assert!(out.contains("fails at step 1"), "{out}");
    let svg = std::fs::read_to_string(dir.join("charts/stability.svg")).unwrap();
    assert_eq!(count(&svg, r#"data-completed="false""#), 1);
    // A setting the scene rejects is a row too, not a crash of the sweep
    // (warned about before the runs; a sweep of nothing but such runs is
    // refused, tests/frontend/hostile.rs).
    let (code, _, err) = mpmlab(&[
        "sweep",
        "scenarios/patch-compression.toml",
        "--vary",
        "h=0.5,0.7",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("warning: run `h=0.7`"), "{err}");
    let bad = table(&dir).into_iter().find(|r| r.id == "h=0.7").unwrap();
    assert!(
        bad.failure.starts_with("bad scene") && bad.failure.contains("grid.size"),
        "{bad:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn emitted_jobs_run_anywhere_and_are_collected() {
    let dir = temp_path("sweep-emit", "d");
    let (code, out, err) = mpmlab(&[
        "sweep",
        "scenarios/column-small-strain.toml",
        "--vary",
        "h=1.0,0.5",
        "--out",
        dir.to_str().unwrap(),
        "--emit-jobs",
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let jobs = std::fs::read_to_string(dir.join("jobs.txt")).unwrap();
    assert_eq!(jobs.lines().count(), 2);
    assert!(!dir.join("sweep.csv").exists(), "nothing ran yet");
    // What a scheduler would do: run each line in a shell, anywhere.
    for line in jobs.lines() {
        let s = Command::new("sh")
            .arg("-c")
            .arg(line)
            .current_dir("/")
            .status()
            .unwrap();
        assert!(s.success(), "{line}");
    }
    let (code, out, err) = mpmlab(&["sweep", "--collect", dir.to_str().unwrap()]);
    assert_eq!(code, 0, "{out}{err}");
    let rows = table(&dir);
    assert_eq!(
        rows.iter().map(|r| r.id.as_str()).collect::<Vec<_>>(),
        ["h=1.0", "h=0.5"]
    );
    assert!(rows.iter().all(|r| r.completed));
    assert!((error(&rows[1], "syy_normalised") - 1.25e-2).abs() < 1e-12);
    assert!(out.contains("h=0.5"), "{out}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_sweep_arguments_are_clear_errors() {
    let (code, _, err) = mpmlab(&["sweep", "--preset", "nope"]);
    assert_eq!(code, 2);
    assert!(
        err.contains("no preset `nope`") && err.contains("beam-stability"),
        "{err}"
    );
    let (code, _, err) = mpmlab(&["sweep", "scenarios/patch-compression.toml", "--vary", "h"]);
    assert_eq!(code, 2);
    assert!(err.contains("key=value1,value2"), "{err}");
}

#[test]
fn an_edited_scene_reruns_and_values_keep_their_spaces_out() {
    let dir = temp_path("sweep-stale", "d");
    let base = temp_path("base", "toml");
    let text = std::fs::read_to_string(common::scene_path("column-small-strain")).unwrap();
    std::fs::write(&base, &text).unwrap();
    let sweep = || {
        mpmlab(&[
            "sweep",
            base.to_str().unwrap(),
            "--vary",
            "h=1.0",
            "--vary",
            "grid.origin=[0.0, 0.0]",
            "--out",
            dir.to_str().unwrap(),
        ])
    };
    let (code, out, err) = sweep();
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("1 runs, 0 already done"), "{out}");
    // The bracketed value survives the run's header (spaces dropped).
    let row = &table(&dir)[0];
    assert!(row.completed, "{row:?}");
    assert_eq!(row.settings[1], ("grid.origin".into(), "[0.0,0.0]".into()));
    // Unchanged: nothing reruns. Edited base scene: the stale result goes.
    let (_, out, _) = sweep();
    assert!(out.contains("1 runs, 1 already done"), "{out}");
    std::fs::write(&base, text.replace("load_steps = 1", "load_steps = 2")).unwrap();
    let (code, out, _) = sweep();
    assert_eq!(code, 0);
    assert!(out.contains("1 runs, 0 already done"), "{out}");
    assert_eq!(table(&dir)[0].steps_total, 2);
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_file(&base);
}

#[test]
fn recorded_sweep_reports_recording_sizes() {
    // `--record`: each run writes recordings/<id>.rrd and its row holds the
    // recording's size, per step and per point; the cadence is a setting.
    let dir = temp_path("sweep-record", "d");
    let (code, out, err) = mpmlab(&[
        "sweep",
        "scenarios/column-small-strain.toml",
        "--vary",
        "h=1.0,0.5",
        "--vary",
        "record.every=1",
        "--record",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let rows = table(&dir);
    assert_eq!(rows.len(), 2, "{out}");
    for r in &rows {
        assert!(r.completed, "{r:?}");
        let rrd = dir.join("recordings").join(format!("{}.rrd", r.id));
        let bytes = std::fs::metadata(&rrd).unwrap().len();
        assert_eq!(r.record_bytes, bytes, "{r:?}");
        assert!((r.record_bytes_per_step - bytes as f64 / r.steps_total as f64).abs() < 1e-6 * bytes as f64);
        assert!(r.record_bytes_per_point > 0.0, "{r:?}");
        // A recorded run is run once (its recording is its time).
        assert_eq!(r.repeats, 1, "{r:?}");
    }
    let header = std::fs::read_to_string(dir.join("sweep.csv")).unwrap();
    assert!(
        header
            .lines()
            .next()
            .unwrap()
            .contains(",cutbacks,repeats,record_bytes,record_bytes_per_step,record_bytes_per_point,error:"),
        "{header}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn estimates_match_the_true_error_in_the_asymptotic_range() {
    // The confined column's probes against the exact column: five cell
    // sizes give three triples, the two finer ones confirmed by the order
    // of the next coarser; every confirmed estimate must be within a
    // factor 2 of the true error (the issue's criterion; measured
    // 0.99-1.01: the column is in its asymptotic range from h = 1, its
    // errors being exact powers of h).
    let dir = temp_path("sweep-estimate", "d");
    let (code, out, err) = mpmlab(&[
        "sweep",
        "scenarios/column-small-strain.toml",
        "--vary",
        "h=1.0,0.5,0.25,0.125,0.0625",
        "--estimate",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("error estimates from the three finest h"), "{out}");
    let text = std::fs::read_to_string(dir.join("estimates.csv")).unwrap();
    let rows = mpmlab::sweep::parse_csv(&text);
    let (header, body) = rows.split_first().unwrap();
    let col = |name: &str| header.iter().position(|c| c == name).unwrap();
    let num = |r: &Vec<String>, name: &str| r[col(name)].parse::<f64>().unwrap_or(f64::NAN);
    let mut checked = 0;
    for r in body {
        let truth = num(r, "true_error");
        if r[col("behaviour")] != "monotone" || !(truth > 1e-9 * num(r, "value_fine").abs()) {
            continue;
        }
        let eff = num(r, "effectivity");
        assert!(
            (0.5..=2.0).contains(&eff),
            "{} at h = {}: {eff}",
            r[col("quantity")],
            r[col("h_fine")]
        );
        checked += 1;
    }
    // top:uy, base:uy, base:sxx, base:syy, top:sxx, top:syy on the two
    // confirmed triples; the coarsest triple has none to confirm it.
    assert!(checked >= 10, "{checked} estimates checked\n{text}");
    assert!(
        body.iter()
            .filter(|r| r[col("h_fine")] == "2.5e-1")
            .all(|r| r[col("behaviour")] != "monotone"),
        "{text}"
    );
    // The orders are the field's: the settlement's position error is
    // second order (zero slope at the free top), the stresses first.
    let order = |q: &str| {
        body.iter()
            .find(|r| r[col("quantity")] == q && r[col("h_fine")] == "6.25e-2")
            .map(|r| num(r, "order"))
            .unwrap()
    };
    assert!((order("probe:top:uy") - 2.0).abs() < 0.05, "{}", order("probe:top:uy"));
    assert!(
        (order("probe:base:syy") - 1.0).abs() < 0.05,
        "{}",
        order("probe:base:syy")
    );
    // The finest run's row carries its estimates; the chart is drawn.
    let sweep = std::fs::read_to_string(dir.join("sweep.csv")).unwrap();
    assert!(
        sweep.lines().next().unwrap().contains("estimate:probe:top:uy:gci"),
        "{sweep}"
    );
    assert!(dir.join("charts/estimates_vs_h.svg").exists());

    // Without a refinement of three sizes --estimate is refused.
    let (code, _, err) = mpmlab(&[
        "sweep",
        "scenarios/column-small-strain.toml",
        "--vary",
        "h=1.0,0.5",
        "--estimate",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--estimate needs a refinement study"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_target_search_predicts_and_meets_the_error() {
    // The confined column's G (31) error is exactly h/(4H) with 2x2 points
    // (H = 10 m): 2.5e-2 at h = 1, 1.25e-2 at 0.5. For a target of 1e-2
    // the observed order 1 predicts 6.25e-3 one halving on, at h = 0.25,
    // which the run must measure to round-off.
    let dir = temp_path("sweep-target", "d");
    let (code, out, err) = mpmlab(&[
        "sweep",
        "scenarios/column-small-strain.toml",
        "--target",
        "error:syy_normalised=1e-2",
        "--budget",
        "60",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let report = out.split("\ntarget: ").last().unwrap();
    let line = report
        .lines()
        .find(|l| l.contains("h=0.25_ppc=2 "))
        .unwrap_or_else(|| panic!("{out}"));
    let nums: Vec<f64> = line.split_whitespace().filter_map(|w| w.parse().ok()).collect();
    // h, ppc, cost, predicted, measure
    assert_eq!(nums.len(), 5, "{line}");
    assert!(
        (nums[3] - 6.25e-3).abs() < 1e-12 && (nums[4] - 6.25e-3).abs() < 1e-12,
        "{line}"
    );
    assert!(out.contains("cheapest meeting the target:"), "{out}");
    // Every run it made is a row of the folder's table.
    let rows = table(&dir);
    assert!(
        rows.iter().any(|r| r.id == "h=0.25_ppc=2") && rows.len() >= 4,
        "{rows:?}"
    );
    // A target that is not a quantity, or a setting to try that the scene
    // rejects, is refused before anything runs.
    let (code, _, err) = mpmlab(&["sweep", "scenarios/column-small-strain.toml", "--target", "stress=1"]);
    assert_eq!(code, 2, "{err}");
    let (code, _, err) = mpmlab(&[
        "sweep",
        "scenarios/column-small-strain.toml",
        "--target",
        "error:syy_normalised=1e-2",
        "--try",
        "body.0.basis=quadratic",
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--try"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The `<text>` labels of an SVG with their boxes `[x0, y0, x1, y1]`:
/// from the position, the anchor and the font size (the picture's 12 px
/// unless the label sets its own), 0.6 em a character
/// (`svg::text_width`), from 0.8 em above the baseline to 0.2 em below.
fn label_boxes(svg: &str) -> Vec<(String, [f64; 4])> {
    let attr = |tag: &str, name: &str| -> Option<String> {
        let at = tag.find(&format!(" {name}=\""))? + name.len() + 3;
        Some(tag[at..].split('"').next()?.to_string())
    };
    svg.split("<text")
        .skip(1)
        .map(|t| {
            let (tag, rest) = t.split_once('>').unwrap();
            let text = rest.split("</text>").next().unwrap();
            let text = text
                .replace("&lt;", "<")
                .replace("&gt;", ">")
                .replace("&quot;", "\"")
                .replace("&amp;", "&");
            let num = |n: &str| attr(tag, n).map(|v| v.parse::<f64>().unwrap());
            let (x, y, size) = (num("x").unwrap(), num("y").unwrap(), num("font-size").unwrap_or(12.0));
            let w = mpmlab::sweep::svg::text_width(&text, size);
            let x0 = match attr(tag, "text-anchor").as_deref() {
                Some("middle") => x - w / 2.0,
                Some("end") => x - w,
                _ => x,
            };
            (text, [x0, y - 0.8 * size, x0 + w, y + 0.2 * size])
        })
        .collect()
}

/// The stability map's labels do not overlap one another and stay inside
/// the picture, and each run has a cell of its own (none hides another):
/// G Table 5's beam settings with failures side by side, and one long
/// setting (delta/h) whose values and failures sit next to each other.
#[test]
fn stability_map_labels_do_not_overlap_and_every_run_shows() {
    let run = |settings: &[(&str, &str)], fails: usize| RunResult {
        id: settings
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join("_"),
        settings: settings.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect(),
        completed: fails == 0,
        failed_step: fails,
        failure: if fails > 0 {
            format!("step {fails} failed: residual above tolerance")
        } else {
            String::new()
        },
        ..Default::default()
    };
    let mut beam = Vec::new();
    for h in ["0.5", "0.25", "0.125"] {
        for ppc in ["2", "3", "4", "5", "6"] {
            for (k, g) in ["12e6", "1e2", "0"].into_iter().enumerate() {
                beam.push(run(
                    &[("h", h), ("ppc", ppc), ("gamma_k", g)],
                    if k == 0 { 0 } else { 13 },
                ));
            }
        }
    }
    let delta: Vec<RunResult> = ["1e-2", "1e-4", "1e-6", "1e-8", "1e-10", "1e-12"]
        .iter()
        .enumerate()
        .map(|(k, d)| run(&[("delta_over_h", d)], if k > 2 { 1 } else { 0 }))
        .collect();
    for (name, results) in [("beam-stability", beam), ("delta", delta)] {
        let svg = mpmlab::sweep::svg::stability_map(&format!("{name}: which runs complete"), &results);
        let size = |n: &str| -> f64 {
            let at = svg.find(&format!(" {n}=\"")).unwrap() + n.len() + 3;
            svg[at..].split('"').next().unwrap().parse().unwrap()
        };
        let (w, h) = (size("width"), size("height"));
        let boxes = label_boxes(&svg);
        assert!(boxes.len() > results.len(), "{name}: {svg}");
        for (k, (a, p)) in boxes.iter().enumerate() {
            assert!(
                p[0] >= 0.0 && p[2] <= w && p[1] >= 0.0 && p[3] <= h,
                "{name}: `{a}` {p:?} outside {w} x {h}"
            );
            for (b, q) in &boxes[k + 1..] {
                let apart = p[2] <= q[0] || q[2] <= p[0] || p[3] <= q[1] || q[3] <= p[1];
                assert!(apart, "{name}: `{a}` {p:?} overlaps `{b}` {q:?}");
            }
        }
        // One cell per run, failed ones marked.
        let failed = results.iter().filter(|r| !r.completed).count();
        assert_eq!(count(&svg, r#"data-completed="false""#), failed, "{name}");
        let mut cells: Vec<(String, String)> = svg
            .split(r#"<g class="run""#)
            .skip(1)
            .map(|g| {
                let rect = g.split("<rect").nth(1).unwrap();
                let v = |n: &str| {
                    rect.split(&format!(" {n}=\""))
                        .nth(1)
                        .unwrap()
                        .split('"')
                        .next()
                        .unwrap()
                        .to_string()
                };
                (v("x"), v("y"))
            })
            .collect();
        assert_eq!(cells.len(), results.len());
        cells.sort();
        cells.dedup();
        assert_eq!(cells.len(), results.len(), "{name}: runs share a cell");
    }
}
