//! rerun recordings of a run: one `.rrd` file per run.
//!
//! Timelines: `step` (load step), `iteration` (a global counter over
//! every residual evaluation of the run) and, for explicit dynamics, `time`
//! (simulated seconds). Entities:
//!
//! | entity | archetype | when |
//! |---|---|---|
//! | `scene` | TextDocument (the scene file) | static |
//! | `grid` | LineStrips2D | static |
//! | `recording` | TextDocument (the cadence and the per-point fields) | static |
//! | `recording/fields` | TextLog (the per-point fields, comma-separated) | static |
//! | `grid/active` | LineStrips2D (outlines of the cells the next step solves on: those the points shown reach, or with `update_points = false` those of the starting configuration) | frames |
//! | `grid/occupied` | LineStrips2D (the cells holding the points shown, drawn inset) | frames |
//! | `points` | Points2D, coloured by sigma_yy, radius from volume; and per point the values of the recorded fields (of `sigma_xx`, `sigma_yy`, `sigma_xy`, `displacement_magnitude`, `plastic_strain`, `speed`, `error`) | frames |
//! | `legend/colour_bar` | LineStrips2D (the colour map under the grid, low values left: diverging for a stress, viridis for a magnitude) | static |
//! | `legend/range` | Points2D (a label: the colour field, its unit, the colours' range and the frame's values) | frames |
//! | `legend/ticks` | Points2D (five labelled ticks under the bar) | frames |
//! | `grid/conditions/<k>` | LineStrips2D (grid-line conditions, labelled with kind and value) | static |
//! | `loads/gravity`, `loads/point/<k>` | Arrows2D (gravity, point loads; labelled) | static, frames |
//! | `probes` | Points2D (the probes' positions, labelled) | frames |
//! | `points`, `grid`, `boundaries`, `ibm`, `legend` | Transform3D (y scaled by -1: drawn with y up, [`layout`]) | static |
//! | `ibm/<name>/line` | LineStrips2D (implicit Dirichlet boundaries, cyan, labelled) | frames |
//! | `ibm/<name>/cut_cells` | LineStrips2D (cells the boundary cuts) | frames |
//! | `metrics/ibm/<name>/{reaction_x,reaction_y,violation,violation_rms,cut_cells}` | Scalars | every step |
//! | `grid/ghost_faces` | LineStrips2D (faces carrying ghost stabilisation) | frames |
//! | `metrics/condition/stiffness_unstabilised` | Scalars (with ghost on: the tangent without it) | every step |
//! | `metrics/newton/iterations`, `metrics/ghost/faces`, `metrics/energy/plastic_dissipation` | Scalars | every step |
//! | `boundaries/<name>/curve` | LineStrips2D (red, thick, labelled `(traction)`: carries a traction) | frames |
//! | `boundaries/<name>/control_points` | Points2D (Bezier control points) | frames |
//! | `metrics/boundary/<name>/{length,area,cells_cut,resultant_x,resultant_y}` | Scalars | every step |
//! | `metrics/residual` | Scalars, on `iteration` | every iteration |
//! | `metrics/newton/residual_history` | BarChart (log10 of the step's residuals against their iteration) | every step |
//! | `metrics/condition/stiffness` | Scalars | every step |
//! | `metrics/log10/residual`, `metrics/log10/condition/stiffness` | Scalars | as above |
//! | `metrics/energy/strain`, `metrics/energy/external_work` | Scalars | every step |
//! | `metrics/energy/ghost` | Scalars (quasi-static: the work the ghost stiffness penalty took up so far, [`crate::report::Energy::ghost`]) | every step |
//! | `metrics/energy/balance_error` | Scalars (quasi-static: strain + plastic - external work) | every step |
//! | `metrics/error/<measure>`, `metrics/log10/error/<measure>` | Scalars | every step with an exact solution |
//! | `metrics/probe/<name>/{ux,uy,sxx,syy,sxy,fx,fy}` | Scalars (the scene's `[[probe]]`s, [`crate::probe`]) | every step |
//! | `metrics/time/<phase>` | Scalars (s) | every step |
//! | `metrics/unknowns` | Scalars | every step |
//! | `metrics/energy/{kinetic,kinetic_grid,total,balance_error,balance_error_relative}` | Scalars (dynamics, balance `W_kin + W_eps + W_p - W_ext - W_0`; also on `time`) | every step |
//! | `metrics/momentum/{x,y}`, `metrics/dynamics/max_grid_speed` | Scalars (dynamics) | every step |
//! | `metrics/condition/mass_{consistent,stabilised,lumped}`, `metrics/cfl/{consistent,stabilised,lumped}` | Scalars (dynamics) | every `condition_every` steps |
//! | `events` | TextLog (start, parameter changes, failures, end), each on the `step` it belongs to and numbered on the `event` timeline (several at one step stay apart) | as they happen |
//!
//! "Frames" are the steps the cadence picks ([`crate::model::record`]:
//! scene `[record]`, or the command line's `--record-every`,
//! `--record-dt`, `--record-fields`), plus the initial state, the last
//! step, the state before a failed step and the state a run stops on; at
//! cadence 1 with every field a recording holds what it held before
//! cadences existed. The step timeline shows which steps hold points (the
//! `points` entity is logged at those steps only).
//!
//! The file also holds a blueprint (rerun's stored layout, [`layout`]) so
//! the viewer opens on the scene with the panels the run has beside it,
//! and static `SeriesLines` (and, in runs of at most
//! [`layout::MARKED_STEPS`] steps, `SeriesPoints`) naming and colouring
//! the series. The recording is listed under its scene and run
//! ([`recording_name`]).
//!
//! The file is flushed after every step while a flush's fixed cost is at
//! most [`SYNC_SHARE`] of the time since the last one, and at the latest once [`SYNC_PERIOD`]
//! (or `--record-sync`) has passed, so a killed run leaves every step up
//! to the last flush; [`repair`] writes the footer rerun adds at close.
//!
//! The engine knows nothing of this module: it reads reports and state.

mod drawing;
pub mod layout;
mod legend;
pub mod repair;
mod sink;
pub mod sweep;

use crate::colormap;
use crate::field::Field;
use crate::format::human_bytes;
use crate::model::record::{Plan, RecordSettings};
use crate::simulation::{Simulation, StepFailure, StepReport};
use layout::{order, titled, Contents, Quantity};
use legend::{colours_of, ColourBar, Recolour};
use rerun::{RecordingStream, RecordingStreamBuilder};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, Receiver, SyncSender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// Why a recording could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("cannot write recording {path}: {message}")]
    Create { path: PathBuf, message: String },
    #[error("recording {path}: {message}")]
    Write { path: PathBuf, message: String },
}

