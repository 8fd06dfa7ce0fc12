//! The explicit step's mass matrices (G (9), (10), (20)): lumped, consistent
//! and stabilised, assembled and factorised as the scalar `M_s` they share
//! between the components; and the grid velocities they map from the
//! points' momentum.
//!
//! The consistent and stabilised masses reuse the [`Pattern`] and the
//! symbolic Cholesky of the last step while the assembly blocks (point
//! groups and ghost faces) are unchanged ([`crate::state::MassCache`]).

use crate::assembly::{Dof, DofMap, Mapping, Pattern, Storage};
use crate::bulk::blocks_of;
use crate::geometry::P2;
use crate::ghost::{self, GhostFace};
use crate::linalg::{self, Factor, Ix};
use crate::report::StepFailure;
use crate::scene::MassKind;
use crate::state::{MassCache, Simulation};
use faer::sparse::SparseColMat;

use super::{dot, transfer};

/// A factorised mass matrix on the free dofs.
pub(super) enum MassSolver {
    Lumped(Vec<f64>),
    /// The consistent mass as scalar parts ([`ScalarMass`]): one shared
    /// by both components when every active node has both free or both
    /// held, else one per component.
    Consistent(Vec<ScalarMass>),
}

/// The consistent (or stabilised) mass is `M_s (x) I_2` (G (9), (20): the
/// same scalar weights for x and y, ghost term included), so it is
/// assembled and factorised once as the scalar `M_s` on the nodes whose
/// component is free, and solved for the components that share those
/// nodes as columns of one right-hand side.
pub(super) struct ScalarMass {
    /// `L L^T` of `M_s` on this part's nodes.
    factor: Factor,
    /// `M_s` (lower triangle), for the kinetic energy.
    matrix: SparseColMat<Ix, f64>,
    /// Per component solved with this part, the free dof of the 2D system
    /// of each scalar unknown (length `M_s.nrows()` each).
    components: Vec<Vec<usize>>,
}

impl MassSolver {
    /// `x = M^-1 b` into `x` (free dofs).
    pub(super) fn solve_into(&self, b: &[f64], x: &mut Vec<f64>) {
        x.clear();
        match self {
            MassSolver::Lumped(d) => x.extend(b.iter().zip(d).map(|(b, d)| b / d)),
            MassSolver::Consistent(parts) => {
                x.resize(b.len(), 0.0);
                for part in parts {
                    let n = part.matrix.nrows();
                    let mut rhs = faer::Mat::<f64>::from_fn(n, part.components.len(), |i, j| b[part.components[j][i]]);
                    part.factor.solve_in_place(&mut rhs);
                    for (j, dofs) in part.components.iter().enumerate() {
                        for (i, &d) in dofs.iter().enumerate() {
                            x[d] = rhs[(i, j)];
                        }
                    }
                }
            }
        }
    }

    fn solve(&self, b: &[f64]) -> Vec<f64> {
        let mut x = Vec::new();
        self.solve_into(b, &mut x);
        x
    }

    /// `x_k = M^-1 b_k` for every right-hand side (free dofs), each part
    /// solved once for all of them as columns of one matrix.
    fn solve_many(&self, bs: &[&[f64]]) -> Vec<Vec<f64>> {
        let parts = match self {
            MassSolver::Lumped(_) => return bs.iter().map(|b| self.solve(b)).collect(),
            MassSolver::Consistent(parts) => parts,
        };
        let mut xs: Vec<Vec<f64>> = bs.iter().map(|b| vec![0.0; b.len()]).collect();
        for part in parts {
            let (n, nc) = (part.matrix.nrows(), part.components.len());
            let mut rhs = faer::Mat::<f64>::from_fn(n, nc * bs.len(), |i, j| bs[j / nc][part.components[j % nc][i]]);
            part.factor.solve_in_place(&mut rhs);
            for (k, x) in xs.iter_mut().enumerate() {
                for (j, dofs) in part.components.iter().enumerate() {
                    for (i, &d) in dofs.iter().enumerate() {
                        x[d] = rhs[(i, k * nc + j)];
                    }
                }
            }
        }
        xs
    }

