//! A B-spline boundary's traction as a contribution of a finite-deformation
//! step (B section 3): the force of its traction on the curve through its
//! tracking points at the iterate (a pressure follows the deformed
//! surface), and its load stiffness `-d f_ext / d d`, one block over the
//! nodes its force can reach (rows) and the nodes that move its points
//! (columns). The load stiffness is not symmetric.

use super::contribution::{At, Contribution};
use super::frame::Frame;
use crate::assembly::{Dof, Mapping};
use crate::boundary::bspline::{BSpline, Interpolation};
use crate::boundary::{integrate_traction, intersect, traction_forces, Boundary, BoundaryReport};
use crate::geometry::P2;
use crate::report::StepFailure;

/// A traction-carrying boundary's load: its nodes and stiffness columns.
pub(crate) struct TractionLoad {
    /// The boundary (index in the model).
    boundary: usize,
    /// The nodes its force can reach during the step (the block's rows).
    nodes: Vec<usize>,
    /// The columns of the load stiffness: the nodes that move the
    /// boundary's points.
    columns: Vec<LoadColumn>,
}

/// A node that moves some of a boundary's points (by their indices in the
/// boundary) and the segments of its spline those points shape (point `i`
/// shapes segments `i - 3 ..= i + 2`, [`Interpolation`]).
struct LoadColumn {
    node: usize,
    points: Vec<usize>,
    segments: Vec<usize>,
}

/// The columns of boundary `b`'s load stiffness: each node of `nodes`
/// whose stencils move some of its points, those points, and the segments
/// they shape (wrapped on a closed curve, clipped on an open one).
fn load_columns(b: &Boundary, map: &Mapping, nodes: &[usize]) -> Vec<LoadColumn> {
    let n = b.points.len() as isize;
    let segments = if b.closed { n } else { n - 1 };
    let mut moves: Vec<(usize, usize)> = Vec::new();
    for (i, &p) in b.points.iter().enumerate() {
        moves.extend(
            map.stencils
                .get(p)
                .nodes()
                .filter(|n| nodes.binary_search(n).is_ok())
                .map(|n| (n, i)),
        );
    }
    moves.sort_unstable();
    moves.dedup();
    let mut columns: Vec<LoadColumn> = Vec::new();
    for (node, i) in moves {
        if columns.last().is_none_or(|c| c.node != node) {
            columns.push(LoadColumn {
                node,
                points: Vec::new(),
                segments: Vec::new(),
            });
        }
        let c = columns.last_mut().expect("pushed above");
        c.points.push(i);
        for k in (i as isize - 3)..=(i as isize + 2) {
            let k = if b.closed { k.rem_euclid(n) } else { k };
            if (0..segments).contains(&k) {
                c.segments.push(k as usize);
            }
        }
    }
    for c in &mut columns {
        c.segments.sort_unstable();
        c.segments.dedup();
    }
    columns
}

impl TractionLoad {
    /// Every traction-carrying boundary's load for the step. Its block
    /// spans the nodes its force can reach during the step: the cells the
    /// curve cuts now and their neighbours (a curve moving into a new cell
    /// within the step must keep its rows, or Newton falls to a linear
    /// rate), and the nodes that move its points.
    pub fn all_of(frame: &Frame) -> Result<Vec<TractionLoad>, StepFailure> {
        let (model, map) = (&frame.sim.model, &frame.map);
        let (grid, pts) = (&model.grid, &frame.sim.state.points);
        let mut loads = Vec::new();
        for (k, b) in model.boundaries.iter().enumerate() {
            if b.traction.is_none() {
                continue;
            }
            let spline = b.spline(pts).map_err(|e| StepFailure::Boundary {
                step: frame.step,
                name: b.name.clone(),
                reason: e.to_string(),
            })?;
            let mut nodes: Vec<usize> = intersect::split(&spline, grid)
                .iter()
                .flat_map(|pc| {
                    let (i, j) = ((pc.cell % grid.nx) as i64, (pc.cell / grid.nx) as i64);
                    (-1..=1).flat_map(move |dj| (-1..=1).map(move |di| (i + di, j + dj)))
                })
                .filter(|&(i, j)| i >= 0 && j >= 0 && i < grid.nx as i64 && j < grid.ny as i64)
                .flat_map(|(i, j)| grid.cell_nodes(i as usize, j as usize))
                .chain(b.points.iter().flat_map(|&p| map.stencils.get(p).nodes()))
                .filter(|&n| map.dofs.node_dof[n][0] != Dof::Inactive)
                .collect();
            nodes.sort_unstable();
            nodes.dedup();
            let columns = load_columns(b, map, &nodes);
            loads.push(TractionLoad {
                boundary: k,
                nodes,
                columns,
            });
        }
        Ok(loads)
    }

