//! Mapping points to the grid for one step, and sparse assembly.
//!
//! Each step the points' stencils are computed once, the active nodes found
//! and numbered ([`DofMap`]), and points that touch the same nodes are
//! grouped. Assembly is local then global: a group's dense matrix
//! `K_g = sum_p V_p B_p^T D_p B_p` is accumulated over its points, then its
//! free-free lower-triangle entries are scattered into the global matrix
//! through a [`Pattern`] built once per step (faer triplet indices with their
//! argsort), so refilling values for another iteration is a copy.

use crate::basis::{factor_len, key_of, weights_1d, write_factors, BasisKind, StencilKey, StencilView};
use crate::geometry::P2;
use crate::grid::Grid;
use crate::linalg::{FactorError, Ix, SparseRef};
use crate::model::{Body, GridDirichlet, GridTarget};
use crate::points::Points;
use faer::sparse::{SparseColMat, SymbolicSparseColMat};

/// What a node's displacement component is this step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dof {
    /// No point touches the node: not part of the system.
    Inactive,
    /// Unknown number `i` of the reduced system.
    Free(usize),
    /// Prescribed value number `i` in [`DofMap::constrained`].
    Fixed(usize),
}

/// Numbering of the active degrees of freedom of one step.
#[derive(Clone, Debug, Default)]
pub struct DofMap {
    /// Per grid node, its x and y components.
    pub node_dof: Vec<[Dof; 2]>,
    pub n_free: usize,
    /// Prescribed components: `(node, component, increment this step)` (m).
    pub constrained: Vec<(usize, usize, f64)>,
    pub active_nodes: usize,
}

impl DofMap {
    /// Number the components of the `active` nodes (per grid node) in
    /// node order, x before y: those with a prescribed value (per node and
    /// component, m) become [`Dof::Fixed`], the others [`Dof::Free`]. The
    /// vectors are refilled in place.
    pub(crate) fn number(&mut self, active: &[bool], prescribed: &[[Option<f64>; 2]]) {
        self.node_dof.clear();
        self.node_dof.resize(active.len(), [Dof::Inactive; 2]);
        self.constrained.clear();
        (self.n_free, self.active_nodes) = (0, 0);
        for n in 0..active.len() {
            if !active[n] {
                continue;
            }
            self.active_nodes += 1;
            for c in 0..2 {
                self.node_dof[n][c] = match prescribed[n][c] {
                    Some(v) => {
                        self.constrained.push((n, c, v));
                        Dof::Fixed(self.constrained.len() - 1)
                    }
                    None => {
                        self.n_free += 1;
                        Dof::Free(self.n_free - 1)
                    }
                };
            }
        }
    }
}

/// Per grid node, the prescribed increment of each component this step
/// (`value * dlambda`, m), or `None`: later conditions override earlier ones.
pub(crate) fn prescribed(
    grid: &Grid,
    dirichlet: &[GridDirichlet],
    dlambda: f64,
) -> Result<Vec<[Option<f64>; 2]>, FactorError> {
    let mut prescribed: Vec<[Option<f64>; 2]> = try_filled(grid.num_nodes(), [None, None], "the prescribed nodes")?;
    for d in dirichlet {
        let nodes: Vec<usize> = match d.target {
            GridTarget::Line { axis: 0, index } => (0..=grid.ny).map(|k| grid.node(index, k)).collect(),
            GridTarget::Line { index, .. } => (0..=grid.nx).map(|k| grid.node(k, index)).collect(),
            GridTarget::Node(n) => vec![n],
        };
        for n in nodes {
            for c in 0..2 {
                if let Some(v) = d.value[c] {
                    prescribed[n][c] = Some(v * dlambda);
                }
            }
        }
    }
    Ok(prescribed)
}