/// Outline of cell `c` as a closed strip.
fn cell_box(g: &crate::grid::Grid, c: usize) -> [[f32; 2]; 5] {
    let m = g.cell_min(c % g.nx, c / g.nx);
    let (x0, y0, x1, y1) = (m[0] as f32, m[1] as f32, (m[0] + g.h) as f32, (m[1] + g.h) as f32);
    [[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]
}

/// Where a point at `x` that started at `x0` is drawn at deformation scale
/// `s`: `x0 + s (x - x0)` (`x` itself at `s = 1`).
fn drawn_at(x0: [f64; 2], x: [f64; 2], s: f64) -> [f32; 2] {
    if s == 1.0 {
        [x[0] as f32, x[1] as f32]
    } else {
        [(x0[0] + s * (x[0] - x0[0])) as f32, (x0[1] + s * (x[1] - x0[1])) as f32]
    }
}

/// Cell `c` drawn a sixth of a cell inside its grid lines.
fn inset_box(g: &crate::grid::Grid, c: usize) -> [[f32; 2]; 5] {
    let m = g.cell_min(c % g.nx, c / g.nx);
    let d = g.h / 6.0;
    let (x0, y0) = ((m[0] + d) as f32, (m[1] + d) as f32);
    let (x1, y1) = ((m[0] + g.h - d) as f32, (m[1] + g.h - d) as f32);
    [[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]
}

/// The bulky part of a point frame: copied from the simulation on the
/// engine's thread into reused buffers (plain copies, no rerun types) and
/// turned into rerun data on the recorder's own thread, so that a step
/// waits for the copies only.
#[derive(Default)]
struct Frame {
    step: i64,
    time: Option<f64>,
    positions: Vec<[f32; 2]>,
    radii: Vec<f32>,
    /// The values the points are coloured by, the scale they are
    /// coloured with and what the frame's values are, in words.
    colour: Vec<f64>,
    scale: colormap::Scale,
    described: String,
    /// The recorded fields' values per point.
    fields: Vec<(&'static str, Vec<f64>)>,
    /// The cells the next step solves on: those the points' bases reach
    /// in the configuration it starts from.
    cells: Vec<usize>,
    ghost: Vec<[[f32; 2]; 2]>,
}

impl Frame {
    /// Copy the state of `sim`: positions drawn at `x0 + s u` with the
    /// deformation scale `s` (1: where the points are).
    fn fill(&mut self, sim: &Simulation, colour: Field, fields: &[Field], s: f64) {
        self.step = sim.step_index() as i64;
        self.time = sim.time();
        let pts = sim.points();
        self.positions.clear();
        self.positions
            .extend(pts.x.iter().zip(&pts.x0).map(|(&x, &x0)| drawn_at(x0, x, s)));
        self.radii.clear();
        self.radii
            .extend(pts.vol.iter().map(|v| (0.5 * v.max(0.0).sqrt()) as f32));
        self.colour = colour.values(sim);
        self.fields.clear();
        self.fields.extend(fields.iter().map(|f| {
            let v = if *f == colour {
                self.colour.clone()
            } else {
                f.values(sim)
            };
            (f.key(), v)
        }));
        self.cells = sim.cells_of_next_step();
        self.ghost.clear();
        self.ghost.extend(
            sim.ghost_faces()
                .iter()
                .map(|(a, b)| [[a[0] as f32, a[1] as f32], [b[0] as f32, b[1] as f32]]),
        );
    }
}

/// What the recorder's thread is asked to do.
enum Job {
    /// Log a frame (its buffers come back on `spare`).
    Frame(Frame),
    /// Flush everything logged so far into the file (the frames before it
    /// and whatever the engine's thread logged before sending it), then
    /// answer with the error, if any, and the time the flush itself took
    /// (the frames' logging excluded).
    Flush(SyncSender<(Option<String>, std::time::Duration)>),
}

/// The recorder's thread: logs the frames it is sent, returns their
/// buffers, flushes when asked, and keeps the first error for the engine's
/// side to report.
struct FrameWriter {
    frames: Option<SyncSender<Job>>,
    spare: Receiver<Frame>,
    thread: Option<JoinHandle<()>>,
    error: Arc<Mutex<Option<String>>>,
    /// A flush did not answer within [`SYNC_LIMIT`].
    stalled: std::sync::atomic::AtomicBool,
}

/// The longest the engine's side waits for a flush of the recording: a
/// disk that takes nothing for this long ends the run (with the reason)
/// instead of hanging it.
const SYNC_LIMIT: std::time::Duration = std::time::Duration::from_secs(60);

impl FrameWriter {
    fn start(rec: RecordingStream, grid: crate::grid::Grid, legend: ColourBar) -> FrameWriter {
        // Two frames in flight at most: a slow disk slows the run down
        // instead of filling the memory.
        let (tx, rx) = mpsc::sync_channel::<Job>(1);
        let (spare_tx, spare) = mpsc::channel();
        let error = Arc::new(Mutex::new(None));
        let err = error.clone();
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || {
                let mut colors = Vec::new();
                let keep = |e: String| {
                    if let Ok(mut slot) = err.lock() {
                        slot.get_or_insert(e);
                    }
                };
                for job in rx {
                    let failed = err.lock().map_or(true, |e| e.is_some());
                    match job {
                        Job::Frame(f) => {
                            if !failed {
                                if let Err(e) = write_frame(&rec, &grid, &legend, &f, &mut colors) {
                                    keep(e.to_string());
                                }
                            }
                            let _ = spare_tx.send(f);
                        }
                        Job::Flush(done) => {
                            let t = std::time::Instant::now();
                            if !failed {
                                if let Err(e) = rec.flush_blocking() {
                                    keep(e.to_string());
                                }
                            }
                            let _ = done.send((err.lock().ok().and_then(|e| e.clone()), t.elapsed()));
                        }
                    }
                }
            })
            .ok();
        FrameWriter {
            frames: Some(tx),
            spare,
            thread,
            error,
            stalled: std::sync::atomic::AtomicBool::new(false),
        }
    }

    fn error(&self) -> Option<String> {
        self.error.lock().ok().and_then(|e| e.clone())
    }

    /// Wait until every frame sent and everything logged before this call
    /// is written to the file (handed to the operating system: it survives
    /// the process being killed). The error, if any, and the time the
    /// flush itself took (waiting for frames not counted).
    fn sync(&self) -> (Option<String>, std::time::Duration) {
        let zero = std::time::Duration::ZERO;
        let Some(tx) = &self.frames else {
            return (self.error(), zero);
        };
        let stopped = || Some(self.error().unwrap_or_else(|| "the recorder's thread stopped".into()));
        let (done, answer) = mpsc::sync_channel(1);
        if tx.send(Job::Flush(done)).is_err() {
            return (stopped(), zero);
        }
        match answer.recv_timeout(SYNC_LIMIT) {
            Ok(a) => a,
            Err(mpsc::RecvTimeoutError::Timeout) => {
                // A stalled disk: the run ends with the reason instead of
                // waiting on; the thread is not waited for again.
                self.stalled.store(true, std::sync::atomic::Ordering::SeqCst);
                (
                    Some(format!(
                        "the recording's file took no data for {} s (a stalled or unreachable disk?)",
                        SYNC_LIMIT.as_secs()
                    )),
                    SYNC_LIMIT,
                )
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => (stopped(), zero),
        }
    }

    /// Wait for every frame sent to be logged.
    fn join(&mut self) -> Option<String> {
        self.frames = None;
        if self.stalled.load(std::sync::atomic::Ordering::SeqCst) {
            return Some(self.error().unwrap_or_else(|| "the recording's file stalled".into()));
        }
        if let Some(t) = self.thread.take() {
            if t.join().is_err() {
                return Some("the recorder's thread panicked".into());
            }
        }
        self.error()
    }
}

/// Log one frame: the points with colours, radii and the recorded fields,
/// the colour bar's range, the active and occupied cells and the ghost
/// faces.
fn write_frame(
    rec: &RecordingStream,
    g: &crate::grid::Grid,
    legend: &ColourBar,
    f: &Frame,
    colors: &mut Vec<rerun::Color>,
) -> Result<(), rerun::RecordingStreamError> {
    rec.set_time_sequence("step", f.step);
    if let Some(t) = f.time {
        rec.set_duration_secs("time", t);
    }
    colours_of(&f.scale, &f.colour, colors);
    rec.log(
        "points",
        &rerun::Points2D::new(f.positions.iter().copied())
            .with_colors(colors.iter().copied())
            .with_radii(f.radii.iter().copied())
            .with_draw_order(order::POINTS),
    )?;
    // The recorded fields' values per point, shown when a point is hovered.
    if !f.fields.is_empty() {
        let mut values = rerun::external::re_sdk_types::AnyValues::default();
        for (key, v) in &f.fields {
            values = values.with_component::<rerun::components::Scalar>(*key, v.iter().copied());
        }
        rec.log("points", &values)?;
    }
    rec.log(
        "legend/range",
        &legend.range(&f.scale, &f.described, f.scale.beyond(&f.colour)),
    )?;
    rec.log("legend/ticks", &legend.ticks(&f.scale))?;
    // The cells holding the points shown, drawn inset (squares inside the
    // grid's lines, not lines on them); the active cells are the mesh the
    // next step solves on, from the points as they are now.
    let mut occupied: Vec<usize> = f
        .positions
        .iter()
        .filter_map(|p| {
            let i = ((p[0] as f64 - g.origin[0]) / g.h).floor();
            let j = ((p[1] as f64 - g.origin[1]) / g.h).floor();
            (i >= 0.0 && j >= 0.0 && (i as usize) < g.nx && (j as usize) < g.ny).then(|| j as usize * g.nx + i as usize)
        })
        .collect();
    occupied.sort_unstable();
    occupied.dedup();
    rec.log(
        "grid/occupied",
        &rerun::LineStrips2D::new(occupied.iter().map(|&c| inset_box(g, c)))
            .with_colors([rerun::Color::from_rgb(150, 120, 190)])
            .with_radii([rerun::Radius::new_ui_points(0.75)])
            .with_draw_order(order::OCCUPIED),
    )?;
    rec.log(
        "grid/active",
        &rerun::LineStrips2D::new(f.cells.iter().map(|&c| cell_box(g, c)))
            .with_colors([rerun::Color::from_rgb(60, 120, 200)])
            .with_radii([rerun::Radius::new_ui_points(1.0)])
            .with_draw_order(order::ACTIVE),
    )?;
    rec.log(
        "grid/ghost_faces",
        &rerun::LineStrips2D::new(f.ghost.iter().copied())
            .with_colors([rerun::Color::from_rgb(240, 140, 20)])
            .with_radii([rerun::Radius::new_ui_points(0.75)])
            .with_draw_order(order::GHOST_FACES),
    )?;
    rec.reset_time();
    Ok(())
}

/// What a finished recording holds and its size.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordingSize {
    pub bytes: u64,
    /// Steps with metrics (the initial state not counted).
    pub steps: usize,
    /// Steps holding points (the initial state counted).
    pub frames: usize,
    pub points: usize,
}

impl RecordingSize {
    pub fn bytes_per_step(&self) -> f64 {
        self.bytes as f64 / self.steps.max(1) as f64
    }

    /// Bytes per point per step holding points (metrics included).
    pub fn bytes_per_point_frame(&self) -> f64 {
        self.bytes as f64 / (self.frames.max(1) * self.points.max(1)) as f64
    }
}

impl std::fmt::Display for RecordingSize {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}, {} steps ({}/step), points at {} of them ({:.1} B per point per frame)",
            human_bytes(self.bytes as f64),
            self.steps,
            human_bytes(self.bytes_per_step()),
            self.frames,
            self.bytes_per_point_frame()
        )
    }
}

