//! A sweep as a rerun recording (`sweeps/<name>/sweep.rrd`), next to its
//! CSV and SVG charts:
//!
//! | entity | archetype |
//! |---|---|
//! | `sweep/summary` | TextDocument: the summary table, rates and Pareto front |
//! | `runs/<measure>` | Scalars on the `run` timeline (run index): wall time, unknowns, iterations, completed, each error |
//! | `charts/error_vs_time/runs`, `.../pareto` | Points2D / LineStrips2D in log10 coordinates, labelled by run |
//! | `charts/error_vs_h/<group>` | LineStrips2D and Points2D, log10 coordinates |
//! | `charts/stability` | Points2D on a grid (column: last setting, row: the others), green completed, red failed |
//!
//! The charts are drawn with y up (a static transform on `charts`, as for
//! a run's scene: [`super::layout`]), and the recording is listed in the
//! viewer as `sweep <name>`, after the sweep's folder. Its own layout
//! ([`layout`]) shows the three charts, the per-run metrics and the
//! summary; without one the viewer would reuse the last run's layout
//! (recordings share the application id) and show empty panels.

use super::{RecordError, APP_ID};
use crate::sweep::{pareto_front, RunResult};
use rerun::RecordingStreamBuilder;
use std::path::Path;

/// The sweep's layout: the charts on the left (error against h only when
/// the sweep varies h), the summary and the per-run metrics on the right.
fn layout(with_h: bool) -> rerun::blueprint::Blueprint {
    use rerun::blueprint::{
        Blueprint, ContainerLike, Horizontal, Spatial2DView, TextDocumentView, TimeSeriesView, Vertical,
    };
    let mut charts: Vec<ContainerLike> =
        vec![
            Spatial2DView::new("log10 error against log10 wall time (s), Pareto front red")
                .with_origin("/")
                .with_contents(["/charts/error_vs_time/**"])
                .into(),
        ];
    if with_h {
        charts.push(
            Spatial2DView::new("log10 error against log10 h (in the scene's length unit)")
                .with_origin("/")
                .with_contents(["/charts/error_vs_h/**"])
                .into(),
        );
    }
    charts.push(
        Spatial2DView::new("stability: green completed, red failed")
            .with_origin("/")
            .with_contents(["/charts/stability/**"])
            .into(),
    );
    let charts = Vertical::new(charts);
    let right = Vertical::new([
        TextDocumentView::new("summary").with_origin("/sweep/summary").into(),
        TimeSeriesView::new("per run (x: run index)")
            .with_origin("/runs")
            .into(),
    ]);
    // The charts' views start at the root: a transform above a view's
    // origin does not apply in it, and the y flip sits on `charts`.
    use rerun::blueprint::components::PanelState;
    use rerun::blueprint::{SelectionPanel, TimePanel};
    Blueprint::new(Horizontal::new([charts.into(), right.into()]))
        .with_selection_panel(SelectionPanel::new().with_state(PanelState::Collapsed))
        .with_time_panel(TimePanel::new().with_state(PanelState::Collapsed).with_timeline("run"))
}

fn log10_point(x: f64, y: f64) -> Option<[f32; 2]> {
    (x > 0.0 && y > 0.0 && x.is_finite() && y.is_finite()).then(|| [x.log10() as f32, y.log10() as f32])
}

