//! SVG charts of a sweep, written by hand (a few elements; no plotting
//! crate): scatter and line series on linear or log axes, and a stability
//! map of which settings completed.
//!
//! Each series is a `<g class="series" data-name="...">` holding a
//! `<polyline>` (line series) and one `<circle>` per point with a `<title>`
//! tooltip, so the charts can be read back by tests and tools.

use super::RunResult;
use std::fmt::Write as _;

/// One series of a chart.
pub struct Series {
    pub name: String,
    /// `(x, y, tooltip)`.
    pub points: Vec<(f64, f64, String)>,
    pub color: &'static str,
    /// Join the points with a line (in the given order).
    pub line: bool,
}

/// Colours for successive series.
pub const PALETTE: &[&str] = &[
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
];

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

const W: f64 = 720.0;
const H: f64 = 440.0;
const LEFT: f64 = 80.0;
const RIGHT: f64 = 200.0;
const TOP: f64 = 40.0;
const BOTTOM: f64 = 60.0;

/// An axis: data range, log or linear, and pixel range.
struct Axis {
    lo: f64,
    hi: f64,
    log: bool,
}

impl Axis {
    fn new(values: impl Iterator<Item = f64>, log: bool) -> Axis {
        let v: Vec<f64> = values
            .filter(|v| v.is_finite() && (!log || *v > 0.0))
            .map(|v| if log { v.log10() } else { v })
            .collect();
        let (mut lo, mut hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
        if !lo.is_finite() {
            (lo, hi) = (0.0, 1.0);
        }
        if log {
            (lo, hi) = (lo.floor(), hi.ceil());
        }
        if hi - lo < 1e-12 {
            (lo, hi) = (lo - 0.5, hi + 0.5);
        }
        Axis { lo, hi, log }
    }

    /// Fraction along the axis, or `None` for values a log axis cannot show.
    fn frac(&self, v: f64) -> Option<f64> {
        let v = if self.log {
            if v > 0.0 {
                v.log10()
            } else {
                return None;
            }
        } else {
            v
        };
        v.is_finite().then(|| (v - self.lo) / (self.hi - self.lo))
    }

    fn ticks(&self) -> Vec<(f64, String)> {
        if self.log {
            let (a, b) = (self.lo as i32, self.hi as i32);
            let step = ((b - a) / 8).max(1);
            (a..=b)
                .step_by(step as usize)
                .map(|e| ((e as f64 - self.lo) / (self.hi - self.lo), format!("1e{e}")))
                .collect()
        } else {
            (0..=4)
                .map(|k| {
                    let v = self.lo + (self.hi - self.lo) * k as f64 / 4.0;
                    (k as f64 / 4.0, format!("{v:.3}"))
                })
                .collect()
        }
    }
}

/// A chart of `series` with axis labels; log axes where asked.
pub fn chart(title: &str, x_label: &str, y_label: &str, series: &[Series], log_x: bool, log_y: bool) -> String {
    let ax = Axis::new(series.iter().flat_map(|s| s.points.iter().map(|p| p.0)), log_x);
    let ay = Axis::new(series.iter().flat_map(|s| s.points.iter().map(|p| p.1)), log_y);
    let (pw, ph) = (W - LEFT - RIGHT, H - TOP - BOTTOM);
    let px = |f: f64| LEFT + f * pw;
    let py = |f: f64| TOP + (1.0 - f) * ph;
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}" font-family="sans-serif" font-size="12">"#
    );
    let _ = write!(s, r#"<rect width="{W}" height="{H}" fill="white"/>"#);
    let _ = write!(
        s,
        r#"<text x="{}" y="24" text-anchor="middle" font-size="15">{}</text>"#,
        LEFT + pw / 2.0,
        esc(title)
    );
    let _ = write!(
        s,
        r##"<rect x="{LEFT}" y="{TOP}" width="{pw}" height="{ph}" fill="none" stroke="#444"/>"##
    );
    for (f, label) in ax.ticks() {
        let x = px(f);
        let _ = write!(
            s,
            r##"<line x1="{x}" y1="{TOP}" x2="{x}" y2="{}" stroke="#ddd"/><text x="{x}" y="{}" text-anchor="middle">{label}</text>"##,
            TOP + ph,
            TOP + ph + 16.0
        );
    }
    for (f, label) in ay.ticks() {
        let y = py(f);
        let _ = write!(
            s,
            r##"<line x1="{LEFT}" y1="{y}" x2="{}" y2="{y}" stroke="#ddd"/><text x="{}" y="{}" text-anchor="end">{label}</text>"##,
            LEFT + pw,
            LEFT - 6.0,
            y + 4.0
        );
    }
    let _ = write!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
        LEFT + pw / 2.0,
        H - 16.0,
        esc(x_label)
    );
    let _ = write!(
        s,
        r#"<text x="18" y="{}" text-anchor="middle" transform="rotate(-90 18 {})">{}</text>"#,
        TOP + ph / 2.0,
        TOP + ph / 2.0,
        esc(y_label)
    );
    for (k, ser) in series.iter().enumerate() {
        let _ = write!(s, r#"<g class="series" data-name="{}">"#, esc(&ser.name));
        let pts: Vec<(f64, f64, &String)> = ser
            .points
            .iter()
            .filter_map(|(x, y, t)| Some((px(ax.frac(*x)?), py(ay.frac(*y)?), t)))
            .collect();
        if ser.line && pts.len() > 1 {
            let p: Vec<String> = pts.iter().map(|(x, y, _)| format!("{x:.1},{y:.1}")).collect();
            let _ = write!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{}" stroke-width="1.5"/>"#,
                p.join(" "),
                ser.color
            );
        }
        for (x, y, t) in &pts {
            let _ = write!(
                s,
                r#"<circle cx="{x:.1}" cy="{y:.1}" r="4" fill="{}"><title>{}</title></circle>"#,
                ser.color,
                esc(t)
            );
        }
        let ly = TOP + 10.0 + 18.0 * k as f64;
        let _ = write!(
            s,
            r#"<circle cx="{}" cy="{ly}" r="4" fill="{}"/><text x="{}" y="{}">{}</text></g>"#,
            LEFT + pw + 16.0,
            ser.color,
            LEFT + pw + 26.0,
            ly + 4.0,
            esc(&ser.name)
        );
    }
    s.push_str("</svg>\n");
    s
}

