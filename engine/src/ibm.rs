//! Implicit boundary method for Dirichlet conditions at any inclination
//! (Cortis et al. 2018, C section 3; Bing et al. 2019, B 3.5).
//!
//! With `phi` the signed distance to a boundary (positive in the material)
//! and bandwidth `delta`, the Dirichlet function is
//! `d(phi) = 1 - (1 - phi/delta)^2` for `0 <= phi <= delta`, 0 below and 1
//! above. Per boundary, `D = d I` (fixed) or `D = I - (1 - d) n n^T`
//! (roller, `n` the inward normal); several boundaries multiply. The
//! displacement is `u = D sum_k N_k d_k + sum_k N_k d^a_k`, so its strain
//! operator is `B_bar = B1 + B2`, `B1` from `D grad N`, `B2` from
//! `(grad D) N`. Outside the band `D = I` and points keep the ordinary `B`;
//! the band (width `delta`, typically 1e-6 h) is integrated separately with
//! Gauss points along each piece of boundary in a cell and 3 across,
//! adding `B_bar^T C B_bar - B^T C B`: the terms `K2 + K2^T + K3` of
//! C (18)-(27), and the difference between `K1` with `D` and the points'
//! `K1`, which integrates the band with `D = I`. Prescribed
//! values go on the nodes of the cells the boundary cuts (B footnote 3) and
//! their strain moves to the right-hand side, `f_d = -int B_bar^T C B d^a`
//! (over the points, and `(B_bar - B)^T` over the band for the same reason).

use crate::basis::{stencil, BasisKind, Stencil, StencilView};
use crate::exact::ExactSolution;
use crate::geometry::P2;
use crate::grid::Grid;
use crate::material::mul3;
use crate::quadrature::gauss_legendre;
use crate::scene::DirichletKind;

/// One implicit Dirichlet boundary: a polyline with the material on the
/// side of `normal`.
#[derive(Clone, Debug, PartialEq)]
pub struct IbmBoundary {
    pub name: String,
    pub kind: DirichletKind,
    pub points: Vec<P2>,
    /// `+1`: the material is to the left of the direction of travel.
    pub side: f64,
    /// Fixed: the prescribed displacement; roller: `[u_n, 0]` along the inward normal (totals at load factor 1).
    pub value: P2,
    pub gauss_points: usize,
    /// Prescribe the exact solution's displacement (least-squares fit).
    pub exact_field: bool,
    /// Tikhonov weight of the fit: `None` automatic (plain B (36), and
    /// [`AUTO_FIT_REGULARISATION`] in a step where that is singular);
    /// `Some(0)` plain always; `Some(eps)` always `eps`.
    pub fit_regularisation: Option<f64>,
    /// The boundary moves with its prescribed displacement (a rigid footing).
    pub moves: bool,
    /// Follows the B-spline boundary with this index, flattened to this
    /// many chords per spline segment (its `points` are then rebuilt each step).
    pub spline: Option<(usize, usize)>,
}

impl IbmBoundary {
    /// How far the boundary moves per unit load factor when it `moves`:
    /// a fixed boundary by its displacement, a (straight) roller by its
    /// normal displacement along its inward normal.
    pub fn motion(&self) -> P2 {
        match self.kind {
            DirichletKind::Fixed => self.value,
            DirichletKind::Roller => {
                let n = self.normal(self.points[0], self.points[1]);
                [self.value[0] * n[0], self.value[0] * n[1]]
            }
        }
    }

    /// The boundary translated by `d`.
    pub fn translated(&self, d: P2) -> IbmBoundary {
        IbmBoundary {
            points: self.points.iter().map(|p| [p[0] + d[0], p[1] + d[1]]).collect(),
            ..self.clone()
        }
    }
}

/// `d(phi)` and `d'(phi)` for bandwidth `delta`.
pub fn dirichlet_function(phi: f64, delta: f64) -> (f64, f64) {
    if phi <= 0.0 {
        (0.0, 0.0)
    } else if phi >= delta {
        (1.0, 0.0)
    } else {
        let s = 1.0 - phi / delta;
        (1.0 - s * s, 2.0 * s / delta)
    }
}

type M2 = [[f64; 2]; 2];

/// A node's 3 x 2 block of a strain operator (Voigt rows, displacement columns).
pub type Op = [[f64; 2]; 3];

fn mul(a: &M2, b: &M2) -> M2 {
    [
        [
            a[0][0] * b[0][0] + a[0][1] * b[1][0],
            a[0][0] * b[0][1] + a[0][1] * b[1][1],
        ],
        [
            a[1][0] * b[0][0] + a[1][1] * b[1][0],
            a[1][0] * b[0][1] + a[1][1] * b[1][1],
        ],
    ]
}

fn add(a: &M2, b: &M2) -> M2 {
    [
        [a[0][0] + b[0][0], a[0][1] + b[0][1]],
        [a[1][0] + b[1][0], a[1][1] + b[1][1]],
    ]
}

const I2: M2 = [[1.0, 0.0], [0.0, 1.0]];

impl IbmBoundary {
    pub fn segments(&self) -> impl Iterator<Item = (P2, P2)> + '_ {
        self.points.windows(2).map(|w| (w[0], w[1]))
    }

    /// Inward unit normal of the segment `a -> b`.
    pub fn normal(&self, a: P2, b: P2) -> P2 {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let l = dx.hypot(dy);
        [-self.side * dy / l, self.side * dx / l]
    }

    /// Signed distance (positive in the material) and the inward normal of
    /// the nearest segment; `None` when the nearest point is one of the
    /// polyline's two ends (the point lies beside the boundary, not across
    /// it, and is not constrained by it).
    pub fn distance(&self, x: P2) -> Option<(f64, P2)> {
        let last = self.points.len() - 2;
        let mut best = (f64::INFINITY, 0.0, [0.0; 2], true);
        for (k, (a, b)) in self.segments().enumerate() {
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let t_raw = ((x[0] - a[0]) * dx + (x[1] - a[1]) * dy) / (dx * dx + dy * dy);
            let t = t_raw.clamp(0.0, 1.0);
            let c = [a[0] + t * dx, a[1] + t * dy];
            let dist = (x[0] - c[0]).hypot(x[1] - c[1]);
            let n = self.normal(a, b);
            if dist < best.0 {
                let signed = (x[0] - c[0]) * n[0] + (x[1] - c[1]) * n[1];
                let beyond_end = (k == 0 && t_raw < 0.0) || (k == last && t_raw > 1.0);
                best = (dist, if signed >= 0.0 { dist } else { -dist }, n, !beyond_end);
            }
        }
        best.3.then_some((best.1, best.2))
    }

    /// `D` of this boundary and its gradient `dD/dx_j` at `x`.
    fn d_matrix(&self, x: P2, delta: f64) -> (M2, [M2; 2]) {
        let Some((phi, n)) = self.distance(x) else {
            return (I2, [[[0.0; 2]; 2]; 2]);
        };
        let (d, dd) = dirichlet_function(phi, delta);
        match self.kind {
            DirichletKind::Fixed => (
                [[d, 0.0], [0.0, d]],
                [0, 1].map(|j| [[dd * n[j], 0.0], [0.0, dd * n[j]]]),
            ),
            DirichletKind::Roller => {
                let nn = [[n[0] * n[0], n[0] * n[1]], [n[1] * n[0], n[1] * n[1]]];
                let dm = [
                    [1.0 - (1.0 - d) * nn[0][0], -(1.0 - d) * nn[0][1]],
                    [-(1.0 - d) * nn[1][0], 1.0 - (1.0 - d) * nn[1][1]],
                ];
                (dm, [0, 1].map(|j| nn.map(|r| r.map(|v| dd * n[j] * v))))
            }
        }
    }

    /// Cells the polyline passes through.
    pub fn cut_cells(&self, grid: &Grid) -> Vec<usize> {
        let mut cells: Vec<usize> = self.pieces(grid).iter().map(|p| p.2).collect();
        cells.sort_unstable();
        cells.dedup();
        cells
    }

    /// Pieces `(a, b, cell)` of the segments inside one cell each.
    pub fn pieces(&self, grid: &Grid) -> Vec<(P2, P2, usize)> {
        let mut out = Vec::new();
        for (a, b) in self.segments() {
            let mut ts = vec![0.0, 1.0];
            for d in 0..2 {
                let (lo, hi) = (a[d].min(b[d]), a[d].max(b[d]));
                if hi - lo < 1e-14 * grid.h {
                    continue;
                }
                let first = ((lo - grid.origin[d]) / grid.h).ceil() as i64;
                let last = ((hi - grid.origin[d]) / grid.h).floor() as i64;
                for k in first..=last {
                    let c = grid.origin[d] + k as f64 * grid.h;
                    ts.push((c - a[d]) / (b[d] - a[d]));
                }
            }
            ts.sort_by(f64::total_cmp);
            ts.dedup_by(|x, y| (*x - *y).abs() < 1e-12);
            for w in ts.windows(2) {
                let p = |t: f64| [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                let (pa, pb) = (p(w[0]), p(w[1]));
                // The cell on the material side of the piece's midpoint.
                let m = p(0.5 * (w[0] + w[1]));
                let n = self.normal(a, b);
                let probe = [m[0] + 1e-9 * grid.h * n[0], m[1] + 1e-9 * grid.h * n[1]];
                if let Some((i, j)) = grid.cell_of(probe) {
                    out.push((pa, pb, j * grid.nx + i));
                }
            }
        }
        out
    }

    /// Gauss points of the band `0 <= phi <= delta`: `(x, weight)`.
    pub fn band_points(&self, grid: &Grid, delta: f64) -> Vec<(P2, f64)> {
        let (xa, wa) = gauss_legendre(self.gauss_points);
        let (xc, wc) = gauss_legendre(3);
        let mut out = Vec::new();
        for (a, b, _) in self.pieces(grid) {
            let len = (b[0] - a[0]).hypot(b[1] - a[1]);
            // The piece's own segment normal (pieces come from one segment).
            let n = {
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                [-self.side * dy / len, self.side * dx / len]
            };
            for (s, ws) in xa.iter().zip(&wa) {
                let t = 0.5 * (1.0 + s);
                let base = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                for (r, wr) in xc.iter().zip(&wc) {
                    let phi = 0.5 * delta * (1.0 + r);
                    out.push((
                        [base[0] + phi * n[0], base[1] + phi * n[1]],
                        ws * wr * 0.25 * len * delta,
                    ));
                }
            }
        }
        out
    }
}

