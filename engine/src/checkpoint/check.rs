//! The values of a checkpoint checked as a scene's are: a state read back
//! from a file is accepted only if every number is one a run could have
//! written, and each refusal names the field (and the point or node).
//!
//! The checksum catches damage on the disk; this catches a file edited
//! by hand (a negative volume, a `NaN` band width, a penalty of -1e30)
//! or written by a defective program.

use crate::model::{Model, MAX_DENSE_LIMIT};
use crate::state::{Params, State};

/// Why a value is refused: `field` (as the checkpoint names it, with the
/// index of the point or node), what it holds and what it must be.
fn refuse(field: &str, at: Option<usize>, value: impl std::fmt::Display, must: &str) -> String {
    match at {
        Some(i) => format!("`{field}` of entry {i} is {value}: {must}"),
        None => format!("`{field}` is {value}: {must}"),
    }
}

/// The first entry of `values` that is not `ok`, refused.
fn each<T: Copy + std::fmt::Debug>(
    field: &str,
    values: &[T],
    must: &str,
    ok: impl Fn(T) -> bool,
) -> Result<(), String> {
    match values.iter().position(|&v| !ok(v)) {
        Some(i) => Err(refuse(field, Some(i), format!("{:?}", values[i]), must)),
        None => Ok(()),
    }
}

fn finite<const N: usize>(v: [f64; N]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// The settings, as the scene's analysis checks them
/// ([`crate::model::analysis`]).
pub(super) fn params(p: &Params) -> Result<(), String> {
    let f = |name: &str, v: f64, ok: bool, must: &str| if ok { Ok(()) } else { Err(refuse(name, None, v, must)) };
    f(
        "params.tolerance",
        p.tolerance,
        p.tolerance > 0.0 && p.tolerance < 1.0,
        "must lie in (0, 1)",
    )?;
    if !(1..=1000).contains(&p.max_iterations) {
        return Err(refuse(
            "params.max_iterations",
            None,
            p.max_iterations,
            "must be between 1 and 1000",
        ));
    }
    if p.dense_limit > MAX_DENSE_LIMIT {
        return Err(refuse(
            "params.dense_limit",
            None,
            p.dense_limit,
            &format!("must be at most {MAX_DENSE_LIMIT}"),
        ));
    }
    let penalty = "must be zero (off) or positive and finite";
    f(
        "params.gamma_k",
        p.gamma_k,
        p.gamma_k >= 0.0 && p.gamma_k.is_finite(),
        penalty,
    )?;
    f(
        "params.gamma_m",
        p.gamma_m,
        p.gamma_m >= 0.0 && p.gamma_m.is_finite(),
        penalty,
    )?;
    f(
        "params.delta_over_h",
        p.delta_over_h,
        p.delta_over_h > 0.0 && p.delta_over_h <= 1.0,
        "must lie in (0, 1]",
    )
}

/// The state against the model it resumes: every number finite, volumes,
/// masses and domain sizes not negative, deformation gradients of
/// positive determinant, points inside the grid, grid fields per node.
pub(super) fn state(s: &State, model: &Model) -> Result<(), String> {
    let p = &s.points;
    let grid = &model.grid;
    // The configuration the steps solve on must lie on the grid: the
    // current one, or with `update_points = false` the starting one (the
    // moved points are then only drawn).
    let inside = |x: [f64; 2]| finite(x) && grid.cell_of(x).is_some();
    if model.analysis.update_points {
        each("points.x", &p.x, "must be finite and inside the grid", inside)?;
        each("points.x0", &p.x0, "must be finite", finite)?;
    } else {
        each("points.x", &p.x, "must be finite", finite)?;
        each("points.x0", &p.x0, "must be finite and inside the grid", inside)?;
    }
    let size = "must be zero or positive and finite";
    for (name, v) in [
        ("points.vol", &p.vol),
        ("points.vol0", &p.vol0),
        ("points.mass", &p.mass),
        ("points.dissipation", &p.dissipation),
    ] {
        each(name, v, size, |v: f64| v >= 0.0 && v.is_finite())?;
    }
    for (name, v) in [("points.lp", &p.lp), ("points.lp0", &p.lp0)] {
        each(name, v, size, |v: [f64; 2]| {
            v.iter().all(|x| *x >= 0.0 && x.is_finite())
        })?;
    }
    each("points.stress", &p.stress, "must be finite", finite)?;
    each("points.strain", &p.strain, "must be finite", finite)?;
    each("points.szz", &p.szz, "must be finite", |v: f64| v.is_finite())?;
    each("points.v", &p.v, "must be finite", finite)?;
    let det = |f: [f64; 4]| f[0] * f[3] - f[1] * f[2];
    let positive = "must be finite with a positive determinant";
    each("points.def_grad", &p.def_grad, positive, |f| finite(f) && det(f) > 0.0)?;
    each("points.b_e", &p.b_e, positive, |f| finite(f) && det(f) > 0.0)?;
    let scalars = [
        ("external_work", s.external_work),
        ("strain_energy", s.strain_energy),
        ("ghost_energy", s.ghost_energy),
        ("initial_energy", s.initial_energy),
    ];
    for (name, v) in scalars {
        if !v.is_finite() {
            return Err(refuse(name, None, v, "must be finite"));
        }
    }
    let nodes = grid.num_nodes();
    for (name, v) in [
        ("ghost_force", &s.ghost_force),
        ("constraint_force", &s.constraint_force),
        ("grid_acceleration", &s.grid_acceleration),
    ] {
        if !(v.is_empty() || v.len() == nodes) {
            return Err(refuse(
                name,
                None,
                format!("{} entries", v.len()),
                &format!("must hold none or one per grid node ({nodes})"),
            ));
        }
        each(name, v, "must be finite", finite)?;
    }
    each("ibm_offsets", &s.ibm_offsets, "must be finite", finite)?;
    each("ghost_faces", &s.ghost_faces, "must be finite", |(a, b)| {
        finite(a) && finite(b)
    })?;
    Ok(())
}
