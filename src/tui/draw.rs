//! Pure drawing: `draw(frame, &app)` renders the whole screen.

use super::app::{App, ChartKind};
use crate::colormap;
use crate::format;
use crate::simulation::{StepFailure, StepReport};
use crate::units::{Quantity, Units};
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::canvas::{Canvas, Line as CLine, Points};
use ratatui::widgets::{Block, Borders, Cell, Clear, Paragraph, Row, Table, Wrap};
use ratatui::Frame;

/// Number of colour bins used on the canvas.
const BINS: usize = 8;

pub fn draw(frame: &mut Frame, app: &App) {
    let area = frame.area();
    let [title, body, status] =
        Layout::vertical([Constraint::Length(1), Constraint::Min(5), Constraint::Length(1)]).areas(area);
    frame.render_widget(
        Paragraph::new(Line::from(vec![
            Span::styled(" mpmlab ", Style::new().add_modifier(Modifier::BOLD).bg(Color::Blue)),
            Span::raw(format!(
                " {}  | step {}/{}  {}  | {} points, grid {}x{} h={}",
                app.scene_name,
                app.view.step,
                app.view.load_steps,
                match app.view.time {
                    Some(t) => format!("t = {t:.4} s"),
                    None => format!("load factor {:.3}", app.view.load_factor),
                },
                app.points,
                app.grid.nx,
                app.grid.ny,
                app.grid.h
            )),
        ])),
        title,
    );
    let [canvas, side] = Layout::horizontal([Constraint::Percentage(50), Constraint::Percentage(50)]).areas(body);
    draw_canvas(frame, app, canvas);
    // Taller terminals give the last step and the chart more rows.
    let extra = side.height.saturating_sub(28);
    let [params, last, chart, table] = Layout::vertical([
        Constraint::Length(if app.implicit_dynamics { 4 } else { 3 }),
        Constraint::Length(12 + extra / 2),
        Constraint::Length(9 + extra / 4),
        Constraint::Min(3),
    ])
    .areas(side);
    draw_params(frame, app, params);
    draw_last_step(frame, app, last);
    match app.chart {
        ChartKind::Residual => draw_residuals(frame, app, chart),
        ChartKind::Probe => draw_probes(frame, app, chart),
        ChartKind::Energy if app.view.time.is_some() => draw_energies(frame, app, chart),
        kind => draw_per_step(frame, app, chart, kind),
    }
    draw_table(frame, app, table);
    let keys = if app.implicit_dynamics {
        "space step · enter run/pause · g/G gamma_K · m/M gamma_M · ? help · q quit"
    } else if app.view.time.is_some() {
        "space step · enter run/pause · m/M gamma_M · ? help · q quit"
    } else {
        "space step · enter run/pause · g/G gamma_K · ? help · q quit"
    };
    let rec = app
        .recording
        .as_deref()
        .map(|r| format!("  rec: {r}"))
        .unwrap_or_default();
    match &app.input {
        Some(text) => frame.render_widget(
            Paragraph::new(format!(" set: {text}_   ({})", app.status)).style(Style::new().fg(Color::Yellow)),
            status,
        ),
        None => frame.render_widget(
            Paragraph::new(format!(" {keys}  | {}{rec}", app.status)).style(Style::new().fg(Color::Gray)),
            status,
        ),
    }
    if let Some(r) = &app.redo {
        draw_redo(frame, area, r);
    } else if let (true, Some(f)) = (app.show_failure, &app.failure) {
        draw_failure(frame, area, f);
    }
    if app.show_help {
        draw_help(frame, area);
    }
}

/// A centred box of at most `w x h` cells, cleared.
fn centred(frame: &mut Frame, area: Rect, w: u16, h: u16) -> Rect {
    let (w, h) = (w.min(area.width), h.min(area.height));
    let r = Rect::new(area.x + (area.width - w) / 2, area.y + (area.height - h) / 2, w, h);
    frame.render_widget(Clear, r);
    r
}

/// What to try after a failure of this kind.
fn remedies(f: &StepFailure) -> &'static [&'static str] {
    match f {
        StepFailure::NotConverged { .. } => &[
            "raise the ghost penalty gamma_K (G), or switch ghost on (0)",
            "take smaller load steps (more steps in the scene)",
            "loosen the tolerance if the residual stalls at round-off",
        ],
        StepFailure::Singular { .. } => &[
            "raise gamma_K (G): nodes that points barely touch need it",
            "enlarge the implicit-boundary bandwidth delta (D)",
            "for dynamics: use the stabilised mass or raise gamma_M (M)",
            "check that supports hold every rigid-body mode",
        ],
        StepFailure::NonFinite { .. } | StepFailure::Diverged { .. } => &[
            "explicit dynamics: raise gamma_M (M) or use the stabilised mass",
            "take a smaller time step (more steps over the duration)",
            "quasi-static: raise gamma_K (G) or take smaller load steps",
        ],
        StepFailure::LeftGrid { .. } => &["enlarge the grid in the scene file"],
        StepFailure::Boundary { .. } => &["check the boundary's points: it needs at least two, in order"],
        StepFailure::Internal { .. } => &["this is a bug: please report it with the scene file"],
        StepFailure::OutOfMemory { .. } => &[
            "use a larger grid h in the scene file (fewer unknowns)",
            "start mpmlab with a larger --max-memory, if the machine has it",
        ],
        StepFailure::Cancelled { .. } => &["space takes the step again (change parameters first if you like)"],
        StepFailure::Finished { .. } => &[],
    }
}

/// `text` in lines of at most `width` characters, broken between words (a
/// word longer than a line is broken where the line ends).
fn wrap_words(text: &str, width: usize) -> Vec<String> {
    let width = width.max(1);
    let mut out: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        let mut word: Vec<char> = word.chars().collect();
        while word.len() > width {
            if !line.is_empty() {
                out.push(std::mem::take(&mut line));
            }
            out.push(word.drain(..width).collect());
        }
        let word: String = word.into_iter().collect();
        let n = line.chars().count();
        if n > 0 && n + 1 + word.chars().count() > width {
            out.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(&word);
    }
    if !line.is_empty() || out.is_empty() {
        out.push(line);
    }
    out
}

