//! The sweep view (`mpmlab tui --sweep DIR`): a finished or running
//! sweep's table, error against wall time with the Pareto front, error
//! against h, and which runs completed. State, pure drawing, and a small
//! event loop (arrows/jk scroll, r reloads, L hides the legends, q or Esc quits).

use super::draw::{place_legend, AxisEnds, Named};
use crate::sweep::{pareto_front, RunResult};
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Borders, Cell, Chart, Dataset, GraphType, Paragraph, Row, Table};
use ratatui::Frame;

/// What the sweep view shows.
pub struct SweepView {
    pub title: String,
    pub results: Vec<RunResult>,
    /// First table row shown.
    pub scroll: usize,
    /// The charts' legends (`L` hides them).
    pub show_legend: bool,
}

/// Log10 of the positive finite values, else `None`.
fn lg(v: f64) -> Option<f64> {
    (v > 0.0 && v.is_finite()).then(|| v.log10())
}

/// A chart title of whole words in a block `width` wide: `main` and
/// `extra` where both fit, else `main` alone, else `main`'s words that
/// fit and an ellipsis.
fn fit_title(main: &str, extra: &str, width: u16) -> String {
    let room = width.saturating_sub(2) as usize;
    let full = format!("{main}{extra}");
    if full.chars().count() <= room {
        return full;
    }
    if main.chars().count() < room {
        return format!("{main} ");
    }
    let mut out = String::new();
    for word in main.split_whitespace() {
        if out.chars().count() + word.chars().count() + 4 > room {
            break;
        }
        out.push(' ');
        out.push_str(word);
    }
    format!("{out} … ")
}

/// An axis's bounds with its two end labels, as the legend placement
/// takes them.
fn ends(bounds: [f64; 2], labels: Vec<String>) -> AxisEnds {
    let mut l = labels.into_iter();
    (bounds, [l.next().unwrap_or_default(), l.next().unwrap_or_default()])
}

/// Bounds with a little margin, and decade labels.
fn axis(values: &[f64]) -> ([f64; 2], Vec<String>) {
    let (lo, hi) = values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    let (lo, hi) = if lo.is_finite() {
        (lo.floor(), hi.ceil().max(lo.floor() + 1.0))
    } else {
        (0.0, 1.0)
    };
    ([lo, hi], vec![format!("1e{}", lo as i32), format!("1e{}", hi as i32)])
}

impl SweepView {
    fn h_key(&self) -> Option<&'static str> {
        ["h", "grid.h"]
            .into_iter()
            .find(|k| self.results.iter().any(|r| r.setting(k).is_some()))
    }

    /// The setting the convergence chart is drawn against: h where the
    /// sweep varies it, else the first setting that takes several positive
    /// values (delta/h, gamma_K, steps, ...).
    fn axis_key(&self) -> Option<String> {
        if let Some(h) = self.h_key() {
            return Some(h.to_string());
        }
        let keys: Vec<String> = self
            .results
            .iter()
            .flat_map(|r| r.settings.iter().map(|s| s.0.clone()))
            .collect();
        keys.into_iter().find(|k| {
            let mut vals: Vec<f64> = self.results.iter().filter_map(|r| r.setting(k)).collect();
            vals.sort_by(f64::total_cmp);
            vals.dedup();
            vals.len() >= 2 && vals.iter().all(|v| *v > 0.0)
        })
    }

    /// Error estimates from the finest three refinements of h, one per
    /// group and quantity ([`crate::sweep::estimate`]).
    fn estimates(&self) -> Vec<crate::sweep::estimate::Estimate> {
        let Some(h) = self.h_key() else { return Vec::new() };
        let all = crate::sweep::estimate::estimates(&self.results, h);
        crate::sweep::estimate::finest(&all).into_iter().cloned().collect()
    }

    fn error_name(&self) -> String {
        self.results
            .iter()
            .find_map(|r| r.errors.first().map(|e| e.0.clone()))
            .unwrap_or_else(|| "error".into())
    }
}

