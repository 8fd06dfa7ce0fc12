//! What an implicit step fixes at its start: the points on the grid, the
//! implicit boundaries' prescribed motion and band operators, the ghost
//! faces.

use super::bbar::Bbar;
use crate::assembly::{Dof, Mapping};
use crate::bulk::BandView;
use crate::geometry::P2;
use crate::ghost::{self, GhostFace};
use crate::ibm::{GradOp, IbmBoundary, IbmStep};
use crate::report::StepFailure;
use crate::state::Simulation;

/// The interval an implicit step covers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Interval {
    /// Load factor at its start and end: the loads are `lambda f`.
    pub load: (f64, f64),
    /// The run's progress at its start and end, in `[0, 1]`: prescribed
    /// motions (grid supports, implicit boundaries) move by their totals
    /// times its increment, and exact solutions and the report read its
    /// end. The load factor in a quasi-static step; `t / duration` in
    /// implicit dynamics, whose loads act in full from the start.
    pub path: (f64, f64),
}

impl Interval {
    /// A quasi-static increment `lambda0 -> lambda1`: loads and prescribed
    /// motions in proportion.
    pub fn quasi_static(lambda0: f64, lambda1: f64) -> Interval {
        Interval {
            load: (lambda0, lambda1),
            path: (lambda0, lambda1),
        }
    }
}

/// What an implicit step keeps fixed from its start to its commit.
pub(crate) struct Frame<'s> {
    pub sim: &'s Simulation,
    /// 1-based load step.
    pub step: usize,
    /// Load factor at the start and the end of the increment.
    pub lambda0: f64,
    pub lambda1: f64,
    /// The run's progress over the increment ([`Interval::path`]).
    pub path: (f64, f64),
    /// The points on the grid: stencils, point groups, dofs (the grid
    /// supports' increments net of `d^a`).
    pub map: Mapping,
    /// The implicit boundaries' prescribed increments `d^a` and which
    /// points lie in a band (`None` without implicit boundaries).
    pub ibm: Option<IbmStep<'s>>,
    /// Finite deformation: per point, its band operators ([`GradOp`]) when
    /// it lies in a band (empty for a small-strain step).
    pub ops: Vec<Option<Vec<GradOp>>>,
    /// The ghost faces (G 4.2; none when `gamma_K = 0`).
    pub faces: Vec<GhostFace>,
    /// `gamma_K` (G (27)).
    pub gamma: f64,
    /// Small strain with `analysis.fbar`: the B-bar patches.
    pub bbar: Option<Bbar>,
}

