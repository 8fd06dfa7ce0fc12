//! The simulation's data: a model, its evolving state and the settings
//! that may change between steps; what every driver reads and commits to.
//! The drivers ([`crate::linear`], [`crate::newton`], [`crate::dynamics`])
//! are functions over it; [`crate::simulation`] dispatches a step to them.

use crate::assembly::{Dof, Mapping};
use crate::boundary::{self, bspline::BSpline, BoundaryReport};
use crate::geometry::P2;
use crate::ghost;
use crate::model::Model;
use crate::points::{Points, Tracked};
pub use crate::report::{Energy, Progress, ProgressHook, StepFailure, StepReport, Timings};
use crate::scene::{AnalysisKind, ConditionMode};

/// Settings that may change between steps.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Params {
    /// Largest accepted relative residual (see [`crate::scene::AnalysisSpec::tolerance`]).
    pub tolerance: f64,
    pub condition: ConditionMode,
    /// Largest reduced system whose condition number is computed densely.
    pub dense_limit: usize,
    /// Newton iterations per step at most.
    pub max_iterations: usize,
    /// Ghost stiffness penalty `gamma_K` (0: off).
    pub gamma_k: f64,
    /// Implicit-boundary bandwidth over cell size.
    pub delta_over_h: f64,
    /// Ghost mass penalty `gamma_M` (kg/m^3; explicit dynamics, G (20)).
    pub gamma_m: f64,
}

/// The evolving part of a simulation (what a checkpoint keeps,
/// [`crate::checkpoint`]).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub(crate) struct State {
    pub(crate) points: Points,
    pub(crate) step: usize,
    pub(crate) external_work: f64,
    pub(crate) active_cells: Vec<usize>,
    /// Ghost faces of the last step, as segments (for observers).
    pub(crate) ghost_faces: Vec<(P2, P2)>,
    /// Newton iterations over all steps so far.
    pub(crate) iterations: usize,
    /// Linear path: the work the stresses have done so far,
    /// `sum_steps sum_p V_p (s0 + s1)/2 : de` with each step's starting
    /// volumes (the stored energy of the updated small-strain model).
    pub(crate) strain_energy: f64,
    /// Energy the ghost stiffness penalty has taken up so far
    /// ([`crate::report::Energy::ghost`]); absent from older checkpoints.
    #[serde(default)]
    pub(crate) ghost_energy: f64,
    /// The ghost force at the end of the last step, per grid node (empty:
    /// none), which the next step starts with ([`crate::ghost::step_work`]).
    #[serde(default)]
    pub(crate) ghost_force: Vec<P2>,
    /// Implicit dynamics: the implicit boundaries' force on the grid
    /// nodes at the end of the last step (N per unit thickness, per grid
    /// node; empty: none), which the next step's start acceleration
    /// balances ([`crate::implicit::Inertia::new`]); absent from older
    /// checkpoints.
    #[serde(default)]
    pub(crate) constraint_force: Vec<P2>,
    /// Implicit dynamics with Bossak's alpha: the grid's acceleration
    /// `a_n` at the start of the last step (per grid node; empty at the
    /// run's start), from which the next step's follows
    /// ([`crate::implicit::Inertia::new`]).
    #[serde(default)]
    pub(crate) grid_acceleration: Vec<P2>,
    /// How far each moving implicit boundary has moved.
    pub(crate) ibm_offsets: Vec<P2>,
    /// Explicit dynamics: kinetic plus strain energy at the start (J).
    pub(crate) initial_energy: f64,
}

/// A saved state to return to with [`Simulation::restore`].
#[derive(Clone, Debug)]
pub struct Snapshot(State);

