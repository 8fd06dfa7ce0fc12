//! One runner for every front end (the CLI's `run`, the TUI's engine
//! thread, sweeps): a step with panics caught, its outcome handed to the
//! observers, and the loop to the end with cancellation.
//!
//! Observers only read: the table printer, the recorder
//! (the `mpmlab` crate's recorder implements [`Observer`]) and the TUI's
//! update channel. An observer that can no longer follow (a full disk
//! under the recorder) says why and detaches itself; the run goes on.

use crate::simulation::{Simulation, StepFailure, StepReport};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Something that follows a run step by step.
pub trait Observer {
    /// A step completed; `Some(message)` when the observer stops following.
    fn stepped(&mut self, _sim: &Simulation, _report: &StepReport) -> Option<String> {
        None
    }
    /// A step failed (the state is the last good step).
    fn failed(&mut self, _sim: &Simulation, _failure: &StepFailure) -> Option<String> {
        None
    }
    /// Something worth a line in the log (a parameter change, a stop).
    fn note(&mut self, _text: &str, _level: &str) -> Option<String> {
        None
    }
}

impl<T: Observer> Observer for Option<T> {
    fn stepped(&mut self, sim: &Simulation, report: &StepReport) -> Option<String> {
        let m = self.as_mut()?.stepped(sim, report);
        if m.is_some() {
            *self = None;
        }
        m
    }
    fn failed(&mut self, sim: &Simulation, failure: &StepFailure) -> Option<String> {
        let m = self.as_mut()?.failed(sim, failure);
        if m.is_some() {
            *self = None;
        }
        m
    }
    fn note(&mut self, text: &str, level: &str) -> Option<String> {
        let m = self.as_mut()?.note(text, level);
        if m.is_some() {
            *self = None;
        }
        m
    }
}

/// One step and what the observers said about it.
pub struct Stepped {
    pub result: Result<StepReport, StepFailure>,
    /// Observers that stopped following, with their reasons.
    pub detached: Vec<String>,
}

/// Take one step ([`Simulation::step_guarded`]) and hand its outcome to
/// every observer.
pub fn step(sim: &mut Simulation, observers: &mut [&mut dyn Observer]) -> Stepped {
    let result = sim.step_guarded();
    let detached = observers
        .iter_mut()
        .filter_map(|o| match &result {
            Ok(r) => o.stepped(sim, r),
            Err(f) => o.failed(sim, f),
        })
        .collect();
    Stepped { result, detached }
}

/// Tell every observer; the messages of those that stopped following.
pub fn note(observers: &mut [&mut dyn Observer], text: &str, level: &str) -> Vec<String> {
    observers.iter_mut().filter_map(|o| o.note(text, level)).collect()
}

/// How a run ended.
#[derive(Debug)]
pub enum RunEnd {
    /// Every load step is done.
    Finished,
    /// A step failed; the state is the last good step.
    Failed(StepFailure),
    /// `stop` was set: between steps, or during one (the step is cancelled
    /// and the state is that of `after` steps).
    Stopped { after: usize },
    /// An observer could not write its output (its reason is among the
    /// detached ones) after `after` steps.
    OutputFailed { after: usize },
}

/// Step to the end, the first failure, or until `stop` is set. `stop` also
/// cancels a running step (through the progress hook, which every long
/// phase polls), so a signal ends a long step too. `detached` gets the
/// reasons of observers that stopped following.
pub fn run(
    sim: &mut Simulation,
    observers: &mut [&mut dyn Observer],
    stop: &Arc<AtomicBool>,
    detached: &mut Vec<String>,
) -> RunEnd {
    {
        let stop = stop.clone();
        sim.set_progress(Some(Box::new(move |_| !stop.load(Ordering::SeqCst))));
    }
    sim.set_cancel(Some(stop.clone()));
    let end = loop {
        if sim.finished() {
            break RunEnd::Finished;
        }
        if stop.load(Ordering::SeqCst) {
            break RunEnd::Stopped {
                after: sim.step_index(),
            };
        }
        let s = step(sim, observers);
        let lost = !s.detached.is_empty();
        detached.extend(s.detached);
        if lost {
            // An output that cannot be written (a full disk, a quota, a
            // vanished folder) ends the run after the step: what was
            // written stays readable, nothing is silently left out.
            break RunEnd::OutputFailed {
                after: sim.step_index(),
            };
        }
        match s.result {
            Ok(_) => {}
            Err(StepFailure::Cancelled { .. }) if stop.load(Ordering::SeqCst) => {
                break RunEnd::Stopped {
                    after: sim.step_index(),
                }
            }
            Err(f) => break RunEnd::Failed(f),
        }
    };
    sim.set_progress(None);
    sim.set_cancel(None);
    end
}
