//! One finite-deformation load step: updated Lagrangian, Newton-Raphson
//! (G section 2.1; AMPLE; Charlton et al. 2017), with every method of the
//! scene as a contribution to the residual and the tangent.
//!
//! Per step, on the configuration at its start (grid reset):
//!
//! 1. [`Setup::new`]: map points to the grid, collect the contributions
//!    that hold for the whole step (ghost faces, the implicit boundaries'
//!    prescribed increments `d^a`, band and per-point `D` operators, the
//!    dead loads), build the sparsity pattern once;
//! 2. Newton on the nodal unknowns `d` (grid-prescribed components applied
//!    from the start), [`Setup::residual`] and [`Setup::tangent`]:
//!    - material points: `dF = I + grad(S (d + d^a))` (in a band
//!      `I + sum G d + grad(S d^a)`, [`crate::ibm::GradOp`]), the material's
//!      `P = tau dF^-T` and `A = dP/d dF` ([`crate::material::hencky`]),
//!      `f_int = sum_p P : G V0_p`, `K = sum_p V0 G : A : G`;
//!    - ghost faces: `f_G = gamma_K J_G (d + d^a)`, `K_G = gamma_K J_G`
//!      (G (27), on the nodes' whole motion);
//!    - implicit boundaries: the band's `K_band d + f_d` with its blocks
//!      `int B_bar^T C B_bar - B^T C B` (C (18)-(27), on the increment);
//!    - loads: body forces and point loads at `lambda`, tractions on the
//!      boundary curves through the points' positions at this iterate
//!      (a pressure follows the deformed surface), with their load
//!      stiffness `-d f_ext / d d`;
//!
//!    residual `r = f_ext - f_int - f_G - f_band` on the free dofs,
//!    converged when `|r| / (|f_ext| + |reactions|) <= tol`; else factorise
//!    (sparse LU, symbolic analysis reused across iterations), solve, update;
//! 3. commit: `F = dF F_n`, `b_e`, Cauchy `s = tau / det F`, positions
//!    (`x += D S d + S d^a`), `V = det(dF) V_n`, GIMP domains `l = l_0 diag(U)`.
//!
//! Every iteration's residual goes into the report; non-convergence, a
//! singular tangent and non-finite values are [`StepFailure`]s that leave
//! the state at the last good step.

use crate::assembly::{Dof, Mapping, Pattern, Storage};
use crate::boundary::BoundaryReport;
use crate::bulk::{band_gradient, blocks_of, evaluate_with, group_tangent, Iterate};
use crate::geometry::P2;
use crate::ghost::{self, GhostFace};
use crate::ibm::{self, BandBlock, GradOp, IbmBoundary, IbmStep};
use crate::kinematics::{commit_point, increment_gradient};
use crate::linalg::{self, Condition, SparseRef};
use crate::report::{Energy, SolverReport, StepFailure, StepReport, Timings};
use crate::scene::ConditionMode;
use crate::solver::{Factorisation, Symbolic, Symmetry};
use crate::state::Simulation;
use std::time::Instant;

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// 1-norm condition estimate of a tangent through its factorisation
/// (Hager-Higham: a handful of solves on the factor already computed).
fn condition_with(k: SparseRef<'_>, symmetry: Symmetry, f: &mut Factorisation) -> Condition {
    let norm = linalg::one_norm(k, symmetry == Symmetry::Symmetric);
    let failed = std::cell::Cell::new(false);
    let solve = |x: &[f64], f: &mut Factorisation| {
        f.solve(x).unwrap_or_else(|_| {
            failed.set(true);
            vec![f64::INFINITY; x.len()]
        })
    };
    let f = std::cell::RefCell::new(f);
    let c = linalg::one_norm_estimate(
        norm,
        k.nrows(),
        |x| solve(x, &mut f.borrow_mut()),
        |x| match symmetry {
            Symmetry::Symmetric => solve(x, &mut f.borrow_mut()),
            Symmetry::General => f.borrow().solve_transpose(x),
        },
    );
    if failed.get() {
        return infinite_condition();
    }
    c
}

fn infinite_condition() -> Condition {
    Condition {
        value: f64::INFINITY,
        lambda_min: 0.0,
        lambda_max: f64::NAN,
        method: linalg::ConditionMethod::OneNormEstimate,
    }
}

/// The condition estimate of a tangent not factorised yet (the one without
/// the ghost term).
fn condition_of(k: SparseRef<'_>, symmetry: Symmetry, budget: u64) -> Condition {
    match Symbolic::new(k, symmetry).and_then(|s| Factorisation::new(&s, k, budget)) {
        Ok(mut f) => condition_with(k, symmetry, &mut f),
        Err(_) => infinite_condition(),
    }
}

/// The implicit boundaries' contribution for one Newton step.
struct Band<'a> {
    step: IbmStep<'a>,
    /// Per point: its [`GradOp`]s when it lies in a band.
    ops: Vec<Option<Vec<GradOp>>>,
    /// The band's blocks (`K_band`, symmetric) and `f_d` per node.
    blocks: Vec<BandBlock>,
    f_d: Vec<P2>,
}