/// The cells a point's basis reaches into, each with the fraction of its
/// area the point fills: `f(cell, fill)`. Standard: the cell holding `x`
/// (position, m) with `vol / h^2` (`vol` in m^3 per unit thickness); GIMP:
/// every cell the domain of half-lengths `lp` (m) overlaps by more than
/// round-off, with the overlap's area over `h^2`.
#[inline]
pub(crate) fn reached_cells(
    grid: &Grid,
    kind: BasisKind,
    x: [f64; 2],
    lp: [f64; 2],
    vol: f64,
    mut f: impl FnMut(usize, f64),
) {
    let h2 = grid.h * grid.h;
    match kind {
        BasisKind::Standard => {
            if let Some((i, j)) = grid.cell_of(x) {
                f(j * grid.nx + i, vol / h2);
            }
        }
        BasisKind::Gimp => {
            let range = |d: usize, n: usize| {
                let s = |v: f64| (v - grid.origin[d]) / grid.h;
                let lo = (s(x[d] - lp[d]) + 1e-12).floor().max(0.0) as usize;
                let hi = ((s(x[d] + lp[d]) - 1e-12).ceil().max(1.0) as usize).min(n);
                lo..hi.max(lo + 1).min(n)
            };
            for j in range(1, grid.ny) {
                for i in range(0, grid.nx) {
                    let c0 = grid.cell_min(i, j);
                    let overlap = |d: usize| ((x[d] + lp[d]).min(c0[d] + grid.h) - (x[d] - lp[d]).max(c0[d])).max(0.0);
                    f(j * grid.nx + i, overlap(0) * overlap(1) / h2);
                }
            }
        }
    }
}

/// Points that touch the same nodes, and those nodes.
#[derive(Clone, Debug)]
pub struct Group {
    pub nodes: Vec<usize>,
    pub points: Vec<usize>,
}

/// The sparsity pattern of a reduced matrix assembled from dense blocks
/// (compressed columns, rows sorted): built once per step, refilled by
/// every assembly. No triplets are kept: a block's entries are added where
/// they belong, found by binary search in their column, in block order (so
/// sums of overlapping blocks are formed in the same order as before).
pub struct Pattern {
    pub n: usize,
    symbolic: SymbolicSparseColMat<Ix>,
    storage: Storage,
}

/// The stencils of every point of one step, stored compactly: per point
/// its node rectangle ([`StencilKey`]) and where its 1D basis factors start
/// in one flat array (`2 (ni + nj)` numbers: 8 for the standard basis'
/// 2 x 2 nodes, up to 16 for GIMP's 4 x 4), read through [`StencilView`]s
/// that form the weights and gradients as [`crate::basis::stencil`] does.
/// A standard-basis point takes 84 bytes (12 key, 8 offset, 64 factors).
#[derive(Clone, Debug, Default)]
pub struct Stencils {
    /// Node numbers per grid row (`nx + 1`).
    row: usize,
    /// Per point, its node rectangle.
    keys: Vec<StencilKey>,
    /// Per point, where its factors start in `factors`, and their end.
    start: Vec<usize>,
    /// Every point's `[S_x, dS_x/dx, S_y, dS_y/dy]` (1, 1/m), point by point.
    factors: Vec<f64>,
}

impl Stencils {
    /// The stencils of the points at their current positions, each with its
    /// body's basis. The buffers are reserved fallibly: memory that cannot
    /// be had is an error (a step failure), not an abort.
    pub fn build(grid: &Grid, pts: &Points, bodies: &[Body]) -> Result<Stencils, FactorError> {
        let n = pts.len();
        let weights = |p: usize| weights_1d(grid, bodies[pts.body[p]].basis, pts.x[p], pts.lp[p]);
        let mut keys = try_with_capacity(n, "the points' stencil keys")?;
        keys.extend((0..n).map(|p| key_of(&weights(p))));
        let mut start = try_with_capacity(n + 1, "the points' stencil offsets")?;
        start.push(0);
        let mut total = 0;
        for &k in &keys {
            total += factor_len(k);
            start.push(total);
        }
        let mut factors = try_filled(total, 0.0, "the points' stencil weights")?;
        for p in 0..n {
            write_factors(&weights(p), &mut factors[start[p]..start[p + 1]]);
        }
        Ok(Stencils {
            row: grid.nx + 1,
            keys,
            start,
            factors,
        })
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// Point `p`'s stencil.
    #[inline]
    pub fn get(&self, p: usize) -> StencilView<'_> {
        StencilView::new(self.keys[p], self.row, &self.factors[self.start[p]..self.start[p + 1]])
    }

