//! One quasi-static small-strain load step (the linear driver).
//!
//! A quasi-static small-strain step `n -> n+1` (B section 2, C section 2),
//! on the configuration at the start of the step:
//!
//! 1. map points to the grid: stencils, active nodes, dofs ([`Mapping`]);
//! 2. assemble `K = sum_p B_p^T D B_p V_p`, `f_ext(lambda_{n+1})` and
//!    `f_int = sum_p B_p^T s_p V_p`;
//! 3. factorise the reduced `K` (sparse Cholesky);
//! 4. solve `K du = f_ext - f_int - K_fc du_c` for the free increments;
//! 5. update points: `de = B du`, `s += D de`, `x += N du`, `V *= det(I + grad du)`;
//!    the grid is then forgotten.
//!
//! With `fbar` the points of a patch strain with B-bar's operator instead
//! of `B` ([`crate::implicit::bbar`]); in an implicit boundary's band with
//! C (18)'s.
//!
//! Failures (singular system, residual above tolerance, non-finite values)
//! are returned as [`StepFailure`] and leave the state at the last good step.

use crate::assembly::{Dof, Mapping};
use crate::geometry::P2;
use crate::ibm::{self, IbmReport};
use crate::implicit::bbar::Bbar;
use crate::implicit::{band, contributions, finish, norm, Assembly, At, Done, Frame, Interval, Response};
use crate::linalg::{self, Condition, Eigen, SparseRef};
use crate::material::mul3;
use crate::points::Points;
use crate::report::{SolverReport, StepFailure, StepReport, Timings};
use crate::scene::ConditionMode;
use crate::state::{check_finite, check_points, Forces, Simulation};
use std::time::Instant;

/// One quasi-static small-strain load step, on the configuration at the
/// start of the step (`update_points`, the default) or on the starting
/// configuration ([`on_the_starting_configuration`]).
pub(crate) fn linear_step(sim: &mut Simulation) -> Result<StepReport, StepFailure> {
    if sim.model.analysis.update_points {
        incremental_step(sim)
    } else {
        on_the_starting_configuration(sim)
    }
}

/// `update_points = false`: the step is solved with the points at their
/// starting positions, volumes and domains (a linear analysis of one
/// configuration: the load steps then split a linear solution, and the
/// grid needs no room for the motion); the points then move on by the
/// step's displacement, so that displacements accumulate and drawings
/// show the deformed body (where the grid need not reach). On a failure
/// the state is as it was.
fn on_the_starting_configuration(sim: &mut Simulation) -> Result<StepReport, StepFailure> {
    let step = sim.state.step + 1;
    let copy = |v: &[P2], what: &str| -> Result<Vec<P2>, StepFailure> {
        let mut c = Vec::new();
        c.try_reserve_exact(v.len())
            .map_err(|_| linalg::FactorError::allocation(what, v.len().saturating_mul(16)).at_step(step))?;
        c.extend_from_slice(v);
        Ok(c)
    };
    let pts = &sim.state.points;
    let start = copy(&pts.x0, "the points' starting positions")?;
    let lp = copy(&pts.lp, "the points' domains")?;
    let mut vol = Vec::new();
    vol.try_reserve_exact(pts.vol.len())
        .map_err(|_| linalg::FactorError::allocation("the points' volumes", pts.vol.len() * 8).at_step(step))?;
    vol.extend_from_slice(&pts.vol);
    let moved = std::mem::replace(&mut sim.state.points.x, start);
    // A panic in the step (caught above the driver) must not leave the
    // points at their starting positions.
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| incremental_step(sim)));
    let pts = &mut sim.state.points;
    match result {
        Ok(Ok(mut report)) => {
            for (p, x) in pts.x.iter_mut().enumerate() {
                let x0 = pts.x0[p];
                *x = [moved[p][0] + (x[0] - x0[0]), moved[p][1] + (x[1] - x0[1])];
            }
            (pts.vol, pts.lp) = (vol, lp);
            // The errors against an exact solution read the accumulated
            // displacements, not the step's.
            report.errors = sim.exact_errors(report.load_factor);
            Ok(report)
        }
        Ok(Err(e)) => {
            pts.x = moved;
            Err(e)
        }
        Err(panic) => {
            pts.x = moved;
            std::panic::resume_unwind(panic)
        }
    }
}

