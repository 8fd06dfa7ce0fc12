//! TUI state and actions. No drawing and no terminal here: `draw.rs` renders
//! an [`App`], `mod.rs` feeds it key presses and engine updates.

use crate::field::Field;
use crate::grid::Grid;
use crate::simulation::{Params, Simulation, StepFailure, StepReport};

/// What the canvas shows of the simulation at its latest step.
#[derive(Clone, Debug)]
pub struct View {
    pub step: usize,
    pub load_steps: usize,
    pub load_factor: f64,
    /// Simulated time (s), dynamics only.
    pub time: Option<f64>,
    pub positions: Vec<[f64; 2]>,
    /// The colour field at every point.
    pub values: Vec<f64>,
    pub field: Field,
    /// The field's name and unit.
    pub label: String,
    pub active_cells: Vec<usize>,
    pub boundaries: Vec<BoundaryView>,
    /// Faces carrying ghost stabilisation in the last step.
    pub ghost_faces: Vec<([f64; 2], [f64; 2])>,
    /// Implicit Dirichlet boundaries (polylines) and their names.
    pub ibm: Vec<Vec<[f64; 2]>>,
    pub ibm_names: Vec<String>,
    /// Grid-line supports as segments (a fixed or roller grid line), and
    /// supported single nodes as zero-length segments.
    pub supports: Vec<([f64; 2], [f64; 2])>,
    /// Point loads: where (the loaded point now) and the force's direction
    /// (unit vector).
    pub loads: Vec<([f64; 2], [f64; 2])>,
    /// Cells the implicit boundaries cut.
    pub cut_cells: Vec<usize>,
}

/// A boundary as drawn: the sampled spline and its Bezier control points.
#[derive(Clone, Debug)]
pub struct BoundaryView {
    pub name: String,
    pub curve: Vec<[f64; 2]>,
    pub control: Vec<[f64; 2]>,
    /// Carries a traction (drawn apart from merely tracked curves).
    pub loaded: bool,
}

impl BoundaryView {
    /// Views of all boundaries of a simulation at its current state.
    pub fn all(sim: &Simulation) -> Vec<BoundaryView> {
        sim.boundary_splines()
            .into_iter()
            .zip(&sim.model().boundaries)
            .map(|((name, spline), b)| {
                let (curve, control) = match spline {
                    Some(s) => (
                        s.sample(16),
                        s.segments.iter().flat_map(|seg| seg.iter().copied()).collect(),
                    ),
                    None => (Vec::new(), Vec::new()),
                };
                BoundaryView {
                    name,
                    curve,
                    control,
                    loaded: b.traction.is_some(),
                }
            })
            .collect()
    }
}

impl View {
    pub fn of(sim: &Simulation, field: Field) -> View {
        let ibm = sim.ibm_boundaries();
        View {
            step: sim.step_index(),
            load_steps: sim.load_steps(),
            load_factor: sim.load_factor(),
            time: sim.time(),
            positions: sim.points().x.clone(),
            values: field.values(sim),
            field,
            label: field.label_for(sim),
            active_cells: sim.active_cells().to_vec(),
            boundaries: BoundaryView::all(sim),
            ghost_faces: sim.ghost_faces().to_vec(),
            cut_cells: {
                let mut c: Vec<usize> = ibm.iter().flat_map(|b| b.cut_cells(&sim.model().grid)).collect();
                c.sort_unstable();
                c.dedup();
                c
            },
            ibm_names: ibm.iter().map(|b| b.name.clone()).collect(),
            ibm: ibm.into_iter().map(|b| b.points).collect(),
            supports: supports(sim),
            loads: sim
                .model()
                .point_loads
                .iter()
                .filter_map(|l| {
                    let n = l.force[0].hypot(l.force[1]);
                    (n > 0.0).then(|| (sim.points().x[l.point], [l.force[0] / n, l.force[1] / n]))
                })
                .collect(),
        }
    }
}