impl IbmBoundary {
    /// Per node of the cells the boundary cuts, how much of it the
    /// boundary constrains and along which directions:
    /// `W_b(n) = int_Gamma_b N_n P_b ds`, with `P_b = I` for a fixed
    /// boundary and `n n^T` for a roller, `N_n` the grid's bilinear
    /// function (3 Gauss points per piece: `N_n` is quadratic along it).
    pub fn constraint_weights(&self, grid: &Grid) -> std::collections::BTreeMap<usize, M2> {
        let mut out: std::collections::BTreeMap<usize, M2> = Default::default();
        let (xg, wg) = gauss_legendre(3);
        for (a, e, _) in self.pieces(grid) {
            let n = self.normal(a, e);
            let len = (e[0] - a[0]).hypot(e[1] - a[1]);
            let p = match self.kind {
                DirichletKind::Fixed => I2,
                DirichletKind::Roller => [[n[0] * n[0], n[0] * n[1]], [n[1] * n[0], n[1] * n[1]]],
            };
            for (xi, wi) in xg.iter().zip(&wg) {
                let t = 0.5 * (1.0 + xi);
                let x = [a[0] + t * (e[0] - a[0]), a[1] + t * (e[1] - a[1])];
                let st = grid_stencil(grid, [x[0] + 1e-9 * grid.h * n[0], x[1] + 1e-9 * grid.h * n[1]]);
                for (k, nk, _) in st.view().iter() {
                    let w = 0.5 * len * wi * nk;
                    let m = out.entry(k).or_insert([[0.0; 2]; 2]);
                    for r in 0..2 {
                        for c in 0..2 {
                            m[r][c] += w * p[r][c];
                        }
                    }
                }
            }
        }
        out
    }
}

/// Share a node's out-of-balance `r` among the constraints acting on it:
/// the implicit boundaries with weights `ws` (their [`IbmBoundary::constraint_weights`]
/// at the node) and the grid's supports, `grid[c]` the weight of a grid
/// support holding component `c` there (0: none). Returns each implicit
/// boundary's share.
///
/// The out-of-balance with the plain test function `N_n e_c` is the
/// virtual work of the supports' tractions: the trial space
/// `u = D S d + S d^a` (C section 3) satisfies the weak form for the test
/// functions `D N_n e_c` only, and `N_n e_c - D N_n e_c = (I - D) N_n e_c`
/// lives in the bands, where `grad (I - D)` (`d'(phi) n`) turns
/// the band integral into `int_Gamma_b N_n (P_b sigma n) ds` as
/// `delta -> 0`. So `r_n = sum_b int_Gamma_b N_n t_b ds`, with each
/// boundary's traction `t_b` in the range of its `P_b` (a roller pushes
/// along its normal only, a grid roller along its axis). Writing each
/// share as `W_b(n) y` with `W_b(n) = int_Gamma_b N_n P_b ds`, the common
/// `y` solves `M y = r_n`, `M = sum_b W_b(n)`: for tractions that are
/// constant over the node's support this is exact (`y` is the traction),
/// and where the constraints' directions are independent and each is
/// one-dimensional (two rollers at a corner, C 5.1; a roller and a grid
/// roller) the split is exact whatever the weights, since then `r_n`
/// has one decomposition along them. Where the directions do not span the
/// plane (one roller, or parallel ones), `M` is singular: `y = M^+ r_n`
/// and what `M` cannot carry goes to the implicit boundaries in proportion
/// to `tr W_b(n)`, so the shares always add up to `r_n` less the grid
/// supports' part (reactions and loads balance). A node serving a single
/// implicit boundary and no grid support gives it all of `r_n`.
pub fn split_reaction(r: P2, ws: &[M2], grid: [f64; 2]) -> Vec<P2> {
    let mut m = [[grid[0], 0.0], [0.0, grid[1]]];
    for w in ws {
        m = add(&m, w);
    }
    let y = {
        let p = pinv_sym(&m);
        [p[0][0] * r[0] + p[0][1] * r[1], p[1][0] * r[0] + p[1][1] * r[1]]
    };
    let apply = |w: &M2| [w[0][0] * y[0] + w[0][1] * y[1], w[1][0] * y[0] + w[1][1] * y[1]];
    let carried = apply(&m);
    let rest = [r[0] - carried[0], r[1] - carried[1]];
    let traces: Vec<f64> = ws.iter().map(|w| w[0][0] + w[1][1]).collect();
    let total: f64 = traces.iter().sum();
    ws.iter()
        .zip(&traces)
        .map(|(w, tr)| {
            let f = if total > 0.0 { tr / total } else { 1.0 / ws.len() as f64 };
            let s = apply(w);
            [s[0] + f * rest[0], s[1] + f * rest[1]]
        })
        .collect()
}

/// Pseudo-inverse of a symmetric positive semi-definite 2 x 2 matrix
/// (rank 1: `m = s v v^T`, `m^+ = m / s^2` with `s = tr m`).
fn pinv_sym(m: &M2) -> M2 {
    let (a, b, c) = (m[0][0], 0.5 * (m[0][1] + m[1][0]), m[1][1]);
    let tr = a + c;
    if tr <= 0.0 {
        return [[0.0; 2]; 2];
    }
    let det = a * c - b * b;
    if det > 1e-10 * tr * tr {
        [[c / det, -b / det], [-b / det, a / det]]
    } else {
        let s = tr * tr;
        [[a / s, b / s], [b / s, c / s]]
    }
}

/// The combined `D = D_1 D_2 ...` and its gradient at `x`.
pub fn d_total(bs: &[IbmBoundary], x: P2, delta: f64) -> (M2, [M2; 2]) {
    let mut d = I2;
    let mut g = [[[0.0; 2]; 2]; 2];
    for b in bs {
        let (db, gb) = b.d_matrix(x, delta);
        for j in 0..2 {
            g[j] = add(&mul(&g[j], &db), &mul(&d, &gb[j]));
        }
        d = mul(&d, &db);
    }
    (d, g)
}

/// Whether `x` is inside the band of (or beyond) any boundary.
pub fn in_band(bs: &[IbmBoundary], x: P2, delta: f64) -> bool {
    bs.iter().any(|b| b.distance(x).is_some_and(|(phi, _)| phi < delta))
}

