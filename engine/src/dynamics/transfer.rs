//! The explicit step's point-grid transfers as tight loops over reused
//! buffers (G 2.3, 3.3).
//!
//! A [`Workspace`] lives as long as the simulation and holds everything a
//! step needs per grid node, per free dof and per point, so a step in its
//! steady state allocates nothing. Each pass walks the points once in
//! order and evaluates the basis from its 1D factors
//! ([`crate::basis::weights_1d`], standard or GIMP) inside the loop:
//! no stencil array, no dynamic dispatch, no per-point vectors. Every sum
//! runs over the points in the same order, with the same expressions, as
//! the stencil-based helpers of [`super::mass`], so the results are the same to
//! the bit. With a thread pool ([`crate::Simulation::set_threads`]) the
//! stress pass updates the points' materials in parallel chunks and then
//! sums their forces and energies in point order: the same bits again.
//!
//! The updated points are written into [`Transfer::next`] and swapped
//! into the state only once every guard has passed
//! ([`Transfer::swap_points`]): a failed step leaves the last good state
//! without copying it first.

use crate::assembly::{reached_cells, try_resize, try_room, Dof, DofMap, Mapping};
use crate::basis::{weights_1d, BasisKind, Weights1d};
use crate::geometry::P2;
use crate::grid::Grid;
use crate::kinematics::be_matrix;
use crate::linalg::FactorError;
use crate::material::hencky::{right_stretch, Hencky};
use crate::points::Points;
use nalgebra::Matrix2;

/// Buffers of the explicit step, reused from step to step.
pub(crate) struct Workspace {
    /// Nodal buffers, the next points and the passes over them.
    pub(crate) transfer: Transfer,
    /// Lumped steps: a mapping with the dofs and active cells only (no
    /// stencils, no groups), refilled in place by [`Transfer::p2g`].
    pub(crate) map: Mapping,
    /// The step's vectors on the free dofs.
    pub(crate) free: FreeVectors,
    /// The lumped mass on the free dofs (kg).
    pub(crate) lumped: Vec<f64>,
    /// Per point, its 1D basis factors this step (GIMP scenes; see
    /// [`cache_weights`]).
    pub(crate) weights: Vec<[Weights1d; 2]>,
}

impl Default for Workspace {
    fn default() -> Workspace {
        Workspace {
            transfer: Transfer::default(),
            map: Mapping {
                stencils: Default::default(),
                groups: Vec::new(),
                dofs: DofMap::default(),
                active_cells: Vec::new(),
                populated_cells: Vec::new(),
                cell_fill: Vec::new(),
            },
            free: Default::default(),
            lumped: Vec::new(),
            weights: Vec::new(),
        }
    }
}

/// The explicit step's vectors on the free dofs, one per quantity.
#[derive(Default)]
pub(crate) struct FreeVectors {
    /// `sum_p m_p S_p^T v_p` (kg m/s; G (10)), mapped from the points.
    pub(crate) momentum: Vec<f64>,
    /// `v_n = M^-1 momentum` (m/s).
    pub(crate) v_n: Vec<f64>,
    /// `f_ext`: body forces, point loads, tractions (N).
    pub(crate) f_ext: Vec<f64>,
    /// `f_int = sum_p V0_p P_p grad S` (N).
    pub(crate) f_int: Vec<f64>,
    /// `f_ext - f_int` (N), the right-hand side of `M a = f`.
    pub(crate) force: Vec<f64>,
    /// `a = M^-1 (f_ext - f_int)` (m/s^2).
    pub(crate) acceleration: Vec<f64>,
    /// `v_{n+1} = v_n + dt a` (m/s).
    pub(crate) v_next: Vec<f64>,
    /// MUSL: the momentum of the updated point velocities and the grid
    /// velocities it maps to (kg m/s, m/s).
    pub(crate) musl_momentum: Vec<f64>,
    pub(crate) musl_velocity: Vec<f64>,
}

