//! The B-spline boundary mathematics: interpolation, continuity, straight
//! runs and corners, convergence to a circle, Gauss integration along
//! pieces, and splitting at grid lines.

use mpmlab_engine::boundary::bspline::{BSpline, Interpolation};
use mpmlab_engine::boundary::intersect::split;
use mpmlab_engine::grid::Grid;
use mpmlab_engine::quadrature::gauss_legendre;
use proptest::prelude::*;

fn close(a: [f64; 2], b: [f64; 2], tol: f64) -> bool {
    (a[0] - b[0]).abs() <= tol && (a[1] - b[1]).abs() <= tol
}

fn random_points(seed: &[f64]) -> Vec<[f64; 2]> {
    // A wiggly open curve with increasing x (steps 0.6 to 1.4, slopes up to
    // about 1), so no two points coincide and there are no cusps.
    seed.chunks_exact(2)
        .enumerate()
        .map(|(k, c)| [k as f64 + 0.4 * c[0], 0.6 * c[1]])
        .collect()
}

/// The unit square counter-clockwise from the origin, 3 points a side
/// (corners included once): `(k / 3)` steps along each side, so a side's
/// points are collinear to the bit.
fn unit_square() -> Vec<[f64; 2]> {
    let mut q = Vec::new();
    for (x0, y0, dx, dy) in [
        (0.0, 0.0, 1.0, 0.0),
        (1.0, 0.0, 0.0, 1.0),
        (1.0, 1.0, -1.0, 0.0),
        (0.0, 1.0, 0.0, -1.0),
    ] {
        for k in 0..3 {
            let f = k as f64 / 3.0;
            q.push([x0 + dx * f, y0 + dy * f]);
        }
    }
    q
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn passes_through_points_and_is_c1(seed in prop::collection::vec(0.0f64..1.0, 8..30), closed: bool) {
        let q = random_points(&seed);
        let s = BSpline::interpolate(&q, closed, &[]).unwrap();
        let m = s.segments.len();
        for k in 0..m {
            prop_assert!(close(s.point(k, 0.0), q[k], 1e-14));
            prop_assert!(close(s.point(k, 1.0), q[(k + 1) % q.len()], 1e-12));
        }
        // C1 in the global parameter u at every interior join (and the
        // closing join of a closed curve).
        let joins = if closed { m } else { m - 1 };
        for k in 0..joins {
            let (a, b) = (s.du(k, 1.0), s.du((k + 1) % m, 0.0));
            let scale = a[0].hypot(a[1]);
            prop_assert!(close(a, b, 1e-9 * scale), "join {}: {:?} vs {:?}", k, a, b);
        }
    }

    #[test]
    fn grid_pieces_cover_the_curve_once(seed in prop::collection::vec(0.0f64..1.0, 8..24), h in 0.05f64..0.7, ox in 0.0f64..1.0) {
        let q = random_points(&seed);
        let s = BSpline::interpolate(&q, false, &[]).unwrap();
        let grid = Grid { origin: [-1.0 - ox, -1.0], h, nx: (16.0 / h) as usize + 2, ny: (5.0 / h) as usize + 2 };
        let pieces = split(&s, &grid);
        // Contiguous and ordered: each piece starts where the last ended.
        for w in pieces.windows(2) {
            let (a, b) = (w[0], w[1]);
            if a.segment == b.segment {
                prop_assert!(a.t1 == b.t0 && a.t0 < a.t1);
            } else {
                prop_assert!(b.segment == a.segment + 1 && a.t1 == 1.0 && b.t0 == 0.0);
            }
        }
        prop_assert_eq!(pieces[0].t0, 0.0);
        prop_assert_eq!(pieces.last().unwrap().t1, 1.0);
        // Lengths add up to the whole curve. (Contiguity above is the exact
        // check; this one catches pieces of the wrong length. Both sides are
        // composite Gauss rules of a smooth speed.)
        let total: f64 = pieces.iter().map(|p| s.length_between(p.segment, p.t0, p.t1)).sum();
        let reference: f64 = (0..s.segments.len())
            .flat_map(|k| (0..256).map(move |i| (k, i as f64 / 256.0, (i + 1) as f64 / 256.0)))
            .map(|(k, a, b)| s.length_between(k, a, b))
            .sum();
        prop_assert!((total - reference).abs() < 1e-11 * reference, "{} vs {}", total, reference);
        // Each piece lies in its cell.
        for p in &pieces {
            let (i, j) = (p.cell % grid.nx, p.cell / grid.nx);
            let c0 = grid.cell_min(i, j);
            for t in [0.0, 0.25, 0.5, 0.75, 1.0] {
                let x = s.point(p.segment, p.t0 + t * (p.t1 - p.t0));
                let tol = 1e-9 * h;
                prop_assert!(x[0] >= c0[0] - tol && x[0] <= c0[0] + h + tol && x[1] >= c0[1] - tol && x[1] <= c0[1] + h + tol,
                    "piece {:?} leaves cell ({}, {}) at {:?}", p, i, j, x);
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(100))]

    /// The interpolation is local: segment `k` is a function of points
    /// `k - 2 ..= k + 3` alone (the follower load stiffness re-interpolates
    /// only the segments a moved point shapes, `i - 3 ..= i + 2`). Moving
    /// one point leaves every other segment bit for bit, and a segment
    /// built on its own is the whole curve's segment bit for bit.
    #[test]
    fn moving_a_point_changes_only_the_six_segments_it_shapes(
        seed in prop::collection::vec(0.0f64..1.0, 12..30),
        closed: bool,
        corner in 0usize..15,
        pick in 0usize..15,
        distance in 0.01f64..0.2,
        angle in 0.0f64..std::f64::consts::TAU,
    ) {
        let q = random_points(&seed);
        let n = q.len();
        let mut corners = vec![false; n];
        corners[corner % n] = true;
        let whole = BSpline::interpolate(&q, closed, &corners).unwrap();
        let it = Interpolation::new(&q, closed, &corners).unwrap();
        for k in 0..whole.segments.len() {
            prop_assert_eq!(it.spline_of(&[k]).segments[0], whole.segments[k]);
        }
        let i = pick % n;
        let mut moved = q.clone();
        moved[i] = [q[i][0] + distance * angle.cos(), q[i][1] + distance * angle.sin()];
        let after = Interpolation::with_scale(&moved, closed, &corners, it.scale());
        let m = whole.segments.len() as isize;
        let shaped: Vec<usize> = (i as isize - 3..=i as isize + 2)
            .map(|k| if closed { k.rem_euclid(m) } else { k })
            .filter(|k| (0..m).contains(k))
            .map(|k| k as usize)
            .collect();
        let mut changed = 0;
        for k in 0..whole.segments.len() {
            let seg = after.spline_of(&[k]).segments[0];
            if shaped.contains(&k) {
                changed += usize::from(seg != whole.segments[k]);
            } else {
                prop_assert_eq!(seg, whole.segments[k], "segment {} of {} moved with point {}", k, m, i);
            }
        }
        // The point's own two segments always change.
        prop_assert!(changed >= 1);
    }
}

#[test]
fn straight_runs_stay_straight() {
    // Points on a line, unevenly spaced: every segment is straight
    // (zero second derivative) and parametrised at constant speed.
    let q = [[0.0, 0.0], [0.3, 0.15], [1.0, 0.5], [1.2, 0.6], [2.0, 1.0]];
    let s = BSpline::interpolate(&q, false, &[]).unwrap();
    for k in 0..s.segments.len() {
        for t in [0.0, 0.3, 0.7, 1.0] {
            let d2 = s.d2(k, t);
            assert!(d2[0].abs() < 1e-13 && d2[1].abs() < 1e-13, "{d2:?}");
        }
    }
    assert!((s.length() - 2.0f64.hypot(1.0)).abs() < 1e-14);
}

#[test]
fn corners_keep_the_sides_of_a_square_straight() {
    // A closed square sampled with 3 points per side: corners are detected
    // (both side triples collinear, the sides not) without being marked.
    let q = unit_square();
    let s = BSpline::interpolate(&q, true, &[]).unwrap();
    for k in 0..s.segments.len() {
        for t in [0.2, 0.5, 0.9] {
            let d2 = s.d2(k, t);
            assert!(d2[0].abs() < 1e-12 && d2[1].abs() < 1e-12, "segment {k}: {d2:?}");
        }
    }
    assert!((s.signed_area() - 1.0).abs() < 1e-14 && (s.length() - 4.0).abs() < 1e-13);
}

#[test]
fn signed_area_is_positive_counter_clockwise_and_scales_with_the_square() {
    // The square of the test above with side 2 (corners detected, sides
    // straight): Green's theorem on the curve gives 4 counter-clockwise
    // and -4 read clockwise (the quadrature is exact on cubics; round-off
    // 1e-13 of the area).
    let mut q: Vec<[f64; 2]> = unit_square().iter().map(|p| [2.0 * p[0], 2.0 * p[1]]).collect();
    let ccw = BSpline::interpolate(&q, true, &[]).unwrap();
    q.reverse();
    let cw = BSpline::interpolate(&q, true, &[]).unwrap();
    for (s, want) in [(ccw, 4.0), (cw, -4.0)] {
        let a = s.signed_area();
        assert!((a - want).abs() < 1e-13 * 4.0, "{a}, want {want}");
    }
    // A smooth closed curve (8 points on an ellipse of axes 2 and 1): the
    // area of the polygon through 1000 samples per segment, by the
    // shoelace formula, converges to the curve's as the square of the
    // spacing (here ~1e-7 of it): 1e-6 leaves a factor 10.
    let q: Vec<[f64; 2]> = (0..8)
        .map(|k| {
            let t = std::f64::consts::TAU * k as f64 / 8.0;
            [2.0 * t.cos() + 0.5, t.sin() - 0.25]
        })
        .collect();
    let s = BSpline::interpolate(&q, true, &[]).unwrap();
    let p = s.sample(1000);
    let shoelace = 0.5 * p.windows(2).map(|w| w[0][0] * w[1][1] - w[1][0] * w[0][1]).sum::<f64>();
    let a = s.signed_area();
    println!("ellipse spline: Green {a}, shoelace {shoelace}");
    assert!((a - shoelace).abs() < 1e-6 * a.abs(), "Green {a}, shoelace {shoelace}");
}

#[test]
fn circle_converges() {
    // Points on the unit circle: the largest radial error falls by at least
    // 2^3 per halving of the spacing (local cubic interpolation with
    // estimated tangents; observed about 2^4).
    let err = |n: usize| {
        let q: Vec<[f64; 2]> = (0..n)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / n as f64;
                [t.cos(), t.sin()]
            })
            .collect();
        let s = BSpline::interpolate(&q, true, &[]).unwrap();
        s.sample(20)
            .iter()
            .map(|p| (p[0].hypot(p[1]) - 1.0).abs())
            .fold(0.0, f64::max)
    };
    let e: Vec<f64> = [8, 16, 32, 64].iter().map(|&n| err(n)).collect();
    println!("circle radial errors for 8, 16, 32, 64 points: {e:?}");
    for w in e.windows(2) {
        assert!(w[0] / w[1] > 8.0, "{e:?}");
    }
}

