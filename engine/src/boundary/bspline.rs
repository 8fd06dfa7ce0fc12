//! Local cubic B-spline interpolation of boundary points (B section 3.1;
//! Piegl & Tiller, *The NURBS Book*, 9.3.4).
//!
//! Through points `Q_0 .. Q_n` (open or closed) each segment `k` is a cubic
//! Bezier curve `Q_k, Q_k + (s_k/3) T_k, Q_{k+1} - (s_k/3) T_{k+1}, Q_{k+1}`
//! with unit tangents `T` estimated from the neighbouring chords
//! `q_k = Q_k - Q_{k-1}`:
//! `V_k = (1 - a_k) q_k + a_k q_{k+1}`,
//! `a_k = |q_{k-1} x q_k| / (|q_{k-1} x q_k| + |q_{k+1} x q_{k+2}|)` (1/2 when
//! both vanish), and `s_k` the positive root of
//! `(16 - |T_k + T_{k+1}|^2) s^2 + 12 (Q_{k+1} - Q_k).(T_k + T_{k+1}) s - 36 |Q_{k+1} - Q_k|^2 = 0`
//! (B (9)-(12)). With knots `u_{k+1} = u_k + s_k` the curve is C1 in `u`, a
//! cubic B-spline with double interior knots. Open ends extrapolate the
//! chords (`q_0 = 2 q_1 - q_2`, ...); closed curves wrap.
//!
//! Corners — marked, or found where both side triples are collinear but the
//! two sides are not — take one-sided tangents, so straight runs between
//! corners stay exactly straight.

use crate::geometry::P2;
use crate::quadrature::gauss_legendre;

fn sub(a: P2, b: P2) -> P2 {
    [a[0] - b[0], a[1] - b[1]]
}

fn cross(a: P2, b: P2) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn norm(a: P2) -> f64 {
    a[0].hypot(a[1])
}

fn unit(a: P2) -> P2 {
    let n = norm(a);
    if n > 0.0 {
        [a[0] / n, a[1] / n]
    } else {
        [0.0, 0.0]
    }
}

/// A C1 piecewise-cubic curve: Bezier segments and their knot spans.
#[derive(Clone, Debug, PartialEq)]
pub struct BSpline {
    /// Control points of each segment `[Q_k, P_k1, P_k2, Q_{k+1}]`.
    pub segments: Vec<[P2; 4]>,
    /// Knots `u_0 = 0 < u_1 < ... < u_m = 1` bounding the segments.
    pub knots: Vec<f64>,
}

/// Why a set of points cannot be interpolated.
#[derive(Clone, Debug, PartialEq)]
pub enum SplineError {
    TooFewPoints(usize),
    /// Points `k` and `k + 1` coincide.
    RepeatedPoint(usize),
}

impl std::fmt::Display for SplineError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SplineError::TooFewPoints(n) => write!(f, "a boundary needs at least 3 points, got {n}"),
            SplineError::RepeatedPoint(k) => write!(f, "boundary points {k} and {} coincide", k + 1),
        }
    }
}

/// The local interpolation of one set of points: everything segment `k`
/// needs, from the points around it (segment `k` depends on points
/// `k - 2 ..= k + 3` only, through the chords `q_{k-1} .. q_{k+3}`).
pub struct Interpolation<'a> {
    points: &'a [P2],
    closed: bool,
    corners: &'a [bool],
    /// The longest chord: cross products at or below `1e-12 scale^2`
    /// count as zero (collinear chords).
    scale: f64,
}