/// Per grid node and per point: what the passes read and write.
#[derive(Default)]
pub(crate) struct Transfer {
    /// Per grid node: lumped mass `sum_p m_p S_vp` (kg per unit thickness).
    pub(crate) mass: Vec<f64>,
    /// Per grid node: momentum `sum_p S_vp m_p v_p` (kg m/s).
    pub(crate) momentum: Vec<P2>,
    /// Per grid node: internal force `sum_p V0_p P_p grad S_vp` (N).
    pub(crate) fint: Vec<P2>,
    /// Per grid node: body force `sum_p S_vp m_p g` (N).
    pub(crate) body_force: Vec<P2>,
    /// Per grid node: the displacement increments `du = dt v` the stress
    /// pass reads (m).
    pub(crate) increment: Vec<P2>,
    /// Per grid node: the accelerations `a` and the velocities `v_{n+1}`
    /// grid to points reads (m/s^2, m/s).
    pub(crate) acceleration: Vec<P2>,
    pub(crate) velocity: Vec<P2>,
    /// Per grid node: touched by a point with volume this step.
    active: Vec<bool>,
    /// Per grid cell: reached by a point's basis this step.
    cells: Vec<bool>,
    /// Per grid node, the prescribed components (value 0 in explicit
    /// steps), computed once.
    prescribed: Vec<[Option<f64>; 2]>,
    /// Per point, the node rectangle `(i0, j0, ni, nj)` its basis touches
    /// ([`crate::basis::Stencil::key`]; [`NO_GROUP`] for points without
    /// volume), this step and the step the groups were built for.
    keys: Vec<(u32, u32, u8, u8)>,
    grouped: Vec<(u32, u32, u8, u8)>,
    /// The points after the step (only the fields a step changes).
    pub(crate) next: Points,
    /// Per point, its stress pass result when the pass runs in parallel.
    per_point: Vec<PointStress>,
}

/// The key of a point in no group (no volume).
const NO_GROUP: (u32, u32, u8, u8) = (u32::MAX, u32::MAX, 0, 0);

/// Per body: its basis and finite-strain material; and the points' 1D
/// basis factors of this step when they are cached.
pub(crate) struct Bodies<'a> {
    pub(crate) basis: Vec<BasisKind>,
    pub(crate) material: Vec<Hencky>,
    /// Per point, empty or its 1D factors at the start of the step (see
    /// [`cache_weights`]).
    pub(crate) cached: &'a [[Weights1d; 2]],
}

impl Bodies<'_> {
    /// Point `p`'s 1D basis factors at its position: cached, or evaluated.
    #[inline(always)]
    pub(crate) fn weights(&self, grid: &Grid, pts: &Points, p: usize) -> [Weights1d; 2] {
        match self.cached.get(p) {
            Some(w) => *w,
            None => weights_1d(grid, self.basis[pts.body[p]], pts.x[p], pts.lp[p]),
        }
    }
}

/// With a GIMP body, the 1D basis factors of every point into `out` (as
/// the passes read them five times a step and GIMP's are dear to
/// evaluate); without, `out` is left empty: the standard basis is cheaper
/// to evaluate in the loops than to read back.
pub(crate) fn cache_weights(
    grid: &Grid,
    pts: &Points,
    basis: &[BasisKind],
    out: &mut Vec<[Weights1d; 2]>,
) -> Result<(), FactorError> {
    out.clear();
    if basis.contains(&BasisKind::Gimp) {
        try_room(out, pts.len(), "the points' basis factors")?;
        out.extend((0..pts.len()).map(|p| weights_1d(grid, basis[pts.body[p]], pts.x[p], pts.lp[p])));
    }
    Ok(())
}

/// Call `f(node, S_vp, grad S_vp)` for the nodes of a point's stencil in
/// the order of [`crate::basis::stencil`] (row by row), from its 1D
/// factors: `S = wx wy`, `grad S = [wx' wy, wx wy']` (1, 1/m).
#[inline(always)]
fn for_each_node(grid: &Grid, w: &[Weights1d; 2], mut f: impl FnMut(usize, f64, [f64; 2])) {
    let [wx, wy] = w;
    let stride = grid.nx + 1;
    for b in 0..wy.len {
        let row = (wy.first + b) * stride + wx.first;
        for a in 0..wx.len {
            f(row + a, wx.w[a] * wy.w[b], [wx.dw[a] * wy.w[b], wx.w[a] * wy.dw[b]]);
        }
    }
}