#[test]
fn gauss_integration_along_a_piece_is_exact_for_polynomials() {
    // A straight spline from (0, 0) to (3, 4) (length 5) at constant speed:
    // the integral of s^k along it with n Gauss points is exact for k <= 2n - 1.
    let q = [[0.0, 0.0], [1.2, 1.6], [1.8, 2.4], [3.0, 4.0]];
    let s = BSpline::interpolate(&q, false, &[]).unwrap();
    for n in 1..=4 {
        let (x, w) = gauss_legendre(n);
        for k in 0..2 * n {
            let mut sum = 0.0;
            for seg in 0..s.segments.len() {
                for (xi, wi) in x.iter().zip(&w) {
                    let t = 0.5 * (1.0 + xi);
                    let p = s.point(seg, t);
                    let d = s.d1(seg, t);
                    let arc = p[0].hypot(p[1]);
                    sum += wi * 0.5 * d[0].hypot(d[1]) * arc.powi(k as i32);
                }
            }
            let exact = 5f64.powi(k as i32 + 1) / (k as f64 + 1.0);
            assert!((sum - exact).abs() < 1e-12 * exact, "n={n} k={k}: {sum} vs {exact}");
        }
    }
}

#[test]
fn curves_along_and_touching_grid_lines_split_cleanly() {
    let grid = Grid {
        origin: [0.0, 0.0],
        h: 0.5,
        nx: 8,
        ny: 8,
    };
    // Along the line y = 1 through grid nodes: one piece per cell, no gaps.
    let q = [[0.0, 1.0], [0.5, 1.0], [1.0, 1.0], [1.7, 1.0], [2.0, 1.0]];
    let s = BSpline::interpolate(&q, false, &[]).unwrap();
    let pieces = split(&s, &grid);
    let total: f64 = pieces.iter().map(|p| s.length_between(p.segment, p.t0, p.t1)).sum();
    assert!((total - 2.0).abs() < 1e-14);
    assert_eq!(pieces.len(), 4 + 1, "{pieces:?}"); // cells of width 0.5 over [0, 2]; the 1.0-1.7 segment is cut at 1.5
                                                   // A parabola-like arc touching y = 1.5 tangentially at its top.
    let q = [[0.1, 1.0], [0.6, 1.375], [1.1, 1.5], [1.6, 1.375], [2.1, 1.0]];
    let s = BSpline::interpolate(&q, false, &[]).unwrap();
    let pieces = split(&s, &grid);
    let total: f64 = pieces.iter().map(|p| s.length_between(p.segment, p.t0, p.t1)).sum();
    assert!((total - s.length()).abs() < 1e-12);
    assert!(pieces.iter().all(|p| p.t1 - p.t0 > 1e-9));
}

