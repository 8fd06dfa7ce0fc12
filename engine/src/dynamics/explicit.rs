//! One explicit sub-step (G 2.3, 3.3) as the phases it runs, each a
//! function over the data it reads and writes, called in order by
//! [`step_with`]:
//!
//! 1. [`prepare`]: size the workspace, cache GIMP's basis factors;
//! 2. [`map_points`]: the consistent masses' point groups and, stabilised,
//!    the ghost faces (G 4.2);
//! 3. [`assemble_mass`]: nodal mass and momentum in one pass, then the mass
//!    ([`MassKind`]): lumped `M_bar = diag(sum_p m_p S_vp)`, consistent
//!    `M = sum_p m_p S_p^T S_p` or stabilised `M_tilde = M + gamma_M J_G`
//!    (G (20)), the last two factorised ([`super::mass`]);
//! 4. [`grid_velocity`]: `M v_n = sum_p m_p S_p^T v_p` (G (10));
//! 5. [`forces`]: USF stresses from `dF = I + dt grad v_n`; `f_int =
//!    sum_p V0_p P_p grad S` (`P = tau dF^-T`), `f_ext` (gravity, point
//!    loads, tractions);
//! 6. [`accelerate`]: `M a = f_ext - f_int`, `v_{n+1} = v_n + dt a`
//!    (supported components stay at rest); [`nodal_motion`]: both per
//!    grid node, and the largest grid speed;
//! 7. [`move_points`]: FLIP `v_p += dt sum_v S_vp a_v` or PIC `v_p = sum_v
//!    S_vp v_v`; `x_p += dt sum_v S_vp v_v`; USL stresses from `dF = I + dt
//!    grad v_{n+1}`, MUSL (Sulsky's modified USL) from the updated point
//!    velocities mapped back to the grid with the same mass;
//! 8. [`guards::points`]: finite velocities, no point moving more than a cell,
//!    `|dF - I| <= 1/2`, points and GIMP domains inside the grid;
//! 9. [`energies`]: kinetic, strain, plastic dissipation and the loads'
//!    work, and their balance against the initial energy (the energy
//!    guard, [`guards::energy`]);
//! 10. [`condition`]: the masses' conditioning and CFL numbers, when asked;
//! 11. [`commit`]: the updated point fields swap into the state;
//! 12. [`report`].
//!
//! A sub-step whose grid velocities or energy explode is a
//! [`StepFailure::Diverged`], non-finite values a [`StepFailure::NonFinite`]:
//! nothing is committed before the last guard, so the state stays at the
//! last good step (the mass cache may hold this configuration's pattern,
//! valid for any step that maps the same blocks).

use super::mass::{self, MassSolver};
use super::transfer::{self, Bodies, Committed, FreeVectors, Moved, Transfer, Workspace};
use super::{conditioning, guards, norm};
use crate::assembly::{Dof, Mapping};
use crate::basis::Weights1d;
use crate::boundary::BoundaryReport;
use crate::ghost::{self, GhostFace};
use crate::report::{timed, Conditioning, DynamicsReport, Energy, StepFailure, StepReport, Timings};
use crate::scene::{ConditionMode, MassKind, StressUpdate, VelocityUpdate};
use crate::state::Simulation;
use std::time::Instant;

/// One sub-step of an explicit step: `dt` (s) from the current state;
/// `first` when it starts at the step's start (the mass conditioning, on the
/// configuration there, is computed in it), `last` when it ends at the
/// step's end (it commits the step's number and computes the errors against
/// the exact solution). The whole step is the one sub-step both first and
/// last.
#[derive(Clone, Copy, Debug)]
pub(super) struct Substep {
    pub(super) dt: f64,
    pub(super) first: bool,
    pub(super) last: bool,
}

/// The scene's time step `duration / load_steps` (s).
pub(super) fn step_dt(sim: &Simulation) -> f64 {
    sim.model.analysis.duration.unwrap_or(0.0) / sim.load_steps() as f64
}