/// The width a label of `text` takes at `font_size` px, estimated at 0.6 em
/// a character (sans-serif glyphs average about 0.5-0.6 em): what the
/// stability map's layout and its test use.
pub fn text_width(text: &str, font_size: f64) -> f64 {
    0.6 * font_size * text.chars().count() as f64
}

/// Which runs completed: rows are the settings but the last, columns the
/// last setting's values; green completed, red failed (with its step).
/// Columns are as wide as their widest label (header or cell), the row
/// labels' margin as wide as the widest row label, and the picture as
/// wide as its title, so no two labels overlap.
pub fn stability_map(title: &str, results: &[RunResult]) -> String {
    let key = |r: &RunResult| -> (String, String) {
        let n = r.settings.len();
        let row: Vec<String> = r.settings[..n.saturating_sub(1)]
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        let col = r.settings.last().map(|(k, v)| format!("{k}={v}")).unwrap_or_default();
        (row.join(" "), col)
    };
    let mut rows: Vec<String> = Vec::new();
    let mut cols: Vec<String> = Vec::new();
    for r in results {
        let (a, b) = key(r);
        if !rows.contains(&a) {
            rows.push(a);
        }
        if !cols.contains(&b) {
            cols.push(b);
        }
    }
    let outcome = |r: &RunResult| -> (&'static str, String) {
        if r.completed {
            ("#2a9d45", "completed".to_string())
        } else if r.failed_step > 0 {
            ("#d1495b", format!("fails at step {}", r.failed_step))
        } else {
            ("#888888", "invalid".to_string())
        }
    };
    const FONT: f64 = 12.0;
    let widest = |labels: &mut dyn Iterator<Item = String>| labels.map(|l| text_width(&l, FONT)).fold(0.0, f64::max);
    let cw = widest(&mut cols.iter().cloned().chain(results.iter().map(|r| outcome(r).1))).max(98.0) + 12.0;
    let left = widest(&mut rows.iter().cloned()).max(92.0) + 28.0;
    let (rh, top) = (26.0, 60.0);
    let (w, h) = (
        (left + cw * cols.len() as f64 + 20.0).max(text_width(title, 15.0) + 20.0),
        top + rh * rows.len() as f64 + 20.0,
    );
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="12"><rect width="{w}" height="{h}" fill="white"/>"#
    );
    let _ = write!(s, r#"<text x="10" y="22" font-size="15">{}</text>"#, esc(title));
    for (j, c) in cols.iter().enumerate() {
        let _ = write!(
            s,
            r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
            left + cw * (j as f64 + 0.5),
            top - 8.0,
            esc(c)
        );
    }
    for (i, rname) in rows.iter().enumerate() {
        let _ = write!(
            s,
            r#"<text x="{}" y="{}" text-anchor="end">{}</text>"#,
            left - 8.0,
            top + rh * (i as f64 + 0.65),
            esc(rname)
        );
    }
    for r in results {
        let (a, b) = key(r);
        let (i, j) = (
            rows.iter().position(|x| *x == a).unwrap_or(0),
            cols.iter().position(|x| *x == b).unwrap_or(0),
        );
        let (fill, label) = outcome(r);
        let _ = write!(
            s,
            r#"<g class="run" data-id="{}" data-completed="{}"><rect x="{}" y="{}" width="{}" height="{}" fill="{fill}" stroke="white"><title>{}</title></rect><text x="{}" y="{}" text-anchor="middle" fill="white">{label}</text></g>"#,
            esc(&r.id),
            r.completed,
            left + cw * j as f64,
            top + rh * i as f64,
            cw,
            rh,
            esc(&if r.failure.is_empty() {
                r.id.clone()
            } else {
                r.failure.clone()
            }),
            left + cw * (j as f64 + 0.5),
            top + rh * (i as f64 + 0.65)
        );
    }
    s.push_str("</svg>\n");
    s
}