    /// Nodal forces (at load factor 1) of the boundary's traction with its
    /// points at `xs` (indexed like the boundary's points).
    fn traction(&self, frame: &Frame, xs: &[P2]) -> Result<(Vec<(usize, P2)>, BoundaryReport), StepFailure> {
        let model = &frame.sim.model;
        let b = &model.boundaries[self.boundary];
        let spline = BSpline::interpolate(xs, b.closed, &b.corners).map_err(|e| StepFailure::Boundary {
            step: frame.step,
            name: b.name.clone(),
            reason: e.to_string(),
        })?;
        let active = |n: usize| frame.map.dofs.node_dof[n][0] != Dof::Inactive;
        Ok(traction_forces(
            b,
            &spline,
            &model.grid,
            model.exact.as_ref(),
            &active,
            frame.lambda1,
        ))
    }
}

impl Contribution for TractionLoad {
    fn name(&self) -> &'static str {
        "traction"
    }

    fn blocks<'a>(&'a self, _frame: &'a Frame) -> Vec<&'a [usize]> {
        vec![self.nodes.as_slice()]
    }

    fn symmetric(&self, _frame: &Frame) -> bool {
        false
    }

    /// `lambda` times the traction's nodal forces on the curve through the
    /// points where the iterate moves them.
    fn external(&self, at: &At, fext: &mut [f64]) -> Result<(), StepFailure> {
        let frame = at.frame;
        let b = &frame.sim.model.boundaries[self.boundary];
        let xs: Vec<P2> = b.points.iter().map(|&p| frame.moved(p, at.d)).collect();
        for (n, f) in self.traction(frame, &xs)?.0 {
            for c in 0..2 {
                if let Some(i) = frame.free(n, c) {
                    fext[i] += frame.lambda1 * f[c];
                }
            }
        }
        Ok(())
    }

    /// The load stiffness at `d`: `-d f_ext / d d` by central differences
    /// of the traction in each nodal unknown that moves the boundary's
    /// points (difference step 1e-6 h: the traction is smooth in `d`
    /// between grid-line crossings, so the derivative holds to about 1e-9
    /// relative). Differencing in `d` rather than in the points' positions
    /// keeps the motions Newton takes: points of one cell stay collinear
    /// under `S d`, where B's tangent weights `|q x q|` are not
    /// differentiable in a single point's position.
    ///
    /// Each difference re-interpolates and re-integrates only the segments
    /// the moved points shape (the interpolation is local), with the
    /// collinearity tolerance of the unperturbed curve: the block costs
    /// time in proportion to the boundary's length, not its square.
    fn block(&self, _k: usize, at: &At, out: &mut Vec<f64>) -> Result<(), StepFailure> {
        let (frame, d) = (at.frame, at.d);
        let model = &frame.sim.model;
        let b = &model.boundaries[self.boundary];
        let m2 = 2 * self.nodes.len();
        out.clear();
        out.resize(m2 * m2, 0.0);
        let local = |n: usize| self.nodes.binary_search(&n).ok();
        let eps = 1e-6 * model.grid.h;
        let lambda = frame.lambda1;
        let x0: Vec<P2> = b.points.iter().map(|&p| frame.moved(p, d)).collect();
        // The unperturbed curve's checks and collinearity scale.
        let scale = Interpolation::new(&x0, b.closed, &b.corners)
            .map_err(|e| StepFailure::Boundary {
                step: frame.step,
                name: b.name.clone(),
                reason: e.to_string(),
            })?
            .scale();
        let (mut xs, mut shifted) = (x0.clone(), d.to_vec());
        for col in &self.columns {
            let (m, bb) = (col.node, local(col.node).expect("columns are block nodes"));
            for k in 0..2 {
                for sign in [1.0, -1.0] {
                    shifted[m][k] = d[m][k] + sign * eps;
                    for &i in &col.points {
                        xs[i] = frame.moved(b.points[i], &shifted);
                    }
                    shifted[m][k] = d[m][k];
                    let spline = Interpolation::with_scale(&xs, b.closed, &b.corners, scale).spline_of(&col.segments);
                    let pieces = intersect::split(&spline, &model.grid);
                    integrate_traction(b, &spline, &pieces, &model.grid, model.exact.as_ref(), |n, f| {
                        if let (Some(a), true) = (local(n), frame.map.dofs.node_dof[n][0] != Dof::Inactive) {
                            for i in 0..2 {
                                out[(2 * a + i) * m2 + 2 * bb + k] -= sign * lambda * f[i] / (2.0 * eps);
                            }
                        }
                    });
                    for &i in &col.points {
                        xs[i] = x0[i];
                    }
                }
            }
        }
        Ok(())
    }
}