    /// Every point's stencil, in point order.
    pub fn iter(&self) -> impl Iterator<Item = StencilView<'_>> {
        (0..self.len()).map(|p| self.get(p))
    }
}

/// The points mapped to the grid at the start of a step.
pub struct Mapping {
    pub stencils: Stencils,
    pub groups: Vec<Group>,
    pub dofs: DofMap,
    /// Cells a point's basis reaches into (standard: the cell holding it;
    /// GIMP: every cell its domain overlaps): the elements of G 4.2.
    pub active_cells: Vec<usize>,
    /// Cells holding a point (G 3.1's "populated" elements); for GIMP a
    /// subset of `active_cells`.
    pub populated_cells: Vec<usize>,
    /// Per grid cell, the fraction of its area the points fill: their
    /// volumes (standard) or their GIMP domains' overlap with the cell.
    pub cell_fill: Vec<f64>,
}

impl Mapping {
    /// Free the stencils and the point groups, the largest buffers of the
    /// mapping (at 200,704 points 17 and 6 MB), while a factor is built:
    /// the factorisation is a linear step's peak. [`Mapping::restore`]
    /// rebuilds them.
    pub fn release(&mut self) {
        self.stencils = Stencils::default();
        self.groups = Vec::new();
    }

    /// The stencils and point groups again after [`Mapping::release`],
    /// built as [`Mapping::build`] built them (the same values: the points
    /// have not moved).
    pub fn restore(&mut self, grid: &Grid, pts: &Points, bodies: &[Body]) -> Result<(), FactorError> {
        if self.stencils.len() != pts.len() {
            self.stencils = Stencils::build(grid, pts, bodies)?;
            self.groups = groups_of(pts, &self.stencils)?;
        }
        Ok(())
    }

    /// Map the points (at their current positions) to the grid and number
    /// the dofs; prescribed components get `value * dlambda` as this step's
    /// increment. The stencils, the groups, the per-node and per-cell flags
    /// and the dof map are reserved fallibly: memory that cannot be had is
    /// an error ([`FactorError::Memory`], a step failure), not an abort.
    pub fn build(
        grid: &Grid,
        pts: &Points,
        bodies: &[Body],
        dirichlet: &[GridDirichlet],
        dlambda: f64,
    ) -> Result<Mapping, FactorError> {
        let stencils = Stencils::build(grid, pts, bodies)?;
        let groups = groups_of(pts, &stencils)?;
        let mut active = try_filled(grid.num_nodes(), false, "the active nodes")?;
        for g in &groups {
            for &n in &g.nodes {
                active[n] = true;
            }
        }
        // Active cells: those a point's basis reaches into: its own cell
        // (standard), or every cell its GIMP domain overlaps by more than
        // round-off (the cells whose nodes it weights).
        let mut cells = try_filled(grid.num_cells(), false, "the active cells")?;
        let mut cell_fill = try_filled(grid.num_cells(), 0.0, "the cells' fill")?;
        reach(grid, pts, |b| bodies[b].basis, &mut cells, &mut cell_fill);
        let active_cells = (0..cells.len()).filter(|&c| cells[c]).collect();
        let mut populated = cells;
        populated.fill(false);
        for p in (0..pts.len()).filter(|&p| pts.vol[p] > 0.0) {
            if let Some((i, j)) = grid.cell_of(pts.x[p]) {
                populated[j * grid.nx + i] = true;
            }
        }
        let populated_cells = (0..populated.len()).filter(|&c| populated[c]).collect();

        let mut dofs = DofMap {
            node_dof: try_with_capacity(grid.num_nodes(), "the dof map")?,
            ..DofMap::default()
        };
        dofs.number(&active, &prescribed(grid, dirichlet, dlambda)?);
        Ok(Mapping {
            stencils,
            groups,
            dofs,
            active_cells,
            populated_cells,
            cell_fill,
        })
    }