/// A point's stencil weights `S_vp` in the order of
/// [`crate::basis::stencil`] (row by row) and how many there are.
#[inline]
pub(crate) fn stencil_weights(grid: &Grid, w: &[Weights1d; 2]) -> (usize, [f64; crate::basis::MAX_NODES]) {
    let mut out = [0.0; crate::basis::MAX_NODES];
    let mut k = 0;
    for_each_node(grid, w, |_, w, _| {
        out[k] = w;
        k += 1;
    });
    (k, out)
}

fn reset<T: Copy>(v: &mut Vec<T>, len: usize, value: T) {
    v.clear();
    v.resize(len, value);
}

/// Values on the free dofs from per-node pairs, into `out` (length
/// `n_free`).
pub(crate) fn gather_into(dofs: &DofMap, nodal: &[P2], out: &mut Vec<f64>) {
    reset(out, dofs.n_free, 0.0);
    for (n, d) in dofs.node_dof.iter().enumerate() {
        for c in 0..2 {
            if let Dof::Free(i) = d[c] {
                out[i] = nodal[n][c];
            }
        }
    }
}

/// Per-node pairs from values on the free dofs, `scale * free` (0 on the
/// other components), into `out` (one pair per grid node).
pub(crate) fn scatter_into(dofs: &DofMap, free: &[f64], scale: Option<f64>, out: &mut Vec<P2>) {
    reset(out, dofs.node_dof.len(), [0.0; 2]);
    for (n, d) in dofs.node_dof.iter().enumerate() {
        for c in 0..2 {
            if let Dof::Free(i) = d[c] {
                out[n][c] = match scale {
                    Some(s) => s * free[i],
                    None => free[i],
                };
            }
        }
    }
}

/// What the commit of the points' increments found: summed energies and
/// the largest `|dF - I|`.
pub(crate) struct Committed {
    /// `sum_p V0_p psi(b_e)` (J per unit thickness).
    pub(crate) strain: f64,
    /// `sum_p` of the points' plastic dissipation so far (J).
    pub(crate) dissipation: f64,
    /// Largest Frobenius `|dF - I|` (or the first NaN) and its point.
    pub(crate) strained: (f64, usize),
}

/// What the grid-to-point pass found.
pub(crate) struct Moved {
    /// Largest point displacement of the step (m) and its point.
    pub(crate) fastest: (f64, usize),
    /// First point with a non-finite velocity.
    pub(crate) non_finite: Option<usize>,
    /// `sum_p 1/2 m_p |v_p|^2` (J) and `sum_p m_p v_p` (kg m/s) after the step.
    pub(crate) kinetic: f64,
    pub(crate) momentum: P2,
}

/// One point's result of the stress pass: its first Piola-Kirchhoff
/// stress `P = tau dF^-T` (Pa; `None` for a point without reference
/// volume), the Frobenius `|dF - I|` of its increment and, committed,
/// its strain energy `V0 psi(b_e)` (J).
#[derive(Clone, Copy, Debug, Default)]
struct PointStress {
    pk: Option<[[f64; 2]; 2]>,
    stretch: f64,
    energy: f64,
}

/// The next points' fields a stress pass writes, as slices (so chunks of
/// points can be written in parallel).
struct NextSlices<'a> {
    def_grad: &'a mut [[f64; 4]],
    vol: &'a mut [f64],
    lp: &'a mut [P2],
    stress: &'a mut [[f64; 3]],
    szz: &'a mut [f64],
    b_e: &'a mut [[f64; 4]],
    dissipation: &'a mut [f64],
    yielding: &'a mut [bool],
}