/// The failure panel: why, the residual history and what to try.
fn draw_failure(frame: &mut Frame, area: Rect, f: &StepFailure) {
    let r = centred(frame, area, 86, 16);
    let mut lines = vec![Line::styled(f.to_string(), Style::new().fg(Color::Red))];
    if !f.residuals().is_empty() {
        let res: Vec<String> = f.residuals().iter().map(|x| format!("{x:.2e}")).collect();
        lines.push(Line::raw(format!("residuals: {}", res.join(" "))));
    }
    lines.push(Line::raw(""));
    lines.push(Line::styled("try:", Style::new().add_modifier(Modifier::BOLD)));
    for t in remedies(f) {
        lines.push(Line::raw(format!("  - {t}")));
    }
    lines.push(Line::raw(""));
    lines.push(Line::raw(
        "then r redoes the step with the new parameters (space tries it again); Esc hides this",
    ));
    frame.render_widget(
        Paragraph::new(lines).wrap(Wrap { trim: false }).block(
            Block::default()
                .borders(Borders::ALL)
                .title(format!(" step {} failed ", f.step()))
                .border_style(Style::new().fg(Color::Red)),
        ),
        r,
    );
}

/// Before and after a redo, side by side.
fn draw_redo(frame: &mut Frame, area: Rect, outcomes: &(super::app::Outcome, super::app::Outcome)) {
    // As wide as the terminal allows (up to 140 columns), each column's
    // lines wrapped between words to its width.
    let w = area.width.saturating_sub(4).clamp(40, 140);
    let col = (w.saturating_sub(3) / 2) as usize;
    let describe = |o: &super::app::Outcome| -> Vec<String> {
        match o {
            Ok(r) => {
                let mut v = vec![
                    "completed".to_string(),
                    format!("iterations {}", r.iterations),
                    format!(
                        "residuals {}",
                        r.residuals
                            .iter()
                            .map(|x| format!("{x:.1e}"))
                            .collect::<Vec<_>>()
                            .join(" ")
                    ),
                    r.condition.map_or("cond -".into(), |c| format!("cond {:.3e}", c.value)),
                ];
                v.extend(r.errors.iter().map(|e| format!("{} {:.4e}", e.name, e.value)));
                v
            }
            Err(f) => vec![
                "FAILED".to_string(),
                f.to_string(),
                format!(
                    "residuals {}",
                    f.residuals()
                        .iter()
                        .map(|x| format!("{x:.1e}"))
                        .collect::<Vec<_>>()
                        .join(" ")
                ),
            ],
        }
    };
    let (a, b) = (describe(&outcomes.0), describe(&outcomes.1));
    let cells: Vec<(Vec<String>, Vec<String>)> = (0..a.len().max(b.len()))
        .map(|k| {
            (
                wrap_words(a.get(k).map_or("", |s| s.as_str()), col),
                wrap_words(b.get(k).map_or("", |s| s.as_str()), col),
            )
        })
        .collect();
    let h = cells.iter().map(|(x, y)| x.len().max(y.len()) as u16).sum::<u16>() + 4;
    let rows = cells.into_iter().map(|(x, y)| {
        let height = x.len().max(y.len()) as u16;
        Row::new([Cell::from(x.join("\n")), Cell::from(y.join("\n"))]).height(height)
    });
    let r = centred(frame, area, w, h.max(14));
    frame.render_widget(
        Table::new(rows, [Constraint::Length(col as u16), Constraint::Length(col as u16)])
            .header(Row::new(["before", "after (current parameters)"]).style(Style::new().add_modifier(Modifier::BOLD)))
            .block(
                Block::default()
                    .borders(Borders::ALL)
                    .title(" redo: before / after (Esc closes) "),
            ),
        r,
    );
}

/// The points binned by colour (each bin is one `Points` shape), and the
/// field's range.
fn colour_bins(app: &App) -> (Vec<Vec<(f64, f64)>>, f64, f64) {
    let (lo, hi) = colormap::range(app.view.values.iter().copied());
    let mut bins: Vec<Vec<(f64, f64)>> = vec![Vec::new(); BINS];
    for (x, v) in app.view.positions.iter().zip(&app.view.values) {
        let t = colormap::unit(*v, lo, hi);
        let b = ((t * BINS as f64) as usize).min(BINS - 1);
        bins[b].push((x[0], x[1]));
    }
    (bins, lo, hi)
}

/// The colour bar: the field's range through the colour map, low to high.
fn colour_legend(label: &str, lo: f64, hi: f64) -> Line<'static> {
    let mut legend = vec![Span::raw(format!(" {label} {lo:.3e} "))];
    for k in 0..12 {
        let [r, gg, bb] = colormap::viridis((k as f64 + 0.5) / 12.0);
        legend.push(Span::styled("█", Style::new().fg(Color::Rgb(r, gg, bb))));
    }
    legend.push(Span::raw(if hi > lo {
        format!(" {hi:.3e} ")
    } else {
        " (uniform) ".to_string()
    }));
    Line::from(legend)
}

/// The canvas's x and y bounds: the grid, zoomed and panned, with square
/// cells (the shorter extent padded; terminal cells are ~1:2).
fn canvas_bounds(app: &App, area: Rect) -> ([f64; 2], [f64; 2]) {
    let g = &app.grid;
    let max = g.max();
    let (w, h) = (max[0] - g.origin[0], max[1] - g.origin[1]);
    let inner = (
        area.width.saturating_sub(2).max(1) as f64,
        2.0 * area.height.saturating_sub(2).max(1) as f64,
    );
    let scale = (w / inner.0).max(h / inner.1);
    let (cx, cy) = (
        0.5 * (g.origin[0] + max[0]) + app.pan[0],
        0.5 * (g.origin[1] + max[1]) + app.pan[1],
    );
    let (hw, hh) = (0.5 * scale * inner.0 / app.zoom, 0.5 * scale * inner.1 / app.zoom);
    ([cx - hw, cx + hw], [cy - hh, cy + hh])
}

