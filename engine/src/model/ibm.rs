//! `[[ibm]]`: implicit-boundary Dirichlet conditions.

use super::*;
use crate::scene::IbmSpec;

/// The implicit boundaries, checked against the analysis, the grid and the bodies' regions.
pub(super) fn build(
    scene: &Scene,
    grid: &Grid,
    a: &AnalysisSpec,
    boundaries: &[Boundary],
    points: &Points,
    regions: &[Region],
    exact: Option<&ExactSolution>,
) -> Result<Vec<IbmBoundary>, FieldError> {
    let mut ibm = Vec::new();
    for (k, spec) in scene.ibm.iter().enumerate() {
        let f = |n: &str| format!("ibm[{k}].{n}");
        if a.kind == crate::scene::AnalysisKind::ExplicitDynamics {
            // C (17)-(27) enforce the condition through the band's
            // stiffness in an implicit equilibrium solve; an explicit
            // step solves only M a = f and has no stiffness to carry it.
            return Err(FieldError::new(
                f("kind"),
                "the implicit boundary method (Cortis et al. 2018) acts through the stiffness of an implicit \
                 solve; explicit dynamics has none: use kind = \"dynamic-implicit\" (Newmark, the same \
                 boundaries), a quasi-static analysis or grid-line supports",
            ));
        }
        let (poly, spline) = polyline(k, spec, boundaries, points)?;
        check_polyline(k, spec, &poly, grid)?;
        if !(1..=20).contains(&spec.gauss_points) {
            return Err(FieldError::new(f("gauss_points"), "must be between 1 and 20"));
        }
        let value = prescribed_value(k, spec)?;
        if spec.fit_regularisation.is_some_and(|e| !(0.0..1.0).contains(&e)) {
            return Err(FieldError::new(f("fit_regularisation"), "must lie in [0, 1)"));
        }
        if spec.exact_field {
            if spec.kind != DirichletKind::Fixed || spec.displacement.is_some() {
                return Err(FieldError::new(
                    f("exact_field"),
                    "only for fixed boundaries without `displacement`",
                ));
            }
            if exact.is_none() {
                return Err(FieldError::new(f("exact_field"), "needs an [exact] solution"));
            }
        }
        let mut b = IbmBoundary {
            name: spec.name.clone(),
            kind: spec.kind,
            points: poly.clone(),
            side: 1.0,
            value,
            gauss_points: spec.gauss_points,
            exact_field: spec.exact_field,
            fit_regularisation: spec.fit_regularisation,
            moves: spec.moves,
            spline,
        };
        if spec.moves {
            check_moves(k, spec, &poly)?;
            if !scene.analysis.update_points {
                return Err(FieldError::new(
                    format!("ibm[{k}].moves"),
                    "a moving boundary moves the configuration, and `analysis.update_points = false` keeps \
                     the starting one: prescribe the displacement on a boundary that stays (`moves = false`)",
                ));
            }
        }
        b.side = material_side(k, spec, &b, &poly, grid, regions)?;
        ibm.push(b);
    }

    Ok(ibm)
}

/// The boundary's polyline: its `points`, or the curve of the named
/// B-spline boundary sampled at `per_segment` chords per segment (with the
/// boundary's index and that count).
#[allow(clippy::type_complexity)]
fn polyline(
    k: usize,
    spec: &IbmSpec,
    boundaries: &[Boundary],
    points: &Points,
) -> Result<(Vec<P2>, Option<(usize, usize)>), FieldError> {
    let f = |n: &str| format!("ibm[{k}].{n}");
    match (&spec.boundary, spec.points.is_empty()) {
        (Some(name), true) => {
            let idx = boundaries
                .iter()
                .position(|b| &b.name == name)
                .ok_or_else(|| FieldError::new(f("boundary"), format!("no [[boundary]] named `{name}`")))?;
            if !(1..=256).contains(&spec.per_segment) {
                return Err(FieldError::new(f("per_segment"), "must be between 1 and 256"));
            }
            let s = boundaries[idx]
                .spline(points)
                .map_err(|e| FieldError::new(f("boundary"), e.to_string()))?;
            if s.segments.len().saturating_mul(spec.per_segment) > MAX_CURVE_POINTS {
                return Err(FieldError::new(
                    f("per_segment"),
                    format!(
                        "{} segments x {} chords are more than the {MAX_CURVE_POINTS} vertices a polyline may have",
                        s.segments.len(),
                        spec.per_segment
                    ),
                ));
            }
            Ok((s.sample(spec.per_segment), Some((idx, spec.per_segment))))
        }
        (None, false) => Ok((spec.points.clone(), None)),
        _ => Err(FieldError::new(
            format!("ibm[{k}]"),
            "give exactly one of `points` or `boundary`",
        )),
    }
}