    /// The dofs of a group's nodes, `[x0, y0, x1, y1, ...]`.
    pub fn group_dofs(&self, g: &Group) -> Vec<Dof> {
        g.nodes.iter().flat_map(|&n| self.dofs.node_dof[n]).collect()
    }

    /// Local stiffness of a group: `K_g = sum_p V_p B_p^T D_p B_p`, a dense
    /// row-major `2m x 2m` matrix, `m` = number of nodes.
    pub fn group_stiffness(&self, g: &Group, pts: &Points, d_of: &impl Fn(usize) -> [[f64; 3]; 3], out: &mut Vec<f64>) {
        let m2 = 2 * g.nodes.len();
        out.clear();
        out.resize(m2 * m2, 0.0);
        for &p in &g.points {
            let s = self.stencils.get(p);
            let d = d_of(p);
            let v = pts.vol[p];
            for a in 0..s.len() {
                let [ax, ay] = s.dw(a);
                // Rows of B^T for node a: [[ax, 0, ay], [0, ay, ax]]; times D.
                let bd = [
                    [
                        ax * d[0][0] + ay * d[2][0],
                        ax * d[0][1] + ay * d[2][1],
                        ax * d[0][2] + ay * d[2][2],
                    ],
                    [
                        ay * d[1][0] + ax * d[2][0],
                        ay * d[1][1] + ax * d[2][1],
                        ay * d[1][2] + ax * d[2][2],
                    ],
                ];
                for b in 0..s.len() {
                    let [bx, by] = s.dw(b);
                    // Columns of B for node b: [bx, 0, by] and [0, by, bx].
                    for (i, row) in bd.iter().enumerate() {
                        let kx = row[0] * bx + row[2] * by;
                        let ky = row[1] * by + row[2] * bx;
                        out[(2 * a + i) * m2 + 2 * b] += v * kx;
                        out[(2 * a + i) * m2 + 2 * b + 1] += v * ky;
                    }
                }
            }
        }
    }
}

/// The points with volume grouped by the node rectangle they touch, in
/// rectangle order, each group's points in point order; its nodes are
/// those of its first point's stencil.
fn groups_of(pts: &Points, stencils: &Stencils) -> Result<Vec<Group>, FactorError> {
    let mut order = try_with_capacity(pts.len(), "the points' grouping")?;
    order.extend((0..pts.len()).filter(|&p| pts.vol[p] > 0.0));
    order.sort_unstable_by_key(|&p| (stencils.get(p).key(), p));
    let same = |p: &usize, q: &usize| stencils.get(*p).key() == stencils.get(*q).key();
    let mut groups = try_with_capacity(order.chunk_by(same).count(), "the point groups")?;
    for run in order.chunk_by(same) {
        let st = stencils.get(run[0]);
        let mut nodes = try_with_capacity(st.len(), "a point group's nodes")?;
        nodes.extend(st.nodes());
        let mut points = try_with_capacity(run.len(), "a point group's points")?;
        points.extend_from_slice(run);
        groups.push(Group { nodes, points });
    }
    Ok(groups)
}

/// Per grid cell, whether a point with volume reaches into it with its
/// basis (`cells`), and the fraction of its area the points fill
/// (`fill`), both zeroed by the caller ([`reached_cells`]); `basis(b)` is
/// body `b`'s basis. The points in order: the fill sums the same way for
/// every caller.
pub(crate) fn reach(
    grid: &Grid,
    pts: &Points,
    basis: impl Fn(usize) -> BasisKind,
    cells: &mut [bool],
    fill: &mut [f64],
) {
    reach_from(grid, pts, &pts.x, basis, cells, fill)
}