/// The grid-aligned supports of a model as segments.
fn supports(sim: &Simulation) -> Vec<([f64; 2], [f64; 2])> {
    use crate::model::GridTarget;
    let g = &sim.model().grid;
    let max = g.max();
    sim.model()
        .dirichlet
        .iter()
        .map(|d| match d.target {
            GridTarget::Line { axis: 0, index } => {
                let x = g.origin[0] + index as f64 * g.h;
                ([x, g.origin[1]], [x, max[1]])
            }
            GridTarget::Line { index, .. } => {
                let y = g.origin[1] + index as f64 * g.h;
                ([g.origin[0], y], [max[0], y])
            }
            GridTarget::Node(n) => {
                let p = g.node_position(n);
                (p, p)
            }
        })
        .collect()
}

/// Something the user asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    Step,
    ToggleHelp,
    ToggleControlPoints,
    /// Multiply `gamma_K` by 10 (from 0: start at 1e-6 E).
    RaiseGammaK,
    /// Divide `gamma_K` by 10.
    LowerGammaK,
    /// Switch ghost stabilisation off, or back on at its last value.
    ToggleGhost,
    /// Implicit-boundary bandwidth delta/h times 10.
    RaiseDelta,
    /// Implicit-boundary bandwidth delta/h divided by 10.
    LowerDelta,
    /// Ghost mass penalty gamma_M times 10 (from 0: rho/4).
    RaiseGammaM,
    /// Ghost mass penalty gamma_M divided by 10.
    LowerGammaM,
    /// Step continuously until paused, finished or failed.
    RunPause,
    /// Canvas zoom in / out (x2), pan by a fifth of the view, back to fit.
    ZoomIn,
    ZoomOut,
    PanLeft,
    PanRight,
    PanUp,
    PanDown,
    ResetView,
    /// The probe chart's next y (`p`) or x (`P`) quantity.
    NextProbeY,
    NextProbeX,
    /// Write a checkpoint of the state after the last step.
    Checkpoint,
    /// Start or stop a ParaView series of the steps from now on.
    ToggleVtk,
    /// Next chart: residuals, condition numbers, energies, errors.
    NextChart,
    /// Show or hide the grid lines, the active cells, the ghost faces.
    ToggleGrid,
    ToggleActive,
    ToggleGhostFaces,
    /// Show or hide the charts' legends.
    ToggleLegend,
    /// Redo the last step (done or failed) from its snapshot with the
    /// current parameters, and compare.
    Redo,
    /// Cancel the step being computed.
    Cancel,
    /// Tolerance times / divided by 10.
    RaiseTolerance,
    LowerTolerance,
    /// Open the parameter prompt (`name = value`), type into it, submit.
    OpenInput,
    Type(char),
    Backspace,
    Submit,
    CloseOverlay,
    NextField,
    Quit,
}

/// What the app wants the engine to do after an action.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    Step,
    SetField(Field),
    /// New ghost stiffness penalty `gamma_K` (from the next step).
    SetGammaK(f64),
    /// New implicit-boundary bandwidth `delta/h` (from the next step).
    SetDeltaOverH(f64),
    /// New ghost mass penalty `gamma_M` (from the next step).
    SetGammaM(f64),
    /// New tolerance (from the next step).
    SetTolerance(f64),
    /// New Newton iteration limit (from the next step).
    SetMaxIterations(usize),
    /// Restore the state before the last step and take it again.
    Redo,
    /// Stop the step being computed (handled by the UI loop through a flag
    /// the engine's progress hook reads).
    Cancel,
    /// Write a checkpoint of the current state (`checkpoints/`).
    Checkpoint,
    /// Start (or stop) writing a ParaView series (`vtk/`), every step from now.
    ToggleVtk,
    Quit,
}

/// What the chart panel shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChartKind {
    /// Newton residual per iteration, the last steps overlaid (log10).
    Residual,
    /// Condition numbers per step (log10), with and without ghost.
    Condition,
    /// Energies per step (quasi-static) or against time (dynamics).
    Energy,
    /// Errors against the exact solution per step (log10).
    Error,
    /// One probe quantity against another (or the load factor): a
    /// load–displacement curve (`p`/`P` choose y and x).
    Probe,
}

impl ChartKind {
    pub fn next(self) -> ChartKind {
        match self {
            ChartKind::Residual => ChartKind::Condition,
            ChartKind::Condition => ChartKind::Energy,
            ChartKind::Energy => ChartKind::Error,
            ChartKind::Error => ChartKind::Probe,
            ChartKind::Probe => ChartKind::Residual,
        }
    }
}

