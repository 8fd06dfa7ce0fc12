//! A step, dispatched by analysis kind to its driver, each a short
//! function that names the phases of a step:
//!
//! - [`crate::linear`]: quasi-static small strain (B, C): map, assemble,
//!   Cholesky, solve, update;
//! - [`crate::newton`]: quasi-static finite deformation (G 2.1): map,
//!   collect the contributions, Newton (residual, tangent, LU), commit;
//! - [`crate::dynamics`]: explicit dynamics (G 2.3): map, mass, momentum,
//!   forces, velocities, points.
//!
//! The two implicit drivers share one core (`crate::implicit`): every
//! method is a contribution to a step's residual and tangent, collected in
//! one list (material points, ghost penalty, implicit boundaries' band,
//! dead loads, tractions on B-spline boundaries), over one frame (the
//! mapping, the implicit boundaries' `d^a`, the ghost faces), committed
//! and reported by one function. The cutback layer
//! (`crate::cutback`) halves a failed load or time increment for every
//! driver. The data they read and commit is in [`crate::state`], what
//! they report in [`crate::report`].
//!
//! Failures are values ([`StepFailure`]) and leave the state at the last
//! good step.

pub use crate::report::{Energy, Progress, ProgressHook, StepFailure, StepReport, Timings};
pub use crate::state::{Params, Simulation, Snapshot};

impl Simulation {
    /// [`Simulation::step`], with a panic inside the engine turned into
    /// [`StepFailure::Internal`] so that observers (TUI, recordings) can
    /// report it and close cleanly. A step commits only at its end, so the
    /// state stays at the last good step.
    pub fn step_guarded(&mut self) -> Result<StepReport, StepFailure> {
        let step = self.state.step + 1;
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| self.step())) {
            Ok(r) => r,
            Err(e) => Err(StepFailure::Internal {
                step,
                message: crate::report::panic_message(e.as_ref()),
            }),
        }
    }

    /// Take one load step.
    pub fn step(&mut self) -> Result<StepReport, StepFailure> {
        if self.finished() {
            return Err(StepFailure::Finished {
                steps: self.load_steps(),
            });
        }
        // Whatever ran on this thread since the last step (a front end's
        // dense algebra) leaves the step's scalar arithmetic at full speed.
        crate::vector_state::after_wide_kernels();
        let mut report = match self.model.analysis.kind {
            crate::scene::AnalysisKind::QuasiStaticLinear => crate::linear::linear_step(self),
            crate::scene::AnalysisKind::QuasiStaticFinite => crate::newton::finite_step(self),
            crate::scene::AnalysisKind::ExplicitDynamics => crate::dynamics::explicit_step(self),
            crate::scene::AnalysisKind::DynamicImplicit => crate::newmark::dynamic_step(self),
        }?;
        report.probes = self.probe_values(Some(&report));
        Ok(report)
    }

    /// Largest relative difference between the assembled finite-deformation
    /// tangent (every contribution: points, ghost, implicit boundaries,
    /// traction load stiffness) and central finite differences of the
    /// residual, for the next step (see [`crate::newton`]).
    pub fn tangent_check(&self, amplitude: f64) -> Result<f64, StepFailure> {
        crate::newton::tangent_check(self, amplitude)
    }

    /// Mass conditioning and CFL numbers at the current configuration, on
    /// demand (any analysis): the consistent, stabilised (`gamma_M` of the
    /// parameters) and lumped masses, over the dofs the scene's supports
    /// leave free. Memory that cannot be allocated for its matrices is an
    /// error.
    pub fn conditioning(&self) -> Result<crate::report::Conditioning, crate::linalg::FactorError> {
        crate::dynamics::conditioning(self)
    }

    /// Grid velocities from mapping the point momenta with the stabilised
    /// (`gamma_M` of the parameters), consistent or lumped mass (G (10)),
    /// per active node (m/s); `Err` when the mass cannot be factorised.
    pub fn map_velocities(&self, kind: crate::scene::MassKind) -> Result<Vec<(usize, crate::geometry::P2)>, String> {
        crate::dynamics::grid_velocities(self, kind)
    }
}