impl<'a> NextSlices<'a> {
    fn of(next: &'a mut Points) -> NextSlices<'a> {
        NextSlices {
            def_grad: &mut next.def_grad,
            vol: &mut next.vol,
            lp: &mut next.lp,
            stress: &mut next.stress,
            szz: &mut next.szz,
            b_e: &mut next.b_e,
            dissipation: &mut next.dissipation,
            yielding: &mut next.yielding,
        }
    }

    /// The first `mid` points and the rest.
    fn split_at_mut(self, mid: usize) -> (NextSlices<'a>, NextSlices<'a>) {
        let (def_grad, d2) = self.def_grad.split_at_mut(mid);
        let (vol, v2) = self.vol.split_at_mut(mid);
        let (lp, l2) = self.lp.split_at_mut(mid);
        let (stress, s2) = self.stress.split_at_mut(mid);
        let (szz, z2) = self.szz.split_at_mut(mid);
        let (b_e, b2) = self.b_e.split_at_mut(mid);
        let (dissipation, di2) = self.dissipation.split_at_mut(mid);
        let (yielding, y2) = self.yielding.split_at_mut(mid);
        (
            NextSlices {
                def_grad,
                vol,
                lp,
                stress,
                szz,
                b_e,
                dissipation,
                yielding,
            },
            NextSlices {
                def_grad: d2,
                vol: v2,
                lp: l2,
                stress: s2,
                szz: z2,
                b_e: b2,
                dissipation: di2,
                yielding: y2,
            },
        )
    }
}

/// The nodal forces a stress pass accumulates: internal forces and, with
/// `gravity` (m/s^2), body forces; `None` when the pass only commits.
struct Forces<'a> {
    fint: &'a mut Vec<P2>,
    body_force: &'a mut Vec<P2>,
    gravity: Option<P2>,
}

/// Point `p`'s material update from the nodal increments `du` (`dt v`, m):
/// `dF = I + sum du (x) grad S`, the Hencky/von Mises response and, with
/// `commit`, its updated `F`, `V`, GIMP domain, stresses, `b_e`,
/// dissipation into `next[i]` (as [`crate::kinematics::commit_point`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn update_point(
    grid: &Grid,
    pts: &Points,
    bodies: &Bodies,
    du: &[P2],
    p: usize,
    commit: bool,
    next: &mut NextSlices,
    i: usize,
) -> PointStress {
    let body = pts.body[p];
    let w = bodies.weights(grid, pts, p);
    let mut g = [[0.0; 2]; 2];
    for_each_node(grid, &w, |n, _, dw| {
        let v = du[n];
        for i in 0..2 {
            for j in 0..2 {
                g[i][j] += v[i] * dw[j];
            }
        }
    });
    let df = Matrix2::new(1.0 + g[0][0], g[0][1], g[1][0], 1.0 + g[1][1]);
    let (vol0, material) = (pts.vol0[p], &bodies.material[body]);
    let r = (vol0 != 0.0).then(|| material.respond_stress(&df, &be_matrix(pts.b_e[p])));
    let mut out = PointStress {
        pk: r
            .as_ref()
            .map(|r| [[r.p[(0, 0)], r.p[(0, 1)]], [r.p[(1, 0)], r.p[(1, 1)]]]),
        stretch: 0.0,
        energy: 0.0,
    };
    if !commit {
        return out;
    }
    out.stretch = (df - Matrix2::identity()).norm();
    let fo = pts.def_grad[p];
    let f = df * Matrix2::new(fo[0], fo[1], fo[2], fo[3]);
    next.def_grad[i] = [f[(0, 0)], f[(0, 1)], f[(1, 0)], f[(1, 1)]];
    next.vol[i] = pts.vol[p] * df.determinant();
    let (l0, u) = (pts.lp0[p], right_stretch(&f));
    next.lp[i] = [l0[0] * u[(0, 0)], l0[1] * u[(1, 1)]];
    match r {
        Some(r) => {
            let s = r.tau / f.determinant();
            next.stress[i] = [s[(0, 0)], s[(1, 1)], s[(0, 1)]];
            next.szz[i] = s[(2, 2)];
            next.b_e[i] = [r.b_e[(0, 0)], r.b_e[(1, 1)], r.b_e[(0, 1)], r.b_e[(2, 2)]];
            next.dissipation[i] = pts.dissipation[p] + r.dissipation * vol0;
            next.yielding[i] = r.yielding;
            out.energy = vol0 * material.stored_energy(&r.b_e);
        }
        None => {
            next.stress[i] = pts.stress[p];
            next.szz[i] = pts.szz[p];
            next.b_e[i] = pts.b_e[p];
            next.dissipation[i] = pts.dissipation[p];
            next.yielding[i] = pts.yielding[p];
        }
    }
    out
}

