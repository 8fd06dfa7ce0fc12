//! Splitting a spline at the grid lines it crosses (B section 3.3), so each
//! piece lies in one cell.
//!
//! For each segment and each grid line within the segment's control hull,
//! the cubic `C_d(t) - c` is split at its critical points into monotone
//! intervals, and a root is bracketed and refined by bisection safeguarding
//! Newton. Roots closer than `1e-12` in `t` are merged, so tangential touches
//! and curves running along a grid line produce neither gaps, duplicates nor
//! zero-length pieces.

use super::bspline::BSpline;
use crate::grid::Grid;

/// A piece of segment `segment` between `t0 < t1`, inside cell `cell`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Piece {
    pub segment: usize,
    pub t0: f64,
    pub t1: f64,
    /// Cell index `j nx + i`.
    pub cell: usize,
}

/// Power-basis coefficients `[c0, c1, c2, c3]` of coordinate `d` of segment `k`.
fn power(s: &BSpline, k: usize, d: usize) -> [f64; 4] {
    let p = s.segments[k].map(|v| v[d]);
    [
        p[0],
        3.0 * (p[1] - p[0]),
        3.0 * (p[2] - 2.0 * p[1] + p[0]),
        p[3] - 3.0 * p[2] + 3.0 * p[1] - p[0],
    ]
}

fn eval(c: &[f64; 4], t: f64) -> f64 {
    ((c[3] * t + c[2]) * t + c[1]) * t + c[0]
}

fn deriv(c: &[f64; 4], t: f64) -> f64 {
    (3.0 * c[3] * t + 2.0 * c[2]) * t + c[1]
}

/// Roots in (0, 1) of the derivative of the cubic `c` (its critical points).
fn critical_points(c: &[f64; 4]) -> Vec<f64> {
    let (a, b, cc) = (3.0 * c[3], 2.0 * c[2], c[1]);
    let mut out = Vec::new();
    let scale = a.abs().max(b.abs()).max(cc.abs());
    if scale == 0.0 {
        return out;
    }
    if a.abs() <= 1e-14 * scale {
        if b != 0.0 {
            out.push(-cc / b);
        }
    } else {
        let disc = b * b - 4.0 * a * cc;
        if disc >= 0.0 {
            let r = disc.sqrt();
            let q = -0.5 * (b + b.signum() * r);
            if q != 0.0 {
                out.push(q / a);
                out.push(cc / q);
            } else {
                out.push(0.0);
            }
        }
    }
    out.retain(|t| *t > 0.0 && *t < 1.0);
    out.sort_by(f64::total_cmp);
    out
}

/// Parameters in [0, 1] where `c(t) = value`; `tol` is the coordinate tolerance.
fn roots(c: &[f64; 4], value: f64, tol: f64) -> Vec<f64> {
    let f = |t: f64| eval(c, t) - value;
    let mut edges = vec![0.0];
    edges.extend(critical_points(c));
    edges.push(1.0);
    let mut out = Vec::new();
    for w in edges.windows(2) {
        let (mut lo, mut hi) = (w[0], w[1]);
        let (flo, fhi) = (f(lo), f(hi));
        if flo.abs() <= tol {
            out.push(lo);
            continue;
        }
        if fhi.abs() <= tol {
            out.push(hi);
            continue;
        }
        if flo.signum() == fhi.signum() {
            continue;
        }
        // Monotone with a sign change: bisection safeguarding Newton.
        let mut t = 0.5 * (lo + hi);
        for _ in 0..100 {
            let ft = f(t);
            if ft.abs() <= 0.01 * tol || hi - lo < 1e-15 {
                break;
            }
            if ft.signum() == flo.signum() {
                lo = t;
            } else {
                hi = t;
            }
            let d = deriv(c, t);
            let tn = if d != 0.0 { t - ft / d } else { f64::NAN };
            t = if tn > lo && tn < hi { tn } else { 0.5 * (lo + hi) };
        }
        out.push(t);
    }
    out
}

/// Split every segment of `s` at the grid lines it crosses.
pub fn split(s: &BSpline, grid: &Grid) -> Vec<Piece> {
    let tol = 1e-12 * grid.h;
    let mut pieces = Vec::new();
    for k in 0..s.segments.len() {
        let mut ts = vec![0.0, 1.0];
        for d in 0..2 {
            let c = power(s, k, d);
            let (lo, hi) = s.segments[k]
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                    (a.min(p[d]), b.max(p[d]))
                });
            if hi - lo <= tol {
                continue; // runs along a line of constant coordinate d
            }
            let first = ((lo - grid.origin[d]) / grid.h).ceil() as i64;
            let last = ((hi - grid.origin[d]) / grid.h).floor() as i64;
            for j in first..=last {
                let value = grid.origin[d] + j as f64 * grid.h;
                ts.extend(roots(&c, value, tol));
            }
        }
        ts.sort_by(f64::total_cmp);
        ts.dedup_by(|a, b| (*a - *b).abs() < 1e-12);
        // Keep both ends exact.
        if let Some(l) = ts.last_mut() {
            *l = 1.0;
        }
        ts[0] = 0.0;
        for w in ts.windows(2) {
            let (t0, t1) = (w[0], w[1]);
            if s.length_between(k, t0, t1) <= tol {
                continue;
            }
            let mid = s.point(k, 0.5 * (t0 + t1));
            if let Some((i, j)) = grid.cell_of(mid) {
                pieces.push(Piece {
                    segment: k,
                    t0,
                    t1,
                    cell: j * grid.nx + i,
                });
            }
        }
    }
    pieces
}