#[test]
fn a_curve_that_doubles_back_has_a_cusp_not_nans() {
    // (0,0) -> (1,0) -> (0,0) is accepted (no two consecutive points
    // coincide) and turns back on itself at (1,0). There the chords on
    // either side are opposite and collinear, B (9)-(10) weight them
    // equally, and the tangent's direction is undefined: the interpolation
    // gives it zero length, a cusp, so both segments stay on y = 0 and pass
    // through the points. The normal at the cusp is zero (there is none),
    // never NaN.
    let q = [[0.0, 0.0], [1.0, 0.0], [0.0, 0.0]];
    let s = BSpline::interpolate(&q, false, &[]).unwrap();
    for seg in &s.segments {
        for p in seg {
            assert!(p[0].is_finite() && p[1] == 0.0, "{:?}", s.segments);
        }
    }
    for k in 0..2 {
        assert_eq!(s.point(k, 0.0), q[k]);
        assert_eq!(s.point(k, 1.0), q[k + 1]);
    }
    assert_eq!(s.d1(0, 1.0), [0.0, 0.0]);
    assert_eq!(s.d1(1, 0.0), [0.0, 0.0]);
    assert_eq!(s.right_normal(0, 1.0), [0.0, 0.0]);
    // Away from the cusp the normal is the unit normal to the right of
    // travel: -y on the way out, +y on the way back.
    assert!(close(s.right_normal(0, 0.5), [0.0, -1.0], 1e-15));
    assert!(close(s.right_normal(1, 0.5), [0.0, 1.0], 1e-15));
}

