//! Explicit dynamics (G 2.3, 3.3): one time step at a time.
//!
//! Per step, on the configuration at its start (the grid is reset):
//!
//! 1. map the points to the grid; with the stabilised mass, find the ghost
//!    faces (G 4.2);
//! 2. assemble the mass ([`MassKind`]): lumped `M_bar = diag(sum_p m_p S_vp)`,
//!    consistent `M = sum_p m_p S_p^T S_p`, or stabilised
//!    `M_tilde = M + gamma_M J_G` (G (20)); factorise the consistent ones
//!    (sparse Cholesky, pattern and symbolic analysis reused while the
//!    point groups and faces are unchanged);
//! 3. map momentum: `M v_n = sum_p m_p S_p^T v_p` (G (10));
//! 4. USF: update stresses from `dF = I + dt grad v_n`;
//! 5. `f_int = sum_p V0_p P_p grad S` (`P = tau dF^-T`), `f_ext` (gravity,
//!    point loads, tractions); `M a = f_ext - f_int`;
//!    `v_{n+1} = v_n + dt a` (supported components stay at rest);
//! 6. points: FLIP `v_p += dt sum_v S_vp a_v` or PIC `v_p = sum_v S_vp v_v`;
//!    `x_p += dt sum_v S_vp v_v`;
//! 7. USL: update stresses from `dF = I + dt grad v_{n+1}`; MUSL (Sulsky's
//!    modified USL): from the updated point velocities mapped back to the
//!    grid with the same mass;
//! 8. energies (kinetic, strain, plastic dissipation, work of the loads) and
//!    their balance against the initial energy; a step whose grid velocities
//!    or energy explode is a [`StepFailure::Diverged`], non-finite values a
//!    [`StepFailure::NonFinite`]: the state stays at the last good step.
//!
//! A step that fails for want of a smaller time step (see
//! `can_cut_back`) is cut back (`cut_back`): retried from its start as
//! two sub-steps of `dt / 2`, each halved again when it fails, at most
//! `analysis.max_cutbacks` halvings deep; the next step starts again at
//! `dt`. `max_cutbacks = 0` keeps the papers' fixed time steps.

use crate::assembly::{Dof, DofMap, Mapping, Pattern, Storage};
use crate::bulk::blocks_of;
use crate::geometry::P2;
use crate::ghost::{self, GhostFace};
use crate::linalg::{self, Condition, ConditionMethod, Factor, Ix, SparseRef};
use crate::report::{Cutback, Energy, StepFailure, StepReport, Timings};
use crate::scene::{ConditionMode, MassKind, StressUpdate, VelocityUpdate};
use crate::state::{MassCache, Simulation};
use faer::sparse::SparseColMat;
use std::time::Instant;
use transfer::{Bodies, Workspace};

pub(crate) mod transfer;

pub use crate::report::{Conditioning, DynamicsReport};

