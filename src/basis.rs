//! Basis functions that map between material points and grid nodes.
//!
//! - Standard MPM: `S_vp = N_v(x_p)`, the bilinear shape function of the
//!   cell containing the point.
//! - GIMP (generalised interpolation MPM): the bilinear function averaged
//!   over the point's rectangular domain of half-lengths `l_p`; per
//!   direction, with `d = x_p - x_v`,
//!   `S = 1 - (d^2 + l^2)/(2 h l)` for `|d| < l`,
//!   `S = 1 - |d|/h` for `l <= |d| < h - l`,
//!   `S = (h + l - |d|)^2 / (4 h l)` for `h - l <= |d| < h + l`, 0 beyond
//!   (Bardenhagen & Kober 2004; G section 2.2), and the 2D weight is the
//!   tensor product.
//!
//! Both give a partition of unity while the point (and its domain) stays
//! inside the grid, and their gradients sum to zero.

use crate::grid::Grid;
use serde::Deserialize;

/// Largest number of nodes a point can touch: 4 per direction for GIMP
/// domains up to one cell wide.
pub const MAX_NODES: usize = 16;

/// Which basis a body uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BasisKind {
    #[default]
    Standard,
    Gimp,
}

impl BasisKind {
    pub fn name(self) -> &'static str {
        match self {
            BasisKind::Standard => "standard",
            BasisKind::Gimp => "gimp",
        }
    }
}

/// The nodes a point touches with their weights `S_vp` and gradients
/// `dS_vp/dx` (1/length). The nodes form the rectangle of node columns
/// `i0 .. i0 + ni` and rows `j0 .. j0 + nj`, listed row by row.
#[derive(Clone, Copy, Debug)]
pub struct Stencil {
    pub len: usize,
    pub nodes: [usize; MAX_NODES],
    pub w: [f64; MAX_NODES],
    pub dw: [[f64; 2]; MAX_NODES],
    /// `(i0, j0, ni, nj)`: the node rectangle. Points with equal keys touch
    /// the same nodes, which is what assembly groups by.
    pub key: (u32, u32, u8, u8),
}

impl Stencil {
    pub fn iter(&self) -> impl Iterator<Item = (usize, f64, [f64; 2])> + '_ {
        (0..self.len).map(|k| (self.nodes[k], self.w[k], self.dw[k]))
    }

    /// Interpolate a nodal vector field (two values per grid node).
    pub fn interpolate(&self, nodal: impl Fn(usize) -> [f64; 2]) -> [f64; 2] {
        let mut u = [0.0; 2];
        for (n, w, _) in self.iter() {
            let v = nodal(n);
            u[0] += w * v[0];
            u[1] += w * v[1];
        }
        u
    }

    /// Gradient `du_i/dx_j` of a nodal vector field, as `[[u_x,x, u_x,y], [u_y,x, u_y,y]]`.
    pub fn gradient(&self, nodal: impl Fn(usize) -> [f64; 2]) -> [[f64; 2]; 2] {
        let mut g = [[0.0; 2]; 2];
        for (n, _, dw) in self.iter() {
            let v = nodal(n);
            for i in 0..2 {
                for j in 0..2 {
                    g[i][j] += v[i] * dw[j];
                }
            }
        }
        g
    }
}

/// 1D weights of one direction: up to 4 nodes starting at index `first`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Weights1d {
    pub(crate) first: usize,
    pub(crate) len: usize,
    /// Weights (1) and their derivatives (1/length) of nodes `first ..`.
    pub(crate) w: [f64; 4],
    pub(crate) dw: [f64; 4],
}

#[inline(always)]
fn standard_1d(s: f64, n_cells: usize, h: f64) -> Weights1d {
    // s = (x - x0)/h, the point's coordinate in cell units.
    // `s as usize` is `floor(max(s, 0))` (NaN to 0) without a libm call.
    let c = (s as usize).min(n_cells - 1);
    let xi = s - c as f64;
    Weights1d {
        first: c,
        len: 2,
        w: [1.0 - xi, xi, 0.0, 0.0],
        dw: [-1.0 / h, 1.0 / h, 0.0, 0.0],
    }
}