/// One quasi-static small-strain load step on the points as they are:
/// each phase is a function below.
fn incremental_step(sim: &mut Simulation) -> Result<StepReport, StepFailure> {
    let step = sim.state.step + 1;
    let lambda0 = sim.state.step as f64 / sim.load_steps() as f64;
    let lambda1 = step as f64 / sim.load_steps() as f64;
    let start = Instant::now();
    let mut timings = Timings::default();

    // 1. Map the points and collect the contributions (implicit boundaries'
    //    d^a, band and f_d; ghost faces); the pattern once.
    let ibm_now = sim.ibm_boundaries_now(step)?;
    let mut setup = Setup::new(sim, &ibm_now, step, lambda0, lambda1, &mut timings)?;
    // 2. Assemble K and the right-hand side.
    let t = Instant::now();
    let system = assemble(&setup)?;
    timings.assembly = t.elapsed().as_secs_f64();
    // 3. Factorise (sparse Cholesky). The factorisation holds the step's
    //    peak memory: the stencils and point groups are freed while it
    //    runs and rebuilt, the same numbers, when they are next read.
    setup.frame.map.release();
    let t = Instant::now();
    let factor = linalg::cholesky_within(setup.k(&system), sim.model.max_memory).map_err(|e| e.at_step(step))?;
    timings.factorisation = t.elapsed().as_secs_f64();
    // 4. Solve and check the residual.
    let t = Instant::now();
    let (du, residuals) = solve(&setup, &system, &factor)?;
    timings.solve = t.elapsed().as_secs_f64();
    // 5. Condition numbers of the reduced stiffness.
    let t = Instant::now();
    if !setup.frame.faces.is_empty() && sim.params.condition != ConditionMode::Off {
        setup.frame.restore_mapping()?;
    }
    let condition = conditioning(&setup, &system, &factor, &residuals)?;
    timings.condition = t.elapsed().as_secs_f64();
    // 6. Update the points; work and stored energy (the factor is no
    //    longer needed: free it before the fields the step writes are copied).
    drop(factor);
    let t = Instant::now();
    setup.frame.restore_mapping()?;
    let updated = update(&setup, &system, &du, &residuals)?;
    timings.update = t.elapsed().as_secs_f64();
    // 7. Commit and report.
    let done = done(&setup, system, &du, residuals, condition, updated);
    let strain_energy = done.strain_energy;
    let report = finish(sim, setup.frame.close(), done, timings, start);
    sim.state.strain_energy = strain_energy;
    Ok(report)
}

/// What the solved step commits and reports.
fn done(
    setup: &Setup,
    system: System,
    du: &[f64],
    residuals: Vec<f64>,
    condition: (Option<Condition>, Option<Condition>),
    updated: Updated,
) -> Done {
    Done {
        points: updated.points,
        committed_step: setup.frame.step,
        // The penalty's force and work on the nodes' whole motion d + d^a.
        motion: setup.frame.motion(&nodal_increments(&setup.frame.map, du)),
        strain_energy: updated.strain_energy,
        dissipation: 0.0,
        work: updated.work,
        iterations: 1,
        residuals,
        residual_norm: system.residual_norm,
        condition,
        ibm: updated.ibm,
        boundaries: system.boundaries,
        solver: SolverReport {
            factorisation: Some(crate::solver::FactorKind::Cholesky),
            negative_pivots: Some(0),
            cutbacks: Vec::new(),
            substeps: 1,
            attainable: None,
        },
    }
}

