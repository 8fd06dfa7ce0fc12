//! What a step reports to its observers: [`StepReport`] on success,
//! [`StepFailure`] otherwise, [`Progress`] while it runs. Plain data,
//! shared by every driver (linear, Newton, explicit) and every observer.

use crate::boundary::BoundaryReport;
use crate::exact::ErrorNorm;
use crate::geometry::P2;
use crate::ibm::IbmReport;
use crate::linalg::Condition;
use crate::scene::{MassKind, StressUpdate, VelocityUpdate};
use std::fmt;

/// Wall-clock time of each phase of a step (s). The phases account for the
/// step's `total` up to bookkeeping (reports, commits).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Timings {
    /// Points to grid: stencils, active nodes, dofs (and, for implicit
    /// boundaries, the band and its operators).
    pub mapping: f64,
    /// The sparsity pattern of the system (once per step).
    pub pattern: f64,
    /// Residuals, tangents, stiffness and mass values.
    pub assembly: f64,
    pub factorisation: f64,
    pub solve: f64,
    pub condition: f64,
    pub update: f64,
    pub total: f64,
}

/// Run one phase of a step, adding its wall time (s) to `slot`, one of
/// the step's [`Timings`].
pub(crate) fn timed<T>(slot: &mut f64, phase: impl FnOnce() -> T) -> T {
    let start = std::time::Instant::now();
    let out = phase();
    *slot += start.elapsed().as_secs_f64();
    out
}

impl Timings {
    /// Add another increment's times (load-step cutbacks).
    pub fn add(&mut self, o: &Timings) {
        self.mapping += o.mapping;
        self.pattern += o.pattern;
        self.assembly += o.assembly;
        self.factorisation += o.factorisation;
        self.solve += o.solve;
        self.condition += o.condition;
        self.update += o.update;
        self.total += o.total;
    }

    /// Every phase and the total by name (s), in the order tables list
    /// them.
    pub fn named(&self) -> [(&'static str, f64); 8] {
        [
            ("mapping", self.mapping),
            ("pattern", self.pattern),
            ("assembly", self.assembly),
            ("factorisation", self.factorisation),
            ("solve", self.solve),
            ("condition", self.condition),
            ("update", self.update),
            ("total", self.total),
        ]
    }

    /// The time not in any phase (s).
    pub fn other(&self) -> f64 {
        self.total
            - (self.mapping
                + self.pattern
                + self.assembly
                + self.factorisation
                + self.solve
                + self.condition
                + self.update)
    }
}

/// Energies after a step (J per unit thickness).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Energy {
    /// `sum_p 1/2 s_p : e_p V_p`.
    pub strain: f64,
    /// Work of loads and supports, trapezoidal in each step.
    pub external_work: f64,
    /// Plastic work dissipated so far.
    pub plastic_dissipation: f64,
    /// `sum_p 1/2 m_p |v_p|^2` (explicit dynamics; 0 for quasi-static steps).
    pub kinetic: f64,
    /// Work the ghost stiffness penalty has taken up so far: over each
    /// step, trapezoidal like the loads' work, `1/2 (f_G^start + f_G^end) . d`
    /// with `f_G = gamma_K J_G d` ([`crate::ghost::step_work`]). The grid is
    /// reset every step, so this energy is never given back. Quasi-static
    /// steps only (0 in explicit dynamics, whose ghost term is a mass); with
    /// it the balance reads `external_work ~ strain + plastic_dissipation
    /// + ghost`, up to the trapezoidal rule along the load path.
    pub ghost: f64,
}