impl Band<'_> {
    /// `K_band d + f_d`, per node.
    fn force(&self, d: &[P2]) -> Vec<P2> {
        let mut f = self.f_d.clone();
        for (nodes, k) in &self.blocks {
            let m2 = 2 * nodes.len();
            for (a, &na) in nodes.iter().enumerate() {
                for i in 0..2 {
                    let row = &k[(2 * a + i) * m2..(2 * a + i + 1) * m2];
                    f[na][i] += nodes
                        .iter()
                        .enumerate()
                        .map(|(b, &nb)| row[2 * b] * d[nb][0] + row[2 * b + 1] * d[nb][1])
                        .sum::<f64>();
                }
            }
        }
        f
    }
}

/// A traction-carrying boundary's load stiffness block: the nodes its
/// force can reach (rows) and the nodes that move its points (columns).
struct LoadBlock {
    boundary: usize,
    nodes: Vec<usize>,
    /// The columns of the load stiffness: the nodes that move the
    /// boundary's points.
    columns: Vec<LoadColumn>,
}

/// A node that moves some of a boundary's points (by their indices in the
/// boundary) and the segments of its spline those points shape (point `i`
/// shapes segments `i - 3 ..= i + 2`,
/// [`crate::boundary::bspline::Interpolation`]).
struct LoadColumn {
    node: usize,
    points: Vec<usize>,
    segments: Vec<usize>,
}

/// Assembly blocks: point groups, ghost faces, band blocks, load blocks.
fn newton_blocks<'a>(
    map: &'a Mapping,
    faces: &'a [GhostFace],
    band: &'a Option<Band>,
    loads: &'a [LoadBlock],
) -> Vec<&'a [usize]> {
    let mut blocks = blocks_of(map, faces);
    if let Some(b) = band {
        blocks.extend(b.blocks.iter().map(|b| b.0.as_slice()));
    }
    blocks.extend(loads.iter().map(|l| l.nodes.as_slice()));
    blocks
}

/// The columns of boundary `b`'s load stiffness: each node of `nodes`
/// whose stencils move some of its points, those points, and the segments
/// they shape (wrapped on a closed curve, clipped on an open one).
fn load_columns(b: &crate::boundary::Boundary, map: &Mapping, nodes: &[usize]) -> Vec<LoadColumn> {
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

/// What one Newton step keeps fixed over its iterations: the mapping and
/// every method's contribution.
struct Setup<'a> {
    sim: &'a Simulation,
    step: usize,
    lambda: f64,
    /// Load factor at the start of the increment.
    lambda0: f64,
    map: Mapping,
    faces: Vec<GhostFace>,
    gamma: f64,
    band: Option<Band<'a>>,
    /// Body forces and point loads at `lambda`, on the free dofs.
    dead: Vec<f64>,
    /// Loads per unit load factor at the start of the step (tractions on
    /// the curves then) and the internal force of the start-of-step
    /// stresses: the work's trapezoidal rule.
    start_loads: crate::state::Forces,
    /// Each boundary at the start of the step, for the report.
    boundaries: Vec<BoundaryReport>,
    loads: Vec<LoadBlock>,
    /// Symmetric unless a contribution is not (follower tractions' load
    /// stiffness, F-bar): decides the storage and the factorisation.
    symmetry: Symmetry,
    pattern: Pattern,
}

/// The residual's parts at one iterate.
struct Residual {
    it: Iterate,
    /// `f_ext - f_int - f_G - f_band` on the free dofs.
    r: Vec<f64>,
    /// External force at this iterate (free dofs).
    fext: Vec<f64>,
    /// The norm the residual is measured against: external forces plus
    /// reactions (grid supports and implicit boundaries).
    scale: f64,
}