/// The bottom layer: grid lines (thinned on dense grids) and supports.
fn paint_grid(ctx: &mut ratatui::widgets::canvas::Context, app: &App) {
    let g = &app.grid;
    let max = g.max();
    let grid_color = Color::DarkGray;
    let dense = g.nx + g.ny > 400;
    let step_i = if dense { g.nx.div_ceil(50).max(1) } else { 1 };
    let step_j = if dense { g.ny.div_ceil(50).max(1) } else { 1 };
    if app.show_grid {
        for i in (0..=g.nx).step_by(step_i).chain([g.nx]) {
            let x = g.origin[0] + i as f64 * g.h;
            ctx.draw(&CLine::new(x, g.origin[1], x, max[1], grid_color));
        }
        for j in (0..=g.ny).step_by(step_j).chain([g.ny]) {
            let y = g.origin[1] + j as f64 * g.h;
            ctx.draw(&CLine::new(g.origin[0], y, max[0], y, grid_color));
        }
    }
    // Grid supports (magenta lines; a supported node as a cross), with
    // the grid: the layers above (active cells, boundaries) show over them.
    let support = Color::Magenta;
    for (a, b) in &app.view.supports {
        if a == b {
            let d = 0.25 * g.h;
            ctx.draw(&CLine::new(a[0] - d, a[1] - d, a[0] + d, a[1] + d, support));
            ctx.draw(&CLine::new(a[0] - d, a[1] + d, a[0] + d, a[1] - d, support));
        } else {
            ctx.draw(&CLine::new(a[0], a[1], b[0], b[1], support));
        }
    }
}

/// The middle layer: active and cut cells, implicit boundaries, point
/// loads, ghost faces, B-spline boundaries and their names.
fn paint_shapes(ctx: &mut ratatui::widgets::canvas::Context, app: &App) {
    let g = &app.grid;
    // Outlines of cells `c` in a colour.
    let outline = |ctx: &mut ratatui::widgets::canvas::Context, cells: &[usize], col: Color| {
        for &c in cells {
            let m = g.cell_min(c % g.nx, c / g.nx);
            let (x0, y0, x1, y1) = (m[0], m[1], m[0] + g.h, m[1] + g.h);
            ctx.draw(&CLine::new(x0, y0, x1, y0, col));
            ctx.draw(&CLine::new(x1, y0, x1, y1, col));
            ctx.draw(&CLine::new(x1, y1, x0, y1, col));
            ctx.draw(&CLine::new(x0, y1, x0, y0, col));
        }
    };
    if app.show_active {
        outline(ctx, &app.view.active_cells, Color::Rgb(60, 120, 200));
    }
    outline(ctx, &app.view.cut_cells, Color::Rgb(0, 110, 120));
    for line in &app.view.ibm {
        for w in line.windows(2) {
            ctx.draw(&CLine::new(w[0][0], w[0][1], w[1][0], w[1][1], Color::Cyan));
        }
    }
    // Point loads: an arrow two cells long pointing at the point.
    for (p, d) in &app.view.loads {
        let l = 2.0 * g.h;
        let tail = [p[0] - l * d[0], p[1] - l * d[1]];
        ctx.draw(&CLine::new(tail[0], tail[1], p[0], p[1], Color::LightRed));
        let (c, s) = (0.3 * g.h, 0.15 * g.h);
        for sign in [-1.0, 1.0] {
            let head = [p[0] - c * d[0] - sign * s * d[1], p[1] - c * d[1] + sign * s * d[0]];
            ctx.draw(&CLine::new(head[0], head[1], p[0], p[1], Color::LightRed));
        }
    }
    if app.show_ghost_faces {
        for (a, b) in &app.view.ghost_faces {
            ctx.draw(&CLine::new(a[0], a[1], b[0], b[1], Color::Rgb(240, 140, 20)));
        }
    }
    for bv in &app.view.boundaries {
        let color = if bv.loaded { Color::LightRed } else { Color::White };
        for w in bv.curve.windows(2) {
            ctx.draw(&CLine::new(w[0][0], w[0][1], w[1][0], w[1][1], color));
        }
    }
    if app.show_control {
        let coords: Vec<(f64, f64)> = app
            .view
            .boundaries
            .iter()
            .flat_map(|b| b.control.iter().map(|p| (p[0], p[1])))
            .collect();
        ctx.draw(&Points {
            coords: &coords,
            color: Color::Yellow,
        });
    }
    // Names of the implicit boundaries (at their first vertex) and
    // of the B-spline boundaries (at the middle of their curve).
    for (line, name) in app.view.ibm.iter().zip(&app.view.ibm_names) {
        if let Some(p) = line.first() {
            ctx.print(p[0], p[1], Span::styled(name.clone(), Style::new().fg(Color::Cyan)));
        }
    }
    for bv in &app.view.boundaries {
        if let Some(p) = bv.curve.get(bv.curve.len() / 2) {
            let color = if bv.loaded { Color::LightRed } else { Color::White };
            ctx.print(p[0], p[1], Span::styled(bv.name.clone(), Style::new().fg(color)));
        }
    }
}

fn draw_canvas(frame: &mut Frame, app: &App, area: Rect) {
    let (bins, lo, hi) = colour_bins(app);
    let (x_bounds, y_bounds) = canvas_bounds(app, area);
    let canvas = Canvas::default()
        .block(
            Block::default()
                .borders(Borders::ALL)
                .title(if app.zoom > 1.0 {
                    format!(" points (zoom x{}) ", app.zoom)
                } else {
                    " points ".to_string()
                })
                .title_bottom(colour_legend(&app.view.label, lo, hi)),
        )
        .marker(Marker::Braille)
        .x_bounds(x_bounds)
        .y_bounds(y_bounds)
        .paint(move |ctx| {
            paint_grid(ctx, app);
            ctx.layer();
            paint_shapes(ctx, app);
            ctx.layer();
            for (b, coords) in bins.iter().enumerate() {
                if coords.is_empty() {
                    continue;
                }
                let [r, gg, bb] = colormap::viridis((b as f64 + 0.5) / BINS as f64);
                ctx.draw(&Points {
                    coords,
                    color: Color::Rgb(r, gg, bb),
                });
            }
        });
    frame.render_widget(canvas, area);
}

fn draw_params(frame: &mut Frame, app: &App, area: Rect) {
    let p = &app.params;
    let ghost = if p.gamma_k > 0.0 {
        format!(
            "gamma_K {:.3e} {} ({:.1e} E)",
            p.gamma_k,
            app.units.of(Quantity::Stress),
            p.gamma_k / app.modulus
        )
    } else {
        "ghost off".to_string()
    };
    let text = if app.implicit_dynamics {
        format!(
            "{ghost}  delta/h {:.0e}  gamma_M {:.3e} {}  tol {:.1e}  max it {}  cond {:?}",
            p.delta_over_h,
            p.gamma_m,
            app.units.of(Quantity::Density),
            p.tolerance,
            p.max_iterations,
            p.condition
        )
    } else if app.view.time.is_some() {
        format!(
            "gamma_M {:.3e} {} (m/M: /10, x10)  cond {:?}",
            p.gamma_m,
            app.units.of(Quantity::Density),
            p.condition
        )
    } else {
        format!(
            "{ghost}  delta/h {:.0e}  tol {:.1e}  max it {}  cond {:?}",
            p.delta_over_h, p.tolerance, p.max_iterations, p.condition
        )
    };
    frame.render_widget(
        Paragraph::new(text)
            .wrap(Wrap { trim: true })
            .block(Block::default().borders(Borders::ALL).title(" parameters ")),
        area,
    );
}