/// A factorised mass matrix on the free dofs.
enum MassSolver {
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
struct ScalarMass {
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
    fn solve_into(&self, b: &[f64], x: &mut Vec<f64>) {
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

    /// `v.M v / 2`: the kinetic energy of grid velocities `v` (J).
    fn energy(&self, v: &[f64]) -> f64 {
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
struct PointsOnGrid<'a> {
    grid: &'a crate::grid::Grid,
    pts: &'a crate::points::Points,
    basis: Vec<crate::basis::BasisKind>,
    cached: &'a [[crate::basis::Weights1d; 2]],
}

impl<'a> PointsOnGrid<'a> {
    fn of(sim: &'a Simulation) -> PointsOnGrid<'a> {
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
fn consistent_mass(
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

/// Pattern and symbolic Cholesky of each scalar part (values only give the
/// structure here).
fn analyse_parts(
    map: &Mapping,
    parts: &[(DofMap, Vec<Vec<usize>>)],
    blocks: &[&[usize]],
    faces: &[GhostFace],
    points: &PointsOnGrid,
) -> Result<Vec<(Pattern, linalg::CholeskySymbolic)>, linalg::FactorError> {
    parts
        .iter()
        .map(|(dofs, _)| {
            let pattern = Pattern::new(dofs, blocks, Storage::Lower)?;
            let m = consistent_mass(map, dofs, &pattern, blocks, faces, points, 1.0)?;
            Ok((pattern, linalg::cholesky_symbolic(m.as_ref())?))
        })
        .collect()
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

/// The lumped mass on the free dofs.
fn lumped_mass(map: &Mapping, masses: &[f64]) -> Vec<f64> {
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
    let mut momentum = vec![[0.0; 2]; map.dofs.node_dof.len()];
    for (p, s) in map.stencils.iter().enumerate() {
        for (n, w, _) in s.iter() {
            momentum[n][0] += w * masses[p] * velocities[p][0];
            momentum[n][1] += w * masses[p] * velocities[p][1];
        }
    }
    mass.solve(&gather(map, &momentum))
}

fn non_finite(step: usize, what: &str) -> StepFailure {
    StepFailure::NonFinite {
        step,
        what: what.into(),
        residuals: Vec::new(),
    }
}

/// Factorise the consistent or stabilised mass of this step (reusing the
/// cached pattern when the blocks are unchanged). Returns the solver and
/// whether the cache was hit.
fn factorise_mass(
    sim: &mut Simulation,
    map: &Mapping,
    faces: &[GhostFace],
    kind: MassKind,
    step: usize,
    cached: &[[crate::basis::Weights1d; 2]],
) -> Result<(MassSolver, bool), StepFailure> {
    let blocks = blocks_of(map, faces);
    let parts = scalar_parts(&map.dofs);
    let cache = &sim.mass_cache;
    let reused = cache.parts.len() == parts.len()
        && cache.key.len() == blocks.len()
        && cache.key.iter().zip(&blocks).all(|(k, b)| k.as_slice() == *b);
    if !reused {
        let key: Vec<Vec<usize>> = blocks.iter().map(|b| b.to_vec()).collect();
        let points = PointsOnGrid {
            cached,
            ..PointsOnGrid::of(sim)
        };
        let analyses = analyse_parts(map, &parts, &blocks, faces, &points).map_err(|e| match e {
            e @ linalg::FactorError::Memory { .. } => e.at_step(step),
            e => StepFailure::Singular {
                step,
                reason: format!("mass matrix: {e}"),
            },
        })?;
        sim.mass_cache = MassCache { key, parts: analyses };
    }
    let gamma = if kind == MassKind::Stabilised {
        sim.params.gamma_m
    } else {
        0.0
    };
    let points = PointsOnGrid {
        cached,
        ..PointsOnGrid::of(sim)
    };
    let analyses = &sim.mass_cache.parts;
    let parts = factorise_parts(map, parts, analyses, &blocks, faces, &points, gamma, sim.model.max_memory).map_err(|e| match e {
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

/// One explicit step of `dt = duration / load_steps` (s; see the module's
/// documentation): the whole step, or, when it fails with a failure a
/// smaller time step may avoid and `analysis.max_cutbacks > 0`, the step
/// cut back ([`cut_back`]).
pub(crate) fn explicit_step(sim: &mut Simulation) -> Result<StepReport, StepFailure> {
    let dt = step_dt(sim);
    let whole = Substep {
        dt,
        first: true,
        last: true,
    };
    match substep(sim, whole) {
        Err(e) if sim.model.analysis.max_cutbacks > 0 && can_cut_back(&e) => cut_back(sim, dt, e),
        other => other,
    }
}

/// The scene's time step `duration / load_steps` (s).
fn step_dt(sim: &Simulation) -> f64 {
    sim.model.analysis.duration.unwrap_or(0.0) / sim.load_steps() as f64
}

/// The explicit step's energy guard: the limit `factor (W0 + |W| + D)`
/// (initial energy, the loads' work, plastic dissipation; J per unit
/// thickness) when kinetic plus strain energy `ku` exceeds it, `None`
/// otherwise or when nothing has entered the system yet. A balanced run
/// has `ku = W0 + W - D`, below the limit for any `factor >= 1`.
fn energy_limit_exceeded(ku: f64, w0: f64, work: f64, dissipation: f64, factor: f64) -> Option<f64> {
    let scale = w0 + work.abs() + dissipation;
    (scale > 0.0 && ku > factor * scale).then_some(factor * scale)
}

/// Failures a smaller time step may avoid, which [`cut_back`] retries:
///
/// - [`StepFailure::Diverged`]: each of its guards measures what the time
///   step drives: a point moving more than a cell (its increment is
///   `dt |v|`), a deformation increment `|dF - I| > 1/2` (`dt |grad v|`),
///   and kinetic plus strain energy beyond `blowup_factor` times what the
///   loads supplied (past the critical time step, G 3.5, the central
///   difference scheme amplifies every step's error);
/// - [`StepFailure::NonFinite`]: the overflow that same instability ends in.
///
/// Not retried, as a smaller step meets them again: [`StepFailure::LeftGrid`]
/// (a point that moves less than a cell, the guard above, and leaves the
/// grid follows its trajectory out: the sub-steps end at the same time, past
/// the edge, after `2^max_cutbacks` futile sub-steps); `Singular`,
/// `Boundary` and `OutOfMemory` (the mass matrix, the splines and the factor
/// are those of the points at the step's start, whatever `dt`); `Cancelled`
/// (the observer asked to stop) and `Internal` (a bug).
fn can_cut_back(e: &StepFailure) -> bool {
    matches!(e, StepFailure::Diverged { .. } | StepFailure::NonFinite { .. })
}

/// One sub-step of an explicit step: `dt` (s) from the current state;
/// `first` when it starts at the step's start (the mass conditioning, on the
/// configuration there, is computed in it), `last` when it ends at the
/// step's end (it commits the step's number and computes the errors against
/// the exact solution). The whole step is the one sub-step both first and
/// last.
#[derive(Clone, Copy, Debug)]
struct Substep {
    dt: f64,
    first: bool,
    last: bool,
}

/// One sub-step, with the buffers of [`Workspace`] reused from the last.
fn substep(sim: &mut Simulation, s: Substep) -> Result<StepReport, StepFailure> {
    let mut ws = std::mem::take(&mut sim.explicit);
    let out = step_with(sim, &mut ws, s);
    sim.explicit = ws;
    out
}

/// Cut the step of `dt` (s) back after its `failure`: retry it from its
/// start (where a failed sub-step leaves the state: a sub-step commits only
/// after every guard has passed) as two sub-steps of `dt / 2`, each split
/// again when it fails ([`advance`]), at most `analysis.max_cutbacks`
/// halvings deep. The sub-step sizes are `dt / 2^k`, so they add up to
/// `dt` exactly and the step ends at `t_n = n dt`, as without cutbacks.
///
/// The step's report covers the whole step ([`Merged::report`]), with
/// every cutback in [`crate::report::DynamicsReport::cutbacks`]. When the
/// halvings run out (or a sub-step fails otherwise, or the observer
/// cancels between sub-steps), the step fails with the last failure, its
/// message naming the cutbacks tried, and the state returns to the step's
/// start bit for bit.
fn cut_back(sim: &mut Simulation, dt: f64, failure: StepFailure) -> Result<StepReport, StepFailure> {
    let step = sim.state.step + 1;
    let t0 = sim.state.step as f64 * dt;
    let start = sim.snapshot();
    let mut merged = Merged {
        dt,
        cutbacks: vec![Cutback {
            from: t0,
            to: step as f64 * dt,
            reason: failure.to_string(),
        }],
        ..Merged::default()
    };
    let half = 0.5 * dt;
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let (first, second) = (
            Substep {
                dt: half,
                first: true,
                last: false,
            },
            Substep {
                dt: half,
                first: false,
                last: true,
            },
        );
        advance(sim, &mut merged, first, t0, 1)?;
        advance(sim, &mut merged, second, t0 + half, 1)?;
        Ok(())
    }));
    let outcome = outcome.unwrap_or_else(|e| {
        Err(StepFailure::Internal {
            step,
            message: crate::report::panic_message(e.as_ref()),
        })
    });
    match outcome {
        Ok(()) => Ok(merged.report()),
        Err(e) => {
            sim.restore(&start);
            Err(after_cutbacks(e, &merged, sim.model.analysis.max_cutbacks))
        }
    }
}

/// Advance the state by `s.dt` (s) from time `t` (s): one sub-step, or,
/// when it fails with a failure a smaller time step may avoid and fewer
/// than `analysis.max_cutbacks` halvings led to it (`depth`), two halves,
/// each advanced the same way. The observer's stop flag is polled before
/// each sub-step: a step cut back `k` deep may take `2^k` of them, and
/// cancelling is never cut back.
fn advance(sim: &mut Simulation, merged: &mut Merged, s: Substep, t: f64, depth: usize) -> Result<(), StepFailure> {
    if sim.cancelled() {
        return Err(StepFailure::Cancelled {
            step: sim.state.step + 1,
            residuals: Vec::new(),
        });
    }
    match substep(sim, s) {
        Ok(r) => {
            merged.add(r);
            Ok(())
        }
        Err(e) if can_cut_back(&e) && depth < sim.model.analysis.max_cutbacks => {
            merged.cutbacks.push(Cutback {
                from: t,
                to: t + s.dt,
                reason: e.to_string(),
            });
            let half = 0.5 * s.dt;
            let (first, second) = (
                Substep {
                    dt: half,
                    first: s.first,
                    last: false,
                },
                Substep {
                    dt: half,
                    first: false,
                    last: s.last,
                },
            );
            advance(sim, merged, first, t, depth + 1)?;
            advance(sim, merged, second, t + half, depth + 1)
        }
        Err(e) => Err(e),
    }
}

/// `failure`, which ended a step cut back as `merged` records, with its
/// message naming the cutbacks tried (the variant is kept).
fn after_cutbacks(failure: StepFailure, merged: &Merged, max: usize) -> StepFailure {
    // Each cutback tries at least the first of its halves.
    let smallest = 0.5 * merged.cutbacks.iter().map(|c| c.to - c.from).fold(merged.dt, f64::min);
    let note = format!(
        "; still failing after {} cutback(s) of the time step {:.3e} s (sub-steps down to {:.3e} s; analysis.max_cutbacks = {max}), the state is the step's start",
        merged.cutbacks.len(),
        merged.dt,
        smallest
    );
    match failure {
        StepFailure::Diverged { step, reason } => StepFailure::Diverged {
            step,
            reason: reason + &note,
        },
        StepFailure::NonFinite { step, what, residuals } => StepFailure::NonFinite {
            step,
            what: what + &note,
            residuals,
        },
        StepFailure::Singular { step, reason } => StepFailure::Singular {
            step,
            reason: reason + &note,
        },
        other => other,
    }
}

/// The sub-steps of a step cut back, merged into the step's report.
#[derive(Default)]
struct Merged {
    /// The step's time step (s).
    dt: f64,
    /// Every failed attempt, in order.
    cutbacks: Vec<Cutback>,
    /// The first and the last sub-step's reports.
    first: Option<StepReport>,
    last: Option<StepReport>,
    substeps: usize,
    timings: Timings,
    /// Largest grid speed over the sub-steps (m/s).
    max_speed: f64,
    /// Whether every sub-step reused the mass pattern.
    pattern_reused: bool,
}

impl Merged {
    fn add(&mut self, r: StepReport) {
        self.timings.add(&r.timings);
        let d = r.dynamics.as_ref().expect("explicit steps report dynamics");
        let reused = d.pattern_reused;
        self.max_speed = self.max_speed.max(d.max_speed);
        self.pattern_reused = reused && (self.substeps == 0 || self.pattern_reused);
        self.substeps += 1;
        if self.first.is_none() {
            self.first = Some(r);
        } else {
            self.last = Some(r);
        }
    }

    /// The step's report: the state at its end (energies, work and
    /// dissipation so far, momentum, errors, time `n dt`) from the last
    /// sub-step; the boundaries and conditioning of its start from the
    /// first; timings summed, the largest grid speed over all, the largest
    /// increment as that speed times `dt` (m), and the cutbacks.
    fn report(self) -> StepReport {
        let first = self.first.expect("a step cut back has at least two sub-steps");
        let mut r = self.last.expect("a step cut back has at least two sub-steps");
        r.timings = self.timings;
        r.boundaries = first.boundaries;
        r.condition = first.condition;
        r.condition_unstabilised = first.condition_unstabilised;
        r.max_increment = self.max_speed * self.dt;
        if let Some(d) = r.dynamics.as_mut() {
            d.conditioning = first.dynamics.and_then(|f| f.conditioning);
            d.max_speed = self.max_speed;
            d.pattern_reused = self.pattern_reused;
            d.cutbacks = self.cutbacks;
            d.substeps = self.substeps;
        }
        r
    }
}

/// Sub-step `s` of step `n` (see the module's documentation); the
/// updated point fields are swapped into the state only after every guard
/// has passed, so a failed sub-step leaves the state as it found it (the
/// mass cache may hold this configuration's pattern, valid for any step
/// that maps the same blocks).
fn step_with(sim: &mut Simulation, ws: &mut Workspace, s: Substep) -> Result<StepReport, StepFailure> {
    let step = sim.state.step + 1;
    let steps = sim.load_steps();
    let step_dt = step_dt(sim);
    let a = &sim.model.analysis;
    let (stress_update, velocity_update, blowup_factor, every) =
        (a.stress_update, a.velocity_update, a.blowup_factor, a.condition_every);
    let dt = s.dt;
    let start = Instant::now();
    let mut timings = Timings::default();
    let h = sim.model.grid.h;
    let stabilised = a.mass == MassKind::Stabilised && sim.params.gamma_m > 0.0;
    let kind = if a.mass == MassKind::Stabilised && !stabilised {
        MassKind::Consistent
    } else {
        a.mass
    };
    let grid = &sim.model.grid;
    // Threads pay for themselves above a few thousand points.
    let pool = sim.pool.clone().filter(|_| sim.state.points.len() >= 4096);
    let pool = pool.as_deref();
    let Workspace {
        transfer: tr,
        map,
        free,
        lumped,
        weights,
    } = ws;
    let basis: Vec<_> = sim.model.bodies.iter().map(|b| b.basis).collect();
    transfer::cache_weights(grid, &sim.state.points, &basis, weights).map_err(|e| e.at_step(step))?;
    let bodies = Bodies {
        basis,
        material: sim
            .model
            .bodies
            .iter()
            .map(|b| sim.model.materials[b.material].hencky())
            .collect(),
        cached: weights,
    };
    tr.prepare(grid, &sim.model.dirichlet, sim.state.points.len())
        .map_err(|e| e.at_step(step))?;

    // 1. Map points: the lumped mass needs only the dofs and the active
    // cells (found by the point-to-grid pass); the consistent ones their
    // groups and, stabilised, the ghost faces (G 4.2).
    let pts = &sim.state.points;
    let consistent = kind != MassKind::Lumped;
    if consistent {
        tr.map_groups(grid, pts, &bodies, map);
    }
    let faces = if stabilised {
        ghost::faces_of(grid, map, sim.model.analysis.ghost_cells)
    } else {
        Vec::new()
    };

    // 2. Mass: nodal lumped mass and momentum in one pass.
    let t = Instant::now();
    tr.p2g(grid, pts, &bodies, &pts.v, (!consistent).then_some(&mut *map));
    let (mass, pattern_reused) = if consistent {
        factorise_mass(sim, map, &faces, kind, step, bodies.cached)?
    } else {
        let mut d = std::mem::take(lumped);
        d.clear();
        d.resize(map.dofs.n_free, 0.0);
        for (n, dof) in map.dofs.node_dof.iter().enumerate() {
            for c in 0..2 {
                if let Dof::Free(i) = dof[c] {
                    d[i] = tr.mass[n];
                }
            }
        }
        (MassSolver::Lumped(d), false)
    };
    timings.factorisation = t.elapsed().as_secs_f64();
    let map: &Mapping = map;
    let pts = &sim.state.points;
    let grid = &sim.model.grid;

    // 3. Momentum to grid velocities: M v = sum_p m_p S_p^T v_p (G (10)).
    let t = Instant::now();
    let [b, v0, ext, fint, rhs, acc, v1] = free;
    transfer::gather_into(&map.dofs, &tr.momentum, b);
    mass.solve_into(b, v0);
    if v0.iter().any(|v| !v.is_finite()) {
        return Err(non_finite(step, "grid velocity from the momentum"));
    }
    timings.solve += t.elapsed().as_secs_f64();

    // 4-5. Stress (USF: dF = I + dt grad v_n) and forces, accelerations.
    let t = Instant::now();
    let usf = stress_update == StressUpdate::Usf;
    transfer::scatter_into(&map.dofs, v0, Some(dt), &mut tr.nodal_a);
    if !usf {
        tr.nodal_a.iter_mut().for_each(|v| *v = [0.0; 2]);
    }
    let gravity = sim.model.gravity;
    let first = tr.stress_pass(grid, pts, &bodies, Some(gravity), usf, pool);
    // The free-dof internal force, then f_ext: body forces, point loads
    // and tractions in that order (as `Simulation::nodal_forces`).
    transfer::gather_into(&map.dofs, &tr.fint, fint);
    if gravity != [0.0; 2] {
        transfer::gather_into(&map.dofs, &tr.body_force, ext);
    } else {
        ext.clear();
        ext.resize(map.dofs.n_free, 0.0);
    }
    for load in &sim.model.point_loads {
        let st = crate::basis::stencil(
            grid,
            sim.model.bodies[pts.body[load.point]].basis,
            pts.x[load.point],
            pts.lp[load.point],
        );
        for (n, w, _) in st.view().iter() {
            for c in 0..2 {
                if let Dof::Free(i) = map.dofs.node_dof[n][c] {
                    ext[i] += w * load.force[c];
                }
            }
        }
    }
    let boundaries = sim.add_tractions(map, step, 1.0, ext)?;
    rhs.clear();
    rhs.extend(ext.iter().zip(fint.iter()).map(|(e, i)| e - i));
    timings.assembly += t.elapsed().as_secs_f64();
    let t = Instant::now();
    mass.solve_into(rhs, acc);
    v1.clear();
    v1.extend(v0.iter().zip(acc.iter()).map(|(v, a)| v + dt * a));
    timings.solve += t.elapsed().as_secs_f64();
    if acc.iter().chain(v1.iter()).any(|v| !v.is_finite()) {
        return Err(non_finite(step, "grid acceleration"));
    }
    transfer::scatter_into(&map.dofs, acc, None, &mut tr.nodal_a);
    transfer::scatter_into(&map.dofs, v1, None, &mut tr.nodal_b);
    // Nodes that points barely touch may take large velocities without
    // moving anything; the points' own increments are what must stay small.
    let max_speed = (tr.nodal_b.iter().zip(&map.dofs.node_dof))
        .filter(|(_, d)| d[0] != Dof::Inactive)
        .map(|(v, _)| v[0].hypot(v[1]))
        .fold(0.0, f64::max);

    // 6-7. Points: velocities, positions, then (USL) stresses.
    let t = Instant::now();
    let moved = tr.g2p(grid, pts, &bodies, dt, velocity_update == VelocityUpdate::Flip);
    let committed = match stress_update {
        StressUpdate::Usf => first,
        StressUpdate::Usl => {
            let (du, v) = (&mut tr.nodal_a, &tr.nodal_b);
            du.clear();
            du.extend(v.iter().map(|v| [dt * v[0], dt * v[1]]));
            tr.stress_pass(grid, pts, &bodies, None, true, pool)
        }
        StressUpdate::Musl => {
            // Sulsky's modified USL: the strain increment from the updated
            // point velocities mapped back to the grid with the same mass.
            let velocities = std::mem::take(&mut tr.next.v);
            tr.p2g_momentum(grid, pts, &bodies, &velocities);
            tr.next.v = velocities;
            // The momentum and f_int vectors are free again.
            let (bm, vm) = (&mut *b, &mut *fint);
            transfer::gather_into(&map.dofs, &tr.momentum, bm);
            mass.solve_into(bm, vm);
            transfer::scatter_into(&map.dofs, vm, Some(dt), &mut tr.nodal_a);
            tr.stress_pass(grid, pts, &bodies, None, true, pool)
        }
    };
    let (strain, dissipation) = (committed.strain, committed.dissipation);
    let (fastest, strained) = (moved.fastest, committed.strained);
    let guards = (|| {
        if let Some(p) = moved.non_finite {
            return Err(non_finite(step, &format!("velocity at point {p}")));
        }
        if fastest.0 > h {
            return Err(StepFailure::Diverged {
                step,
                reason: format!(
                    "point {} would move {:.3e} m in one step, more than a cell (h = {h}, dt = {dt:.3e} s, largest grid speed {max_speed:.3e} m/s): the time step is too large or the {} mass is ill-conditioned",
                    fastest.1,
                    fastest.0,
                    mass_name(kind)
                ),
            });
        }
        // Explicit steps are small: a point whose deformation gradient
        // changes by more than half in one step (or to a non-finite value)
        // has diverged.
        if !(strained.0 <= 0.5) {
            return Err(StepFailure::Diverged {
                step,
                reason: format!(
                    "point {} would deform by |dF - I| = {:.3e} in one step (dt = {dt:.3e} s, largest grid speed {max_speed:.3e} m/s): the time step is too large or the {} mass is ill-conditioned",
                    strained.1,
                    strained.0,
                    mass_name(kind)
                ),
            });
        }
        crate::state::check_points(grid, &tr.next, step, &[])?;
        gimp_domains_inside(sim, &tr.next, step)
    })();
    guards?;
    timings.update = t.elapsed().as_secs_f64();

    // 8. Energies and the balance.
    let work: f64 = ext.iter().zip(v1.iter()).map(|(f, v)| f * dt * v).sum();
    let kinetic = moved.kinetic;
    let external_work = sim.state.external_work + work;
    let w0 = sim.state.initial_energy;
    let energy_error = kinetic + strain + dissipation - external_work - w0;
    if let Some(limit) = energy_limit_exceeded(kinetic + strain, w0, external_work, dissipation, blowup_factor) {
        return Err(StepFailure::Diverged {
            step,
            reason: format!(
                "kinetic + strain energy {:.6e} J exceeds {} x (initial energy + work + dissipation) = {:.6e} J with the {} mass",
                kinetic + strain,
                blowup_factor,
                limit,
                mass_name(kind)
            ),
        });
    }

    // Conditioning of this step's mass matrices, when asked (on the
    // mapping at the start of the step, as the points still are).
    let t = Instant::now();
    let asked = sim.params.condition != ConditionMode::Off && every > 0 && (step % every == 0 || step == 1);
    let conditioning = (s.first && asked)
        .then(|| {
            // The conditioning's stiffness reads the stencils.
            let model = &sim.model;
            let map = &Mapping::build(grid, pts, &model.bodies, &model.dirichlet, 0.0)?;
            let faces = if faces.is_empty() {
                ghost::faces_of(grid, map, sim.model.analysis.ghost_cells)
            } else {
                faces.clone()
            };
            conditioning_on(sim, map, &faces)
        })
        .transpose()
        .map_err(|e| e.at_step(step))?;
    timings.condition = t.elapsed().as_secs_f64();
    let (condition, condition_unstabilised) = match &conditioning {
        None => (None, None),
        Some(c) => match kind {
            MassKind::Stabilised => (Some(c.mass_stabilised), Some(c.mass_consistent)),
            MassKind::Consistent => (Some(c.mass_consistent), None),
            MassKind::Lumped => (Some(c.mass_lumped), None),
        },
    };

    let (unknowns, active_nodes) = (map.dofs.n_free, map.dofs.active_nodes);
    let residual_norm = norm(rhs);
    let kinetic_grid = mass.energy(v1);
    // Commit: the updated fields swap into the state; the cells of the
    // step before go back to the workspace to be refilled.
    let map = &mut ws.map;
    std::mem::swap(&mut sim.state.active_cells, &mut map.active_cells);
    tr.swap_points(&mut sim.state.points);
    if s.last {
        sim.state.step = step;
    }
    sim.state.external_work += work;
    sim.state.ghost_faces = faces.iter().map(|f| ghost::face_segment(&sim.model.grid, f)).collect();
    if let MassSolver::Lumped(d) = mass {
        *lumped = d;
    }
    let lambda = step as f64 / steps as f64;
    let errors = if s.last { sim.exact_errors(lambda) } else { Vec::new() };
    timings.total = start.elapsed().as_secs_f64();
    Ok(StepReport {
        step,
        load_steps: steps,
        load_factor: lambda,
        unknowns,
        active_nodes,
        active_cells: sim.state.active_cells.len(),
        residual_norm,
        residuals: Vec::new(),
        timings,
        energy: Energy {
            strain,
            external_work,
            plastic_dissipation: dissipation,
            kinetic,
            ghost: 0.0,
        },
        condition,
        condition_unstabilised,
        iterations: 0,
        ghost_faces: faces.len(),
        ibm: Vec::new(),
        errors,
        max_increment: max_speed * dt,
        boundaries,
        dynamics: Some(DynamicsReport {
            time: step as f64 * step_dt,
            dt: step_dt,
            initial_energy: w0,
            energy_error,
            momentum: moved.momentum,
            kinetic_grid,
            max_speed,
            mass: kind,
            stress_update,
            velocity_update,
            pattern_reused,
            conditioning,
            cutbacks: Vec::new(),
            substeps: 1,
        }),
        solver: None,
        probes: Vec::new(),
    })
}

/// A GIMP domain reaching past the grid's edge loses nodes of its basis,
/// and with them partition of unity and momentum conservation: the first
/// point of `pts` (the step's updated points) whose domain does is the
/// step's failure.
fn gimp_domains_inside(sim: &Simulation, pts: &crate::points::Points, step: usize) -> Result<(), StepFailure> {
    let grid = &sim.model.grid;
    let (lo, hi) = (grid.origin, grid.max());
    let tol = 1e-9 * grid.h;
    let body = &sim.state.points.body;
    for p in 0..pts.len() {
        if sim.model.bodies[body[p]].basis != crate::basis::BasisKind::Gimp {
            continue;
        }
        let (x, l) = (pts.x[p], pts.lp[p]);
        let corner = [0, 1].map(|d| {
            if x[d] - l[d] < lo[d] - tol {
                x[d] - l[d]
            } else if x[d] + l[d] > hi[d] + tol {
                x[d] + l[d]
            } else {
                x[d]
            }
        });
        if corner != x {
            return Err(StepFailure::LeftGrid {
                step,
                point: p,
                position: corner,
                domain: true,
            });
        }
    }
    Ok(())
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

fn mass_name(kind: MassKind) -> &'static str {
    match kind {
        MassKind::Lumped => "lumped",
        MassKind::Consistent => "consistent",
        MassKind::Stabilised => "stabilised",
    }
}

/// Condition number of an SPD matrix, or `inf` when it cannot be factorised.
fn spd_condition(m: SparseRef<'_>, mode: ConditionMode, dense_limit: usize) -> (Condition, Option<Factor>) {
    match linalg::cholesky(m) {
        Ok(f) => {
            let limit = match mode {
                ConditionMode::Dense => usize::MAX,
                ConditionMode::Lanczos => 0,
                _ => dense_limit,
            };
            (linalg::condition(m, &f, limit), Some(f))
        }
        // Not numerically positive definite: its smallest eigenvalue is at
        // or below round-off of the largest; dense eigenvalues say where.
        Err(_) => {
            let ev = (m.nrows() <= dense_limit)
                .then(|| linalg::dense_eigenvalues(m))
                .flatten();
            let (lo, hi) = ev.map_or((0.0, f64::NAN), |e| (e[0], e[e.len() - 1]));
            (
                Condition {
                    value: f64::INFINITY,
                    lambda_min: lo,
                    lambda_max: hi,
                    method: ConditionMethod::NotPositiveDefinite,
                },
                None,
            )
        }
    }
}

/// Largest eigenvalue of `K x = lambda M x` (0 if none is positive), by
/// power iteration on `M^-1 K` with the Rayleigh quotient `x.Kx / x.Mx`,
/// from a fixed pseudo-random start; stops when it settles to 1e-8
/// relative (at most 2000 iterations). `K` is stored in full, `M` applied
/// through `m_mul` and `m_solve`. The iteration finds the eigenvalue of
/// largest magnitude; where that is negative (an indefinite `K`), it runs
/// again on `K - lambda_neg M`, whose eigenvalues `lambda_i - lambda_neg`
/// are all `>= 0`, and the largest is `lambda_neg` plus its dominant one.
/// Infinite for a mass that is not positive.
fn generalised_lambda_max(
    k: SparseRef<'_>,
    m_mul: impl Fn(&[f64]) -> Vec<f64>,
    m_solve: impl Fn(&[f64]) -> Vec<f64>,
) -> f64 {
    let dominant = power_iteration(k, &m_mul, &m_solve, 0.0);
    if dominant < 0.0 {
        (dominant + power_iteration(k, &m_mul, &m_solve, dominant)).max(0.0)
    } else {
        dominant
    }
}

/// The eigenvalue of largest magnitude of `(K - shift M) x = mu M x`.
fn power_iteration(
    k: SparseRef<'_>,
    m_mul: &impl Fn(&[f64]) -> Vec<f64>,
    m_solve: &impl Fn(&[f64]) -> Vec<f64>,
    shift: f64,
) -> f64 {
    let n = k.nrows();
    let k_mul = |x: &[f64], mx: &[f64]| {
        let mut y: Vec<f64> = mx.iter().map(|m| -shift * m).collect();
        let (ri, v) = (k.row_idx(), k.val());
        for c in 0..n {
            for i in k.symbolic().col_range(c) {
                y[ri[i] as usize] += v[i] * x[c];
            }
        }
        y
    };
    let mut rand = crate::linalg::XorShift::new(0x2545_f491_4f6c_dd1d);
    let mut x: Vec<f64> = (0..n).map(|_| rand.centred()).collect();
    let mut last = 0.0;
    for _ in 0..2000 {
        let mx = m_mul(&x);
        let kx = k_mul(&x, &mx);
        let (xkx, xmx) = (dot(&x, &kx), dot(&x, &mx));
        if !(xmx > 0.0) || !xkx.is_finite() {
            return f64::INFINITY;
        }
        let lambda = xkx / xmx;
        if lambda <= 0.0 && norm(&kx) == 0.0 {
            return 0.0;
        }
        if (lambda - last).abs() <= 1e-8 * lambda.abs() {
            return lambda;
        }
        last = lambda;
        let z = m_solve(&kx);
        let nz = norm(&z);
        if !(nz > 0.0 && nz.is_finite()) {
            return lambda;
        }
        x = z.iter().map(|v| v / nz).collect();
    }
    last
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn cfl(h: f64, lambda_max: f64) -> Option<f64> {
    if lambda_max == 0.0 {
        None
    } else if !lambda_max.is_finite() {
        Some(0.0)
    } else {
        Some(1.0 / (h * lambda_max.sqrt()))
    }
}

/// Mass conditioning and CFL numbers for a mapping and its ghost faces.
fn conditioning_on(sim: &Simulation, map: &Mapping, faces: &[GhostFace]) -> Result<Conditioning, linalg::FactorError> {
    let (mode, limit) = (sim.params.condition, sim.params.dense_limit);
    let masses = &sim.state.points.mass;
    let blocks = blocks_of(map, faces);
    let pattern = Pattern::new(&map.dofs, &blocks, Storage::Lower)?;
    let points = PointsOnGrid::of(sim);
    let mc = consistent_mass(map, &map.dofs, &pattern, &blocks, faces, &points, 0.0)?;
    let ms = consistent_mass(map, &map.dofs, &pattern, &blocks, faces, &points, sim.params.gamma_m)?;
    let (cond_c, fact_c) = spd_condition(mc.as_ref(), mode, limit);
    let (cond_s, fact_s) = spd_condition(ms.as_ref(), mode, limit);
    let lumped = lumped_mass(map, masses);
    let (lo, hi) = lumped
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), &d| (lo.min(d), hi.max(d)));
    let cond_l = Condition {
        value: if lo > 0.0 { hi / lo } else { f64::INFINITY },
        lambda_min: lo,
        lambda_max: hi,
        method: ConditionMethod::Dense,
    };
    // Stiffness: the material tangent at the current state, with and
    // without the ghost term.
    let full = Pattern::new(&map.dofs, &blocks, Storage::Full)?;
    let zero = vec![[0.0; 2]; map.dofs.node_dof.len()];
    let it = crate::bulk::evaluate(sim, map, &zero)?;
    let k = crate::bulk::tangent(sim, map, &full, &blocks, faces, &it, 0.0)?;
    let ks = crate::bulk::tangent(sim, map, &full, &blocks, faces, &it, sim.params.gamma_k)?;
    let h = sim.model.grid.h;
    let with = |k: SparseRef<'_>, m: SparseRef<'_>, f: &Option<Factor>| match f {
        Some(f) => cfl(
            h,
            generalised_lambda_max(k, |x| linalg::sym_lower_mul(m, x), |b| linalg::solve(f, b)),
        ),
        None => Some(0.0),
    };
    Ok(Conditioning {
        mass_consistent: cond_c,
        mass_stabilised: cond_s,
        mass_lumped: cond_l,
        cfl_consistent: with(k.as_ref(), mc.as_ref(), &fact_c),
        cfl_stabilised: with(ks.as_ref(), ms.as_ref(), &fact_s),
        cfl_lumped: if lo > 0.0 {
            cfl(
                h,
                generalised_lambda_max(
                    k.as_ref(),
                    |x| x.iter().zip(&lumped).map(|(x, d)| x * d).collect(),
                    |b| b.iter().zip(&lumped).map(|(b, d)| b / d).collect(),
                ),
            )
        } else {
            Some(0.0)
        },
        stiffness: None,
        stiffness_stabilised: None,
    })
}

/// Mass conditioning and CFL numbers at the current configuration, on
/// demand (any analysis): the consistent, stabilised (`gamma_M` of the
/// parameters) and lumped masses, over the dofs the scene's supports
/// leave free.
pub(crate) fn conditioning(sim: &Simulation) -> Result<Conditioning, linalg::FactorError> {
    let model = &sim.model;
    let map = Mapping::build(&model.grid, &sim.state.points, &model.bodies, &model.dirichlet, 0.0)?;
    let faces = ghost::faces_of(&model.grid, &map, model.analysis.ghost_cells);
    let mut c = conditioning_on(sim, &map, &faces)?;
    let blocks = blocks_of(&map, &faces);
    let lower = Pattern::new(&map.dofs, &blocks, Storage::Lower)?;
    let it = crate::bulk::evaluate(sim, &map, &vec![[0.0; 2]; map.dofs.node_dof.len()])?;
    let (mode, limit) = (sim.params.condition, sim.params.dense_limit);
    let k = |gamma: f64| crate::bulk::tangent(sim, &map, &lower, &blocks, &faces, &it, gamma);
    c.stiffness = Some(spd_condition(k(0.0)?.as_ref(), mode, limit).0);
    c.stiffness_stabilised = Some(spd_condition(k(sim.params.gamma_k)?.as_ref(), mode, limit).0);
    Ok(c)
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
        let analyses = analyse_parts(&map, &parts, &blocks, &faces, &points).map_err(|e| e.to_string())?;
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

    /// The energy guard counts dissipation on the side of what entered:
    /// a plastic run that has dissipated `D` may hold `ku` up to
    /// `factor (W0 + |W| + D)`. With W0 = 2, W = -1 (the loads took 1 J
    /// out), D = 1 and factor 10 the limit is 40 J: 39 passes, 41 does not,
    /// and 40 itself passes (the guard trips beyond the limit; all these
    /// numbers are exact in binary). A run with nothing in it
    /// (W0 = W = D = 0) is never stopped.
    #[test]
    fn energy_guard_limit_is_factor_times_initial_energy_work_and_dissipation() {
        assert_eq!(energy_limit_exceeded(39.0, 2.0, -1.0, 1.0, 10.0), None);
        assert_eq!(energy_limit_exceeded(40.0, 2.0, -1.0, 1.0, 10.0), None);
        assert_eq!(energy_limit_exceeded(41.0, 2.0, -1.0, 1.0, 10.0), Some(40.0));
        assert_eq!(energy_limit_exceeded(1.0, 0.0, 0.0, 0.0, 10.0), None);
    }

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
            let analyses = analyse_parts(&map, &parts, &blocks, &faces, &points).unwrap();
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

    /// The power iteration of the CFL numbers: for `K = diag(3, 2)`, `M =
    /// diag(1, 4)` the largest eigenvalue of `K x = lambda M x` is 3 (the
    /// iteration settles to 1e-8 relative; 1e-6 leaves room). A mass with
    /// A diagonal stiffness `diag(d)`, stored in full as the CFL's `K` is.
    fn diag(d: &[f64]) -> faer::sparse::SparseColMat<linalg::Ix, f64> {
        let t: Vec<_> = (0..d.len())
            .map(|i| faer::sparse::Triplet::new(i as linalg::Ix, i as linalg::Ix, d[i]))
            .collect();
        faer::sparse::SparseColMat::try_new_from_triplets(d.len(), d.len(), &t).unwrap()
    }

    /// `x.Mx <= 0` (`M = -I`, whose "eigenvalue" with `K = I` would be -1)
    /// has no stable explicit step: infinite `lambda_max`, CFL number 0.
    #[test]
    fn generalised_lambda_max_is_infinite_for_a_mass_that_is_not_positive() {
        let mul = |d: [f64; 2]| move |x: &[f64]| vec![d[0] * x[0], d[1] * x[1]];
        let solve = |d: [f64; 2]| move |b: &[f64]| vec![b[0] / d[0], b[1] / d[1]];
        let k = diag(&[3.0, 2.0]);
        let lambda = generalised_lambda_max(k.as_ref(), mul([1.0, 4.0]), solve([1.0, 4.0]));
        assert!((lambda - 3.0).abs() < 1e-6 * 3.0, "{lambda}");
        let k = diag(&[1.0, 1.0]);
        let lambda = generalised_lambda_max(k.as_ref(), mul([-1.0, -1.0]), solve([-1.0, -1.0]));
        assert_eq!(lambda, f64::INFINITY);
        assert_eq!(cfl(1.0, lambda), Some(0.0));
    }

    /// A Rayleigh quotient at or below zero stops the power iteration only
    /// where `K x = 0` (a stress-free mode, lambda_max 0). For an indefinite
    /// `K = diag(-1, c)` (M = I) arranged so that the iteration's fixed
    /// start `x` has `x.Kx < 0`, the dominant eigenvalue `c > 1` is still
    /// found (to the iteration's 1e-8; 1e-6 leaves room).
    #[test]
    fn generalised_lambda_max_goes_on_past_a_negative_start() {
        // The start `generalised_lambda_max` draws.
        let mut rand = crate::linalg::XorShift::new(0x2545_f491_4f6c_dd1d);
        let (a, b) = (rand.centred(), rand.centred());
        // The larger start component on the negative eigenvalue -1, the
        // other on c, halfway between 1 and the ratio that keeps x.Kx < 0.
        let (big, small, first) = if a.abs() >= b.abs() { (a, b, 0) } else { (b, a, 1) };
        let c = 0.5 * (1.0 + (big / small).powi(2));
        let mut d = [c; 2];
        d[first] = -1.0;
        assert!(d[0] * a * a + d[1] * b * b < 0.0 && c > 1.0);
        let lambda = generalised_lambda_max(diag(&d).as_ref(), |x: &[f64]| x.to_vec(), |b: &[f64]| b.to_vec());
        assert!((lambda - c).abs() < 1e-6 * c, "{lambda}, want {c}");
    }

    #[test]
    fn generalised_lambda_max_scales_with_the_stiffness() {
        // K = s diag(1, 2, 3) against M = I: the largest eigenvalue is 3 s
        // for a stiffness in any unit (s from 1e-12 to 1e12); the settle
        // test is relative, so a tiny K converges as far as a big one.
        // The iteration settles at 1e-8 relative change with error
        // ratio (2/3)^2 per step: 1e-6 of 3 s is room for it.
        for s in [1e-12, 1.0, 1e12] {
            let k = diag(&[s, 2.0 * s, 3.0 * s]);
            let lambda = generalised_lambda_max(k.as_ref(), |x: &[f64]| x.to_vec(), |b: &[f64]| b.to_vec());
            assert!(
                (lambda - 3.0 * s).abs() < 1e-6 * 3.0 * s,
                "s = {s}: {lambda}, want {}",
                3.0 * s
            );
        }
    }

    /// Where the eigenvalue of largest magnitude is negative (an indefinite
    /// `K`, as a compressed body's geometric stiffness can make it), the
    /// CFL number comes from the largest positive eigenvalue: `K = diag(-3,
    /// 1, 0.5)` against `M = I` gives 1, so CFL 1 / (h sqrt 1) (to the
    /// iterations' 1e-8 settle test, twice: 1e-6). With no positive
    /// eigenvalue (`diag(-3, -1)`) there is no stability limit: 0, no CFL
    /// number, never the square root of a negative one.
    #[test]
    fn generalised_lambda_max_is_the_largest_positive_eigenvalue_of_an_indefinite_k() {
        let id = |x: &[f64]| x.to_vec();
        let lambda = generalised_lambda_max(diag(&[-3.0, 1.0, 0.5]).as_ref(), id, id);
        assert!((lambda - 1.0).abs() < 1e-6, "{lambda}");
        let c = cfl(0.5, lambda).unwrap();
        assert!((c - 2.0).abs() < 1e-6, "{c}");
        let lambda = generalised_lambda_max(diag(&[-3.0, -1.0]).as_ref(), id, id);
        assert_eq!(lambda, 0.0);
        assert_eq!(cfl(0.5, lambda), None);
    }
}
