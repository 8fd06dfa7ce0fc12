//! One finite-deformation load step: updated Lagrangian, Newton-Raphson
//! (G section 2.1; AMPLE; Charlton et al. 2017), with every method of the
//! scene as a contribution to the residual and the tangent.
//!
//! Per step, on the configuration at its start (grid reset):
//!
//! 1. [`Setup::new`]: the step's [`Frame`] (points on the grid, ghost
//!    faces, the implicit boundaries' prescribed increments `d^a` and
//!    per-point band operators) and its contributions in one list
//!    ([`crate::implicit::contributions`]), the sparsity pattern once;
//! 2. Newton on the nodal unknowns `d` (grid-prescribed components applied
//!    from the start), on the core's residual and tangent
//!    ([`Assembly::residual`], [`Assembly::tangent`]), summed over the
//!    contributions:
//!    - material points ([`crate::bulk::FinitePoints`]): `dF = I + grad(S (d + d^a))` (in a band
//!      `I + sum G d + grad(S d^a)`, [`crate::ibm::GradOp`]), the material's
//!      `P = tau dF^-T` and `A = dP/d dF` ([`crate::material::hencky`]),
//!      `f_int = sum_p P : G V0_p`, `K = sum_p V0 G : A : G`;
//!    - ghost faces ([`crate::ghost::GhostPenalty`]): `f_G = gamma_K J_G (d + d^a)`, `K_G = gamma_K J_G`
//!      (G (27), on the nodes' whole motion);
//!    - implicit boundaries ([`crate::ibm::Band`]): the band's `K_band d + f_d` with its blocks
//!      `int B_bar^T C B_bar - B^T C B` (C (18)-(27), on the increment);
//!    - loads ([`crate::loads::DeadLoads`], [`crate::boundary::TractionLoad`]):
//!      body forces and point loads at `lambda`, tractions on the
//!      boundary curves through the points' positions at this iterate
//!      (a pressure follows the deformed surface), with their load
//!      stiffness `-d f_ext / d d`;
//!
//!    residual `r = f_ext - f_int - f_G - f_band` on the free dofs,
//!    converged when `|r| / (|f_ext| + |reactions|) <= tol`; else factorise
//!    (sparse LU, symbolic analysis reused across iterations), solve, update;
//! 3. commit ([`crate::implicit::finish`]): `F = dF F_n`, `b_e`, Cauchy `s = tau / det F`, positions
//!    (`x += D S d + S d^a`), `V = det(dF) V_n`, GIMP domains `l = l_0 diag(U)`.
//!
//! Every iteration's residual goes into the report; non-convergence, a
//! singular tangent and non-finite values are [`StepFailure`]s that leave
//! the state at the last good step.

use crate::assembly::Dof;
use crate::boundary::BoundaryReport;
use crate::bulk::band_gradient;
use crate::geometry::P2;
use crate::ibm::IbmBoundary;
use crate::implicit::{
    band, contributions, finish, norm, Assembly, Done, Frame, Inertia, Interval, Newmark, Residual, Response,
};
use crate::kinematics::{commit_point, increment_gradient};
use crate::linalg::{self, Condition, SparseRef};
use crate::report::{Attainable, SolverReport, StepFailure, StepReport, Timings};
use crate::scene::ConditionMode;
use crate::solver::{Factorisation, Symbolic, Symmetry};
use crate::state::Simulation;
use std::time::Instant;

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

/// What one Newton step keeps fixed over its iterations: the frame (the
/// mapping, the implicit boundaries' `d^a`, the ghost faces) and the
/// contributions in one list: the points, the ghost penalty, the band, the
/// dead loads and each traction's load.
struct Setup<'a> {
    frame: Frame<'a>,
    assembly: Assembly,
    /// Loads per unit load factor at the start of the step (tractions on
    /// the curves then) and the internal force of the start-of-step
    /// stresses: the work's trapezoidal rule.
    start_loads: crate::state::Forces,
    /// Each boundary at the start of the step, for the report.
    boundaries: Vec<BoundaryReport>,
    /// Implicit dynamics: the step's inertia (also in the list).
    inertia: Option<std::sync::Arc<Inertia>>,
}