impl<'a> Interpolation<'a> {
    /// Check `points` and set up their interpolation; `corners[k]` marks
    /// point `k` as a corner.
    pub fn new(points: &'a [P2], closed: bool, corners: &'a [bool]) -> Result<Interpolation<'a>, SplineError> {
        let n = points.len();
        if n < 3 {
            return Err(SplineError::TooFewPoints(n));
        }
        let m = if closed { n } else { n - 1 };
        for k in 0..m {
            if norm(sub(points[(k + 1) % n], points[k])) == 0.0 {
                return Err(SplineError::RepeatedPoint(k));
            }
        }
        let scale = (0..m)
            .map(|k| norm(sub(points[(k + 1) % n], points[k])))
            .fold(0.0, f64::max);
        Ok(Interpolation::with_scale(points, closed, corners, scale))
    }

    /// As [`Interpolation::new`] with the longest chord `scale` given (and
    /// the points not checked): for points that differ from checked ones
    /// by a perturbation, whose collinearity tolerance stays that of the
    /// unperturbed points.
    pub fn with_scale(points: &'a [P2], closed: bool, corners: &'a [bool], scale: f64) -> Interpolation<'a> {
        Interpolation {
            points,
            closed,
            corners,
            scale,
        }
    }

    /// The longest chord (m), which sets the collinearity tolerance.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// Number of segments.
    pub fn segments(&self) -> usize {
        let n = self.points.len();
        if self.closed {
            n
        } else {
            n - 1
        }
    }

    /// The chord `q_k = Q_k - Q_{k-1}` for `k` in `-1 ..= n + 1`: wrapped on
    /// a closed curve, extrapolated past the ends of an open one
    /// (`q_0 = 2 q_1 - q_2`, `q_{-1} = 2 q_0 - q_1`, `q_n = 2 q_{n-1} -
    /// q_{n-2}`, `q_{n+1} = 2 q_n - q_{n-1}`).
    fn chord(&self, k: isize) -> P2 {
        let (p, n) = (self.points, self.points.len() as isize);
        let ext = |a: P2, b: P2| [2.0 * a[0] - b[0], 2.0 * a[1] - b[1]];
        if self.closed {
            sub(p[k.rem_euclid(n) as usize], p[(k - 1).rem_euclid(n) as usize])
        } else if (1..n).contains(&k) {
            sub(p[k as usize], p[k as usize - 1])
        } else if k == 0 {
            ext(self.chord(1), self.chord(2))
        } else if k == -1 {
            ext(self.chord(0), self.chord(1))
        } else if k == n {
            ext(self.chord(n - 1), self.chord(n - 2))
        } else {
            ext(self.chord(n), self.chord(n - 1))
        }
    }

    /// Unit tangents at point `k`: `(incoming, outgoing)`, equal but at a
    /// corner (B (9)-(10)).
    fn tangents(&self, k: usize) -> (P2, P2) {
        let n = self.points.len();
        let ki = k as isize;
        let (qm, q0, q1, q2) = (
            self.chord(ki - 1),
            self.chord(ki),
            self.chord(ki + 1),
            self.chord(ki + 2),
        );
        let a1 = cross(qm, q0).abs();
        let a2 = cross(q1, q2).abs();
        let tol = 1e-12 * self.scale * self.scale;
        let end = !self.closed && (k == 0 || k == n - 1);
        let marked = self.corners.get(k).copied().unwrap_or(false);
        let detected = a1 <= tol && a2 <= tol && cross(q0, q1).abs() > tol;
        if !end && (marked || detected) {
            return (unit(q0), unit(q1));
        }
        let alpha = if a1 + a2 <= tol { 0.5 } else { a1 / (a1 + a2) };
        let v = [
            (1.0 - alpha) * q0[0] + alpha * q1[0],
            (1.0 - alpha) * q0[1] + alpha * q1[1],
        ];
        let t = unit(v);
        (t, t)
    }

    /// Segment `k`: its control points and its knot span `s_k` (B (11)-(12)).
    pub fn segment(&self, k: usize) -> ([P2; 4], f64) {
        let (p, n) = (self.points, self.points.len());
        let (a, b) = (p[k], p[(k + 1) % n]);
        let (ta, tb) = (self.tangents(k).1, self.tangents((k + 1) % n).0);
        let ts = [ta[0] + tb[0], ta[1] + tb[1]];
        let d = sub(b, a);
        let qa = 16.0 - (ts[0] * ts[0] + ts[1] * ts[1]);
        let qb = 12.0 * (d[0] * ts[0] + d[1] * ts[1]);
        let qc = -36.0 * (d[0] * d[0] + d[1] * d[1]);
        // qa >= 12 and qc < 0: one positive root; the stable form avoids cancellation.
        let disc = (qb * qb - 4.0 * qa * qc).sqrt();
        let s = if qb >= 0.0 {
            -2.0 * qc / (qb + disc)
        } else {
            (disc - qb) / (2.0 * qa)
        };
        (
            [
                a,
                [a[0] + s / 3.0 * ta[0], a[1] + s / 3.0 * ta[1]],
                [b[0] - s / 3.0 * tb[0], b[1] - s / 3.0 * tb[1]],
                b,
            ],
            s,
        )
    }

    /// The curve made of segments `ks` only, in that order (an open curve
    /// whose segment `i` is segment `ks[i]` of the whole; its knots are
    /// those segments' spans, normalised).
    pub fn spline_of(&self, ks: &[usize]) -> BSpline {
        let mut segments = Vec::with_capacity(ks.len());
        let mut knots = vec![0.0];
        for (i, &k) in ks.iter().enumerate() {
            let (c, s) = self.segment(k);
            segments.push(c);
            knots.push(knots[i] + s);
        }
        let total = knots[ks.len()];
        knots.iter_mut().for_each(|u| *u /= total);
        BSpline { segments, knots }
    }
}