/// What a sub-step reads of the analysis and the run, fixed while it runs.
struct Plan {
    /// The step the sub-step belongs to (1-based) and the scene's count.
    step: usize,
    steps: usize,
    /// The scene's time step (s); the sub-step's own is `sub.dt`.
    step_dt: f64,
    sub: Substep,
    /// The mass in use: stabilised only with `gamma_M > 0`, else consistent.
    kind: MassKind,
    stress_update: StressUpdate,
    velocity_update: VelocityUpdate,
    blowup_factor: f64,
    condition_every: usize,
    /// Threads for the stress passes: they pay for themselves above a few
    /// thousand points.
    pool: Option<std::sync::Arc<rayon::ThreadPool>>,
}

impl Plan {
    fn of(sim: &Simulation, sub: Substep) -> Plan {
        let a = &sim.model.analysis;
        let stabilised = a.mass == MassKind::Stabilised && sim.params.gamma_m > 0.0;
        Plan {
            step: sim.state.step + 1,
            steps: sim.load_steps(),
            step_dt: step_dt(sim),
            sub,
            kind: if a.mass == MassKind::Stabilised && !stabilised {
                MassKind::Consistent
            } else {
                a.mass
            },
            stress_update: a.stress_update,
            velocity_update: a.velocity_update,
            blowup_factor: a.blowup_factor,
            condition_every: a.condition_every,
            pool: sim.pool.clone().filter(|_| sim.state.points.len() >= 4096),
        }
    }

    fn dt(&self) -> f64 {
        self.sub.dt
    }

    fn consistent(&self) -> bool {
        self.kind != MassKind::Lumped
    }

    fn pool(&self) -> Option<&rayon::ThreadPool> {
        self.pool.as_deref()
    }

    /// The step, sub-step and mass the guards name.
    fn at(&self) -> (usize, f64, MassKind) {
        (self.step, self.sub.dt, self.kind)
    }
}

/// Sub-step `sub` of the next step: the phases in order (see the module's
/// documentation), with the buffers of `ws`; the updated point fields are
/// swapped into the state only after every guard has passed, so a failed
/// sub-step leaves the state as it found it.
pub(super) fn step_with(sim: &mut Simulation, ws: &mut Workspace, sub: Substep) -> Result<StepReport, StepFailure> {
    let clock = Instant::now();
    let mut timings = Timings::default();
    let plan = Plan::of(sim, sub);
    let (tr, map, v, lumped) = (&mut ws.transfer, &mut ws.map, &mut ws.free, &mut ws.lumped);
    let bodies = prepare(sim, &plan, tr, &mut ws.weights)?;
    let faces = map_points(sim, &plan, tr, &bodies, map);
    let (mass, pattern_reused) = timed(&mut timings.factorisation, || {
        assemble_mass(sim, &plan, tr, &bodies, map, &faces, lumped)
    })?;
    timed(&mut timings.solve, || grid_velocity(&plan, tr, map, &mass, v))?;
    let (usf, boundaries) = timed(&mut timings.assembly, || forces(sim, &plan, tr, &bodies, map, v))?;
    timed(&mut timings.solve, || accelerate(&plan, &mass, v))?;
    let max_speed = nodal_motion(tr, map, v);
    let (moved, committed) = timed(&mut timings.update, || {
        let (moved, committed) = move_points(sim, &plan, tr, &bodies, map, &mass, v, usf);
        guards::points(sim, &tr.next, &moved, &committed, plan.at(), max_speed)?;
        Ok::<_, StepFailure>((moved, committed))
    })?;
    let balance = energies(sim, &plan, v, &moved, &committed)?;
    let cond = timed(&mut timings.condition, || condition(sim, &plan, &faces))?;
    let grid = summary(map, &faces, v, &mass, max_speed, pattern_reused, boundaries);
    let errors = commit(sim, &plan, tr, map, &faces, mass, lumped, balance.work);
    timings.total = clock.elapsed().as_secs_f64();
    Ok(report(sim, &plan, grid, &balance, &moved, cond, errors, timings))
}