    /// The lumped diagonal's buffer, to be reused by the next step.
    pub(super) fn into_lumped(self) -> Option<Vec<f64>> {
        match self {
            MassSolver::Lumped(d) => Some(d),
            MassSolver::Consistent(_) => None,
        }
    }

    /// `v.M v / 2`: the kinetic energy of grid velocities `v` (J).
    pub(super) fn energy(&self, v: &[f64]) -> f64 {
        match self {
            MassSolver::Lumped(d) => 0.5 * v.iter().zip(d).map(|(v, d)| d * v * v).sum::<f64>(),
            MassSolver::Consistent(parts) => parts
                .iter()
                .flat_map(|part| {
                    part.components.iter().map(|dofs| {
                        let vc: Vec<f64> = dofs.iter().map(|&d| v[d]).collect();
                        0.5 * dot(&vc, &linalg::sym_lower_mul(part.matrix.as_ref(), &vc))
                    })
                })
                .sum(),
        }
    }
}

/// The scalar parts of the consistent mass on `dofs`: per part, a scalar
/// numbering of nodes (a [`DofMap`] whose x component is the scalar
/// unknown, y inactive) and, per component it serves, the 2D free dof of
/// each scalar unknown. One part when every node has the same components
/// free, else one per component (a roller holds one of them).
fn scalar_parts(dofs: &DofMap) -> Vec<(DofMap, Vec<Vec<usize>>)> {
    let free = |d: Dof| matches!(d, Dof::Free(_));
    let shared = dofs.node_dof.iter().all(|d| free(d[0]) == free(d[1]));
    // The nodes whose component `c` is free, numbered in node order, with
    // the 2D free dof of each component in `cs`.
    let numbering = |c: usize, cs: &[usize]| {
        let mut map = DofMap {
            node_dof: vec![[Dof::Inactive; 2]; dofs.node_dof.len()],
            ..DofMap::default()
        };
        let mut of = vec![Vec::new(); cs.len()];
        for (n, d) in dofs.node_dof.iter().enumerate() {
            if free(d[c]) {
                map.node_dof[n][0] = Dof::Free(map.n_free);
                map.n_free += 1;
                for (k, &c) in cs.iter().enumerate() {
                    if let Dof::Free(i) = d[c] {
                        of[k].push(i);
                    }
                }
            }
        }
        map.active_nodes = map.n_free;
        (map, of)
    };
    if shared {
        vec![numbering(0, &[0, 1])]
    } else {
        vec![numbering(0, &[0]), numbering(1, &[1])]
    }
}

/// Row-major `2m x 2m` mass block of a point group: `sum_p m_p S_a S_b I_2`,
/// with each point's weights from its basis (`basis` per body).
fn group_mass(map: &Mapping, b: usize, points: &PointsOnGrid, out: &mut Vec<f64>) {
    let g = &map.groups[b];
    let m2 = 2 * g.nodes.len();
    let pts = points.pts;
    out.clear();
    out.resize(m2 * m2, 0.0);
    for &p in &g.points {
        let w1 = match points.cached.get(p) {
            Some(w) => *w,
            None => crate::basis::weights_1d(points.grid, points.basis[pts.body[p]], pts.x[p], pts.lp[p]),
        };
        let (len, w) = transfer::stencil_weights(points.grid, &w1);
        for a in 0..len {
            for c in 0..len {
                let v = pts.mass[p] * w[a] * w[c];
                out[2 * a * m2 + 2 * c] += v;
                out[(2 * a + 1) * m2 + 2 * c + 1] += v;
            }
        }
    }
}

/// The points, the grid and each body's basis: what the mass blocks read;
/// with the points' 1D basis factors when the step has cached them.
pub(super) struct PointsOnGrid<'a> {
    grid: &'a crate::grid::Grid,
    pts: &'a crate::points::Points,
    basis: Vec<crate::basis::BasisKind>,
    cached: &'a [[crate::basis::Weights1d; 2]],
}

