//! `[[probe]]`: named quantities followed through a run.

use super::*;
use crate::probe::{FieldFit, Probe, ProbeTarget};
use crate::scene::ProbeRead;

/// The probes, each resolved to a point or a boundary of the model.
pub(super) fn build(
    scene: &Scene,
    points: &Points,
    regions: &[Region],
    boundaries: &[Boundary],
    ibm: &[IbmBoundary],
) -> Result<Vec<Probe>, FieldError> {
    let mut probes: Vec<Probe> = Vec::with_capacity(scene.probes.len());
    if scene.probes.len() > MAX_ENTRIES {
        return Err(FieldError::new(
            format!("probe[{MAX_ENTRIES}]"),
            format!("more than the {MAX_ENTRIES} probes supported"),
        ));
    }
    for (k, spec) in scene.probes.iter().enumerate() {
        let f = |n: &str| format!("probe[{k}].{n}");
        let name = spec.name.trim();
        // Probe names become CSV headers (`probe:<name>:uy`) and recording
        // paths (`metrics/probe/<name>/uy`): keep them to one plain word.
        if name.is_empty()
            || name.chars().count() > MAX_NAME
            || !name
                .chars()
                .all(|c| c.is_alphanumeric() || c == '_' || c == '-' || c == '.')
        {
            return Err(FieldError::new(
                f("name"),
                format!("a probe name is 1 to {MAX_NAME} letters, digits, `_`, `-` or `.`"),
            ));
        }
        if probes.iter().any(|p| p.name == name) {
            return Err(FieldError::new(f("name"), format!("probe `{name}` is defined twice")));
        }
        let target = match (&spec.at, &spec.boundary, &spec.ibm) {
            (Some(at), None, None) => position_target(k, *at, spec.point.unwrap_or_default(), scene, points, regions)?,
            (None, Some(b), None) => ProbeTarget::Boundary(
                boundaries
                    .iter()
                    .position(|x| &x.name == b)
                    .ok_or_else(|| FieldError::new(f("boundary"), format!("no [[boundary]] named `{b}`")))?,
            ),
            (None, None, Some(b)) => ProbeTarget::Ibm(
                ibm.iter()
                    .position(|x| &x.name == b)
                    .ok_or_else(|| FieldError::new(f("ibm"), format!("no [[ibm]] named `{b}`")))?,
            ),
            _ => {
                return Err(FieldError::new(
                    format!("probe[{k}]"),
                    "give exactly one of `at` (a position), `boundary` or `ibm` (a name)",
                ))
            }
        };
        if spec.point.is_some() && spec.at.is_none() {
            return Err(FieldError::new(
                f("point"),
                "`point` chooses what answers at a position: give `at`",
            ));
        }
        probes.push(Probe {
            name: name.to_string(),
            target,
            at: spec.at,
            velocity: scene.analysis.kind.is_dynamic(),
        });
    }
    Ok(probes)
}

/// A probe at position `at` (`probe[k].at`): the fields there, fitted from
/// the points of the body that holds it, or that body's point nearest to
/// it. Tracking points (zero volume) never answer. Refused outside the
/// grid and outside every body.
fn position_target(
    k: usize,
    at: P2,
    read: ProbeRead,
    scene: &Scene,
    points: &Points,
    regions: &[Region],
) -> Result<ProbeTarget, FieldError> {
    let field = || format!("probe[{k}].at");
    if !at.iter().all(|v| v.is_finite()) {
        return Err(FieldError::new(field(), "must be a finite position"));
    }
    let g = &scene.grid;
    let inside = (0..2).all(|c| at[c] >= g.origin[c] && at[c] <= g.origin[c] + g.size[c]);
    if !inside {
        return Err(FieldError::new(
            field(),
            format!(
                "[{}, {}] is outside the grid ([{}, {}] x [{}, {}])",
                at[0],
                at[1],
                g.origin[0],
                g.origin[0] + g.size[0],
                g.origin[1],
                g.origin[1] + g.size[1]
            ),
        ));
    }
    // The body whose region holds `at`; a position on a region's edge
    // (a beam's tip, a corner) is held by the body on either side.
    let e = 1e-6 * g.h;
    let near = [
        [0.0, 0.0],
        [e, 0.0],
        [-e, 0.0],
        [0.0, e],
        [0.0, -e],
        [e, e],
        [-e, e],
        [e, -e],
        [-e, -e],
    ];
    let body = regions
        .iter()
        .position(|r| near.iter().any(|d| r.contains([at[0] + d[0], at[1] + d[1]])))
        .ok_or_else(|| {
            FieldError::new(
                field(),
                format!(
                    "[{}, {}] is outside every body: a probe reads the material at a position",
                    at[0], at[1]
                ),
            )
        })?;
    let mine = (0..points.len()).filter(|&p| points.body[p] == body && points.vol0[p] > 0.0);
    match read {
        ProbeRead::Field => FieldFit::new(at, g.h, mine.map(|p| (p, points.x0[p], points.vol0[p])))
            .map(ProbeTarget::Field)
            .ok_or_else(|| {
                FieldError::new(
                    field(),
                    format!(
                        "no material point of body `{}` lies within 1.5 cells of [{}, {}]",
                        scene.bodies[body].name, at[0], at[1]
                    ),
                )
            }),
        ProbeRead::Nearest => {
            let d2 = |p: &usize| (points.x0[*p][0] - at[0]).powi(2) + (points.x0[*p][1] - at[1]).powi(2);
            mine.min_by(|a, b| d2(a).total_cmp(&d2(b)))
                .map(ProbeTarget::Point)
                .ok_or_else(|| {
                    FieldError::new(
                        field(),
                        format!("body `{}` has no material points", scene.bodies[body].name),
                    )
                })
        }
    }
}