#[test]
fn interpolation_refuses_too_few_or_repeated_points_by_name() {
    // The scene checks report these messages on the boundary's `points`
    // field, so they must say which points and how many.
    let two = [[0.0, 0.0], [1.0, 0.0]];
    let e = Interpolation::new(&two, false, &[false; 2]).err().expect("two points");
    assert_eq!(e.to_string(), "a boundary needs at least 3 points, got 2");
    let three = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]];
    assert!(Interpolation::new(&three, false, &[false; 3]).is_ok());
    let repeated = [[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [2.0, 1.0]];
    let e = BSpline::interpolate(&repeated, false, &[false; 4]).expect_err("a repeated point");
    assert_eq!(e.to_string(), "boundary points 1 and 2 coincide");
}

#[test]
fn derivatives_are_those_of_the_curve_they_belong_to() {
    // On a curved closed spline (9 points on an ellipse of semi-axes 2 m and
    // 1 m), d1 and d2 are the derivatives in t of `point` and of `d1`,
    // checked by central differences of step e = 1e-4. Each segment is a
    // cubic: the central difference of `point` is C'(t) + e^2/6 C'''
    // exactly (measured off by 2.2e-9 m), and that of the quadratic `d1` is
    // C''(t) exactly, to round-off (about 1e-16 / e: measured 1.9e-12 m).
    // Both derivatives are of order 1 m here (measured up to 1.36 m and
    // 1.35 m), so tolerances of 1e-7 m and 1e-9 m leave the differences' own
    // errors far behind, while a wrong term of either derivative moves it at
    // first order.
    let q: Vec<[f64; 2]> = (0..9)
        .map(|k| {
            let a = 2.0 * std::f64::consts::PI * k as f64 / 9.0;
            [2.0 * a.cos(), a.sin()]
        })
        .collect();
    let s = BSpline::interpolate(&q, true, &[]).unwrap();
    let e = 1e-4;
    let (mut largest, mut miss) = ([0.0f64; 2], [0.0f64; 2]);
    for k in 0..s.segments.len() {
        for t in [0.1, 0.35, 0.5, 0.8, 0.95] {
            let (d1, d2) = (s.d1(k, t), s.d2(k, t));
            let (p, m) = (s.point(k, t + e), s.point(k, t - e));
            let fd1 = [(p[0] - m[0]) / (2.0 * e), (p[1] - m[1]) / (2.0 * e)];
            let (p, m) = (s.d1(k, t + e), s.d1(k, t - e));
            let fd2 = [(p[0] - m[0]) / (2.0 * e), (p[1] - m[1]) / (2.0 * e)];
            for (i, (d, fd)) in [(d1, fd1), (d2, fd2)].into_iter().enumerate() {
                largest[i] = largest[i].max(d[0].hypot(d[1]));
                miss[i] = miss[i].max((d[0] - fd[0]).abs().max((d[1] - fd[1]).abs()));
            }
            assert!(
                close(d1, fd1, 1e-7),
                "segment {k}, t = {t}: d1 {d1:?}, differences {fd1:?}"
            );
            assert!(
                close(d2, fd2, 1e-9),
                "segment {k}, t = {t}: d2 {d2:?}, differences {fd2:?}"
            );
        }
    }
    println!(
        "|d1| <= {:.3}, |d2| <= {:.3}; differences off by {:.1e} and {:.1e}",
        largest[0], largest[1], miss[0], miss[1]
    );
    // The derivatives the tolerances are small against: of order 1 on an
    // ellipse, never zero.
    assert!(largest[0] > 0.5 && largest[1] > 0.5, "{largest:?}");
}