/// Residual per iteration, log10, for the last few steps (newest brightest).
fn draw_residuals(frame: &mut Frame, app: &App, area: Rect) {
    use ratatui::widgets::Dataset;
    let mut series: Vec<Vec<(f64, f64)>> = app
        .reports
        .iter()
        .rev()
        .take(4)
        .map(|r| {
            r.residuals
                .iter()
                .enumerate()
                .filter(|(_, v)| **v > 0.0)
                .map(|(i, v)| (i as f64, v.log10()))
                .collect()
        })
        .collect();
    if let Some(f) = &app.failure {
        series.insert(
            0,
            f.residuals()
                .iter()
                .enumerate()
                .filter(|(_, v)| **v > 0.0)
                .map(|(i, v)| (i as f64, v.log10()))
                .collect(),
        );
    }
    let (mut ymin, mut ymax, mut xmax) = (-16.0f64, 1.0f64, 1.0f64);
    for s in &series {
        for &(x, y) in s {
            ymin = ymin.min(y.floor());
            ymax = ymax.max(y.ceil());
            xmax = xmax.max(x);
        }
    }
    let colors = [
        Color::White,
        Color::Gray,
        Color::DarkGray,
        Color::DarkGray,
        Color::DarkGray,
    ];
    let datasets: Vec<Dataset> = series
        .iter()
        .enumerate()
        .map(|(k, s)| {
            line(
                "",
                if k == 0 && app.failure.is_some() {
                    Color::Red
                } else {
                    colors[k.min(4)]
                },
                s,
            )
        })
        .collect();
    let chart = framed(
        datasets,
        " residual per iteration (log10; v: next chart) ".into(),
        ([0.0, xmax], ["0".into(), format!("{xmax}")]),
        ([ymin, ymax], [format!("1e{ymin}"), format!("1e{ymax}")]),
    );
    frame.render_widget(chart, area);
}

/// One probe quantity against another ([`App::probe_columns`]), from the
/// initial state to the last step, with a marker at the last point.
fn draw_probes(frame: &mut Frame, app: &App, area: Rect) {
    let cols = app.probe_columns();
    let (xc, yc) = (app.probe_x.min(cols.len() - 1), app.probe_y.min(cols.len() - 1));
    let data: Vec<(f64, f64)> = app
        .probe_series(xc)
        .into_iter()
        .zip(app.probe_series(yc))
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    let bounds = |v: &mut dyn Iterator<Item = f64>| {
        let (lo, hi) = v.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
        if !(lo <= hi) {
            [0.0, 1.0]
        } else if hi > lo {
            [lo, hi]
        } else {
            [lo - 0.5 * lo.abs().max(1e-30), hi + 0.5 * hi.abs().max(1e-30)]
        }
    };
    let xb = bounds(&mut data.iter().map(|p| p.0));
    let yb = bounds(&mut data.iter().map(|p| p.1));
    let last: Vec<(f64, f64)> = data.last().copied().into_iter().collect();
    let datasets = vec![
        line("", Color::Cyan, &data),
        ratatui::widgets::Dataset::default()
            .marker(Marker::Dot)
            .graph_type(ratatui::widgets::GraphType::Scatter)
            .style(Style::new().fg(Color::Yellow))
            .data(&last),
    ];
    let lab = |v: f64| format!("{v:.3e}");
    let chart = framed(
        datasets,
        format!(" {} against {} (p/P) ", cols[yc].1, cols[xc].1),
        (xb, [lab(xb[0]), lab(xb[1])]),
        (yb, [lab(yb[0]), lab(yb[1])]),
    );
    frame.render_widget(chart, area);
}

/// A named line series (an empty name shows no legend entry); a single
/// value is drawn as a dot (a line needs two).
fn line<'a>(name: &str, color: Color, data: &'a [(f64, f64)]) -> ratatui::widgets::Dataset<'a> {
    use ratatui::widgets::GraphType;
    let (marker, kind) = if data.len() == 1 {
        (Marker::Dot, GraphType::Scatter)
    } else {
        (Marker::Braille, GraphType::Line)
    };
    let d = ratatui::widgets::Dataset::default()
        .marker(marker)
        .graph_type(kind)
        .style(Style::new().fg(color))
        .data(data);
    if name.is_empty() {
        d
    } else {
        d.name(name.to_string())
    }
}

/// A chart in a bordered block, each axis with its bounds and end labels.
fn framed<'a>(
    datasets: Vec<ratatui::widgets::Dataset<'a>>,
    title: String,
    x: ([f64; 2], [String; 2]),
    y: ([f64; 2], [String; 2]),
) -> ratatui::widgets::Chart<'a> {
    use ratatui::widgets::{Axis, Chart};
    Chart::new(datasets)
        .block(Block::default().borders(Borders::ALL).title(title))
        .x_axis(Axis::default().bounds(x.0).labels(x.1))
        .y_axis(Axis::default().bounds(y.0).labels(y.1))
}

/// An axis: its bounds and its two end labels.
pub(crate) type AxisEnds = ([f64; 2], [String; 2]);

/// A named, coloured series of a chart with a legend: name, colour, data,
/// and whether its points are joined by lines (else scattered).
pub(crate) type Named<'a> = (&'a str, Color, &'a [(f64, f64)], bool);

/// A chart of named series whose legend hides none of their curves: in
/// the corner (or edge) of the plot where the curves cross no cell under
/// the legend's box; when every place would hide some, the names go into
/// the chart's bottom border instead, in their colours. Without `show`,
/// no legend.
fn with_legend<'a>(
    series: &[Named<'a>],
    title: String,
    x: ([f64; 2], [String; 2]),
    y: ([f64; 2], [String; 2]),
    area: Rect,
    show: bool,
) -> ratatui::widgets::Chart<'a> {
    use ratatui::widgets::{Axis, Chart, Dataset};
    let datasets: Vec<Dataset<'a>> = series.iter().map(|(n, c, d, _)| line(n, *c, d)).collect();
    let chart = Chart::new(datasets)
        .x_axis(Axis::default().bounds(x.0).labels(x.1.clone()))
        .y_axis(Axis::default().bounds(y.0).labels(y.1.clone()));
    place_legend(
        chart,
        Block::default().borders(Borders::ALL).title(title),
        series,
        (&x, &y),
        area,
        show,
    )
}