/// GIMP weight and derivative for distance `d = x_p - x_v` and half-length `l` (`0 < l <= h`).
pub fn gimp_1d(d: f64, l: f64, h: f64) -> (f64, f64) {
    let a = d.abs();
    let sg = if d < 0.0 { -1.0 } else { 1.0 };
    if a < l {
        (1.0 - (d * d + l * l) / (2.0 * h * l), -d / (h * l))
    } else if a < h - l {
        (1.0 - a / h, -sg / h)
    } else if h + l - a > 1e-12 * h {
        // Overlaps thinner than round-off are no overlap: a node reached
        // only through them would enter the system with a zero row.
        let t = h + l - a;
        (t * t / (4.0 * h * l), -sg * t / (2.0 * h * l))
    } else {
        (0.0, 0.0)
    }
}

#[inline]
fn gimp_1d_nodes(x: f64, x0: f64, l: f64, h: f64, n_cells: usize) -> Weights1d {
    let lo = ((x - l - h - x0) / h).ceil().max(0.0) as usize;
    let hi = (((x + l + h - x0) / h).floor().max(0.0) as usize).min(n_cells);
    let mut out = Weights1d {
        first: lo,
        len: 0,
        w: [0.0; 4],
        dw: [0.0; 4],
    };
    let mut first_set = false;
    for i in lo..=hi {
        let (w, dw) = gimp_1d(x - (x0 + i as f64 * h), l, h);
        if w > 0.0 || dw != 0.0 {
            if !first_set {
                out.first = i;
                first_set = true;
            }
            if out.len < 4 {
                out.w[out.len] = w;
                out.dw[out.len] = dw;
                out.len += 1;
            }
        } else if first_set {
            break;
        }
    }
    out
}

/// The 1D factors of a point's stencil along x and y: the stencil's node
/// `(wx.first + a, wy.first + b)` has weight `wx.w[a] wy.w[b]` and
/// gradient `[wx.dw[a] wy.w[b], wx.w[a] wy.dw[b]]` (what [`stencil`]
/// lists row by row; tight loops use them without building a [`Stencil`]).
#[inline]
pub(crate) fn weights_1d(grid: &Grid, kind: BasisKind, x: [f64; 2], lp: [f64; 2]) -> [Weights1d; 2] {
    let h = grid.h;
    let n = [grid.nx, grid.ny];
    match kind {
        BasisKind::Standard => [0, 1].map(|d| standard_1d((x[d] - grid.origin[d]) / h, n[d], h)),
        BasisKind::Gimp => [0, 1].map(|d| gimp_1d_nodes(x[d], grid.origin[d], lp[d].clamp(1e-12 * h, h), h, n[d])),
    }
}

/// The stencil of a point at `x` with GIMP half-lengths `lp` (ignored by the
/// standard basis). The point must lie inside the grid.
pub fn stencil(grid: &Grid, kind: BasisKind, x: [f64; 2], lp: [f64; 2]) -> Stencil {
    let [wx, wy] = weights_1d(grid, kind, x, lp);
    let mut st = Stencil {
        len: 0,
        nodes: [0; MAX_NODES],
        w: [0.0; MAX_NODES],
        dw: [[0.0; 2]; MAX_NODES],
        key: (wx.first as u32, wy.first as u32, wx.len as u8, wy.len as u8),
    };
    for b in 0..wy.len {
        for a in 0..wx.len {
            let k = st.len;
            st.nodes[k] = grid.node(wx.first + a, wy.first + b);
            st.w[k] = wx.w[a] * wy.w[b];
            st.dw[k] = [wx.dw[a] * wy.w[b], wx.w[a] * wy.dw[b]];
            st.len += 1;
        }
    }
    st
}