/// The name a recording is listed under in the viewer: its file's stem
/// (which the TUI and sweeps make from the scene and the run), with the
/// scene's name in front when the stem does not hold it.
pub fn recording_name(scene: &str, path: &Path) -> String {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    if stem.is_empty() {
        scene.to_string()
    } else if stem.contains(scene) {
        stem
    } else {
        format!("{scene}: {stem}")
    }
}

/// What the run will record, from its model: it decides the layout.
fn contents(sim: &Simulation, colour: Field) -> Contents {
    use crate::scene::{ConditionMode, MassKind};
    let m = sim.model();
    let a = &m.analysis;
    let dynamic = a.kind.is_dynamic();
    Contents {
        dynamic,
        newton: a.kind.is_newton(),
        condition: a.condition != ConditionMode::Off && (!dynamic || a.condition_every > 0),
        ghost: if dynamic {
            a.mass == MassKind::Stabilised
        } else {
            a.gamma_k > 0.0
        },
        exact: m.exact.is_some(),
        colour: titled(colour.key(), m.units, Quantity::Field(colour)),
        units: m.units,
        probes: probe_panels(sim),
    }
}

/// The probes' series, one panel per unit, in the order displacements,
/// velocities, stresses, forces.
fn probe_panels(sim: &Simulation) -> Vec<layout::ProbePanel> {
    use crate::units::Quantity as Q;
    let units = sim.model().units;
    let mut panels: Vec<(Q, &str, Vec<String>)> = vec![
        (Q::Length, "probes: displacements", Vec::new()),
        (Q::Velocity, "probes: velocities", Vec::new()),
        (Q::Stress, "probes: stresses", Vec::new()),
        (Q::Force, "probes: forces", Vec::new()),
    ];
    for p in sim.probe_values(None) {
        for (key, q, _) in p.columns() {
            if let Some(panel) = panels.iter_mut().find(|x| x.0 == q) {
                panel.2.push(format!("metrics/probe/{}/{key}", p.name));
            }
        }
    }
    panels
        .into_iter()
        .filter(|p| !p.2.is_empty())
        .map(|(q, title, paths)| layout::ProbePanel {
            title: format!("{title} ({})", units.of(q)),
            paths,
        })
        .collect()
}