impl<'a> Setup<'a> {
    fn new(
        sim: &'a Simulation,
        ibm_now: &'a [IbmBoundary],
        step: usize,
        lambda0: f64,
        lambda1: f64,
        timings: &mut Timings,
    ) -> Result<Setup<'a>, StepFailure> {
        let start = Instant::now();
        let model = &sim.model;
        let grid = &model.grid;
        let pts = &sim.state.points;
        let mut map = Mapping::build(grid, pts, &model.bodies, &model.dirichlet, lambda1 - lambda0)
            .map_err(|e| e.at_step(step))?;
        let gamma = sim.params.gamma_k;
        let faces = if gamma > 0.0 {
            ghost::faces_of(grid, &map, model.analysis.ghost_cells)
        } else {
            Vec::new()
        };
        let band = if ibm_now.is_empty() {
            None
        } else {
            let s = IbmStep::new(
                ibm_now,
                grid,
                &pts.x,
                sim.params.delta_over_h,
                lambda1 - lambda0,
                model.exact.as_ref(),
            )
            .map_err(|e| StepFailure::Singular {
                step,
                reason: e.to_string(),
            })?;
            // A grid constraint prescribes a node's whole motion: where an
            // implicit boundary also puts d^a on that dof, the grid unknown
            // carries only the rest.
            for (n, c, u) in map.dofs.constrained.iter_mut() {
                *u -= s.da[*n][*c];
            }
            let ops = (0..pts.len())
                .map(|p| {
                    (pts.vol0[p] > 0.0)
                        .then(|| s.gradient_ops(map.stencils.get(p), pts.x[p]))
                        .flatten()
                })
                .collect();
            let material = ibm::BandMaterial::new(grid, &pts.x, &pts.vol, &|p| sim.material_of(p).d_matrix());
            let (blocks, f_d) = s.band(grid, &material);
            Some(Band {
                step: s,
                ops,
                blocks,
                f_d,
            })
        };
        let mapping = start.elapsed().as_secs_f64();
        // Dead loads (body forces and point loads) at lambda; the loads at
        // the start of the step with the tractions on the curves then (for
        // the work's trapezoidal rule) and each boundary as it is then.
        let mut start_loads = sim.dead_forces(&map);
        let dead: Vec<f64> = start_loads.ext.iter().map(|f| lambda1 * f).collect();
        let boundaries = sim.add_tractions(&map, step, lambda1, &mut start_loads.ext)?;
        // Tractions: a load stiffness block per loaded boundary over the
        // nodes its force can reach during the step (the cells the curve
        // cuts now and their neighbours: a curve moving into a new cell
        // within the step must keep its rows, or Newton falls to a linear
        // rate) and the nodes that move its points.
        let mut loads = Vec::new();
        for (k, b) in model.boundaries.iter().enumerate() {
            if b.traction.is_none() {
                continue;
            }
            let spline = b.spline(pts).map_err(|e| StepFailure::Boundary {
                step,
                name: b.name.clone(),
                reason: e.to_string(),
            })?;
            let mut nodes: Vec<usize> = crate::boundary::intersect::split(&spline, grid)
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
            let columns = load_columns(b, &map, &nodes);
            loads.push(LoadBlock {
                boundary: k,
                nodes,
                columns,
            });
        }
        let symmetry = if sim.model.analysis.fbar || !loads.is_empty() {
            Symmetry::General
        } else {
            Symmetry::Symmetric
        };
        let storage = match symmetry {
            Symmetry::Symmetric => Storage::Lower,
            Symmetry::General => Storage::Full,
        };
        let t = Instant::now();
        let pattern = Pattern::new(&map.dofs, &newton_blocks(&map, &faces, &band, &loads), storage)
            .map_err(|e| e.at_step(step))?;
        let pattern_time = t.elapsed().as_secs_f64();
        timings.mapping += mapping;
        timings.pattern += pattern_time;
        timings.assembly += start.elapsed().as_secs_f64() - pattern_time - mapping;
        Ok(Setup {
            sim,
            step,
            lambda: lambda1,
            lambda0,
            map,
            faces,
            gamma,
            band,
            dead,
            start_loads,
            boundaries,
            loads,
            symmetry,
            pattern,
        })
    }

    fn blocks(&self) -> Vec<&[usize]> {
        newton_blocks(&self.map, &self.faces, &self.band, &self.loads)
    }

    /// The nodes' whole motion `d + d^a` at unknowns `d` ([`crate::ibm::nodal_motion`]).
    fn motion(&self, d: &[P2]) -> Vec<P2> {
        crate::ibm::nodal_motion(d, self.band.as_ref().map(|b| &b.step))
    }

    /// Where point `p` is at unknowns `d`: `x + D S d + S d^a`.
    fn moved(&self, p: usize, d: &[P2]) -> P2 {
        let x = self.sim.state.points.x[p];
        let st = self.map.stencils.get(p);
        let u = match &self.band {
            Some(b) => b.step.point_increment(st, x, d),
            None => st.interpolate(|n| d[n]),
        };
        [x[0] + u[0], x[1] + u[1]]
    }

    /// Nodal forces (at load factor 1) of boundary `k`'s traction with its
    /// points at `xs` (indexed like the boundary's points).
    fn traction(&self, k: usize, xs: &[P2]) -> Result<(Vec<(usize, P2)>, BoundaryReport), StepFailure> {
        let model = &self.sim.model;
        let b = &model.boundaries[k];
        let spline = crate::boundary::bspline::BSpline::interpolate(xs, b.closed, &b.corners).map_err(|e| {
            StepFailure::Boundary {
                step: self.step,
                name: b.name.clone(),
                reason: e.to_string(),
            }
        })?;
        let active = |n: usize| self.map.dofs.node_dof[n][0] != Dof::Inactive;
        Ok(crate::boundary::traction_forces(
            b,
            &spline,
            &model.grid,
            model.exact.as_ref(),
            &active,
            self.lambda,
        ))
    }

    /// The residual and its parts at unknowns `d` (grid-prescribed
    /// components included).
    fn residual(&self, d: &[P2]) -> Result<Residual, StepFailure> {
        let map = &self.map;
        let motion = self.motion(d);
        let band = self.band.as_ref().map(|b| (&b.ops[..], d, &b.step.da[..]));
        let it = evaluate_with(self.sim, map, &motion, band).map_err(|e| e.at_step(self.step))?;
        let mut fext = self.dead.clone();
        for l in &self.loads {
            let b = &self.sim.model.boundaries[l.boundary];
            let xs: Vec<P2> = b.points.iter().map(|&p| self.moved(p, d)).collect();
            for (n, f) in self.traction(l.boundary, &xs)?.0 {
                for c in 0..2 {
                    if let Dof::Free(i) = map.dofs.node_dof[n][c] {
                        fext[i] += self.lambda * f[c];
                    }
                }
            }
        }
        // Ghost force f_G = gamma J_G (d + d^a) on the free rows: the
        // penalty acts on the nodes' whole motion, whose normal derivative
        // a linear field leaves without jumps (the unknowns d alone have
        // them where d^a ends).
        let mut fg = vec![0.0; map.dofs.n_free];
        for f in &self.faces {
            for row in 0..6 {
                for c in 0..2 {
                    let Dof::Free(i) = map.dofs.node_dof[f.nodes[row]][c] else {
                        continue;
                    };
                    fg[i] += self.gamma * (0..6).map(|k| f.j[row][k] * motion[f.nodes[k]][c]).sum::<f64>();
                }
            }
        }
        let mut r: Vec<f64> = (0..map.dofs.n_free)
            .map(|i| fext[i] - it.fint_free[i] - fg[i])
            .collect();
        let mut reaction = norm(&it.fint_fixed);
        if let Some(b) = &self.band {
            let fb = b.force(d);
            let mut sq = 0.0;
            for (n, dofs) in map.dofs.node_dof.iter().enumerate() {
                for c in 0..2 {
                    if let Dof::Free(i) = dofs[c] {
                        r[i] -= fb[n][c];
                        sq += fb[n][c] * fb[n][c];
                    }
                }
            }
            reaction += sq.sqrt();
        }
        Ok(Residual {
            scale: norm(&fext) + reaction,
            it,
            r,
            fext,
        })
    }

    /// Load stiffness of boundary block `l` at `d`: `-d f_ext / d d` by
    /// central differences of the traction in each nodal unknown that
    /// moves the boundary's points (difference step 1e-6 h: the traction is
    /// smooth in `d` between grid-line crossings, so the derivative holds to
    /// about 1e-9 relative). Differencing in `d` rather than in the points'
    /// positions keeps the motions Newton takes: points of one cell stay
    /// collinear under `S d`, where B's tangent weights `|q x q|` are not
    /// differentiable in a single point's position.
    ///
    /// Each difference re-interpolates and re-integrates only the segments
    /// the moved points shape (the interpolation is local), with the
    /// collinearity tolerance of the unperturbed curve: the block costs
    /// time in proportion to the boundary's length, not its square.
    fn load_block(&self, l: &LoadBlock, d: &[P2], out: &mut Vec<f64>) -> Result<(), StepFailure> {
        use crate::boundary::bspline::Interpolation;
        let model = &self.sim.model;
        let b = &model.boundaries[l.boundary];
        let m2 = 2 * l.nodes.len();
        out.clear();
        out.resize(m2 * m2, 0.0);
        let local = |n: usize| l.nodes.binary_search(&n).ok();
        let eps = 1e-6 * model.grid.h;
        let x0: Vec<P2> = b.points.iter().map(|&p| self.moved(p, d)).collect();
        // The unperturbed curve's checks and collinearity scale.
        let scale = Interpolation::new(&x0, b.closed, &b.corners)
            .map_err(|e| StepFailure::Boundary {
                step: self.step,
                name: b.name.clone(),
                reason: e.to_string(),
            })?
            .scale();
        let (mut xs, mut shifted) = (x0.clone(), d.to_vec());
        for col in &l.columns {
            let (m, bb) = (col.node, local(col.node).expect("columns are block nodes"));
            for k in 0..2 {
                for sign in [1.0, -1.0] {
                    shifted[m][k] = d[m][k] + sign * eps;
                    for &i in &col.points {
                        xs[i] = self.moved(b.points[i], &shifted);
                    }
                    shifted[m][k] = d[m][k];
                    let spline = Interpolation::with_scale(&xs, b.closed, &b.corners, scale).spline_of(&col.segments);
                    let pieces = crate::boundary::intersect::split(&spline, &model.grid);
                    crate::boundary::integrate_traction(
                        b,
                        &spline,
                        &pieces,
                        &model.grid,
                        model.exact.as_ref(),
                        |n, f| {
                            if let (Some(a), true) = (local(n), self.map.dofs.node_dof[n][0] != Dof::Inactive) {
                                for i in 0..2 {
                                    out[(2 * a + i) * m2 + 2 * bb + k] -= sign * self.lambda * f[i] / (2.0 * eps);
                                }
                            }
                        },
                    );
                    for &i in &col.points {
                        xs[i] = x0[i];
                    }
                }
            }
        }
        Ok(())
    }

    /// The matrix of a tangent's `values` over the step's pattern.
    fn matrix<'v>(&'v self, values: &'v [f64]) -> SparseRef<'v> {
        self.pattern.matrix(values)
    }

    /// The tangent of the residual at `d` (its negative derivative), with
    /// the ghost term scaled by `gamma`: its values over the step's pattern
    /// ([`Setup::matrix`]).
    fn tangent(&self, res: &Residual, d: &[P2], gamma: f64) -> Result<Vec<f64>, StepFailure> {
        let (ng, nf) = (self.map.groups.len(), self.faces.len());
        let nb = self.band.as_ref().map_or(0, |b| b.blocks.len());
        let blocks = self.blocks();
        let mut failure = None;
        let ops = self.band.as_ref().map(|b| b.ops.as_slice());
        let assembled = self.pattern.assemble_with(&self.map.dofs, &blocks, |b, out| {
            if b < ng {
                group_tangent(self.sim, &self.map, &res.it, ops, b, out)
            } else if b < ng + nf {
                self.faces[b - ng].stiffness(gamma, out)
            } else if b < ng + nf + nb {
                out.clear();
                out.extend_from_slice(&self.band.as_ref().expect("nb > 0").blocks[b - ng - nf].1);
            } else if let Err(e) = self.load_block(&self.loads[b - ng - nf - nb], d, out) {
                failure = Some(e);
            }
        });
        match (failure, assembled) {
            (Some(e), _) => Err(e),
            (None, Err(e)) => Err(e.at_step(self.step)),
            (None, Ok((k, _))) => Ok(k),
        }
    }
}