/// Draw the whole sweep screen.
pub fn draw(frame: &mut Frame, v: &SweepView) {
    let [title, body, status] =
        Layout::vertical([Constraint::Length(1), Constraint::Min(5), Constraint::Length(1)]).areas(frame.area());
    let done = v.results.iter().filter(|r| r.completed).count();
    frame.render_widget(
        Paragraph::new(Line::from(vec![
            Span::styled(
                " mpmlab sweep ",
                Style::new().add_modifier(Modifier::BOLD).bg(Color::Blue),
            ),
            Span::raw(format!(
                " {}  | {} runs, {} completed, {} failed",
                v.title,
                v.results.len(),
                done,
                v.results.len() - done
            )),
        ])),
        title,
    );
    let [left, right] = Layout::horizontal([Constraint::Percentage(50), Constraint::Percentage(50)]).areas(body);
    let estimates = v.estimates();
    let est_height = if estimates.is_empty() {
        0
    } else {
        (estimates.len() as u16 + 3).min(12)
    };
    let [table, est, map] = Layout::vertical([
        Constraint::Min(5),
        Constraint::Length(est_height),
        Constraint::Length(stability_height(v, left.height)),
    ])
    .areas(left);
    draw_table(frame, v, table);
    if !estimates.is_empty() {
        draw_estimates(frame, &estimates, est);
    }
    draw_stability(frame, v, map);
    let [top, bottom] = Layout::vertical([Constraint::Percentage(50), Constraint::Percentage(50)]).areas(right);
    draw_time_chart(frame, v, top);
    draw_h_chart(frame, v, bottom);
    frame.render_widget(
        Paragraph::new(" up/down scroll · r reload · L legends · q quit").style(Style::new().fg(Color::Gray)),
        status,
    );
}

fn draw_table(frame: &mut Frame, v: &SweepView, area: Rect) {
    let err = v.error_name();
    let header = Row::new(vec!["run".to_string(), "outcome".into(), "wall s".into(), err])
        .style(Style::new().add_modifier(Modifier::BOLD));
    let rows = v.results.iter().skip(v.scroll).map(|r| {
        let (outcome, color) = if r.completed {
            ("completed".to_string(), Color::Green)
        } else if r.failed_step > 0 {
            (format!("fails at {}", r.failed_step), Color::Red)
        } else {
            ("invalid".to_string(), Color::Red)
        };
        Row::new(vec![
            Cell::from(r.id.clone()),
            Cell::from(outcome).style(Style::new().fg(color)),
            Cell::from(format!("{:.3}", r.wall_s)),
            Cell::from(r.error().map_or("-".into(), |e| format!("{e:.3e}"))),
        ])
    });
    let widths = [
        Constraint::Percentage(36),
        Constraint::Percentage(26),
        Constraint::Percentage(14),
        Constraint::Percentage(24),
    ];
    frame.render_widget(
        Table::new(rows, widths).header(header).block(
            Block::default()
                .borders(Borders::ALL)
                .title(" runs (green: completed) "),
        ),
        area,
    );
}

/// The estimates panel: per quantity the fine value, observed order,
/// GCI and, where the exact value is known, estimated over true error.
fn draw_estimates(frame: &mut Frame, est: &[crate::sweep::estimate::Estimate], area: Rect) {
    use crate::sweep::estimate::Behaviour;
    let header = Row::new(vec!["quantity", "value", "order", "GCI", "est/true"])
        .style(Style::new().add_modifier(Modifier::BOLD));
    let fmt = |v: f64, f: &dyn Fn(f64) -> String| if v.is_finite() { f(v) } else { "-".into() };
    let rows = est.iter().map(|e| {
        let color = match e.behaviour {
            Behaviour::Monotone | Behaviour::Resolved => Color::Green,
            Behaviour::Unconfirmed | Behaviour::NotAsymptotic | Behaviour::Oscillatory => Color::Yellow,
            Behaviour::Diverging => Color::Red,
        };
        let name = e.quantity.strip_prefix("probe:").unwrap_or(&e.quantity);
        let name = if e.group == "runs" {
            name.to_string()
        } else {
            format!("{} {name}", e.group)
        };
        Row::new(vec![
            Cell::from(name),
            Cell::from(format!("{:.4e}", e.values[0])),
            Cell::from(fmt(e.order, &|p| format!("{p:.2}"))).style(Style::new().fg(color)),
            Cell::from(fmt(e.gci, &|g| format!("{g:.2e}"))),
            Cell::from(fmt(e.effectivity(), &|r| format!("{r:.2}"))),
        ])
    });
    let widths = [
        Constraint::Percentage(36),
        Constraint::Percentage(20),
        Constraint::Percentage(10),
        Constraint::Percentage(18),
        Constraint::Percentage(16),
    ];
    let h = est.first().map_or(0.0, |e| e.h[0]);
    frame.render_widget(
        Table::new(rows, widths)
            .header(header)
            .block(Block::default().borders(Borders::ALL).title(format!(
                " error estimates at h = {h} (GCI; order green: confirmed, yellow: not, red: diverging) "
            ))),
        area,
    );
}