/// Writes one run to an `.rrd` file.
pub struct Recorder {
    rec: RecordingStream,
    /// The file the stream writes, closed by [`Recorder::finish`].
    sink: Arc<sink::Shared>,
    /// The recording's path as given; it is written as `staged`'s
    /// `.partial` file until [`Recorder::finish`].
    path: PathBuf,
    staged: Option<crate::output::Staged>,
    iteration: i64,
    field: Field,
    settings: RecordSettings,
    plan: Plan,
    writer: FrameWriter,
    /// The step of the last frame sent (points are sent once per step).
    last_frame: Option<i64>,
    points: usize,
    frames: std::collections::BTreeSet<i64>,
    steps: std::collections::BTreeSet<i64>,
    /// Whether the error series have their names and colours (logged at
    /// the first step with errors, when their names are known).
    error_styles: bool,
    /// Mark every value of a series (short runs).
    marked: bool,
    /// The step the next event belongs to, and the events logged so far:
    /// events carry both (the `event` timeline keeps several events of one
    /// step apart; rerun's times are per thread, and the TUI logs from
    /// another thread than the one that created the recorder).
    step_now: std::cell::Cell<i64>,
    events: std::cell::Cell<i64>,
    /// The longest wall time between flushes into the file
    /// ([`Recorder::sync`]) and the last one.
    sync_period: std::time::Duration,
    last_sync: std::time::Instant,
    /// The shortest flush so far (its fixed cost; `None` before the
    /// first): a step is flushed sooner than the period once that cost is
    /// at most [`SYNC_SHARE`] of the time since the last flush.
    sync_cost: Option<std::time::Duration>,
    /// The colour bar, and with `colour_range = "run"` the run's colour
    /// scale so far and the frames to colour again with the final one.
    legend: ColourBar,
    scale: Option<colormap::Scale>,
    recolour: Vec<Recolour>,
    /// Values kept in `recolour`, and the first frame not kept (over
    /// the budget, `legend::RECOLOUR_BUDGET`).
    recolour_values: usize,
    recolour_from: Option<i64>,
    /// Small strain: the deformation scale the points are drawn with,
    /// once known.
    deformation: Option<f64>,
    /// The scene's unit system (events' units).
    units: crate::units::Units,
}

/// The default longest time between flushes of a recording into its file:
/// a killed run loses at most the steps of the last half second (and every
/// step that took longer is in the file before the run reports it).
pub const SYNC_PERIOD: std::time::Duration = std::time::Duration::from_millis(500);

/// The share of a run's wall time its recording may spend flushing after
/// steps that the period does not yet require: within it, every step is
/// flushed. A flush costs about 3 ms and, in the file, a chunk per entity
/// (rerun cuts its batches there), so runs of steps longer than about 60 ms
/// flush every step, and faster ones (explicit dynamics) every 60 ms or so.
pub const SYNC_SHARE: f64 = 0.05;

/// Whether a step ending `since` after the last flush is flushed, with the
/// longest period `period` and a flush's fixed cost `cost` (`None`: not yet
/// measured, so the first step is flushed): see [`SYNC_SHARE`].
fn flush_due(since: std::time::Duration, period: std::time::Duration, cost: Option<std::time::Duration>) -> bool {
    since >= period || cost.is_none_or(|c| c.as_secs_f64() <= SYNC_SHARE * since.as_secs_f64())
}

/// The rerun version the recordings are written with; viewers read their
/// own and the previous minor version only.
pub const RERUN_VERSION: &str = "0.36.3";

/// Application id under which mpmlab recordings appear in the viewer.
pub const APP_ID: &str = "mpmlab";

impl Recorder {
    /// Create the file and log the static parts (scene text, grid) and the
    /// initial state, with the scene's `[record]` settings. With
    /// `deterministic`, the recording id is fixed and no wall-clock
    /// timeline is added (for tests).
    pub fn create(
        path: &Path,
        scene_text: &str,
        sim: &Simulation,
        deterministic: bool,
    ) -> Result<Recorder, RecordError> {
        Self::create_with(path, scene_text, sim, deterministic, sim.model().record.clone(), false)
    }