#[test]
fn every_segment_moves_at_its_span_at_its_middle() {
    // B (11)-(12): segment k's span s_k is the positive root of
    // (16 - |t_a + t_b|^2) s^2 + 12 (d . (t_a + t_b)) s - 36 |d|^2 = 0,
    // with d the chord and t_a, t_b the unit tangents at its ends. With the
    // control points a, a + s t_a / 3, b - s t_b / 3, b this says the cubic's
    // speed at its middle is its span: C'(1/2) = 3/2 d - s/4 (t_a + t_b)
    // (the Bezier derivative at t = 1/2, written out here from the control
    // points), and |C'(1/2)|^2 = s^2 is that quadratic. The curves: a wiggly
    // one and a hairpin, where the tangents lean along each chord
    // (d . (t_a + t_b) > 0), and a short hop between two straight runs
    // going back (B (9): a tangent next to a straight run is that run's
    // direction), whose tangents lean against its chord (d . (t_a + t_b) < 0):
    // the quadratic's other root formula. Both are met to round-off (1e-13
    // of the span).
    let curves: Vec<Vec<[f64; 2]>> = vec![
        random_points(&[0.3, 0.9, 0.1, 0.5, 0.7, 0.2, 0.9, 0.4, 0.6, 0.8]),
        vec![[0.0, 0.0], [1.0, 0.0], [1.0, 0.1], [0.0, 0.1], [0.0, 0.2], [1.0, 0.2]],
        vec![[2.0, 0.0], [1.0, 0.0], [0.0, 0.0], [0.3, 0.1], [-0.7, 0.1], [-1.7, 0.1]],
    ];
    let (mut along, mut against) = (0, 0);
    for q in &curves {
        let corners = vec![false; q.len()];
        let it = Interpolation::new(q, false, &corners).unwrap();
        for k in 0..it.segments() {
            let (c, s) = it.segment(k);
            let mid = [0, 1].map(|i| 0.75 * ((c[1][i] - c[0][i]) + 2.0 * (c[2][i] - c[1][i]) + (c[3][i] - c[2][i])));
            let ts = [0, 1].map(|i| 3.0 * (c[1][i] - c[0][i] + c[3][i] - c[2][i]) / s);
            let lean = (c[3][0] - c[0][0]) * ts[0] + (c[3][1] - c[0][1]) * ts[1];
            println!(
                "{q:?} segment {k}: s {s:.6}, |C'(1/2)| {:.6}, d . (t_a + t_b) {lean:.3}",
                mid[0].hypot(mid[1])
            );
            if lean >= 0.0 {
                along += 1;
            } else {
                against += 1;
            }
            assert!(s > 0.0, "segment {k} of {q:?}: span {s}");
            assert!(
                (mid[0].hypot(mid[1]) - s).abs() <= 1e-13 * s,
                "segment {k} of {q:?}: speed {} at the middle, span {s}",
                mid[0].hypot(mid[1])
            );
        }
    }
    assert!(
        along > 0 && against > 0,
        "{along} segments lean along their chord, {against} against"
    );
}