/// The whole state of the interface.
pub struct App {
    pub scene_name: String,
    pub description: String,
    /// The scene's unit system (labels).
    pub units: crate::units::Units,
    pub grid: Grid,
    pub points: usize,
    pub view: View,
    pub reports: Vec<StepReport>,
    pub failure: Option<StepFailure>,
    /// A step is being computed.
    pub busy: bool,
    pub show_help: bool,
    /// Draw the boundaries' Bezier control points.
    pub show_control: bool,
    pub recording: Option<String>,
    /// The engine's current parameters.
    pub params: Params,
    /// `gamma_K` to restore when ghost stabilisation is switched back on.
    pub last_gamma: f64,
    /// Young's modulus of the first material (scale for `gamma_K`).
    pub modulus: f64,
    /// A message for the status line (e.g. recording errors).
    pub status: String,
    pub quit: bool,
    /// Stepping continuously.
    pub running: bool,
    /// `gamma_M` to start from when raising it from 0 (the analysis' default:
    /// rho/4 of the densest material explicitly, rho/4000 implicitly).
    pub default_gamma_m: f64,
    /// Implicit dynamics: every step is a Newton solve in time, so Newton's
    /// knobs (gamma_K, delta, tolerance) and residuals apply as well as
    /// gamma_M and the energies against time.
    pub implicit_dynamics: bool,
    /// Canvas magnification (1: the whole grid) and view centre offset (m).
    pub zoom: f64,
    pub pan: [f64; 2],
    pub chart: ChartKind,
    /// `q` was pressed while a step runs: a second `q` quits.
    pub confirm_quit: bool,
    /// The last redo: the step's outcome before and after.
    pub redo: Option<Box<(Outcome, Outcome)>>,
    /// Show the failure panel (Esc hides it; the failure stays).
    pub show_failure: bool,
    /// The latest residual of the step being computed.
    pub progress: Option<crate::simulation::Progress>,
    /// The parameter prompt's text while it is open.
    pub input: Option<String>,
    /// Canvas layers.
    pub show_grid: bool,
    pub show_active: bool,
    pub show_ghost_faces: bool,
    /// The charts' legends (placed where they hide no curve).
    pub show_legend: bool,
    /// The probes at the start (the probe chart's first point).
    pub probes_start: Vec<crate::probe::ProbeValue>,
    /// The probe chart's axes: indices into [`App::probe_columns`].
    pub probe_x: usize,
    pub probe_y: usize,
}

/// A step's outcome.
pub type Outcome = Result<StepReport, StepFailure>;

impl App {
    pub fn new(sim: &Simulation, recording: Option<String>) -> App {
        App {
            scene_name: sim.model().name.clone(),
            description: sim.model().description.clone(),
            units: sim.model().units,
            grid: sim.model().grid.clone(),
            points: sim.points().len(),
            view: View::of(sim, Field::SigmaYy),
            reports: Vec::new(),
            failure: None,
            busy: false,
            show_help: false,
            show_control: false,
            recording,
            params: sim.params().clone(),
            last_gamma: if sim.params().gamma_k > 0.0 {
                sim.params().gamma_k
            } else {
                modulus(sim)
            },
            modulus: modulus(sim),
            status: String::new(),
            quit: false,
            running: false,
            default_gamma_m: sim.model().default_gamma_m(),
            implicit_dynamics: sim.time().is_some() && sim.model().analysis.kind.is_newton(),
            zoom: 1.0,
            pan: [0.0; 2],
            chart: if sim.time().is_some() {
                ChartKind::Energy
            } else {
                ChartKind::Residual
            },
            confirm_quit: false,
            redo: None,
            show_failure: false,
            progress: None,
            input: None,
            show_grid: true,
            show_active: false,
            show_ghost_faces: true,
            show_legend: true,
            probes_start: Vec::new(),
            probe_x: 0,
            probe_y: 0,
        }
        .with_probes(sim)
    }