/// Give `chart` its `block` and a legend of `series` that hides none of
/// their curves ([`legend_place`]): in the plot, or as coloured names in
/// the block's bottom border; none without `show`. `axes` are the chart's
/// bounds and end labels.
pub(crate) fn place_legend<'a>(
    chart: ratatui::widgets::Chart<'a>,
    mut block: Block<'a>,
    series: &[Named],
    axes: (&AxisEnds, &AxisEnds),
    area: Rect,
    show: bool,
) -> ratatui::widgets::Chart<'a> {
    let placement = if show {
        legend_place(series, axes.0, axes.1, area)
    } else {
        None
    };
    let position = match placement {
        Some(Ok(p)) => Some(p),
        Some(Err(())) => {
            // Whole names only: those that fit in the border, then how
            // many are left out (L hides the legend to see the chart).
            let named: Vec<&Named> = series.iter().filter(|s| !s.0.is_empty() && !s.2.is_empty()).collect();
            let room = area.width.saturating_sub(4) as usize;
            let items: Vec<String> = named.iter().map(|s| format!("■ {} ", s.0)).collect();
            let all_fit = items.iter().map(|i| i.chars().count()).sum::<usize>() < room;
            let mut spans = vec![Span::raw(" ")];
            let mut used = 1;
            for (k, (item, (_, color, _, _))) in items.into_iter().zip(&named).enumerate() {
                let rest = named.len() - k - 1;
                let tail = if all_fit || rest == 0 {
                    0
                } else {
                    format!("+{rest} ").len()
                };
                if used + item.chars().count() + tail > room {
                    spans.push(Span::raw(format!("+{} ", named.len() - k)));
                    break;
                }
                used += item.chars().count();
                spans.push(Span::styled(item, Style::new().fg(*color)));
            }
            block = block.title_bottom(Line::from(spans));
            None
        }
        None => None,
    };
    chart
        .block(block)
        .legend_position(position)
        .hidden_legend_constraints((Constraint::Ratio(1, 1), Constraint::Ratio(1, 1)))
}

/// Where a legend of `series` hides no curve: `Ok(position)` (the first
/// of the corners, then the edges, whose box covers no cell the curves
/// pass through), `Err(())` when every place would hide some or the box
/// does not fit, `None` when there is nothing to name. The plot's cells
/// follow ratatui's chart layout for a bordered chart with end labels on
/// both axes and no axis titles.
pub(crate) fn legend_place(
    series: &[Named],
    x: &AxisEnds,
    y: &AxisEnds,
    area: Rect,
) -> Option<Result<ratatui::widgets::LegendPosition, ()>> {
    use ratatui::widgets::LegendPosition as P;
    // Every named series has a line in ratatui's legend, even without data.
    let named: Vec<&Named> = series.iter().filter(|s| !s.0.is_empty()).collect();
    let width = named.iter().map(|s| s.0.chars().count()).max()? as u16 + 2;
    let height = named.len() as u16 + 2;
    // The chart's inner area, less the x labels and axis (two rows) and
    // the y labels and axis on the left.
    let inner = Rect::new(
        area.x + 1,
        area.y + 1,
        area.width.saturating_sub(2),
        area.height.saturating_sub(2),
    );
    let left = y.1.iter().map(|l| l.chars().count()).max().unwrap_or(0);
    let left = left.max(x.1[0].chars().count().saturating_sub(1)) as u16;
    let left = left.min(inner.width / 3) + 1;
    let (gw, gh) = (inner.width.saturating_sub(left), inner.height.saturating_sub(2));
    if gw < width || gh < height {
        return Some(Err(()));
    }
    // The cells each curve passes through, as ratatui's canvas maps data
    // to braille dots (2 x 4 a cell; a lone value is a dot of a cell).
    let (gwu, ghu) = (gw as usize, gh as usize);
    let mut covered = vec![false; gwu * ghu];
    let (xb, yb) = (x.0, y.0);
    // `p` on a grid of `nx x ny` dots, rounded as ratatui does.
    let at = |p: (f64, f64), nx: usize, ny: usize| -> Option<(f64, f64)> {
        let fx = (p.0 - xb[0]) / (xb[1] - xb[0]);
        let fy = (yb[1] - p.1) / (yb[1] - yb[0]);
        ((0.0..=1.0).contains(&fx) && (0.0..=1.0).contains(&fy)).then(|| (fx * (nx - 1) as f64, fy * (ny - 1) as f64))
    };
    let mut mark = |d: (f64, f64), per: (usize, usize)| {
        let (i, j) = (d.0.round() as usize / per.0, d.1.round() as usize / per.1);
        covered[j.min(ghu - 1) * gwu + i.min(gwu - 1)] = true;
    };
    for s in &named {
        let pts: Vec<(f64, f64)> =
            s.2.iter()
                .copied()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .collect();
        for p in &pts {
            if let Some(d) = at(*p, gwu, ghu) {
                mark(d, (1, 1));
            }
            if let Some(d) = at(*p, 2 * gwu, 4 * ghu) {
                mark(d, (2, 4));
            }
        }
        for w in pts.windows(2).filter(|_| s.3) {
            let (Some(a), Some(b)) = (at(w[0], 2 * gwu, 4 * ghu), at(w[1], 2 * gwu, 4 * ghu)) else {
                continue;
            };
            let n = (2.0 * (b.0 - a.0).abs().max((b.1 - a.1).abs())).ceil() as usize + 1;
            for k in 0..=n {
                let t = k as f64 / n as f64;
                mark((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)), (2, 4));
            }
        }
    }
    let (mx, my) = (gw - width, gh - height);
    let places = [
        (P::TopRight, mx, 0),
        (P::TopLeft, 0, 0),
        (P::BottomRight, mx, my),
        (P::BottomLeft, 0, my),
        (P::Right, mx, my / 2),
        (P::Left, 0, my / 2),
        (P::Top, mx / 2, 0),
        (P::Bottom, mx / 2, my),
    ];
    let free = |x0: u16, y0: u16| {
        (y0..y0 + height).all(|j| (x0..x0 + width).all(|i| !covered[j as usize * gw as usize + i as usize]))
    };
    Some(places.iter().find(|(_, x0, y0)| free(*x0, *y0)).map(|p| p.0).ok_or(()))
}