/// The modified strain operator split as `(B1, B2)` at `x` for a stencil:
/// per node, the 3 x 2 matrices (Voigt rows xx, yy, xy; columns the
/// displacement components).
pub fn b_bar(st: StencilView, d: &M2, g: &[M2; 2]) -> Vec<(Op, Op)> {
    st.iter()
        .map(|(_, w, dw)| {
            let mut b1 = [[0.0; 2]; 3];
            let mut b2 = [[0.0; 2]; 3];
            for l in 0..2 {
                // u_i = N D_il: du_i/dx_j = dN/dx_j D_il + N dD_il/dx_j.
                let grad1 = |i: usize, j: usize| dw[j] * d[i][l];
                let grad2 = |i: usize, j: usize| w * g[j][i][l];
                b1[0][l] = grad1(0, 0);
                b1[1][l] = grad1(1, 1);
                b1[2][l] = grad1(0, 1) + grad1(1, 0);
                b2[0][l] = grad2(0, 0);
                b2[1][l] = grad2(1, 1);
                b2[2][l] = grad2(0, 1) + grad2(1, 0);
            }
            (b1, b2)
        })
        .collect()
}

/// Why the least-squares fit of prescribed boundary values (B (36)) failed.
#[derive(Clone, Debug, PartialEq)]
pub enum FitError {
    /// The dense eigen-decomposition of the fit's matrix failed.
    Eigen(String),
    /// The fit is singular or ill-conditioned (eigenvalues `lo .. hi`):
    /// grid node `node` at `position` barely touches the boundary.
    IllConditioned {
        lo: f64,
        hi: f64,
        node: usize,
        position: P2,
    },
    /// The Cholesky factorisation of the fit's matrix failed.
    Factor(String),
}

impl std::fmt::Display for FitError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FitError::Eigen(e) => write!(f, "boundary least-squares fit: eigenvalues failed: {e}"),
            FitError::IllConditioned { lo, hi, node, position } => write!(
                f,
                "the least-squares fit of the prescribed boundary values is singular or ill-conditioned \
                 (eigenvalues {lo:.3e} .. {hi:.3e}): node {node} at ({:.6}, {:.6}) barely touches the boundary; \
                 leave fit_regularisation unset (automatic) or set it (e.g. 1e-10)",
                position[0], position[1]
            ),
            FitError::Factor(e) => write!(f, "boundary least-squares fit: {e}"),
        }
    }
}

impl std::error::Error for FitError {}

/// The Tikhonov weight an automatic fit takes in a step where the plain
/// fit B (36) is singular: it decides the values of nodes the boundary
/// barely touches (pulling them towards the exact field there) and changes
/// the others by about this share. 1e-10 makes the fit's matrix
/// positive definite at every h of the plate with a hole (h = 1/2..1/32).
pub const AUTO_FIT_REGULARISATION: f64 = 1e-10;

/// Global least-squares fit of the exact displacement on the boundaries
/// with `exact_field` (B (36)); writes the nodal values into `da` and
/// returns the Tikhonov weight it used (0: the plain fit). With no weight
/// set on any boundary the plain fit is tried first and, if it is singular,
/// repeated with [`AUTO_FIT_REGULARISATION`].
fn fit_exact(
    bs: &[IbmBoundary],
    grid: &Grid,
    ex: &ExactSolution,
    dlambda: f64,
    da: &mut [P2],
) -> Result<f64, FitError> {
    let fitted = bs.iter().filter(|b| b.exact_field);
    let set = fitted.filter_map(|b| b.fit_regularisation).reduce(f64::max);
    match set {
        Some(eps) => fit_exact_with(bs, grid, ex, dlambda, eps, da).map(|_| eps),
        None => match fit_exact_with(bs, grid, ex, dlambda, 0.0, da) {
            Ok(()) => Ok(0.0),
            Err(FitError::IllConditioned { .. }) => {
                fit_exact_with(bs, grid, ex, dlambda, AUTO_FIT_REGULARISATION, da).map(|_| AUTO_FIT_REGULARISATION)
            }
            Err(e) => Err(e),
        },
    }
}

/// [`fit_exact`] with Tikhonov weight `eps`.
fn fit_exact_with(
    bs: &[IbmBoundary],
    grid: &Grid,
    ex: &ExactSolution,
    dlambda: f64,
    eps: f64,
    da: &mut [P2],
) -> Result<(), FitError> {
    use std::collections::BTreeMap;
    let mut index: BTreeMap<usize, usize> = BTreeMap::new();
    // Per Gauss point: the stencil's (node, N) pairs, the weight, the value.
    struct Sample {
        nodes: Vec<(usize, f64)>,
        w: f64,
        u: P2,
    }
    let mut entries: Vec<Sample> = Vec::new();
    let (xg, wg) = gauss_legendre(3);
    for b in bs.iter().filter(|b| b.exact_field) {
        for (a, e, _) in b.pieces(grid) {
            let n = b.normal(a, e);
            let len = (e[0] - a[0]).hypot(e[1] - a[1]);
            for (xi, wi) in xg.iter().zip(&wg) {
                let t = 0.5 * (1.0 + xi);
                let x = [a[0] + t * (e[0] - a[0]), a[1] + t * (e[1] - a[1])];
                let st = grid_stencil(grid, [x[0] + 1e-9 * grid.h * n[0], x[1] + 1e-9 * grid.h * n[1]]);
                let nodes: Vec<(usize, f64)> = st.view().iter().map(|(k, w, _)| (k, w)).collect();
                for &(k, _) in &nodes {
                    let len_before = index.len();
                    index.entry(k).or_insert(len_before);
                }
                entries.push(Sample {
                    nodes,
                    w: 0.5 * len * wi,
                    u: ex.displacement(x).map(|u| u * dlambda),
                });
            }
        }
    }
    let m = index.len();
    if m == 0 {
        return Ok(());
    }
    let mut mat = faer::Mat::<f64>::zeros(m, m);
    let mut rhs = faer::Mat::<f64>::zeros(m, 2);
    for Sample { nodes, w, u } in &entries {
        for &(k, nk) in nodes {
            let i = index[&k];
            for &(l, nl) in nodes {
                mat[(i, index[&l])] += w * nk * nl;
            }
            for c in 0..2 {
                rhs[(i, c)] += w * nk * u[c];
            }
        }
    }
    if eps > 0.0 {
        // Tikhonov term towards the exact field at the nodes: decides the
        // values of nodes the boundary barely touches, negligible elsewhere.
        let scale = eps * (0..m).map(|i| mat[(i, i)]).sum::<f64>() / m as f64;
        for (&k, &i) in &index {
            let u = ex.displacement(grid.node_position(k)).map(|v| v * dlambda);
            mat[(i, i)] += scale;
            rhs[(i, 0)] += scale * u[0];
            rhs[(i, 1)] += scale * u[1];
        }
    }
    let evd = mat.self_adjoint_eigen(faer::Side::Lower);
    crate::vector_state::after_wide_kernels();
    let evd = evd.map_err(|e| FitError::Eigen(format!("{e:?}")))?;
    let (lo, hi) = (evd.S()[0], evd.S()[m - 1]);
    if !(lo > 1e-13 * hi) {
        // The node that carries most of the weakest mode: the one whose
        // basis function barely touches the boundary.
        let weakest = evd.U().col(0);
        let (&node, _) = index
            .iter()
            .max_by(|a, b| weakest[*a.1].abs().total_cmp(&weakest[*b.1].abs()))
            .expect("m > 0");
        return Err(FitError::IllConditioned {
            lo,
            hi,
            node,
            position: grid.node_position(node),
        });
    }
    let llt = mat.llt(faer::Side::Lower);
    crate::vector_state::after_wide_kernels();
    let llt = llt.map_err(|e| FitError::Factor(format!("{e:?}")))?;
    use faer::linalg::solvers::Solve;
    llt.solve_in_place(&mut rhs);
    crate::vector_state::after_wide_kernels();
    for (&k, &i) in &index {
        da[k] = [rhs[(i, 0)], rhs[(i, 1)]];
    }
    Ok(())
}

/// The standard-basis stencil at `x` (band integration uses the grid's
/// bilinear functions).
pub fn grid_stencil(grid: &Grid, x: P2) -> Stencil {
    stencil(grid, BasisKind::Standard, x, [0.0; 2])
}