impl<'a> PointsOnGrid<'a> {
    pub(super) fn of(sim: &'a Simulation) -> PointsOnGrid<'a> {
        PointsOnGrid {
            grid: &sim.model.grid,
            pts: &sim.state.points,
            basis: sim.model.bodies.iter().map(|b| b.basis).collect(),
            cached: &[],
        }
    }
}

/// The reduced consistent mass plus `gamma_m J_G` (lower triangle) on
/// `dofs` (the step's 2D numbering, or a scalar part's from
/// [`scalar_parts`]).
pub(super) fn consistent_mass(
    map: &Mapping,
    dofs: &DofMap,
    pattern: &Pattern,
    blocks: &[&[usize]],
    faces: &[GhostFace],
    points: &PointsOnGrid,
    gamma_m: f64,
) -> Result<SparseColMat<Ix, f64>, linalg::FactorError> {
    let ng = map.groups.len();
    let (values, _) = pattern.assemble_with(dofs, blocks, |b, out| {
        if b < ng {
            group_mass(map, b, points, out)
        } else {
            faces[b - ng].stiffness(gamma_m, out)
        }
    })?;
    pattern.owned_matrix(values)
}

/// The pattern of each scalar part.
fn part_patterns(
    parts: &[(DofMap, Vec<Vec<usize>>)],
    blocks: &[&[usize]],
) -> Result<Vec<Pattern>, linalg::FactorError> {
    parts
        .iter()
        .map(|(dofs, _)| Pattern::new(dofs, blocks, Storage::Lower))
        .collect()
}

/// The symbolic Cholesky of each pattern (values only give the structure
/// here).
fn analyse_parts(
    patterns: Vec<Pattern>,
    relaxed: bool,
) -> Result<Vec<(Pattern, linalg::CholeskySymbolic)>, linalg::FactorError> {
    patterns
        .into_iter()
        .map(|pattern| {
            // The symbolic factorisation reads the structure alone.
            let zeros = crate::assembly::try_filled(pattern.nnz(), 0.0, "the values of the mass matrix")?;
            let symbolic = linalg::cholesky_symbolic_relaxed(pattern.matrix(&zeros), relaxed)?;
            Ok((pattern, symbolic))
        })
        .collect()
}

/// The values of `M_s + gamma_m J_G` on each scalar part's pattern, in one
/// pass over the point groups: a group's scalar block `sum_p m_p S_a S_b`
/// (`masses` per point, weights from the step's stencils, as the inertia
/// block of the tangent has them) is formed once and added to every part;
/// then the ghost faces' (their x-x entries: `J_G` is `J_s (x) I_2`).
fn scalar_mass_values(
    map: &Mapping,
    parts: &[(DofMap, Vec<Vec<usize>>)],
    analyses: &[(Pattern, linalg::CholeskySymbolic)],
    faces: &[GhostFace],
    masses: &[f64],
    gamma_m: f64,
) -> Result<Vec<Vec<f64>>, linalg::FactorError> {
    let mut values = analyses
        .iter()
        .map(|(p, _)| crate::assembly::try_filled(p.nnz(), 0.0, "the values of the mass matrix"))
        .collect::<Result<Vec<_>, _>>()?;
    let (mut kb, mut w) = (Vec::new(), Vec::new());
    let add = |nodes: &[usize], kb: &[f64], values: &mut [Vec<f64>]| {
        for (((dofs, _), (pattern, _)), v) in parts.iter().zip(analyses).zip(values.iter_mut()) {
            pattern.add_scalar_block(dofs, nodes, kb, v);
        }
    };
    for g in &map.groups {
        let m = g.nodes.len();
        kb.clear();
        kb.resize(m * m, 0.0);
        for &p in &g.points {
            let st = map.stencils.get(p);
            debug_assert_eq!(st.len(), m);
            w.clear();
            w.extend((0..m).map(|a| st.w(a)));
            for a in 0..m {
                let wa = masses[p] * w[a];
                for (k, wc) in kb[a * m..(a + 1) * m].iter_mut().zip(&w) {
                    *k += wa * wc;
                }
            }
        }
        add(&g.nodes, &kb, &mut values);
    }
    let mut k2 = Vec::new();
    for f in faces {
        f.stiffness(gamma_m, &mut k2);
        let m = f.nodes.len();
        kb.clear();
        kb.extend((0..m * m).map(|i| k2[(2 * (i / m)) * 2 * m + 2 * (i % m)]));
        add(&f.nodes, &kb, &mut values);
    }
    Ok(values)
}

/// Assemble `M_s + gamma_m J_G` of each scalar part on its analysis and
/// factorise it (refused beyond `budget` bytes, [`linalg::check_memory`]).
#[allow(clippy::too_many_arguments)]
fn factorise_parts(
    map: &Mapping,
    parts: Vec<(DofMap, Vec<Vec<usize>>)>,
    analyses: &[(Pattern, linalg::CholeskySymbolic)],
    blocks: &[&[usize]],
    faces: &[GhostFace],
    points: &PointsOnGrid,
    gamma_m: f64,
    budget: u64,
) -> Result<Vec<ScalarMass>, linalg::FactorError> {
    parts
        .into_iter()
        .zip(analyses)
        .map(|((dofs, components), (pattern, symbolic))| {
            let matrix = consistent_mass(map, &dofs, pattern, blocks, faces, points, gamma_m)?;
            let factor = linalg::cholesky_with(symbolic, matrix.as_ref(), budget)?;
            Ok(ScalarMass {
                factor,
                matrix,
                components,
            })
        })
        .collect()
}

/// The lumped mass `M_bar = diag(sum_p m_p S_vp)` on the free dofs, from
/// the points' stencils.
pub(super) fn lumped_mass(map: &Mapping, masses: &[f64]) -> Vec<f64> {
    let mut d = vec![0.0; map.dofs.n_free];
    for (p, s) in map.stencils.iter().enumerate() {
        for (n, w, _) in s.iter() {
            for c in 0..2 {
                if let Dof::Free(i) = map.dofs.node_dof[n][c] {
                    d[i] += masses[p] * w;
                }
            }
        }
    }
    d
}

/// The lumped mass on the free dofs from the nodal masses `nodal` of the
/// point-to-grid pass (the same sums as [`lumped_mass`]), in the reused
/// buffer `d`.
pub(super) fn lumped_from_nodes(map: &Mapping, nodal: &[f64], mut d: Vec<f64>) -> MassSolver {
    d.clear();
    d.resize(map.dofs.n_free, 0.0);
    for (n, dof) in map.dofs.node_dof.iter().enumerate() {
        for c in 0..2 {
            if let Dof::Free(i) = dof[c] {
                d[i] = nodal[n];
            }
        }
    }
    MassSolver::Lumped(d)
}

/// The mass's name in messages.
pub(super) fn name(kind: MassKind) -> &'static str {
    match kind {
        MassKind::Lumped => "lumped",
        MassKind::Consistent => "consistent",
        MassKind::Stabilised => "stabilised",
    }
}