/// What a linear step keeps fixed: the frame (mapping, implicit
/// boundaries' `d^a`, ghost faces) and the contributions: the points'
/// linear response, the ghost penalty and the band.
struct Setup<'a> {
    frame: Frame<'a>,
    assembly: Assembly,
    /// `f_d` per node: the band's, the in-band points' and the ghost
    /// penalty's on `d^a` (C (18)-(27); G (27)).
    f_d: Vec<P2>,
}

impl<'a> Setup<'a> {
    fn new(
        sim: &'a Simulation,
        ibm_now: &'a [ibm::IbmBoundary],
        step: usize,
        lambda0: f64,
        lambda1: f64,
        timings: &mut Timings,
    ) -> Result<Setup<'a>, StepFailure> {
        let start = Instant::now();
        let frame = Frame::new(sim, ibm_now, step, Interval::quasi_static(lambda0, lambda1), false)?;
        let list = contributions(&frame, Response::Linear, Vec::new(), None)?;
        // What the implicit boundaries' prescribed motion d^a does at d = 0:
        // the band's, the in-band points' and the ghost penalty's f_d.
        let mut f_d = vec![[0.0; 2]; sim.model.grid.num_nodes()];
        for c in &list {
            c.prescribed(&frame, &mut f_d);
        }
        timings.mapping = start.elapsed().as_secs_f64();
        let t = Instant::now();
        let assembly = Assembly::new(&frame, list)?;
        timings.pattern = t.elapsed().as_secs_f64();
        Ok(Setup { frame, assembly, f_d })
    }

    /// The reduced stiffness `K` of `system` (lower triangle), over the
    /// step's pattern.
    fn k<'s>(&'s self, system: &'s System) -> SparseRef<'s> {
        self.assembly.matrix(&system.k)
    }

    /// The reduced stiffness' values (lower triangle, over the pattern) and
    /// `K_fc du_c`, with or without the ghost term.
    fn stiffness(&self, with_ghost: bool) -> Result<(Vec<f64>, Vec<f64>), StepFailure> {
        let zero = vec![[0.0; 2]; self.frame.sim.model.grid.num_nodes()];
        self.assembly.stiffness(&At {
            frame: &self.frame,
            d: &zero,
            motion: &zero,
            points: None,
            stabilised: with_ghost,
        })
    }
}

/// The assembled system of a step.
struct System {
    /// `K`'s values over the step's pattern ([`Setup::k`]).
    k: Vec<f64>,
    /// Loads per unit load factor, internal forces (free and prescribed).
    forces: Forces,
    boundaries: Vec<crate::boundary::BoundaryReport>,
    /// `lambda f_ext - f_int - K_fc du_c - f_d` on the free dofs.
    rhs: Vec<f64>,
    residual_norm: f64,
}

/// `K` and the right-hand side `lambda1 f_ext - f_int - K_fc du_c - f_d`.
fn assemble(setup: &Setup) -> Result<System, StepFailure> {
    let frame = &setup.frame;
    let (sim, map, pts) = (frame.sim, &frame.map, &frame.sim.state.points);
    let (k, coupling) = setup.stiffness(true)?;
    let (mut forces, boundaries) = sim.nodal_forces(map, frame.step, frame.lambda1)?;
    // Points inside a band (C (18)) and in a B-bar patch work through
    // their own operator, not B: correct f_int by (op - B)^T s V.
    // A patch's points also correct the supports' reaction (the band's
    // points, as before B-bar, only the free dofs).
    for p in (0..pts.len()).filter(|&p| pts.vol[p] > 0.0) {
        let st = map.stencils.get(p);
        let (op, patch) = match (frame.bbar.as_ref().and_then(|b| b.op(map, p)), &frame.ibm) {
            (Some(op), _) => (op, true),
            (None, Some(s)) if s.in_band[p] => (s.point_b(st, pts.x[p]).0, false),
            _ => continue,
        };
        let plain = ibm::plain_b(st);
        let sig = pts.stress[p];
        for (k, (n, _, _)) in st.iter().enumerate() {
            for c in 0..2 {
                let f = || pts.vol[p] * (0..3).map(|r| (op[k][r][c] - plain[k][r][c]) * sig[r]).sum::<f64>();
                match map.dofs.node_dof[n][c] {
                    Dof::Free(i) => forces.int[i] += f(),
                    Dof::Fixed(i) if patch => forces.int_fixed[i] += f(),
                    _ => {}
                }
            }
        }
    }
    let lambda1 = frame.lambda1;
    let rhs: Vec<f64> = (0..map.dofs.n_free)
        .map(|i| lambda1 * forces.ext[i] - forces.int[i] - coupling[i])
        .collect();
    let mut rhs = rhs;
    for (n, d) in map.dofs.node_dof.iter().enumerate() {
        for c in 0..2 {
            if let Dof::Free(i) = d[c] {
                rhs[i] -= setup.f_d[n][c];
            }
        }
    }
    let residual_norm = norm(&rhs);
    Ok(System {
        k,
        forces,
        boundaries,
        rhs,
        residual_norm,
    })
}