/// What an implicit boundary did in a step.
#[derive(Clone, Debug, PartialEq)]
pub struct IbmReport {
    pub name: String,
    /// Cells the boundary cuts.
    pub cut_cells: usize,
    /// Force the boundary exerts on the material at the end of the step
    /// (N per unit thickness): the out-of-balance `f_int - f_ext` (every
    /// load, tractions included) of its cut cells' nodes, each node's
    /// shared with the other constraints acting there ([`split_reaction`]).
    pub reaction: P2,
    /// Largest deviation of the step's displacement increment on the
    /// boundary from its prescribed increment (m).
    pub violation: f64,
    /// Root mean square of that deviation along the boundary (m).
    pub violation_rms: f64,
    /// The Tikhonov weight of the least-squares fit of its values in this
    /// step (0: the plain fit B (36), or no fit).
    pub fit_regularisation: f64,
}

/// Per-step implicit-boundary data: bandwidth, the prescribed increments on
/// nodes (`d^a`), and which points lie in a band.
pub struct IbmStep<'a> {
    pub bs: &'a [IbmBoundary],
    pub delta: f64,
    /// `d^a` increment per grid node.
    pub da: Vec<P2>,
    pub in_band: Vec<bool>,
    /// The Tikhonov weight the step's least-squares fit used (0: plain, or
    /// no fit).
    pub fit_regularisation: f64,
}

impl<'a> IbmStep<'a> {
    /// Prepare a step: `d^a` increments for the load-factor increment
    /// `dlambda`. Boundaries with `exact_field` get their nodal values from
    /// the global least-squares fit `(int N^T N dS) d^a = int N^T u dS`
    /// (B (36)) over all of them at once; an ill-conditioned fit is an error.
    pub fn new(
        bs: &'a [IbmBoundary],
        grid: &Grid,
        xs: &[P2],
        delta_over_h: f64,
        dlambda: f64,
        exact: Option<&ExactSolution>,
    ) -> Result<IbmStep<'a>, FitError> {
        let delta = delta_over_h * grid.h;
        let mut da = vec![[0.0; 2]; grid.num_nodes()];
        for b in bs.iter().filter(|b| !b.exact_field) {
            for (a, e, cell) in b.pieces(grid) {
                let (i, j) = (cell % grid.nx, cell / grid.nx);
                for node in grid.cell_nodes(i, j) {
                    match b.kind {
                        DirichletKind::Fixed => da[node] = [b.value[0] * dlambda, b.value[1] * dlambda],
                        DirichletKind::Roller => {
                            // Set only the normal component, so rollers meeting
                            // at a corner each keep their own value.
                            let n = b.normal(a, e);
                            let old = da[node][0] * n[0] + da[node][1] * n[1];
                            let dv = b.value[0] * dlambda - old;
                            da[node] = [da[node][0] + dv * n[0], da[node][1] + dv * n[1]];
                        }
                    }
                }
            }
        }
        let fit_regularisation = match exact {
            Some(ex) => fit_exact(bs, grid, ex, dlambda, &mut da)?,
            None => 0.0,
        };
        let in_band = xs.iter().map(|&x| in_band(bs, x, delta)).collect();
        Ok(IbmStep {
            bs,
            delta,
            da,
            in_band,
            fit_regularisation,
        })
    }

    /// Strain operator rows of a point: `B_bar` (for `d`) per stencil node,
    /// and the plain `B` (for `d^a`).
    pub fn point_b(&self, st: StencilView, x: P2) -> (Vec<Op>, Vec<Op>) {
        let plain = plain_b(st);
        if !in_band(self.bs, x, self.delta) {
            return (plain.clone(), plain);
        }
        let (d, g) = d_total(self.bs, x, self.delta);
        let (b1, b2): (Vec<Op>, Vec<Op>) = b_bar(st, &d, &g).into_iter().unzip();
        (add_ops(&b1, 1.0, &b2), plain)
    }
}

/// The plain strain operator `B` of a stencil, per node.
pub fn plain_b(st: StencilView) -> Vec<Op> {
    st.iter()
        .map(|(_, _, g)| [[g[0], 0.0], [0.0, g[1]], [g[1], g[0]]])
        .collect()
}

/// `a + s b`, node by node.
pub fn add_ops(a: &[Op], s: f64, b: &[Op]) -> Vec<Op> {
    a.iter()
        .zip(b)
        .map(|(x, y)| [0, 1, 2].map(|r| [x[r][0] + s * y[r][0], x[r][1] + s * y[r][1]]))
        .collect()
}

/// `sum_rows A^T C B` for per-node 3 x 2 operators: adds `w A^T C B` into
/// the row-major `2m x 2m` matrix `out`.
pub fn add_atcb(a: &[[[f64; 2]; 3]], c: &[[f64; 3]; 3], b: &[[[f64; 2]; 3]], w: f64, out: &mut [f64]) {
    let m2 = 2 * a.len();
    for (ka, ra) in a.iter().enumerate() {
        for i in 0..2 {
            // (A^T C) row for (ka, i).
            let mut at_c = [0.0; 3];
            for s in 0..3 {
                at_c[s] = (0..3).map(|r| ra[r][i] * c[r][s]).sum();
            }
            for (kb, rb) in b.iter().enumerate() {
                for j in 0..2 {
                    let v: f64 = (0..3).map(|s| at_c[s] * rb[s][j]).sum();
                    out[(2 * ka + i) * m2 + 2 * kb + j] += w * v;
                }
            }
        }
    }
}

/// A band block: its nodes and dense row-major `2m x 2m` matrix.
pub type BandBlock = (Vec<usize>, Vec<f64>);

/// A point's deformation-gradient operator inside a band, per stencil node
/// and displacement component `l`: `G[l][i][j] = D_il dS/dx_j + dD_il/dx_j S`,
/// so that `dF = I + sum_k sum_l d_kl G_k[l] + grad(S d^a)` (the finite
/// deformation form of `B_bar = B1 + B2`).
pub type GradOp = [[[f64; 2]; 2]; 2];

/// Add `w B_bar^T C (B d^a)` to the nodal force `f` (the strain of the
/// prescribed field moved to the right-hand side).
pub fn add_fd(st: StencilView, bbar: &[Op], c: &[[f64; 3]; 3], da: &[P2], w: f64, f: &mut [P2]) {
    let g = st.gradient(|n| da[n]);
    add_bt_c_eps(st, bbar, c, [g[0][0], g[1][1], g[0][1] + g[1][0]], w, f);
}

/// Add `w B^T C eps` to the nodal force `f`, for per-node operators `b`
/// of stencil `st` and a strain `eps`.
pub fn add_bt_c_eps(st: StencilView, b: &[Op], c: &[[f64; 3]; 3], eps: [f64; 3], w: f64, f: &mut [P2]) {
    if eps == [0.0; 3] {
        return;
    }
    let sig = mul3(c, eps);
    for (k, (n, _, _)) in st.iter().enumerate() {
        for comp in 0..2 {
            f[n][comp] += w * (0..3).map(|r| b[k][r][comp] * sig[r]).sum::<f64>();
        }
    }
}

/// A material point's position and small-strain elasticity matrix.
type PointC = (P2, [[f64; 3]; 3]);

/// The elasticity the band takes at each of its points: that of the
/// material point nearest to it in its cell (or the cells around), so that
/// bodies of different stiffness under one boundary each get their own,
/// also where an interface between them crosses a cut cell.
pub struct BandMaterial {
    /// Per grid cell holding points: the points, with their `C` (a map,
    /// so a large grid costs nothing where there is no material).
    cells: std::collections::HashMap<usize, Vec<PointC>>,
    nx: usize,
    ny: usize,
    /// Volume-weighted mean over all points (for a band point with no
    /// material point within a cell of it, which only a boundary past the
    /// material's edge meets).
    mean: [[f64; 3]; 3],
}