/// Grid values on the free dofs from per-node pairs, and back.
fn gather(map: &Mapping, nodal: &[P2]) -> Vec<f64> {
    let mut v = vec![0.0; map.dofs.n_free];
    for (n, d) in map.dofs.node_dof.iter().enumerate() {
        for c in 0..2 {
            if let Dof::Free(i) = d[c] {
                v[i] = nodal[n][c];
            }
        }
    }
    v
}

fn scatter(map: &Mapping, free: &[f64]) -> Vec<P2> {
    let mut nodal = vec![[0.0; 2]; map.dofs.node_dof.len()];
    for (n, d) in map.dofs.node_dof.iter().enumerate() {
        for c in 0..2 {
            if let Dof::Free(i) = d[c] {
                nodal[n][c] = free[i];
            }
        }
    }
    nodal
}

/// Grid velocities on the free dofs from point masses and velocities:
/// `M v = sum_p m_p S_p^T v_p` (G (10)).
fn map_velocities(map: &Mapping, mass: &MassSolver, masses: &[f64], velocities: &[P2]) -> Vec<f64> {
    mass.solve(&momentum(map, masses, velocities))
}

/// `sum_p m_p S_p^T v_p` on the free dofs.
fn momentum(map: &Mapping, masses: &[f64], velocities: &[P2]) -> Vec<f64> {
    let mut momentum = vec![[0.0; 2]; map.dofs.node_dof.len()];
    for (p, s) in map.stencils.iter().enumerate() {
        for (n, w, _) in s.iter() {
            momentum[n][0] += w * masses[p] * velocities[p][0];
            momentum[n][1] += w * masses[p] * velocities[p][1];
        }
    }
    gather(map, &momentum)
}