/// Per-step series: condition numbers (log10, with and without ghost),
/// energies (strain, external work, plastic dissipation) or errors (log10).
fn draw_per_step(frame: &mut Frame, app: &App, area: Rect, kind: ChartKind) {
    let log = |v: f64| (v > 0.0 && v.is_finite()).then(|| v.log10());
    let colors = [Color::Cyan, Color::Yellow, Color::Red, Color::Green, Color::Magenta];
    /// A named series of `(step, value)`.
    type Series = (String, Vec<(f64, f64)>);
    let ghost = app.reports.iter().any(|r| r.condition_unstabilised.is_some());
    let (title, mut series): (String, Vec<Series>) = match kind {
        ChartKind::Condition => (
            " condition number per step (log10) ".into(),
            vec![
                (
                    if ghost { "with ghost" } else { "K" }.into(),
                    app.reports
                        .iter()
                        .filter_map(|r| Some((r.step as f64, log(r.condition?.value)?)))
                        .collect(),
                ),
                (
                    "without ghost".into(),
                    app.reports
                        .iter()
                        .filter_map(|r| Some((r.step as f64, log(r.condition_unstabilised?.value)?)))
                        .collect(),
                ),
            ],
        ),
        ChartKind::Error => {
            let names: Vec<&str> = app
                .reports
                .last()
                .map_or(Vec::new(), |r| r.errors.iter().map(|e| e.name).collect());
            (
                " errors per step (log10) ".into(),
                names
                    .iter()
                    .map(|n| {
                        (
                            n.to_string(),
                            app.reports
                                .iter()
                                .filter_map(|r| {
                                    let e = r.errors.iter().find(|e| e.name == *n)?;
                                    Some((r.step as f64, log(e.value)?))
                                })
                                .collect(),
                        )
                    })
                    .collect(),
            )
        }
        _ => (
            format!(" energy per step ({}) ", app.units.of(Quantity::Energy)),
            vec![
                (
                    "strain".into(),
                    app.reports.iter().map(|r| (r.step as f64, r.energy.strain)).collect(),
                ),
                (
                    "external work".into(),
                    app.reports
                        .iter()
                        .map(|r| (r.step as f64, r.energy.external_work))
                        .collect(),
                ),
                (
                    "plastic".into(),
                    app.reports
                        .iter()
                        .map(|r| (r.step as f64, r.energy.plastic_dissipation))
                        .collect(),
                ),
                (
                    "ghost".into(),
                    // Only when the ghost penalty took up any work.
                    if app.reports.iter().any(|r| r.energy.ghost != 0.0) {
                        app.reports.iter().map(|r| (r.step as f64, r.energy.ghost)).collect()
                    } else {
                        Vec::new()
                    },
                ),
            ],
        ),
    };
    series.retain(|s| !s.1.is_empty());
    let pts = series.iter().flat_map(|s| s.1.iter());
    let (mut ymin, mut ymax, mut xmax) = (f64::INFINITY, f64::NEG_INFINITY, 1.0f64);
    for &(x, y) in pts.filter(|p| p.1.is_finite()) {
        ymin = ymin.min(y);
        ymax = ymax.max(y);
        xmax = xmax.max(x);
    }
    if !ymin.is_finite() {
        (ymin, ymax) = (0.0, 1.0);
    }
    if kind != ChartKind::Energy {
        (ymin, ymax) = (ymin.floor(), ymax.ceil().max(ymin.floor() + 1.0));
    } else if ymax - ymin < 1e-300 {
        ymax = ymin + 1.0;
    }
    let label = |v: f64| {
        if kind == ChartKind::Energy {
            format!("{v:.2e}")
        } else {
            format!("1e{v}")
        }
    };
    let named: Vec<Named> = series
        .iter()
        .enumerate()
        .map(|(k, (name, data))| (name.as_str(), colors[k % colors.len()], data.as_slice(), true))
        .collect();
    let mut title = if named.is_empty() {
        format!("{title}— nothing yet ")
    } else {
        title
    };
    // The key hint only where it fits whole in the top border.
    if title.chars().count() + 16 <= area.width.saturating_sub(2) as usize {
        title.push_str("(v: next chart) ");
    }
    let chart = with_legend(
        &named,
        title,
        // One step: centre its dot rather than put it on the edge.
        if xmax > 1.0 {
            ([1.0, xmax], ["1".into(), format!("{xmax}")])
        } else {
            ([0.0, 2.0], ["0".into(), "2".into()])
        },
        ([ymin, ymax], [label(ymin), label(ymax)]),
        area,
        app.show_legend,
    );
    frame.render_widget(chart, area);
}