#[test]
fn tangents_weigh_the_chords_by_the_turn_beyond_them() {
    // B (9)-(10): at an interior point k of a curve with no straight runs
    // the tangent is the unit vector along (1 - a) q_k + a q_(k+1), with
    // q_j = P_j - P_(j-1) the chords and a = A1 / (A1 + A2),
    // A1 = |q_(k-1) x q_k|, A2 = |q_(k+1) x q_(k+2)| (the turn before the
    // chord pair weighs the far chord). Segment k leaves P_k along its
    // control polygon's first leg (B (11): P_k1 = P_k + s t / 3), so that
    // leg's direction is the tangent. An uneven curve (A1 != A2 everywhere,
    // cross products of order 0.1 against chords of about 1), checked at
    // the points with two real chords on either side; round-off of a few
    // products: 1e-12.
    let q = random_points(&[
        0.3, 0.9, 0.1, 0.5, 0.7, 0.2, 0.9, 0.4, 0.6, 0.8, 0.15, 0.05, 0.5, 0.95, 0.05, 0.3, 0.8, 0.7, 0.35, 0.1, 0.6,
        0.9, 0.2, 0.4,
    ]);
    let s = BSpline::interpolate(&q, false, &[]).unwrap();
    let chord = |j: usize| [q[j][0] - q[j - 1][0], q[j][1] - q[j - 1][1]];
    let cross = |a: [f64; 2], b: [f64; 2]| (a[0] * b[1] - a[1] * b[0]).abs();
    let unit = |v: [f64; 2]| {
        let l = v[0].hypot(v[1]);
        [v[0] / l, v[1] / l]
    };
    let mut uneven = 0;
    for k in 2..q.len() - 2 {
        let (qm, q0, q1, q2) = (chord(k - 1), chord(k), chord(k + 1), chord(k + 2));
        let (a1, a2) = (cross(qm, q0), cross(q1, q2));
        let a = a1 / (a1 + a2);
        if (a - 0.5).abs() > 0.05 {
            uneven += 1;
        }
        let want = unit([(1.0 - a) * q0[0] + a * q1[0], (1.0 - a) * q0[1] + a * q1[1]]);
        let c = s.segments[k];
        let got = unit([c[1][0] - c[0][0], c[1][1] - c[0][1]]);
        assert!(close(got, want, 1e-12), "point {k}: {got:?} vs {want:?} (a = {a})");
    }
    assert!(uneven >= 4, "the weights must differ from 1/2 to be tested: {uneven}");
}

