//! The command line's arguments (clap definitions) and what they mean
//! for the engine and the outputs: recording settings, the ParaView
//! series, the memory budget.

use clap::{Parser, Subcommand};
use mpmlab::model::Limits;
use mpmlab::record::Recorder;
use mpmlab::simulation::Simulation;
use mpmlab::vtk::VtkExport;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "mpmlab", version, about = "Implicit material point method laboratory")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Cmd>,
}

#[derive(Subcommand)]
pub enum Cmd {
    /// Run a scene headless: per-step table and summary.
    Run(RunArgs),
    /// Validate a scene file without running it.
    Check {
        scene: PathBuf,
        /// Refuse scenes whose estimated memory exceeds this (bytes, or
        /// with k, M, G, T); default half of the available memory.
        #[arg(long, value_name = "SIZE", value_parser = parse_size)]
        max_memory: Option<u64>,
    },
    /// List the scenes in a folder with their descriptions.
    List {
        #[arg(default_value = "scenarios")]
        dir: PathBuf,
    },
    /// Run a scene over the cross product of settings (or a preset of a
    /// paper study): a CSV row per run, rates, Pareto front, SVG charts.
    Sweep(SweepArgs),
    /// Run one scene of a sweep and write its result row (used by `sweep`
    /// and by emitted job lists).
    SweepRun {
        scene: PathBuf,
        #[arg(long)]
        result: PathBuf,
        /// Record the run to this file.
        #[arg(long)]
        record: Option<PathBuf>,
    },
    /// Open a recording in the rerun viewer (or say how to install it).
    Replay { recording: PathBuf },
    /// Run every paper benchmark against the papers' numbers: paper value,
    /// ours, ratio, tolerance and pass per row; exit 1 when a row fails.
    Verify(VerifyArgs),
    /// Make a recording cut short (a killed run) whole again: every
    /// complete message of INPUT is written to OUTPUT with rerun's footer.
    Repair {
        input: PathBuf,
        output: PathBuf,
        /// Replace an existing OUTPUT whatever it holds.
        #[arg(long)]
        force: bool,
    },
    /// Step a scene interactively in the terminal.
    Tui(TuiArgs),
    /// Decode a recording's messages as `repair` would, one `ok K` line
    /// after each (run by `repair` in a process of its own).
    #[command(hide = true)]
    RepairProbe { input: PathBuf },
}