/// A step's mass on the free dofs of its mapping, factorised: what maps
/// the points' velocities and accelerations to the grid at the start of
/// an implicit dynamic step (G (10)), and solves for the initial
/// acceleration.
pub(crate) struct GridMass(MassSolver);

impl GridMass {
    /// The mass `kind` of the points mapped by `map` (lumped, consistent,
    /// or stabilised with `gamma_m J_G` on `faces`), factorised within
    /// `budget` bytes.
    pub(crate) fn new(
        sim: &Simulation,
        map: &Mapping,
        faces: &[GhostFace],
        kind: MassKind,
        gamma_m: f64,
        budget: u64,
    ) -> Result<GridMass, linalg::FactorError> {
        if kind == MassKind::Lumped {
            return Ok(GridMass(MassSolver::Lumped(lumped_mass(map, &sim.state.points.mass))));
        }
        let faces = if kind == MassKind::Stabilised { faces } else { &[] };
        let blocks = blocks_of(map, faces);
        let parts = scalar_parts(&map.dofs);
        let (mut cache, _) = analysed(sim, &parts, &blocks, true, true)?;
        let values = scalar_mass_values(map, &parts, &cache.parts, faces, &sim.state.points.mass, gamma_m)?;
        let mut spare = std::mem::take(&mut cache.spare);
        let parts = parts
            .into_iter()
            .zip(&cache.parts)
            .zip(values)
            .map(|(((_, components), (pattern, symbolic)), values)| {
                let matrix = pattern.owned_matrix(values)?;
                let buffer = spare.pop().unwrap_or_default();
                let factor = linalg::cholesky_reusing(symbolic, matrix.as_ref(), budget, buffer)?;
                Ok(ScalarMass {
                    factor,
                    matrix,
                    components,
                })
            })
            .collect::<Result<Vec<_>, linalg::FactorError>>()?;
        Ok(GridMass(MassSolver::Consistent(parts)))
    }

    /// Hand the factors' buffers to the simulation's mass cache for the
    /// next step's factors.
    pub(crate) fn recycle(self, sim: &Simulation) {
        if let MassSolver::Consistent(parts) = self.0 {
            let mut cache = sim.mass_cache.lock().unwrap_or_else(|e| e.into_inner());
            cache.spare = parts.into_iter().rev().map(|p| p.factor.into_values()).collect();
        }
    }

    /// `M x = sum_p m_p S_p^T f_p` for the point field `field` (per
    /// point) and `M y = b` for `b` on the free dofs, in one solve with
    /// two right-hand sides: `x` and `y` per grid node, zero where a
    /// component is held or inactive.
    pub(crate) fn map_points_and_solve(
        &self,
        map: &Mapping,
        masses: &[f64],
        field: &[P2],
        b: &[f64],
    ) -> (Vec<P2>, Vec<P2>) {
        let p = momentum(map, masses, field);
        let mut xs = self.0.solve_many(&[&p, b]).into_iter().map(|x| scatter(map, &x));
        let (Some(x), Some(y)) = (xs.next(), xs.next()) else {
            unreachable!("two right-hand sides give two solutions")
        };
        (x, y)
    }
}