/// Energies against time (explicit dynamics): kinetic, strain, plastic
/// dissipation and their sum, as G Figs. 13-14 chart them.
fn draw_energies(frame: &mut Frame, app: &App, area: Rect) {
    type Part = (&'static str, Color, fn(&StepReport) -> f64);
    let parts: [Part; 4] = [
        ("kinetic", Color::Cyan, |r| r.energy.kinetic),
        ("strain", Color::Yellow, |r| r.energy.strain),
        ("plastic", Color::Red, |r| r.energy.plastic_dissipation),
        ("total", Color::White, |r| {
            r.energy.kinetic + r.energy.strain + r.energy.plastic_dissipation
        }),
    ];
    let series: Vec<Vec<(f64, f64)>> = parts
        .iter()
        .map(|(_, _, f)| {
            app.reports
                .iter()
                .filter_map(|r| r.dynamics.as_ref().map(|d| (d.time, f(r))))
                .filter(|(_, v)| v.is_finite())
                .collect()
        })
        .collect();
    let tmax = series[0].last().map_or(1.0, |p| p.0).max(1e-12);
    let emax = series.iter().flatten().map(|p| p.1).fold(0.0, f64::max).max(1e-300);
    let named: Vec<Named> = parts
        .iter()
        .zip(&series)
        .map(|((name, color, _), s)| (*name, *color, s.as_slice(), true))
        .collect();
    let chart = with_legend(
        &named,
        format!(" energy ({}) against time (s) ", app.units.of(Quantity::Energy)),
        ([0.0, tmax], ["0".into(), format!("{tmax:.3}")]),
        ([0.0, 1.05 * emax], ["0".into(), format!("{:.3e}", 1.05 * emax)]),
        area,
        app.show_legend,
    );
    frame.render_widget(chart, area);
}

/// The dynamics lines of the last-step panel (explicit, or implicit with
/// its Newton solve).
fn dynamics_lines(r: &StepReport, d: &crate::dynamics::DynamicsReport, u: Units) -> Vec<Line<'static>> {
    let e = &r.energy;
    let (en, vel) = (u.of(Quantity::Energy), u.of(Quantity::Velocity));
    let newton = d.integrator.map(|i| {
        Line::raw(format!(
            "Newmark ({}): {} iterations, residual {:.2e}{}",
            i.label(),
            r.iterations,
            r.residuals.last().copied().unwrap_or(f64::NAN),
            r.condition
                .map(|c| format!("  cond(K + M/(beta dt^2)) {:.2e}", c.value))
                .unwrap_or_default()
        ))
    });
    let mut lines = vec![
        Line::raw(format!(
            "t = {:.4} s (dt {:.2e} s)  {} mass, {}, {}",
            d.time,
            d.dt,
            d.mass.label(),
            d.stress_update.label(),
            d.velocity_update.label()
        )),
        Line::raw(format!(
            "energy: kinetic {:.4e}  strain {:.4e}  plastic {:.4e} {en}",
            e.kinetic, e.strain, e.plastic_dissipation
        )),
        Line::raw(format!(
            "balance {:.3e} {en} ({} of W0 = {:.4e} {en})  max grid speed {:.3e} {vel}",
            d.energy_error,
            format::sci_or_dash(format::relative_balance(d), 2),
            d.initial_energy,
            d.max_speed
        )),
    ];
    lines.extend(newton);
    if let Some(c) = &d.conditioning {
        lines.push(Line::raw(format!(
            "cond: M~ {:.2e}  M {:.2e}  lumped {:.2e}  CFL\u{a0}({}\u{a0}mass)\u{a0}{}\u{a0}s/m",
            c.mass_stabilised.value,
            c.mass_consistent.value,
            c.mass_lumped.value,
            d.mass.label(),
            format::sci_or_dash(d.cfl(), 3)
        )));
    }
    if !d.cutbacks.is_empty() {
        lines.push(Line::raw(format!(
            "cut {}: the time step was halved ({} sub-steps)",
            d.cutbacks.len(),
            d.substeps
        )));
    }
    lines
}

fn draw_last_step(frame: &mut Frame, app: &App, area: Rect) {
    let mut lines: Vec<Line> = Vec::new();
    if let Some(f) = &app.failure {
        lines.push(Line::styled(
            format!("FAILED at step {}", f.step()),
            Style::new().fg(Color::Red).add_modifier(Modifier::BOLD),
        ));
        lines.push(Line::raw(f.to_string()));
    } else if app.busy {
        lines.push(Line::styled(
            match &app.progress {
                Some(p) => format!(
                    "computing step {}... iteration {}, residual {:.2e} (x cancels)",
                    p.step, p.iteration, p.residual
                ),
                None => format!("computing step {}... (x cancels)", app.view.step + 1),
            },
            Style::new().fg(Color::Yellow),
        ));
    }
    match app.reports.last() {
        None => lines.push(Line::raw("step 0: initial state (press space to step)")),
        Some(r) => {
            if let Some(d) = &r.dynamics {
                lines.push(Line::raw(format!(
                    "step {}/{}  unknowns {}",
                    r.step, r.load_steps, r.unknowns
                )));
                lines.extend(dynamics_lines(r, d, app.units));
                lines.extend(errors_line(r));
                lines.extend(r.probes.iter().map(|p| Line::raw(probe_line(p, app.units))));
            } else {
                static_lines(r, app.units, &mut lines);
            }
        }
    }
    frame.render_widget(
        Paragraph::new(lines)
            .wrap(Wrap { trim: true })
            .block(Block::default().borders(Borders::ALL).title(" last step ")),
        area,
    );
}

/// The errors against the exact solution, each name with its value (a
/// no-break space between them: a narrow panel wraps between pairs, never
/// inside one).
fn errors_line(r: &StepReport) -> Option<Line<'static>> {
    (!r.errors.is_empty()).then(|| {
        let e: Vec<String> = r
            .errors
            .iter()
            .map(|e| format!("{}\u{a0}{:.3e}", e.name, e.value))
            .collect();
        Line::raw(format!("errors: {}", e.join("  ")))
    })
}

/// A probe's values on one line: `tip: u (ux, uy) m  [v (vx, vy) m/s]  s (xx, yy, xy) Pa`.
fn probe_line(p: &crate::probe::ProbeValue, u: Units) -> String {
    let mut s = format!(
        "probe {}: u ({:.3e}, {:.3e}) {}",
        p.name,
        p.u[0],
        p.u[1],
        u.of(Quantity::Length)
    );
    if let Some(v) = p.v {
        s.push_str(&format!(
            "  v ({:.3e}, {:.3e}) {}",
            v[0],
            v[1],
            u.of(Quantity::Velocity)
        ));
    }
    if let Some(t) = p.stress {
        s.push_str(&format!(
            "  s ({:.3e}, {:.3e}, {:.3e}) {}",
            t[0],
            t[1],
            t[2],
            u.of(Quantity::Stress)
        ));
    }
    if let Some(f) = p.force {
        s.push_str(&format!("  F ({:.3e}, {:.3e}) {}", f[0], f[1], u.of(Quantity::Force)));
    }
    s
}

/// The factorisation of the step's last system and the tangent's inertia,
/// as in the run table ([`format::factor_label`]); and the cutbacks taken.
fn solver_label(s: &crate::report::SolverReport) -> String {
    let f = format::factor_label(s);
    let f = match s.cutbacks.len() {
        0 => f,
        n => format!("{f} cut {n}"),
    };
    match s.attainable {
        Some(a) => format!("{f}  at round-off floor {:.1e}", a.floor),
        None => f,
    }
}