/// Arguments of `mpmlab tui` (and of `mpmlab` with none).
#[derive(clap::Args, Default)]
pub struct TuiArgs {
    pub scene: Option<PathBuf>,
    /// Recording file (default recordings/<scene>-<time>.rrd).
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Do not record.
    #[arg(long, conflicts_with = "record")]
    pub no_record: bool,
    /// Replace an existing --record file whatever it holds.
    #[arg(long, requires = "record")]
    pub force: bool,
    #[command(flatten)]
    pub cadence: RecordArgs,
    /// Refuse scenes whose estimated memory exceeds this, and steps
    /// whose factor would take the process beyond it (bytes, or with
    /// k, M, G, T); default half of the available memory.
    #[arg(long, value_name = "SIZE", value_parser = parse_size)]
    pub max_memory: Option<u64>,
    /// Threads for the points' material updates (explicit and
    /// finite-deformation steps) and the tangent's blocks (implicit steps)
    /// (0: one per core; default 1). Results are the same to the bit for
    /// any count.
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Start from a checkpoint of this scene (`run --checkpoint`, or `w`
    /// in the TUI) and step on, with other parameters if you like: the
    /// recording is the branch, and says where it started.
    #[arg(long, value_name = "FILE")]
    pub resume: Option<PathBuf>,
    /// Show a sweep folder instead (table, error against time and h).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["scene", "record", "no_record", "force", "max_memory", "record_every", "record_dt", "record_fields", "resume", "threads"])]
    pub sweep: Option<PathBuf>,
}

/// Arguments of `mpmlab run`.
#[derive(clap::Args)]
pub struct RunArgs {
    pub scene: PathBuf,
    /// Write a rerun recording (.rrd) of the run. An existing file is
    /// replaced only when it is a recording (or with --force); never the
    /// scene itself.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Write the step table as CSV: every reported quantity per step, with
    /// units in the headers, probes as `probe:<name>:<key>`, and a row for
    /// the initial state. An existing file is replaced only when it is
    /// such a table (or with --force).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Write checkpoints (the complete state, to resume from) into this
    /// folder: `step-NNNNNN.ckpt` every --checkpoint-every steps, after
    /// the last step, and of the last good state when a step fails or the
    /// run is interrupted. A folder holding other files is refused (or
    /// with --force written beside them); one run at a time writes it.
    #[arg(long, value_name = "DIR")]
    pub checkpoint: Option<PathBuf>,
    /// Steps between checkpoints (default: only the last).
    #[arg(long, value_name = "N", requires = "checkpoint", value_parser = clap::value_parser!(u64).range(1..))]
    pub checkpoint_every: Option<u64>,
    /// Continue from a checkpoint written for this scene (same scene file,
    /// same program version); the run ends bit for bit where the
    /// uninterrupted run ends.
    #[arg(long, value_name = "FILE")]
    pub resume: Option<PathBuf>,
    /// Replace an existing --record or --csv regular file whatever it
    /// holds, a stale NAME.partial, and write checkpoints or a --vtk
    /// series into a folder holding other files (never the scene, a
    /// folder, a device, FIFO or socket).
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub cadence: RecordArgs,
    #[command(flatten)]
    pub vtk: VtkArgs,
    /// Threads for the points' material updates (explicit and
    /// finite-deformation steps) and the tangent's blocks (implicit steps)
    /// (0: one per core; default 1). Results are the same to the bit for
    /// any count. Sweeps run one scene per core
    /// instead.
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Print only the summary.
    #[arg(long)]
    pub quiet: bool,
    /// Refuse scenes whose estimated memory exceeds this, and steps whose
    /// factor would take the process beyond it (bytes, or with k, M, G,
    /// T); default half of the available memory.
    #[arg(long, value_name = "SIZE", value_parser = parse_size)]
    pub max_memory: Option<u64>,
}

/// A ParaView time series of the run (`mpmlab::vtk`).
#[derive(clap::Args, Clone, Default)]
pub struct VtkArgs {
    /// Write a ParaView time series to DIR (created if needed): a .pvd
    /// collection per kind (points with every field, grid, B-spline and
    /// implicit boundaries) and a VTK XML file per kind and step.
    #[arg(long, value_name = "DIR")]
    pub vtk: Option<PathBuf>,
    /// Write every N-th step to --vtk (the initial state, the last step and
    /// the last good state of a failed run are always written).
    #[arg(long, value_name = "N", requires = "vtk", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub vtk_every: u64,
}

impl VtkArgs {
    /// Create the series and write the initial state; exit status 3 (with
    /// the folder and the cause on stderr) when it cannot be written.
    pub fn open(&self, sim: &Simulation, force: bool) -> Result<Option<VtkExport>, ExitCode> {
        let Some(dir) = &self.vtk else { return Ok(None) };
        VtkExport::create(dir, sim, self.vtk_every as usize, force)
            .map(Some)
            .map_err(|e| {
                eprintln!("error: {e}");
                ExitCode::from(3)
            })
    }
}

/// What a recording holds, over the scene's `[record]` settings.
#[derive(clap::Args, Clone, Default)]
pub struct RecordArgs {
    /// Record the points every N steps (metrics and events go in at every
    /// step; the first, last and failed steps always hold points).
    /// Overrides the scene's `[record]` cadence; default: every step up to
    /// a budget of 2 million points times frames.
    #[arg(long, value_name = "N", conflicts_with = "record_dt")]
    pub record_every: Option<usize>,
    /// Explicit dynamics: record the points every T seconds of simulated time.
    #[arg(long, value_name = "T")]
    pub record_dt: Option<f64>,
    /// Per-point fields recorded with the positions, comma-separated
    /// (sigma_xx, sigma_yy, sigma_xy, displacement_magnitude,
    /// plastic_strain, speed, error; `all` for every one; default sigma_yy).
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    pub record_fields: Option<Vec<String>>,
    /// Longest wall time in seconds between flushes of the recording into
    /// its file (0: after every step; default 0.5). Steps are flushed
    /// sooner, after every step of more than about 60 ms, while a flush
    /// costs at most 5% of the time since the last one. A killed run's
    /// file holds every step up to the last flush; `mpmlab repair` makes
    /// it readable.
    #[arg(long, value_name = "SECONDS", value_parser = parse_seconds)]
    pub record_sync: Option<std::time::Duration>,
}

/// A `--record-sync` value: finite, at least 0, at most a day.
pub fn parse_seconds(s: &str) -> Result<std::time::Duration, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number of seconds"))?;
    if !(0.0..=86400.0).contains(&v) {
        return Err(format!("{s} s is outside 0 ..= 86400"));
    }
    Ok(std::time::Duration::from_secs_f64(v))
}

impl RecordArgs {
    pub fn given(&self) -> bool {
        self.record_every.is_some()
            || self.record_dt.is_some()
            || self.record_fields.is_some()
            || self.record_sync.is_some()
    }

    /// The recorder made with these.
    pub fn create(
        &self,
        path: &Path,
        text: &str,
        sim: &Simulation,
        settings: mpmlab::model::record::RecordSettings,
        force: bool,
    ) -> Result<Recorder, mpmlab::record::RecordError> {
        let mut r = Recorder::create_with(path, text, sim, false, settings, force)?;
        if let Some(p) = self.record_sync {
            r.set_sync_period(p);
        }
        Ok(r)
    }

