//! TUI state and actions. No drawing and no terminal here: `draw.rs` renders
//! an [`App`], `mod.rs` feeds it key presses and engine updates.

use crate::field::Field;
use crate::grid::Grid;
use crate::simulation::{Simulation, StepFailure, StepReport};

/// What the canvas shows of the simulation at its latest step.
#[derive(Clone, Debug)]
pub struct View {
    pub step: usize,
    pub load_steps: usize,
    pub load_factor: f64,
    pub positions: Vec<[f64; 2]>,
    /// The colour field at every point.
    pub values: Vec<f64>,
    pub field: Field,
    pub active_cells: Vec<usize>,
    pub boundaries: Vec<BoundaryView>,
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
        View {
            step: sim.step_index(),
            load_steps: sim.load_steps(),
            load_factor: sim.load_factor(),
            positions: sim.points().x.clone(),
            values: field.values(sim),
            field,
            active_cells: sim.active_cells().to_vec(),
            boundaries: BoundaryView::all(sim),
        }
    }
}

/// Something the user asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    Step,
    ToggleHelp,
    ToggleControlPoints,
    CloseOverlay,
    NextField,
    Quit,
}

/// What the app wants the engine to do after an action.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    Step,
    SetField(Field),
    Quit,
}

/// The whole state of the interface.
pub struct App {
    pub scene_name: String,
    pub description: String,
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
    /// A message for the status line (e.g. recording errors).
    pub status: String,
    pub quit: bool,
}

impl App {
    pub fn new(sim: &Simulation, recording: Option<String>) -> App {
        App {
            scene_name: sim.model().name.clone(),
            description: sim.model().description.clone(),
            grid: sim.model().grid.clone(),
            points: sim.points().len(),
            view: View::of(sim, Field::SigmaYy),
            reports: Vec::new(),
            failure: None,
            busy: false,
            show_help: false,
            show_control: false,
            recording,
            status: String::new(),
            quit: false,
        }
    }

    pub fn finished(&self) -> bool {
        self.view.step >= self.view.load_steps
    }

    /// Apply a user action; returns the command for the engine, if any.
    pub fn apply(&mut self, action: Action) -> Option<Command> {
        match action {
            Action::Step => {
                if self.busy {
                    self.status = "a step is running".into();
                    None
                } else if self.failure.is_some() {
                    self.status = "the last step failed; nothing more to do (q quits)".into();
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
            Action::ToggleHelp => {
                self.show_help = !self.show_help;
                None
            }
            Action::ToggleControlPoints => {
                self.show_control = !self.show_control;
                None
            }
            Action::CloseOverlay => {
                self.show_help = false;
                None
            }
            Action::NextField => {
                let k = Field::ALL.iter().position(|f| *f == self.view.field).unwrap_or(0);
                Some(Command::SetField(Field::ALL[(k + 1) % Field::ALL.len()]))
            }
            Action::Quit => {
                self.quit = true;
                Some(Command::Quit)
            }
        }
    }

    /// Take an update from the engine.
    pub fn update(&mut self, update: Update) {
        match update {
            Update::Stepped(report, view) => {
                self.busy = false;
                self.status = format!("step {} done in {:.3} s", report.step, report.timings.total);
                self.reports.push(*report);
                self.view = *view;
            }
            Update::Failed(failure) => {
                self.busy = false;
                self.status = failure.to_string();
                self.failure = Some(failure);
            }
            Update::View(view) => self.view = *view,
            Update::Message(m) => self.status = m,
        }
    }
}

/// What the engine sends back.
#[derive(Debug)]
pub enum Update {
    Stepped(Box<StepReport>, Box<View>),
    Failed(StepFailure),
    View(Box<View>),
    Message(String),
}
