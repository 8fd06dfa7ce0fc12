//! The material points as a contribution: under small strain (B section 2,
//! C section 2) the linear response's stiffness per point group,
//! `K = sum_p B_p^T D B_p V_p`, with `B_bar` (C (18)) for the points inside
//! an implicit boundary's band and the B-bar patches' operator
//! ([`super::bbar`]) with `fbar` (its forces are the small-strain step's
//! right-hand side, [`crate::linear`]); under finite deformation (G 2.1)
//! their internal force and tangent ([`crate::bulk`]).

use super::contribution::{At, Contribution};
use super::frame::Frame;
use crate::bulk::group_tangent;
use crate::geometry::P2;
use crate::ibm;
use crate::report::StepFailure;

/// The points' linear-elastic stiffness blocks.
pub(crate) struct SmallStrainPoints;

impl Contribution for SmallStrainPoints {
    fn name(&self) -> &'static str {
        "points"
    }

    fn blocks<'a>(&'a self, frame: &'a Frame) -> Vec<&'a [usize]> {
        frame.map.groups.iter().map(|g| g.nodes.as_slice()).collect()
    }

    /// The in-band points' `int (B_bar)^T D B d^a` (C (27)); with B-bar,
    /// a patch's points' `B_bar^T D B_bar d^a`.
    fn prescribed(&self, frame: &Frame, f_d: &mut [P2]) {
        let Some(s) = &frame.ibm else { return };
        let (sim, pts) = (frame.sim, &frame.sim.state.points);
        for p in (0..pts.len()).filter(|&p| pts.vol[p] > 0.0) {
            let st = frame.map.stencils.get(p);
            let d = sim.material_of(p).d_matrix();
            if let Some(bb) = frame.bbar.as_ref() {
                if let Some(op) = bb.op(&frame.map, p) {
                    let eps = super::bbar::Bbar::strain(&op, st, &s.da);
                    ibm::add_bt_c_eps(st, &op, &d, eps, pts.vol[p], f_d);
                    continue;
                }
            }
            let (bbar, _) = s.point_b(st, pts.x[p]);
            ibm::add_fd(st, &bbar, &d, &s.da, pts.vol[p], f_d);
        }
    }

    fn block(&self, k: usize, at: &At, out: &mut Vec<f64>) -> Result<(), StepFailure> {
        let (frame, sim) = (at.frame, at.frame.sim);
        let (map, pts) = (&frame.map, &sim.state.points);
        let d_of = |p: usize| sim.material_of(p).d_matrix();
        let g = &map.groups[k];
        let band = frame.ibm.as_ref().filter(|s| g.points.iter().any(|&p| s.in_band[p]));
        if band.is_none() && frame.bbar.is_none() {
            map.group_stiffness(g, pts, &d_of, out);
            return Ok(());
        }
        // Per point its operator: a B-bar patch's, else C (18)'s in a
        // band, else the plain B.
        let m2 = 2 * g.nodes.len();
        out.clear();
        out.resize(m2 * m2, 0.0);
        for &p in &g.points {
            let st = map.stencils.get(p);
            let op = match (frame.bbar.as_ref().and_then(|b| b.op(map, p)), band) {
                (Some(op), _) => op,
                (None, Some(s)) => s.point_b(st, pts.x[p]).0,
                (None, None) => ibm::plain_b(st),
            };
            ibm::add_atcb(&op, &d_of(p), &op, pts.vol[p], out);
        }
        Ok(())
    }
}

/// The material points of a finite-deformation step as a contribution:
/// their internal force `f_int = sum_p P : G V0_p` (subtracted from the
/// residual; the grid supports' reaction is its prescribed rows) and the
/// tangent blocks of the point groups ([`group_tangent`]).
pub(crate) struct FinitePoints;

impl Contribution for FinitePoints {
    fn name(&self) -> &'static str {
        "points"
    }

    fn blocks<'a>(&'a self, frame: &'a Frame) -> Vec<&'a [usize]> {
        frame.map.groups.iter().map(|g| g.nodes.as_slice()).collect()
    }

    /// F-bar couples the points of a patch unsymmetrically.
    fn symmetric(&self, frame: &Frame) -> bool {
        !frame.sim.model.analysis.fbar
    }

    fn internal(&self, at: &At, r: &mut [f64]) -> f64 {
        let Some(it) = at.points else { return 0.0 };
        for (r, f) in r.iter_mut().zip(&it.fint_free) {
            *r -= f;
        }
        crate::linalg::norm(&it.fint_fixed)
    }

    fn block(&self, k: usize, at: &At, out: &mut Vec<f64>) -> Result<(), StepFailure> {
        let frame = at.frame;
        let ops = frame.ibm.as_ref().map(|_| frame.ops.as_slice());
        match at.points {
            Some(it) => group_tangent(frame.sim, &frame.map, it, ops, k, out),
            None => out.clear(),
        }
        Ok(())
    }
}