#[test]
fn a_straight_run_leaves_along_itself_into_a_curve() {
    // B (9)-(10) where a straight run meets a curve: at its last point
    // P_2 = (2, 0) the turn before (A1 = |q_1 x q_2| = 0) is none, the
    // turn after is A2 = 0.75, so a = A1 / (A1 + A2) = 0 and the tangent
    // is the run's own chord: the curve leaves the run along it, with no
    // kink or overshoot. Read backwards the same point has A2 = 0 and
    // a = 1: the tangent is the far chord, the run again. Round-off: 1e-12.
    let q = vec![[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.5], [3.5, 1.5], [3.6, 2.6]];
    let unit = |v: [f64; 2]| {
        let l = v[0].hypot(v[1]);
        [v[0] / l, v[1] / l]
    };
    for (points, k, along) in [
        (q.clone(), 2, [1.0, 0.0]),
        (q.iter().rev().copied().collect(), 3, [-1.0, 0.0]),
    ] {
        let s = BSpline::interpolate(&points, false, &[]).unwrap();
        let (arrive, leave) = (s.segments[k - 1], s.segments[k]);
        let t_in = unit([arrive[3][0] - arrive[2][0], arrive[3][1] - arrive[2][1]]);
        let t_out = unit([leave[1][0] - leave[0][0], leave[1][1] - leave[0][1]]);
        for t in [t_in, t_out] {
            assert!(
                close(t, along, 1e-12),
                "point {k}: tangent {t:?}, the run goes {along:?}"
            );
        }
    }
}

#[test]
fn corners_are_found_in_any_units_and_ignored_at_open_ends() {
    // A square rotated by 30 deg, 3 points per side, of side 1 m and of
    // side 10^4 (10 m in mm): the collinear chord pairs' cross products
    // are round-off of the coordinates, which grows with the units, and the
    // straight-run test compares them with 1e-12 times the longest chord
    // squared, so the corners are found and the sides stay straight
    // (|C''| at round-off of the curve's size) in both.
    let (sn, c) = 30f64.to_radians().sin_cos();
    for side in [1.0, 1e4] {
        let q: Vec<[f64; 2]> = unit_square()
            .iter()
            .map(|&[x, y]| {
                [
                    side * (c * x - sn * y) + 0.1 * side,
                    side * (sn * x + c * y) + 0.3 * side,
                ]
            })
            .collect();
        let s = BSpline::interpolate(&q, true, &[]).unwrap();
        for k in 0..s.segments.len() {
            for t in [0.2, 0.5, 0.9] {
                let d2 = s.d2(k, t);
                assert!(d2[0].hypot(d2[1]) < 1e-11 * side, "side {side}, segment {k}: {d2:?}");
            }
        }
        assert!(
            (s.length() / (4.0 * side) - 1.0).abs() < 1e-13,
            "side {side}: {}",
            s.length()
        );
    }
    // An open curve's ends have one tangent each (B (9) with the end
    // chords extrapolated): marking them as corners changes nothing, while
    // marking an interior point does.
    let q = random_points(&[0.3, 0.9, 0.1, 0.5, 0.7, 0.2, 0.9, 0.4, 0.6, 0.8]);
    let n = q.len();
    let plain = BSpline::interpolate(&q, false, &vec![false; n]).unwrap();
    let mut ends = vec![false; n];
    ends[0] = true;
    ends[n - 1] = true;
    assert_eq!(BSpline::interpolate(&q, false, &ends).unwrap(), plain);
    let mut inner = vec![false; n];
    inner[2] = true;
    assert_ne!(BSpline::interpolate(&q, false, &inner).unwrap(), plain);
}