/// Size the transfer buffers for the points, and cache every point's 1D
/// basis factors when a body is GIMP ([`transfer::cache_weights`]): the
/// bodies' bases and finite-strain materials, with those factors.
fn prepare<'w>(
    sim: &Simulation,
    plan: &Plan,
    tr: &mut Transfer,
    weights: &'w mut Vec<[Weights1d; 2]>,
) -> Result<Bodies<'w>, StepFailure> {
    let (grid, pts) = (&sim.model.grid, &sim.state.points);
    let basis: Vec<_> = sim.model.bodies.iter().map(|b| b.basis).collect();
    transfer::cache_weights(grid, pts, &basis, weights).map_err(|e| e.at_step(plan.step))?;
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
    tr.prepare(grid, &sim.model.dirichlet, pts.len())
        .map_err(|e| e.at_step(plan.step))?;
    Ok(bodies)
}

/// Map the points: the lumped mass needs only the dofs and the active
/// cells, which the point-to-grid pass of [`assemble_mass`] finds; the
/// consistent ones their point groups and, stabilised, the ghost faces
/// (G 4.2), returned.
fn map_points(sim: &Simulation, plan: &Plan, tr: &mut Transfer, bodies: &Bodies, map: &mut Mapping) -> Vec<GhostFace> {
    let grid = &sim.model.grid;
    if plan.consistent() {
        tr.map_groups(grid, &sim.state.points, bodies, map);
    }
    if plan.kind == MassKind::Stabilised {
        ghost::faces_of(grid, map, sim.model.analysis.ghost_cells)
    } else {
        Vec::new()
    }
}

/// Nodal lumped mass and momentum in one pass over the points (numbering,
/// for the lumped mass, the dofs and active cells into `map`), then the
/// step's mass: the lumped diagonal in the reused buffer `lumped`, or the
/// consistent or stabilised mass factorised ([`mass::factorise_mass`]).
/// Returns it and whether the cached pattern was reused.
fn assemble_mass(
    sim: &mut Simulation,
    plan: &Plan,
    tr: &mut Transfer,
    bodies: &Bodies,
    map: &mut Mapping,
    faces: &[GhostFace],
    lumped: &mut Vec<f64>,
) -> Result<(MassSolver, bool), StepFailure> {
    let (grid, pts) = (&sim.model.grid, &sim.state.points);
    let consistent = plan.consistent();
    tr.p2g(grid, pts, bodies, &pts.v, (!consistent).then_some(&mut *map));
    if consistent {
        mass::factorise_mass(sim, map, faces, plan.kind, plan.step, bodies.cached)
    } else {
        Ok((mass::lumped_from_nodes(map, &tr.mass, std::mem::take(lumped)), false))
    }
}

/// Grid velocities from the mapped momentum: `M v_n = sum_p m_p S_p^T
/// v_p` (G (10)), into `v.v_n`.
fn grid_velocity(
    plan: &Plan,
    tr: &Transfer,
    map: &Mapping,
    mass: &MassSolver,
    v: &mut FreeVectors,
) -> Result<(), StepFailure> {
    transfer::gather_into(&map.dofs, &tr.momentum, &mut v.momentum);
    mass.solve_into(&v.momentum, &mut v.v_n);
    if v.v_n.iter().any(|v| !v.is_finite()) {
        return Err(guards::non_finite(plan.step, "grid velocity from the momentum"));
    }
    Ok(())
}

