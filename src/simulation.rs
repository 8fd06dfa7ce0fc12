//! The simulation: state, one load step at a time, and what a step reports.
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
//! Failures (singular system, residual above tolerance, non-finite values)
//! are returned as [`StepFailure`] and leave the state at the last good step.

use crate::assembly::{Dof, Mapping, Pattern, Storage};
use crate::basis::Stencil;
use crate::boundary::{self, bspline::BSpline, BoundaryReport};
use crate::exact::ErrorNorm;
use crate::geometry::P2;
use crate::ghost;
use crate::ibm::{self, IbmReport, IbmStep};
use crate::linalg::{self, Condition};
use crate::material::mul3;
use crate::model::Model;
use crate::points::Points;
use crate::scene::ConditionMode;
use std::collections::BTreeMap;
use std::fmt;
use std::time::Instant;

/// Settings that may change between steps.
#[derive(Clone, Debug, PartialEq)]
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

/// Wall-clock time of each phase of a step (s).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Timings {
    pub assembly: f64,
    pub factorisation: f64,
    pub solve: f64,
    pub condition: f64,
    pub update: f64,
    pub total: f64,
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
    pub dynamics: Option<crate::dynamics::DynamicsReport>,
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
    /// The engine panicked (a bug): caught by [`Simulation::step_guarded`];
    /// the state is the last good step.
    Internal { step: usize, message: String },
    /// The observer cancelled the step ([`Simulation::set_progress`]); the
    /// state is the last good step.
    Cancelled { step: usize, residuals: Vec<f64> },
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

/// The evolving part of a simulation.
#[derive(Clone, Debug)]
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
    /// Explicit dynamics: the mass pattern of the last step.
    pub(crate) mass_cache: crate::dynamics::MassCache,
    /// The observer's progress hook (behind a mutex so steps can call it
    /// through `&self`).
    progress: Option<std::sync::Mutex<ProgressHook>>,
}