/// What drives a Newton step beside the loads: nothing (quasi-static), or
/// inertia over a time step (implicit dynamics, [`crate::newmark`]).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Drive {
    QuasiStatic,
    Dynamic { scheme: Newmark },
}

impl<'a> Setup<'a> {
    fn new(
        sim: &'a Simulation,
        ibm_now: &'a [IbmBoundary],
        step: usize,
        interval: Interval,
        drive: Drive,
        timings: &mut Timings,
    ) -> Result<Setup<'a>, StepFailure> {
        let start = Instant::now();
        let frame = Frame::new(sim, ibm_now, step, interval, true)?;
        let mapping = start.elapsed().as_secs_f64();
        // Dead loads (body forces and point loads) at lambda; the loads at
        // the start of the step with the tractions on the curves then (for
        // the work's trapezoidal rule) and each boundary as it is then.
        let lambda1 = interval.load.1;
        let mut start_loads = sim.dead_forces(&frame.map);
        let dead: Vec<f64> = start_loads.ext.iter().map(|f| lambda1 * f).collect();
        let boundaries = sim.add_tractions(&frame.map, step, lambda1, &mut start_loads.ext)?;
        // Inertia: the grid's start velocity mapped from the points, its
        // start acceleration that of the out-of-balance force on it.
        let inertia = match drive {
            Drive::QuasiStatic => None,
            Drive::Dynamic { scheme } => {
                let mut r0: Vec<f64> = start_loads
                    .ext
                    .iter()
                    .zip(&start_loads.int)
                    .map(|(e, i)| interval.load.0 * e - i)
                    .collect();
                for (n, f) in sim.state.constraint_force.iter().enumerate() {
                    for (c, f) in f.iter().enumerate() {
                        if let Some(i) = frame.free(n, c) {
                            r0[i] -= f;
                        }
                    }
                }
                let previous = &sim.state.grid_acceleration;
                Some(std::sync::Arc::new(Inertia::new(&frame, scheme, &r0, previous)?))
            }
        };
        let list = contributions(&frame, Response::Finite, dead, inertia.clone())?;
        let t = Instant::now();
        let assembly = Assembly::new(&frame, list)?;
        let pattern_time = t.elapsed().as_secs_f64();
        timings.mapping += mapping;
        timings.pattern += pattern_time;
        timings.assembly += start.elapsed().as_secs_f64() - pattern_time - mapping;
        Ok(Setup {
            frame,
            assembly,
            start_loads,
            boundaries,
            inertia,
        })
    }

    fn residual(&self, d: &[P2]) -> Result<Residual, StepFailure> {
        self.assembly.residual(&self.frame, d)
    }

    fn tangent(&self, res: &Residual, d: &[P2], stabilised: bool) -> Result<Vec<f64>, StepFailure> {
        self.assembly.tangent(&self.frame, res, d, stabilised)
    }

    fn matrix<'v>(&'v self, values: &'v [f64]) -> SparseRef<'v> {
        self.assembly.matrix(values)
    }

    fn symmetry(&self) -> Symmetry {
        self.assembly.symmetry
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
    crate::cutback::step(sim, &policy, whole, |sim, s| {
        increment(
            sim,
            step,
            Interval::quasi_static(s.from, s.to),
            s.last,
            Drive::QuasiStatic,
        )
    })
}