/// Point `p`'s share of the pass's sums, in point order: its internal and
/// body forces into `forces`, and, committed, its `|dF - I|` against the
/// largest so far, its strain energy and its dissipation (`dissipation[0]`,
/// its next value).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn apply_point(
    grid: &Grid,
    pts: &Points,
    bodies: &Bodies,
    forces: &mut Forces,
    p: usize,
    ps: &PointStress,
    commit: bool,
    dissipation: &[f64],
    out: &mut Committed,
) {
    if let Some(gravity) = forces.gravity {
        let w = bodies.weights(grid, pts, p);
        if let Some(pk) = &ps.pk {
            let vol0 = pts.vol0[p];
            for_each_node(grid, &w, |n, _, dw| {
                for i in 0..2 {
                    forces.fint[n][i] += (pk[i][0] * dw[0] + pk[i][1] * dw[1]) * vol0;
                }
            });
        }
        if gravity != [0.0; 2] && pts.vol[p] != 0.0 {
            let m = pts.mass[p];
            for_each_node(grid, &w, |n, w, _| {
                forces.body_force[n][0] += w * m * gravity[0];
                forces.body_force[n][1] += w * m * gravity[1];
            });
        }
    }
    if !commit {
        return;
    }
    if !(ps.stretch <= out.strained.0) {
        out.strained = (ps.stretch, p);
    }
    if ps.pk.is_some() {
        out.strain += ps.energy;
        out.dissipation += dissipation[0];
    }
}

impl Transfer {
    /// Size the buffers for `grid` and `n` points (no allocation once
    /// sized) and compute the prescribed components on the first step.
    /// Memory that cannot be allocated is an error naming the buffer.
    pub(crate) fn prepare(
        &mut self,
        grid: &Grid,
        dirichlet: &[crate::model::GridDirichlet],
        n: usize,
    ) -> Result<(), FactorError> {
        let nodes = grid.num_nodes();
        if self.prescribed.len() != nodes {
            self.prescribed = crate::assembly::prescribed(grid, dirichlet, 0.0)?;
        }
        let next = &mut self.next;
        try_resize(&mut next.x, n, [0.0; 2], "the points' next positions")?;
        try_resize(&mut next.v, n, [0.0; 2], "the points' next velocities")?;
        try_resize(
            &mut next.def_grad,
            n,
            [0.0; 4],
            "the points' next deformation gradients",
        )?;
        try_resize(&mut next.vol, n, 0.0, "the points' next volumes")?;
        try_resize(&mut next.lp, n, [0.0; 2], "the points' next domains")?;
        try_resize(&mut next.stress, n, [0.0; 3], "the points' next stresses")?;
        try_resize(&mut next.szz, n, 0.0, "the points' next out-of-plane stresses")?;
        try_resize(&mut next.b_e, n, [0.0; 4], "the points' next elastic strains")?;
        try_resize(&mut next.dissipation, n, 0.0, "the points' next dissipation")?;
        try_resize(&mut next.yielding, n, false, "the points' next yield flags")?;
        Ok(())
    }

    /// Point to grid: nodal lumped mass and momentum of `velocities` over
    /// every point (G (10)); with `map` (lumped steps), also the nodes and
    /// cells the points with volume reach, numbered into its dofs and
    /// active cells.
    pub(crate) fn p2g(
        &mut self,
        grid: &Grid,
        pts: &Points,
        bodies: &Bodies,
        velocities: &[P2],
        map: Option<&mut Mapping>,
    ) {
        let activity = map.is_some();
        let nodes = grid.num_nodes();
        reset(&mut self.mass, nodes, 0.0);
        reset(&mut self.momentum, nodes, [0.0; 2]);
        if activity {
            reset(&mut self.active, nodes, false);
            reset(&mut self.cells, grid.num_cells(), false);
        }
        let (mass, momentum, active) = (&mut self.mass, &mut self.momentum, &mut self.active);
        for p in 0..pts.len() {
            let kind = bodies.basis[pts.body[p]];
            let w = bodies.weights(grid, pts, p);
            let (m, v) = (pts.mass[p], velocities[p]);
            let with_volume = activity && pts.vol[p] > 0.0;
            for_each_node(grid, &w, |n, w, _| {
                mass[n] += m * w;
                momentum[n][0] += w * m * v[0];
                momentum[n][1] += w * m * v[1];
                if with_volume {
                    active[n] = true;
                }
            });
            if activity && pts.vol[p] != 0.0 {
                let cells = &mut self.cells;
                reached_cells(grid, kind, pts.x[p], pts.lp[p], pts.vol[p], |c, _| cells[c] = true);
            }
        }
        if let Some(map) = map {
            map.dofs.number(&self.active, &self.prescribed);
            map.active_cells.clear();
            map.active_cells
                .extend((0..self.cells.len()).filter(|&c| self.cells[c]));
        }
    }