/// One finite-deformation load step from `lambda_n` to `lambda_{n+1}`: one
/// increment, or, when it fails, the increment cut back: halved and retried
/// from the last converged state, at most `analysis.max_cutbacks` times in
/// a row, growing back after easy increments
/// ([`crate::cutback::Policy::load_step`]).
pub(crate) fn finite_step(sim: &mut Simulation) -> Result<StepReport, StepFailure> {
    let step = sim.state.step + 1;
    let steps = sim.load_steps();
    let (lambda0, lambda1) = ((step - 1) as f64 / steps as f64, step as f64 / steps as f64);
    let policy = crate::cutback::Policy::load_step(sim);
    let whole = crate::cutback::Span::whole(lambda0, lambda1, lambda1 - lambda0);
    crate::cutback::step(sim, &policy, whole, |sim, s| increment(sim, step, s.from, s.to, s.last))
}

/// One increment `lambda0 -> lambda1` of load step `step`, committed with
/// the step's number when it is the step's `last` (else the state keeps the
/// previous step's number, at the load factor reached): each phase is a
/// function below.
fn increment(
    sim: &mut Simulation,
    step: usize,
    lambda0: f64,
    lambda1: f64,
    last: bool,
) -> Result<StepReport, StepFailure> {
    let steps = sim.load_steps();
    let start = Instant::now();
    let mut timings = Timings::default();

    // 1. Map the points and collect every method's contribution; the loads
    //    at the start of the step (for the work) and the boundaries then.
    let ibm_now = sim.ibm_boundaries_now(step)?;
    let setup = Setup::new(sim, &ibm_now, step, lambda0, lambda1, &mut timings)?;
    // 2. Newton on the nodal unknowns.
    let mut solved = newton(&setup, &mut timings)?;
    // 3. Condition numbers of the last tangent (of the step's last
    //    increment).
    let t = Instant::now();
    let (condition, condition_unstabilised) = if last {
        conditioning(&setup, &mut solved)?
    } else {
        (None, None)
    };
    timings.condition = t.elapsed().as_secs_f64();
    // 4. The points' new state, the work of loads and supports, and the
    //    implicit boundaries' reactions (the last tangent and its factor
    //    are freed first: the fields the step writes are copied).
    let factor = solved.last.take().map(|(_, f)| (f.kind(), f.negative_pivots()));
    let t = Instant::now();
    let updated = update(&setup, &solved)?;
    timings.update = t.elapsed().as_secs_f64();
    // 5. Commit and report.
    let (faces, boundaries) = (setup.faces.clone(), setup.boundaries.clone());
    let motion = setup.motion(&solved.d);
    let ghost_force = ghost::force(&faces, setup.gamma, &motion);
    let ghost = ghost::step_work(&sim.state.ghost_force, &ghost_force, &motion);
    let map = &setup.map;
    let (active, n_free, active_nodes) = (map.active_cells.clone(), map.dofs.n_free, map.dofs.active_nodes);
    drop(setup);
    let active_cells = active.len();
    let work = updated.work;
    sim.state.ghost_energy += ghost;
    sim.state.ghost_force = ghost_force;
    sim.commit_quasi_static(
        updated.points,
        if last { step } else { step - 1 },
        work,
        active,
        &faces,
        solved.iterations,
        lambda1 - lambda0,
    );
    let errors = sim.exact_errors(lambda1);
    timings.total = start.elapsed().as_secs_f64();
    Ok(StepReport {
        step,
        load_steps: steps,
        load_factor: lambda1,
        unknowns: n_free,
        active_nodes,
        active_cells,
        residual_norm: norm(&solved.res.fext),
        residuals: solved.residuals,
        timings,
        energy: Energy {
            strain: updated.strain_energy,
            external_work: sim.state.external_work,
            plastic_dissipation: updated.dissipation,
            kinetic: 0.0,
            ghost: sim.state.ghost_energy,
        },
        condition,
        condition_unstabilised,
        iterations: solved.iterations,
        ghost_faces: faces.len(),
        ibm: updated.ibm,
        errors,
        max_increment: updated.max_increment,
        boundaries,
        dynamics: None,
        solver: Some(SolverReport {
            factorisation: factor.map(|f| f.0),
            negative_pivots: factor.and_then(|f| f.1),
            cutbacks: Vec::new(),
            substeps: 1,
        }),
        probes: Vec::new(),
    })
}

