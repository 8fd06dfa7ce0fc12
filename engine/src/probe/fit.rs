//! A field probe's fit: the displacement, velocity and stress at a
//! material position `X`, read from the points around it.
//!
//! The points of the body at `X` whose reference positions lie within
//! 1.5 cells of it (a quadratic B-spline's support) are weighted by
//! `w_p = N(dx / h) N(dy / h) V_p0` (`N` the quadratic B-spline, `V_p0` the
//! point's initial volume: the fit is volume-weighted), and a field `f`
//! is fitted by first-order moving least squares, centred at the
//! weighted mean position `x_bar`:
//!
//! ```text
//! f(X) = f_bar + G (X - x_bar),   f_bar = sum_p w_p f_p / W,
//! G = (sum_p w_p f_p d_p^T) C^+,  C = sum_p w_p d_p d_p^T,  d_p = x_p0 - x_bar,
//! ```
//!
//! so `f(X) = sum_p c_p f_p` with fixed coefficients
//! `c_p = w_p / W + w_p d_p^T C^+ (X - x_bar)` (which sum to one). The fit
//! is exact for any field linear in the material position (a patch test's
//! displacement and stress at every `X`, not only at a point), it
//! extrapolates linearly to a position on a body's edge, and a position
//! between two points no longer answers with either one's value. Where the
//! points around `X` lie on one line (a body one point thick), `C^+`
//! drops the direction across it: the fit is then linear along the line
//! and constant across.
//!
//! Tracking points (zero volume) carry no weight: they never answer.

use crate::geometry::P2;

/// The points a field probe reads and their coefficients `c_p`.
#[derive(Clone, Debug, PartialEq)]
pub struct FieldFit {
    pub points: Vec<usize>,
    pub coeff: Vec<f64>,
    /// Directions the fit is linear in: 2, or 1 for points on one line.
    pub rank: usize,
}

/// The quadratic B-spline `N(xi)`, support `|xi| < 3/2`.
fn quadratic(xi: f64) -> f64 {
    let a = xi.abs();
    if a < 0.5 {
        0.75 - a * a
    } else if a < 1.5 {
        0.5 * (1.5 - a) * (1.5 - a)
    } else {
        0.0
    }
}

impl FieldFit {
    /// The fit at `at` from `near`: `(index, reference position, initial
    /// volume)` of candidate points (those of one body). `None` when no
    /// point with volume lies within 1.5 cells of `at` (`h` the cell size).
    pub fn new(at: P2, h: f64, near: impl IntoIterator<Item = (usize, P2, f64)>) -> Option<FieldFit> {
        let mut points = Vec::new();
        let mut w = Vec::new();
        let mut x = Vec::new();
        for (p, x0, v0) in near {
            let wp = quadratic((x0[0] - at[0]) / h) * quadratic((x0[1] - at[1]) / h) * v0;
            if wp > 0.0 {
                points.push(p);
                w.push(wp);
                x.push(x0);
            }
        }
        if points.is_empty() {
            return None;
        }
        let total: f64 = w.iter().sum();
        let mean = (0..2).map(|c| w.iter().zip(&x).map(|(w, x)| w * x[c]).sum::<f64>() / total);
        let mean: Vec<f64> = mean.collect();
        let d: Vec<P2> = x.iter().map(|x| [x[0] - mean[0], x[1] - mean[1]]).collect();
        let mut c = [0.0; 3]; // C_xx, C_yy, C_xy
        for (wp, dp) in w.iter().zip(&d) {
            c[0] += wp * dp[0] * dp[0];
            c[1] += wp * dp[1] * dp[1];
            c[2] += wp * dp[0] * dp[1];
        }
        let (pinv, rank) = pseudo_inverse(c);
        let r = [at[0] - mean[0], at[1] - mean[1]];
        // C^+ (X - x_bar)
        let g = [pinv[0] * r[0] + pinv[2] * r[1], pinv[2] * r[0] + pinv[1] * r[1]];
        let coeff = w
            .iter()
            .zip(&d)
            .map(|(wp, dp)| wp / total + wp * (dp[0] * g[0] + dp[1] * g[1]))
            .collect();
        Some(FieldFit { points, coeff, rank })
    }

    /// `sum_p c_p f(p)`: a field's fitted value at the probe's position.
    pub fn apply<const N: usize>(&self, f: impl Fn(usize) -> [f64; N]) -> [f64; N] {
        let mut s = [0.0; N];
        for (&p, &c) in self.points.iter().zip(&self.coeff) {
            let v = f(p);
            for k in 0..N {
                s[k] += c * v[k];
            }
        }
        s
    }
}