    /// Fill `map` as [`Mapping::build`] does, except its stencils (left
    /// empty: the passes evaluate the basis themselves): the groups of
    /// points with volume by node rectangle (rebuilt only when a point
    /// changed rectangle since they were built), the active nodes, their
    /// dofs, the reached, populated and filled cells. What the consistent
    /// and stabilised masses and the ghost faces read.
    pub(crate) fn map_groups(&mut self, grid: &Grid, pts: &Points, bodies: &Bodies, map: &mut Mapping) {
        self.keys.clear();
        self.keys.extend((0..pts.len()).map(|p| {
            if pts.vol[p] > 0.0 {
                let [wx, wy] = bodies.weights(grid, pts, p);
                (wx.first as u32, wy.first as u32, wx.len as u8, wy.len as u8)
            } else {
                NO_GROUP
            }
        }));
        if self.keys != self.grouped || map.groups.is_empty() {
            let mut order: Vec<usize> = (0..pts.len()).filter(|&p| self.keys[p] != NO_GROUP).collect();
            order.sort_unstable_by_key(|&p| (self.keys[p], p));
            map.groups.clear();
            for run in order.chunk_by(|&p, &q| self.keys[p] == self.keys[q]) {
                let (i0, j0, ni, nj) = self.keys[run[0]];
                let nodes = (0..nj as usize)
                    .flat_map(|b| (0..ni as usize).map(move |a| grid.node(i0 as usize + a, j0 as usize + b)))
                    .collect();
                map.groups.push(crate::assembly::Group {
                    nodes,
                    points: run.to_vec(),
                });
            }
            std::mem::swap(&mut self.keys, &mut self.grouped);
        }
        reset(&mut self.active, grid.num_nodes(), false);
        for g in &map.groups {
            for &n in &g.nodes {
                self.active[n] = true;
            }
        }
        reset(&mut self.cells, grid.num_cells(), false);
        reset(&mut map.cell_fill, grid.num_cells(), 0.0);
        let (cells, fill) = (&mut self.cells, &mut map.cell_fill);
        crate::assembly::reach(grid, pts, |b| bodies.basis[b], cells, fill);
        map.active_cells.clear();
        map.active_cells.extend((0..cells.len()).filter(|&c| cells[c]));
        cells.iter_mut().for_each(|c| *c = false);
        for p in (0..pts.len()).filter(|&p| pts.vol[p] > 0.0) {
            if let Some((i, j)) = grid.cell_of(pts.x[p]) {
                cells[j * grid.nx + i] = true;
            }
        }
        map.populated_cells.clear();
        map.populated_cells.extend((0..cells.len()).filter(|&c| cells[c]));
        map.dofs.number(&self.active, &self.prescribed);
    }

    /// Point to grid: nodal momentum only (MUSL's second mapping).
    pub(crate) fn p2g_momentum(&mut self, grid: &Grid, pts: &Points, bodies: &Bodies, velocities: &[P2]) {
        reset(&mut self.momentum, grid.num_nodes(), [0.0; 2]);
        let momentum = &mut self.momentum;
        for p in 0..pts.len() {
            let w = bodies.weights(grid, pts, p);
            let (m, v) = (pts.mass[p], velocities[p]);
            for_each_node(grid, &w, |n, w, _| {
                momentum[n][0] += w * m * v[0];
                momentum[n][1] += w * m * v[1];
            });
        }
    }

