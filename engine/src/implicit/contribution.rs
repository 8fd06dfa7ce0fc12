//! What a method adds to an implicit step: the [`Contribution`] interface.
//!
//! An implicit step (small strain or Newton) solves `K dd = r` with
//!
//! ```text
//! r(d) = f_ext(d) - sum_c f_c(d)          (free dofs)
//! K(d) = -dr/dd = sum_c K_c(d)            (over the step's pattern)
//! ```
//!
//! where each contribution `c` is one method: the material points (their
//! internal force and tangent), the ghost penalty (G (27)), an implicit
//! boundary's band (C (18)-(27)), the dead loads (body forces, point
//! loads) and each B-spline boundary's traction (with its load stiffness
//! when it follows the surface). The core ([`super`]) holds them in one
//! list; the list's order is the order of the blocks in the pattern, of
//! the loads in `f_ext` and of the forces subtracted from `r`, so it
//! decides the round-off and nothing else.
//!
//! A contribution reads the step's [`Frame`] (mapping, implicit-boundary
//! data, ghost faces) and an iterate [`At`]; it writes only into the
//! vectors and blocks it is handed.

use super::frame::Frame;
use crate::bulk::Iterate;
use crate::geometry::P2;
use crate::report::StepFailure;

/// One iterate of an implicit step, as the contributions see it.
pub(crate) struct At<'a, 's> {
    pub frame: &'a Frame<'s>,
    /// The nodal unknowns `d` (m; grid-prescribed components included),
    /// per grid node.
    pub d: &'a [P2],
    /// The nodes' whole motion `d + d^a` (m), per grid node.
    pub motion: &'a [P2],
    /// The material points' response at `motion` (finite deformation;
    /// `None` in a small-strain step, whose response is linear).
    pub points: Option<&'a Iterate>,
    /// `false` to leave out the stabilisation terms (the ghost penalty):
    /// the tangent without them, for its condition number.
    pub stabilised: bool,
}

/// A method's part of an implicit step (see the module's documentation).
/// Every method has defaults for what it does not add.
pub(crate) trait Contribution: Sync {
    /// What it is, for reports and diagnostics (`points`, `ghost`,
    /// `band`, `dead loads`, `traction`).
    fn name(&self) -> &'static str;

    /// The node lists of its stiffness blocks, in order: the pattern holds
    /// every free-free entry of each.
    fn blocks<'a>(&'a self, _frame: &'a Frame) -> Vec<&'a [usize]> {
        Vec::new()
    }

    /// Whether its tangent is symmetric (the step's factorisation is
    /// Cholesky or `L D L^T` only if every contribution's is).
    fn symmetric(&self, _frame: &Frame) -> bool {
        true
    }

    /// Add its external force at `at` to `fext` (N per unit thickness,
    /// free dofs).
    fn external(&self, _at: &At, _fext: &mut [f64]) -> Result<(), StepFailure> {
        Ok(())
    }

    /// Subtract its force at `at` from the residual `r` (free dofs);
    /// return the size of the reaction it carries (N), which the residual
    /// is measured against.
    fn internal(&self, _at: &At, _r: &mut [f64]) -> f64 {
        0.0
    }

    /// Small-strain steps: add its force at `d = 0` from the implicit
    /// boundaries' prescribed motion `d^a` to `f_d` (N, per grid node),
    /// which the step's right-hand side subtracts.
    fn prescribed(&self, _frame: &Frame, _f_d: &mut [P2]) {}

    /// Block `k`'s values at `at`, row-major `2m x 2m` over the block's
    /// `m` nodes `[x0, y0, x1, y1, ...]`, into `out` (resized here).
    fn block(&self, _k: usize, _at: &At, _out: &mut Vec<f64>) -> Result<(), StepFailure> {
        Ok(())
    }

    /// Add block `k`'s values at `at` to `out` (row-major `2m x 2m`, as
    /// [`Contribution::block`] gives them), entry by entry: the way the
    /// core sums the contributions that share a block's node list. The
    /// default forms the block in `scratch` and adds it; a contribution
    /// whose block is sparse adds its nonzero entries alone (the sum is
    /// the same to the bit: the others would add zeros).
    fn add_block(&self, k: usize, at: &At, out: &mut [f64], scratch: &mut Vec<f64>) -> Result<(), StepFailure> {
        add_formed(self, k, at, out, scratch)
    }
}

/// [`Contribution::add_block`] by forming the block in `scratch` and
/// adding it entry by entry; a block of another size than `out` is a
/// failure naming the contribution.
pub(crate) fn add_formed<C: Contribution + ?Sized>(
    c: &C,
    k: usize,
    at: &At,
    out: &mut [f64],
    scratch: &mut Vec<f64>,
) -> Result<(), StepFailure> {
    c.block(k, at, scratch)?;
    if scratch.len() != out.len() {
        return Err(StepFailure::Internal {
            step: at.frame.step,
            message: format!(
                "the {} contribution's block {k} has {} values where {} were expected",
                c.name(),
                scratch.len(),
                out.len()
            ),
        });
    }
    for (o, v) in out.iter_mut().zip(scratch.iter()) {
        *o += v;
    }
    Ok(())
}