/// The stability map's row labels (all settings but the last), column
/// labels (the last setting) and each run's `(row, column, completed)`.
struct Grid {
    rows: Vec<String>,
    cols: Vec<String>,
    cells: Vec<(usize, usize, bool)>,
}

fn stability_grid(v: &SweepView) -> Grid {
    let (mut rows, mut cols, mut cells) = (Vec::new(), Vec::new(), Vec::new());
    for r in &v.results {
        let n = r.settings.len();
        let row: Vec<String> = r.settings[..n.saturating_sub(1)]
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        let (row, col) = (
            row.join(" "),
            r.settings.last().map(|(k, v)| format!("{k}={v}")).unwrap_or_default(),
        );
        if !rows.contains(&row) {
            rows.push(row.clone());
        }
        if !cols.contains(&col) {
            cols.push(col.clone());
        }
        let i = rows.iter().position(|x| *x == row).unwrap_or(0);
        let j = cols.iter().position(|x| *x == col).unwrap_or(0);
        cells.push((i, j, r.completed));
    }
    Grid { rows, cols, cells }
}

/// Rows for the stability map: all of them where they fit in half the
/// column (at least 16), the table keeping the rest.
fn stability_height(v: &SweepView, column: u16) -> u16 {
    (stability_grid(v).rows.len() as u16 + 3).min((column / 2).max(16))
}

/// Which settings completed: a row per combination of the other settings,
/// a column per value of the last one; green completed, red failed.
fn draw_stability(frame: &mut Frame, v: &SweepView, area: Rect) {
    let Grid { rows, cols, cells } = stability_grid(v);
    let width = cols.iter().map(|c| c.len()).max().unwrap_or(1).max(4) + 1;
    let label = rows.iter().map(|r| r.len()).max().unwrap_or(0).max(4) + 1;
    let mut lines = vec![Line::raw(format!(
        "{:<label$}{}",
        "",
        cols.iter().map(|c| format!("{c:<width$}")).collect::<String>()
    ))];
    // Where not every row fits, the rows with a failed run come first (in
    // their order), then completed ones, and a last line counts the rest:
    // a failure is never hidden for want of room.
    let failing = |i: usize| cells.iter().any(|c| c.0 == i && !c.2);
    let room = area.height.saturating_sub(3) as usize;
    let shown: Vec<usize> = if rows.len() <= room {
        (0..rows.len()).collect()
    } else {
        let keep = room.saturating_sub(1);
        let mut pick: Vec<usize> = (0..rows.len()).filter(|&i| failing(i)).take(keep).collect();
        let more = keep - pick.len();
        pick.extend((0..rows.len()).filter(|&i| !failing(i)).take(more));
        pick.sort_unstable();
        pick
    };
    let failed = v.results.iter().filter(|r| !r.completed).count();
    for (i, r) in rows.iter().enumerate().filter(|(i, _)| shown.contains(i)) {
        let mut spans = vec![Span::raw(format!("{:<label$}", if r.is_empty() { "runs" } else { r }))];
        for j in 0..cols.len() {
            let (text, color) = match cells.iter().find(|c| c.0 == i && c.1 == j) {
                Some((_, _, true)) => ("ok", Color::Green),
                Some((_, _, false)) => ("FAIL", Color::Red),
                None => ("-", Color::Gray),
            };
            spans.push(Span::styled(format!("{text:<width$}"), Style::new().fg(color)));
        }
        lines.push(Line::from(spans));
    }
    let hidden: Vec<usize> = (0..rows.len()).filter(|i| !shown.contains(i)).collect();
    if !hidden.is_empty() {
        let with = hidden.iter().filter(|&&i| failing(i)).count();
        lines.push(Line::styled(
            if with == 0 {
                format!("... {} more rows, all ok", hidden.len())
            } else {
                format!("... {} more rows, {with} with failures", hidden.len())
            },
            Style::new().fg(if with == 0 { Color::Gray } else { Color::Red }),
        ));
    }
    frame.render_widget(
        Paragraph::new(lines).block(
            Block::default()
                .borders(Borders::ALL)
                .title(format!(" stability map ({failed} failed) ")),
        ),
        area,
    );
}