/// The mass pattern and symbolic Cholesky of each scalar part for these
/// blocks: the last step's, kept in the simulation, while its blocks
/// (point groups and ghost faces) are the same or, with `by_structure`,
/// give the same patterns (points that moved within their cells change
/// the groups, seldom the node pairs they couple), else analysed anew and
/// kept. Returns the cache, held, and whether it was hit.
///
/// Explicit dynamics keys on the blocks alone (its reports say whether
/// the step mapped the same cells); the implicit dynamic step's
/// projection keys on the structure too.
fn analysed<'s>(
    sim: &'s Simulation,
    parts: &[(DofMap, Vec<Vec<usize>>)],
    blocks: &[&[usize]],
    relaxed: bool,
    by_structure: bool,
) -> Result<(std::sync::MutexGuard<'s, MassCache>, bool), linalg::FactorError> {
    // A panic while the cache was held left it whole or stale, never
    // half-written: it is reset below when its key does not match.
    let mut cache = sim.mass_cache.lock().unwrap_or_else(|e| e.into_inner());
    let comparable = cache.parts.len() == parts.len() && cache.relaxed == relaxed;
    if comparable && cache.key.len() == blocks.len() && cache.key.iter().zip(blocks).all(|(k, b)| k.as_slice() == *b) {
        return Ok((cache, true));
    }
    let patterns = part_patterns(parts, blocks)?;
    let key = blocks.iter().map(|b| b.to_vec()).collect();
    if by_structure && comparable && cache.parts.iter().zip(&patterns).all(|((p, _), q)| p.same_structure(q)) {
        cache.key = key;
        return Ok((cache, true));
    }
    let spare = std::mem::take(&mut cache.spare);
    *cache = MassCache::default();
    let parts = analyse_parts(patterns, relaxed)?;
    *cache = MassCache {
        key,
        relaxed,
        parts,
        spare,
    };
    Ok((cache, false))
}

/// Factorise the consistent or stabilised mass of this step (reusing the
/// cached pattern when the blocks are unchanged). Returns the solver and
/// whether the cache was hit.
pub(super) fn factorise_mass(
    sim: &mut Simulation,
    map: &Mapping,
    faces: &[GhostFace],
    kind: MassKind,
    step: usize,
    cached: &[[crate::basis::Weights1d; 2]],
) -> Result<(MassSolver, bool), StepFailure> {
    let blocks = blocks_of(map, faces);
    let parts = scalar_parts(&map.dofs);
    let (cache, reused) = analysed(sim, &parts, &blocks, false, false).map_err(|e| match e {
        e @ linalg::FactorError::Memory { .. } => e.at_step(step),
        e => StepFailure::Singular {
            step,
            reason: format!("mass matrix: {e}"),
        },
    })?;
    let gamma = if kind == MassKind::Stabilised {
        sim.params.gamma_m
    } else {
        0.0
    };
    let points = PointsOnGrid {
        cached,
        ..PointsOnGrid::of(sim)
    };
    let parts = factorise_parts(map, parts, &cache.parts, &blocks, faces, &points, gamma, sim.model.max_memory).map_err(|e| match e {
        e @ linalg::FactorError::Memory { .. } => e.at_step(step),
        e => StepFailure::Singular {
        step,
        reason: format!(
            "the {} mass matrix cannot be factorised: {}{}",
            if kind == MassKind::Stabilised {
                "stabilised"
            } else {
                "consistent"
            },
            match e {
                linalg::FactorError::NotPositiveDefinite { pivot } => format!(
                    "not positive definite to working precision (pivot {pivot} of the permuted system): a node is held by almost no mass"
                ),
                other => other.to_string(),
            },
            if kind == MassKind::Consistent {
                " (nodes barely touched by points; use mass = \"stabilised\" or \"lumped\")"
            } else {
                ""
            }
        ),
    },
    })?;
    Ok((MassSolver::Consistent(parts), reused))
}