    /// [`Recorder::create`] with other settings (the command line's);
    /// `force` replaces a `.partial` file an earlier run left
    /// ([`crate::output::Staged::claim`]).
    pub fn create_with(
        path: &Path,
        scene_text: &str,
        sim: &Simulation,
        deterministic: bool,
        settings: RecordSettings,
        force: bool,
    ) -> Result<Recorder, RecordError> {
        let err = |m: String| RecordError::Create {
            path: path.to_path_buf(),
            message: m,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            if !dir.is_dir() {
                return Err(err(format!("directory {} does not exist", dir.display())));
            }
        }
        // The file is written as `NAME.partial` (locked: one run at a
        // time) and renamed to `NAME` by `finish`: a run that never gets
        // there leaves the file it would replace as it was.
        let staged = crate::output::Staged::claim(path, force).map_err(err)?;
        let partial = staged.partial().to_path_buf();
        // Metrics arrive a few dozen scalars a step: batched over a second
        // (rerun's default for files is 200 ms), a chunk holds many steps
        // instead of one, which keeps the per-chunk overhead (about a
        // kilobyte) from dominating a long run's file. At most 16 MiB
        // (a few point frames of a large run) wait in the batcher.
        let batching = rerun::log::ChunkBatcherConfig {
            flush_tick: std::time::Duration::from_secs(1),
            flush_num_bytes: 16 * 1024 * 1024,
            ..rerun::log::ChunkBatcherConfig::DEFAULT
        };
        let name = recording_name(&sim.model().name, path);
        let mut builder = RecordingStreamBuilder::new(APP_ID)
            .batcher_config(batching)
            .recording_name(name.clone());
        if deterministic {
            builder = builder.recording_id("mpmlab-test");
        }
        // rerun's own file sink hangs a flush after a write error: ours
        // returns it ([`sink`]).
        let shared = match sink::Shared::create(&partial) {
            Ok(s) => s,
            Err(e) => {
                staged.discard();
                return Err(err(e));
            }
        };
        let sinks: Vec<Box<dyn rerun::sink::LogSink>> = vec![Box::new(sink::Sink(shared.clone()))];
        let rec = match builder.set_sinks(sinks) {
            Ok(rec) => rec,
            Err(e) => {
                staged.discard();
                return Err(err(e.to_string()));
            }
        };
        if deterministic {
            rec.set_log_time_enabled(false);
            // A fixed recording id leaves out rerun's properties chunk, and
            // the name with it.
            rec.send_recording_name(name).map_err(|e| err(e.to_string()))?;
        }
        let a = &sim.model().analysis;
        let step_dt = a.duration.map(|d| d / a.load_steps as f64);
        let plan = Plan::new(settings.cadence, sim.load_steps(), sim.points().len(), step_dt);
        let colour = Field::SigmaYy;
        let legend = ColourBar::new(
            &sim.model().grid,
            titled(colour.key(), sim.model().units, Quantity::Field(colour)),
        );
        let writer = FrameWriter::start(rec.clone(), sim.model().grid.clone(), legend.clone());
        let mut r = Recorder {
            rec,
            sink: shared,
            path: path.to_path_buf(),
            staged: Some(staged),
            iteration: 0,
            field: colour,
            settings,
            plan,
            writer,
            last_frame: None,
            points: sim.points().len(),
            frames: Default::default(),
            steps: Default::default(),
            error_styles: false,
            marked: sim.load_steps() <= layout::MARKED_STEPS,
            step_now: std::cell::Cell::new(sim.step_index() as i64),
            events: std::cell::Cell::new(0),
            sync_period: SYNC_PERIOD,
            last_sync: std::time::Instant::now(),
            sync_cost: None,
            legend: legend.clone(),
            scale: None,
            recolour: Vec::new(),
            recolour_values: 0,
            recolour_from: None,
            deformation: None,
            units: sim.model().units,
        };
        // A recording that cannot take its header and first state (a
        // full disk already) is removed: the run has not started.
        let opened = (|| {
            let contents = contents(sim, colour);
            r.check(
                contents
                    .blueprint()
                    .send(&r.rec, rerun::blueprint::BlueprintActivation::default()),
            )?;
            r.log_styles(&contents)?;
            r.log_static(scene_text, sim, &legend)?;
            r.log_state(sim)?;
            r.event(
                &format!(
                    "start: scene `{}`, {} points, {} load steps; points recorded {}",
                    sim.model().name,
                    sim.points().len(),
                    sim.load_steps(),
                    r.cadence()
                ),
                rerun::TextLogLevel::INFO,
            )?;
            r.sync()?;
            Ok(())
        })();
        if let Err(e) = opened {
            r.discard();
            return Err(e);
        }
        Ok(r)
    }