/// [`reach`] with the points at positions `x`.
fn reach_from(
    grid: &Grid,
    pts: &Points,
    x: &[P2],
    basis: impl Fn(usize) -> BasisKind,
    cells: &mut [bool],
    fill: &mut [f64],
) {
    for p in 0..pts.len() {
        if pts.vol[p] == 0.0 {
            continue;
        }
        reached_cells(grid, basis(pts.body[p]), x[p], pts.lp[p], pts.vol[p], |c, f| {
            cells[c] = true;
            fill[c] += f;
        });
    }
}

/// The cells the points' bases reach into ([`Mapping::active_cells`])
/// without the rest of a mapping: what a simulation shows before its first
/// step.
pub(crate) fn active_cells(grid: &Grid, pts: &Points, bodies: &[Body]) -> Vec<usize> {
    active_cells_at(grid, pts, &pts.x, bodies)
}

/// [`active_cells`] with the points at positions `x`.
pub(crate) fn active_cells_at(grid: &Grid, pts: &Points, x: &[P2], bodies: &[Body]) -> Vec<usize> {
    let mut cells = vec![false; grid.num_cells()];
    reach_from(
        grid,
        pts,
        x,
        |b| bodies[b].basis,
        &mut cells,
        &mut vec![0.0; grid.num_cells()],
    );
    (0..cells.len()).filter(|&c| cells[c]).collect()
}

/// Which entries of the reduced matrix a [`Pattern`] stores.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Storage {
    /// The lower triangle of a symmetric matrix (what the Cholesky reads).
    Lower,
    /// Every entry (non-symmetric tangents, LU).
    Full,
}

impl Pattern {
    /// The pattern of a matrix assembled from dense blocks, each over a list
    /// of nodes (a stencil group, a ghost face's six nodes, ...): the
    /// free-free entries of every block (those on or below the diagonal
    /// for [`Storage::Lower`]). Memory: the node adjacency (4 bytes per node
    /// pair of a block) while it is built, then the pattern itself.
    ///
    /// Its big buffers are reserved fallibly: memory that cannot be had is
    /// an error (a step failure), not an abort.
    pub fn new(dofs: &DofMap, blocks: &[&[usize]], storage: Storage) -> Result<Pattern, FactorError> {
        let n = dofs.n_free;
        let nodes = dofs.node_dof.len();
        let free = |nd: usize| dofs.node_dof[nd].iter().any(|d| matches!(d, Dof::Free(_)));
        // Node adjacency: for each node, the nodes it shares a block with.
        let mut count = vec![0u32; nodes + 1];
        for b in blocks {
            let m = b.iter().filter(|&&nd| free(nd)).count() as u32;
            for &a in b.iter().filter(|&&nd| free(nd)) {
                count[a] += m;
            }
        }
        let mut start = vec![0usize; nodes + 1];
        for a in 0..nodes {
            start[a + 1] = start[a] + count[a] as usize;
        }
        let mut adj = try_filled(start[nodes], 0u32, "the node adjacency of the matrix pattern")?;
        let mut fill = start.clone();
        for b in blocks {
            for &a in b.iter().filter(|&&nd| free(nd)) {
                for &c in b.iter().filter(|&&nd| free(nd)) {
                    adj[fill[a]] = c as u32;
                    fill[a] += 1;
                }
            }
        }
        // Columns: for each free dof, the free dofs of its node's
        // neighbours (below the diagonal only for the lower triangle).
        let mut col_of = vec![usize::MAX; n];
        for (nd, d) in dofs.node_dof.iter().enumerate() {
            for c in 0..2 {
                if let Dof::Free(i) = d[c] {
                    col_of[i] = nd;
                }
            }
        }
        // 32-bit indices ([`Ix`]): the unknowns here, the entries below.
        let too_many = |what: &str, count: usize| {
            FactorError::Other(format!(
                "the matrix pattern has {count} {what}, more than the {} its indices can number",
                Ix::MAX
            ))
        };
        if Ix::try_from(n).is_err() {
            return Err(too_many("unknowns", n));
        }
        let mut col_ptr: Vec<Ix> = Vec::new();
        col_ptr
            .try_reserve_exact(n + 1)
            .map_err(|_| FactorError::allocation("the column pointers of the matrix pattern", 4 * (n + 1)))?;
        col_ptr.push(0);
        let mut row_idx: Vec<Ix> = Vec::new();
        let mut rows = Vec::new();
        let mut neighbours: Vec<u32> = Vec::new();
        for (col, &nd) in col_of.iter().enumerate() {
            neighbours.clear();
            neighbours.extend_from_slice(&adj[start[nd]..start[nd + 1]]);
            neighbours.sort_unstable();
            neighbours.dedup();
            rows.clear();
            for &b in &neighbours {
                for d in dofs.node_dof[b as usize] {
                    if let Dof::Free(r) = d {
                        if storage == Storage::Full || r >= col {
                            rows.push(r as Ix);
                        }
                    }
                }
            }
            rows.sort_unstable();
            row_idx.try_reserve(rows.len()).map_err(|_| {
                FactorError::allocation(
                    "the row indices of the matrix pattern",
                    4 * (row_idx.len() + rows.len()),
                )
            })?;
            row_idx.extend_from_slice(&rows);
            col_ptr.push(Ix::try_from(row_idx.len()).map_err(|_| too_many("entries", row_idx.len()))?);
        }
        // faer checks the invariants: sorted, in-range rows.
        let symbolic = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        Ok(Pattern { n, symbolic, storage })
    }