/// One increment over `interval` of step `step`, driven by `drive`,
/// committed with the step's number when it is the step's `last` (else
/// the state keeps the previous step's number, at the load factor or time
/// reached): each phase is a function.
pub(crate) fn increment(
    sim: &mut Simulation,
    step: usize,
    interval: Interval,
    last: bool,
    drive: Drive,
) -> Result<StepReport, StepFailure> {
    let start = Instant::now();
    let mut timings = Timings::default();
    // 1. Map the points and collect every method's contribution.
    let ibm_now = sim.ibm_boundaries_now(step)?;
    let setup = Setup::new(sim, &ibm_now, step, interval, drive, &mut timings)?;
    // 2. Newton on the nodal unknowns.
    let mut solved = newton(&setup, &mut timings)?;
    // 3. Condition numbers of the last tangent (of the step's last increment).
    let t = Instant::now();
    let condition = if last {
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
    let motion = setup.frame.motion(&solved.d);
    let mut points = updated.points;
    let dynamic = match &setup.inertia {
        Some(i) => {
            let constraint = setup.assembly.force_of("band", &setup.frame, &solved.d, &solved.res.it);
            Some(crate::newmark::GridMotion::commit(
                i,
                &setup.frame,
                &motion,
                constraint,
                &mut points,
            ))
        }
        None => None,
    };
    let done = Done {
        points,
        committed_step: if last { step } else { step - 1 },
        motion,
        strain_energy: updated.strain_energy,
        dissipation: updated.dissipation,
        work: updated.work,
        iterations: solved.iterations,
        residual_norm: norm(&solved.res.fext),
        residuals: solved.residuals,
        condition,
        ibm: updated.ibm,
        boundaries: setup.boundaries,
        solver: SolverReport {
            factorisation: factor.map(|f| f.0),
            negative_pivots: factor.and_then(|f| f.1),
            cutbacks: Vec::new(),
            substeps: 1,
            attainable: solved.attainable,
        },
    };
    let closed = setup.frame.close();
    drop(ibm_now);
    let report = finish(sim, closed, done, timings, start);
    Ok(match dynamic {
        Some(moved) => crate::newmark::report(sim, report, moved),
        None => report,
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
    /// Stopped above the tolerance at the round-off floor.
    attainable: Option<Attainable>,
}

/// Newton-Raphson on the step's residual: tangent, factorisation by
/// structure ([`crate::solver`]: Cholesky, `L D L^T` or LU, the symbolic
/// analysis reused by every iteration), full correction, until the relative
/// residual is below the tolerance.
fn newton(setup: &Setup, timings: &mut Timings) -> Result<Solved, StepFailure> {
    let (sim, step) = (setup.frame.sim, setup.frame.step);
    let params = &sim.params;
    let mut d = setup.frame.start();
    let mut residuals = Vec::new();
    let mut symbolic = None;
    let mut last = None;
    let mut iterations = 0;
    // The last correction relative to the unknowns, and the last
    // tangent's condition estimate once a stalled residual asked for it.
    let mut correction = f64::INFINITY;
    let mut kappa = None;
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
                attainable: None,
            });
        }
        if let Some(a) = at_the_floor(setup, &mut last, &residuals, correction, &mut kappa) {
            return Ok(Solved {
                d,
                res,
                residuals,
                iterations,
                last,
                attainable: Some(a),
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
        // iteration: the tangent is freed before the next is built, and
        // the factor's values become the next factor's (two factors are
        // never held at once).
        let spare = last
            .take()
            .map(|(_, f): (Vec<f64>, Factorisation)| f.into_values())
            .unwrap_or_default();
        let t = Instant::now();
        let k = setup.tangent(&res, &d, true)?;
        timings.assembly += t.elapsed().as_secs_f64();
        let (factor, dd) = factorise_and_solve(setup, &k, &mut symbolic, &res.r, iterations, timings, spare)?;
        // The full correction; its residual opens the next iteration (in
        // the last one's buffers).
        let t = Instant::now();
        setup.assembly.recycle(res);
        res = correct(setup, &mut d, &dd, rel, &relative)?;
        timings.assembly += t.elapsed().as_secs_f64();
        let size = d.iter().map(|v| v[0] * v[0] + v[1] * v[1]).sum::<f64>().sqrt();
        correction = norm(&dd) / size.max(f64::MIN_POSITIVE);
        last = Some((k, factor));
        iterations += 1;
    }
}

/// The largest relative residual ever taken as converged at the
/// round-off floor: a floor above it (a tangent with `kappa` past 5e9)
/// means too little accuracy to call a solution, and the step fails.
const MAX_ATTAINABLE: f64 = 1e-5;

/// Whether Newton has converged as far as arithmetic allows
/// ([`Attainable`]): the relative residual (the last of `residuals`) has
/// stalled (above half the one before); the last correction changed the
/// unknowns by at most `sqrt(eps)` of their size (the classic step test
/// of nonlinear solvers: below it a further step only moves round-off);
/// and the residual is within `10 kappa eps` (and [`MAX_ATTAINABLE`]), the floor the last
/// tangent's 1-norm condition estimate `kappa` predicts (computed once per
/// increment, when first asked; the factor 10 covers the estimate's
/// looseness and the few round-off-sized terms each residual sums), with
/// `kappa < 1/eps` (past it the tangent is singular to working precision
/// and nothing is attained). Never before two iterations. A stall with
/// larger corrections (an ill-conditioned Newton cycling, G 5.3's beam
/// without ghost) still fails the step.
fn at_the_floor(
    setup: &Setup,
    last: &mut Option<(Vec<f64>, Factorisation)>,
    residuals: &[f64],
    correction: f64,
    kappa: &mut Option<f64>,
) -> Option<Attainable> {
    let [.., before, rel] = residuals else { return None };
    if residuals.len() < 3 || *rel < 0.5 * before || correction > f64::EPSILON.sqrt() {
        return None;
    }
    let (k, f) = last.as_mut()?;
    let kappa = *kappa.get_or_insert_with(|| condition_with(setup.matrix(k), setup.symmetry(), f).value);
    let floor = 10.0 * kappa * f64::EPSILON;
    (kappa < 1.0 / f64::EPSILON && *rel <= floor.min(MAX_ATTAINABLE)).then_some(Attainable {
        residual: *rel,
        floor,
        condition: kappa,
        correction,
        tolerance: setup.frame.sim.params.tolerance,
    })
}

/// Factorise the tangent `k` (the symbolic analysis made at the first
/// iteration and reused) and solve for the Newton correction of `r`.
fn factorise_and_solve(
    setup: &Setup,
    k: &[f64],
    symbolic: &mut Option<Symbolic>,
    r: &[f64],
    iterations: usize,
    timings: &mut Timings,
    spare: Vec<f64>,
) -> Result<(Factorisation, Vec<f64>), StepFailure> {
    let (sim, step) = (setup.frame.sim, setup.frame.step);
    let t = Instant::now();
    let singular = |e: linalg::FactorError| e.at_step(step);
    if symbolic.is_none() {
        *symbolic = Some(Symbolic::new(setup.matrix(k), setup.symmetry()).map_err(singular)?);
    }
    let Some(analysis) = symbolic.as_ref() else {
        return Err(StepFailure::Internal {
            step,
            message: "no symbolic analysis".into(),
        });
    };
    let mut factor =
        Factorisation::new_reusing(analysis, setup.matrix(k), sim.model.max_memory, spare).map_err(singular)?;
    timings.factorisation += t.elapsed().as_secs_f64();
    let t = Instant::now();
    let dd = factor.solve(r).map_err(singular)?;
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
    Ok((factor, dd))
}

/// Apply the correction `dd` to the free unknowns of `d` and return the
/// residual there. With `analysis.line_search`, a correction that makes
/// the relative residual non-finite or larger than `rel` is halved (at
/// most 10 times) first.
fn correct(
    setup: &Setup,
    d: &mut [P2],
    dd: &[f64],
    rel: f64,
    relative: &dyn Fn(&Residual) -> f64,
) -> Result<Residual, StepFailure> {
    let (sim, map) = (setup.frame.sim, &setup.frame.map);
    let mut alpha = 1.0;
    let start = d.to_vec();
    loop {
        for (n, dofs) in map.dofs.node_dof.iter().enumerate() {
            for c in 0..2 {
                if let Dof::Free(i) = dofs[c] {
                    d[n][c] = start[n][c] + alpha * dd[i];
                }
            }
        }
        let res = setup.residual(d)?;
        let better = relative(&res) <= rel;
        if !sim.model.analysis.line_search || better || alpha < 1e-3 {
            return Ok(res);
        }
        setup.assembly.recycle(res);
        alpha *= 0.5;
    }
}

/// Condition numbers of the last tangent, with and without the ghost term
/// (1-norm estimates through the LU factor).
fn conditioning(setup: &Setup, solved: &mut Solved) -> Result<(Option<Condition>, Option<Condition>), StepFailure> {
    let (sim, frame) = (setup.frame.sim, &setup.frame);
    if sim.params.condition == ConditionMode::Off || frame.map.dofs.n_free == 0 {
        return Ok((None, None));
    }
    let with = match &mut solved.last {
        Some((k, f)) => condition_with(setup.matrix(k), setup.symmetry(), f),
        None => condition_of(
            setup.matrix(&setup.tangent(&solved.res, &solved.d, true)?),
            setup.symmetry(),
            sim.model.max_memory,
        ),
    };
    let without = if frame.faces.is_empty() {
        None
    } else {
        Some(condition_of(
            setup.matrix(&setup.tangent(&solved.res, &solved.d, false)?),
            setup.symmetry(),
            sim.model.max_memory,
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
}

/// Commit the converged increment into a copy of the fields it changes
/// (`F`, `b_e`, stress, positions `x + D S d + S d^a`, volumes, GIMP
/// domains; [`crate::points::Points::finite_copy`]), check them, and
/// account the work: free dofs carry `f_ext` (trapezoidal between
/// the step's start and end, tractions on their curves then), prescribed
/// dofs their support force, implicit boundaries their reactions.
fn update(setup: &Setup, solved: &Solved) -> Result<Updated, StepFailure> {
    let frame = &setup.frame;
    let (sim, map, d, step) = (frame.sim, &frame.map, &solved.d, frame.step);
    let (res, it) = (&solved.res, &solved.res.it);
    let (lambda0, lambda1) = (frame.lambda0, frame.lambda1);
    let old = &sim.state.points;
    let mut pts = old.finite_copy().map_err(|_| {
        linalg::FactorError::allocation("the points' new state", old.len().saturating_mul(145)).at_step(step)
    })?;
    let (mut strain_energy, mut dissipation) = (0.0, 0.0);
    let total = frame.motion(d);
    for p in 0..pts.len() {
        let st = map.stencils.get(p);
        let x = frame.moved(p, d);
        let df = match frame.ibm.as_ref().and_then(|s| frame.ops[p].as_ref().map(|o| (o, s))) {
            Some((ops, s)) => band_gradient(st, ops, d, &s.da),
            None => increment_gradient(st, &total),
        };
        pts.x[p] = x;
        if let Some((w, diss)) = commit_point(old, &mut pts, p, &df, it.responses[p].as_ref(), &sim.hencky(p)) {
            strain_energy += w;
            dissipation += diss;
        }
    }
    crate::state::check_points(&sim.model.grid, &pts, step, &solved.residuals)?;
    let forces = &setup.start_loads;
    let mut work = 0.0;
    // A traction's load moves with the points: its work is trapezoidal
    // between the loads at the step's start and at its end.
    let traction = sim.model.boundaries.iter().any(|b| b.traction.is_some());
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
    // The implicit boundaries' reactions and their work; in dynamics the
    // reactions hold the inertial force too (at the start `M a_n`).
    let ibm = match &frame.ibm {
        Some(s) => {
            let (fext, start_ext) = match &setup.inertia {
                Some(i) => (
                    i.less_inertia(frame, &res.fext, Some(&total)),
                    i.less_inertia(frame, &forces.ext, None),
                ),
                None => (res.fext.clone(), forces.ext.clone()),
            };
            let (reports, w) = band::finite_reports(frame, s, it, &fext, &start_ext, d)?;
            work += w;
            reports
        }
        None => Vec::new(),
    };
    Ok(Updated {
        points: pts,
        strain_energy,
        dissipation,
        work,
        ibm,
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
    let (interval, drive) = match sim.model.analysis.kind {
        crate::scene::AnalysisKind::DynamicImplicit => crate::newmark::next_step(sim),
        _ => (Interval::quasi_static(l0, l1), Drive::QuasiStatic),
    };
    let setup = Setup::new(sim, &ibm_now, step, interval, drive, &mut Timings::default())?;
    let map = &setup.frame.map;
    let mut rand = crate::linalg::XorShift::new(0x9e37_79b9_7f4a_7c15);
    let h = sim.model.grid.h;
    let mut d = setup.frame.start();
    for (n, dofs) in map.dofs.node_dof.iter().enumerate() {
        for c in 0..2 {
            if let Dof::Free(_) = dofs[c] {
                d[n][c] = amplitude * h * rand.centred();
            }
        }
    }
    let res = setup.residual(&d)?;
    let values = setup.tangent(&res, &d, true)?;
    let k = setup.matrix(&values);
    let (ri, val) = (k.row_idx(), k.val());
    let mut worst = 0.0f64;
    for _ in 0..4 {
        let v: Vec<f64> = (0..map.dofs.n_free).map(|_| rand.centred()).collect();
        let kv = match setup.symmetry() {
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
