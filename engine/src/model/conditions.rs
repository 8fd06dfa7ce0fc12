//! `[[dirichlet]]` grid-line conditions and `[loads]`.

use super::*;

/// Grid-aligned Dirichlet conditions.
pub(super) fn dirichlet(scene: &Scene, grid: &Grid) -> Result<Vec<GridDirichlet>, FieldError> {
    let mut dirichlet = Vec::new();
    for (k, d) in scene.dirichlet.iter().enumerate() {
        let f = |n: &str| format!("dirichlet[{k}].{n}");
        let (target, axis) = match (d.x, d.y, d.node) {
            (Some(x), None, None) => (
                GridTarget::Line {
                    axis: 0,
                    index: grid
                        .line_index(0, x)
                        .ok_or_else(|| FieldError::new(f("x"), format!("x = {} is not a grid line", number(x))))?,
                },
                0,
            ),
            (None, Some(y), None) => (
                GridTarget::Line {
                    axis: 1,
                    index: grid
                        .line_index(1, y)
                        .ok_or_else(|| FieldError::new(f("y"), format!("y = {} is not a grid line", number(y))))?,
                },
                1,
            ),
            (None, None, Some(at)) => {
                if d.kind != DirichletKind::Fixed {
                    return Err(FieldError::new(f("kind"), "a condition on one node must be `fixed`"));
                }
                let (i, j) = (grid.line_index(0, at[0]), grid.line_index(1, at[1]));
                let (Some(i), Some(j)) = (i, j) else {
                    return Err(FieldError::new(
                        f("node"),
                        format!("[{}, {}] is not a grid node", number(at[0]), number(at[1])),
                    ));
                };
                (GridTarget::Node(grid.node(i, j)), 0)
            }
            _ => {
                return Err(FieldError::new(
                    format!("dirichlet[{k}]"),
                    "give exactly one of `x`, `y` or `node`",
                ))
            }
        };
        let value = match d.kind {
            DirichletKind::Fixed => {
                if d.normal_displacement.is_some() {
                    return Err(FieldError::new(
                        f("normal_displacement"),
                        "only for rollers; use `displacement`",
                    ));
                }
                let u = d.displacement.unwrap_or([0.0; 2]);
                if !u.iter().all(|v| v.is_finite()) {
                    return Err(FieldError::new(f("displacement"), "must be finite"));
                }
                [Some(u[0]), Some(u[1])]
            }
            DirichletKind::Roller => {
                if d.displacement.is_some() {
                    return Err(FieldError::new(
                        f("displacement"),
                        "only for fixed; use `normal_displacement`",
                    ));
                }
                let u = d.normal_displacement.unwrap_or(0.0);
                if !u.is_finite() {
                    return Err(FieldError::new(f("normal_displacement"), "must be finite"));
                }
                let mut v = [None, None];
                v[axis] = Some(u);
                v
            }
        };
        dirichlet.push(GridDirichlet { target, value });
    }

    Ok(dirichlet)
}

/// Gravity and point loads (each on the point nearest to where it acts).
pub(super) fn loads(scene: &Scene, grid: &Grid, points: &Points) -> Result<(P2, Vec<PointLoad>), FieldError> {
    let gravity = scene.loads.gravity.unwrap_or([0.0; 2]);
    if !gravity.iter().all(|g| g.is_finite()) {
        return Err(FieldError::new("loads.gravity", "must be finite"));
    }
    let mut point_loads = Vec::new();
    if scene.loads.point.len() > MAX_POINT_LOADS {
        return Err(FieldError::new(
            "loads.point",
            format!(
                "{} point loads are more than the {MAX_POINT_LOADS} supported",
                scene.loads.point.len()
            ),
        ));
    }
    if (scene.loads.point.len() as u128) * (points.len() as u128) > MAX_GENERATION_WORK {
        return Err(FieldError::new(
            "loads.point",
            format!(
                "finding the nearest of {} points for each of {} point loads is more than the {MAX_GENERATION_WORK} tests allowed; use fewer point loads",
                points.len(),
                scene.loads.point.len()
            ),
        ));
    }
    for (k, l) in scene.loads.point.iter().enumerate() {
        if !l.at.iter().all(|v| v.is_finite()) {
            return Err(FieldError::new(format!("loads.point[{k}].at"), "must be finite"));
        }
        if !l.force.iter().all(|v| v.is_finite()) {
            return Err(FieldError::new(format!("loads.point[{k}].force"), "must be finite"));
        }
        if grid.cell_of(l.at).is_none() {
            return Err(FieldError::new(format!("loads.point[{k}].at"), "lies outside the grid"));
        }
        let point = (0..points.len())
            .filter(|&p| points.vol[p] > 0.0)
            .min_by(|&a, &b| dist2(points.x[a], l.at).total_cmp(&dist2(points.x[b], l.at)))
            .expect("bodies are non-empty");
        point_loads.push(PointLoad { point, force: l.force });
    }

    Ok((gravity, point_loads))
}
