//! Boundaries: ordered material points interpolated by a B-spline every
//! step, optionally carrying a traction (Neumann) condition.
//!
//! - [`bspline`]: local cubic interpolation, evaluation, length, area;
//! - [`intersect`]: splitting at grid lines;
//! - this module: the boundary model, traction integration and reports.
//!
//! Traction (B (13)-(17)): per piece of the curve inside one cell,
//! Gauss-Legendre in the piece's parameter,
//! `f_v += sum_g N_v(C(t_g)) t(C(t_g), n) |C'(t_g)| (t1 - t0)/2 w_g`,
//! with `N_v` the grid's bilinear functions and `n` the outward normal of
//! the curve through the points' *current* positions (so a pressure follows
//! the deformed surface).

pub mod bspline;
pub mod intersect;

use crate::basis::{stencil, BasisKind};
use crate::exact::ExactSolution;
use crate::geometry::P2;
use crate::grid::Grid;
use crate::points::Points;
use crate::quadrature::gauss_legendre;
use bspline::{BSpline, SplineError};

/// The load a boundary carries, at load factor 1.
#[derive(Clone, Debug, PartialEq)]
pub enum Traction {
    /// A fixed traction vector (Pa, i.e. N/m per unit thickness).
    Vector(P2),
    /// A pressure `p` (Pa) acting against the outward normal: `t = -p n`.
    Pressure(f64),
    /// `t = s_exact(x) n` from the scene's exact solution.
    ExactStress,
}

/// A boundary of the model.
#[derive(Clone, Debug, PartialEq)]
pub struct Boundary {
    pub name: String,
    /// Indices of the points it passes through, in order.
    pub points: Vec<usize>,
    pub closed: bool,
    /// Corner marks per point.
    pub corners: Vec<bool>,
    /// Gauss points per piece for the traction integral.
    pub gauss_points: usize,
    pub traction: Option<Traction>,
    /// `+1` when the outward normal is the curve's right normal, `-1` when it is the left.
    pub outward: f64,
}

impl Boundary {
    /// The spline through the boundary's points at their positions in `pts`.
    pub fn spline(&self, pts: &Points) -> Result<BSpline, SplineError> {
        let q: Vec<P2> = self.points.iter().map(|&p| pts.x[p]).collect();
        BSpline::interpolate(&q, self.closed, &self.corners)
    }
}

/// What a boundary looked like in a step.
#[derive(Clone, Debug, PartialEq)]
pub struct BoundaryReport {
    pub name: String,
    /// Length of the spline (m).
    pub length: f64,
    /// Enclosed area (m^2), closed curves only.
    pub area: Option<f64>,
    /// Cells the curve passes through.
    pub cells_cut: usize,
    /// Resultant of the traction at the step's load factor (N per unit thickness).
    pub resultant: P2,
    /// Part of the resultant that fell on nodes no material point touches
    /// (lost; nonzero means the boundary strays from its material).
    pub lost: f64,
}

/// Nodal forces of one boundary's traction at load factor 1: `(node, force)`
/// pairs, and the report (resultant scaled by `load_factor`).
pub fn traction_forces(
    b: &Boundary,
    spline: &BSpline,
    grid: &Grid,
    exact: Option<&ExactSolution>,
    active: &dyn Fn(usize) -> bool,
    load_factor: f64,
) -> (Vec<(usize, P2)>, BoundaryReport) {
    let pieces = intersect::split(spline, grid);
    let mut cells: Vec<usize> = pieces.iter().map(|p| p.cell).collect();
    cells.sort_unstable();
    cells.dedup();
    let mut forces = Vec::new();
    let (mut resultant, mut lost) = ([0.0; 2], [0.0; 2]);
    integrate_traction(b, spline, &pieces, grid, exact, |node, f| {
        resultant[0] += f[0];
        resultant[1] += f[1];
        if active(node) {
            forces.push((node, f));
        } else {
            lost[0] += f[0];
            lost[1] += f[1];
        }
    });
    let report = BoundaryReport {
        name: b.name.clone(),
        length: spline.length(),
        area: b.closed.then(|| spline.signed_area().abs()),
        cells_cut: cells.len(),
        resultant: resultant.map(|v| v * load_factor),
        lost: load_factor * lost[0].hypot(lost[1]),
    };
    (forces, report)
}

/// B (13)-(17): the traction of boundary `b` (at load factor 1) over
/// `pieces` of `spline`, node by node: `force(node, f)` for every
/// quadrature point and grid node of its stencil (N per unit thickness).
/// Nothing when the boundary carries no traction.
pub fn integrate_traction(
    b: &Boundary,
    spline: &BSpline,
    pieces: &[intersect::Piece],
    grid: &Grid,
    exact: Option<&ExactSolution>,
    mut force: impl FnMut(usize, P2),
) {
    let Some(t) = &b.traction else {
        return;
    };
    let (xg, wg) = gauss_legendre(b.gauss_points);
    for pc in pieces {
        let half = 0.5 * (pc.t1 - pc.t0);
        for (xi, wi) in xg.iter().zip(&wg) {
            let tp = pc.t0 + half * (1.0 + xi);
            let x = spline.point(pc.segment, tp);
            let d = spline.d1(pc.segment, tp);
            let speed = d[0].hypot(d[1]);
            let rn = spline.right_normal(pc.segment, tp);
            let n = [b.outward * rn[0], b.outward * rn[1]];
            let tv = match t {
                Traction::Vector(v) => *v,
                Traction::Pressure(p) => [-p * n[0], -p * n[1]],
                Traction::ExactStress => match exact {
                    Some(e) => {
                        let s = e.stress(x);
                        [s[0] * n[0] + s[2] * n[1], s[2] * n[0] + s[1] * n[1]]
                    }
                    None => [0.0; 2],
                },
            };
            let jw = speed * half * wi;
            let st = stencil(grid, BasisKind::Standard, x, [0.0; 2]);
            for (node, w, _) in st.view().iter() {
                if w == 0.0 {
                    continue;
                }
                force(node, [w * tv[0] * jw, w * tv[1] * jw]);
            }
        }
    }
}