/// The stress pass on `dF = I + dt grad v_n` (USF: committed; USL and
/// MUSL: `dF = I`, the stresses of the step's start) with the nodal
/// internal and body forces; then on the free dofs `f_int`, `f_ext` (body
/// forces, point loads and tractions in that order, as
/// `Simulation::nodal_forces`) and `f_ext - f_int`. Returns the pass's
/// commit (the step's under USF) and the boundaries' reports.
fn forces(
    sim: &Simulation,
    plan: &Plan,
    tr: &mut Transfer,
    bodies: &Bodies,
    map: &Mapping,
    v: &mut FreeVectors,
) -> Result<(Committed, Vec<BoundaryReport>), StepFailure> {
    let (grid, pts) = (&sim.model.grid, &sim.state.points);
    let usf = plan.stress_update == StressUpdate::Usf;
    transfer::scatter_into(&map.dofs, &v.v_n, Some(plan.dt()), &mut tr.increment);
    if !usf {
        tr.increment.iter_mut().for_each(|v| *v = [0.0; 2]);
    }
    let gravity = sim.model.gravity;
    let stressed = tr.stress_pass(grid, pts, bodies, Some(gravity), usf, plan.pool());
    transfer::gather_into(&map.dofs, &tr.fint, &mut v.f_int);
    let ext = &mut v.f_ext;
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
    let boundaries = sim.add_tractions(map, plan.step, 1.0, ext)?;
    v.force.clear();
    v.force.extend(ext.iter().zip(v.f_int.iter()).map(|(e, i)| e - i));
    Ok((stressed, boundaries))
}

/// `M a = f_ext - f_int` and `v_{n+1} = v_n + dt a` on the free dofs (the
/// supported components are not unknowns: they stay at rest).
fn accelerate(plan: &Plan, mass: &MassSolver, v: &mut FreeVectors) -> Result<(), StepFailure> {
    let dt = plan.dt();
    mass.solve_into(&v.force, &mut v.acceleration);
    v.v_next.clear();
    v.v_next
        .extend(v.v_n.iter().zip(v.acceleration.iter()).map(|(u, a)| u + dt * a));
    if v.acceleration.iter().chain(v.v_next.iter()).any(|v| !v.is_finite()) {
        return Err(guards::non_finite(plan.step, "grid acceleration"));
    }
    Ok(())
}

/// The accelerations and `v_{n+1}` per grid node, for grid to points;
/// returns the largest speed of an active node (m/s). Nodes that points
/// barely touch may take large velocities without moving anything: the
/// guards measure the points' own increments.
fn nodal_motion(tr: &mut Transfer, map: &Mapping, v: &FreeVectors) -> f64 {
    transfer::scatter_into(&map.dofs, &v.acceleration, None, &mut tr.acceleration);
    transfer::scatter_into(&map.dofs, &v.v_next, None, &mut tr.velocity);
    (tr.velocity.iter().zip(&map.dofs.node_dof))
        .filter(|(_, d)| d[0] != Dof::Inactive)
        .map(|(v, _)| v[0].hypot(v[1]))
        .fold(0.0, f64::max)
}

/// Grid to points (FLIP or PIC velocities, positions) into the next
/// points, then their stresses: USF keeps `usf`, the pass [`forces`] ran;
/// USL runs the stress pass on `dF = I + dt grad v_{n+1}`; MUSL on the
/// velocities of the updated points mapped back to the grid with the same
/// mass (`M v = sum_p m_p S_p^T v_p^{n+1}`, G (10)).
#[allow(clippy::too_many_arguments)]
fn move_points(
    sim: &Simulation,
    plan: &Plan,
    tr: &mut Transfer,
    bodies: &Bodies,
    map: &Mapping,
    mass: &MassSolver,
    v: &mut FreeVectors,
    usf: Committed,
) -> (Moved, Committed) {
    let (grid, pts, dt) = (&sim.model.grid, &sim.state.points, plan.dt());
    let moved = tr.g2p(grid, pts, bodies, dt, plan.velocity_update == VelocityUpdate::Flip);
    let committed = match plan.stress_update {
        StressUpdate::Usf => usf,
        StressUpdate::Usl => {
            let (du, velocity) = (&mut tr.increment, &tr.velocity);
            du.clear();
            du.extend(velocity.iter().map(|v| [dt * v[0], dt * v[1]]));
            tr.stress_pass(grid, pts, bodies, None, true, plan.pool())
        }
        StressUpdate::Musl => {
            let velocities = std::mem::take(&mut tr.next.v);
            tr.p2g_momentum(grid, pts, bodies, &velocities);
            tr.next.v = velocities;
            transfer::gather_into(&map.dofs, &tr.momentum, &mut v.musl_momentum);
            mass.solve_into(&v.musl_momentum, &mut v.musl_velocity);
            transfer::scatter_into(&map.dofs, &v.musl_velocity, Some(dt), &mut tr.increment);
            tr.stress_pass(grid, pts, bodies, None, true, plan.pool())
        }
    };
    (moved, committed)
}

