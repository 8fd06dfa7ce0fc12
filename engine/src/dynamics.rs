//! Explicit dynamics (G 2.3, 3.3): one time step at a time.
//!
//! Per step, on the configuration at its start (the grid is reset): map the
//! points, assemble the mass (lumped, consistent or stabilised, G (9),
//! (20)), map the momentum to grid velocities (G (10)), stresses (USF) and
//! forces, `M a = f_ext - f_int`, move the points (FLIP or PIC), stresses
//! (USL, MUSL), guards, energies, commit. One module per concept:
//!
//! - [`explicit`]: the step as its named phases, in order;
//! - [`guards`]: what fails a sub-step before it commits;
//! - [`mass`]: the mass matrices, their factorisation, grid velocities;
//! - [`conditioning`]: mass condition numbers and CFL numbers;
//! - [`transfer`]: the reused buffers and the point-grid passes.
//!
//! A step that fails for want of a smaller time step is cut back
//! ([`crate::cutback`], [`crate::cutback::Policy::time_step`]): retried
//! from its start as two sub-steps of `dt / 2`, each halved again when it
//! fails, at most `analysis.max_cutbacks` halvings deep; the next step
//! starts again at `dt`. `max_cutbacks = 0` keeps the papers' fixed time
//! steps.

use crate::cutback::{self, Policy, Span};
use crate::report::{StepFailure, StepReport};
use crate::state::Simulation;
use explicit::Substep;

mod conditioning;
mod explicit;
mod guards;
mod mass;
pub(crate) mod transfer;

pub use crate::report::{Conditioning, DynamicsReport};
pub(crate) use conditioning::conditioning;
pub(crate) use mass::{grid_velocities, GridMass};

/// One explicit step of `dt = duration / load_steps` (s): the whole step,
/// or, when it fails with a failure a smaller time step may avoid and
/// `analysis.max_cutbacks > 0`, the step cut back.
pub(crate) fn explicit_step(sim: &mut Simulation) -> Result<StepReport, StepFailure> {
    let dt = explicit::step_dt(sim);
    let step = sim.state.step + 1;
    let whole = Span::whole(sim.state.step as f64 * dt, step as f64 * dt, dt);
    let policy = Policy::time_step(sim);
    cutback::step(sim, &policy, whole, |sim, s| {
        substep(
            sim,
            Substep {
                dt: s.size,
                first: s.first,
                last: s.last,
            },
        )
    })
}

/// One sub-step, with the buffers of [`transfer::Workspace`] reused from
/// the last.
fn substep(sim: &mut Simulation, s: Substep) -> Result<StepReport, StepFailure> {
    let mut ws = std::mem::take(&mut sim.explicit);
    let out = explicit::step_with(sim, &mut ws, s);
    sim.explicit = ws;
    out
}

/// The masses' conditioning and CFL numbers (G 3.5) of the points where
/// they are, for implicit dynamics' report: the explicit step's limit the
/// implicit one is not bound by.
pub(crate) fn mass_conditioning(sim: &Simulation) -> Result<Conditioning, crate::linalg::FactorError> {
    let (model, grid) = (&sim.model, &sim.model.grid);
    let map = crate::assembly::Mapping::build(grid, &sim.state.points, &model.bodies, &model.dirichlet, 0.0)?;
    let faces = crate::ghost::faces_of(grid, &map, model.analysis.ghost_cells);
    conditioning::conditioning_on(sim, &map, &faces)
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
