//! `[[probe]]`: named quantities followed through a run.

use super::*;
use crate::probe::{Probe, ProbeTarget};

/// The probes, each resolved to a point or a boundary of the model.
pub(super) fn build(
    scene: &Scene,
    points: &Points,
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
            (Some(at), None, None) => {
                if !at.iter().all(|v| v.is_finite()) {
                    return Err(FieldError::new(f("at"), "must be a finite position"));
                }
                let g = &scene.grid;
                let inside = (0..2).all(|c| at[c] >= g.origin[c] && at[c] <= g.origin[c] + g.size[c]);
                if !inside {
                    return Err(FieldError::new(
                        f("at"),
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
                let d2 = |p: usize| (points.x0[p][0] - at[0]).powi(2) + (points.x0[p][1] - at[1]).powi(2);
                let p = (0..points.len())
                    .min_by(|&a, &b| d2(a).total_cmp(&d2(b)))
                    .ok_or_else(|| FieldError::new(f("at"), "the scene has no material points"))?;
                // Outside every body: no point with volume within a cell
                // of the position (the nearest would answer from afar).
                let reach = (0..points.len())
                    .filter(|&q| points.vol0[q] > 0.0)
                    .map(d2)
                    .fold(f64::INFINITY, f64::min)
                    .sqrt();
                if reach > g.h {
                    return Err(FieldError::new(
                        f("at"),
                        format!(
                            "[{}, {}] is outside every body: the nearest material point is {reach:.3e} m away, \
                             more than a cell (h = {})",
                            at[0], at[1], g.h
                        ),
                    ));
                }
                ProbeTarget::Point(p)
            }
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
        probes.push(Probe {
            name: name.to_string(),
            target,
            at: spec.at,
        });
    }
    Ok(probes)
}
