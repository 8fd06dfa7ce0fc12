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

/// The 1D factors of one stencil are at most `2 (4 + 4)` numbers.
const MAX_FACTORS: usize = 16;

/// A point's node rectangle `(i0, j0, ni, nj)`: node columns
/// `i0 .. i0 + ni` and rows `j0 .. j0 + nj`. Points with equal keys touch
/// the same nodes, which is what assembly groups by.
pub type StencilKey = (u32, u32, u8, u8);

/// The nodes a point touches with their weights `S_vp` and gradients
/// `dS_vp/dx` (1/length), owned: one point's stencil built on its own
/// (quadrature points of a band, a point load). Stored as its 1D factors;
/// [`Stencil::view`] reads it. A step's stencils of all points are kept
/// compactly in [`crate::assembly::Stencils`].
#[derive(Clone, Copy, Debug)]
pub struct Stencil {
    key: StencilKey,
    /// Node numbers per grid row (`nx + 1`).
    row: usize,
    /// `[S_x (ni), dS_x/dx (ni), S_y (nj), dS_y/dy (nj)]`, the rest unused.
    factors: [f64; MAX_FACTORS],
}

impl Stencil {
    /// The stencil as the view every consumer reads.
    pub fn view(&self) -> StencilView<'_> {
        StencilView::new(self.key, self.row, &self.factors[..factor_len(self.key)])
    }
}

/// How many 1D factors a stencil of node rectangle `key` has:
/// `2 (ni + nj)`.
#[inline]
pub(crate) fn factor_len(key: StencilKey) -> usize {
    2 * (key.2 as usize + key.3 as usize)
}

/// One point's stencil, borrowed: its node rectangle `key` (the nodes
/// listed row by row: node `k` is column `i0 + k % ni`, row `j0 + k / ni`)
/// and its 1D factors, from which every weight and gradient is formed as
/// [`stencil`] forms it (`S = S_x S_y`, `grad S = [S_x' S_y, S_x S_y']`),
/// so the numbers are those of a stencil that stores the products. Cheap to
/// copy (a key, a stride and a slice).
#[derive(Clone, Copy, Debug)]
pub struct StencilView<'a> {
    key: StencilKey,
    /// Node numbers per grid row (`nx + 1`).
    row: usize,
    ni: usize,
    nj: usize,
    /// `[S_x (ni), dS_x/dx (ni), S_y (nj), dS_y/dy (nj)]` (1, 1/length).
    factors: &'a [f64],
}

impl<'a> StencilView<'a> {
    /// The view of node rectangle `key` on a grid of `row` nodes per row
    /// with `factors` laid out as `[S_x, dS_x/dx, S_y, dS_y/dy]`
    /// (`2 (ni + nj)` numbers).
    #[inline]
    pub(crate) fn new(key: StencilKey, row: usize, factors: &'a [f64]) -> StencilView<'a> {
        StencilView {
            key,
            row,
            ni: key.2 as usize,
            nj: key.3 as usize,
            factors,
        }
    }

    /// Number of nodes, `ni nj`.
    #[inline]
    pub fn len(&self) -> usize {
        self.ni * self.nj
    }

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The node rectangle `(i0, j0, ni, nj)`.
    #[inline]
    pub fn key(&self) -> StencilKey {
        self.key
    }

    #[inline]
    fn first(&self) -> usize {
        self.key.1 as usize * self.row + self.key.0 as usize
    }

    #[inline]
    fn wx(&self, a: usize) -> f64 {
        self.factors[a]
    }

    #[inline]
    fn dwx(&self, a: usize) -> f64 {
        self.factors[self.ni + a]
    }

    #[inline]
    fn wy(&self, b: usize) -> f64 {
        self.factors[2 * self.ni + b]
    }

    #[inline]
    fn dwy(&self, b: usize) -> f64 {
        self.factors[2 * self.ni + self.nj + b]
    }

    /// Grid node of entry `k` (`k < len`).
    #[inline]
    pub fn node(&self, k: usize) -> usize {
        self.first() + (k / self.ni) * self.row + k % self.ni
    }

    /// Weight `S_vp` of entry `k` (1).
    #[inline]
    pub fn w(&self, k: usize) -> f64 {
        self.wx(k % self.ni) * self.wy(k / self.ni)
    }

    /// Gradient `dS_vp/dx` of entry `k` (1/length).
    #[inline]
    pub fn dw(&self, k: usize) -> [f64; 2] {
        let (a, b) = (k % self.ni, k / self.ni);
        [self.dwx(a) * self.wy(b), self.wx(a) * self.dwy(b)]
    }

    /// The grid nodes, row by row.
    pub fn nodes(self) -> impl Iterator<Item = usize> + 'a {
        let (first, row, ni) = (self.first(), self.row, self.ni);
        (0..self.nj).flat_map(move |b| (0..ni).map(move |a| first + b * row + a))
    }

    /// `(node, S_vp, dS_vp/dx)` row by row.
    pub fn iter(self) -> impl Iterator<Item = (usize, f64, [f64; 2])> + 'a {
        let (first, row, ni) = (self.first(), self.row, self.ni);
        (0..self.nj).flat_map(move |b| {
            (0..ni).map(move |a| {
                let (wx, dwx, wy, dwy) = (self.wx(a), self.dwx(a), self.wy(b), self.dwy(b));
                (first + b * row + a, wx * wy, [dwx * wy, wx * dwy])
            })
        })
    }

    /// Interpolate a nodal vector field (two values per grid node).
    pub fn interpolate(self, nodal: impl Fn(usize) -> [f64; 2]) -> [f64; 2] {
        let mut u = [0.0; 2];
        for (n, w, _) in self.iter() {
            let v = nodal(n);
            u[0] += w * v[0];
            u[1] += w * v[1];
        }
        u
    }

    /// Gradient `du_i/dx_j` of a nodal vector field, as `[[u_x,x, u_x,y], [u_y,x, u_y,y]]`.
    pub fn gradient(self, nodal: impl Fn(usize) -> [f64; 2]) -> [[f64; 2]; 2] {
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

/// The node rectangle of a point's 1D factors.
#[inline]
pub(crate) fn key_of(w: &[Weights1d; 2]) -> StencilKey {
    let [wx, wy] = w;
    (wx.first as u32, wy.first as u32, wx.len as u8, wy.len as u8)
}

/// Write a point's 1D factors as a [`StencilView`] reads them,
/// `[S_x, dS_x/dx, S_y, dS_y/dy]`, into `out` (`2 (ni + nj)` numbers).
#[inline]
pub(crate) fn write_factors(w: &[Weights1d; 2], out: &mut [f64]) {
    let [wx, wy] = w;
    let (ni, nj) = (wx.len, wy.len);
    out[..ni].copy_from_slice(&wx.w[..ni]);
    out[ni..2 * ni].copy_from_slice(&wx.dw[..ni]);
    out[2 * ni..2 * ni + nj].copy_from_slice(&wy.w[..nj]);
    out[2 * ni + nj..2 * (ni + nj)].copy_from_slice(&wy.dw[..nj]);
}

/// The stencil of a point at `x` with GIMP half-lengths `lp` (ignored by the
/// standard basis). The point must lie inside the grid.
pub fn stencil(grid: &Grid, kind: BasisKind, x: [f64; 2], lp: [f64; 2]) -> Stencil {
    let w = weights_1d(grid, kind, x, lp);
    let mut st = Stencil {
        key: key_of(&w),
        row: grid.nx + 1,
        factors: [0.0; MAX_FACTORS],
    };
    write_factors(&w, &mut st.factors);
    st
}