    /// The stress pass over the points, with the nodal increments `du`
    /// (m, per grid node) in [`Transfer::increment`]: per point
    /// `dF = I + sum_v du_v (x) grad S_v` and the material's response
    /// (points with `V0 > 0`). With `forces = Some(gravity)` (m/s^2): the
    /// nodal internal force `sum_p V0_p P_p grad S` (`P = tau dF^-T`) and
    /// body force `sum_p S m_p g` (points with `V > 0`). With
    /// `commit`: the points' updated `F`, `V`, GIMP domains, stresses,
    /// `b_e`, dissipation into [`Transfer::next`] (as
    /// [`crate::kinematics::commit_point`]), their energies and the
    /// largest `|dF - I|`. With `pool`, the material updates run on its
    /// threads and the sums follow in point order (the same result).
    pub(crate) fn stress_pass(
        &mut self,
        grid: &Grid,
        pts: &Points,
        bodies: &Bodies,
        forces: Option<P2>,
        commit: bool,
        pool: Option<&rayon::ThreadPool>,
    ) -> Committed {
        let nodes = grid.num_nodes();
        let gravity = forces.unwrap_or([0.0; 2]);
        if forces.is_some() {
            reset(&mut self.fint, nodes, [0.0; 2]);
            if gravity != [0.0; 2] {
                reset(&mut self.body_force, nodes, [0.0; 2]);
            }
        }
        let mut out = Committed {
            strain: 0.0,
            dissipation: 0.0,
            strained: (0.0, 0),
        };
        let (du, fint, body_force) = (&self.increment, &mut self.fint, &mut self.body_force);
        let mut next = NextSlices::of(&mut self.next);
        let mut forces = Forces {
            fint,
            body_force,
            gravity: forces,
        };
        match pool {
            None => {
                for p in 0..pts.len() {
                    let ps = update_point(grid, pts, bodies, du, p, commit, &mut next, p);
                    apply_point(
                        grid,
                        pts,
                        bodies,
                        &mut forces,
                        p,
                        &ps,
                        commit,
                        &next.dissipation[p..],
                        &mut out,
                    );
                }
            }
            Some(pool) => {
                // Each point's material update in parallel (its own next
                // fields); then forces and sums in point order, so the
                // result is the serial one to the bit.
                let per = &mut self.per_point;
                per.resize(pts.len(), PointStress::default());
                let chunk = pts.len().div_ceil(8 * pool.current_num_threads()).max(1024);
                pool.install(|| {
                    use rayon::prelude::*;
                    let mut jobs = Vec::new();
                    let (mut rest, mut stresses, mut start) = (next, per.as_mut_slice(), 0);
                    while start < pts.len() {
                        let len = chunk.min(pts.len() - start);
                        let (head, tail) = rest.split_at_mut(len);
                        let (sh, st) = stresses.split_at_mut(len);
                        jobs.push((start, head, sh));
                        (rest, stresses, start) = (tail, st, start + len);
                    }
                    jobs.into_par_iter().for_each(|(start, mut next, stresses)| {
                        for (i, ps) in stresses.iter_mut().enumerate() {
                            *ps = update_point(grid, pts, bodies, du, start + i, commit, &mut next, i);
                        }
                    });
                });
                let dissipation = &self.next.dissipation;
                for p in 0..pts.len() {
                    apply_point(
                        grid,
                        pts,
                        bodies,
                        &mut forces,
                        p,
                        &per[p],
                        commit,
                        &dissipation[p..],
                        &mut out,
                    );
                }
            }
        }
        out
    }

    /// Grid to points with the nodal accelerations `a` in
    /// [`Transfer::acceleration`] and new velocities `v_{n+1}` in
    /// [`Transfer::velocity`] (m/s^2, m/s): FLIP `v_p += dt sum S a` or PIC
    /// `v_p = sum S v`, and `x_p += dt sum S v` into [`Transfer::next`].
    pub(crate) fn g2p(&mut self, grid: &Grid, pts: &Points, bodies: &Bodies, dt: f64, flip: bool) -> Moved {
        let mut out = Moved {
            fastest: (0.0, 0),
            non_finite: None,
            kinetic: 0.0,
            momentum: [0.0; 2],
        };
        let (an, vn, next) = (&self.acceleration, &self.velocity, &mut self.next);
        for p in 0..pts.len() {
            let w = bodies.weights(grid, pts, p);
            let (mut a, mut v) = ([0.0; 2], [0.0; 2]);
            for_each_node(grid, &w, |n, w, _| {
                if flip {
                    a[0] += w * an[n][0];
                    a[1] += w * an[n][1];
                }
                v[0] += w * vn[n][0];
                v[1] += w * vn[n][1];
            });
            let vp = if flip {
                [pts.v[p][0] + dt * a[0], pts.v[p][1] + dt * a[1]]
            } else {
                v
            };
            // `x += sum S (dt v)`, as the increments `dt v_v` interpolate.
            let mut dx = [0.0; 2];
            for_each_node(grid, &w, |n, w, _| {
                dx[0] += w * (dt * vn[n][0]);
                dx[1] += w * (dt * vn[n][1]);
            });
            let d = dx[0].hypot(dx[1]);
            if d > out.fastest.0 {
                out.fastest = (d, p);
            }
            next.x[p] = [pts.x[p][0] + dx[0], pts.x[p][1] + dx[1]];
            next.v[p] = vp;
            if out.non_finite.is_none() && !(vp[0].is_finite() && vp[1].is_finite()) {
                out.non_finite = Some(p);
            }
            let m = pts.mass[p];
            out.kinetic += 0.5 * m * (vp[0].powi(2) + vp[1].powi(2));
            out.momentum = [out.momentum[0] + m * vp[0], out.momentum[1] + m * vp[1]];
        }
        out
    }

