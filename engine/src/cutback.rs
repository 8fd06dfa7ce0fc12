//! Cutbacks: a step whose increment fails in a way a smaller increment may
//! avoid is retried from its start in smaller increments, and reports as
//! the one step the user asked for.
//!
//! One layer serves both drivers that cut back, generic over what is cut:
//! the load factor interval `lambda_n -> lambda_{n+1}` of a
//! finite-deformation load step (`newton.rs`, [`Policy::load_step`]) and
//! the time interval `t_n -> t_n + dt` of an explicit step (`dynamics.rs`,
//! [`Policy::time_step`]). The driver supplies one attempt over a
//! [`Span`]; the layer decides which failures are retried, halves, grows
//! back, enforces `analysis.max_cutbacks` halvings in a row, records every
//! [`Cutback`], merges the sub-steps' reports into the step's, restores the
//! state at the step's start when the step still fails, and turns a panic
//! into [`StepFailure::Internal`]. Where the two drivers want different
//! things the [`Policy`] says which, and its constructors why.

use crate::report::{Cutback, StepFailure, StepReport, Timings};
use crate::state::Simulation;

/// One attempt's interval: `from -> to` (load factor, or time in s) of
/// size `size` (the time step of an explicit sub-step: exactly the step's
/// `dt / 2^k`, where `to - from` may round), whether it starts the step
/// (`first`: no attempt has passed before it) and ends it (`last`), and the
/// halvings in a row that led to it (`depth`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Span {
    pub(crate) from: f64,
    pub(crate) to: f64,
    pub(crate) size: f64,
    pub(crate) first: bool,
    pub(crate) last: bool,
    depth: usize,
}

impl Span {
    /// The whole step `from -> to`, of size `size`.
    pub(crate) fn whole(from: f64, to: f64, size: f64) -> Span {
        Span {
            from,
            to,
            size,
            first: true,
            last: true,
            depth: 0,
        }
    }
}

/// How a driver cuts its steps back.
pub(crate) struct Policy {
    /// Failures a smaller increment may avoid.
    retries: fn(&StepFailure) -> bool,
    /// Halvings allowed in a row (`analysis.max_cutbacks`; 0: none, the
    /// papers' fixed increments).
    max_cutbacks: usize,
    schedule: Schedule,
    /// Poll the observer's stop flag before every attempt.
    poll_cancel: bool,
    merge: Merge,
}

/// How the increments after a cutback are chosen.
#[derive(Clone, Copy, Debug)]
enum Schedule {
    /// A failed interval is replaced by its two halves, each attempted in
    /// turn and halved again when it fails: the sub-steps are the leaves of
    /// a binary tree over the step, of sizes `size / 2^k` (exact), and a
    /// second half starts at its parent's `from + size / 2`, so they tile
    /// the step and it ends where it would without cutbacks.
    Bisect,
    /// A walk from the step's start: a failed increment is halved and
    /// retried from the same start; after one that passed within half of
    /// `max_iterations` Newton iterations the next doubles (undoing a
    /// halving), and the increment that reaches the step's end (to 1e-12
    /// of the step) lands exactly on it.
    Regrow { max_iterations: usize },
}

/// How the sub-steps' reports become the step's.
#[derive(Clone, Copy, Debug)]
enum Merge {
    /// [`crate::report::SolverReport`]: the last increment's report with
    /// the Newton iterations and timings summed over the increments.
    Load,
    /// [`crate::report::DynamicsReport`]: see [`Merged::time_step`]; a
    /// failure's message names the cutbacks tried ([`Merged::annotate`]).
    Time,
}

impl Policy {
    /// The finite-deformation load step (`newton.rs`). Retried:
    /// [`StepFailure::NotConverged`], `NonFinite`, `Singular` and
    /// `LeftGrid`: each may come from an increment too large for Newton's
    /// region of convergence (a singular tangent or points pushed past the
    /// grid along a diverging iteration, too). The increments grow back
    /// ([`Schedule::Regrow`]): a load path's hard stretch is often short,
    /// and Newton's iteration count says when the increments may grow
    /// again. No stop flag is polled between increments: each Newton
    /// iteration reports to the progress hook, which may cancel. A failure
    /// is the last increment's, as it is.
    pub(crate) fn load_step(sim: &Simulation) -> Policy {
        Policy {
            retries: |e| {
                matches!(
                    e,
                    StepFailure::NotConverged { .. }
                        | StepFailure::NonFinite { .. }
                        | StepFailure::Singular { .. }
                        | StepFailure::LeftGrid { .. }
                )
            },
            max_cutbacks: sim.model.analysis.max_cutbacks,
            schedule: Schedule::Regrow {
                max_iterations: sim.params.max_iterations,
            },
            poll_cancel: false,
            merge: Merge::Load,
        }
    }