    /// Start the probe chart on the probes' initial values: the load of an
    /// implicit boundary that is moved against its displacement (a
    /// footing's load against its settlement, a platen's), else the first
    /// other probe's vertical displacement against the load factor (a
    /// beam's tip).
    fn with_probes(mut self, sim: &Simulation) -> App {
        use crate::probe::ProbeTarget;
        self.probes_start = sim.probe_values(None);
        let m = sim.model();
        // Column of probe k's first value (after the load factor).
        let first: Vec<usize> = self
            .probes_start
            .iter()
            .scan(1, |c, p| {
                let at = *c;
                *c += p.columns().len();
                Some(at)
            })
            .collect();
        let moved = m.probes.iter().position(|p| match p.target {
            ProbeTarget::Ibm(b) => m.ibm[b].motion() != [0.0; 2],
            _ => false,
        });
        let other = m.probes.iter().position(|p| !matches!(p.target, ProbeTarget::Ibm(_)));
        // Columns: ux, uy, then fx, fy for boundaries.
        (self.probe_x, self.probe_y) = match (moved, other.or(if m.probes.is_empty() { None } else { Some(0) })) {
            (Some(k), _) => (first[k] + 1, first[k] + 3),
            (None, Some(k)) => (0, first[k] + 1),
            (None, None) => (0, 0),
        };
        self
    }

    /// The quantities the probe chart can show: the load factor (or time)
    /// first, then every probe's `(name:key, label with unit)`.
    pub fn probe_columns(&self) -> Vec<(String, String)> {
        let mut c = vec![match self.view.time {
            Some(_) => ("time".to_string(), "time (s)".to_string()),
            None => ("load factor".to_string(), "load factor".to_string()),
        }];
        for p in &self.probes_start {
            for (k, q, _) in p.columns() {
                let name = format!("{}:{k}", p.name);
                c.push((name.clone(), self.units.label(&name, q)));
            }
        }
        c
    }

    /// Column `col` of [`App::probe_columns`] at the start and after each step.
    pub fn probe_series(&self, col: usize) -> Vec<f64> {
        let value = |probes: &[crate::probe::ProbeValue], lambda: f64| {
            if col == 0 {
                return lambda;
            }
            probes
                .iter()
                .flat_map(|p| p.columns().into_iter().map(|c| c.2))
                .nth(col - 1)
                .unwrap_or(f64::NAN)
        };
        std::iter::once(value(&self.probes_start, 0.0))
            .chain(self.reports.iter().map(|r| {
                let x = r.dynamics.as_ref().map_or(r.load_factor, |d| d.time);
                value(&r.probes, x)
            }))
            .collect()
    }

    /// The next step while running continuously (stops at the end or at a failure).
    pub fn pending(&mut self) -> Option<Command> {
        if !self.running || self.busy {
            return None;
        }
        if self.failure.is_some() || self.finished() {
            self.running = false;
            return None;
        }
        self.busy = true;
        Some(Command::Step)
    }

    pub fn finished(&self) -> bool {
        self.view.step >= self.view.load_steps
    }

    /// Apply a user action; returns the command for the engine, if any.
    /// Parameter changes take effect in the shown parameters at once, so
    /// repeated presses during a step compound (the engine applies them in
    /// order from the next step).
    pub fn apply(&mut self, action: Action) -> Option<Command> {
        let cmd = self.act(action);
        match cmd {
            Some(Command::SetGammaK(g)) => self.params.gamma_k = g,
            Some(Command::SetDeltaOverH(d)) => self.params.delta_over_h = d,
            Some(Command::SetGammaM(g)) => self.params.gamma_m = g,
            Some(Command::SetTolerance(t)) => self.params.tolerance = t,
            Some(Command::SetMaxIterations(n)) => self.params.max_iterations = n,
            _ => {}
        }
        cmd
    }