#[test]
fn the_global_parameter_runs_from_0_to_1_at_the_segments_spans() {
    // B (12): the knots are the segments' spans s_k, summed and
    // normalised: u_0 = 0, u_m = 1, u_(k+1) - u_k = s_k / sum s. The
    // derivative in u is dC/dt / (u_(k+1) - u_k), and its length
    // integrated over u in [0, 1] is the curve's length (10-point Gauss on
    // each segment against `length`, 10-point Gauss on four quarters of
    // each: measured 3e-12, bound 1e-9 relative). An open wiggly curve
    // and a closed wavy loop (r = 2 + 0.3 cos 3 theta at uneven angles);
    // the spans from the interpolation's own segments, to round-off.
    let open = random_points(&[0.3, 0.9, 0.1, 0.5, 0.7, 0.2, 0.9, 0.4, 0.6, 0.8]);
    let loop_: Vec<[f64; 2]> = [0.0, 0.5, 1.1, 1.6, 2.3, 2.9, 3.4, 4.0, 4.7, 5.2, 5.8]
        .iter()
        .map(|&t: &f64| {
            let r = 2.0 + 0.3 * (3.0 * t).cos();
            [r * t.cos(), r * t.sin()]
        })
        .collect();
    for (q, closed) in [(open, false), (loop_, true)] {
        let s = BSpline::interpolate(&q, closed, &[]).unwrap();
        let corners = vec![false; q.len()];
        let it = Interpolation::new(&q, closed, &corners).unwrap();
        let m = s.segments.len();
        assert_eq!(s.knots.len(), m + 1);
        assert_eq!(s.knots[0], 0.0);
        assert!((s.knots[m] - 1.0).abs() < 1e-15, "{:?}", s.knots);
        let total: f64 = (0..m).map(|k| it.segment(k).1).sum();
        let (xg, wg) = gauss_legendre(10);
        let mut length = 0.0;
        for k in 0..m {
            let span = s.knots[k + 1] - s.knots[k];
            assert!((span - it.segment(k).1 / total).abs() < 1e-14, "segment {k}: {span}");
            for (x, w) in xg.iter().zip(&wg) {
                let t = 0.5 * (1.0 + x);
                let (du, d1) = (s.du(k, t), s.d1(k, t));
                assert!(
                    close([du[0] * span, du[1] * span], d1, 1e-13 * d1[0].hypot(d1[1])),
                    "segment {k}"
                );
                length += 0.5 * w * du[0].hypot(du[1]) * span;
            }
        }
        println!("closed {closed}: {:e}", length / s.length() - 1.0);
        assert!(
            (length / s.length() - 1.0).abs() < 1e-9,
            "closed {closed}: {length} vs {}",
            s.length()
        );
    }
}

/// The seeds of this module's past property failures are where proptest
/// reads them, so every run replays them first (the file holds 4).
#[test]
fn saved_failure_seeds_replay() {
    assert_eq!(crate::common::saved_seeds(file!()), 4);
}