/// The energies after a sub-step (J per unit thickness).
struct Balance {
    /// The loads' work over the sub-step, `f_ext . dt v_{n+1}`.
    work: f64,
    kinetic: f64,
    strain: f64,
    dissipation: f64,
    /// The loads' work since the start, this sub-step's included.
    external_work: f64,
    /// The initial energy and `kinetic + strain + dissipation - work - W0`.
    initial: f64,
    error: f64,
}

/// The sub-step's energies and their balance, and the energy guard
/// ([`guards::energy`]): kinetic plus strain energy past
/// `blowup_factor` times what entered the system is
/// [`StepFailure::Diverged`].
fn energies(
    sim: &Simulation,
    plan: &Plan,
    v: &FreeVectors,
    moved: &Moved,
    committed: &Committed,
) -> Result<Balance, StepFailure> {
    let dt = plan.dt();
    let work: f64 = v.f_ext.iter().zip(v.v_next.iter()).map(|(f, v)| f * dt * v).sum();
    let (kinetic, strain, dissipation) = (moved.kinetic, committed.strain, committed.dissipation);
    let external_work = sim.state.external_work + work;
    let w0 = sim.state.initial_energy;
    let error = kinetic + strain + dissipation - external_work - w0;
    let ku = kinetic + strain;
    guards::energy(
        plan.step,
        ku,
        (w0, external_work, dissipation),
        plan.blowup_factor,
        plan.kind,
    )?;
    Ok(Balance {
        work,
        kinetic,
        strain,
        dissipation,
        external_work,
        initial: w0,
        error,
    })
}

/// The masses' conditioning and CFL numbers on the configuration at the
/// step's start (where the points still are), on its first sub-step when
/// `condition_every` asks for this step (and always for step 1).
fn condition(sim: &Simulation, plan: &Plan, faces: &[GhostFace]) -> Result<Option<Conditioning>, StepFailure> {
    let (step, every) = (plan.step, plan.condition_every);
    let asked = sim.params.condition != ConditionMode::Off && every > 0 && (step % every == 0 || step == 1);
    (plan.sub.first && asked)
        .then(|| {
            // The conditioning's stiffness reads the stencils.
            let (model, grid) = (&sim.model, &sim.model.grid);
            let map = &Mapping::build(grid, &sim.state.points, &model.bodies, &model.dirichlet, 0.0)?;
            let faces = if faces.is_empty() {
                ghost::faces_of(grid, map, sim.model.analysis.ghost_cells)
            } else {
                faces.to_vec()
            };
            conditioning::conditioning_on(sim, map, &faces)
        })
        .transpose()
        .map_err(|e| e.at_step(step))
}

/// Commit the sub-step: the updated point fields and active cells swap into
/// the state (the old ones go back to the workspace to be refilled), with
/// the work done, the ghost faces and, on the step's last sub-step, its
/// number; the lumped mass's buffer returns to `lumped`. Returns the errors
/// against the exact solution at the step's end (on its last sub-step).
#[allow(clippy::too_many_arguments)]
fn commit(
    sim: &mut Simulation,
    plan: &Plan,
    tr: &mut Transfer,
    map: &mut Mapping,
    faces: &[GhostFace],
    mass: MassSolver,
    lumped: &mut Vec<f64>,
    work: f64,
) -> Vec<crate::exact::ErrorNorm> {
    std::mem::swap(&mut sim.state.active_cells, &mut map.active_cells);
    tr.swap_points(&mut sim.state.points);
    if plan.sub.last {
        sim.state.step = plan.step;
    }
    sim.state.external_work += work;
    sim.state.ghost_faces = faces.iter().map(|f| ghost::face_segment(&sim.model.grid, f)).collect();
    if let Some(d) = mass.into_lumped() {
        *lumped = d;
    }
    if plan.sub.last {
        sim.exact_errors(load_factor(plan))
    } else {
        Vec::new()
    }
}