    fn act(&mut self, action: Action) -> Option<Command> {
        match action {
            Action::Step => self.request_step(),
            Action::ToggleHelp => {
                self.show_help = !self.show_help;
                None
            }
            Action::ToggleControlPoints => {
                self.show_control = !self.show_control;
                None
            }
            Action::RaiseGammaK | Action::LowerGammaK | Action::ToggleGhost => self.change_gamma_k(action),
            Action::RaiseDelta | Action::LowerDelta => self.change_delta(action),
            Action::RaiseGammaM | Action::LowerGammaM => self.change_gamma_m(action),
            Action::RunPause => self.run_pause(),
            Action::Redo => self.request_redo(),
            Action::Cancel => {
                self.running = false;
                if self.busy {
                    self.status = "cancelling the step...".into();
                    Some(Command::Cancel)
                } else {
                    None
                }
            }
            Action::RaiseTolerance | Action::LowerTolerance => self.change_tolerance(action),
            Action::OpenInput => {
                self.input = Some(String::new());
                self.status = "type name = value (gamma_k, gamma_m, delta_over_h, tolerance, max_iterations), enter sets it, Esc cancels".into();
                None
            }
            Action::Type(c) => {
                if let Some(i) = self.input.as_mut() {
                    i.push(c);
                }
                None
            }
            Action::Backspace => {
                if let Some(i) = self.input.as_mut() {
                    i.pop();
                }
                None
            }
            Action::Submit => self.submit_input(),
            Action::CloseOverlay => self.close_overlay(),
            Action::ZoomIn | Action::ZoomOut | Action::ResetView => self.change_zoom(action),
            Action::PanLeft | Action::PanRight | Action::PanUp | Action::PanDown => self.move_view(action),
            Action::ToggleGrid => {
                self.show_grid = !self.show_grid;
                None
            }
            Action::ToggleActive => {
                self.show_active = !self.show_active;
                None
            }
            Action::ToggleGhostFaces => {
                self.show_ghost_faces = !self.show_ghost_faces;
                None
            }
            Action::ToggleLegend => {
                self.show_legend = !self.show_legend;
                None
            }
            Action::NextChart => {
                self.chart = self.chart.next();
                if self.chart == ChartKind::Probe && self.probes_start.is_empty() {
                    self.chart = self.chart.next();
                }
                None
            }
            Action::ToggleVtk => Some(Command::ToggleVtk),
            Action::Checkpoint => {
                if self.busy {
                    self.status = "a step is running: checkpoint after it".into();
                    None
                } else {
                    Some(Command::Checkpoint)
                }
            }
            Action::NextProbeY | Action::NextProbeX => self.next_probe_axis(action),
            Action::NextField => {
                let k = Field::ALL.iter().position(|f| *f == self.view.field).unwrap_or(0);
                Some(Command::SetField(Field::ALL[(k + 1) % Field::ALL.len()]))
            }
            Action::Quit => self.request_quit(),
        }
    }

    /// Step once, unless a step is running or every step is done.
    fn request_step(&mut self) -> Option<Command> {
        if self.busy {
            self.status = "a step is running".into();
            None
        } else if self.finished() {
            self.status = format!("all {} load steps done (q quits)", self.view.load_steps);
            None
        } else {
            self.busy = true;
            self.status = format!("computing step {}...", self.view.step + 1);
            Some(Command::Step)
        }
    }

    /// gamma_K ten times up or down, or the ghost penalty off and on again.
    fn change_gamma_k(&mut self, action: Action) -> Option<Command> {
        if self.busy {
            self.status = "wait for the step to finish before changing gamma_K".into();
            return None;
        }
        let g = self.params.gamma_k;
        let new = match action {
            Action::RaiseGammaK if g == 0.0 => 1e-6 * self.modulus,
            Action::RaiseGammaK => 10.0 * g,
            Action::LowerGammaK => g / 10.0,
            _ if g > 0.0 => 0.0,
            _ => self.last_gamma,
        };
        if new > 0.0 {
            self.last_gamma = new;
        }
        self.status = format!("gamma_K = {new:.3e} Pa from the next step");
        Some(Command::SetGammaK(new))
    }

    /// delta/h ten times up or down, within 1e-16 ..= 1.
    fn change_delta(&mut self, action: Action) -> Option<Command> {
        if self.busy {
            self.status = "wait for the step to finish before changing delta".into();
            return None;
        }
        let d = self.params.delta_over_h;
        let new = if action == Action::RaiseDelta {
            (10.0 * d).min(1.0)
        } else {
            (d / 10.0).max(1e-16)
        };
        self.status = format!("delta/h = {new:.1e} from the next step");
        Some(Command::SetDeltaOverH(new))
    }

    /// gamma_M ten times up or down (from zero: the default).
    fn change_gamma_m(&mut self, action: Action) -> Option<Command> {
        if self.busy && !self.running {
            self.status = "wait for the step to finish before changing gamma_M".into();
            return None;
        }
        let g = self.params.gamma_m;
        let new = match action {
            Action::RaiseGammaM if g == 0.0 => self.default_gamma_m,
            Action::RaiseGammaM => 10.0 * g,
            _ => g / 10.0,
        };
        self.status = format!("gamma_M = {new:.3e} kg/m^3 from the next step");
        Some(Command::SetGammaM(new))
    }