/// Solve and check the residual; ill-conditioned systems (tiny point
/// volumes near boundaries) get up to two rounds of iterative refinement
/// with the same factor, each recorded as a residual.
fn solve(setup: &Setup, system: &System, factor: &linalg::Factor) -> Result<(Vec<f64>, Vec<f64>), StepFailure> {
    let (sim, step) = (setup.frame.sim, setup.frame.step);
    let (k, rhs, residual_norm) = (setup.k(system), &system.rhs, system.residual_norm);
    let rel_of = |v: &[f64]| {
        if residual_norm > 0.0 {
            norm(v) / residual_norm
        } else {
            norm(v)
        }
    };
    let mut du = linalg::solve(factor, rhs);
    let mut lin = residual_of(k, &du, rhs);
    let mut rel = rel_of(&lin);
    let mut residuals = vec![if residual_norm > 0.0 { 1.0 } else { 0.0 }, rel];
    for _ in 0..2 {
        if !(rel > sim.params.tolerance) {
            break;
        }
        let neg: Vec<f64> = lin.iter().map(|v| -v).collect();
        let correction = linalg::solve(factor, &neg);
        du.iter_mut().zip(&correction).for_each(|(a, c)| *a += c);
        lin = residual_of(k, &du, rhs);
        rel = rel_of(&lin);
        residuals.push(rel);
    }
    if !sim.report_progress(step, 1, rel) {
        return Err(StepFailure::Cancelled { step, residuals });
    }
    if !residual_norm.is_finite() || !rel.is_finite() || du.iter().any(|v| !v.is_finite()) {
        return Err(StepFailure::NonFinite {
            step,
            what: "residual or displacement increment".into(),
            residuals,
        });
    }
    if rel > sim.params.tolerance {
        return Err(StepFailure::NotConverged {
            step,
            residuals,
            tolerance: sim.params.tolerance,
        });
    }
    Ok((du, residuals))
}

/// Condition number of the reduced stiffness, and without the ghost term
/// for comparison (infinite when singular).
/// Condition numbers of the stiffness with and without the ghost term:
/// dense eigenvalues up to `dense_limit` unknowns, the Lanczos estimate
/// above (`auto`), or what the scene asks. Cancelled with the step when the
/// observer's stop flag is set.
fn conditioning(
    setup: &Setup,
    system: &System,
    factor: &linalg::Factor,
    residuals: &[f64],
) -> Result<(Option<Condition>, Option<Condition>), StepFailure> {
    let (sim, step) = (setup.frame.sim, setup.frame.step);
    let params = &sim.params;
    let k = setup.k(system);
    let how = |n: usize| match params.condition {
        ConditionMode::Auto if n <= params.dense_limit => Some(Eigen::Dense),
        ConditionMode::Auto => Some(Eigen::Estimate),
        ConditionMode::Dense => Some(Eigen::Dense),
        ConditionMode::Lanczos => Some(Eigen::Lanczos),
        ConditionMode::Off => None,
    };
    let cancelled = || StepFailure::Cancelled {
        step,
        residuals: residuals.to_vec(),
    };
    let keep_going = || !sim.cancelled();
    let Some(how) = how(k.nrows()) else {
        return Ok((None, None));
    };
    let c = linalg::condition_by(k, factor, how, &keep_going).ok_or_else(cancelled)?;
    if setup.frame.faces.is_empty() {
        return Ok((Some(c), None));
    }
    let (k0, _) = setup.stiffness(false)?;
    let k0 = setup.assembly.matrix(&k0);
    let c0 = match linalg::cholesky_within(k0, sim.model.max_memory) {
        Ok(f0) => linalg::condition_by(k0, &f0, how, &keep_going).ok_or_else(cancelled)?,
        Err(e @ linalg::FactorError::Memory { .. }) => return Err(e.at_step(step)),
        Err(_) => Condition {
            value: f64::INFINITY,
            lambda_min: 0.0,
            ..c
        },
    };
    Ok((Some(c), Some(c0)))
}