    /// The explicit time step (`dynamics.rs`). Retried:
    ///
    /// - [`StepFailure::Diverged`]: each of its guards measures what the
    ///   time step drives: a point moving more than a cell (its increment
    ///   is `dt |v|`), a deformation increment `|dF - I| > 1/2` (`dt |grad
    ///   v|`), and kinetic plus strain energy beyond `blowup_factor` times
    ///   what the loads supplied (past the critical time step, G 3.5, the
    ///   central difference scheme amplifies every step's error);
    /// - [`StepFailure::NonFinite`]: the overflow that same instability
    ///   ends in.
    ///
    /// Not retried, as a smaller step meets them again: `LeftGrid` (a
    /// point that moves less than a cell, the guard above, and leaves the
    /// grid follows its trajectory out: the sub-steps end at the same time,
    /// past the edge, after `2^max_cutbacks` futile sub-steps); `Singular`,
    /// `Boundary` and `OutOfMemory` (the mass matrix, the splines and the
    /// factor are those of the points at the step's start, whatever `dt`);
    /// `Cancelled` (the observer asked to stop) and `Internal` (a bug).
    ///
    /// The sub-steps bisect the step ([`Schedule::Bisect`]): their sizes
    /// `dt / 2^k` add up to `dt` exactly, so the step ends at `t_n = n dt`
    /// as without cutbacks, and the next step starts at `dt` again. An
    /// explicit sub-step polls no stop flag of its own, so the layer polls
    /// it before each: a step cut back `k` deep may take `2^k` of them.
    pub(crate) fn time_step(sim: &Simulation) -> Policy {
        Policy {
            retries: |e| matches!(e, StepFailure::Diverged { .. } | StepFailure::NonFinite { .. }),
            max_cutbacks: sim.model.analysis.max_cutbacks,
            schedule: Schedule::Bisect,
            poll_cancel: true,
            merge: Merge::Time,
        }
    }
}

impl Policy {
    /// The implicit dynamic time step (`newmark.rs`): Newton's failures
    /// are retried as in [`Policy::load_step`] (a time step too long for
    /// Newton's region of convergence, e.g. at an impact), and the
    /// increments grow back after easy ones ([`Schedule::Regrow`]): the
    /// time step adapts to Newton's iteration count within each step and
    /// the step ends at `n dt`, where the user asked for output.
    pub(crate) fn implicit_time_step(sim: &Simulation) -> Policy {
        Policy {
            merge: Merge::Load,
            ..Policy::load_step(sim)
        }
    }
}

/// Step `whole` with `attempt`: the whole interval at once, or, when that
/// fails with a failure `policy` retries and `max_cutbacks > 0`, cut back
/// ([`cut_back`]). `attempt` runs one increment over a [`Span`] from the
/// current state and commits it only when it passes (a failed attempt
/// leaves the state as it found it), with the step's number on the `last`.
pub(crate) fn step(
    sim: &mut Simulation,
    policy: &Policy,
    whole: Span,
    mut attempt: impl FnMut(&mut Simulation, Span) -> Result<StepReport, StepFailure>,
) -> Result<StepReport, StepFailure> {
    match attempt(sim, whole) {
        Err(e) if policy.max_cutbacks > 0 && (policy.retries)(&e) => cut_back(sim, policy, whole, e, attempt),
        other => other,
    }
}

/// Cut the step `whole` back after its `failure`: retry it from its start
/// in the increments of `policy`'s schedule, each failing one halved again
/// while fewer than `max_cutbacks` halvings in a row led to it. The step's
/// report covers the whole step, with every cutback in it (the whole
/// step's first). When the halvings run out, or an attempt fails otherwise
/// (or panics, or the observer cancels between attempts), the step fails
/// with that failure and the state returns to the step's start bit for
/// bit.
fn cut_back(
    sim: &mut Simulation,
    policy: &Policy,
    whole: Span,
    failure: StepFailure,
    mut attempt: impl FnMut(&mut Simulation, Span) -> Result<StepReport, StepFailure>,
) -> Result<StepReport, StepFailure> {
    let step = sim.state.step + 1;
    let start = sim.snapshot();
    let mut merged = Merged::new(whole, failure);
    let mut pending = Pending::new(policy.schedule, whole);
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| loop {
        let span = pending.next();
        if policy.poll_cancel && sim.cancelled() {
            return Err(StepFailure::Cancelled {
                step,
                residuals: Vec::new(),
            });
        }
        match attempt(sim, span) {
            Ok(r) => {
                let done = pending.passed(span, &r);
                merged.add(r);
                if done {
                    return Ok(());
                }
            }
            Err(e) if (policy.retries)(&e) && span.depth < policy.max_cutbacks => {
                merged.cutbacks.push(Cutback {
                    from: span.from,
                    to: span.to,
                    reason: e.to_string(),
                });
                pending.split(span);
            }
            Err(e) => return Err(e),
        }
    }));
    let outcome = outcome.unwrap_or_else(|e| {
        Err(StepFailure::Internal {
            step,
            message: crate::report::panic_message(e.as_ref()),
        })
    });
    match (outcome, policy.merge) {
        (Ok(()), Merge::Load) => Ok(merged.load_step()),
        (Ok(()), Merge::Time) => Ok(merged.time_step()),
        (Err(e), merge) => {
            sim.restore(&start);
            Err(match merge {
                Merge::Load => e,
                Merge::Time => merged.annotate(e, policy.max_cutbacks),
            })
        }
    }
}

