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
//! A step that fails for want of a smaller time step (see
//! `can_cut_back`) is cut back (`cut_back`): retried from its start as
//! two sub-steps of `dt / 2`, each halved again when it fails, at most
//! `analysis.max_cutbacks` halvings deep; the next step starts again at
//! `dt`. `max_cutbacks = 0` keeps the papers' fixed time steps.

use crate::report::{Cutback, StepFailure, StepReport, Timings};
use crate::state::Simulation;
use explicit::Substep;

mod conditioning;
mod explicit;
mod guards;
mod mass;
pub(crate) mod transfer;

pub use crate::report::{Conditioning, DynamicsReport};
pub(crate) use conditioning::conditioning;
pub(crate) use mass::grid_velocities;

/// One explicit step of `dt = duration / load_steps` (s; see the module's
/// documentation): the whole step, or, when it fails with a failure a
/// smaller time step may avoid and `analysis.max_cutbacks > 0`, the step
/// cut back ([`cut_back`]).
pub(crate) fn explicit_step(sim: &mut Simulation) -> Result<StepReport, StepFailure> {
    let dt = explicit::step_dt(sim);
    let whole = Substep {
        dt,
        first: true,
        last: true,
    };
    match substep(sim, whole) {
        Err(e) if sim.model.analysis.max_cutbacks > 0 && can_cut_back(&e) => cut_back(sim, dt, e),
        other => other,
    }
}

/// Failures a smaller time step may avoid, which [`cut_back`] retries:
///
/// - [`StepFailure::Diverged`]: each of its guards measures what the time
///   step drives: a point moving more than a cell (its increment is
///   `dt |v|`), a deformation increment `|dF - I| > 1/2` (`dt |grad v|`),
///   and kinetic plus strain energy beyond `blowup_factor` times what the
///   loads supplied (past the critical time step, G 3.5, the central
///   difference scheme amplifies every step's error);
/// - [`StepFailure::NonFinite`]: the overflow that same instability ends in.
///
/// Not retried, as a smaller step meets them again: [`StepFailure::LeftGrid`]
/// (a point that moves less than a cell, the guard above, and leaves the
/// grid follows its trajectory out: the sub-steps end at the same time, past
/// the edge, after `2^max_cutbacks` futile sub-steps); `Singular`,
/// `Boundary` and `OutOfMemory` (the mass matrix, the splines and the factor
/// are those of the points at the step's start, whatever `dt`); `Cancelled`
/// (the observer asked to stop) and `Internal` (a bug).
fn can_cut_back(e: &StepFailure) -> bool {
    matches!(e, StepFailure::Diverged { .. } | StepFailure::NonFinite { .. })
}

/// One sub-step, with the buffers of [`transfer::Workspace`] reused from
/// the last.
fn substep(sim: &mut Simulation, s: Substep) -> Result<StepReport, StepFailure> {
    let mut ws = std::mem::take(&mut sim.explicit);
    let out = explicit::step_with(sim, &mut ws, s);
    sim.explicit = ws;
    out
}

/// Cut the step of `dt` (s) back after its `failure`: retry it from its
/// start (where a failed sub-step leaves the state: a sub-step commits only
/// after every guard has passed) as two sub-steps of `dt / 2`, each split
/// again when it fails ([`advance`]), at most `analysis.max_cutbacks`
/// halvings deep. The sub-step sizes are `dt / 2^k`, so they add up to
/// `dt` exactly and the step ends at `t_n = n dt`, as without cutbacks.
///
/// The step's report covers the whole step ([`Merged::report`]), with
/// every cutback in [`crate::report::DynamicsReport::cutbacks`]. When the
/// halvings run out (or a sub-step fails otherwise, or the observer
/// cancels between sub-steps), the step fails with the last failure, its
/// message naming the cutbacks tried, and the state returns to the step's
/// start bit for bit.
fn cut_back(sim: &mut Simulation, dt: f64, failure: StepFailure) -> Result<StepReport, StepFailure> {
    let step = sim.state.step + 1;
    let t0 = sim.state.step as f64 * dt;
    let start = sim.snapshot();
    let mut merged = Merged {
        dt,
        cutbacks: vec![Cutback {
            from: t0,
            to: step as f64 * dt,
            reason: failure.to_string(),
        }],
        ..Merged::default()
    };
    let half = 0.5 * dt;
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let (first, second) = (
            Substep {
                dt: half,
                first: true,
                last: false,
            },
            Substep {
                dt: half,
                first: false,
                last: true,
            },
        );
        advance(sim, &mut merged, first, t0, 1)?;
        advance(sim, &mut merged, second, t0 + half, 1)?;
        Ok(())
    }));
    let outcome = outcome.unwrap_or_else(|e| {
        Err(StepFailure::Internal {
            step,
            message: crate::report::panic_message(e.as_ref()),
        })
    });
    match outcome {
        Ok(()) => Ok(merged.report()),
        Err(e) => {
            sim.restore(&start);
            Err(after_cutbacks(e, &merged, sim.model.analysis.max_cutbacks))
        }
    }
}

