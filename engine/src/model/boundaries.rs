//! `[[boundary]]`: B-spline boundaries through tracking points or a layer of a body's points.

use super::bodies::layer_points;
use super::*;

#[allow(clippy::too_many_arguments)]
pub(super) fn build_boundary(
    k: usize,
    spec: &BoundarySpec,
    grid: &Grid,
    bodies: &[Body],
    regions: &[Region],
    ranges: &[std::ops::Range<usize>],
    has_exact: bool,
    points: &mut Points,
) -> Result<Boundary, FieldError> {
    let f = |n: &str| format!("boundary[{k}].{n}");
    let body = bodies
        .iter()
        .position(|b| b.name == spec.body)
        .ok_or_else(|| FieldError::new(f("body"), format!("no body named `{}`", spec.body)))?;
    let idx: Vec<usize> = match (&spec.points, spec.layer) {
        (Some(list), None) => {
            if list.len() > MAX_CURVE_POINTS {
                return Err(FieldError::new(
                    f("points"),
                    format!(
                        "{} points are more than the {MAX_CURVE_POINTS} a boundary may have",
                        list.len()
                    ),
                ));
            }
            let gmax = grid.max();
            let tol = 1e-9 * grid.h;
            let mut idx = Vec::new();
            for (i, p) in list.iter().enumerate() {
                if !(p.iter().all(|v| v.is_finite())
                    && p[0] >= grid.origin[0] - tol
                    && p[1] >= grid.origin[1] - tol
                    && p[0] <= gmax[0] + tol
                    && p[1] <= gmax[1] + tol)
                {
                    return Err(FieldError::new(f("points"), format!("point {i} lies outside the grid")));
                }
                // Zero-volume tracking point: follows the body, carries nothing.
                points.push(*p, 0.0, 0.0, [0.0; 2], body);
                idx.push(points.len() - 1);
            }
            idx
        }
        (None, Some(side)) => {
            let center = spec.center.unwrap_or([0.0; 2]);
            if matches!(side, LayerSide::Inner | LayerSide::Outer) && spec.center.is_none() {
                return Err(FieldError::new(f("center"), "inner and outer layers need a `center`"));
            }
            layer_points(points, ranges[body].clone(), side, center, 1e-9 * grid.h)
        }
        _ => {
            return Err(FieldError::new(
                format!("boundary[{k}]"),
                "give exactly one of `points` or `layer`",
            ))
        }
    };
    let mut corners = vec![false; idx.len()];
    for &c in &spec.corners {
        *corners
            .get_mut(c)
            .ok_or_else(|| FieldError::new(f("corners"), format!("there is no point {c}")))? = true;
    }
    if !(1..=20).contains(&spec.gauss_points) {
        return Err(FieldError::new(f("gauss_points"), "must be between 1 and 20"));
    }
    let traction = match &spec.traction {
        None => None,
        Some(TractionSpec::Vector { value }) => {
            if !value.iter().all(|v| v.is_finite()) {
                return Err(FieldError::new(f("traction"), "must be finite"));
            }
            Some(Traction::Vector(*value))
        }
        Some(TractionSpec::Pressure { value }) => {
            if !value.is_finite() {
                return Err(FieldError::new(f("traction"), "must be finite"));
            }
            Some(Traction::Pressure(*value))
        }
        Some(TractionSpec::ExactStress) => {
            if !has_exact {
                return Err(FieldError::new(
                    f("traction"),
                    "exact-stress traction needs an [exact] solution",
                ));
            }
            Some(Traction::ExactStress)
        }
    };
    let q: Vec<P2> = idx.iter().map(|&p| points.x[p]).collect();
    let spline =
        BSpline::interpolate(&q, spec.closed, &corners).map_err(|e| FieldError::new(f("points"), e.to_string()))?;
    let outward = match spec.material_side {
        Some(MaterialSide::Left) => 1.0,
        Some(MaterialSide::Right) => -1.0,
        None => material_side(&spline, &regions[body], grid.h).ok_or_else(|| {
            FieldError::new(
                f("material_side"),
                "cannot tell which side of the curve the material is on; give material_side = \"left\" or \"right\"",
            )
        })?,
    };
    Ok(Boundary {
        name: spec.name.clone(),
        points: idx,
        closed: spec.closed,
        corners,
        gauss_points: spec.gauss_points,
        traction,
        outward,
    })
}

/// `+1` when the material lies to the left of the curve (outward normal =
/// right normal), `-1` when to the right, by probing the region on both
/// sides of the middle of the curve at growing distances.
pub(super) fn material_side(s: &BSpline, region: &Region, h: f64) -> Option<f64> {
    let k = s.segments.len() / 2;
    let x = s.point(k, 0.5);
    let n = s.right_normal(k, 0.5);
    for eps in [0.05, 0.1, 0.25, 0.5, 1.0, 2.0] {
        let d = eps * h;
        let right = region.contains([x[0] + d * n[0], x[1] + d * n[1]]);
        let left = region.contains([x[0] - d * n[0], x[1] - d * n[1]]);
        match (left, right) {
            (true, false) => return Some(1.0),
            (false, true) => return Some(-1.0),
            _ => {}
        }
    }
    None
}