/// Grid velocities from mapping the point momenta with the stabilised
/// (`gamma_M` of the parameters), consistent or lumped mass (G (10)),
/// per active node (m/s); `Err` when the mass cannot be factorised.
pub(crate) fn grid_velocities(sim: &Simulation, kind: MassKind) -> Result<Vec<(usize, P2)>, String> {
    let model = &sim.model;
    let map = Mapping::build(&model.grid, &sim.state.points, &model.bodies, &model.dirichlet, 0.0)
        .map_err(|e| e.to_string())?;
    let pts = &sim.state.points;
    let faces = if kind == MassKind::Stabilised {
        ghost::faces_of(&model.grid, &map, model.analysis.ghost_cells)
    } else {
        Vec::new()
    };
    let solver = if kind == MassKind::Lumped {
        MassSolver::Lumped(lumped_mass(&map, &pts.mass))
    } else {
        let blocks = blocks_of(&map, &faces);
        let parts = scalar_parts(&map.dofs);
        let points = PointsOnGrid::of(sim);
        let analyses = part_patterns(&parts, &blocks)
            .and_then(|p| analyse_parts(p, false))
            .map_err(|e| e.to_string())?;
        let gamma = sim.params.gamma_m;
        MassSolver::Consistent(
            factorise_parts(&map, parts, &analyses, &blocks, &faces, &points, gamma, u64::MAX)
                .map_err(|e| e.to_string())?,
        )
    };
    let v = scatter(&map, &map_velocities(&map, &solver, &pts.mass, &pts.v));
    Ok((0..v.len())
        .filter(|&n| map.dofs.node_dof[n][0] != Dof::Inactive)
        .map(|n| (n, v[n]))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block moving with a velocity gradient in a 2 m grid, optionally on
    /// a roller at y = 0.5 (the grid line under its points).
    fn block(roller: bool) -> Simulation {
        let mut text = String::from(
            r#"
[scene]
name = "mass-parts"
description = "A block for the scalar mass parts."
[grid]
origin = [0.0, 0.0]
size = [2.0, 2.0]
h = 0.25
[[material]]
name = "soft"
E = 1000.0
nu = 0.3
density = 1000.0
[[body]]
name = "block"
material = "soft"
points_per_cell = 2
region = { shape = "rectangle", min = [0.5, 0.5], max = [1.3, 1.1] }
velocity = [0.1, -0.05]
velocity_gradient = [[0.2, 0.3], [-0.1, 0.4]]
[analysis]
kind = "explicit-dynamics"
duration = 0.01
load_steps = 1
mass = "stabilised"
"#,
        );
        if roller {
            text.push_str("[[dirichlet]]\nkind = \"roller\"\ny = 0.5\n");
        }
        Simulation::from_scene_text(&text, "mass-parts.toml").expect("valid scene")
    }

    /// The scalar parts solve `(M_s (x) I_2) v = p` as the 2D system does:
    /// grid velocities and kinetic energy from the parts against a Cholesky
    /// of the interleaved 2D stabilised mass, with and without a roller
    /// (one part for both components, or one per component). Both are
    /// direct solves of a matrix with condition below 1e3 here, so they
    /// agree to a few ulps times that: 1e-12 relative.
    #[test]
    fn scalar_mass_parts_solve_the_two_dimensional_system() {
        for roller in [false, true] {
            let sim = block(roller);
            let model = &sim.model;
            let map = Mapping::build(&model.grid, &sim.state.points, &model.bodies, &model.dirichlet, 0.0).unwrap();
            let faces = ghost::faces_of(&model.grid, &map, model.analysis.ghost_cells);
            let blocks = blocks_of(&map, &faces);
            let points = PointsOnGrid::of(&sim);
            let gamma = sim.params.gamma_m;
            let parts = scalar_parts(&map.dofs);
            assert_eq!(parts.len(), if roller { 2 } else { 1 });
            let analyses = analyse_parts(part_patterns(&parts, &blocks).unwrap(), false).unwrap();
            let solver = MassSolver::Consistent(
                factorise_parts(&map, parts, &analyses, &blocks, &faces, &points, gamma, u64::MAX).unwrap(),
            );
            let pattern = Pattern::new(&map.dofs, &blocks, Storage::Lower).unwrap();
            let m = consistent_mass(&map, &map.dofs, &pattern, &blocks, &faces, &points, gamma).unwrap();
            let factor = linalg::cholesky(m.as_ref()).unwrap();
            let pts = &sim.state.points;
            let v = map_velocities(&map, &solver, &pts.mass, &pts.v);
            let mut momentum = vec![[0.0; 2]; map.dofs.node_dof.len()];
            for (p, s) in map.stencils.iter().enumerate() {
                for (n, w, _) in s.iter() {
                    for c in 0..2 {
                        momentum[n][c] += w * pts.mass[p] * pts.v[p][c];
                    }
                }
            }
            let reference = linalg::solve(&factor, &gather(&map, &momentum));
            let scale = reference.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(scale > 0.05, "the block moves");
            for (a, b) in v.iter().zip(&reference) {
                assert!((a - b).abs() <= 1e-12 * scale, "roller {roller}: {a} vs {b}");
            }
            let e = solver.energy(&v);
            let e_ref = 0.5 * dot(&reference, &linalg::sym_lower_mul(m.as_ref(), &reference));
            assert!(
                (e - e_ref).abs() <= 1e-12 * e_ref,
                "roller {roller}: energy {e} vs {e_ref}"
            );
        }
    }

    /// The analysis is kept while the blocks are the same list, and while
    /// other blocks give the same patterns (here the same blocks in the
    /// reverse order), and made anew when a block couples new nodes. A
    /// projection whose factors reuse the last one's buffers
    /// ([`GridMass::recycle`]) gives the same grid fields to the bit.
    #[test]
    fn the_mass_analysis_is_kept_while_the_patterns_are() {
        let sim = block(true);
        let model = &sim.model;
        let map = Mapping::build(&model.grid, &sim.state.points, &model.bodies, &model.dirichlet, 0.0).unwrap();
        let faces = ghost::faces_of(&model.grid, &map, model.analysis.ghost_cells);
        let blocks = blocks_of(&map, &faces);
        let parts = scalar_parts(&map.dofs);
        let hit = |blocks: &[&[usize]]| analysed(&sim, &parts, blocks, true, true).unwrap().1;
        assert!(!hit(&blocks), "the first analysis");
        assert!(hit(&blocks), "the same blocks");
        let reversed: Vec<&[usize]> = blocks.iter().rev().copied().collect();
        assert!(hit(&reversed), "other blocks, the same pattern");
        let active: Vec<usize> = (0..map.dofs.node_dof.len())
            .filter(|&n| map.dofs.node_dof[n][0] != Dof::Inactive)
            .collect();
        let far = [active[0], active[active.len() - 1]];
        let mut wider = blocks.clone();
        wider.push(&far);
        assert!(!hit(&wider), "a block that couples two far nodes");
        assert!(!hit(&blocks), "back to the first pattern");
        let by_blocks = |blocks: &[&[usize]]| analysed(&sim, &parts, blocks, true, false).unwrap().1;
        assert!(!by_blocks(&reversed), "keyed on the blocks alone");

        let pts = &sim.state.points;
        let b: Vec<f64> = (0..map.dofs.n_free).map(|i| (i as f64 * 0.37).sin()).collect();
        let project = || {
            let mass = GridMass::new(&sim, &map, &faces, MassKind::Stabilised, sim.params.gamma_m, u64::MAX).unwrap();
            let out = mass.map_points_and_solve(&map, &pts.mass, &pts.v, &b);
            mass.recycle(&sim);
            out
        };
        let first = project();
        let spare = sim.mass_cache.lock().unwrap().spare.len();
        assert_eq!(spare, parts.len(), "one buffer per part kept");
        assert_eq!(project(), first, "reused buffers, the same fields");
    }
}