impl BandMaterial {
    /// `c_of(p)` is point `p`'s small-strain elasticity matrix (Pa).
    pub fn new(grid: &Grid, xs: &[P2], vol: &[f64], c_of: &dyn Fn(usize) -> [[f64; 3]; 3]) -> BandMaterial {
        let mut cells: std::collections::HashMap<usize, Vec<PointC>> = Default::default();
        let (mut total, mut total_v) = ([[0.0; 3]; 3], 0.0);
        for p in (0..xs.len()).filter(|&p| vol[p] > 0.0) {
            let c = c_of(p);
            for r in 0..3 {
                for s in 0..3 {
                    total[r][s] += vol[p] * c[r][s];
                }
            }
            total_v += vol[p];
            if let Some((i, j)) = grid.cell_of(xs[p]) {
                cells.entry(j * grid.nx + i).or_default().push((xs[p], c));
            }
        }
        let mean = if total_v > 0.0 {
            total.map(|r| r.map(|v| v / total_v))
        } else {
            [[0.0; 3]; 3]
        };
        BandMaterial {
            cells,
            nx: grid.nx,
            ny: grid.ny,
            mean,
        }
    }

    /// `C` at a band point `x` (on a tie, the cell first in the grid's order).
    pub fn at(&self, grid: &Grid, x: P2) -> [[f64; 3]; 3] {
        let Some((i, j)) = grid.cell_of(x) else {
            return self.mean;
        };
        let nearest = |cells: &mut dyn Iterator<Item = usize>| {
            cells
                .flat_map(|c| self.cells.get(&c).into_iter().flatten())
                .min_by(|a, b| dist2(a.0, x).total_cmp(&dist2(b.0, x)))
                .map(|&(_, c)| c)
        };
        if let Some(c) = nearest(&mut std::iter::once(j * self.nx + i)) {
            return c;
        }
        let (i, j) = (i as i64, j as i64);
        let mut ring = (-1..=1)
            .flat_map(|dj| (-1..=1).map(move |di| (i + di, j + dj)))
            .filter(|&(a, b)| a >= 0 && b >= 0 && a < self.nx as i64 && b < self.ny as i64)
            .map(|(a, b)| b as usize * self.nx + a as usize);
        nearest(&mut ring).unwrap_or(self.mean)
    }
}

fn dist2(a: P2, b: P2) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

impl IbmStep<'_> {
    /// The band's contribution (C (18)-(27)): per cut cell a block
    /// `int_band B_bar^T C B_bar - B^T C B` over the grid's bilinear
    /// functions of that cell, and the band's part of `f_d`,
    /// `int_band (B_bar - B)^T C B d^a`, per node.
    ///
    /// The points integrate the band as if `D = I` (with the plain `B`);
    /// the band adds what makes its energy that of the trial space: `K2 +
    /// K2^T + K3` of C (18) and `K1`'s own `D`-weighting there. Leaving the
    /// last out costs an O(delta/h) stress error in the cells along the
    /// boundary (docs/verification.md).
    pub fn band(&self, grid: &Grid, material: &BandMaterial) -> (Vec<BandBlock>, Vec<P2>) {
        let mut f_d = vec![[0.0; 2]; grid.num_nodes()];
        let mut band: std::collections::BTreeMap<(u32, u32, u8, u8), BandBlock> = Default::default();
        for b in self.bs {
            for (x, w) in b.band_points(grid, self.delta) {
                let owned = grid_stencil(grid, x);
                let st = owned.view();
                let c = material.at(grid, x);
                let (dm, g) = d_total(self.bs, x, self.delta);
                let (b1, b2): (Vec<Op>, Vec<Op>) = b_bar(st, &dm, &g).into_iter().unzip();
                let entry = band
                    .entry(st.key())
                    .or_insert_with(|| (st.nodes().collect(), vec![0.0; 4 * st.len() * st.len()]));
                let plain = plain_b(st);
                let bbar = add_ops(&b1, 1.0, &b2);
                add_atcb(&bbar, &c, &bbar, w, &mut entry.1);
                add_atcb(&plain, &c, &plain, -w, &mut entry.1);
                add_fd(st, &add_ops(&bbar, -1.0, &plain), &c, &self.da, w, &mut f_d);
            }
        }
        (band.into_values().collect(), f_d)
    }

    /// A point's [`GradOp`] per stencil node when it lies in a band; `None`
    /// elsewhere (there `D = I` and `dF = I + grad(S (d + d^a))`).
    pub fn gradient_ops(&self, st: StencilView, x: P2) -> Option<Vec<GradOp>> {
        if !in_band(self.bs, x, self.delta) {
            return None;
        }
        let (d, g) = d_total(self.bs, x, self.delta);
        Some(
            st.iter()
                .map(|(_, w, dw)| {
                    let mut op = [[[0.0; 2]; 2]; 2];
                    for l in 0..2 {
                        for i in 0..2 {
                            for j in 0..2 {
                                op[l][i][j] = d[i][l] * dw[j] + w * g[j][i][l];
                            }
                        }
                    }
                    op
                })
                .collect(),
        )
    }

    /// Move a point at `x` with nodal increments `d` (the unknowns) and the
    /// prescribed `d^a`: `D S d + S d^a`.
    pub fn point_increment(&self, st: StencilView, x: P2, d: &[P2]) -> P2 {
        let nd = st.interpolate(|n| d[n]);
        let na = st.interpolate(|n| self.da[n]);
        if !in_band(self.bs, x, self.delta) {
            return [nd[0] + na[0], nd[1] + na[1]];
        }
        let (dm, _) = d_total(self.bs, x, self.delta);
        [
            dm[0][0] * nd[0] + dm[0][1] * nd[1] + na[0],
            dm[1][0] * nd[0] + dm[1][1] * nd[1] + na[1],
        ]
    }

    /// The weight of the grid support holding component `c` of node `n`
    /// for [`split_reaction`]: `int N_n ds` over the grid line through `n`
    /// that the support holds (the edges to neighbours held in the same
    /// component), where it lies in the material as the implicit
    /// boundaries bound it (`phi >= 0` for each, or beside its ends).
    fn grid_weight(&self, grid: &Grid, free: &dyn Fn(usize, usize) -> bool, n: usize, c: usize) -> f64 {
        let (i, j) = grid.node_ij(n);
        let x0 = grid.node_position(n);
        let inside = |x: P2| self.bs.iter().all(|b| b.distance(x).is_none_or(|(phi, _)| phi >= 0.0));
        let (xg, wg) = gauss_legendre(3);
        let mut w = 0.0;
        for (di, dj) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
            let (a, b) = (i as i64 + di, j as i64 + dj);
            if a < 0 || b < 0 || a > grid.nx as i64 || b > grid.ny as i64 {
                continue;
            }
            let m = grid.node(a as usize, b as usize);
            if free(m, c) {
                continue;
            }
            let x1 = grid.node_position(m);
            for (xi, wi) in xg.iter().zip(&wg) {
                let t = 0.5 * (1.0 + xi);
                let x = [x0[0] + t * (x1[0] - x0[0]), x0[1] + t * (x1[1] - x0[1])];
                if inside(x) {
                    w += 0.5 * grid.h * wi * (1.0 - t);
                }
            }
        }
        w
    }

    /// Reports of the boundaries after a step, and the work their reactions
    /// did in it (trapezoidal). `free(node, component)` tells which dofs
    /// are unknowns of the step; the others are held by the grid's own
    /// supports (or carry no material).
    ///
    /// `residual0` and `residual` are the out-of-balance of the material
    /// (internal minus every external force, per node; at grid-held dofs
    /// the internal force) at the start and the end of the step: where the
    /// implicit boundaries act, it is their reaction. Where a node serves
    /// one boundary only, that boundary takes its whole out-of-balance;
    /// where several constraints meet, [`split_reaction`] shares it out.
    /// The violation compares the increment on the boundary
    /// (`D S d + S d^a` at phi = 0) with the prescribed one.
    #[allow(clippy::too_many_arguments)]
    pub fn reports(
        &self,
        grid: &Grid,
        free: &dyn Fn(usize, usize) -> bool,
        residual0: &[P2],
        residual: &[P2],
        nodal_d: &[P2],
        exact: Option<&ExactSolution>,
        dlambda: f64,
    ) -> (Vec<IbmReport>, f64) {
        // Per boundary: its cut cells and their nodes.
        let cut: Vec<(Vec<usize>, Vec<usize>)> = self
            .bs
            .iter()
            .map(|b| {
                let cells = b.cut_cells(grid);
                let mut nodes: Vec<usize> = cells
                    .iter()
                    .flat_map(|&c| grid.cell_nodes(c % grid.nx, c / grid.nx))
                    .collect();
                nodes.sort_unstable();
                nodes.dedup();
                (cells, nodes)
            })
            .collect();
        // Work of the reactions: trapezoidal on the increments of the free
        // dofs of the cut cells' nodes (grid-prescribed dofs count their
        // reactions' work with the other grid constraints; elsewhere the
        // out-of-balance is the remap's, not a support's).
        let mut support: Vec<usize> = cut.iter().flat_map(|(_, nodes)| nodes.iter().copied()).collect();
        support.sort_unstable();
        support.dedup();
        let mut work = 0.0;
        for &n in &support {
            for c in (0..2).filter(|&c| free(n, c)) {
                work += 0.5 * (residual0[n][c] + residual[n][c]) * (nodal_d[n][c] + self.da[n][c]);
            }
        }
        // Reactions: each node's out-of-balance shared among the
        // constraints that act on it.
        let weights: Vec<std::collections::BTreeMap<usize, M2>> =
            self.bs.iter().map(|b| b.constraint_weights(grid)).collect();
        let mut at_node: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
        for (k, (_, nodes)) in cut.iter().enumerate() {
            for &n in nodes {
                at_node.entry(n).or_default().push(k);
            }
        }
        let mut reactions = vec![[0.0; 2]; self.bs.len()];
        for (&n, list) in &at_node {
            let ws: Vec<M2> = list
                .iter()
                .map(|&k| weights[k].get(&n).copied().unwrap_or([[0.0; 2]; 2]))
                .collect();
            let grid_held: [f64; 2] = [0, 1].map(|c| {
                if free(n, c) {
                    0.0
                } else {
                    self.grid_weight(grid, free, n, c)
                }
            });
            let shares = split_reaction(residual[n], &ws, grid_held);
            for (&k, s) in list.iter().zip(shares) {
                reactions[k][0] += s[0];
                reactions[k][1] += s[1];
            }
        }
        let mut reports = Vec::new();
        for ((b, (cells, _)), reaction) in self.bs.iter().zip(&cut).zip(reactions) {
            // Violation: the increment on the boundary (phi = 0) against the
            // prescribed one, sampled at each piece's ends (for the largest)
            // and its three Gauss points (for the root mean square along the
            // boundary).
            let mut violation = 0.0f64;
            let (xg, wg) = gauss_legendre(3);
            let samples: Vec<(f64, f64)> = [(0.0, 0.0), (1.0, 0.0)]
                .into_iter()
                .chain(xg.iter().zip(&wg).map(|(x, w)| (0.5 * (1.0 + x), 0.5 * w)))
                .collect();
            let (mut sum_sq, mut length) = (0.0, 0.0);
            for (a, e, _) in b.pieces(grid) {
                let n = b.normal(a, e);
                let len = (e[0] - a[0]).hypot(e[1] - a[1]);
                for &(t, w) in &samples {
                    let x = [a[0] + t * (e[0] - a[0]), a[1] + t * (e[1] - a[1])];
                    let st = grid_stencil(grid, [x[0] + 1e-12 * grid.h * n[0], x[1] + 1e-12 * grid.h * n[1]]);
                    let (dm, _) = d_total(self.bs, x, self.delta);
                    let nd = st.view().interpolate(|k| nodal_d[k]);
                    let na = st.view().interpolate(|k| self.da[k]);
                    let u = [
                        dm[0][0] * nd[0] + dm[0][1] * nd[1] + na[0],
                        dm[1][0] * nd[0] + dm[1][1] * nd[1] + na[1],
                    ];
                    let target = match (exact, b.exact_field) {
                        (Some(ex), true) => ex.displacement(x).map(|v| v * dlambda),
                        _ => [b.value[0] * dlambda, b.value[1] * dlambda],
                    };
                    let v = match b.kind {
                        DirichletKind::Fixed => (u[0] - target[0]).hypot(u[1] - target[1]),
                        DirichletKind::Roller => (u[0] * n[0] + u[1] * n[1] - b.value[0] * dlambda).abs(),
                    };
                    violation = violation.max(v);
                    sum_sq += w * len * v * v;
                    length += w * len;
                }
            }
            reports.push(IbmReport {
                name: b.name.clone(),
                cut_cells: cells.len(),
                reaction,
                violation,
                violation_rms: if length > 0.0 { (sum_sq / length).sqrt() } else { 0.0 },
                fit_regularisation: if b.exact_field { self.fit_regularisation } else { 0.0 },
            });
        }
        (reports, work)
    }
}