/// The polyline's size, its points finite and inside the grid (its cells
/// and band must be cells of the grid), no two consecutive ones equal.
fn check_polyline(k: usize, spec: &IbmSpec, poly: &[P2], grid: &Grid) -> Result<(), FieldError> {
    let f = |n: &str| format!("ibm[{k}].{n}");
    if spec.points.len() > MAX_CURVE_POINTS {
        return Err(FieldError::new(
            f("points"),
            format!(
                "{} points are more than the {MAX_CURVE_POINTS} a polyline may have",
                spec.points.len()
            ),
        ));
    }
    if poly.len() < 2 || !poly.iter().flatten().all(|v| v.is_finite()) {
        return Err(FieldError::new(
            f("points"),
            "a polyline needs at least 2 finite points",
        ));
    }
    // The boundary's cells and its band must be cells of the grid.
    let gmax = grid.max();
    let tol = 1e-9 * grid.h;
    if let Some((i, p)) = poly.iter().enumerate().find(|(_, p)| {
        !(p[0] >= grid.origin[0] - tol
            && p[1] >= grid.origin[1] - tol
            && p[0] <= gmax[0] + tol
            && p[1] <= gmax[1] + tol)
    }) {
        let what = if spec.boundary.is_some() {
            format!(
                "the curve of boundary `{}`",
                spec.boundary.as_deref().unwrap_or_default()
            )
        } else {
            format!("point {i}")
        };
        return Err(FieldError::new(
            if spec.boundary.is_some() {
                f("boundary")
            } else {
                f("points")
            },
            format!(
                "{what} at ({}, {}) lies outside the grid [{}, {}] x [{}, {}]",
                short(p[0]),
                short(p[1]),
                short(grid.origin[0]),
                short(gmax[0]),
                short(grid.origin[1]),
                short(gmax[1])
            ),
        ));
    }
    if poly.windows(2).any(|w| w[0] == w[1]) {
        return Err(FieldError::new(f("points"), "consecutive points coincide"));
    }
    Ok(())
}

/// The prescribed value: a fixed boundary's `displacement`, or a roller's
/// `normal_displacement` as `[u_n, 0]`; each kind refuses the other's field.
fn prescribed_value(k: usize, spec: &IbmSpec) -> Result<P2, FieldError> {
    let f = |n: &str| format!("ibm[{k}].{n}");
    match spec.kind {
        DirichletKind::Fixed => {
            if spec.normal_displacement.is_some() {
                return Err(FieldError::new(
                    f("normal_displacement"),
                    "only for rollers; use `displacement`",
                ));
            }
            let u = spec.displacement.unwrap_or([0.0; 2]);
            if !u.iter().all(|v| v.is_finite()) {
                return Err(FieldError::new(f("displacement"), "must be finite"));
            }
            Ok(u)
        }
        DirichletKind::Roller => {
            if spec.displacement.is_some() {
                return Err(FieldError::new(
                    f("displacement"),
                    "only for fixed; use `normal_displacement`",
                ));
            }
            let u = spec.normal_displacement.unwrap_or(0.0);
            if !u.is_finite() {
                return Err(FieldError::new(f("normal_displacement"), "must be finite"));
            }
            Ok([u, 0.0])
        }
    }
}

/// A moving boundary must be fixed with a uniform displacement, or a
/// straight roller given by points (it translates along its one normal).
fn check_moves(k: usize, spec: &IbmSpec, poly: &[P2]) -> Result<(), FieldError> {
    // A moving roller translates along its one normal.
    let straight = poly.windows(3).all(|w| {
        let (a, b) = (
            [w[1][0] - w[0][0], w[1][1] - w[0][1]],
            [w[2][0] - w[1][0], w[2][1] - w[1][1]],
        );
        (a[0] * b[1] - a[1] * b[0]).abs() <= 1e-9 * a[0].hypot(a[1]) * b[0].hypot(b[1])
            && a[0] * b[0] + a[1] * b[1] > 0.0
    });
    let ok = match spec.kind {
        DirichletKind::Fixed => !spec.exact_field,
        DirichletKind::Roller => straight && spec.boundary.is_none(),
    };
    if !ok {
        return Err(FieldError::new(
            format!("ibm[{k}].moves"),
            "only fixed boundaries with a uniform displacement, or straight rollers, can move",
        ));
    }
    Ok(())
}

/// Which side of the polyline the material is on (`1`: left, `-1`:
/// right): as given, or found by probing the bodies' regions on either side
/// of the middle segment at growing distances.
fn material_side(
    k: usize,
    spec: &IbmSpec,
    b: &IbmBoundary,
    poly: &[P2],
    grid: &Grid,
    regions: &[Region],
) -> Result<f64, FieldError> {
    match spec.material_side {
        Some(MaterialSide::Left) => Ok(1.0),
        Some(MaterialSide::Right) => Ok(-1.0),
        None => {
            let mid = poly.len() / 2 - 1;
            let (p0, p1) = (poly[mid], poly[mid + 1]);
            let m = [0.5 * (p0[0] + p1[0]), 0.5 * (p0[1] + p1[1])];
            let n = b.normal(p0, p1); // left normal for side = +1
            let inside = |x: P2| regions.iter().any(|r| r.contains(x));
            let mut side = None;
            for eps in [0.01, 0.05, 0.25, 0.5, 1.0] {
                let d = eps * grid.h;
                match (
                    inside([m[0] + d * n[0], m[1] + d * n[1]]),
                    inside([m[0] - d * n[0], m[1] - d * n[1]]),
                ) {
                    (true, false) => side = Some(1.0),
                    (false, true) => side = Some(-1.0),
                    _ => continue,
                }
                break;
            }
            side.ok_or_else(|| {
                FieldError::new(
                    format!("ibm[{k}].material_side"),
                    "cannot tell which side the material is on; give material_side",
                )
            })
        }
    }
}