/// The attempts still to make, by [`Schedule`].
enum Pending {
    /// The intervals still to attempt, the next on top.
    Bisect(Vec<Span>),
    /// The step, where the next increment starts, its size, the halvings
    /// in a row behind it, and whether one has passed.
    Regrow {
        whole: Span,
        max_iterations: usize,
        at: f64,
        size: f64,
        depth: usize,
        passed: bool,
    },
}

impl Pending {
    /// After the whole step failed: its two halves.
    fn new(schedule: Schedule, whole: Span) -> Pending {
        match schedule {
            Schedule::Bisect => {
                let mut stack = Vec::new();
                push_halves(&mut stack, whole);
                Pending::Bisect(stack)
            }
            Schedule::Regrow { max_iterations } => Pending::Regrow {
                whole,
                max_iterations,
                at: whole.from,
                size: 0.5 * (whole.to - whole.from),
                depth: 1,
                passed: false,
            },
        }
    }

    /// The next increment to attempt.
    fn next(&mut self) -> Span {
        match self {
            Pending::Bisect(stack) => stack.pop().expect("a step cut back ends with its last half"),
            Pending::Regrow {
                whole,
                at,
                size,
                depth,
                passed,
                ..
            } => {
                let (lambda0, lambda1) = (whole.from, whole.to);
                // The last increment lands exactly on lambda1.
                let last = *at + *size >= lambda1 - 1e-12 * (lambda1 - lambda0);
                let to = if last { lambda1 } else { *at + *size };
                Span {
                    from: *at,
                    to,
                    size: *size,
                    first: !*passed,
                    last,
                    depth: *depth,
                }
            }
        }
    }

    /// `span` passed with report `r`: whether the step is complete.
    fn passed(&mut self, span: Span, r: &StepReport) -> bool {
        match self {
            Pending::Bisect(stack) => stack.is_empty(),
            Pending::Regrow {
                max_iterations,
                at,
                size,
                depth,
                passed,
                ..
            } => {
                *passed = true;
                if span.last {
                    return true;
                }
                *at = span.to;
                if r.iterations * 2 <= *max_iterations && *depth > 0 {
                    *size *= 2.0;
                    *depth -= 1;
                }
                false
            }
        }
    }

    /// `span` failed and is cut back: halve it.
    fn split(&mut self, span: Span) {
        match self {
            Pending::Bisect(stack) => push_halves(stack, span),
            Pending::Regrow { size, depth, .. } => {
                *size *= 0.5;
                *depth += 1;
            }
        }
    }
}

/// The halves of `span` onto `stack`, the first on top: `from -> from +
/// size/2` and `from + size/2 -> (from + size/2) + size/2`, one halving
/// deeper.
fn push_halves(stack: &mut Vec<Span>, span: Span) {
    let half = 0.5 * span.size;
    let mid = span.from + half;
    let depth = span.depth + 1;
    stack.push(Span {
        from: mid,
        to: mid + half,
        size: half,
        first: false,
        last: span.last,
        depth,
    });
    stack.push(Span {
        from: span.from,
        to: span.from + half,
        size: half,
        first: span.first,
        last: false,
        depth,
    });
}

/// The sub-steps of a step cut back, merged into the step's report.
struct Merged {
    /// The whole step's size (the time step `dt`, or the load increment).
    size: f64,
    /// Every failed attempt, in order.
    cutbacks: Vec<Cutback>,
    /// The first and the last sub-step's reports.
    first: Option<StepReport>,
    last: Option<StepReport>,
    substeps: usize,
    /// Newton iterations and timings summed over the sub-steps.
    iterations: usize,
    timings: Timings,
    /// Explicit: the largest grid speed over the sub-steps (m/s), and
    /// whether every sub-step reused the mass pattern.
    max_speed: f64,
    pattern_reused: bool,
    /// The first sub-step Newton stopped at the round-off floor.
    attainable: Option<crate::report::Attainable>,
}

impl Merged {
    /// Before any sub-step: the whole step failed with `failure`.
    fn new(whole: Span, failure: StepFailure) -> Merged {
        Merged {
            size: whole.size,
            cutbacks: vec![Cutback {
                from: whole.from,
                to: whole.to,
                reason: failure.to_string(),
            }],
            first: None,
            last: None,
            substeps: 0,
            iterations: 0,
            timings: Timings::default(),
            max_speed: 0.0,
            pattern_reused: false,
            attainable: None,
        }
    }