/// A converged Newton solve.
struct Solved {
    /// The nodal unknowns `d` (grid-prescribed components included).
    d: Vec<P2>,
    /// The residual and the points' response at `d`.
    res: Residual,
    /// Relative residual of every iteration.
    residuals: Vec<f64>,
    iterations: usize,
    /// The last tangent and its factorisation (for the condition number,
    /// the factorisation used and the inertia).
    last: Option<(Vec<f64>, Factorisation)>,
}

/// Newton-Raphson on the step's residual: tangent, factorisation by
/// structure ([`crate::solver`]: Cholesky, `L D L^T` or LU, the symbolic
/// analysis reused by every iteration), full correction, until the relative
/// residual is below the tolerance.
fn newton(setup: &Setup, timings: &mut Timings) -> Result<Solved, StepFailure> {
    let (sim, step, map) = (setup.sim, setup.step, &setup.map);
    let params = &sim.params;
    let mut d = vec![[0.0; 2]; sim.model.grid.num_nodes()];
    for &(n, c, v) in &map.dofs.constrained {
        d[n][c] = v;
    }
    let mut residuals = Vec::new();
    let mut symbolic = None;
    let mut last = None;
    let mut iterations = 0;
    let relative = |res: &Residual| norm(&res.r) / if res.scale > 0.0 { res.scale } else { 1.0 };
    let t = Instant::now();
    let mut res = setup.residual(&d)?;
    timings.assembly += t.elapsed().as_secs_f64();
    loop {
        let rel = relative(&res);
        residuals.push(rel);
        if !sim.report_progress(step, iterations, rel) {
            return Err(StepFailure::Cancelled { step, residuals });
        }
        if !rel.is_finite() {
            return Err(StepFailure::NonFinite {
                step,
                what: "Newton residual".into(),
                residuals,
            });
        }
        if rel <= params.tolerance {
            return Ok(Solved {
                d,
                res,
                residuals,
                iterations,
                last,
            });
        }
        if iterations >= params.max_iterations {
            return Err(StepFailure::NotConverged {
                step,
                residuals,
                tolerance: params.tolerance,
            });
        }
        // The previous tangent and its factor are read only after the last
        // iteration: free them before the next are built, so that two
        // factors are never held at once.
        drop(last.take());
        let t = Instant::now();
        let k = setup.tangent(&res, &d, setup.gamma)?;
        timings.assembly += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let singular = |e: linalg::FactorError| e.at_step(step);
        if symbolic.is_none() {
            symbolic = Some(Symbolic::new(setup.matrix(&k), setup.symmetry).map_err(singular)?);
        }
        let Some(analysis) = symbolic.as_ref() else {
            return Err(StepFailure::Internal {
                step,
                message: "no symbolic analysis".into(),
            });
        };
        let mut factor =
            Factorisation::new(analysis, setup.matrix(&k), setup.sim.model.max_memory).map_err(singular)?;
        timings.factorisation += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let dd = factor.solve(&res.r).map_err(singular)?;
        timings.solve += t.elapsed().as_secs_f64();
        if dd.iter().any(|v| !v.is_finite()) {
            return Err(StepFailure::Singular {
                step,
                reason: format!(
                    "the tangent is numerically singular (non-finite Newton correction at iteration {})",
                    iterations + 1
                ),
            });
        }
        // The full correction; its residual opens the next iteration. With
        // `analysis.line_search`, a correction that makes the residual
        // non-finite or larger is halved (at most 10 times) first.
        let t = Instant::now();
        let mut alpha = 1.0;
        let start = d.clone();
        loop {
            for (n, dofs) in map.dofs.node_dof.iter().enumerate() {
                for c in 0..2 {
                    if let Dof::Free(i) = dofs[c] {
                        d[n][c] = start[n][c] + alpha * dd[i];
                    }
                }
            }
            res = setup.residual(&d)?;
            let better = relative(&res) <= rel;
            if !sim.model.analysis.line_search || better || alpha < 1e-3 {
                break;
            }
            alpha *= 0.5;
        }
        timings.assembly += t.elapsed().as_secs_f64();
        last = Some((k, factor));
        iterations += 1;
    }
}