/// What one successful step did.
#[derive(Clone, Debug, PartialEq)]
pub struct StepReport {
    /// 1-based step number.
    pub step: usize,
    pub load_steps: usize,
    pub load_factor: f64,
    /// Free unknowns of the reduced system.
    pub unknowns: usize,
    pub active_nodes: usize,
    pub active_cells: usize,
    /// `|r|` of the step's right-hand side (N).
    pub residual_norm: f64,
    /// Relative residuals per iteration: `1` before the solve, then
    /// `|K du - r| / |r|` after it and after each round of iterative
    /// refinement (taken only while above the tolerance, at most two).
    pub residuals: Vec<f64>,
    pub timings: Timings,
    pub energy: Energy,
    pub condition: Option<Condition>,
    /// With ghost stabilisation: the condition number of the tangent without it.
    pub condition_unstabilised: Option<Condition>,
    /// Newton iterations of this step (1 for a linear step).
    pub iterations: usize,
    /// Faces carrying ghost stabilisation this step.
    pub ghost_faces: usize,
    /// Each implicit boundary: reaction and constraint violation.
    pub ibm: Vec<IbmReport>,
    /// Errors against the scene's exact solution, if it names one.
    pub errors: Vec<ErrorNorm>,
    /// Largest nodal displacement increment of the step (m).
    pub max_increment: f64,
    /// Each boundary as it was at the start of the step, with its traction
    /// resultant at this step's load factor.
    pub boundaries: Vec<BoundaryReport>,
    /// Explicit dynamics: time, energy balance, mass conditioning.
    pub dynamics: Option<DynamicsReport>,
    /// Implicit steps: which factorisation solved the last system, the
    /// inertia of the last tangent, and the load-step cutbacks taken.
    pub solver: Option<SolverReport>,
    /// The scene's probes at the end of the step ([`crate::probe`]).
    pub probes: Vec<crate::probe::ProbeValue>,
}

impl StepReport {
    /// The report of step `step` of `load_steps` at `load_factor` with
    /// nothing else yet: every driver builds its report from this, setting
    /// what it has (a field added here needs a default and the drivers
    /// that fill it, nothing else).
    pub(crate) fn new(step: usize, load_steps: usize, load_factor: f64) -> StepReport {
        StepReport {
            step,
            load_steps,
            load_factor,
            unknowns: 0,
            active_nodes: 0,
            active_cells: 0,
            residual_norm: 0.0,
            residuals: Vec::new(),
            timings: Timings::default(),
            energy: Energy::default(),
            condition: None,
            condition_unstabilised: None,
            iterations: 0,
            ghost_faces: 0,
            ibm: Vec::new(),
            errors: Vec::new(),
            max_increment: 0.0,
            boundaries: Vec::new(),
            dynamics: None,
            solver: None,
            probes: Vec::new(),
        }
    }

    /// Every failed attempt of the step that was cut back, in order: the
    /// Newton increments of a quasi-static step, the time steps of an
    /// explicit one.
    pub fn cutbacks(&self) -> &[Cutback] {
        match (&self.solver, &self.dynamics) {
            (Some(s), _) => &s.cutbacks,
            (None, Some(d)) => &d.cutbacks,
            (None, None) => &[],
        }
    }

    /// What cutback `c` of this step halved, in words: `the increment of the
    /// load factor 0.250000 -> 0.500000` or (explicit, times in s as stored)
    /// `the time step from t = 0.05 s to 0.1 s`.
    pub fn cutback_span(&self, c: &Cutback) -> String {
        if self.dynamics.is_some() {
            format!("the time step from t = {} s to {} s", c.from, c.to)
        } else {
            format!("the increment of the load factor {:.6} -> {:.6}", c.from, c.to)
        }
    }
}

/// How an implicit step's systems were solved.
#[derive(Clone, Debug, PartialEq)]
pub struct SolverReport {
    /// The factorisation of the last system solved ([`crate::solver`];
    /// `None` when the step needed no solve).
    pub factorisation: Option<crate::solver::FactorKind>,
    /// Negative eigenvalues of the last tangent, counted from the pivots of
    /// its `L D L^T` factor (0 when Cholesky succeeded; `None` after LU). A
    /// negative pivot on an equilibrium path is a loss of stability (limit
    /// point, bifurcation) or a spurious mode.
    pub negative_pivots: Option<usize>,
    /// Each failed attempt that was cut back, in order.
    pub cutbacks: Vec<Cutback>,
    /// Increments that made up the step (1 without cutbacks).
    pub substeps: usize,
    /// Newton stopped above the tolerance at the accuracy arithmetic
    /// allows (the first such increment of the step; see [`Attainable`]).
    pub attainable: Option<Attainable>,
}