/// Write the recording of a finished sweep.
pub fn record_sweep(path: &Path, summary: &str, results: &[RunResult], h_key: Option<&str>) -> Result<(), RecordError> {
    let err = |m: String| RecordError::Write {
        path: path.to_path_buf(),
        message: m,
    };
    let name = path
        .parent()
        .and_then(|d| d.file_name())
        .map_or("sweep".to_string(), |d| format!("sweep {}", d.to_string_lossy()));
    let rec = RecordingStreamBuilder::new(APP_ID)
        .recording_name(name)
        .save(path)
        .map_err(|e| err(e.to_string()))?;
    let check = |r: Result<(), rerun::RecordingStreamError>| r.map_err(|e| err(e.to_string()));
    check(layout(h_key.is_some()).send(&rec, rerun::blueprint::BlueprintActivation::default()))?;
    check(rec.log_static("charts", &super::layout::y_up()))?;
    check(rec.log_static(
        "sweep/summary",
        &rerun::TextDocument::new(format!("```\n{summary}\n```")).with_media_type(rerun::MediaType::markdown()),
    ))?;
    for (k, r) in results.iter().enumerate() {
        rec.set_time_sequence("run", k as i64);
        let mut scalars = vec![
            ("wall_s", r.wall_s),
            ("unknowns", r.unknowns as f64),
            ("iterations", r.iterations as f64),
            ("completed", if r.completed { 1.0 } else { 0.0 }),
        ];
        for (n, v) in &r.errors {
            scalars.push((n.as_str(), *v));
        }
        for (n, v) in scalars {
            if v.is_finite() {
                check(rec.log(format!("runs/{n}"), &rerun::Scalars::single(v)))?;
            }
        }
    }
    rec.reset_time();
    // Error against wall time, with the Pareto front.
    let done: Vec<&RunResult> = results.iter().filter(|r| r.completed).collect();
    let pts: Vec<(f64, f64)> = done.iter().map(|r| (r.cost(), r.error().unwrap_or(f64::NAN))).collect();
    let shown: Vec<(usize, [f32; 2])> = pts
        .iter()
        .enumerate()
        .filter_map(|(i, p)| log10_point(p.0, p.1).map(|q| (i, q)))
        .collect();
    if !shown.is_empty() {
        check(
            rec.log_static(
                "charts/error_vs_time/runs",
                &rerun::Points2D::new(shown.iter().map(|s| s.1))
                    .with_labels(shown.iter().map(|s| done[s.0].id.clone()))
                    .with_colors([rerun::Color::from_rgb(31, 119, 180)]),
            ),
        )?;
        let mut front = pareto_front(&pts);
        front.sort_by(|&a, &b| pts[a].0.partial_cmp(&pts[b].0).unwrap());
        let line: Vec<[f32; 2]> = front.iter().filter_map(|&i| log10_point(pts[i].0, pts[i].1)).collect();
        check(rec.log_static(
            "charts/error_vs_time/pareto",
            &rerun::LineStrips2D::new([line]).with_colors([rerun::Color::from_rgb(214, 39, 40)]),
        ))?;
    }
    // Error against h, one line per group of the other settings.
    if let Some(h) = h_key {
        for (label, g) in crate::sweep::groups_without(results, h) {
            let line: Vec<[f32; 2]> = g
                .iter()
                .filter_map(|r| log10_point(r.setting(h)?, r.error()?))
                .collect();
            // Entity path parts: letters, digits, '.', '-' and '_' only.
            let name: String = label
                .chars()
                .map(|c| {
                    if c.is_ascii_alphanumeric() || ".-".contains(c) {
                        c
                    } else {
                        '_'
                    }
                })
                .collect();
            check(rec.log_static(
                format!("charts/error_vs_h/{name}"),
                &rerun::LineStrips2D::new([line.clone()]),
            ))?;
            check(rec.log_static(format!("charts/error_vs_h/{name}/points"), &rerun::Points2D::new(line)))?;
        }
    }
    // Stability map.
    let (mut rows, mut cols): (Vec<String>, Vec<String>) = (Vec::new(), Vec::new());
    let key = |r: &RunResult| {
        let n = r.settings.len();
        let row: Vec<String> = r.settings[..n.saturating_sub(1)]
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        (
            row.join(" "),
            r.settings.last().map(|(k, v)| format!("{k}={v}")).unwrap_or_default(),
        )
    };
    let mut cells = Vec::new();
    for r in results {
        let (a, b) = key(r);
        if !rows.contains(&a) {
            rows.push(a.clone());
        }
        if !cols.contains(&b) {
            cols.push(b.clone());
        }
        let (i, j) = (
            rows.iter().position(|x| *x == a).unwrap_or(0),
            cols.iter().position(|x| *x == b).unwrap_or(0),
        );
        let color = if r.completed {
            rerun::Color::from_rgb(42, 157, 69)
        } else {
            rerun::Color::from_rgb(209, 73, 91)
        };
        let label = if r.completed {
            format!("{}: completed", r.id)
        } else if r.failed_step > 0 {
            format!("{}: fails at step {}", r.id, r.failed_step)
        } else {
            format!("{}: invalid ({})", r.id, r.failure)
        };
        cells.push(([j as f32, -(i as f32)], color, label));
    }
    check(
        rec.log_static(
            "charts/stability",
            &rerun::Points2D::new(cells.iter().map(|c| c.0))
                .with_colors(cells.iter().map(|c| c.1))
                .with_labels(cells.iter().map(|c| c.2.clone()))
                .with_radii([rerun::Radius::new_scene_units(0.3)]),
        ),
    )?;
    rec.flush_blocking().map_err(|e| err(e.to_string()))
}