/// Condition numbers of the last tangent, with and without the ghost term
/// (1-norm estimates through the LU factor).
fn conditioning(setup: &Setup, solved: &mut Solved) -> Result<(Option<Condition>, Option<Condition>), StepFailure> {
    if setup.sim.params.condition == ConditionMode::Off || setup.map.dofs.n_free == 0 {
        return Ok((None, None));
    }
    let with = match &mut solved.last {
        Some((k, f)) => condition_with(setup.matrix(k), setup.symmetry, f),
        None => condition_of(
            setup.matrix(&setup.tangent(&solved.res, &solved.d, setup.gamma)?),
            setup.symmetry,
            setup.sim.model.max_memory,
        ),
    };
    let without = if setup.faces.is_empty() {
        None
    } else {
        Some(condition_of(
            setup.matrix(&setup.tangent(&solved.res, &solved.d, 0.0)?),
            setup.symmetry,
            setup.sim.model.max_memory,
        ))
    };
    Ok((Some(with), without))
}

/// The points after a converged step, and what the step did.
struct Updated {
    points: crate::points::Points,
    strain_energy: f64,
    dissipation: f64,
    /// Work of loads, supports and implicit boundaries over the step (J).
    work: f64,
    ibm: Vec<crate::ibm::IbmReport>,
    max_increment: f64,
}