/// The nodes' whole motion: the increments `d` plus the implicit
/// boundaries' prescribed `d^a` (just `d` without them).
pub fn nodal_motion(nodal_d: &[P2], ibm: Option<&IbmStep>) -> Vec<P2> {
    match ibm {
        Some(s) => nodal_d
            .iter()
            .zip(&s.da)
            .map(|(a, b)| [a[0] + b[0], a[1] + b[1]])
            .collect(),
        None => nodal_d.to_vec(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fixed straight (or polyline) boundary through `points`, the
    /// material on its left, prescribing zero.
    fn line(points: &[P2]) -> IbmBoundary {
        IbmBoundary {
            name: "line".into(),
            kind: DirichletKind::Fixed,
            points: points.to_vec(),
            side: 1.0,
            value: [0.0, 0.0],
            gauss_points: 2,
            exact_field: false,
            fit_regularisation: None,
            moves: false,
            spline: None,
        }
    }

    /// Which dofs are free when the grid holds `u_x` on its left and right
    /// columns and `u_y` on its bottom and top rows.
    fn held_at_the_edges(grid: &Grid) -> impl Fn(usize, usize) -> bool + '_ {
        move |n, c| {
            let (i, j) = grid.node_ij(n);
            match c {
                0 => i != 0 && i != grid.nx,
                _ => j != 0 && j != grid.ny,
            }
        }
    }

    /// A step of the boundaries `bs` with the band 1e-6 h and the nodal
    /// prescribed increments `da`.
    fn step_with(bs: &[IbmBoundary], da: Vec<P2>) -> IbmStep<'_> {
        IbmStep {
            bs,
            delta: 1e-6,
            da,
            in_band: vec![],
            fit_regularisation: 0.0,
        }
    }

    /// `grid_weight` is `int N_n ds` over the grid lines from `n` to the
    /// neighbours held in the same component, inside the material: each
    /// whole edge gives `int_0^h (1 - s/h) ds = h/2`. A 4 x 4 grid of unit
    /// cells, the material above a fixed boundary at y = 0.5, `u_x` held on
    /// the columns x = 0 and x = 4 (the grid's edges) and `u_y` on the rows
    /// y = 0 and y = 4. The Gauss points of a whole edge weigh `(1 - t)`
    /// exactly (degree 1), so the weights are h/2 per edge to round-off.
    #[test]
    fn grid_weight_is_the_held_grid_lines_inside_the_material() {
        let grid = Grid {
            origin: [0.0, 0.0],
            h: 1.0,
            nx: 4,
            ny: 4,
        };
        let bs = [line(&[[-1.0, 0.5], [5.0, 0.5]])];
        let step = step_with(&bs, vec![[0.0; 2]; grid.num_nodes()]);
        let free = held_at_the_edges(&grid);
        let h = grid.h;
        for (i, j, c, want) in [
            // On a held column: the edges up and down it.
            (0, 2, 0, h),
            (4, 2, 0, h),
            // Beside one: the edge across to it.
            (1, 2, 0, 0.5 * h),
            (3, 2, 0, 0.5 * h),
            // On the held top row: the edges along it.
            (2, 4, 1, h),
            // Where a held column meets the held top row, each component
            // has one edge.
            (0, 4, 0, 0.5 * h),
            (0, 4, 1, 0.5 * h),
            // The bottom row lies outside the material.
            (2, 0, 1, 0.0),
            // Away from the held lines, nothing.
            (2, 2, 0, 0.0),
        ] {
            let w = step.grid_weight(&grid, &free, grid.node(i, j), c);
            assert!((w - want).abs() < 1e-15, "node ({i}, {j}) component {c}: {w} vs {want}");
        }
        // With the base below the grid the bottom row is in the material:
        // its edges count like the top row's. The held column's bottom
        // node has one edge, up the column (the line below it is off the
        // grid and, past the base, partly outside the material).
        let mut low = bs[0].clone();
        low.points = vec![[-1.0, -0.5], [5.0, -0.5]];
        let low = [low];
        let step = IbmStep { bs: &low, ..step };
        for (i, j, c, want) in [(2, 0, 1, h), (2, 1, 1, 0.5 * h), (4, 0, 1, 0.5 * h), (0, 0, 0, 0.5 * h)] {
            let w = step.grid_weight(&grid, &free, grid.node(i, j), c);
            assert!(
                (w - want).abs() < 1e-15,
                "low base, node ({i}, {j}) component {c}: {w} vs {want}"
            );
        }
    }

    /// The end node of a held grid line, next to a boundary across the
    /// line: its one edge must run from the node towards its neighbour,
    /// with the edge's true length. Cells of h = 0.5 (so that dividing by
    /// the edge's length is not multiplying by it), `u_x` held on the
    /// columns x = 0 and x = 2 and `u_y` on the rows y = 0 and y = 2, one
    /// fixed straight boundary with the material on its left. Each case
    /// wants one whole edge inside the material, h/2; an edge that ran the
    /// other way, too far, or from the wrong place would cross the
    /// boundary (the 3-point Gauss rule then gives 0.469 h or less).
    #[test]
    fn a_held_lines_end_node_weighs_its_own_edge() {
        let grid = Grid {
            origin: [0.0, 0.0],
            h: 0.5,
            nx: 4,
            ny: 4,
        };
        let free = held_at_the_edges(&grid);
        let h = grid.h;
        for (points, (i, j, c)) in [
            // Rows: a wall a half cell beyond the right end (material to
            // its left), or a cell and a half from the left end.
            ([[2.25, -1.0], [2.25, 3.0]], (4, 0, 1)),
            ([[0.75, -1.0], [0.75, 3.0]], (0, 0, 1)),
            // Columns: a boundary a half cell above the top end
            // (material below), or a cell and a half above the bottom.
            ([[3.0, 2.25], [-1.0, 2.25]], (0, 4, 0)),
            ([[3.0, 0.75], [-1.0, 0.75]], (0, 0, 0)),
            // The far end of each line with the material beyond a boundary
            // a half cell before the near end: the far end's edge, and
            // only that, is inside.
            ([[-0.25, 3.0], [-0.25, -1.0]], (4, 0, 1)),
            ([[-1.0, -0.25], [3.0, -0.25]], (0, 4, 0)),
        ] {
            let bs = [line(&points)];
            let step = step_with(&bs, vec![[0.0; 2]; grid.num_nodes()]);
            let w = step.grid_weight(&grid, &free, grid.node(i, j), c);
            assert!(
                (w - 0.5 * h).abs() < 1e-15,
                "wall {points:?}, node ({i}, {j}) component {c}: {w} vs {}",
                0.5 * h
            );
        }
    }

    /// The violation a step reports: on the boundary (phi = 0, where D
    /// vanishes) the increment is the interpolated `d^a`, so a linear `d^a`
    /// gives a deviation from the prescribed increment whose square is a
    /// quadratic along the boundary, which hats reproduce exactly and
    /// 3-point Gauss integrates exactly on each piece. A 4 x 4 grid of unit
    /// cells, `d^a = (s x, s x)` with s = 0.01, prescribed values (0.02,
    /// 0.01) at the load-factor increment 0.5, and the line y = 0.5 + x/2
    /// from x = 0 to 4 inside the grid (inward normal n = (-1, 2)/sqrt 5):
    /// - fixed: `v^2 = (s x - 0.01)^2 + (s x - 0.005)^2 = 10^-4 ((x - 1)^2 +
    ///   (x - 0.5)^2)`, the largest 0.01 sqrt 21.25 (at x = 4), the root
    ///   mean square over the arc `sqrt((1/4) int_0^4 v^2 dx) = 0.01
    ///   sqrt(71/12)`;
    /// - roller: `v = |d^a . n - 0.01| = 0.01 |x/sqrt 5 - 1|`, the largest
    ///   0.01 (at x = 0), the root mean square 0.01 sqrt((64/15 - 16/sqrt 5
    ///   + 4)/4).
    #[test]
    fn the_violation_is_the_deviation_along_the_boundary() {
        let grid = Grid {
            origin: [0.0, 0.0],
            h: 1.0,
            nx: 4,
            ny: 4,
        };
        let s = 0.01;
        let nn = grid.num_nodes();
        let da: Vec<P2> = (0..nn).map(|n| [s * grid.node_position(n)[0]; 2]).collect();
        let zero = vec![[0.0; 2]; nn];
        let free = |_: usize, _: usize| true;
        let r5 = 5f64.sqrt();
        for (kind, largest, rms) in [
            (
                DirichletKind::Fixed,
                0.01 * 21.25f64.sqrt(),
                0.01 * (71.0f64 / 12.0).sqrt(),
            ),
            (
                DirichletKind::Roller,
                0.01,
                0.01 * ((64.0 / 15.0 - 16.0 / r5 + 4.0) / 4.0f64).sqrt(),
            ),
        ] {
            let bs = [IbmBoundary {
                kind,
                value: [0.02, 0.01],
                ..line(&[[-1.0, 0.0], [5.0, 3.0]])
            }];
            let step = step_with(&bs, da.clone());
            let (reports, _) = step.reports(&grid, &free, &zero, &zero, &zero, None, 0.5);
            let r = &reports[0];
            // The stencils are taken 1e-12 h off the boundary (to pick the
            // cell on its material side), which moves v by up to
            // sqrt 2 s 1e-12 h = 1.4e-14; round-off is smaller.
            assert!(
                (r.violation - largest).abs() < 3e-14 && (r.violation_rms - rms).abs() < 3e-14,
                "{kind:?}: largest {} vs {largest}, rms {} vs {rms}",
                r.violation,
                r.violation_rms
            );
        }
    }

    /// The least-squares fit of B (36), `(int N^T N dS) d^a = int N^T u dS`,
    /// leaves a misfit orthogonal to every fitted node's function along the
    /// boundary: `int N_k (N d^a - u) dS = 0`. Checked with an integral of
    /// the test's own: the polygon (a circle of radius 1.3 m in 40 chords,
    /// on cells of 0.5 m) split at the grid lines by hand, 5-point Gauss
    /// on each piece where the fit uses 3 (exact: the integrand is a
    /// polynomial of degree 4 on a piece), and the bilinear hats written
    /// out. The field is the
    /// self-weight column's, quadratic in y, which the hats cannot
    /// represent, so the misfit is not zero and a fit weighted otherwise
    /// along the boundary would not be orthogonal.
    #[test]
    fn the_boundary_fit_is_orthogonal_along_the_boundary() {
        let grid = Grid {
            origin: [0.0, 0.0],
            h: 0.5,
            nx: 8,
            ny: 8,
        };
        let h = grid.h;
        let (c, r) = ([2.05, 1.95], 1.3);
        let points: Vec<P2> = (0..=40)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / 40.0;
                [c[0] + r * a.cos(), c[1] + r * a.sin()]
            })
            .collect();
        let circle = IbmBoundary {
            exact_field: true,
            fit_regularisation: Some(0.0),
            ..line(&points)
        };
        let ex = ExactSolution::ColumnSelfWeight {
            rho_g: 2.0e4,
            base: 0.0,
            top: 4.0,
            material: crate::material::LinearElastic {
                e: 1.0e7,
                nu: 0.3,
                density: 2.0e3,
                plane: crate::scene::Plane::Strain,
            },
        };
        let mut da = vec![[0.0; 2]; grid.num_nodes()];
        fit_exact_with(&[circle], &grid, &ex, 1.0, 0.0, &mut da).unwrap_or_else(|e| panic!("{e:?}"));
        let hat = |k: usize, x: P2| {
            let y = grid.node_position(k);
            (1.0 - (x[0] - y[0]).abs() / h).max(0.0) * (1.0 - (x[1] - y[1]).abs() / h).max(0.0)
        };
        // Per node: int N_k (N d^a - u) dS, and int N_k |u| dS for scale.
        let mut misfit = vec![[0.0; 2]; grid.num_nodes()];
        let mut scale = vec![0.0; grid.num_nodes()];
        let (gx, gw) = gauss_legendre(5);
        for w in points.windows(2) {
            let (a, b) = (w[0], w[1]);
            let mut ts = vec![0.0, 1.0];
            for d in 0..2 {
                let (lo, hi) = (a[d].min(b[d]), a[d].max(b[d]));
                let mut line = (lo / h).ceil() * h;
                while line < hi {
                    ts.push((line - a[d]) / (b[d] - a[d]));
                    line += h;
                }
            }
            ts.sort_by(f64::total_cmp);
            let chord = (b[0] - a[0]).hypot(b[1] - a[1]);
            for t in ts.windows(2) {
                for (xi, wi) in gx.iter().zip(&gw) {
                    let s = 0.5 * (t[0] + t[1]) + 0.5 * (t[1] - t[0]) * xi;
                    let x = [a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])];
                    let ds = 0.5 * (t[1] - t[0]) * chord * wi;
                    let near: Vec<usize> = (0..grid.num_nodes()).filter(|&k| hat(k, x) > 0.0).collect();
                    let mut uh = [0.0; 2];
                    for &k in &near {
                        uh[0] += hat(k, x) * da[k][0];
                        uh[1] += hat(k, x) * da[k][1];
                    }
                    let u = ex.displacement(x);
                    for &k in &near {
                        for d in 0..2 {
                            misfit[k][d] += ds * hat(k, x) * (uh[d] - u[d]);
                        }
                        scale[k] += ds * hat(k, x) * u[0].hypot(u[1]);
                    }
                }
            }
        }
        let fitted: Vec<usize> = (0..grid.num_nodes()).filter(|&k| scale[k] > 0.0).collect();
        assert!(fitted.len() > 30, "{} nodes", fitted.len());
        let worst = fitted
            .iter()
            .map(|&k| misfit[k][0].abs().max(misfit[k][1].abs()) / scale[k])
            .fold(0.0, f64::max);
        println!("largest moment of the misfit over int N_k |u| dS: {worst:.2e}");
        // The fit takes its hats 1e-9 h off the boundary (to pick the
        // material side), which perturbs its matrix and right-hand side by
        // about 1e-9 relative: the moments come out at ~4e-10 of the
        // scale, and 1e-8 allows for that. One chord length computed
        // wrongly (the y difference as a sum) gives 4e-4.
        for &k in &fitted {
            for d in 0..2 {
                assert!(
                    misfit[k][d].abs() < 1e-8 * scale[k],
                    "node {k} component {d}: int N_k (N d^a - u) dS = {:e} against int N_k |u| dS = {:e}",
                    misfit[k][d],
                    scale[k]
                );
            }
        }
    }

    /// A boundary with no piece in the grid has no length to average over:
    /// its report is zero deviation, not 0/0.
    #[test]
    fn a_boundary_off_the_grid_reports_no_violation_not_nan() {
        let grid = Grid {
            origin: [0.0, 0.0],
            h: 1.0,
            nx: 4,
            ny: 4,
        };
        let nn = grid.num_nodes();
        let zero = vec![[0.0; 2]; nn];
        let bs = [line(&[[-1.0, 6.0], [5.0, 7.0]])];
        let step = step_with(&bs, zero.clone());
        let (reports, _) = step.reports(&grid, &|_, _| true, &zero, &zero, &zero, None, 1.0);
        let r = &reports[0];
        assert_eq!((r.cut_cells, r.violation, r.violation_rms), (0, 0.0, 0.0), "{r:?}");
    }

    /// B (36) with its Tikhonov term: the fitted nodal values `a_k` (of the
    /// nodes whose functions the fitted boundary touches) minimise
    /// `sum_g w_g |sum_k N_k(x_g) a_k - dl u(x_g)|^2 + s sum_k |a_k - dl u(x_k)|^2`,
    /// with 3 Gauss points per piece (`w_g` = half the piece's length times
    /// the Gauss weight), `u` the exact field, `dl` the step's share of the
    /// load and `s = eps` times the mean diagonal of the fit's matrix. So
    /// the gradient, written out here from those definitions, vanishes:
    /// `sum_g w_g N_k (u_h - dl u) + s (a_k - dl u(x_k)) = 0` for every
    /// fitted node. A quarter of the Kirsch field's outer boundary (an arc
    /// of chords at r = 3.3, which the grid's functions cannot reproduce),
    /// half a load step, eps = 1e-3 (the Tikhonov term a visible share of
    /// the balance). The solve is backward stable: the gradient is
    /// round-off of `|M| |a|`, bound 1e-12 of the term sizes.
    #[test]
    fn exact_field_fit_solves_its_normal_equations() {
        let grid = Grid {
            origin: [0.0, 0.0],
            h: 0.5,
            nx: 8,
            ny: 8,
        };
        let ex = ExactSolution::Kirsch {
            s: 1.0e6,
            a: 0.5,
            material: crate::material::LinearElastic {
                e: 1.0e7,
                nu: 0.3,
                density: 0.0,
                plane: crate::scene::Plane::Strain,
            },
        };
        let points: Vec<P2> = (0..=6)
            .map(|k| {
                let t = std::f64::consts::FRAC_PI_2 * k as f64 / 6.0;
                [3.3 * t.cos(), 3.3 * t.sin()]
            })
            .collect();
        let mut b = line(&points);
        b.side = -1.0;
        b.exact_field = true;
        let bs = [b];
        let (dl, eps) = (0.5, 1e-3);
        let nn = grid.num_nodes();
        let mut da = vec![[f64::NAN; 2]; nn];
        fit_exact_with(&bs, &grid, &ex, dl, eps, &mut da).unwrap();
        // The samples, from the definitions above.
        let (xg, wg) = gauss_legendre(3);
        // Per sample: its stencil's (node, weight), its weight w_g, u(x_g).
        type Sample = (Vec<(usize, f64)>, f64, P2);
        let mut samples: Vec<Sample> = Vec::new();
        for (a, e, _) in bs[0].pieces(&grid) {
            let n = bs[0].normal(a, e);
            let len = (e[0] - a[0]).hypot(e[1] - a[1]);
            for (xi, wi) in xg.iter().zip(&wg) {
                let t = 0.5 * (1.0 + xi);
                let x = [a[0] + t * (e[0] - a[0]), a[1] + t * (e[1] - a[1])];
                // The fit takes the cell on the material side of a point on
                // a grid line: nudged 1e-9 h along the inward normal.
                let st = grid_stencil(&grid, [x[0] + 1e-9 * grid.h * n[0], x[1] + 1e-9 * grid.h * n[1]]);
                let nodes: Vec<(usize, f64)> = st.view().iter().map(|(k, w, _)| (k, w)).collect();
                samples.push((nodes, 0.5 * len * wi, ex.displacement(x)));
            }
        }
        let mut fitted: Vec<usize> = samples.iter().flat_map(|(n, _, _)| n.iter().map(|&(k, _)| k)).collect();
        fitted.sort_unstable();
        fitted.dedup();
        // Only the fitted nodes are written.
        for k in 0..nn {
            assert_eq!(fitted.binary_search(&k).is_ok(), da[k][0].is_finite(), "node {k}");
        }
        let diag: f64 = fitted
            .iter()
            .map(|&k| {
                samples
                    .iter()
                    .flat_map(|(n, w, _)| n.iter().filter(|e| e.0 == k).map(move |e| w * e.1 * e.1))
                    .sum::<f64>()
            })
            .sum();
        let s = eps * diag / fitted.len() as f64;
        let (mut worst, mut size, mut tikhonov) = (0.0f64, 0.0f64, 0.0f64);
        for &k in &fitted {
            let mut g = [0.0; 2];
            for (nodes, w, u) in &samples {
                let Some(&(_, nk)) = nodes.iter().find(|e| e.0 == k) else {
                    continue;
                };
                for c in 0..2 {
                    let uh: f64 = nodes.iter().map(|&(l, nl)| nl * da[l][c]).sum();
                    g[c] += w * nk * (uh - dl * u[c]);
                    size = size.max((w * nk * dl * u[c]).abs());
                }
            }
            let uk = ex.displacement(grid.node_position(k));
            for c in 0..2 {
                let t = s * (da[k][c] - dl * uk[c]);
                tikhonov = tikhonov.max(t.abs());
                worst = worst.max((g[c] + t).abs());
            }
        }
        assert!(worst < 1e-12 * size, "gradient {worst:e} against terms of {size:e}");
        // The Tikhonov term matters here: without it the gradient is off.
        assert!(tikhonov > 1e3 * worst.max(1e-12 * size), "{tikhonov:e}");
    }
}