    /// Whether `other` stores the same entries (its matrices share this
    /// one's symbolic factorisation).
    pub fn same_structure(&self, other: &Pattern) -> bool {
        self.n == other.n
            && self.storage == other.storage
            && self.symbolic.col_ptr() == other.symbolic.col_ptr()
            && self.symbolic.row_idx() == other.symbolic.row_idx()
    }

    /// Stored entries.
    pub fn nnz(&self) -> usize {
        self.symbolic.row_idx().len()
    }

    /// The matrix of `values` (one per stored entry, as
    /// [`Pattern::assemble_with`] returns them) over this pattern: the
    /// pattern is shared, not copied (at 10^5 unknowns its indices are
    /// 4 MB).
    pub fn matrix<'a>(&'a self, values: &'a [f64]) -> SparseRef<'a> {
        SparseRef::new(self.symbolic.as_ref(), values)
    }

    /// The matrix of `values` over a copy of this pattern, for a matrix
    /// kept beyond its pattern; reserved fallibly.
    pub fn owned_matrix(&self, values: Vec<f64>) -> Result<SparseColMat<Ix, f64>, FactorError> {
        let col_ptr = try_copy(self.symbolic.col_ptr(), "the column pointers of the sparse matrix")?;
        let row_idx = try_copy(self.symbolic.row_idx(), "the row indices of the sparse matrix")?;
        let symbolic = SymbolicSparseColMat::new_checked(self.n, self.n, col_ptr, None, row_idx);
        Ok(SparseColMat::new(symbolic, values))
    }

