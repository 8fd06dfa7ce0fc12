//! Implicit dynamics: Newmark time steps, each a Newton step of the
//! implicit core with inertia among its contributions
//! ([`crate::implicit::Inertia`]), so that every method of the Newton path
//! (Hencky and von Mises, sMPM and GIMP, F-bar, the ghost penalty, the
//! implicit boundaries, B-spline tractions, point loads and gravity)
//! takes part in it unchanged.
//!
//! Per step `t_n -> t_n + dt` (`dt = duration / load_steps`):
//!
//! 1. [`crate::newton::increment`] with [`Drive::Dynamic`]: the frame
//!    (points on the grid, ghost faces, the implicit boundaries' `d^a`
//!    over `dt / duration` of their prescribed motion), the inertia (the
//!    grid's `v_n`, `a_n` mapped from the points with the step's mass),
//!    Newton on `r = f_ext - f_int - f_G - f_band - f_I` with the loads in
//!    full, the commit of the points' finite-deformation state;
//! 2. [`GridMotion::commit`]: the points' new velocities and
//!    accelerations;
//! 3. [`report`]: the energies and their balance, the momentum, the
//!    grid's kinetic energy and largest speed, the time.
//!
//! A step that fails to converge is cut back ([`crate::cutback`],
//! [`crate::cutback::Policy::implicit_time_step`]): its time increment is
//! halved and retried from the step's start, grows back after easy
//! increments, and the last lands on `t_n + dt`; `max_cutbacks = 0` keeps
//! the step fixed. The explicit step's stability limit does not bind the
//! implicit one: its CFL number is reported for comparison, with the
//! mass conditioning, every `condition_every` steps.

use crate::cutback::{self, Policy, Span};
use crate::geometry::P2;
use crate::implicit::{Frame, Inertia, Interval, Newmark};
use crate::newton::{increment, Drive};
use crate::points::Points;
use crate::report::{Conditioning, DynamicsReport, StepFailure, StepReport};
use crate::scene::{ConditionMode, MassKind, StressUpdate};
use crate::state::Simulation;

/// The scene's time step `duration / load_steps` (s).
fn step_dt(sim: &Simulation) -> f64 {
    sim.model.analysis.duration.unwrap_or(0.0) / sim.load_steps() as f64
}

/// One implicit dynamic step of `dt` (s): the whole step, or, when Newton
/// fails and `analysis.max_cutbacks > 0`, the step cut back.
pub(crate) fn dynamic_step(sim: &mut Simulation) -> Result<StepReport, StepFailure> {
    let dt = step_dt(sim);
    let step = sim.state.step + 1;
    let whole = Span::whole((step - 1) as f64 * dt, step as f64 * dt, dt);
    let conditioning = mass_conditioning(sim, step)?;
    let policy = Policy::implicit_time_step(sim);
    let mut report = cutback::step(sim, &policy, whole, |sim, s| {
        let (interval, drive) = interval(sim, s.from, s.to);
        increment(sim, step, interval, s.last, drive)
    })?;
    if let Some(d) = report.dynamics.as_mut() {
        d.time = step as f64 * dt;
        d.dt = dt;
        d.conditioning = conditioning;
    }
    Ok(report)
}

/// The increment `t0 -> t1` (s): the loads in full, the prescribed motions
/// over `(t1 - t0) / duration` of their totals, Newmark over `t1 - t0`.
fn interval(sim: &Simulation, t0: f64, t1: f64) -> (Interval, Drive) {
    let duration = sim.model.analysis.duration.unwrap_or(1.0);
    let interval = Interval {
        load: (1.0, 1.0),
        path: (t0 / duration, t1 / duration),
    };
    let drive = Drive::Dynamic {
        scheme: Newmark::of(sim, t1 - t0),
    };
    (interval, drive)
}

/// The next whole step's increment and drive (for the tangent check).
pub(crate) fn next_step(sim: &Simulation) -> (Interval, Drive) {
    let dt = step_dt(sim);
    let n = sim.state.step as f64;
    interval(sim, n * dt, (n + 1.0) * dt)
}