/// A model and its evolving state.
pub struct Simulation {
    pub(crate) model: Model,
    pub(crate) params: Params,
    pub(crate) state: State,
    /// Dynamics: the mass pattern of the last step (shared by the explicit
    /// step and the implicit step's projection, which holds the
    /// simulation by reference).
    pub(crate) mass_cache: std::sync::Mutex<MassCache>,
    /// Explicit dynamics: the step's buffers, reused from step to step.
    pub(crate) explicit: crate::dynamics::transfer::Workspace,
    /// Threads for the per-point passes and the tangent's blocks
    /// ([`Simulation::set_threads`]); `None`: one.
    pub(crate) pool: Option<std::sync::Arc<rayon::ThreadPool>>,
    /// The observer's progress hook (behind a mutex so steps can call it
    /// through `&self`).
    progress: Option<std::sync::Mutex<ProgressHook>>,
    /// The observer's stop flag, polled by long phases without residuals
    /// (condition numbers).
    cancel: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
}

/// The per-point arrays an analysis reads and writes beyond those every
/// analysis does.
pub(crate) fn tracked(kind: AnalysisKind) -> Tracked {
    match kind {
        AnalysisKind::QuasiStaticLinear => Tracked {
            strain: true,
            finite: false,
            velocity: false,
        },
        AnalysisKind::QuasiStaticFinite => Tracked {
            strain: false,
            finite: true,
            velocity: false,
        },
        AnalysisKind::ExplicitDynamics => Tracked {
            strain: false,
            finite: true,
            velocity: true,
        },
        AnalysisKind::DynamicImplicit => Tracked {
            strain: false,
            finite: true,
            velocity: true,
        },
    }
}

impl Simulation {
    /// The simulation of `model` at its start; the model's points move
    /// into the state (one copy of the points, not two).
    pub fn new(mut model: Model) -> Simulation {
        crate::linalg::warm_dense_kernels();
        let params = Params {
            tolerance: model.analysis.tolerance,
            condition: model.analysis.condition,
            dense_limit: model.analysis.dense_limit,
            max_iterations: model.analysis.max_iterations,
            gamma_k: model.analysis.gamma_k,
            delta_over_h: model.analysis.delta_over_h,
            gamma_m: model.gamma_m(),
        };
        let mut points = std::mem::take(&mut model.points);
        points.keep(tracked(model.analysis.kind));
        let active_cells = crate::assembly::active_cells(&model.grid, &points, &model.bodies);
        let initial_energy = points.kinetic_energy();
        let state = State {
            points,
            step: 0,
            external_work: 0.0,
            strain_energy: 0.0,
            ghost_energy: 0.0,
            ghost_force: Vec::new(),
            constraint_force: Vec::new(),
            grid_acceleration: Vec::new(),
            active_cells,
            ghost_faces: Vec::new(),
            iterations: 0,
            ibm_offsets: vec![[0.0; 2]; model.ibm.len()],
            initial_energy,
        };
        Simulation {
            model,
            params,
            state,
            mass_cache: Default::default(),
            explicit: Default::default(),
            pool: None,
            progress: None,
            cancel: None,
        }
    }

    /// Parse, validate and build a scene.
    pub fn from_scene_text(text: &str, file: &str) -> Result<Simulation, crate::scene::SceneError> {
        Ok(Simulation::new(Model::from_text(text, file)?))
    }

    pub fn model(&self) -> &Model {
        &self.model
    }

    pub fn points(&self) -> &Points {
        &self.state.points
    }

    /// Steps taken so far.
    pub fn step_index(&self) -> usize {
        self.state.step
    }

    pub fn load_steps(&self) -> usize {
        self.model.analysis.load_steps
    }

    pub fn load_factor(&self) -> f64 {
        self.state.step as f64 / self.load_steps() as f64
    }

    /// The cells the last step was solved on (the points' bases reached
    /// them at its start; before the first step, the cells they reach).
    pub fn active_cells(&self) -> &[usize] {
        &self.state.active_cells
    }