impl BSpline {
    /// Interpolate `points`; `corners[k]` marks point `k` as a corner.
    pub fn interpolate(points: &[P2], closed: bool, corners: &[bool]) -> Result<BSpline, SplineError> {
        let it = Interpolation::new(points, closed, corners)?;
        let all: Vec<usize> = (0..it.segments()).collect();
        Ok(it.spline_of(&all))
    }

    /// Position on segment `k` at local parameter `t` in [0, 1].
    pub fn point(&self, k: usize, t: f64) -> P2 {
        let p = &self.segments[k];
        let s = 1.0 - t;
        let b = [s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t];
        [0, 1].map(|d| b[0] * p[0][d] + b[1] * p[1][d] + b[2] * p[2][d] + b[3] * p[3][d])
    }

    /// First derivative `dC/dt` on segment `k`.
    pub fn d1(&self, k: usize, t: f64) -> P2 {
        let p = &self.segments[k];
        let s = 1.0 - t;
        [0, 1].map(|d| {
            3.0 * ((p[1][d] - p[0][d]) * s * s + 2.0 * (p[2][d] - p[1][d]) * s * t + (p[3][d] - p[2][d]) * t * t)
        })
    }

    /// Second derivative `d2C/dt2` on segment `k`.
    pub fn d2(&self, k: usize, t: f64) -> P2 {
        let p = &self.segments[k];
        [0, 1]
            .map(|d| 6.0 * ((p[2][d] - 2.0 * p[1][d] + p[0][d]) * (1.0 - t) + (p[3][d] - 2.0 * p[2][d] + p[1][d]) * t))
    }

    /// Derivative with respect to the global parameter `u` (C1 across joins).
    pub fn du(&self, k: usize, t: f64) -> P2 {
        let span = self.knots[k + 1] - self.knots[k];
        self.d1(k, t).map(|v| v / span)
    }

    /// Unit normal to the right of the direction of travel, `(C_y', -C_x') / |C'|`.
    pub fn right_normal(&self, k: usize, t: f64) -> P2 {
        let d = self.d1(k, t);
        unit([d[1], -d[0]])
    }

    /// Arc length of segment `k` between `ta` and `tb`: 10-point Gauss on
    /// 4 equal sub-intervals (the speed of a cubic is smooth unless the
    /// segment is nearly degenerate; this gives ~1e-13 relative on
    /// boundary-like curves).
    pub fn length_between(&self, k: usize, ta: f64, tb: f64) -> f64 {
        let (x, w) = gauss_legendre(10);
        let sub = 4;
        let dt = (tb - ta) / sub as f64;
        let mut total = 0.0;
        for i in 0..sub {
            let a = ta + i as f64 * dt;
            for (xi, wi) in x.iter().zip(&w) {
                total += wi * norm(self.d1(k, a + 0.5 * dt * (1.0 + xi))) * 0.5 * dt;
            }
        }
        total
    }

    pub fn length(&self) -> f64 {
        (0..self.segments.len()).map(|k| self.length_between(k, 0.0, 1.0)).sum()
    }

    /// Signed enclosed area (counter-clockwise positive) by Green's theorem,
    /// `1/2 oint (x y' - y x') dt`, exact for cubics with 4-point Gauss
    /// (the integrand has degree 5). Meaningful for closed curves.
    pub fn signed_area(&self) -> f64 {
        let (x, w) = gauss_legendre(4);
        let mut a = 0.0;
        for k in 0..self.segments.len() {
            for (xi, wi) in x.iter().zip(&w) {
                let t = 0.5 * (1.0 + xi);
                let (p, d) = (self.point(k, t), self.d1(k, t));
                a += 0.5 * wi * 0.5 * (p[0] * d[1] - p[1] * d[0]);
            }
        }
        a
    }

    /// `n` points per segment along the curve (for drawing), ending at the last point.
    pub fn sample(&self, per_segment: usize) -> Vec<P2> {
        let mut out = Vec::with_capacity(self.segments.len() * per_segment + 1);
        for k in 0..self.segments.len() {
            for i in 0..per_segment {
                out.push(self.point(k, i as f64 / per_segment as f64));
            }
        }
        out.push(self.segments.last().map_or([0.0; 2], |s| s[3]));
        out
    }
}
