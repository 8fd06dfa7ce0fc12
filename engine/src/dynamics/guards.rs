//! The explicit step's guards: what fails a sub-step before anything is
//! committed. A point moving more than a cell, a deformation increment
//! `|dF - I| > 1/2` and kinetic plus strain energy beyond `blowup_factor`
//! times what entered the system all grow with the time step
//! ([`StepFailure::Diverged`], which a cutback retries); non-finite values
//! are [`StepFailure::NonFinite`]; points or GIMP domains leaving the grid
//! [`StepFailure::LeftGrid`].

use super::mass;
use super::transfer::{Committed, Moved};
use crate::points::Points;
use crate::report::StepFailure;
use crate::scene::MassKind;
use crate::state::Simulation;

pub(super) fn non_finite(step: usize, what: &str) -> StepFailure {
    StepFailure::NonFinite {
        step,
        what: what.into(),
        residuals: Vec::new(),
    }
}

/// The guards on the updated points `next` of step `step` (sub-step
/// `dt`, s; the mass `kind` in use), in order: finite velocities;
/// no point moving more than a cell and no deformation increment `|dF -
/// I|` beyond 1/2 in one step (both grow with `dt`: [`StepFailure::Diverged`]);
/// finite stresses and positions inside the grid
/// ([`crate::state::check_points`]); GIMP domains inside the grid.
pub(super) fn points(
    sim: &Simulation,
    next: &Points,
    moved: &Moved,
    committed: &Committed,
    (step, dt, kind): (usize, f64, MassKind),
    max_speed: f64,
) -> Result<(), StepFailure> {
    let h = sim.model.grid.h;
    let (fastest, strained) = (moved.fastest, committed.strained);
    if let Some(p) = moved.non_finite {
        return Err(non_finite(step, &format!("velocity at point {p}")));
    }
    if fastest.0 > h {
        return Err(StepFailure::Diverged {
            step,
            reason: format!(
                "point {} would move {:.3e} m in one step, more than a cell (h = {h}, dt = {dt:.3e} s, largest grid speed {max_speed:.3e} m/s): the time step is too large or the {} mass is ill-conditioned",
                fastest.1,
                fastest.0,
                mass::name(kind)
            ),
        });
    }
    // Explicit steps are small: a point whose deformation gradient
    // changes by more than half in one step (or to a non-finite value)
    // has diverged.
    if !(strained.0 <= 0.5) {
        return Err(StepFailure::Diverged {
            step,
            reason: format!(
                "point {} would deform by |dF - I| = {:.3e} in one step (dt = {dt:.3e} s, largest grid speed {max_speed:.3e} m/s): the time step is too large or the {} mass is ill-conditioned",
                strained.1,
                strained.0,
                mass::name(kind)
            ),
        });
    }
    crate::state::check_points(&sim.model.grid, next, step, &[])?;
    gimp_domains_inside(sim, next, step)
}

/// A GIMP domain reaching past the grid's edge loses nodes of its basis,
/// and with them partition of unity and momentum conservation: the first
/// point of `pts` (the step's updated points) whose domain does is the
/// step's failure.
fn gimp_domains_inside(sim: &Simulation, pts: &Points, step: usize) -> Result<(), StepFailure> {
    let grid = &sim.model.grid;
    let (lo, hi) = (grid.origin, grid.max());
    let tol = 1e-9 * grid.h;
    let body = &sim.state.points.body;
    for p in 0..pts.len() {
        if sim.model.bodies[body[p]].basis != crate::basis::BasisKind::Gimp {
            continue;
        }
        let (x, l) = (pts.x[p], pts.lp[p]);
        let corner = [0, 1].map(|d| {
            if x[d] - l[d] < lo[d] - tol {
                x[d] - l[d]
            } else if x[d] + l[d] > hi[d] + tol {
                x[d] + l[d]
            } else {
                x[d]
            }
        });
        if corner != x {
            return Err(StepFailure::LeftGrid {
                step,
                point: p,
                position: corner,
                domain: true,
            });
        }
    }
    Ok(())
}

/// The energy guard of step `step`: kinetic plus strain energy `ku` past
/// `factor` times what entered the system ([`energy_limit_exceeded`]) has
/// diverged (the central difference scheme past its critical time step,
/// G 3.5, amplifies every step's error).
pub(super) fn energy(
    step: usize,
    ku: f64,
    (w0, work, dissipation): (f64, f64, f64),
    factor: f64,
    kind: MassKind,
) -> Result<(), StepFailure> {
    match energy_limit_exceeded(ku, w0, work, dissipation, factor) {
        None => Ok(()),
        Some(limit) => Err(StepFailure::Diverged {
            step,
            reason: format!(
                "kinetic + strain energy {:.6e} J exceeds {} x (initial energy + work + dissipation) = {:.6e} J with the {} mass",
                ku,
                factor,
                limit,
                mass::name(kind)
            ),
        }),
    }
}

/// The explicit step's energy guard: the limit `factor (W0 + |W| + D)`
/// (initial energy, the loads' work, plastic dissipation; J per unit
/// thickness) when kinetic plus strain energy `ku` exceeds it, `None`
/// otherwise or when nothing has entered the system yet. A balanced run
/// has `ku = W0 + W - D`, below the limit for any `factor >= 1`.
fn energy_limit_exceeded(ku: f64, w0: f64, work: f64, dissipation: f64, factor: f64) -> Option<f64> {
    let scale = w0 + work.abs() + dissipation;
    (scale > 0.0 && ku > factor * scale).then_some(factor * scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The energy guard counts dissipation on the side of what entered:
    /// a plastic run that has dissipated `D` may hold `ku` up to
    /// `factor (W0 + |W| + D)`. With W0 = 2, W = -1 (the loads took 1 J
    /// out), D = 1 and factor 10 the limit is 40 J: 39 passes, 41 does not,
    /// and 40 itself passes (the guard trips beyond the limit; all these
    /// numbers are exact in binary). A run with nothing in it
    /// (W0 = W = D = 0) is never stopped.
    #[test]
    fn energy_guard_limit_is_factor_times_initial_energy_work_and_dissipation() {
        assert_eq!(energy_limit_exceeded(39.0, 2.0, -1.0, 1.0, 10.0), None);
        assert_eq!(energy_limit_exceeded(40.0, 2.0, -1.0, 1.0, 10.0), None);
        assert_eq!(energy_limit_exceeded(41.0, 2.0, -1.0, 1.0, 10.0), Some(40.0));
        assert_eq!(energy_limit_exceeded(1.0, 0.0, 0.0, 0.0, 10.0), None);
    }
}