    /// The scene's settings with these over them.
    pub fn settings(&self, sim: &Simulation) -> Result<mpmlab::model::record::RecordSettings, String> {
        use mpmlab::model::record::{check_cadence, parse_fields, Cadence};
        let mut s = sim.model().record.clone();
        let cadence = match (self.record_every, self.record_dt) {
            (Some(n), _) => Some(("--record-every", Cadence::Every(n))),
            (None, Some(t)) => Some(("--record-dt", Cadence::Dt(t))),
            (None, None) => None,
        };
        if let Some((flag, c)) = cadence {
            check_cadence(c, sim.model().analysis.kind).map_err(|(_, m)| format!("{flag}: {m}"))?;
            s.cadence = c;
        }
        if let Some(f) = &self.record_fields {
            s.fields = parse_fields(f).map_err(|m| format!("--record-fields: {m}"))?;
        }
        Ok(s)
    }
}

/// A `--max-memory` value.
pub fn parse_size(s: &str) -> Result<u64, String> {
    mpmlab::model::parse_bytes(s)
}

/// The limits of `--max-memory` (default: half of the available memory).
pub fn limits(max_memory: Option<u64>) -> Limits {
    max_memory.map_or_else(Limits::default, |m| Limits { max_memory: m })
}

/// Arguments of `mpmlab sweep`.
#[derive(clap::Args)]
pub struct SweepArgs {
    /// Scene file (not with --preset or --collect).
    pub scene: Option<PathBuf>,
    /// `key=v1,v2,...`; keys: h, ppc, delta_over_h, gamma_k, gamma_m,
    /// steps, tolerance, mass, ... or a dotted scene path
    /// (`analysis.max_iterations`, `body.0.basis`).
    #[arg(long = "vary", value_name = "KEY=V1,V2,...")]
    pub vary: Vec<String>,
    /// A paper study: plate-hole-h, delta, beam-stability, column-gamma.
    #[arg(long, conflicts_with = "scene")]
    pub preset: Option<String>,
    /// Runs at a time (each single-threaded, in its own process), 1 or more.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..))]
    pub jobs: u16,
    /// Sweep folder (default sweeps/<scene or preset>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write one command per pending run to <out>/jobs.txt instead of running.
    #[arg(long)]
    pub emit_jobs: bool,
    /// Record each run to <out>/recordings/<id>.rrd (with the scene's
    /// `[record]` settings, which `--vary record.every=...` can change);
    /// the CSV then holds the recording's size per step and per point.
    #[arg(long)]
    pub record: bool,
    /// Require a refinement study: `--vary h=...` with three or more cell
    /// sizes, from which every probe and energy gets its observed order,
    /// Richardson-extrapolated value and grid convergence index (also
    /// computed, without this flag, whenever h takes three values).
    #[arg(long)]
    pub estimate: bool,
    /// Find the cheapest discretisation meeting an error target instead of
    /// a cross product: `error:<name>=TOL` (against the exact solution) or
    /// `probe:<name>:<key>=TOL` / `energy:<name>=TOL` (relative GCI of
    /// three refinements). Refines h coarse to fine at the scene's points
    /// per cell and twice them, predicting from the observed order.
    #[arg(long, value_name = "QUANTITY=TOL", conflicts_with_all = ["vary", "preset", "emit_jobs", "record"])]
    pub target: Option<String>,
    /// Seconds of runs a --target search may spend.
    #[arg(long, default_value_t = 300.0, requires = "target")]
    pub budget: f64,
    /// With --target: other settings to search, each value a family of
    /// its own refined in h (`body.0.placement=centres,clipped`,
    /// `body.0.basis=standard,gimp`, `steps=10,20`, `gamma_k=0,1e5`).
    #[arg(long = "try", value_name = "KEY=V1,V2,...", requires = "target")]
    pub tries: Vec<String>,
    /// Write into an --out folder that holds files other than a sweep's
    /// (they are left alone, unless a sweep's file has their name).
    #[arg(long)]
    pub force: bool,
    /// Merge the results in this sweep folder (from --emit-jobs runs) and chart them.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["scene", "preset", "vary", "emit_jobs"])]
    pub collect: Option<PathBuf>,
}

/// Arguments of `mpmlab verify`.
#[derive(clap::Args)]
pub struct VerifyArgs {
    /// Only the rows CI runs (about 2 s on two cores); the full set takes
    /// about half a minute.
    #[arg(long)]
    pub quick: bool,
    /// Also write the rows as CSV
    /// (`benchmark,quantity,paper,ours,ratio,tolerance,pass,why`).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Rewrite the generated table of this Markdown file (between its
    /// `verify` markers; e.g. docs/verification.md) with the rows.
    #[arg(long, value_name = "FILE")]
    pub write_docs: Option<PathBuf>,
    /// Folder of the shipped scenes [default: ./scenarios when there is
    /// one, else the copies built into this program].
    #[arg(long, value_name = "DIR")]
    pub scenes: Option<PathBuf>,
}