    /// Make the step's points the state's: swap the fields a step updates
    /// between `points` and [`Transfer::next`] (no copy).
    pub(crate) fn swap_points(&mut self, points: &mut Points) {
        let next = &mut self.next;
        std::mem::swap(&mut points.x, &mut next.x);
        std::mem::swap(&mut points.v, &mut next.v);
        std::mem::swap(&mut points.def_grad, &mut next.def_grad);
        std::mem::swap(&mut points.vol, &mut next.vol);
        std::mem::swap(&mut points.lp, &mut next.lp);
        std::mem::swap(&mut points.stress, &mut next.stress);
        std::mem::swap(&mut points.szz, &mut next.szz);
        std::mem::swap(&mut points.b_e, &mut next.b_e);
        std::mem::swap(&mut points.dissipation, &mut next.dissipation);
        std::mem::swap(&mut points.yielding, &mut next.yielding);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Grid to points flags the first point whose new velocity is not
    /// finite in either component. Two points of one cell, PIC (`v_p =
    /// sum S v_v`) with every node's `v_(n+1)` infinite along one axis
    /// only: the points' velocities are then non-finite along that axis and
    /// finite (0) along the other, and the step must see it. (Scenes hardly
    /// get here: their numbers are bounded by 1e30, and the grid's
    /// velocities and accelerations are checked before; the pass must hold
    /// on its own all the same.)
    #[test]
    fn grid_to_points_flags_a_velocity_non_finite_along_one_axis() {
        let text = r#"
[scene]
name = "one-cell"

[grid]
origin = [0.0, 0.0]
size = [1.0, 1.0]
h = 0.5

[[material]]
name = "m"
E = 1000.0
nu = 0.3
density = 1000.0

[[body]]
name = "b"
material = "m"
points_per_cell = 1
placement = "lattice"
lattice = [2, 1]
region = { shape = "rectangle", min = [0.0, 0.0], max = [0.5, 0.25] }

[analysis]
kind = "explicit-dynamics"
duration = 1.0
load_steps = 1
"#;
        let sim = crate::Simulation::new(crate::Model::from_text(text, "one-cell.toml").unwrap());
        let (grid, pts) = (&sim.model.grid, &sim.state.points);
        assert_eq!(pts.len(), 2);
        let bodies = Bodies {
            basis: vec![BasisKind::Standard],
            material: vec![sim.model.materials[0].hencky()],
            cached: &[],
        };
        for axis in 0..2 {
            let mut tr = Transfer::default();
            tr.prepare(grid, &sim.model.dirichlet, pts.len()).unwrap();
            let mut v = [0.0; 2];
            v[axis] = f64::INFINITY;
            tr.acceleration = vec![[0.0; 2]; grid.num_nodes()];
            tr.velocity = vec![v; grid.num_nodes()];
            let moved = tr.g2p(grid, pts, &bodies, 0.01, false);
            assert!(
                !tr.next.v[0][axis].is_finite() && tr.next.v[0][1 - axis] == 0.0,
                "{:?}",
                tr.next.v
            );
            assert_eq!(moved.non_finite, Some(0), "infinite along axis {axis}");
        }
    }
}