/// The quasi-static lines of the last-step panel: residuals, condition
/// number, energies, timings, boundaries.
fn static_lines(r: &StepReport, u: Units, lines: &mut Vec<Line<'static>>) {
    let (force, len, en) = (u.of(Quantity::Force), u.of(Quantity::Length), u.of(Quantity::Energy));
    let res: Vec<String> = r.residuals.iter().map(|x| format!("{x:.2e}")).collect();
    lines.push(Line::raw(format!(
        "step {}/{}  load factor {:.3}  unknowns {}  {}",
        r.step,
        r.load_steps,
        r.load_factor,
        r.unknowns,
        r.solver.as_ref().map_or(String::new(), solver_label)
    )));
    lines.push(Line::raw(format!(
        "residuals [{}]  |r0| {:.3e} {force}",
        res.join(", "),
        r.residual_norm
    )));
    match &r.condition {
        Some(c) => lines.push(Line::raw(format!(
            "cond(K) {:.3e} ({})  eig {:.2e}..{:.2e}",
            c.value,
            c.method.label(),
            c.lambda_min,
            c.lambda_max
        ))),
        None => lines.push(Line::raw("cond(K) off")),
    }
    lines.push(Line::raw(format!(
        "energy: strain {:.4e} {en}  work {:.4e} {en}{}",
        r.energy.strain,
        r.energy.external_work,
        if r.energy.ghost != 0.0 {
            format!("  ghost {:.4e} {en}", r.energy.ghost)
        } else {
            String::new()
        }
    )));
    // The errors against the exact solution, then the probes the scene
    // asks for: before the per-boundary lines, which a short panel cuts.
    lines.extend(errors_line(r));
    lines.extend(r.probes.iter().map(|p| Line::raw(probe_line(p, u))));
    for b in &r.ibm {
        lines.push(Line::raw(format!(
            "{} (IBM): R ({:.3e}, {:.3e}) {force}, violation {:.1e} {len}, {} cells cut",
            b.name, b.reaction[0], b.reaction[1], b.violation, b.cut_cells
        )));
    }
    for b in &r.boundaries {
        lines.push(Line::raw(format!(
            "{}: L {:.4} {len}, {} cells, F ({:.3e}, {:.3e}) {force}{}",
            b.name,
            b.length,
            b.cells_cut,
            b.resultant[0],
            b.resultant[1],
            if b.lost > 0.0 {
                format!(" LOST {:.2e} {force}", b.lost)
            } else {
                String::new()
            }
        )));
    }
    // The timings last: on a small terminal the panel's last lines are the
    // ones cut off.
    let t = &r.timings;
    lines.push(Line::raw(format!(
        "time: asm {:.3}s  fact {:.3}s  solve {:.3}s  cond {:.3}s",
        t.mapping + t.pattern + t.assembly,
        t.factorisation,
        t.solve,
        t.condition
    )));
}

fn draw_table(frame: &mut Frame, app: &App, area: Rect) {
    let header = if app.implicit_dynamics {
        Row::new(["step", "t s", "unknowns", "bal/W0", "cond(K)", "time s"])
    } else if app.view.time.is_some() {
        Row::new(["step", "t s", "unknowns", "bal/W0", "cond(M)", "time s"])
    } else {
        Row::new(["step", "load", "unknowns", "residual", "cond(K)", "time s"])
    }
    .style(Style::new().add_modifier(Modifier::BOLD));
    let visible = area.height.saturating_sub(3) as usize;
    let skip = app.reports.len().saturating_sub(visible);
    let rows = app.reports.iter().skip(skip).map(|r| {
        Row::new([
            Cell::from(r.step.to_string()),
            Cell::from(match &r.dynamics {
                Some(d) => format!("{:.3}", d.time),
                None => format!("{:.3}", r.load_factor),
            }),
            Cell::from(r.unknowns.to_string()),
            Cell::from(match &r.dynamics {
                Some(d) => format::sci_or_dash(format::relative_balance(d), 1),
                None => format!("{:.1e}", r.residuals.last().copied().unwrap_or(f64::NAN)),
            }),
            Cell::from(r.condition.map_or("-".into(), |c| format!("{:.1e}", c.value))),
            Cell::from(format!("{:.3}", r.timings.total)),
        ])
    });
    let widths = [
        Constraint::Length(5),
        Constraint::Length(6),
        Constraint::Length(8),
        Constraint::Length(8),
        Constraint::Length(8),
        Constraint::Length(7),
    ];
    frame.render_widget(
        Table::new(rows, widths)
            .header(header)
            .block(Block::default().borders(Borders::ALL).title(" steps ")),
        area,
    );
}

fn draw_help(frame: &mut Frame, area: Rect) {
    let text = vec![
        Line::raw("space   take one load step"),
        Line::raw("enter   run continuously / pause"),
        Line::raw("f       colour points by the next field"),
        Line::raw("c       show or hide boundary control points"),
        Line::raw("# a o   grid lines, active cells (blue), ghost faces (orange)"),
        Line::raw("G / g   gamma_K x10 / /10 (from the next step)"),
        Line::raw("0       ghost stabilisation off / back on"),
        Line::raw("D / d   implicit-boundary delta/h x10 / /10"),
        Line::raw("M / m   ghost mass gamma_M x10 / /10"),
        Line::raw("v       next chart: residual, condition, energy, error, probes"),
        Line::raw("L       show or hide the charts' legends"),
        Line::raw("p / P   probe chart: next quantity on y / on x"),
        Line::raw("w       write a checkpoint of this step (checkpoints/)"),
        Line::raw("V       start / stop a ParaView series from this step (vtk/)"),
        Line::raw("r       redo the last step with the current parameters"),
        Line::raw("x       cancel the step being computed"),
        Line::raw("T / t   tolerance x10 / /10"),
        Line::raw(":       type a parameter: gamma_k = 1e6, tolerance = 1e-9, ..."),
        Line::raw("+ / -   zoom the points (also the mouse wheel); z: fit"),
        Line::raw("arrows  pan (also h j k l)"),
        Line::raw("?       show or hide this help"),
        Line::raw("Esc     close this help, or stay after a first q"),
        Line::raw("q       quit (twice while a step runs; the recording is closed)"),
    ];
    let w = 70.min(area.width);
    let h = (text.len() as u16 + 2).min(area.height);
    let r = Rect::new(area.x + (area.width - w) / 2, area.y + (area.height - h) / 2, w, h);
    frame.render_widget(Clear, r);
    frame.render_widget(
        Paragraph::new(text).block(Block::default().borders(Borders::ALL).title(" keys ")),
        r,
    );
}