/// The points after a step, and what the step did.
struct Updated {
    /// The fields the step wrote ([`Points::small_strain_copy`]).
    points: Points,
    /// Stored energy after the step (J per unit thickness).
    strain_energy: f64,
    work: f64,
    ibm: Vec<IbmReport>,
}

/// Update the points: `de = B du`, `s += D de`, `x += N du`,
/// `V *= det(I + grad du)` (in a band `B_bar` and `D N d + N d^a`); the
/// work of loads, supports and implicit boundaries; the stored energy.
fn update(setup: &Setup, system: &System, du: &[f64], residuals: &[f64]) -> Result<Updated, StepFailure> {
    let frame = &setup.frame;
    let (sim, map) = (frame.sim, &frame.map);
    let (step, lambda0, lambda1) = (frame.step, frame.lambda0, frame.lambda1);
    let forces = &system.forces;
    let nodal_d = nodal_increments(map, du);
    // Points move with N (d + d^a); those inside a band with D N d + N d^a.
    let nodal = frame.motion(&nodal_d);
    let (mut points, fint_fixed_new) = updated_points(sim, map, frame.bbar.as_ref(), &nodal, step)?;
    // In a band, points move with D N d + N d^a and strain with B_bar.
    let (ibm_reports, ibm_work) = match &frame.ibm {
        Some(s) => band::small_strain_update(frame, s, &mut points, &nodal_d, &forces.ext),
        None => (Vec::new(), 0.0),
    };
    // On one configuration (`update_points = false`) the moved points are
    // only drawn: they need to be finite, not on the grid.
    if sim.model.analysis.update_points {
        check_points(&sim.model.grid, &points, step, residuals)?;
    } else {
        check_finite(&points, step, residuals)?;
    }
    // Work: free dofs carry f_ext, prescribed dofs the support force f_int.
    let mut work = 0.0;
    for i in 0..map.dofs.n_free {
        work += 0.5 * (lambda0 + lambda1) * forces.ext[i] * du[i];
    }
    for (c, &(n, comp, u)) in map.dofs.constrained.iter().enumerate() {
        let total = u + frame.ibm.as_ref().map_or(0.0, |s| s.da[n][comp]);
        work += 0.5 * (forces.int_fixed[c] + fint_fixed_new[c]) * total;
    }
    if let Some(s) = &frame.ibm {
        // Body forces also work on the prescribed field's motion N d^a.
        for (n, d) in map.dofs.node_dof.iter().enumerate() {
            for c in 0..2 {
                if let Dof::Free(i) = d[c] {
                    work += 0.5 * (lambda0 + lambda1) * forces.ext[i] * s.da[n][c];
                }
            }
        }
        work += ibm_work;
    }
    // The stresses' work over the step, on the volumes it started with:
    // what the trapezoidal work of loads and reactions pays for. (For
    // one step it is 1/2 s:e V; over several, 1/2 s:e on the updated
    // volumes would differ from it by the volume change.)
    let old = &sim.state.points;
    let strain_energy = sim.state.strain_energy
        + (0..points.len())
            .map(|p| {
                let (s0, s1) = (old.stress[p], points.stress[p]);
                let de = [0, 1, 2].map(|k| points.strain[p][k] - old.strain[p][k]);
                0.5 * (0..3).map(|k| (s0[k] + s1[k]) * de[k]).sum::<f64>() * old.vol[p]
            })
            .sum::<f64>();
    Ok(Updated {
        points,
        strain_energy,
        work,
        ibm: ibm_reports,
    })
}