    /// Add the scalar block `kb` (row-major `m x m` over `nodes`) into
    /// `values` of this pattern, built on a scalar numbering `dofs` (its
    /// x component the unknown, [`Pattern::new`] of the same blocks):
    /// rows and columns of nodes without a free unknown are skipped.
    pub fn add_scalar_block(&self, dofs: &DofMap, nodes: &[usize], kb: &[f64], values: &mut [f64]) {
        let ri = self.symbolic.row_idx();
        let m = nodes.len();
        for (c, &nc) in nodes.iter().enumerate() {
            let Dof::Free(col) = dofs.node_dof[nc][0] else { continue };
            let range = self.symbolic.col_range(col);
            let column = &ri[range.clone()];
            // Rows come in ascending order when the nodes do (a stencil's
            // do, and unknowns are numbered in node order): walk the
            // column from the last row found, else search it.
            let mut k = 0;
            for (r, &nr) in nodes.iter().enumerate() {
                if let Dof::Free(row) = dofs.node_dof[nr][0] {
                    if self.storage == Storage::Full || row >= col {
                        let row = row as Ix;
                        if column.get(k).is_none_or(|&x| x > row) {
                            k = 0;
                        }
                        while column.get(k).is_some_and(|&x| x < row) {
                            k += 1;
                        }
                        assert!(column.get(k) == Some(&row), "the pattern holds every block entry");
                        values[range.start + k] += kb[r * m + c];
                    }
                }
            }
        }
    }

    /// Assemble from dense blocks: `fill(b, out)` writes block `b`'s
    /// row-major `2m x 2m` matrix into `out` (resized by the caller's
    /// closure). Returns the reduced matrix's values, one per stored entry
    /// (the matrix: [`Pattern::matrix`]), and `K_fc du_c`, the coupling of
    /// free rows to this step's prescribed increments. Both are reserved
    /// fallibly.
    pub fn assemble_with(
        &self,
        dofs: &DofMap,
        blocks: &[&[usize]],
        mut fill: impl FnMut(usize, &mut Vec<f64>),
    ) -> Result<(Vec<f64>, Vec<f64>), FactorError> {
        let mut values = try_filled(self.nnz(), 0.0, "the values of the sparse matrix")?;
        let mut coupling = try_filled(self.n, 0.0, "the coupling to prescribed values")?;
        let (mut kb, mut bd) = (Vec::new(), Vec::new());
        for (b, nodes) in blocks.iter().enumerate() {
            fill(b, &mut kb);
            self.scatter(dofs, nodes, &kb, &mut bd, &mut values, &mut coupling);
        }
        Ok((values, coupling))
    }

    /// As [`Pattern::assemble_with`], with the blocks formed on `pool`'s
    /// threads (`fill(b, out, scratch)` writes block `b` into `out`), a
    /// batch at a time, and scattered in block order: every entry is the
    /// same sum in the same order, so any number of threads gives the
    /// serial values to the bit.
    pub fn assemble_on(
        &self,
        dofs: &DofMap,
        blocks: &[&[usize]],
        pool: Option<&rayon::ThreadPool>,
        fill: impl Fn(usize, &mut Vec<f64>, &mut Vec<f64>) + Sync,
    ) -> Result<(Vec<f64>, Vec<f64>), FactorError> {
        let Some(pool) = pool else {
            let mut scratch = Vec::new();
            return self.assemble_with(dofs, blocks, |b, out| fill(b, out, &mut scratch));
        };
        use rayon::prelude::*;
        let mut values = try_filled(self.nnz(), 0.0, "the values of the sparse matrix")?;
        let mut coupling = try_filled(self.n, 0.0, "the coupling to prescribed values")?;
        // A batch's blocks and scratch: enough per thread to spread the
        // work evenly, formed in parallel, then scattered in order before
        // the next batch is formed. At most 1024 blocks (16 MB of 4 x 4
        // node blocks with their scratch) whatever the thread count.
        let batch = (64 * pool.current_num_threads()).min(1024);
        let mut buffers: Vec<(Vec<f64>, Vec<f64>)> = vec![(Vec::new(), Vec::new()); batch.min(blocks.len())];
        let mut bd = Vec::new();
        // The scatter runs on one of the pool's threads too: on a machine
        // with as many cores as threads, a caller's thread beside them
        // would take a core from one.
        pool.install(|| {
            for b0 in (0..blocks.len()).step_by(batch) {
                let len = batch.min(blocks.len() - b0);
                buffers[..len]
                    .par_iter_mut()
                    .with_min_len(8)
                    .enumerate()
                    .for_each(|(i, (out, scratch))| fill(b0 + i, out, scratch));
                for (i, (kb, _)) in buffers[..len].iter().enumerate() {
                    self.scatter(dofs, blocks[b0 + i], kb, &mut bd, &mut values, &mut coupling);
                }
            }
        });
        Ok((values, coupling))
    }