    /// Step on and on, or pause.
    fn run_pause(&mut self) -> Option<Command> {
        self.running = !self.running;
        self.status = if self.running {
            "running (enter pauses)"
        } else {
            "paused"
        }
        .into();
        self.pending()
    }

    /// The last step again with the current parameters.
    fn request_redo(&mut self) -> Option<Command> {
        if self.busy {
            self.status = "wait for the step to finish before redoing it".into();
            None
        } else if self.reports.is_empty() && self.failure.is_none() {
            self.status = "no step to redo yet".into();
            None
        } else {
            self.busy = true;
            self.status = "redoing the last step with the current parameters...".into();
            Some(Command::Redo)
        }
    }

    /// The Newton tolerance ten times up or down, within 1e-16 ..= 0.1.
    fn change_tolerance(&mut self, action: Action) -> Option<Command> {
        let t = self.params.tolerance;
        let new = if action == Action::RaiseTolerance {
            (10.0 * t).min(0.1)
        } else {
            (t / 10.0).max(1e-16)
        };
        self.status = format!("tolerance = {new:.1e} from the next step");
        Some(Command::SetTolerance(new))
    }

    /// The typed `name = value` as a command.
    fn submit_input(&mut self) -> Option<Command> {
        let text = self.input.take().unwrap_or_default();
        match parse_setting(&text) {
            Ok(cmd) => {
                self.status = format!("{} from the next step", text.trim());
                Some(cmd)
            }
            Err(e) => {
                self.status = e;
                None
            }
        }
    }

    /// Close whatever is open over the screen (and a pending quit).
    fn close_overlay(&mut self) -> Option<Command> {
        self.input = None;
        self.show_help = false;
        self.show_failure = false;
        self.redo = None;
        if self.confirm_quit {
            self.confirm_quit = false;
            self.status = "not quitting".into();
        }
        None
    }

    /// Zoom in, out (up to 1024 times) or back to the whole grid.
    fn change_zoom(&mut self, action: Action) -> Option<Command> {
        self.zoom = match action {
            Action::ZoomIn => (self.zoom * 2.0).min(1024.0),
            Action::ZoomOut => (self.zoom / 2.0).max(1.0),
            _ => 1.0,
        };
        if action == Action::ResetView || self.zoom == 1.0 {
            self.pan = [0.0; 2];
        }
        None
    }

    /// Move the view by a fifth of its extent.
    fn move_view(&mut self, action: Action) -> Option<Command> {
        // A fifth of the visible extent of the larger grid side.
        let step = 0.2 * (self.grid.nx.max(self.grid.ny) as f64 * self.grid.h) / self.zoom;
        let (dx, dy) = match action {
            Action::PanLeft => (-step, 0.0),
            Action::PanRight => (step, 0.0),
            Action::PanUp => (0.0, step),
            _ => (0.0, -step),
        };
        self.pan = [self.pan[0] + dx, self.pan[1] + dy];
        None
    }

    /// The next probe column on the probe chart's y or x axis.
    fn next_probe_axis(&mut self, action: Action) -> Option<Command> {
        let n = self.probe_columns().len();
        let axis = if action == Action::NextProbeY {
            &mut self.probe_y
        } else {
            &mut self.probe_x
        };
        *axis = (*axis + 1) % n;
        if !self.probes_start.is_empty() {
            self.chart = ChartKind::Probe;
        }
        None
    }

    /// Quit; while a step runs, only when asked twice.
    fn request_quit(&mut self) -> Option<Command> {
        if (self.busy || self.running) && !self.confirm_quit {
            self.confirm_quit = true;
            self.status = "a step is running: q again quits (the recording is closed), Esc stays".into();
            return None;
        }
        self.quit = true;
        Some(Command::Quit)
    }