/// The pseudo-inverse of the symmetric 2x2 `[[a, c], [c, b]]` (given as
/// `[a, b, c]`) as `[a', b', c']`, dropping eigenvalues below 1e-10 of the
/// largest, and the number kept.
fn pseudo_inverse([a, b, c]: [f64; 3]) -> ([f64; 3], usize) {
    let mean = 0.5 * (a + b);
    let rad = (0.25 * (a - b) * (a - b) + c * c).sqrt();
    let (l1, l2) = (mean + rad, mean - rad);
    if !(l1 > 0.0) {
        return ([0.0; 3], 0);
    }
    // Unit eigenvector of l1.
    let v = if rad > 0.0 {
        let (x, y) = if a >= b { (l1 - b, c) } else { (c, l1 - a) };
        let n = x.hypot(y);
        [x / n, y / n]
    } else {
        [1.0, 0.0]
    };
    let outer = |l: f64, v: P2| [v[0] * v[0] / l, v[1] * v[1] / l, v[0] * v[1] / l];
    let p1 = outer(l1, v);
    if l2 > 1e-10 * l1 {
        let p2 = outer(l2, [-v[1], v[0]]);
        ([p1[0] + p2[0], p1[1] + p2[1], p1[2] + p2[2]], 2)
    } else {
        (p1, 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lattice of points with two per cell (h = 1) around the origin.
    fn lattice() -> Vec<(usize, P2, f64)> {
        let mut v = Vec::new();
        for i in 0..12 {
            for j in 0..12 {
                v.push((
                    v.len(),
                    [-3.0 + 0.25 + 0.5 * i as f64, -3.0 + 0.25 + 0.5 * j as f64],
                    0.25,
                ));
            }
        }
        v
    }

    #[test]
    fn the_fit_reproduces_linear_fields_anywhere_and_sums_to_one() {
        let pts = lattice();
        let field = |x: P2| [1.5 + 0.3 * x[0] - 2.0 * x[1], -0.7 * x[0] + 0.2 * x[1]];
        for at in [[0.0, 0.0], [0.13, -0.41], [0.5, 0.5], [-0.9, 0.77]] {
            let fit = FieldFit::new(at, 1.0, pts.iter().copied()).unwrap();
            assert_eq!(fit.rank, 2);
            let sum: f64 = fit.coeff.iter().sum();
            // Round-off of sums of ~30 terms of order one.
            assert!((sum - 1.0).abs() < 1e-13, "sum {sum}");
            let got = fit.apply(|p| field(pts[p].1));
            let want = field(at);
            for k in 0..2 {
                assert!((got[k] - want[k]).abs() < 1e-12, "at {at:?}: {got:?} vs {want:?}");
            }
        }
    }

    #[test]
    fn an_edge_is_reached_by_linear_extrapolation() {
        // Only the points with x < 0: a probe on the edge x = 0.
        let pts: Vec<_> = lattice().into_iter().filter(|p| p.1[0] < 0.0).collect();
        let fit = FieldFit::new([0.0, 0.3], 1.0, pts.iter().copied()).unwrap();
        let got = fit.apply(|p| {
            let x = pts.iter().find(|q| q.0 == p).unwrap().1;
            [2.0 * x[0] + x[1]]
        });
        assert!((got[0] - 0.3).abs() < 1e-12, "{got:?}");
    }

    #[test]
    fn points_on_one_line_give_a_fit_along_it_and_tracking_points_none() {
        let line: Vec<(usize, P2, f64)> = (0..8).map(|i| (i, [-2.0 + 0.5 * i as f64, 0.0], 0.5)).collect();
        let fit = FieldFit::new([0.1, 0.0], 1.0, line.iter().copied()).unwrap();
        assert_eq!(fit.rank, 1);
        let got = fit.apply(|p| [3.0 * line[p].1[0] + 1.0]);
        assert!((got[0] - 1.3).abs() < 1e-12, "{got:?}");
        // Zero-volume points weigh nothing; none at all means no fit.
        let tracking = [(0, [0.0, 0.0], 0.0), (1, [0.1, 0.0], 0.0)];
        assert!(FieldFit::new([0.0, 0.0], 1.0, tracking).is_none());
    }
}
