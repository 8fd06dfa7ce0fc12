//! Finite-deformation kinematics of one step, shared by the Newton and the
//! explicit drivers: the increment `dF` from nodal increments, the stored
//! `b_e` as a tensor, and committing a point's increment.

use crate::basis::StencilView;
use crate::geometry::P2;
use crate::material::hencky::{right_stretch, Hencky, Response};
use crate::points::Points;
use nalgebra::{Matrix2, Matrix3};

/// `dF = I + sum_v du_v (x) grad S_v` over a point's stencil.
pub fn increment_gradient(st: StencilView, du: &[P2]) -> Matrix2<f64> {
    let g = st.gradient(|n| du[n]);
    Matrix2::new(1.0 + g[0][0], g[0][1], g[1][0], 1.0 + g[1][1])
}

/// The stored `[xx, yy, xy, zz]` components of `b_e` as a 3 x 3 tensor.
pub fn be_matrix(b: [f64; 4]) -> Matrix3<f64> {
    Matrix3::new(b[0], b[2], 0.0, b[2], b[1], 0.0, 0.0, 0.0, b[3])
}

/// Commit point `p`'s deformation increment `df` from `pts` (the state at
/// the start of the step) into `next` (the fields the step writes, as
/// `Points::finite_copy` makes them): `F = dF F_n`, `V = det(dF) V_n`,
/// GIMP domains `l = l_0 diag(U)` (`F = R U`), and with the material's
/// response (points with volume) the Cauchy stress `s = tau / det F`,
/// `b_e`, dissipation and yield flag (without one, `next` keeps them).
/// Returns the point's stored energy (on `V0`, with `material`) and its
/// dissipation so far (J per unit thickness).
pub fn commit_point(
    pts: &Points,
    next: &mut Points,
    p: usize,
    df: &Matrix2<f64>,
    r: Option<&Response>,
    material: &Hencky,
) -> Option<(f64, f64)> {
    let fo = pts.def_grad[p];
    let f = df * Matrix2::new(fo[0], fo[1], fo[2], fo[3]);
    next.def_grad[p] = [f[(0, 0)], f[(0, 1)], f[(1, 0)], f[(1, 1)]];
    next.vol[p] = pts.vol[p] * df.determinant();
    let (l0, u) = (pts.lp0[p], right_stretch(&f));
    next.lp[p] = [l0[0] * u[(0, 0)], l0[1] * u[(1, 1)]];
    let r = r?;
    let s = r.tau / f.determinant();
    next.stress[p] = [s[(0, 0)], s[(1, 1)], s[(0, 1)]];
    next.szz[p] = s[(2, 2)];
    next.b_e[p] = [r.b_e[(0, 0)], r.b_e[(1, 1)], r.b_e[(0, 1)], r.b_e[(2, 2)]];
    next.dissipation[p] = pts.dissipation[p] + r.dissipation * pts.vol0[p];
    next.yielding[p] = r.yielding;
    Some((pts.vol0[p] * material.stored_energy(&r.b_e), next.dissipation[p]))
}