/// Commit the converged increment into a copy of the fields it changes
/// (`F`, `b_e`, stress, positions `x + D S d + S d^a`, volumes, GIMP
/// domains; [`crate::points::Points::finite_copy`]), check them, and
/// account the work: free dofs carry `f_ext` (trapezoidal between
/// the step's start and end, tractions on their curves then), prescribed
/// dofs their support force, implicit boundaries their reactions.
fn update(setup: &Setup, solved: &Solved) -> Result<Updated, StepFailure> {
    let (sim, map, d) = (setup.sim, &setup.map, &solved.d);
    let (res, it) = (&solved.res, &solved.res.it);
    let lambda1 = setup.lambda;
    let lambda0 = setup.lambda0;
    let old = &sim.state.points;
    let mut pts = old.finite_copy().map_err(|_| {
        linalg::FactorError::allocation("the points' new state", old.len().saturating_mul(145)).at_step(setup.step)
    })?;
    let (mut strain_energy, mut dissipation) = (0.0, 0.0);
    let total = setup.motion(d);
    for p in 0..pts.len() {
        let st = map.stencils.get(p);
        let x = setup.moved(p, d);
        let df = match setup.band.as_ref().and_then(|b| b.ops[p].as_ref().map(|o| (o, b))) {
            Some((ops, b)) => band_gradient(st, ops, d, &b.step.da),
            None => increment_gradient(st, &total),
        };
        pts.x[p] = x;
        if let Some((w, diss)) = commit_point(old, &mut pts, p, &df, it.responses[p].as_ref(), &sim.hencky(p)) {
            strain_energy += w;
            dissipation += diss;
        }
    }
    crate::state::check_points(&sim.model.grid, &pts, setup.step, &solved.residuals)?;
    let forces = &setup.start_loads;
    let mut work = 0.0;
    let traction = !setup.loads.is_empty();
    for (n, dofs) in map.dofs.node_dof.iter().enumerate() {
        for c in 0..2 {
            match dofs[c] {
                Dof::Free(i) if traction => {
                    work += 0.5 * (lambda0 * forces.ext[i] + res.fext[i]) * total[n][c];
                }
                Dof::Free(i) => work += 0.5 * (lambda0 + lambda1) * forces.ext[i] * total[n][c],
                Dof::Fixed(i) => work += 0.5 * (forces.int_fixed[i] + it.fint_fixed[i]) * total[n][c],
                Dof::Inactive => {}
            }
        }
    }
    let mut ibm = Vec::new();
    if let Some(b) = &setup.band {
        // Out-of-balance of the points at the start (zero increment) and
        // the end of the step: the implicit boundaries' reactions.
        let zero = vec![[0.0; 2]; d.len()];
        let it0 = evaluate_with(sim, map, &zero, Some((&b.ops, &zero, &zero))).map_err(|e| e.at_step(setup.step))?;
        // At grid-held dofs the internal force: a node shared with a grid
        // support splits it with that support (`IbmStep::reports`).
        let per_node = |fint: &[f64], fixed: &[f64], ext: &dyn Fn(usize) -> f64| {
            let mut out = vec![[0.0; 2]; d.len()];
            for (n, dofs) in map.dofs.node_dof.iter().enumerate() {
                for c in 0..2 {
                    match dofs[c] {
                        Dof::Free(i) => out[n][c] = fint[i] - ext(i),
                        Dof::Fixed(i) => out[n][c] = fixed[i],
                        Dof::Inactive => {}
                    }
                }
            }
            out
        };
        let r0 = per_node(&it0.fint_free, &it0.fint_fixed, &|i| lambda0 * forces.ext[i]);
        let r1 = per_node(&it.fint_free, &it.fint_fixed, &|i| res.fext[i]);
        let (reports, w) = b.step.reports(
            &sim.model.grid,
            &|n, c| matches!(map.dofs.node_dof[n][c], Dof::Free(_)),
            &r0,
            &r1,
            d,
            sim.model.exact.as_ref(),
            lambda1 - lambda0,
        );
        ibm = reports;
        work += w;
    }
    let max_increment = total.iter().map(|u| u[0].hypot(u[1])).fold(0.0, f64::max);
    Ok(Updated {
        points: pts,
        strain_energy,
        dissipation,
        work,
        ibm,
        max_increment,
    })
}