fn draw_time_chart(frame: &mut Frame, v: &SweepView, area: Rect) {
    let done: Vec<&RunResult> = v.results.iter().filter(|r| r.completed).collect();
    let pts: Vec<(f64, f64)> = done.iter().map(|r| (r.cost(), r.error().unwrap_or(f64::NAN))).collect();
    let all: Vec<(f64, f64)> = pts.iter().filter_map(|p| Some((lg(p.0)?, lg(p.1)?))).collect();
    let mut front = pareto_front(&pts);
    front.sort_by(|&a, &b| pts[a].0.partial_cmp(&pts[b].0).unwrap());
    let line: Vec<(f64, f64)> = front
        .iter()
        .filter_map(|&i| Some((lg(pts[i].0)?, lg(pts[i].1)?)))
        .collect();
    let (xb, xl) = axis(&all.iter().map(|p| p.0).collect::<Vec<_>>());
    let (yb, yl) = axis(&all.iter().map(|p| p.1).collect::<Vec<_>>());
    let data = [
        Dataset::default()
            .name("runs")
            .marker(Marker::Dot)
            .graph_type(GraphType::Scatter)
            .style(Style::new().fg(Color::Cyan))
            .data(&all),
        Dataset::default()
            .name("Pareto front")
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .style(Style::new().fg(Color::Red))
            .data(&line),
    ];
    let named: [Named; 2] = [
        ("runs", Color::Cyan, &all, false),
        ("Pareto front", Color::Red, &line, true),
    ];
    let (x, y) = (ends(xb, xl), ends(yb, yl));
    let chart = Chart::new(data.to_vec())
        .x_axis(Axis::default().bounds(xb).labels(x.1.clone()))
        .y_axis(Axis::default().bounds(yb).labels(y.1.clone()));
    let block = Block::default().borders(Borders::ALL).title(fit_title(
        &format!(" {} against wall time", v.error_name()),
        " (log-log) ",
        area.width,
    ));
    frame.render_widget(place_legend(chart, block, &named, (&x, &y), area, v.show_legend), area);
}