    /// The cells the next step will be solved on: those the points' bases
    /// reach in the configuration it starts from (the current one; the
    /// starting one with `update_points = false`).
    pub fn cells_of_next_step(&self) -> Vec<usize> {
        let (m, pts) = (&self.model, &self.state.points);
        let x = if m.analysis.update_points { &pts.x } else { &pts.x0 };
        crate::assembly::active_cells_at(&m.grid, pts, x, &m.bodies)
    }

    /// Commit a quasi-static step (`points`: the fields it wrote, moved in
    /// by [`Points::take_written`]) and move the moving implicit boundaries
    /// by the load factor's increment `dlambda`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn commit_quasi_static(
        &mut self,
        points: Points,
        step: usize,
        work: f64,
        active_cells: Vec<usize>,
        faces: &[ghost::GhostFace],
        iterations: usize,
        dlambda: f64,
    ) {
        self.state.points.take_written(points);
        self.state.step = step;
        self.state.external_work += work;
        self.state.active_cells = active_cells;
        self.state.ghost_faces = faces.iter().map(|f| ghost::face_segment(&self.model.grid, f)).collect();
        self.state.iterations += iterations;
        for (off, b) in self.state.ibm_offsets.iter_mut().zip(&self.model.ibm) {
            if b.moves {
                let m = b.motion();
                off[0] += m[0] * dlambda;
                off[1] += m[1] * dlambda;
            }
        }
    }

    /// Simulated time (s) after the steps taken, for dynamics (explicit or
    /// implicit).
    pub fn time(&self) -> Option<f64> {
        let a = &self.model.analysis;
        a.kind
            .is_dynamic()
            .then(|| self.state.step as f64 * a.duration.unwrap_or(0.0) / a.load_steps as f64)
    }

    /// The finite-strain material of point `p`'s body.
    pub(crate) fn hencky(&self, p: usize) -> crate::material::hencky::Hencky {
        self.material_of(p).hencky()
    }

    /// The material of point `p`'s body.
    pub fn material_of(&self, p: usize) -> &crate::material::Material {
        &self.model.materials[self.model.bodies[self.state.points.body[p]].material]
    }

    /// The implicit boundaries where they are now (moving ones displaced,
    /// those following a B-spline boundary on its curve through the points'
    /// positions now), for observers: a boundary whose spline cannot be
    /// built now is left out (the next step that needs it fails and says
    /// why, [`StepFailure::Boundary`]).
    pub fn ibm_boundaries(&self) -> Vec<crate::ibm::IbmBoundary> {
        self.model
            .ibm
            .iter()
            .zip(&self.state.ibm_offsets)
            .filter_map(|(b, &d)| self.ibm_boundary_now(b, d).ok())
            .collect()
    }

    fn ibm_boundary_now(&self, b: &crate::ibm::IbmBoundary, offset: P2) -> Result<crate::ibm::IbmBoundary, String> {
        match b.spline {
            Some((idx, chords)) => {
                let s = self.model.boundaries[idx]
                    .spline(&self.state.points)
                    .map_err(|e| e.to_string())?;
                Ok(crate::ibm::IbmBoundary {
                    points: s.sample(chords),
                    ..b.clone()
                })
            }
            None => Ok(b.translated(offset)),
        }
    }

    /// The implicit boundaries for step `step`; a tracked boundary whose
    /// spline cannot be built is the step's failure (never the old curve).
    pub(crate) fn ibm_boundaries_now(&self, step: usize) -> Result<Vec<crate::ibm::IbmBoundary>, StepFailure> {
        self.model
            .ibm
            .iter()
            .zip(&self.state.ibm_offsets)
            .map(|(b, &d)| {
                self.ibm_boundary_now(b, d).map_err(|reason| StepFailure::Boundary {
                    step,
                    name: b.name.clone(),
                    reason,
                })
            })
            .collect()
    }

    /// Ghost faces of the last step (empty without ghost stabilisation).
    pub fn ghost_faces(&self) -> &[(P2, P2)] {
        &self.state.ghost_faces
    }

    pub fn finished(&self) -> bool {
        self.state.step >= self.load_steps()
    }

    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Change settings; they apply from the next step.
    pub fn set_params(&mut self, params: Params) {
        self.params = params;
    }

    pub fn snapshot(&self) -> Snapshot {
        Snapshot(self.state.clone())
    }

    pub fn restore(&mut self, snapshot: &Snapshot) {
        self.state = snapshot.0.clone();
    }

    /// Watch steps as they compute: `hook` gets every residual and may
    /// cancel the step by returning `false` ([`StepFailure::Cancelled`]).
    pub fn set_progress(&mut self, hook: Option<ProgressHook>) {
        self.progress = hook.map(std::sync::Mutex::new);
    }

    /// A flag that, once set, cancels the running step in any phase
    /// ([`StepFailure::Cancelled`]), also where no residual is computed.
    pub fn set_cancel(&mut self, flag: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>) {
        self.cancel = flag;
    }

    /// The most threads [`Simulation::set_threads`] starts.
    pub const MAX_THREADS: usize = 256;

    /// Run the points' material updates (the explicit step's stress
    /// passes, an implicit step's residuals) and an implicit step's tangent
    /// blocks on `threads` threads; 0 means one per core, 1 (the default)
    /// none. The results are the same to the bit whatever the count: each
    /// point and block is computed on its own, and forces, energies and
    /// the matrix are summed in point and block order afterwards. Other
    /// phases (the factorisation and solves among them) stay on one
    /// thread. Returns the threads in use, or why they could not be
    /// started.
    pub fn set_threads(&mut self, threads: usize) -> Result<usize, String> {
        if threads == 1 {
            self.pool = None;
            return Ok(1);
        }
        // Threads are started one by one: a mistyped count (100000) would
        // take minutes to start and nothing to use them.
        if threads > Self::MAX_THREADS {
            let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
            return Err(format!(
                "{threads} threads is more than the {} this program starts (this machine has {cores} cores; 0 means one per core)",
                Self::MAX_THREADS
            ));
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("mpmlab-points-{i}"))
            // A thread starts with its parent's vector registers.
            .start_handler(|_| crate::vector_state::after_wide_kernels())
            .build()
            .map_err(|e| format!("cannot start {threads} threads: {e}"))?;
        let n = pool.current_num_threads();
        self.pool = (n > 1).then(|| std::sync::Arc::new(pool));
        Ok(n)
    }

    /// The threads the steps' per-point and per-block work runs on.
    pub fn threads(&self) -> usize {
        self.pool.as_ref().map_or(1, |p| p.current_num_threads())
    }

    /// `f(i, &mut a[i], b.get_mut(i))` for every index of `a` (`b` is
    /// empty or as long as `a`), on the simulation's threads in chunks of
    /// consecutive indices. Each call owns its entries, so the result is
    /// the same for any number of threads.
    pub(crate) fn for_each_point<A: Send, B: Send>(
        &self,
        a: &mut [A],
        b: &mut [B],
        f: impl Fn(usize, &mut A, Option<&mut B>) + Sync,
    ) {
        debug_assert!(b.is_empty() || b.len() == a.len());
        let run = |start: usize, a: &mut [A], b: &mut [B]| {
            crate::vector_state::after_wide_kernels();
            let mut b = b.iter_mut();
            for (i, a) in a.iter_mut().enumerate() {
                f(start + i, a, b.next());
            }
        };
        let Some(pool) = &self.pool else {
            run(0, a, b);
            return;
        };
        use rayon::prelude::*;
        let chunk = a.len().div_ceil(8 * pool.current_num_threads()).max(64);
        let b_chunk = if b.is_empty() { 0 } else { chunk };
        pool.install(|| {
            let mut jobs = Vec::new();
            let (mut a, mut b, mut start) = (a, b, 0);
            while !a.is_empty() {
                let (ah, at) = a.split_at_mut(chunk.min(a.len()));
                let (bh, bt) = b.split_at_mut(b_chunk.min(b.len()));
                jobs.push((start, ah, bh));
                start += chunk;
                (a, b) = (at, bt);
            }
            jobs.into_par_iter().for_each(|(start, a, b)| run(start, a, b));
        });
    }

    /// Whether the observer's stop flag is set.
    pub(crate) fn cancelled(&self) -> bool {
        self.cancel
            .as_ref()
            .is_some_and(|f| f.load(std::sync::atomic::Ordering::SeqCst))
    }

    /// Tell the hook; `false` when the observer cancels the step.
    pub(crate) fn report_progress(&self, step: usize, iteration: usize, residual: f64) -> bool {
        match &self.progress {
            Some(m) => match m.lock() {
                Ok(mut hook) => hook(&Progress {
                    step,
                    iteration,
                    residual,
                }),
                Err(_) => true,
            },
            None => true,
        }
    }

    /// The splines of all boundaries through the points' current positions.
    pub fn boundary_splines(&self) -> Vec<(String, Option<BSpline>)> {
        self.model
            .boundaries
            .iter()
            .map(|b| (b.name.clone(), b.spline(&self.state.points).ok()))
            .collect()
    }

    /// External force per unit load factor (body forces, point loads,
    /// boundary tractions on the current curves) and internal force of the
    /// current stresses, on the free dofs, and the internal force on the
    /// prescribed ones; with a report per boundary.
    pub(crate) fn nodal_forces(
        &self,
        map: &Mapping,
        step: usize,
        lambda: f64,
    ) -> Result<(Forces, Vec<BoundaryReport>), StepFailure> {
        let mut f = self.dead_forces(map);
        let reports = self.add_tractions(map, step, lambda, &mut f.ext)?;
        Ok((f, reports))
    }

    /// Add every boundary's traction (per unit load factor, on the curves
    /// through the points' current positions) to `ext` on the free dofs;
    /// a report per boundary with its resultant at `lambda`.
    pub(crate) fn add_tractions(
        &self,
        map: &Mapping,
        step: usize,
        lambda: f64,
        ext: &mut [f64],
    ) -> Result<Vec<BoundaryReport>, StepFailure> {
        let pts = &self.state.points;
        let active = |n: usize| map.dofs.node_dof[n][0] != Dof::Inactive;
        let mut reports = Vec::with_capacity(self.model.boundaries.len());
        for b in &self.model.boundaries {
            let spline = b.spline(pts).map_err(|e| StepFailure::Boundary {
                step,
                name: b.name.clone(),
                reason: e.to_string(),
            })?;
            let (forces, report) =
                boundary::traction_forces(b, &spline, &self.model.grid, self.model.exact.as_ref(), &active, lambda);
            for (n, force) in forces {
                for c in 0..2 {
                    if let Dof::Free(i) = map.dofs.node_dof[n][c] {
                        ext[i] += force[c];
                    }
                }
            }
            reports.push(report);
        }
        Ok(reports)
    }

    /// A report of the current state with no step behind it (its step,
    /// load factor and probes): what a table starts from when a run
    /// takes no step (resumed from its last checkpoint).
    pub fn start_report(&self) -> StepReport {
        StepReport {
            probes: self.probe_values(None),
            ..StepReport::new(self.state.step, self.load_steps(), self.load_factor())
        }
    }

    /// The names of the errors a step reports against the scene's exact
    /// solution (none without one).
    pub fn error_names(&self) -> Vec<String> {
        self.exact_errors(0.0).iter().map(|e| e.name.to_string()).collect()
    }

    /// Errors against the scene's exact solution at `load_factor` (none
    /// without one).
    pub(crate) fn exact_errors(&self, load_factor: f64) -> Vec<crate::exact::ErrorNorm> {
        match &self.model.exact {
            Some(e) => e.errors(&self.state.points, load_factor),
            None => Vec::new(),
        }
    }

    /// External force per unit load factor of body forces and point loads,
    /// and the internal force of the current stresses (free and prescribed
    /// dofs).
    pub(crate) fn dead_forces(&self, map: &Mapping) -> Forces {
        let pts = &self.state.points;
        let mut f = Forces {
            ext: vec![0.0; map.dofs.n_free],
            int: vec![0.0; map.dofs.n_free],
            int_fixed: vec![0.0; map.dofs.constrained.len()],
        };
        let g = self.model.gravity;
        for p in 0..pts.len() {
            if pts.vol[p] == 0.0 {
                continue;
            }
            let s = pts.stress[p];
            let v = pts.vol[p];
            for (n, w, [dx, dy]) in map.stencils.get(p).iter() {
                let fi = [(dx * s[0] + dy * s[2]) * v, (dy * s[1] + dx * s[2]) * v];
                let fe = [w * pts.mass[p] * g[0], w * pts.mass[p] * g[1]];
                for c in 0..2 {
                    match map.dofs.node_dof[n][c] {
                        Dof::Free(i) => {
                            f.ext[i] += fe[c];
                            f.int[i] += fi[c];
                        }
                        Dof::Fixed(i) => f.int_fixed[i] += fi[c],
                        Dof::Inactive => {}
                    }
                }
            }
        }
        for load in &self.model.point_loads {
            for (n, w, _) in map.stencils.get(load.point).iter() {
                for c in 0..2 {
                    if let Dof::Free(i) = map.dofs.node_dof[n][c] {
                        f.ext[i] += w * load.force[c];
                    }
                }
            }
        }
        f
    }
}