/// A Newton solve that converged as far as arithmetic allows: the
/// relative residual had stopped falling above the tolerance, at no more
/// than the floor `10 kappa eps` that the last tangent's condition number
/// `kappa` predicts (below `1/eps`), and the last correction moved the
/// unknowns by at most `sqrt(eps)` of their size (round-off).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Attainable {
    /// The relative residual where Newton stopped.
    pub residual: f64,
    /// The floor `10 kappa eps`.
    pub floor: f64,
    /// The 1-norm condition estimate `kappa` of the last tangent.
    pub condition: f64,
    /// The last correction relative to the unknowns, `|dd| / |d|`.
    pub correction: f64,
    /// The tolerance the residual did not reach.
    pub tolerance: f64,
}

impl std::fmt::Display for Attainable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "converged to attainable accuracy: residual {:.2e} above the tolerance {:.0e} but within the \
             round-off floor {:.2e} = 10 kappa eps (kappa {:.2e}), last correction {:.1e} of the unknowns \
             (at round-off: below sqrt(eps))",
            self.residual, self.tolerance, self.floor, self.condition, self.correction
        )
    }
}

/// An increment that failed and was halved: the step went on from the
/// last good state `from` with half the increment. Quasi-static steps
/// ([`SolverReport::cutbacks`]) halve the load increment, explicit steps
/// ([`DynamicsReport::cutbacks`]) the time step.
#[derive(Clone, Debug, PartialEq)]
pub struct Cutback {
    /// Load factor (quasi-static) or time (explicit, s) of the last good
    /// state.
    pub from: f64,
    /// The load factor or time (s) the failed increment aimed at.
    pub to: f64,
    /// Why it failed ([`StepFailure`]'s message).
    pub reason: String,
}

/// Why a step did not complete. The state stays at the last good step.
#[derive(Clone, Debug, PartialEq)]
pub enum StepFailure {
    /// Every load step has been taken.
    Finished { steps: usize },
    /// The reduced stiffness could not be factorised.
    Singular { step: usize, reason: String },
    /// The solve's residual stayed above the tolerance.
    NotConverged {
        step: usize,
        residuals: Vec<f64>,
        tolerance: f64,
    },
    /// A residual, increment or stress was NaN or infinite.
    NonFinite {
        step: usize,
        what: String,
        residuals: Vec<f64>,
    },
    /// A boundary's spline could not be built from its points.
    Boundary { step: usize, name: String, reason: String },
    /// A point (or, with `domain`, a corner of its GIMP domain, where the
    /// basis would lose nodes and partition of unity) would leave the grid.
    LeftGrid {
        step: usize,
        point: usize,
        position: P2,
        domain: bool,
    },
    /// An explicit step blew up: energy or grid velocities beyond bounds.
    Diverged { step: usize, reason: String },
    /// The engine panicked (a bug): caught by [`crate::Simulation::step_guarded`];
    /// the state is the last good step.
    Internal { step: usize, message: String },
    /// The observer cancelled the step ([`crate::Simulation::set_progress`]); the
    /// state is the last good step.
    Cancelled { step: usize, residuals: Vec<f64> },
    /// A factor (or another large buffer) of the step would not fit: its
    /// estimate from the symbolic analysis, added to the process's resident
    /// memory `in_use`, exceeds `budget` (`--max-memory`), or (`budget`
    /// `None`) allocating it failed. Nothing was computed with it.
    OutOfMemory {
        step: usize,
        /// What needed the memory (`the Cholesky factor of 12480 unknowns (3.10e6 entries)`).
        what: String,
        bytes: u64,
        in_use: u64,
        budget: Option<u64>,
    },
}