/// The masses' conditioning and CFL numbers on the configuration at the
/// step's start, when `condition_every` asks for step `step` (and always
/// for step 1), as in explicit dynamics.
fn mass_conditioning(sim: &Simulation, step: usize) -> Result<Option<Conditioning>, StepFailure> {
    let every = sim.model.analysis.condition_every;
    let asked = sim.params.condition != ConditionMode::Off && every > 0 && (step.is_multiple_of(every) || step == 1);
    if !asked {
        return Ok(None);
    }
    crate::dynamics::mass_conditioning(sim)
        .map(Some)
        .map_err(|e| e.at_step(step))
}

/// What the grid did over a converged step, for its report.
pub(crate) struct GridMotion {
    /// `v_{n+1}.M v_{n+1} / 2` (J).
    kinetic_grid: f64,
    /// Largest `|v_{n+1}|` (m/s).
    max_speed: f64,
    /// The implicit boundaries' force on the grid at the step's end (per
    /// grid node), which the next step's start acceleration balances.
    constraint: Vec<P2>,
    /// The grid's acceleration at the step's start (Bossak's `a_n`).
    acceleration: Vec<P2>,
    mass: MassKind,
    scheme: Newmark,
}

impl GridMotion {
    /// The points' velocities after the step whose nodes moved by `motion`
    /// ([`Inertia::point_update`]), written into `points` (the step's new
    /// point fields), and the grid's motion; `constraint` is the implicit
    /// boundaries' force at the end (free dofs).
    pub(crate) fn commit(
        inertia: &Inertia,
        frame: &Frame,
        motion: &[P2],
        constraint: Vec<f64>,
        points: &mut Points,
    ) -> GridMotion {
        let (v, v1) = inertia.point_update(frame, motion);
        points.v = v;
        let mut nodal = Vec::new();
        if constraint.iter().any(|f| *f != 0.0) {
            nodal = vec![[0.0; 2]; motion.len()];
            for (n, f) in nodal.iter_mut().enumerate() {
                for (c, f) in f.iter_mut().enumerate() {
                    if let Some(i) = frame.free(n, c) {
                        *f = constraint[i];
                    }
                }
            }
        }
        GridMotion {
            constraint: nodal,
            acceleration: inertia.a0.clone(),
            kinetic_grid: inertia.kinetic_energy(frame, &v1),
            max_speed: v1.iter().map(|v| v[0].hypot(v[1])).fold(0.0, f64::max),
            mass: inertia.mass_kind(),
            scheme: inertia.scheme,
        }
    }
}

/// The committed step's report with what dynamics adds: the kinetic
/// energy of the points, the balance `W_kin + W_eps + W_p + W_G - W_ext -
/// W_0` (J; `W_G` the ghost stiffness penalty's work, `W_ext` the work of
/// loads, supports and implicit boundaries), the momentum, the grid's
/// kinetic energy and largest speed.
pub(crate) fn report(sim: &mut Simulation, mut report: StepReport, g: GridMotion) -> StepReport {
    sim.state.constraint_force = g.constraint;
    sim.state.grid_acceleration = g.acceleration;
    let pts = &sim.state.points;
    let kinetic = pts.kinetic_energy();
    let e = &mut report.energy;
    e.kinetic = kinetic;
    let w0 = sim.state.initial_energy;
    let error = kinetic + e.strain + e.plastic_dissipation + e.ghost - e.external_work - w0;
    let a = &sim.model.analysis;
    report.dynamics = Some(DynamicsReport {
        time: report.load_factor * a.duration.unwrap_or(0.0),
        dt: g.scheme.dt,
        initial_energy: w0,
        energy_error: error,
        momentum: pts.momentum(),
        kinetic_grid: g.kinetic_grid,
        max_speed: g.max_speed,
        mass: g.mass,
        stress_update: StressUpdate::Usf,
        velocity_update: a.velocity_update,
        pattern_reused: false,
        conditioning: None,
        cutbacks: Vec::new(),
        substeps: 1,
        integrator: Some(a.integrator),
    });
    report
}