/// The fields a small-strain step writes after applying nodal increments
/// ([`Points::small_strain_copy`]: the points themselves stay as they were
/// until the step is committed), and the internal force of the new
/// stresses on the prescribed dofs (start-of-step geometry).
fn updated_points(
    sim: &Simulation,
    map: &Mapping,
    bbar: Option<&Bbar>,
    nodal: &[P2],
    step: usize,
) -> Result<(Points, Vec<f64>), StepFailure> {
    let old = &sim.state.points;
    let mut pts = old.small_strain_copy().map_err(|_| {
        linalg::FactorError::allocation("the points' new state", old.len().saturating_mul(88)).at_step(step)
    })?;
    let mut fint_fixed = vec![0.0; map.dofs.constrained.len()];
    for p in 0..pts.len() {
        let st = map.stencils.get(p);
        let du = st.interpolate(|n| nodal[n]);
        let g = st.gradient(|n| nodal[n]);
        // A B-bar patch's point strains with its operator.
        let op = bbar.and_then(|b| b.op(map, p));
        let de = match &op {
            Some(op) => Bbar::strain(op, st, nodal),
            None => [g[0][0], g[1][1], g[0][1] + g[1][0]],
        };
        let d = sim.model.materials[sim.model.bodies[old.body[p]].material].d_matrix();
        let ds = mul3(&d, de);
        let v = pts.vol[p];
        for k in 0..3 {
            pts.stress[p][k] += ds[k];
            pts.strain[p][k] += de[k];
        }
        if v > 0.0 {
            let s = pts.stress[p];
            for (k, (n, _, [dx, dy])) in st.iter().enumerate() {
                let fi = match &op {
                    Some(b) => [0, 1].map(|c| (0..3).map(|r| b[k][r][c] * s[r]).sum::<f64>() * v),
                    None => [(dx * s[0] + dy * s[2]) * v, (dy * s[1] + dx * s[2]) * v],
                };
                for c in 0..2 {
                    if let Dof::Fixed(i) = map.dofs.node_dof[n][c] {
                        fint_fixed[i] += fi[c];
                    }
                }
            }
        }
        pts.x[p] = [pts.x[p][0] + du[0], pts.x[p][1] + du[1]];
        let det = (1.0 + g[0][0]) * (1.0 + g[1][1]) - g[0][1] * g[1][0];
        pts.vol[p] *= det;
        pts.lp[p] = [pts.lp[p][0] * (1.0 + g[0][0]), pts.lp[p][1] * (1.0 + g[1][1])];
    }
    Ok((pts, fint_fixed))
}
/// Increment of every grid node: solved values on free dofs, prescribed
/// increments on fixed ones, zero elsewhere.
fn nodal_increments(map: &Mapping, du: &[f64]) -> Vec<P2> {
    map.dofs
        .node_dof
        .iter()
        .map(|d| {
            let mut u = [0.0; 2];
            for c in 0..2 {
                u[c] = match d[c] {
                    Dof::Free(i) => du[i],
                    Dof::Fixed(i) => map.dofs.constrained[i].2,
                    Dof::Inactive => 0.0,
                };
            }
            u
        })
        .collect()
}

/// `K du - rhs`.
fn residual_of(k: SparseRef<'_>, du: &[f64], rhs: &[f64]) -> Vec<f64> {
    linalg::sym_lower_mul(k, du)
        .iter()
        .zip(rhs)
        .map(|(a, b)| a - b)
        .collect()
}