    /// The temporary file the recording is written to until it is
    /// finished.
    fn partial(&self) -> Option<&Path> {
        self.staged.as_ref().map(|s| s.partial())
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The cadence and fields in words (`every 3 steps; fields sigma_yy`).
    pub fn cadence(&self) -> String {
        let fields: Vec<&str> = self.settings.fields.iter().map(|f| f.key()).collect();
        format!(
            "{} and at the first and last step; fields: positions{}{}",
            self.plan.describe(),
            if fields.is_empty() { "" } else { ", " },
            fields.join(", ")
        )
    }

    /// The points' cadence in words (`every 3 steps`).
    pub fn points_cadence(&self) -> String {
        self.plan.describe()
    }

    /// Whether step `k` holds points under the cadence.
    pub fn holds_points(&self, k: usize) -> bool {
        self.plan.holds_points(k)
    }

    fn check<T, E: std::fmt::Display>(&self, r: Result<T, E>) -> Result<T, RecordError> {
        r.map_err(|e| RecordError::Write {
            path: self.path.clone(),
            message: e.to_string(),
        })
    }

    /// Names and colours of the time series (static), with markers on
    /// every value in short runs.
    fn log_styles_of(&self, series: &[layout::Series]) -> Result<(), RecordError> {
        for s in series {
            let [r, g, b] = s.color;
            let color = rerun::Color::from_rgb(r, g, b);
            self.check(
                self.rec.log_static(
                    s.path.as_str(),
                    &rerun::SeriesLines::new()
                        .with_names([s.name.as_str()])
                        .with_colors([color])
                        .with_widths([1.5]),
                ),
            )?;
            if self.marked || s.marked {
                self.check(
                    self.rec.log_static(
                        s.path.as_str(),
                        &rerun::SeriesPoints::new()
                            .with_names([s.name.as_str()])
                            .with_colors([color])
                            .with_marker_sizes([2.5]),
                    ),
                )?;
            }
        }
        Ok(())
    }

    /// The series' styles and the scene's orientation (y up).
    fn log_styles(&self, contents: &Contents) -> Result<(), RecordError> {
        self.log_styles_of(&contents.series())?;
        for root in layout::SCENE_ROOTS {
            self.check(self.rec.log_static(root, &layout::y_up()))?;
        }
        Ok(())
    }

    fn log_static(&self, scene_text: &str, sim: &Simulation, legend: &ColourBar) -> Result<(), RecordError> {
        let doc = format!("```toml\n{scene_text}\n```");
        self.check(self.rec.log_static(
            "scene",
            &rerun::TextDocument::new(doc).with_media_type(rerun::MediaType::markdown()),
        ))?;
        // What the recording holds: the cadence and the per-point fields.
        let fields: Vec<&str> = self.settings.fields.iter().map(|f| f.key()).collect();
        self.check(self.rec.log_static(
            "recording",
            &rerun::TextDocument::new(format!(
                "Points (positions, colours by {}, radii) {}.\n\nPer-point fields: {}.\n\nMetrics and events: every step.\n\n\
                 The scene is drawn with y up: each of its entities is flipped by a static transform, so a \
                 point's `positions` are its true coordinates while the view's hover position has y negated.\n\n\
                 At a step, `grid/active` (blue) are the cells the next step solves on: those the bases of \
                 the points shown reach (with `update_points = false`, those of the starting configuration); \
                 `grid/occupied` (violet squares inside the grid lines) are the cells holding the points \
                 shown (a small-strain drawing at a deformation scale other than 1 shows the points, and \
                 these, scaled, while the active cells stay those of the true configuration); the ghost faces (thin, orange, under the points) are those of the step's own mesh. \
                 A point's radius is half the square root of its volume (its side were it a square: 0.5 \
                 sqrt(V)). Colours: a stress component on a diverging map (blue negative, grey zero, red \
                 positive) over a range symmetric about zero; a magnitude on viridis from zero; by default \
                 one range over the run (`[record] colour_range`).",
                self.field.key(),
                self.cadence(),
                if fields.is_empty() { "none".to_string() } else { fields.join(", ") }
            )),
        ))?;
        self.check(
            self.rec
                .log_static("recording/fields", &rerun::TextLog::new(fields.join(","))),
        )?;
        let g = &sim.model().grid;
        let max = g.max();
        let mut strips = Vec::new();
        for i in 0..=g.nx {
            let x = (g.origin[0] + i as f64 * g.h) as f32;
            strips.push(vec![[x, g.origin[1] as f32], [x, max[1] as f32]]);
        }
        for j in 0..=g.ny {
            let y = (g.origin[1] + j as f64 * g.h) as f32;
            strips.push(vec![[g.origin[0] as f32, y], [max[0] as f32, y]]);
        }
        self.check(
            self.rec.log_static(
                "grid",
                &rerun::LineStrips2D::new(strips)
                    .with_colors([rerun::Color::from_rgb(90, 90, 90)])
                    .with_radii([rerun::Radius::new_ui_points(0.5)])
                    .with_draw_order(order::GRID),
            ),
        )?;
        self.check(
            self.rec
                .log_static("legend/colour_bar", &legend.bar(self.field.signed())),
        )?;
        self.log_conditions(sim)
    }

    /// Log the points (with the recorded fields), the active cells and the
    /// boundaries at the simulation's current step, whatever the cadence
    /// (once per step: a second call at the same step does nothing).
    pub fn log_state(&mut self, sim: &Simulation) -> Result<(), RecordError> {
        if let Some(e) = self.writer.error() {
            return Err(RecordError::Write {
                path: self.path.clone(),
                message: e,
            });
        }
        let step = sim.step_index() as i64;
        if self.last_frame == Some(step) {
            return Ok(());
        }
        self.last_frame = Some(step);
        self.frames.insert(step);
        let mut frame = self.writer.spare.try_recv().unwrap_or_default();
        let drawn = self.deformation_scale(sim)?;
        frame.fill(sim, self.field, &self.settings.fields, drawn);
        self.scale_frame(&mut frame, drawn);
        if let Some(tx) = &self.writer.frames {
            if tx.send(Job::Frame(frame)).is_err() {
                return Err(RecordError::Write {
                    path: self.path.clone(),
                    message: self
                        .writer
                        .error()
                        .unwrap_or_else(|| "the recorder's thread stopped".into()),
                });
            }
        }
        self.rec.set_time_sequence("step", step);
        self.step_now.set(step);
        if let Some(t) = sim.time() {
            self.rec.set_duration_secs("time", t);
        }
        self.log_loads_and_probes(sim, drawn)?;
        self.log_boundaries(sim, drawn)
    }

    /// Log the current state if the cadence left it out: the last state
    /// of a run that stops early or fails.
    pub fn log_final_state(&mut self, sim: &Simulation) -> Result<(), RecordError> {
        self.log_state(sim)
    }

    fn scalar(&self, path: &str, v: f64) -> Result<(), RecordError> {
        if v.is_finite() {
            self.check(self.rec.log(path, &rerun::Scalars::single(v)))?;
        }
        Ok(())
    }

    /// A condition number `metrics/condition/<name>` (and its log10): a
    /// number up to `1/eps`; past it (or infinite) the matrix is singular
    /// to working precision, which an event says instead of a number.
    fn condition(&self, step: usize, name: &str, what: &str, value: f64) -> Result<(), RecordError> {
        if value.is_finite() && value <= 1.0 / f64::EPSILON {
            self.scalar(&format!("metrics/condition/{name}"), value)?;
            self.scalar(&format!("metrics/log10/condition/{name}"), value.log10())
        } else {
            self.event(
                &format!(
                    "step {step}: {what} is singular to working precision (condition estimate {value:.2e} > 1/eps = {:.2e})",
                    1.0 / f64::EPSILON
                ),
                "WARN",
            )
        }
    }

    /// The step's warnings as events on the timeline: traction lost on
    /// inactive nodes, a regularised implicit-boundary fit (cutbacks and
    /// a stop at the round-off floor are logged with the solver's metrics).
    fn log_warnings(&self, report: &StepReport) -> Result<(), RecordError> {
        let force = self.units.of(crate::units::Quantity::Force);
        // Round-off (1e-16 of the load) is not a loss.
        let lost = |b: &&crate::boundary::BoundaryReport| b.lost > 1e-9 * b.resultant[0].hypot(b.resultant[1]);
        for b in report.boundaries.iter().filter(lost) {
            self.event(
                &format!(
                    "step {}: boundary `{}` LOST {:.3e} {force} of its traction on inactive nodes",
                    report.step, b.name, b.lost
                ),
                "WARN",
            )?;
        }
        for b in report.ibm.iter().filter(|b| b.fit_regularisation > 0.0) {
            self.event(
                &format!(
                    "step {}: implicit boundary `{}`: the exact field's fit was regularised (weight {:e})",
                    report.step, b.name, b.fit_regularisation
                ),
                "WARN",
            )?;
        }
        Ok(())
    }

    /// Log a step's metrics (on `step`, residuals on `iteration`) and the state after it.
    pub fn log_step(&mut self, report: &StepReport, sim: &Simulation) -> Result<(), RecordError> {
        self.log_residuals(report.step, &report.residuals)?;
        self.rec.set_time_sequence("step", report.step as i64);
        self.step_now.set(report.step as i64);
        // A step's condition numbers are its tangent's, but for explicit
        // dynamics, whose are its masses' (logged with the dynamics).
        let tangent = report.dynamics.as_ref().is_none_or(|d| d.integrator.is_some());
        if let Some(d) = &report.dynamics {
            self.log_dynamics(report, d)?;
        }
        if let (true, Some(c)) = (tangent, &report.condition) {
            self.condition(report.step, "stiffness", "the stiffness", c.value)?;
        }
        if let (true, Some(c)) = (tangent, &report.condition_unstabilised) {
            self.condition(
                report.step,
                "stiffness_unstabilised",
                "the stiffness without ghost",
                c.value,
            )?;
        }
        self.log_warnings(report)?;
        self.scalar("metrics/newton/iterations", report.iterations as f64)?;
        self.scalar("metrics/ghost/faces", report.ghost_faces as f64)?;
        self.scalar("metrics/energy/plastic_dissipation", report.energy.plastic_dissipation)?;
        self.scalar("metrics/energy/strain", report.energy.strain)?;
        self.scalar("metrics/energy/external_work", report.energy.external_work)?;
        if tangent {
            self.scalar("metrics/energy/ghost", report.energy.ghost)?;
        }
        if report.dynamics.is_none() {
            // The quasi-static balance, the dynamic one without kinetic
            // energy: stored and dissipated against the work done (0 up to
            // the trapezoidal rule of the work along the load path).
            let e = &report.energy;
            self.scalar(
                "metrics/energy/balance_error",
                e.strain + e.plastic_dissipation - e.external_work,
            )?;
        }
        if !self.error_styles && !report.errors.is_empty() {
            let names: Vec<&str> = report.errors.iter().map(|e| e.name).collect();
            self.log_styles_of(&Contents::error_series(&names))?;
            self.error_styles = true;
        }
        for e in &report.errors {
            self.scalar(&format!("metrics/error/{}", e.name), e.value)?;
            if e.value > 0.0 {
                self.scalar(&format!("metrics/log10/error/{}", e.name), e.value.log10())?;
            }
        }
        for p in &report.probes {
            for (k, _, v) in p.columns() {
                self.scalar(&format!("metrics/probe/{}/{k}", p.name), v)?;
            }
        }
        for (name, v) in report.timings.named() {
            self.scalar(&format!("metrics/time/{name}"), v)?;
        }
        self.scalar("metrics/unknowns", report.unknowns as f64)?;
        // The inertia: negative pivots of the last tangent (a loss of
        // stability or a spurious mode); cutbacks (Newton increments or
        // explicit time steps) as warnings.
        if let Some(n) = report.solver.as_ref().and_then(|s| s.negative_pivots) {
            self.scalar("metrics/solver/negative_pivots", n as f64)?;
        }
        if report.solver.is_some() || report.dynamics.is_some() {
            self.scalar("metrics/solver/cutbacks", report.cutbacks().len() as f64)?;
        }
        for c in report.cutbacks() {
            self.event(
                &format!(
                    "step {}: cutback: {} failed and was halved: {}",
                    report.step,
                    report.cutback_span(c),
                    c.reason
                ),
                "WARN",
            )?;
        }
        if let Some(a) = report.solver.as_ref().and_then(|s| s.attainable) {
            self.event(&format!("step {}: {a}", report.step), "WARN")?;
        }
        for b in &report.ibm {
            let base = format!("metrics/ibm/{}", b.name);
            self.scalar(&format!("{base}/reaction_x"), b.reaction[0])?;
            self.scalar(&format!("{base}/reaction_y"), b.reaction[1])?;
            self.scalar(&format!("{base}/violation"), b.violation)?;
            self.scalar(&format!("{base}/violation_rms"), b.violation_rms)?;
            self.scalar(&format!("{base}/cut_cells"), b.cut_cells as f64)?;
        }
        for b in &report.boundaries {
            let base = format!("metrics/boundary/{}", b.name);
            self.scalar(&format!("{base}/length"), b.length)?;
            if let Some(a) = b.area {
                self.scalar(&format!("{base}/area"), a)?;
            }
            self.scalar(&format!("{base}/cells_cut"), b.cells_cut as f64)?;
            self.scalar(&format!("{base}/resultant_x"), b.resultant[0])?;
            self.scalar(&format!("{base}/resultant_y"), b.resultant[1])?;
        }
        self.steps.insert(report.step as i64);
        // A new state (a redo in the TUI may repeat a step number).
        self.last_frame = None;
        if self.plan.holds_points(report.step) {
            self.log_state(sim)?;
        }
        if self.sync_due() {
            self.sync()?;
        }
        Ok(())
    }

    /// Whether to flush after a step: once the period has passed since the
    /// last flush, or sooner once a flush's fixed cost (the shortest one
    /// so far) is at most [`SYNC_SHARE`] of the time since the last one.
    fn sync_due(&self) -> bool {
        flush_due(self.last_sync.elapsed(), self.sync_period, self.sync_cost)
    }

    /// The longest wall time between flushes into the file after a step
    /// ([`SYNC_PERIOD`] by default; zero: after every step). Steps are
    /// flushed sooner while flushing costs little ([`SYNC_SHARE`]).
    pub fn set_sync_period(&mut self, period: std::time::Duration) {
        self.sync_period = period;
    }

    /// Write everything logged so far into the file: after it, a killed
    /// process leaves a file holding every step logged (without rerun's
    /// footer, which `mpmlab repair` adds: [`repair`]). It costs a few
    /// milliseconds and, in the file, a chunk per entity (about a
    /// kilobyte each): rerun cuts its batches at each call. Steps call it
    /// while it costs little, and at the latest once
    /// [`Recorder::set_sync_period`] has passed since the last one
    /// ([`Recorder::sync_due`]); failures always.
    pub fn sync(&mut self) -> Result<(), RecordError> {
        let (result, cost) = self.writer.sync();
        self.last_sync = std::time::Instant::now();
        self.sync_cost = Some(self.sync_cost.map_or(cost, |c| c.min(cost)));
        match result {
            None => Ok(()),
            Some(message) => Err(RecordError::Write {
                path: self.path.clone(),
                message,
            }),
        }
    }

    /// Dynamics: energies, balance, momentum and (on condition
    /// steps) mass conditioning and CFL numbers, on `step` and `time`.
    fn log_dynamics(&self, report: &StepReport, d: &crate::dynamics::DynamicsReport) -> Result<(), RecordError> {
        self.rec.set_duration_secs("time", d.time);
        let e = &report.energy;
        self.scalar("metrics/energy/kinetic", e.kinetic)?;
        self.scalar("metrics/energy/kinetic_grid", d.kinetic_grid)?;
        self.scalar("metrics/energy/total", e.kinetic + e.strain)?;
        self.scalar("metrics/energy/balance_error", d.energy_error)?;
        if let Some(b) = crate::format::relative_balance(d) {
            self.scalar("metrics/energy/balance_error_relative", b)?;
        }
        self.scalar("metrics/momentum/x", d.momentum[0])?;
        self.scalar("metrics/momentum/y", d.momentum[1])?;
        self.scalar("metrics/dynamics/max_grid_speed", d.max_speed)?;
        if let Some(c) = &d.conditioning {
            for (name, what, v) in [
                ("mass_consistent", "the consistent mass", c.mass_consistent.value),
                ("mass_stabilised", "the stabilised mass", c.mass_stabilised.value),
                ("mass_lumped", "the lumped mass", c.mass_lumped.value),
            ] {
                self.condition(report.step, name, what, v)?;
            }
            for (name, v) in [
                ("consistent", c.cfl_consistent),
                ("stabilised", c.cfl_stabilised),
                ("lumped", c.cfl_lumped),
            ] {
                if let Some(v) = v {
                    self.scalar(&format!("metrics/cfl/{name}"), v)?;
                }
            }
        }
        Ok(())
    }

    fn log_residuals(&mut self, step: usize, residuals: &[f64]) -> Result<(), RecordError> {
        self.rec.set_time_sequence("step", step as i64);
        self.step_now.set(step as i64);
        // The step's convergence as one bar chart (log10 of each residual
        // against its iteration), which the viewer shows for the step under
        // the time cursor.
        let shown: Vec<(u32, f64)> = residuals
            .iter()
            .enumerate()
            .filter(|(_, r)| **r > 0.0 && r.is_finite())
            .map(|(k, r)| (k as u32, r.log10()))
            .collect();
        if !shown.is_empty() {
            self.check(
                self.rec.log(
                    "metrics/newton/residual_history",
                    &rerun::BarChart::new(shown.iter().map(|s| s.1).collect::<Vec<f64>>())
                        .with_abscissa(shown.iter().map(|s| s.0).collect::<Vec<u32>>())
                        .with_color(rerun::Color::from_rgb(86, 180, 233)),
                ),
            )?;
        }
        for &r in residuals {
            self.iteration += 1;
            self.rec.set_time_sequence("iteration", self.iteration);
            self.scalar("metrics/residual", r)?;
            if r > 0.0 {
                self.scalar("metrics/log10/residual", r.log10())?;
            }
        }
        self.rec.reset_time();
        Ok(())
    }

    /// Log a failed step: its residual history and an error event, and
    /// the points of the state it started from (the last good one),
    /// whatever the cadence.
    pub fn log_failure(&mut self, failure: &StepFailure, sim: &Simulation) -> Result<(), RecordError> {
        self.log_residuals(failure.step(), failure.residuals())?;
        self.rec.set_time_sequence("step", failure.step() as i64);
        self.step_now.set(failure.step() as i64);
        self.event(&failure.to_string(), rerun::TextLogLevel::ERROR)?;
        self.log_state(sim)?;
        self.sync()
    }

    /// Log a text event at the current step (the last step logged; the
    /// state the recording started from before any), numbered on the
    /// `event` timeline so that events of one step stay distinct.
    pub fn event(&self, text: &str, level: &str) -> Result<(), RecordError> {
        let n = self.events.get();
        self.events.set(n + 1);
        self.rec.set_time_sequence("step", self.step_now.get());
        self.rec.set_time_sequence("event", n);
        let logged = self.rec.log("events", &rerun::TextLog::new(text).with_level(level));
        self.rec.disable_timeline("event");
        self.check(logged)
    }

    /// Close the recording and remove its temporary file: the run never
    /// started, and the file at its path stays as it was.
    pub fn discard(mut self) {
        let staged = self.staged.take();
        let _ = self.writer.join();
        drop(self);
        if let Some(s) = staged {
            s.discard();
        }
    }

    /// Flush everything to disk and close the file; its size and what it
    /// holds.
    /// When it cannot be, the file stays as `NAME.partial`, which the
    /// error names with the command that repairs it.
    pub fn finish(mut self) -> Result<RecordingSize, RecordError> {
        let kept = |path: &Path, partial: Option<&Path>, e: String| RecordError::Write {
            path: path.to_path_buf(),
            message: match partial {
                Some(p) => format!(
                    "{e}; what was written is kept as {} (mpmlab repair {} {})",
                    p.display(),
                    p.display(),
                    path.display()
                ),
                None => e,
            },
        };
        let partial = self.staged.as_ref().map(|s| s.partial().to_path_buf());
        if let Some(e) = self.writer.join() {
            return Err(kept(&self.path, partial.as_deref(), e));
        }
        if let Err(e) = self.recolour_frames() {
            return Err(kept(&self.path, partial.as_deref(), e.to_string()));
        }
        if let Err(e) = self.rec.flush_blocking() {
            return Err(kept(&self.path, partial.as_deref(), e.to_string()));
        }
        let shared = self.sink.clone();
        let size = RecordingSize {
            bytes: 0,
            steps: self.steps.len(),
            frames: self.frames.len(),
            points: self.points,
        };
        let path = self.path.clone();
        let staged = self.staged.take();
        // The stream closed, every message is with the sink: the footer,
        // and the file synced to disk before it takes its name.
        drop(self);
        if let Err(e) = shared.finish() {
            return Err(kept(&path, partial.as_deref(), e));
        }
        if let Some(s) = staged {
            s.commit().map_err(|message| RecordError::Write {
                path: path.clone(),
                message,
            })?;
        }
        let bytes = std::fs::metadata(&path).map_or(0, |m| m.len());
        Ok(RecordingSize { bytes, ..size })
    }
}

/// The recorder follows runs through the one runner: a write error
/// detaches it with the reason (the run goes on unrecorded).
impl crate::runner::Observer for Recorder {
    fn stepped(&mut self, sim: &Simulation, report: &StepReport) -> Option<String> {
        let r = self.log_step(report, sim);
        self.stopped(r)
    }
    fn failed(&mut self, sim: &Simulation, failure: &StepFailure) -> Option<String> {
        let r = self.log_failure(failure, sim);
        self.stopped(r)
    }
    fn note(&mut self, text: &str, level: &str) -> Option<String> {
        let r = self.event(text, level);
        self.stopped(r)
    }
}

impl Recorder {
    /// The message of a recorder that stops following the run (it is
    /// dropped next): the error and where what was written is kept.
    fn stopped(&self, r: Result<(), RecordError>) -> Option<String> {
        let e = r.err()?;
        Some(match self.partial() {
            Some(p) => format!(
                "recording stopped: {e}; what was written is kept as {} (mpmlab repair {} {})",
                p.display(),
                p.display(),
                self.path.display()
            ),
            None => format!("recording stopped: {e}"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn steps_are_flushed_while_flushing_costs_at_most_its_share() {
        let ms = Duration::from_millis;
        // The first step is flushed, before any cost is known.
        assert!(flush_due(ms(1), SYNC_PERIOD, None));
        // A 3 ms flush is 5% of 60 ms: a step ending 60 ms after the last
        // flush is flushed, one ending 50 ms after it is not yet.
        assert!(flush_due(ms(60), SYNC_PERIOD, Some(ms(3))));
        assert!(!flush_due(ms(50), SYNC_PERIOD, Some(ms(3))));
        // A costly flush waits for the period, and no longer.
        assert!(!flush_due(ms(499), SYNC_PERIOD, Some(ms(100))));
        assert!(flush_due(ms(500), SYNC_PERIOD, Some(ms(100))));
        // Period 0 (`--record-sync 0`): every step, whatever it costs.
        assert!(flush_due(ms(0), Duration::ZERO, Some(ms(100))));
    }
}