impl Simulation {
    pub fn new(model: Model) -> Simulation {
        let params = Params {
            tolerance: model.analysis.tolerance,
            condition: model.analysis.condition,
            dense_limit: model.analysis.dense_limit,
            max_iterations: model.analysis.max_iterations,
            gamma_k: model.analysis.gamma_k,
            delta_over_h: model.analysis.delta_over_h,
            gamma_m: model.gamma_m(),
        };
        let map = Mapping::build(&model.grid, &model.points, &model.bodies, &model.dirichlet, 0.0);
        let state = State {
            points: model.points.clone(),
            step: 0,
            external_work: 0.0,
            strain_energy: 0.0,
            active_cells: map.active_cells,
            ghost_faces: Vec::new(),
            iterations: 0,
            ibm_offsets: vec![[0.0; 2]; model.ibm.len()],
            initial_energy: model.points.kinetic_energy(),
        };
        Simulation {
            model,
            params,
            state,
            mass_cache: Default::default(),
            progress: None,
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

    /// Cells holding points after the last step.
    pub fn active_cells(&self) -> &[usize] {
        &self.state.active_cells
    }

    /// Make a completed step the current state.
    pub(crate) fn commit(
        &mut self,
        points: Points,
        step: usize,
        work: f64,
        map: &Mapping,
        faces: &[ghost::GhostFace],
        iterations: usize,
    ) {
        self.state.points = points;
        self.state.step = step;
        self.state.external_work += work;
        self.state.active_cells = map.active_cells.clone();
        self.state.ghost_faces = faces.iter().map(|f| ghost::face_segment(&self.model.grid, f)).collect();
        self.state.iterations += iterations;
    }

    /// The implicit boundaries where they are now (moving ones displaced).
    pub fn ibm_boundaries(&self) -> Vec<crate::ibm::IbmBoundary> {
        self.model
            .ibm
            .iter()
            .zip(&self.state.ibm_offsets)
            .map(|(b, &d)| match b.spline {
                // Follow the tracked spline through the points' positions now.
                Some((idx, chords)) => match self.model.boundaries[idx].spline(&self.state.points) {
                    Ok(s) => crate::ibm::IbmBoundary {
                        points: s.sample(chords),
                        ..b.clone()
                    },
                    Err(_) => b.clone(),
                },
                None => b.translated(d),
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

    /// [`Simulation::step`], with a panic inside the engine turned into
    /// [`StepFailure::Internal`] so that observers (TUI, recordings) can
    /// report it and close cleanly. A step commits only at its end, so the
    /// state stays at the last good step.
    pub fn step_guarded(&mut self) -> Result<StepReport, StepFailure> {
        let step = self.state.step + 1;
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| self.step())) {
            Ok(r) => r,
            Err(e) => Err(StepFailure::Internal {
                step,
                message: e
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| e.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "panic".into()),
            }),
        }
    }

    /// Take one load step.
    pub fn step(&mut self) -> Result<StepReport, StepFailure> {
        if self.finished() {
            return Err(StepFailure::Finished {
                steps: self.load_steps(),
            });
        }
        match self.model.analysis.kind {
            crate::scene::AnalysisKind::QuasiStaticFinite => return crate::newton::finite_step(self),
            crate::scene::AnalysisKind::ExplicitDynamics => return crate::dynamics::explicit_step(self),
            crate::scene::AnalysisKind::QuasiStaticLinear => {}
        }
        let step = self.state.step + 1;
        let lambda0 = self.state.step as f64 / self.load_steps() as f64;
        let lambda1 = step as f64 / self.load_steps() as f64;
        let start = Instant::now();
        let mut timings = Timings::default();

        // 1-2. Map points to the grid and assemble.
        let mut map = Mapping::build(
            &self.model.grid,
            &self.state.points,
            &self.model.bodies,
            &self.model.dirichlet,
            lambda1 - lambda0,
        );
        let d_of = |p: usize| self.model.materials[self.model.bodies[self.state.points.body[p]].material].d_matrix();
        let grid = &self.model.grid;
        let pts = &self.state.points;
        // Implicit boundaries: prescribed increments d^a on the nodes of cut
        // cells, and the band integrated as extra blocks (C (18)-(27)).
        let ibm_now = self.ibm_boundaries();
        let ibm_step = if ibm_now.is_empty() {
            None
        } else {
            Some(
                IbmStep::new(
                    &ibm_now,
                    grid,
                    &pts.x,
                    self.params.delta_over_h,
                    lambda1 - lambda0,
                    self.model.exact.as_ref(),
                )
                .map_err(|reason| StepFailure::Singular { step, reason })?,
            )
        };
        // A grid constraint prescribes a node's whole motion: where an
        // implicit boundary also puts a value d^a on that dof, the grid
        // unknown carries only the rest.
        if let Some(s) = &ibm_step {
            for (n, c, u) in map.dofs.constrained.iter_mut() {
                *u -= s.da[*n][*c];
            }
        }
        let mut f_d = vec![[0.0; 2]; grid.num_nodes()];
        let mut band: BTreeMap<(u32, u32, u8, u8), BandBlock> = BTreeMap::new();
        if let Some(s) = &ibm_step {
            let c = self.model.materials[self.model.bodies[0].material].d_matrix();
            for b in s.bs {
                for (x, w) in b.band_points(grid, s.delta) {
                    let st = ibm::grid_stencil(grid, x);
                    let (dm, g) = ibm::d_total(s.bs, x, s.delta);
                    let (b1, b2): (Vec<ibm::Op>, Vec<ibm::Op>) = ibm::b_bar(&st, &dm, &g).into_iter().unzip();
                    let entry = band
                        .entry(st.key)
                        .or_insert_with(|| (st.nodes[..st.len].to_vec(), vec![0.0; 4 * st.len * st.len]));
                    // The points integrate the band as if D = I (with the
                    // plain B); the band adds what makes its energy that of
                    // the trial space, B_bar^T C B_bar - B^T C B: K2 + K2^T
                    // + K3 of C (18) and K1's own D-weighting there. Leaving
                    // the last out costs an O(delta/h) stress error in the
                    // cells along the boundary (docs/verification.md).
                    let plain = ibm::plain_b(&st);
                    let bbar = ibm::add_ops(&b1, 1.0, &b2);
                    ibm::add_atcb(&bbar, &c, &bbar, w, &mut entry.1);
                    ibm::add_atcb(&plain, &c, &plain, -w, &mut entry.1);
                    // f_d in the band likewise: -(B_bar - B)^T C B d^a.
                    add_fd(&st, &ibm::add_ops(&bbar, -1.0, &plain), &c, &s.da, w, &mut f_d);
                }
            }
            for p in (0..pts.len()).filter(|&p| pts.vol[p] > 0.0) {
                let st = &map.stencils[p];
                let (bbar, _) = s.point_b(st, pts.x[p]);
                add_fd(st, &bbar, &d_of(p), &s.da, pts.vol[p], &mut f_d);
            }
        }
        let band: Vec<(Vec<usize>, Vec<f64>)> = band.into_values().collect();
        // Ghost faces (G 4.2) join the point groups as blocks of the pattern.
        let gamma = self.params.gamma_k;
        let faces = if gamma > 0.0 {
            ghost::faces_of(grid, &map, self.model.analysis.ghost_cells)
        } else {
            Vec::new()
        };
        let mut blocks: Vec<&[usize]> = map.groups.iter().map(|g| g.nodes.as_slice()).collect();
        blocks.extend(band.iter().map(|b| b.0.as_slice()));
        blocks.extend(faces.iter().map(|f| f.nodes.as_slice()));
        let pattern = Pattern::new(&map.dofs, &blocks, Storage::Lower);
        let (ng, nb) = (map.groups.len(), band.len());
        let stiffness = |with_ghost: bool| {
            pattern.assemble_with(&map.dofs, &blocks, |b, out| {
                if b < ng {
                    let g = &map.groups[b];
                    match &ibm_step {
                        Some(s) if g.points.iter().any(|&p| s.in_band[p]) => {
                            let m2 = 2 * g.nodes.len();
                            out.clear();
                            out.resize(m2 * m2, 0.0);
                            for &p in &g.points {
                                let (bb, _) = s.point_b(&map.stencils[p], pts.x[p]);
                                ibm::add_atcb(&bb, &d_of(p), &bb, pts.vol[p], out);
                            }
                        }
                        _ => map.group_stiffness(g, pts, &d_of, out),
                    }
                } else if b < ng + nb {
                    out.clear();
                    out.extend_from_slice(&band[b - ng].1);
                } else {
                    faces[b - ng - nb].stiffness(if with_ghost { gamma } else { 0.0 }, out)
                }
            })
        };
        let (k, coupling) = stiffness(true);
        let (mut forces, boundaries) = self.nodal_forces(&map, step, lambda1)?;
        if let Some(s) = &ibm_step {
            // Points inside a band work through B_bar: correct f_int.
            for p in (0..pts.len()).filter(|&p| s.in_band[p] && pts.vol[p] > 0.0) {
                let st = &map.stencils[p];
                let (bb, plain) = s.point_b(st, pts.x[p]);
                for (k, (n, _, _)) in st.iter().enumerate() {
                    for c in 0..2 {
                        if let Dof::Free(i) = map.dofs.node_dof[n][c] {
                            let sig = pts.stress[p];
                            forces.int[i] +=
                                pts.vol[p] * (0..3).map(|r| (bb[k][r][c] - plain[k][r][c]) * sig[r]).sum::<f64>();
                        }
                    }
                }
            }
        }
        let rhs: Vec<f64> = (0..map.dofs.n_free)
            .map(|i| lambda1 * forces.ext[i] - forces.int[i] - coupling[i])
            .collect();
        let mut rhs = rhs;
        for (n, d) in map.dofs.node_dof.iter().enumerate() {
            for c in 0..2 {
                if let Dof::Free(i) = d[c] {
                    rhs[i] -= f_d[n][c];
                }
            }
        }
        let residual_norm = norm(&rhs);
        timings.assembly = start.elapsed().as_secs_f64();

        // 3. Factorise.
        let t = Instant::now();
        let factor = linalg::cholesky(&k).map_err(|e| StepFailure::Singular {
            step,
            reason: e.to_string(),
        })?;
        timings.factorisation = t.elapsed().as_secs_f64();

        // 4. Solve and check the residual; ill-conditioned systems (tiny
        // point volumes near boundaries) get up to two rounds of iterative
        // refinement with the same factor, each recorded as a residual.
        let t = Instant::now();
        let rel_of = |v: &[f64]| {
            if residual_norm > 0.0 {
                norm(v) / residual_norm
            } else {
                norm(v)
            }
        };
        let mut du = linalg::solve(&factor, &rhs);
        let mut lin = residual_of(&k, &du, &rhs);
        let mut rel = rel_of(&lin);
        let mut residuals = vec![if residual_norm > 0.0 { 1.0 } else { 0.0 }, rel];
        for _ in 0..2 {
            if !(rel > self.params.tolerance) {
                break;
            }
            let neg: Vec<f64> = lin.iter().map(|v| -v).collect();
            let correction = linalg::solve(&factor, &neg);
            du.iter_mut().zip(&correction).for_each(|(a, c)| *a += c);
            lin = residual_of(&k, &du, &rhs);
            rel = rel_of(&lin);
            residuals.push(rel);
        }
        timings.solve = t.elapsed().as_secs_f64();
        if !self.report_progress(step, 1, rel) {
            return Err(StepFailure::Cancelled { step, residuals });
        }
        if !residual_norm.is_finite() || !rel.is_finite() || du.iter().any(|v| !v.is_finite()) {
            return Err(StepFailure::NonFinite {
                step,
                what: "residual or displacement increment".into(),
                residuals,
            });
        }
        if rel > self.params.tolerance {
            return Err(StepFailure::NotConverged {
                step,
                residuals,
                tolerance: self.params.tolerance,
            });
        }

        // Condition number of the reduced stiffness.
        let t = Instant::now();
        let condition = match self.params.condition {
            ConditionMode::Off => None,
            ConditionMode::Auto => Some(linalg::condition(&k, &factor, self.params.dense_limit)),
            ConditionMode::Dense => Some(linalg::condition(&k, &factor, usize::MAX)),
            ConditionMode::Lanczos => Some(linalg::condition(&k, &factor, 0)),
        };
        // Without the ghost term, for comparison (infinite when singular).
        let condition_unstabilised = match (&condition, faces.is_empty()) {
            (Some(c), false) => {
                let (k0, _) = stiffness(false);
                let limit = match self.params.condition {
                    ConditionMode::Dense => usize::MAX,
                    ConditionMode::Lanczos => 0,
                    _ => self.params.dense_limit,
                };
                Some(match linalg::cholesky(&k0) {
                    Ok(f0) => linalg::condition(&k0, &f0, limit),
                    Err(_) => Condition {
                        value: f64::INFINITY,
                        lambda_min: 0.0,
                        ..*c
                    },
                })
            }
            _ => None,
        };
        timings.condition = t.elapsed().as_secs_f64();

        // 5. Update the points.
        let t = Instant::now();
        let nodal_d = nodal_increments(&map, &du);
        // Points move with N (d + d^a); those inside a band with D N d + N d^a.
        let nodal: Vec<P2> = match &ibm_step {
            Some(s) => nodal_d
                .iter()
                .zip(&s.da)
                .map(|(a, b)| [a[0] + b[0], a[1] + b[1]])
                .collect(),
            None => nodal_d.clone(),
        };
        let max_increment = nodal.iter().map(|u| u[0].hypot(u[1])).fold(0.0, f64::max);
        let (mut points, fint_fixed_new) = self.updated_points(&map, &nodal);
        let mut ibm_reports = Vec::new();
        let mut ibm_work = 0.0;
        if let Some(s) = &ibm_step {
            for p in (0..points.len()).filter(|&p| s.in_band[p]) {
                let st = &map.stencils[p];
                let (bb, plain) = s.point_b(st, pts.x[p]);
                let (dm, _) = ibm::d_total(s.bs, pts.x[p], s.delta);
                let mut de = [0.0; 3];
                let mut dx = [0.0; 2];
                for (k, (n, w, _)) in st.iter().enumerate() {
                    for c in 0..2 {
                        for r in 0..3 {
                            de[r] += (bb[k][r][c] - plain[k][r][c]) * nodal_d[n][c];
                        }
                        for i in 0..2 {
                            dx[i] += ((dm[i][c]) - if i == c { 1.0 } else { 0.0 }) * w * nodal_d[n][c];
                        }
                    }
                }
                let ds = mul3(&d_of(p), de);
                for r in 0..3 {
                    points.stress[p][r] += ds[r];
                    points.strain[p][r] += de[r];
                }
                points.x[p] = [points.x[p][0] + dx[0], points.x[p][1] + dx[1]];
            }
            let (reports, work) = self.ibm_reports(&map, s, &points, &nodal_d, &forces.ext, lambda0, lambda1);
            ibm_reports = reports;
            ibm_work = work;
        }
        check_points(&self.model.grid, &points, step, &residuals)?;
        // Work: free dofs carry f_ext, prescribed dofs the support force f_int.
        let mut work = 0.0;
        for i in 0..map.dofs.n_free {
            work += 0.5 * (lambda0 + lambda1) * forces.ext[i] * du[i];
        }
        for (c, &(n, comp, u)) in map.dofs.constrained.iter().enumerate() {
            let total = u + ibm_step.as_ref().map_or(0.0, |s| s.da[n][comp]);
            work += 0.5 * (forces.int_fixed[c] + fint_fixed_new[c]) * total;
        }
        if let Some(s) = &ibm_step {
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
        let old = &self.state.points;
        let strain_energy = self.state.strain_energy
            + (0..points.len())
                .map(|p| {
                    let (s0, s1) = (old.stress[p], points.stress[p]);
                    let de = [0, 1, 2].map(|k| points.strain[p][k] - old.strain[p][k]);
                    0.5 * (0..3).map(|k| (s0[k] + s1[k]) * de[k]).sum::<f64>() * old.vol[p]
                })
                .sum::<f64>();
        timings.update = t.elapsed().as_secs_f64();

        // Commit.
        self.commit(points, step, work, &map, &faces, 1);
        self.state.strain_energy = strain_energy;
        for (off, b) in self.state.ibm_offsets.iter_mut().zip(&self.model.ibm) {
            if b.moves {
                let m = b.motion();
                off[0] += m[0] * (lambda1 - lambda0);
                off[1] += m[1] * (lambda1 - lambda0);
            }
        }
        let errors = match &self.model.exact {
            Some(e) => e.errors(&self.state.points, lambda1),
            None => Vec::new(),
        };
        timings.total = start.elapsed().as_secs_f64();
        Ok(StepReport {
            step,
            load_steps: self.load_steps(),
            load_factor: lambda1,
            unknowns: map.dofs.n_free,
            active_nodes: map.dofs.active_nodes,
            active_cells: map.active_cells.len(),
            residual_norm,
            residuals,
            timings,
            energy: Energy {
                strain: strain_energy,
                external_work: self.state.external_work,
                plastic_dissipation: 0.0,
                kinetic: 0.0,
            },
            condition,
            condition_unstabilised,
            iterations: 1,
            ghost_faces: faces.len(),
            ibm: ibm_reports,
            errors,
            max_increment,
            boundaries,
            dynamics: None,
        })
    }

    /// Reports of the implicit boundaries after an update (reaction from
    /// the out-of-balance of the new stresses on the nodes of each
    /// boundary's cut cells; violation sampled along the boundary), and the
    /// work their reactions did in the step (trapezoidal).
    #[allow(clippy::too_many_arguments)]
    fn ibm_reports(
        &self,
        map: &Mapping,
        s: &IbmStep,
        new: &Points,
        nodal_d: &[P2],
        ext: &[f64],
        lambda0: f64,
        lambda1: f64,
    ) -> (Vec<IbmReport>, f64) {
        let grid = &self.model.grid;
        let old = &self.state.points;
        // Out-of-balance of the material (internal minus every external
        // force on the free dofs) at the start and end of the step: where
        // the implicit boundaries act, it is their reaction.
        let mut residual = vec![[0.0; 2]; grid.num_nodes()];
        let mut residual0 = vec![[0.0; 2]; grid.num_nodes()];
        for p in (0..new.len()).filter(|&p| old.vol[p] > 0.0) {
            let st = &map.stencils[p];
            let (bb, _) = s.point_b(st, old.x[p]);
            for (k, (n, _, _)) in st.iter().enumerate() {
                for c in 0..2 {
                    let f = |sig: [f64; 3]| (0..3).map(|r| bb[k][r][c] * sig[r]).sum::<f64>() * old.vol[p];
                    residual[n][c] += f(new.stress[p]);
                    residual0[n][c] += f(old.stress[p]);
                }
            }
        }
        for (n, d) in map.dofs.node_dof.iter().enumerate() {
            for c in 0..2 {
                if let Dof::Free(i) = d[c] {
                    residual[n][c] -= lambda1 * ext[i];
                    residual0[n][c] -= lambda0 * ext[i];
                }
            }
        }
        // Per boundary: its cut cells and their nodes.
        let cut: Vec<(Vec<usize>, Vec<usize>)> =
            s.bs.iter()
                .map(|b| {
                    let cells = b.cut_cells(grid);
                    let mut nodes: Vec<usize> = cells
                        .iter()
                        .flat_map(|&c| grid.cell_nodes(c % grid.nx, c / grid.nx))
                        .collect();
                    nodes.sort_unstable();
                    nodes.dedup();
                    (cells, nodes)
                })
                .collect();
        let free = |n: usize, c: usize| matches!(map.dofs.node_dof[n][c], Dof::Free(_));
        // Work of the reactions: trapezoidal on the increments of the free
        // dofs of the cut cells' nodes (grid-prescribed dofs count their
        // reactions' work with the other grid constraints; elsewhere the
        // out-of-balance is the remap's, not a support's).
        let mut support: Vec<usize> = cut.iter().flat_map(|(_, nodes)| nodes.iter().copied()).collect();
        support.sort_unstable();
        support.dedup();
        let mut work = 0.0;
        for &n in &support {
            for c in (0..2).filter(|&c| free(n, c)) {
                work += 0.5 * (residual0[n][c] + residual[n][c]) * (nodal_d[n][c] + s.da[n][c]);
            }
        }
        let mut reports = Vec::new();
        let dl = lambda1 - lambda0;
        for (b, (cells, nodes)) in s.bs.iter().zip(&cut) {
            // The support force on the body balances the out-of-balance
            // force of the material there: R = f_int - f_ext.
            let mut reaction = [0.0; 2];
            for &n in nodes {
                for c in (0..2).filter(|&c| free(n, c)) {
                    reaction[c] += residual[n][c];
                }
            }
            // Violation: the increment on the boundary (phi = 0) against the prescribed one.
            let mut violation = 0.0f64;
            // Sampled at each piece's ends (for the largest) and its three
            // Gauss points (for the root mean square along the boundary).
            let (xg, wg) = crate::quadrature::gauss_legendre(3);
            let samples: Vec<(f64, f64)> = [(0.0, 0.0), (1.0, 0.0)]
                .into_iter()
                .chain(xg.iter().zip(&wg).map(|(x, w)| (0.5 * (1.0 + x), 0.5 * w)))
                .collect();
            let (mut sum_sq, mut length) = (0.0, 0.0);
            for (a, e, _) in b.pieces(grid) {
                let n = b.normal(a, e);
                let len = (e[0] - a[0]).hypot(e[1] - a[1]);
                for &(t, w) in &samples {
                    let x = [a[0] + t * (e[0] - a[0]), a[1] + t * (e[1] - a[1])];
                    let st = ibm::grid_stencil(grid, [x[0] + 1e-12 * grid.h * n[0], x[1] + 1e-12 * grid.h * n[1]]);
                    let (dm, _) = ibm::d_total(s.bs, x, s.delta);
                    let nd = st.interpolate(|k| nodal_d[k]);
                    let na = st.interpolate(|k| s.da[k]);
                    let u = [
                        dm[0][0] * nd[0] + dm[0][1] * nd[1] + na[0],
                        dm[1][0] * nd[0] + dm[1][1] * nd[1] + na[1],
                    ];
                    let target = match (&self.model.exact, b.exact_field) {
                        (Some(ex), true) => ex.displacement(x).map(|v| v * dl),
                        _ => [b.value[0] * dl, b.value[1] * dl],
                    };
                    let v = match b.kind {
                        crate::scene::DirichletKind::Fixed => (u[0] - target[0]).hypot(u[1] - target[1]),
                        crate::scene::DirichletKind::Roller => (u[0] * n[0] + u[1] * n[1] - b.value[0] * dl).abs(),
                    };
                    violation = violation.max(v);
                    sum_sq += w * len * v * v;
                    length += w * len;
                }
            }
            reports.push(IbmReport {
                name: b.name.clone(),
                cut_cells: cells.len(),
                reaction,
                violation,
                violation_rms: if length > 0.0 { (sum_sq / length).sqrt() } else { 0.0 },
            });
        }
        (reports, work)
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
            for (n, w, [dx, dy]) in map.stencils[p].iter() {
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
            for (n, w, _) in map.stencils[load.point].iter() {
                for c in 0..2 {
                    if let Dof::Free(i) = map.dofs.node_dof[n][c] {
                        f.ext[i] += w * load.force[c];
                    }
                }
            }
        }
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
                        f.ext[i] += force[c];
                    }
                }
            }
            reports.push(report);
        }
        Ok((f, reports))
    }

    /// Points after applying nodal increments, and the internal force of
    /// the new stresses on the prescribed dofs (start-of-step geometry).
    fn updated_points(&self, map: &Mapping, nodal: &[P2]) -> (Points, Vec<f64>) {
        let mut pts = self.state.points.clone();
        let mut fint_fixed = vec![0.0; map.dofs.constrained.len()];
        for p in 0..pts.len() {
            let st = &map.stencils[p];
            let du = st.interpolate(|n| nodal[n]);
            let g = st.gradient(|n| nodal[n]);
            let de = [g[0][0], g[1][1], g[0][1] + g[1][0]];
            let d = self.model.materials[self.model.bodies[pts.body[p]].material].d_matrix();
            let ds = mul3(&d, de);
            let v = pts.vol[p];
            for k in 0..3 {
                pts.stress[p][k] += ds[k];
                pts.strain[p][k] += de[k];
            }
            if v > 0.0 {
                let s = pts.stress[p];
                for (n, _, [dx, dy]) in st.iter() {
                    let fi = [(dx * s[0] + dy * s[2]) * v, (dy * s[1] + dx * s[2]) * v];
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
        (pts, fint_fixed)
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

/// A step's updated points must be finite and inside the grid before they
/// are committed.
pub(crate) fn check_points(
    grid: &crate::grid::Grid,
    pts: &Points,
    step: usize,
    residuals: &[f64],
) -> Result<(), StepFailure> {
    if let Some(p) = (0..pts.len()).find(|&p| !pts.stress[p].iter().chain(&pts.x[p]).all(|v| v.is_finite())) {
        return Err(StepFailure::NonFinite {
            step,
            what: format!("stress or position at point {p}"),
            residuals: residuals.to_vec(),
        });
    }
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

/// A band block: its nodes and dense local matrix.
type BandBlock = (Vec<usize>, Vec<f64>);

/// Add `w B_bar^T C (B d^a)` to the nodal force `f` (the strain of the
/// prescribed field moved to the right-hand side).
fn add_fd(st: &Stencil, bbar: &[[[f64; 2]; 3]], c: &[[f64; 3]; 3], da: &[P2], w: f64, f: &mut [P2]) {
    let g = st.gradient(|n| da[n]);
    let eps = [g[0][0], g[1][1], g[0][1] + g[1][0]];
    if eps == [0.0; 3] {
        return;
    }
    let sig = mul3(c, eps);
    for (k, (n, _, _)) in st.iter().enumerate() {
        for comp in 0..2 {
            f[n][comp] += w * (0..3).map(|r| bbar[k][r][comp] * sig[r]).sum::<f64>();
        }
    }
}

/// `K du - rhs`.
fn residual_of(k: &faer::sparse::SparseColMat<usize, f64>, du: &[f64], rhs: &[f64]) -> Vec<f64> {
    linalg::sym_lower_mul(k, du)
        .iter()
        .zip(rhs)
        .map(|(a, b)| a - b)
        .collect()
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}