/// The error (lines, with the observed rate) and the condition number
/// (dots) of the completed runs against h, or against the setting the
/// sweep varies when it keeps h (delta/h, gamma_K, ...), log-log.
fn draw_h_chart(frame: &mut Frame, v: &SweepView, area: Rect) {
    let Some(key) = v.axis_key() else {
        let block = Block::default()
            .borders(Borders::ALL)
            .title(format!(" {} against h (log-log) ", v.error_name()));
        frame.render_widget(
            Paragraph::new("no setting takes several positive values in this sweep").block(block),
            area,
        );
        return;
    };
    let h = key.as_str();
    let block = Block::default().borders(Borders::ALL).title(fit_title(
        &format!(" {} (lines) and cond(K) (dots) against {h}", v.error_name()),
        " (log-log) ",
        area.width,
    ));
    // Each group's points from fine to coarse (log10 setting, log10 error),
    // then its condition numbers.
    /// A series: its name, its points, and whether it is a condition number.
    type Series = (String, Vec<(f64, f64)>, bool);
    let mut groups: Vec<Series> = Vec::new();
    for (label, g) in crate::sweep::groups_without(&v.results, h) {
        let mut pts: Vec<(f64, f64)> = g
            .iter()
            .filter_map(|r| Some((lg(r.setting(h)?)?, lg(r.error()?)?)))
            .collect();
        pts.reverse();
        let mut cond: Vec<(f64, f64)> = g
            .iter()
            .filter_map(|r| Some((lg(r.setting(h)?)?, lg(r.condition)?)))
            .collect();
        cond.reverse();
        groups.push((label.clone(), pts, false));
        if !cond.is_empty() {
            groups.push((format!("cond, {label}"), cond, true));
        }
    }
    let xs: Vec<f64> = groups.iter().flat_map(|g| g.1.iter().map(|p| p.0)).collect();
    let ys: Vec<f64> = groups.iter().flat_map(|g| g.1.iter().map(|p| p.1)).collect();
    let (xb, xl) = axis(&xs);
    let (yb, yl) = axis(&ys);
    let colors = [
        Color::Cyan,
        Color::Yellow,
        Color::Magenta,
        Color::Green,
        Color::Blue,
        Color::White,
    ];
    // Each series' legend name (lines with their observed rate) and colour.
    let names: Vec<(String, Color)> = groups
        .iter()
        .enumerate()
        .map(|(k, (label, pts, cond))| {
            if *cond {
                return (label.clone(), Color::Gray);
            }
            let rate = match (pts.first(), pts.last()) {
                (Some(a), Some(b)) if b.0 != a.0 => format!(" (rate {:.2})", (b.1 - a.1) / (b.0 - a.0)),
                _ => String::new(),
            };
            (format!("{label}{rate}"), colors[k % colors.len()])
        })
        .collect();
    let data: Vec<Dataset> = groups
        .iter()
        .zip(&names)
        .map(|((_, pts, cond), (name, color))| {
            let (marker, kind) = if *cond {
                (Marker::Dot, GraphType::Scatter)
            } else {
                (Marker::Braille, GraphType::Line)
            };
            Dataset::default()
                .name(name.clone())
                .marker(marker)
                .graph_type(kind)
                .style(Style::new().fg(*color))
                .data(pts)
        })
        .collect();
    let named: Vec<Named> = groups
        .iter()
        .zip(&names)
        .map(|((_, pts, cond), (name, color))| (name.as_str(), *color, pts.as_slice(), !*cond))
        .collect();
    let (x, y) = (ends(xb, xl), ends(yb, yl));
    let chart = Chart::new(data)
        .x_axis(Axis::default().bounds(xb).labels(x.1.clone()))
        .y_axis(Axis::default().bounds(yb).labels(y.1.clone()));
    frame.render_widget(place_legend(chart, block, &named, (&x, &y), area, v.show_legend), area);
}

/// Show a sweep folder until the user quits; `r` re-reads it (a sweep
/// running elsewhere fills in).
pub fn run(folder: &crate::sweep::Folder, title: &str) -> std::io::Result<()> {
    use ratatui::crossterm::event::{self, Event, KeyCode, KeyEventKind};
    let load = || {
        let mut all = folder.collect();
        let order: Vec<String> = std::fs::read_to_string(folder.0.join("runs.txt"))
            .map(|t| t.lines().map(str::to_string).collect())
            .unwrap_or_default();
        let mut r: Vec<RunResult> = order.iter().filter_map(|id| all.remove(id)).collect();
        r.extend(all.into_values());
        r
    };
    let mut view = SweepView {
        title: title.to_string(),
        results: load(),
        scroll: 0,
        show_legend: true,
    };
    let mut terminal = ratatui::init();
    let result = (|| -> std::io::Result<()> {
        loop {
            terminal.draw(|f| draw(f, &view))?;
            if let Event::Key(k) = event::read()? {
                if k.kind != KeyEventKind::Press {
                    continue;
                }
                match k.code {
                    KeyCode::Char('q') | KeyCode::Esc => return Ok(()),
                    KeyCode::Down | KeyCode::Char('j') => {
                        view.scroll = (view.scroll + 1).min(view.results.len().saturating_sub(1))
                    }
                    KeyCode::Up | KeyCode::Char('k') => view.scroll = view.scroll.saturating_sub(1),
                    KeyCode::Char('r') => view.results = load(),
                    KeyCode::Char('L') => view.show_legend = !view.show_legend,
                    _ => {}
                }
            }
        }
    })();
    ratatui::restore();
    result
}