fn load_factor(plan: &Plan) -> f64 {
    plan.step as f64 / plan.steps as f64
}

/// What the report says of the grid and the mass.
struct GridSummary {
    unknowns: usize,
    active_nodes: usize,
    ghost_faces: usize,
    /// `|f_ext - f_int|` (N).
    residual_norm: f64,
    /// `v_{n+1}.M v_{n+1} / 2` (J).
    kinetic_grid: f64,
    /// Largest speed of an active node (m/s).
    max_speed: f64,
    pattern_reused: bool,
    boundaries: Vec<BoundaryReport>,
}

/// What the report says of the grid and the mass, read before [`commit`]
/// takes the mass (to give the lumped diagonal's buffer back).
fn summary(
    map: &Mapping,
    faces: &[GhostFace],
    v: &FreeVectors,
    mass: &MassSolver,
    max_speed: f64,
    pattern_reused: bool,
    boundaries: Vec<BoundaryReport>,
) -> GridSummary {
    GridSummary {
        unknowns: map.dofs.n_free,
        active_nodes: map.dofs.active_nodes,
        ghost_faces: faces.len(),
        residual_norm: norm(&v.force),
        kinetic_grid: mass.energy(&v.v_next),
        max_speed,
        pattern_reused,
        boundaries,
    }
}

/// The sub-step's report (the state committed): time and load factor of
/// the step it belongs to.
#[allow(clippy::too_many_arguments)]
fn report(
    sim: &Simulation,
    plan: &Plan,
    grid: GridSummary,
    balance: &Balance,
    moved: &Moved,
    conditioning: Option<Conditioning>,
    errors: Vec<crate::exact::ErrorNorm>,
    timings: Timings,
) -> StepReport {
    let (condition, condition_unstabilised) = match &conditioning {
        None => (None, None),
        Some(c) => match plan.kind {
            MassKind::Stabilised => (Some(c.mass_stabilised), Some(c.mass_consistent)),
            MassKind::Consistent => (Some(c.mass_consistent), None),
            MassKind::Lumped => (Some(c.mass_lumped), None),
        },
    };
    StepReport {
        unknowns: grid.unknowns,
        active_nodes: grid.active_nodes,
        active_cells: sim.state.active_cells.len(),
        residual_norm: grid.residual_norm,
        timings,
        energy: Energy {
            strain: balance.strain,
            external_work: balance.external_work,
            plastic_dissipation: balance.dissipation,
            kinetic: balance.kinetic,
            ghost: 0.0,
        },
        condition,
        condition_unstabilised,
        ghost_faces: grid.ghost_faces,
        errors,
        max_increment: grid.max_speed * plan.dt(),
        boundaries: grid.boundaries,
        dynamics: Some(DynamicsReport {
            time: plan.step as f64 * plan.step_dt,
            dt: plan.step_dt,
            initial_energy: balance.initial,
            energy_error: balance.error,
            momentum: moved.momentum,
            kinetic_grid: grid.kinetic_grid,
            max_speed: grid.max_speed,
            mass: plan.kind,
            stress_update: plan.stress_update,
            velocity_update: plan.velocity_update,
            pattern_reused: grid.pattern_reused,
            conditioning,
            integrator: None,
            cutbacks: Vec::new(),
            substeps: 1,
        }),
        ..StepReport::new(plan.step, plan.steps, load_factor(plan))
    }
}