    fn add(&mut self, r: StepReport) {
        self.timings.add(&r.timings);
        self.iterations += r.iterations;
        if let Some(d) = r.dynamics.as_ref() {
            self.max_speed = self.max_speed.max(d.max_speed);
            self.pattern_reused = d.pattern_reused && (self.substeps == 0 || self.pattern_reused);
        }
        self.substeps += 1;
        self.attainable = self.attainable.or(r.solver.as_ref().and_then(|s| s.attainable));
        if self.first.is_none() {
            self.first = Some(r);
        } else {
            self.last = Some(r);
        }
    }

    /// A load step's report: the last increment's (state, energies,
    /// condition numbers of its last tangent), with the Newton iterations
    /// and the timings summed, and the cutbacks and increments in its
    /// [`crate::report::SolverReport`].
    fn load_step(self) -> StepReport {
        let mut r = self.last.expect("a step cut back has at least two sub-steps");
        r.iterations = self.iterations;
        r.timings = self.timings;
        if let Some(d) = r.dynamics.as_mut() {
            d.cutbacks = self.cutbacks.clone();
            d.substeps = self.substeps;
        }
        if let Some(s) = r.solver.as_mut() {
            s.cutbacks = self.cutbacks;
            s.substeps = self.substeps;
            s.attainable = self.attainable;
        }
        r
    }

    /// An explicit step's report: the state at its end (energies, work and
    /// dissipation so far, momentum, errors, time `n dt`) from the last
    /// sub-step; the boundaries and conditioning of its start from the
    /// first; timings summed, the largest grid speed over all, the largest
    /// increment as that speed times `dt` (m), and the cutbacks and
    /// sub-steps in its [`crate::report::DynamicsReport`].
    fn time_step(self) -> StepReport {
        let first = self.first.expect("a step cut back has at least two sub-steps");
        let mut r = self.last.expect("a step cut back has at least two sub-steps");
        r.timings = self.timings;
        r.boundaries = first.boundaries;
        r.condition = first.condition;
        r.condition_unstabilised = first.condition_unstabilised;
        r.max_increment = self.max_speed * self.size;
        if let Some(d) = r.dynamics.as_mut() {
            d.conditioning = first.dynamics.and_then(|f| f.conditioning);
            d.max_speed = self.max_speed;
            d.pattern_reused = self.pattern_reused;
            d.cutbacks = self.cutbacks;
            d.substeps = self.substeps;
        }
        r
    }

    /// `failure`, which ended an explicit step cut back as recorded here,
    /// with its message naming the cutbacks tried (the variant is kept).
    fn annotate(&self, failure: StepFailure, max: usize) -> StepFailure {
        // Each cutback tries at least the first of its halves.
        let smallest = 0.5 * self.cutbacks.iter().map(|c| c.to - c.from).fold(self.size, f64::min);
        let note = format!(
            "; still failing after {} cutback(s) of the time step {:.3e} s (sub-steps down to {:.3e} s; analysis.max_cutbacks = {max}), the state is the step's start",
            self.cutbacks.len(),
            self.size,
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
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The regrowing schedule's increments tile the step: each starts
    /// where the last ended, the first on `lambda_0`, the last on
    /// `lambda_1` exactly, and none is a sliver, whether the halves sum to
    /// `lambda_1` exactly (0 -> 1) or a few ulps short of it (0.7 -> 0.9:
    /// 0.7 + 0.1 + 0.1 = 0.8999999999999999), with the increments grown
    /// back (an easy increment) or not.
    #[test]
    fn regrown_increments_tile_the_step() {
        for (from, to) in [(0.0, 1.0), (0.7, 0.9), (0.1, 0.4)] {
            for iterations in [1, 9] {
                let whole = Span::whole(from, to, to - from);
                let mut pending = Pending::new(Schedule::Regrow { max_iterations: 10 }, whole);
                let mut spans = Vec::new();
                loop {
                    let span = pending.next();
                    spans.push((span.from, span.to));
                    assert!(spans.len() < 10, "{spans:?}");
                    let mut r = StepReport::new(1, 1, span.to);
                    r.iterations = iterations;
                    if pending.passed(span, &r) {
                        break;
                    }
                }
                assert_eq!(spans[0].0, from, "{spans:?}");
                assert_eq!(spans[spans.len() - 1].1, to, "{spans:?}");
                assert!(spans.windows(2).all(|w| w[0].1 == w[1].0), "{spans:?}");
                // The first half is the smallest increment either way.
                assert!(spans.iter().all(|(a, b)| b - a > 0.49 * (to - from)), "{spans:?}");
            }
        }
    }
}