/// Progress inside a step, for observers: each Newton iteration's (or the
/// linear solve's) relative residual as it is computed.
#[derive(Clone, Debug, PartialEq)]
pub struct Progress {
    pub step: usize,
    /// 0 before the first correction.
    pub iteration: usize,
    pub residual: f64,
}

/// Called with each [`Progress`]; returning `false` cancels the step.
pub type ProgressHook = Box<dyn FnMut(&Progress) -> bool + Send>;

impl StepFailure {
    pub fn step(&self) -> usize {
        match self {
            StepFailure::Finished { steps } => *steps,
            StepFailure::Singular { step, .. }
            | StepFailure::NotConverged { step, .. }
            | StepFailure::NonFinite { step, .. }
            | StepFailure::Boundary { step, .. }
            | StepFailure::LeftGrid { step, .. }
            | StepFailure::Diverged { step, .. }
            | StepFailure::Internal { step, .. }
            | StepFailure::OutOfMemory { step, .. }
            | StepFailure::Cancelled { step, .. } => *step,
        }
    }

    pub fn residuals(&self) -> &[f64] {
        match self {
            StepFailure::NotConverged { residuals, .. }
            | StepFailure::NonFinite { residuals, .. }
            | StepFailure::Cancelled { residuals, .. } => residuals,
            _ => &[],
        }
    }
}

impl fmt::Display for StepFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StepFailure::Finished { steps } => write!(f, "all {steps} load steps are done"),
            StepFailure::Singular { step, reason } => write!(f, "step {step} failed: singular system: {reason}"),
            StepFailure::NotConverged {
                step,
                residuals,
                tolerance,
            } => write!(
                f,
                "step {step} failed: residual {:.3e} above tolerance {tolerance:.1e} (residuals {})",
                residuals.last().copied().unwrap_or(f64::NAN),
                fmt_residuals(residuals)
            ),
            StepFailure::LeftGrid {
                step,
                point,
                position,
                domain,
            } => write!(
                f,
                "step {step} failed: point {point}{} would reach ({:.4}, {:.4}), outside the grid; enlarge the grid",
                if *domain { "'s GIMP domain" } else { "" },
                position[0],
                position[1]
            ),
            StepFailure::Diverged { step, reason } => write!(f, "step {step} failed: diverged: {reason}"),
            StepFailure::Cancelled { step, residuals } => write!(
                f,
                "step {step} cancelled (residuals {}); the state is that of step {}",
                fmt_residuals(residuals),
                step - 1
            ),
            StepFailure::Internal { step, message } => write!(
                f,
                "step {step} failed: internal error (a bug in mpmlab; please report it with the scene): {message}"
            ),
            StepFailure::Boundary { step, name, reason } => {
                write!(f, "step {step} failed: boundary `{name}`: {reason}")
            }
            StepFailure::OutOfMemory {
                step,
                what,
                bytes,
                in_use,
                budget,
            } => {
                let b = crate::model::bytes;
                match budget {
                    Some(budget) => write!(
                        f,
                        "step {step} failed: out of memory: {what} needs an estimated {}, which with the {} in use exceeds the {} allowed (--max-memory); use a larger grid.h (fewer unknowns) or a larger --max-memory",
                        b(*bytes),
                        b(*in_use),
                        b(*budget)
                    ),
                    None => write!(
                        f,
                        "step {step} failed: out of memory: {} could not be allocated ({} in use); use a larger grid.h (fewer unknowns)",
                        crate::linalg::sized(what, *bytes),
                        b(*in_use)
                    ),
                }
            }
            StepFailure::NonFinite { step, what, residuals } if residuals.is_empty() => {
                write!(f, "step {step} failed: non-finite {what}")
            }
            StepFailure::NonFinite { step, what, residuals } => write!(
                f,
                "step {step} failed: non-finite {what} (residuals {})",
                fmt_residuals(residuals)
            ),
        }
    }
}