/// Largest relative difference between the assembled finite-deformation
/// tangent (every contribution: points, ghost, implicit boundaries,
/// traction load stiffness) and central finite differences of the
/// out-of-balance force, at a reproducible pseudo-random trial increment
/// of size `amplitude * h`, along 4 pseudo-random directions, for the
/// next step's load factor. A diagnostic for developers and the test
/// suite; `Err` when the step's contributions cannot be built.
pub(crate) fn tangent_check(sim: &Simulation, amplitude: f64) -> Result<f64, StepFailure> {
    let step = sim.state.step + 1;
    let steps = sim.load_steps();
    let ibm_now = sim.ibm_boundaries_now(step)?;
    let (l0, l1) = ((step - 1) as f64 / steps as f64, step as f64 / steps as f64);
    let setup = Setup::new(sim, &ibm_now, step, l0, l1, &mut Timings::default())?;
    let map = &setup.map;
    let mut rand = crate::linalg::XorShift::new(0x9e37_79b9_7f4a_7c15);
    let h = sim.model.grid.h;
    let mut d = vec![[0.0; 2]; sim.model.grid.num_nodes()];
    for &(n, c, v) in &map.dofs.constrained {
        d[n][c] = v;
    }
    for (n, dofs) in map.dofs.node_dof.iter().enumerate() {
        for c in 0..2 {
            if let Dof::Free(_) = dofs[c] {
                d[n][c] = amplitude * h * rand.centred();
            }
        }
    }
    let res = setup.residual(&d)?;
    let values = setup.tangent(&res, &d, setup.gamma)?;
    let k = setup.matrix(&values);
    let (ri, val) = (k.row_idx(), k.val());
    let mut worst = 0.0f64;
    for _ in 0..4 {
        let v: Vec<f64> = (0..map.dofs.n_free).map(|_| rand.centred()).collect();
        let kv = match setup.symmetry {
            Symmetry::Symmetric => linalg::sym_lower_mul(k, &v),
            Symmetry::General => {
                let mut kv = vec![0.0; map.dofs.n_free];
                for c in 0..k.ncols() {
                    for idx in k.symbolic().col_range(c) {
                        kv[ri[idx] as usize] += val[idx] * v[c];
                    }
                }
                kv
            }
        };
        let eps = 1e-6 * h;
        let shifted = |sign: f64| -> Result<Vec<f64>, StepFailure> {
            let mut s = d.clone();
            for (n, dd) in map.dofs.node_dof.iter().enumerate() {
                for c in 0..2 {
                    if let Dof::Free(i) = dd[c] {
                        s[n][c] += sign * eps * v[i];
                    }
                }
            }
            Ok(setup.residual(&s)?.r)
        };
        let (rp, rm) = (shifted(1.0)?, shifted(-1.0)?);
        // K = -dr/dd.
        let fd: Vec<f64> = rp.iter().zip(&rm).map(|(a, b)| -(a - b) / (2.0 * eps)).collect();
        let diff: Vec<f64> = fd.iter().zip(&kv).map(|(a, b)| a - b).collect();
        worst = worst.max(norm(&diff) / norm(&kv).max(1e-300));
    }
    Ok(worst)
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::sparse::{SparseColMat, Triplet};

    /// `condition_with` reads a symmetric tangent from its lower triangle
    /// and a general one from all its entries. `A = [[4, 1, 0], [1, 4, 3],
    /// [0, 3, 10]]`: `|A|_1 = 13` (the third column; from the lower triangle
    /// alone it would be 10, from all entries counted twice 16), and by
    /// cofactors `A^-1 = [[31, -10, 3], [-10, 40, -12], [3, -12, 15]] / 114`,
    /// `|A^-1|_1 = 62/114` (the second column). Hager's iteration reaches
    /// that column on its third solve (by hand: `x = 1/3`, then `e_0`, then
    /// `e_1`), and Higham's extra vector gives less (394/1026), so the
    /// estimate is exactly `13 * 62/114`, to round-off in the solves.
    #[test]
    fn condition_estimate_is_the_one_norm_condition_of_the_stored_matrix() {
        let a = [[4.0, 1.0, 0.0], [1.0, 4.0, 3.0], [0.0, 3.0, 10.0]];
        let exact = 13.0 * 62.0 / 114.0;
        for symmetry in [Symmetry::Symmetric, Symmetry::General] {
            let mut t = Vec::new();
            for c in 0..3 {
                for r in 0..3 {
                    let stored = symmetry == Symmetry::General || r >= c;
                    if a[r][c] != 0.0 && stored {
                        t.push(Triplet::new(r as linalg::Ix, c as linalg::Ix, a[r][c]));
                    }
                }
            }
            let k = SparseColMat::try_new_from_triplets(3, 3, &t).unwrap();
            let s = Symbolic::new(k.as_ref(), symmetry).unwrap();
            let mut f = Factorisation::new(&s, k.as_ref(), u64::MAX).unwrap();
            let c = condition_with(k.as_ref(), symmetry, &mut f);
            assert!(
                (c.value - exact).abs() < 1e-12 * exact,
                "{symmetry:?}: {} against {exact}",
                c.value
            );
            assert_eq!(c.lambda_max, 13.0, "{symmetry:?}: the 1-norm");
        }
    }
}