    /// Take an update from the engine.
    pub fn update(&mut self, update: Update) {
        match update {
            Update::Progress(p) => self.progress = Some(p),
            Update::Stepped(report, view) => {
                self.busy = false;
                self.progress = None;
                self.failure = None;
                self.show_failure = false;
                let cuts = report.cutbacks().len();
                self.status = if cuts > 0 {
                    format!(
                        "step {} done in {:.3} s after {cuts} {}",
                        report.step,
                        report.timings.total,
                        if report.dynamics.is_some() {
                            "time-step cutback(s): the time step was halved"
                        } else {
                            "load-step cutback(s): the increment was halved"
                        }
                    )
                } else {
                    format!("step {} done in {:.3} s", report.step, report.timings.total)
                };
                if let Some(a) = report.solver.as_ref().and_then(|s| s.attainable) {
                    self.status = format!("{}; {a}", self.status);
                }
                self.reports.push(*report);
                self.view = *view;
            }
            Update::Failed(failure) => {
                self.busy = false;
                self.running = false;
                self.progress = None;
                self.status = failure.to_string();
                if matches!(failure, StepFailure::Cancelled { .. }) {
                    return;
                }
                self.failure = Some(failure);
                self.show_failure = true;
            }
            Update::Redone(outcomes, view) => {
                self.busy = false;
                self.progress = None;
                let (before, after) = &*outcomes;
                // The redone step replaces the one it redid.
                if before.is_ok() {
                    self.reports.pop();
                }
                match after {
                    Ok(r) => {
                        self.status = format!("step {} redone: see the comparison (Esc closes)", r.step);
                        self.reports.push(r.clone());
                        self.failure = None;
                        self.show_failure = false;
                    }
                    Err(f) => {
                        self.status = format!("the redo failed too: {f}");
                        self.failure = Some(f.clone());
                    }
                }
                self.view = *view;
                self.redo = Some(outcomes);
            }
            Update::View(view) => self.view = *view,
            Update::Params(p) => self.params = p,
            Update::Message(m) => self.status = m,
        }
    }
}

/// The command for a typed `name = value`.
pub fn parse_setting(text: &str) -> Result<Command, String> {
    let (name, value) = text
        .split_once('=')
        .ok_or_else(|| format!("`{}`: expected name = value", text.trim()))?;
    let (name, value) = (name.trim(), value.trim());
    let x: f64 = value.parse().map_err(|_| format!("`{value}` is not a number"))?;
    let positive = |x: f64| {
        if x > 0.0 && x.is_finite() {
            Ok(x)
        } else {
            Err(format!("{name} must be positive"))
        }
    };
    match name {
        "gamma_k" | "gamma_K" if x >= 0.0 && x.is_finite() => Ok(Command::SetGammaK(x)),
        "gamma_m" | "gamma_M" if x >= 0.0 && x.is_finite() => Ok(Command::SetGammaM(x)),
        "gamma_k" | "gamma_K" | "gamma_m" | "gamma_M" => Err(format!("{name} must be zero or positive")),
        "delta_over_h" | "delta/h" if x > 0.0 && x <= 1.0 => Ok(Command::SetDeltaOverH(x)),
        "delta_over_h" | "delta/h" => Err("delta/h must lie in (0, 1]".into()),
        "tolerance" if x > 0.0 && x < 1.0 => Ok(Command::SetTolerance(x)),
        "tolerance" => Err("tolerance must lie in (0, 1)".into()),
        "max_iterations" => {
            let n = positive(x)?;
            if n.fract() == 0.0 && n <= 1000.0 {
                Ok(Command::SetMaxIterations(n as usize))
            } else {
                Err("max_iterations must be a whole number up to 1000".into())
            }
        }
        other => Err(format!(
            "unknown parameter `{other}` (gamma_k, gamma_m, delta_over_h, tolerance, max_iterations)"
        )),
    }
}

/// The scale of `gamma_K` shown and stepped from: the stiffest material's
/// Young's modulus (1 Pa when every material is stress-free).
fn modulus(sim: &Simulation) -> f64 {
    let e = sim.model().materials.iter().map(|m| m.elastic.e).fold(0.0, f64::max);
    if e > 0.0 {
        e
    } else {
        1.0
    }
}

/// What the engine sends back.
#[derive(Debug)]
pub enum Update {
    /// The engine's parameters after a change.
    Params(Params),
    Stepped(Box<StepReport>, Box<View>),
    /// A residual of the step being computed.
    Progress(crate::simulation::Progress),
    /// A redo: the outcomes before and after, and the view after.
    Redone(Box<(Outcome, Outcome)>, Box<View>),
    Failed(StepFailure),
    View(Box<View>),
    Message(String),
}