pub(crate) struct Forces {
    /// External force per unit load factor on the free dofs.
    pub(crate) ext: Vec<f64>,
    /// Internal force of the current stresses on the free dofs.
    pub(crate) int: Vec<f64>,
    /// Internal force on the prescribed dofs.
    pub(crate) int_fixed: Vec<f64>,
}

/// A step's updated points must be finite and inside the grid before they
/// are committed.
pub(crate) fn check_points(
    grid: &crate::grid::Grid,
    pts: &Points,
    step: usize,
    residuals: &[f64],
) -> Result<(), StepFailure> {
    check_finite(pts, step, residuals)?;
    if let Some(p) = (0..pts.len()).find(|&p| grid.cell_of(pts.x[p]).is_none()) {
        return Err(StepFailure::LeftGrid {
            step,
            point: p,
            position: pts.x[p],
            domain: false,
        });
    }
    Ok(())
}

/// A step's updated points must have finite stresses and positions.
pub(crate) fn check_finite(pts: &Points, step: usize, residuals: &[f64]) -> Result<(), StepFailure> {
    match (0..pts.len()).find(|&p| !pts.stress[p].iter().chain(&pts.x[p]).all(|v| v.is_finite())) {
        Some(p) => Err(StepFailure::NonFinite {
            step,
            what: format!("stress or position at point {p}"),
            residuals: residuals.to_vec(),
        }),
        None => Ok(()),
    }
}

/// The mass pattern and symbolic Cholesky of the last step, reused while
/// the assembly blocks (point groups and ghost faces) stay the same, or,
/// when they change, while the patterns they give do.
#[derive(Default)]
pub(crate) struct MassCache {
    pub(crate) key: Vec<Vec<usize>>,
    /// Whether the symbolic analyses merge small supernodes
    /// ([`crate::linalg::cholesky_symbolic_relaxed`]): part of the key.
    pub(crate) relaxed: bool,
    /// Per scalar part of the mass (one, or one per component), its
    /// pattern and symbolic Cholesky; empty before the first step.
    pub(crate) parts: Vec<(crate::assembly::Pattern, crate::linalg::CholeskySymbolic)>,
    /// The last factors' value buffers, handed back for the next step's
    /// factors of the same parts (implicit dynamics' projection).
    pub(crate) spare: Vec<Vec<f64>>,
}