    /// Add block `kb` (row-major `2m x 2m` over `nodes`) into `values`
    /// and its columns of prescribed dofs times their increments into
    /// `coupling`; `bd` is scratch for the block's dofs.
    fn scatter(
        &self,
        dofs: &DofMap,
        nodes: &[usize],
        kb: &[f64],
        bd: &mut Vec<Dof>,
        values: &mut [f64],
        coupling: &mut [f64],
    ) {
        let ri = self.symbolic.row_idx();
        let m2 = 2 * nodes.len();
        bd.clear();
        bd.extend(nodes.iter().flat_map(|&n| dofs.node_dof[n]));
        for (c, dc) in bd.iter().enumerate() {
            match *dc {
                Dof::Free(col) => {
                    let range = self.symbolic.col_range(col);
                    let column = &ri[range.clone()];
                    for (r, dr) in bd.iter().enumerate() {
                        if let Dof::Free(row) = *dr {
                            if self.storage == Storage::Full || row >= col {
                                let k = column
                                    .binary_search(&(row as Ix))
                                    .expect("the pattern holds every block entry");
                                values[range.start + k] += kb[r * m2 + c];
                            }
                        }
                    }
                }
                Dof::Fixed(k) => {
                    let du = dofs.constrained[k].2;
                    if du == 0.0 {
                        continue;
                    }
                    for (r, dr) in bd.iter().enumerate() {
                        if let Dof::Free(row) = *dr {
                            coupling[row] += kb[r * m2 + c] * du;
                        }
                    }
                }
                Dof::Inactive => {}
            }
        }
    }
}

/// `n` copies of `value`, or the failure to allocate them for `what`.
pub(crate) fn try_filled<T: Clone>(n: usize, value: T, what: &str) -> Result<Vec<T>, FactorError> {
    let mut v = Vec::new();
    try_resize(&mut v, n, value, what)?;
    Ok(v)
}

/// An empty vector with room for `n` entries, or the failure to allocate
/// it for `what`.
pub(crate) fn try_with_capacity<T>(n: usize, what: &str) -> Result<Vec<T>, FactorError> {
    let mut v = Vec::new();
    try_room(&mut v, n, what)?;
    Ok(v)
}

/// Room in `v` for `n` entries in all, reserved fallibly: a failure names
/// `what`.
pub(crate) fn try_room<T>(v: &mut Vec<T>, n: usize, what: &str) -> Result<(), FactorError> {
    v.try_reserve_exact(n.saturating_sub(v.len())).map_err(|_| {
        FactorError::allocation(
            format!("{what} ({n} entries)"),
            n.saturating_mul(std::mem::size_of::<T>()),
        )
    })
}

/// `v` resized to `n` entries (new ones `value`), its memory reserved
/// fallibly ([`try_room`]).
pub(crate) fn try_resize<T: Clone>(v: &mut Vec<T>, n: usize, value: T, what: &str) -> Result<(), FactorError> {
    try_room(v, n, what)?;
    v.resize(n, value);
    Ok(())
}

/// A copy of `xs`, or the failure to allocate it for `what`.
fn try_copy<T: Copy>(xs: &[T], what: &str) -> Result<Vec<T>, FactorError> {
    let mut v = Vec::new();
    v.try_reserve_exact(xs.len())
        .map_err(|_| FactorError::allocation(format!("{what} ({} entries)", xs.len()), std::mem::size_of_val(xs)))?;
    v.extend_from_slice(xs);
    Ok(v)
}
