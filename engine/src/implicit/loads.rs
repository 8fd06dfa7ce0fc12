//! Dead loads as a contribution of an implicit step: body forces (gravity
//! on each point's mass) and point loads, at the step's load factor,
//! fixed over its iterations ([`crate::state::Simulation::dead_forces`]).

use super::contribution::{At, Contribution};
use crate::report::StepFailure;

/// Body forces and point loads at the step's load factor (N per unit
/// thickness, free dofs).
pub(crate) struct DeadLoads {
    pub ext: Vec<f64>,
}

impl Contribution for DeadLoads {
    fn name(&self) -> &'static str {
        "dead loads"
    }

    fn external(&self, _at: &At, fext: &mut [f64]) -> Result<(), StepFailure> {
        for (f, e) in fext.iter_mut().zip(&self.ext) {
            *f += e;
        }
        Ok(())
    }
}