impl<'s> Frame<'s> {
    /// Map the points of `sim` to the grid and prepare the implicit
    /// boundaries `ibm_now` (their `d^a` over the `interval`'s path) and
    /// the ghost faces; with `finite`, the band operators of the
    /// finite-deformation step.
    pub fn new(
        sim: &'s Simulation,
        ibm_now: &'s [IbmBoundary],
        step: usize,
        interval: Interval,
        finite: bool,
    ) -> Result<Frame<'s>, StepFailure> {
        let model = &sim.model;
        let (grid, pts) = (&model.grid, &sim.state.points);
        let ((lambda0, lambda1), path) = (interval.load, interval.path);
        let moved = path.1 - path.0;
        let mut map = Mapping::build(grid, pts, &model.bodies, &model.dirichlet, moved).map_err(|e| e.at_step(step))?;
        let gamma = sim.params.gamma_k;
        let faces = if gamma > 0.0 {
            ghost::faces_of(grid, &map, model.analysis.ghost_cells)
        } else {
            Vec::new()
        };
        let ibm = if ibm_now.is_empty() {
            None
        } else {
            let s = IbmStep::new(
                ibm_now,
                grid,
                &pts.x,
                sim.params.delta_over_h,
                moved,
                model.exact.as_ref(),
            )
            .map_err(|e| StepFailure::Singular {
                step,
                reason: e.to_string(),
            })?;
            // A grid constraint prescribes a node's whole motion: where an
            // implicit boundary also puts d^a on that dof, the grid unknown
            // carries only the rest.
            for (n, c, u) in map.dofs.constrained.iter_mut() {
                *u -= s.da[*n][*c];
            }
            Some(s)
        };
        let ops = match (&ibm, finite) {
            (Some(s), true) => (0..pts.len())
                .map(|p| {
                    (pts.vol0[p] > 0.0)
                        .then(|| s.gradient_ops(map.stencils.get(p), pts.x[p]))
                        .flatten()
                })
                .collect(),
            _ => Vec::new(),
        };
        let bbar = (!finite && model.analysis.fbar)
            .then(|| Bbar::new(&map, pts, |p| ibm.as_ref().is_some_and(|s| s.in_band[p])));
        Ok(Frame {
            sim,
            step,
            lambda0,
            lambda1,
            path,
            map,
            ibm,
            ops,
            faces,
            gamma,
            bbar,
        })
    }

    /// The nodes' whole motion `d + d^a` at unknowns `d`
    /// ([`crate::ibm::nodal_motion`]).
    pub fn motion(&self, d: &[P2]) -> Vec<P2> {
        crate::ibm::nodal_motion(d, self.ibm.as_ref())
    }

    /// Where point `p` is at unknowns `d`: `x + D S d + S d^a`.
    pub fn moved(&self, p: usize, d: &[P2]) -> P2 {
        let x = self.sim.state.points.x[p];
        let st = self.map.stencils.get(p);
        let u = match &self.ibm {
            Some(s) => s.point_increment(st, x, d),
            None => st.interpolate(|n| d[n]),
        };
        [x[0] + u[0], x[1] + u[1]]
    }

    /// The implicit boundaries as the finite-deformation points see them
    /// at unknowns `d`.
    pub fn band_view<'a>(&'a self, d: &'a [P2]) -> Option<BandView<'a>> {
        self.ibm.as_ref().map(|s| (&self.ops[..], d, &s.da[..]))
    }

    /// The unknowns at the start of a step: the grid-prescribed components
    /// at their increments, zero elsewhere (per grid node).
    pub fn start(&self) -> Vec<P2> {
        let mut d = vec![[0.0; 2]; self.sim.model.grid.num_nodes()];
        for &(n, c, v) in &self.map.dofs.constrained {
            d[n][c] = v;
        }
        d
    }

    /// The free dof of node `n`'s component `c`, if it has one.
    pub fn free(&self, n: usize, c: usize) -> Option<usize> {
        match self.map.dofs.node_dof[n][c] {
            Dof::Free(i) => Some(i),
            _ => None,
        }
    }

    /// What the commit keeps of the frame, with the simulation no longer
    /// borrowed.
    pub fn close(self) -> Closed {
        Closed {
            step: self.step,
            path: self.path,
            unknowns: self.map.dofs.n_free,
            active_nodes: self.map.dofs.active_nodes,
            active_cells: self.map.active_cells,
            faces: self.faces,
            gamma: self.gamma,
        }
    }

    /// The mapping's stencils and point groups again after they were
    /// freed for a factorisation ([`Mapping::restore`]).
    pub fn restore_mapping(&mut self) -> Result<(), StepFailure> {
        let sim = self.sim;
        self.map
            .restore(&sim.model.grid, &sim.state.points, &sim.model.bodies)
            .map_err(|e| e.at_step(self.step))
    }
}

/// What a step's commit needs of its [`Frame`].
pub(crate) struct Closed {
    pub step: usize,
    /// The run's progress over the step ([`Interval::path`]).
    pub path: (f64, f64),
    pub unknowns: usize,
    pub active_nodes: usize,
    pub active_cells: Vec<usize>,
    pub faces: Vec<GhostFace>,
    pub gamma: f64,
}