/// Advance the state by `s.dt` (s) from time `t` (s): one sub-step, or,
/// when it fails with a failure a smaller time step may avoid and fewer
/// than `analysis.max_cutbacks` halvings led to it (`depth`), two halves,
/// each advanced the same way. The observer's stop flag is polled before
/// each sub-step: a step cut back `k` deep may take `2^k` of them, and
/// cancelling is never cut back.
fn advance(sim: &mut Simulation, merged: &mut Merged, s: Substep, t: f64, depth: usize) -> Result<(), StepFailure> {
    if sim.cancelled() {
        return Err(StepFailure::Cancelled {
            step: sim.state.step + 1,
            residuals: Vec::new(),
        });
    }
    match substep(sim, s) {
        Ok(r) => {
            merged.add(r);
            Ok(())
        }
        Err(e) if can_cut_back(&e) && depth < sim.model.analysis.max_cutbacks => {
            merged.cutbacks.push(Cutback {
                from: t,
                to: t + s.dt,
                reason: e.to_string(),
            });
            let half = 0.5 * s.dt;
            let (first, second) = (
                Substep {
                    dt: half,
                    first: s.first,
                    last: false,
                },
                Substep {
                    dt: half,
                    first: false,
                    last: s.last,
                },
            );
            advance(sim, merged, first, t, depth + 1)?;
            advance(sim, merged, second, t + half, depth + 1)
        }
        Err(e) => Err(e),
    }
}

/// `failure`, which ended a step cut back as `merged` records, with its
/// message naming the cutbacks tried (the variant is kept).
fn after_cutbacks(failure: StepFailure, merged: &Merged, max: usize) -> StepFailure {
    // Each cutback tries at least the first of its halves.
    let smallest = 0.5 * merged.cutbacks.iter().map(|c| c.to - c.from).fold(merged.dt, f64::min);
    let note = format!(
        "; still failing after {} cutback(s) of the time step {:.3e} s (sub-steps down to {:.3e} s; analysis.max_cutbacks = {max}), the state is the step's start",
        merged.cutbacks.len(),
        merged.dt,
        smallest
    );
    match failure {
        StepFailure::Diverged { step, reason } => StepFailure::Diverged {
            step,
            reason: reason + &note,
        },
        StepFailure::NonFinite { step, what, residuals } => StepFailure::NonFinite {
            step,
            what: what + &note,
            residuals,
        },
        StepFailure::Singular { step, reason } => StepFailure::Singular {
            step,
            reason: reason + &note,
        },
        other => other,
    }
}

/// The sub-steps of a step cut back, merged into the step's report.
#[derive(Default)]
struct Merged {
    /// The step's time step (s).
    dt: f64,
    /// Every failed attempt, in order.
    cutbacks: Vec<Cutback>,
    /// The first and the last sub-step's reports.
    first: Option<StepReport>,
    last: Option<StepReport>,
    substeps: usize,
    timings: Timings,
    /// Largest grid speed over the sub-steps (m/s).
    max_speed: f64,
    /// Whether every sub-step reused the mass pattern.
    pattern_reused: bool,
}

impl Merged {
    fn add(&mut self, r: StepReport) {
        self.timings.add(&r.timings);
        let d = r.dynamics.as_ref().expect("explicit steps report dynamics");
        let reused = d.pattern_reused;
        self.max_speed = self.max_speed.max(d.max_speed);
        self.pattern_reused = reused && (self.substeps == 0 || self.pattern_reused);
        self.substeps += 1;
        if self.first.is_none() {
            self.first = Some(r);
        } else {
            self.last = Some(r);
        }
    }

    /// The step's report: the state at its end (energies, work and
    /// dissipation so far, momentum, errors, time `n dt`) from the last
    /// sub-step; the boundaries and conditioning of its start from the
    /// first; timings summed, the largest grid speed over all, the largest
    /// increment as that speed times `dt` (m), and the cutbacks.
    fn report(self) -> StepReport {
        let first = self.first.expect("a step cut back has at least two sub-steps");
        let mut r = self.last.expect("a step cut back has at least two sub-steps");
        r.timings = self.timings;
        r.boundaries = first.boundaries;
        r.condition = first.condition;
        r.condition_unstabilised = first.condition_unstabilised;
        r.max_increment = self.max_speed * self.dt;
        if let Some(d) = r.dynamics.as_mut() {
            d.conditioning = first.dynamics.and_then(|f| f.conditioning);
            d.max_speed = self.max_speed;
            d.pattern_reused = self.pattern_reused;
            d.cutbacks = self.cutbacks;
            d.substeps = self.substeps;
        }
        r
    }
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