fn fmt_residuals(r: &[f64]) -> String {
    let v: Vec<String> = r.iter().map(|x| format!("{x:.2e}")).collect();
    format!("[{}]", v.join(", "))
}

impl std::error::Error for StepFailure {}

/// What a dynamic step (explicit or implicit) adds to its [`StepReport`].
#[derive(Clone, Debug, PartialEq)]
pub struct DynamicsReport {
    /// Time at the end of the step (s).
    pub time: f64,
    /// Time step (s).
    pub dt: f64,
    /// `W_0`: kinetic plus strain energy at `t = 0` (J per unit thickness).
    pub initial_energy: f64,
    /// Energy balance `W_kin + W_eps + W_p - W_ext - W_0` (J); G 5.2 charts
    /// `W_kin + W_eps - W_0` for elastic bodies without loads.
    pub energy_error: f64,
    /// `sum_p m_p v_p` after the step (kg m/s per unit thickness).
    pub momentum: P2,
    /// Kinetic energy of the grid velocities at the end of the step with
    /// the mass used, `v_{n+1}.M v_{n+1} / 2` (J): the grid's view of
    /// [`Energy::kinetic`], which is measured on the points.
    pub kinetic_grid: f64,
    /// Largest grid speed `|v_{n+1}|` of the step (m/s).
    pub max_speed: f64,
    pub mass: MassKind,
    pub stress_update: StressUpdate,
    pub velocity_update: VelocityUpdate,
    /// Whether the mass pattern and its symbolic factorisation were reused
    /// from the previous step.
    pub pattern_reused: bool,
    /// Mass conditioning and CFL numbers, every `condition_every` steps.
    pub conditioning: Option<Conditioning>,
    /// Each attempt that failed and was cut back (its time step halved and
    /// retried from the last good state), in order; empty when the step
    /// went through at `dt`.
    pub cutbacks: Vec<Cutback>,
    /// Sub-steps that made up the step (1 without cutbacks).
    pub substeps: usize,
    /// Implicit dynamics: its time integrator (`None`: explicit, central
    /// differences; its `stress_update` then applies).
    pub integrator: Option<crate::scene::Integrator>,
}

impl DynamicsReport {
    /// The CFL number (s/m) of the mass in use, on the steps that measured
    /// the conditioning.
    pub fn cfl(&self) -> Option<f64> {
        let c = self.conditioning.as_ref()?;
        match self.mass {
            MassKind::Stabilised => c.cfl_stabilised,
            MassKind::Consistent => c.cfl_consistent,
            MassKind::Lumped => c.cfl_lumped,
        }
    }
}

/// Condition numbers of the three mass matrices at one configuration, and
/// the CFL numbers `C = 1 / (h sqrt(lambda_max(K, M)))` (s/m; G 3.5) with
/// each. A matrix that is not numerically positive definite has condition
/// `inf` and CFL number 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conditioning {
    /// `M` (G (9)), reduced to the free dofs.
    pub mass_consistent: Condition,
    /// `M + gamma_M J_G` (G (20)).
    pub mass_stabilised: Condition,
    /// `diag(sum_p m_p S_vp)`: exact (largest over smallest entry).
    pub mass_lumped: Condition,
    /// With `K` (the material tangent) and `M`; `None` when `K = 0`.
    pub cfl_consistent: Option<f64>,
    /// With `K + gamma_K J_G` and `M + gamma_M J_G`.
    pub cfl_stabilised: Option<f64>,
    /// With `K` and the lumped mass.
    pub cfl_lumped: Option<f64>,
    /// The reduced material tangent `K` and `K + gamma_K J_G` (on demand
    /// only, [`crate::Simulation::conditioning`]; singular without supports).
    pub stiffness: Option<Condition>,
    pub stiffness_stabilised: Option<Condition>,
}

/// The message of a caught panic.
pub(crate) fn panic_message(e: &(dyn std::any::Any + Send)) -> String {
    e.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| e.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic".into())
}
