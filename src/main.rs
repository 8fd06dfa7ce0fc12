//! The `mpmlab` command line: run scenes headless, check them, list them,
//! or step them in the terminal UI.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use mpmlab::format::{factor_label, relative_balance, sci_or_dash};
use mpmlab::model::Limits;
use mpmlab::record::Recorder;
use mpmlab::runner::{Observer, RunEnd};
use mpmlab::scene::Scene;
use mpmlab::simulation::{Simulation, StepReport};
use mpmlab::units::Quantity;
use mpmlab::vtk::VtkExport;
use mpmlab::Model;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// `println!` that ignores a closed stdout (e.g. `mpmlab run ... | head`)
/// instead of panicking.
macro_rules! out {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($t)*);
    }};
}

/// The scene opened by `mpmlab` with no arguments (also built in, so the
/// command works from any directory).
const DEFAULT_SCENE: &str = "scenarios/column-small-strain.toml";
const DEFAULT_SCENE_TEXT: &str = include_str!("../scenarios/column-small-strain.toml");

#[derive(Parser)]
#[command(name = "mpmlab", version, about = "Implicit material point method laboratory")]
struct Cli {
    #[command(subcommand)]
    command: Option<Cmd>,
}

#[derive(Subcommand)]
enum Cmd {
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
    Tui {
        scene: Option<PathBuf>,
        /// Recording file (default recordings/<scene>-<time>.rrd).
        #[arg(long)]
        record: Option<PathBuf>,
        /// Do not record.
        #[arg(long, conflicts_with = "record")]
        no_record: bool,
        /// Replace an existing --record file whatever it holds.
        #[arg(long, requires = "record")]
        force: bool,
        #[command(flatten)]
        cadence: RecordArgs,
        /// Refuse scenes whose estimated memory exceeds this, and steps
        /// whose factor would take the process beyond it (bytes, or with
        /// k, M, G, T); default half of the available memory.
        #[arg(long, value_name = "SIZE", value_parser = parse_size)]
        max_memory: Option<u64>,
        /// Explicit dynamics: threads for the points' material updates (0:
        /// one per core; default 1). Results are the same to the bit.
        #[arg(long, value_name = "N")]
        threads: Option<usize>,
        /// Start from a checkpoint of this scene (`run --checkpoint`, or `w`
        /// in the TUI) and step on, with other parameters if you like: the
        /// recording is the branch, and says where it started.
        #[arg(long, value_name = "FILE")]
        resume: Option<PathBuf>,
        /// Show a sweep folder instead (table, error against time and h).
        #[arg(long, value_name = "DIR", conflicts_with_all = ["scene", "record", "no_record", "force", "max_memory", "record_every", "record_dt", "record_fields", "resume", "threads"])]
        sweep: Option<PathBuf>,
    },
}

/// Arguments of `mpmlab run`.
#[derive(clap::Args)]
struct RunArgs {
    scene: PathBuf,
    /// Write a rerun recording (.rrd) of the run. An existing file is
    /// replaced only when it is a recording (or with --force); never the
    /// scene itself.
    #[arg(long)]
    record: Option<PathBuf>,
    /// Write the step table as CSV: every reported quantity per step, with
    /// units in the headers, probes as `probe:<name>:<key>`, and a row for
    /// the initial state. An existing file is replaced only when it is
    /// such a table (or with --force).
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
    /// Write checkpoints (the complete state, to resume from) into this
    /// folder: `step-NNNNNN.ckpt` every --checkpoint-every steps, after
    /// the last step, and of the last good state when a step fails or the
    /// run is interrupted.
    #[arg(long, value_name = "DIR")]
    checkpoint: Option<PathBuf>,
    /// Steps between checkpoints (default: only the last).
    #[arg(long, value_name = "N", requires = "checkpoint", value_parser = clap::value_parser!(u64).range(1..))]
    checkpoint_every: Option<u64>,
    /// Continue from a checkpoint written for this scene (same scene file,
    /// same program version); the run ends bit for bit where the
    /// uninterrupted run ends.
    #[arg(long, value_name = "FILE")]
    resume: Option<PathBuf>,
    /// Replace an existing --record or --csv file whatever it holds.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    cadence: RecordArgs,
    #[command(flatten)]
    vtk: VtkArgs,
    /// Explicit dynamics: threads for the points' material updates (0:
    /// one per core; default 1). Results are the same to the bit for any
    /// count. Sweeps run one scene per core instead.
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
    /// Print only the summary.
    #[arg(long)]
    quiet: bool,
    /// Refuse scenes whose estimated memory exceeds this, and steps whose
    /// factor would take the process beyond it (bytes, or with k, M, G,
    /// T); default half of the available memory.
    #[arg(long, value_name = "SIZE", value_parser = parse_size)]
    max_memory: Option<u64>,
}

/// A ParaView time series of the run (`mpmlab::vtk`).
#[derive(clap::Args, Clone, Default)]
struct VtkArgs {
    /// Write a ParaView time series to DIR (created if needed): a .pvd
    /// collection per kind (points with every field, grid, B-spline and
    /// implicit boundaries) and a VTK XML file per kind and step.
    #[arg(long, value_name = "DIR")]
    vtk: Option<PathBuf>,
    /// Write every N-th step to --vtk (the initial state, the last step and
    /// the last good state of a failed run are always written).
    #[arg(long, value_name = "N", requires = "vtk", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    vtk_every: u64,
}

impl VtkArgs {
    /// Create the series and write the initial state; exit status 3 (with
    /// the folder and the cause on stderr) when it cannot be written.
    fn open(&self, sim: &Simulation) -> Result<Option<VtkExport>, ExitCode> {
        let Some(dir) = &self.vtk else { return Ok(None) };
        VtkExport::create(dir, sim, self.vtk_every as usize)
            .map(Some)
            .map_err(|e| {
                eprintln!("error: {e}");
                ExitCode::from(3)
            })
    }
}

/// What a recording holds, over the scene's `[record]` settings.
#[derive(clap::Args, Clone, Default)]
struct RecordArgs {
    /// Record the points every N steps (metrics and events go in at every
    /// step; the first, last and failed steps always hold points).
    /// Overrides the scene's `[record]` cadence; default: every step up to
    /// a budget of 2 million points times frames.
    #[arg(long, value_name = "N", conflicts_with = "record_dt")]
    record_every: Option<usize>,
    /// Explicit dynamics: record the points every T seconds of simulated time.
    #[arg(long, value_name = "T")]
    record_dt: Option<f64>,
    /// Per-point fields recorded with the positions, comma-separated
    /// (sigma_xx, sigma_yy, sigma_xy, displacement_magnitude,
    /// plastic_strain, speed, error; `all` for every one; default sigma_yy).
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    record_fields: Option<Vec<String>>,
    /// Longest wall time in seconds between flushes of the recording into
    /// its file (0: after every step; default 0.5). Steps are flushed
    /// sooner, after every step of more than about 60 ms, while a flush
    /// costs at most 5% of the time since the last one. A killed run's
    /// file holds every step up to the last flush; `mpmlab repair` makes
    /// it readable.
    #[arg(long, value_name = "SECONDS", value_parser = parse_seconds)]
    record_sync: Option<std::time::Duration>,
}

/// A `--record-sync` value: finite, at least 0, at most a day.
fn parse_seconds(s: &str) -> Result<std::time::Duration, String> {
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
    fn given(&self) -> bool {
        self.record_every.is_some()
            || self.record_dt.is_some()
            || self.record_fields.is_some()
            || self.record_sync.is_some()
    }

    /// The recorder made with these.
    fn create(
        &self,
        path: &Path,
        text: &str,
        sim: &Simulation,
        settings: mpmlab::model::record::RecordSettings,
    ) -> Result<Recorder, mpmlab::record::RecordError> {
        let mut r = Recorder::create_with(path, text, sim, false, settings)?;
        if let Some(p) = self.record_sync {
            r.set_sync_period(p);
        }
        Ok(r)
    }

    /// The scene's settings with these over them.
    fn settings(&self, sim: &Simulation) -> Result<mpmlab::model::record::RecordSettings, String> {
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
fn parse_size(s: &str) -> Result<u64, String> {
    mpmlab::model::parse_bytes(s)
}

/// The limits of `--max-memory` (default: half of the available memory).
fn limits(max_memory: Option<u64>) -> Limits {
    max_memory.map_or_else(Limits::default, |m| Limits { max_memory: m })
}

/// Exit codes: 0 success, 1 a step failed, 2 bad input, 3 recording failed,
/// 130 interrupted (Ctrl-C or SIGTERM; the recording is closed cleanly; a
/// second signal ends the process at once, and `mpmlab repair` closes the
/// recording it leaves).
fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Cmd::Run(args)) => run(&args),
        Some(Cmd::Check { scene, max_memory }) => check(&scene, &limits(max_memory)),
        Some(Cmd::List { dir }) => list(&dir),
        Some(Cmd::Sweep(args)) => sweep(args),
        Some(Cmd::SweepRun { scene, result, record }) => sweep_run(&scene, &result, record.as_deref()),
        Some(Cmd::Replay { recording }) => replay(&recording),
        Some(Cmd::Verify(args)) => verify(&args),
        Some(Cmd::Repair { input, output, force }) => Ok(repair(&input, &output, force)),
        Some(Cmd::Tui { sweep: Some(dir), .. }) => sweep_view(&dir),
        Some(Cmd::Tui {
            scene,
            record,
            no_record,
            force,
            cadence,
            max_memory,
            threads,
            resume,
            sweep: None,
        }) => tui(
            scene.as_deref(),
            record,
            no_record,
            force,
            &cadence,
            &Engine {
                limits: limits(max_memory),
                threads,
            },
            resume.as_deref(),
        ),
        None => tui(
            None,
            None,
            false,
            false,
            &RecordArgs::default(),
            &Engine {
                limits: Limits::default(),
                threads: None,
            },
            None,
        ),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

/// What the engine may use: its memory budget and threads (`--max-memory`,
/// `--threads`).
struct Engine {
    limits: Limits,
    threads: Option<usize>,
}

/// `--threads`: start them, say so (unless `quiet`), or exit 2 naming why not.
/// A flag set by the first SIGINT or SIGTERM; a second one ends the process
/// at once with status 130. Handed to [`mpmlab::runner::run`], which cancels
/// the running step when it is set.
fn stop_on_signals() -> std::sync::Arc<std::sync::atomic::AtomicBool> {
    let flag = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        let _ = signal_hook::flag::register_conditional_shutdown(sig, 130, flag.clone());
        let _ = signal_hook::flag::register(sig, flag.clone());
    }
    flag
}

fn use_threads(sim: &mut Simulation, threads: Option<usize>, quiet: bool) -> Result<(), ExitCode> {
    let Some(n) = threads else { return Ok(()) };
    match sim.set_threads(n) {
        Ok(k) if !quiet => {
            let explicit = sim.model().analysis.kind == mpmlab::scene::AnalysisKind::ExplicitDynamics;
            println!(
                "threads: {k} for the points' material updates{}",
                if explicit {
                    ""
                } else {
                    " (explicit dynamics only: this analysis runs on one)"
                }
            );
            Ok(())
        }
        Ok(_) => Ok(()),
        Err(e) => {
            eprintln!("error: --threads: {e}");
            Err(ExitCode::from(2))
        }
    }
}

fn load(path: &Path, limits: &Limits) -> Result<(Simulation, String), ExitCode> {
    let (scene, text) = Scene::load(path).map_err(|e| {
        eprintln!("error: {e}");
        ExitCode::from(2)
    })?;
    let model = Model::build_with(&scene, &text, &path.display().to_string(), limits).map_err(|e| {
        eprintln!("error: {e}");
        ExitCode::from(2)
    })?;
    Ok((Simulation::new(model), text))
}

/// Whether `record` may be written: not the scene itself, not a
/// directory, and, when it exists and is not empty, a rerun recording
/// (its first bytes `RRF0`..`RRF2`) unless `force`. Refusals are bad
/// arguments (exit 2); nothing has been written.
fn check_record_target(record: &Path, scene: Option<&Path>, force: bool) -> Result<(), String> {
    check_output_target("--record", record, scene, force, "a rerun recording", "run.rrd", is_rrd)
}

/// Whether a file's first bytes are those of a rerun recording.
fn is_rrd(magic: &[u8]) -> bool {
    [b"RRF0", b"RRF1", b"RRF2"].iter().any(|x| magic.starts_with(&x[..]))
}

/// Whether the output file `path` of option `flag` may be written: not
/// the scene itself, not a directory, and, when it exists and is not
/// empty, a file of its kind (`ours` of its first bytes) unless `force`.
fn check_output_target(
    flag: &str,
    path: &Path,
    scene: Option<&Path>,
    force: bool,
    kind: &str,
    example: &str,
    ours: impl Fn(&[u8]) -> bool,
) -> Result<(), String> {
    let same = |a: &Path, b: &Path| match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if let Some(scene) = scene {
        if same(path, scene) && !force {
            return Err(format!(
                "{flag} {} is the scene file itself; give another path",
                path.display()
            ));
        }
    }
    let Ok(meta) = std::fs::metadata(path) else {
        return Ok(());
    };
    if meta.is_dir() {
        return Err(format!(
            "{flag} {} is a directory; give a file path such as {}",
            path.display(),
            path.join(example).display()
        ));
    }
    if force {
        return Ok(());
    }
    if !meta.is_file() {
        return Err(format!(
            "{flag} {} exists and is not a regular file; refusing to write to it (--force to do so anyway)",
            path.display()
        ));
    }
    let mut magic = [0u8; 8];
    use std::io::Read as _;
    let n = std::fs::File::open(path)
        .and_then(|mut f| f.read(&mut magic))
        .map_err(|e| {
            format!(
                "{flag} {}: cannot read the existing file: {}",
                path.display(),
                mpmlab::scene::io_reason(&e)
            )
        })?;
    if n == 0 || ours(&magic[..n]) {
        return Ok(());
    }
    Err(format!(
        "{flag} {} exists and is not {kind}; refusing to overwrite it (choose another path, or --force)",
        path.display()
    ))
}

fn check(path: &Path, limits: &Limits) -> Result<ExitCode> {
    let (sim, _) = match load(path, limits) {
        Ok(s) => s,
        Err(code) => return Ok(code),
    };
    let m = sim.model();
    out!(
        "{}: ok — scene `{}`, grid {}x{} (h = {} {}), {}, {} points, {} {} steps, memory estimate within the {} budget",
        path.display(),
        m.name,
        m.grid.nx,
        m.grid.ny,
        mpmlab::scene::number(m.grid.h),
        m.units.of(Quantity::Length),
        match m.bodies.len() {
            1 => "1 body".to_string(),
            n => format!("{n} bodies"),
        },
        sim.points().len(),
        m.analysis.load_steps,
        if sim.time().is_some() { "time" } else { "load" },
        mpmlab::model::bytes(limits.max_memory)
    );
    Ok(ExitCode::SUCCESS)
}

fn list(dir: &Path) -> Result<ExitCode> {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    entries.sort();
    for p in entries {
        let file = p.display().to_string();
        match mpmlab::scene::read_scene_text(&p)
            .and_then(|t| Scene::parse(&t, &file))
            .map_err(|e| e.to_string())
        {
            Ok(s) => {
                let desc = s.scene.description.split_whitespace().collect::<Vec<_>>().join(" ");
                out!("{:<28} {}", s.scene.name, desc);
            }
            Err(e) => out!("{:<28} (invalid: {e})", file),
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The probes' columns of the run table: `<name>:<key>`, each at least
/// 11 wide.
fn probe_header(r: &StepReport) -> String {
    r.probes
        .iter()
        .flat_map(|p| p.columns().into_iter().map(move |(k, _, _)| format!("{}:{k}", p.name)))
        .map(|h| format!(" {h:>11}"))
        .collect()
}

/// The probes' values of a step, under [`probe_header`].
fn probe_cells(r: &StepReport) -> String {
    r.probes
        .iter()
        .flat_map(|p| {
            p.columns()
                .into_iter()
                .map(move |(k, _, v)| (format!("{}:{k}", p.name).len().max(11), v))
        })
        .map(|(w, v)| format!(" {v:>w$.4e}"))
        .collect()
}

/// Header of the explicit-dynamics table (see [`dynamics_row`]).
fn dynamics_header(first: &StepReport) -> String {
    let mut h = format!(
        "{:>6} {:>9} {:>8} {:>11} {:>11} {:>11} {:>11} {:>10} {:>10} {:>10} {:>10}",
        "step",
        "time s",
        "unknowns",
        "kinetic J",
        "strain J",
        "plastic J",
        "balance/W0",
        "cond M~",
        "cond M",
        "cond Mlump",
        "CFL s/m"
    );
    for e in &first.errors {
        h.push_str(&format!(" {:>16}", e.name));
    }
    h.push_str(&format!(" {:>8}", "total s"));
    h.push_str(&probe_header(first));
    h
}

/// One explicit step: energies, the balance error over the initial energy,
/// and (on condition steps) the mass condition numbers and the CFL number
/// of the mass in use.
fn dynamics_row(r: &StepReport) -> String {
    let d = r.dynamics.as_ref().expect("a dynamics report");
    let e = &r.energy;
    let balance = sci_or_dash(relative_balance(d), 3);
    let c = |v: Option<f64>| sci_or_dash(v, 3);
    let cond = d.conditioning.as_ref();
    let cfl = cond.and_then(|c| match d.mass {
        mpmlab::scene::MassKind::Stabilised => c.cfl_stabilised,
        mpmlab::scene::MassKind::Consistent => c.cfl_consistent,
        mpmlab::scene::MassKind::Lumped => c.cfl_lumped,
    });
    let mut s = format!(
        "{:>6} {:>9.4} {:>8} {:>11.4e} {:>11.4e} {:>11.4e} {:>11} {:>10} {:>10} {:>10} {:>10}",
        r.step,
        d.time,
        r.unknowns,
        e.kinetic,
        e.strain,
        e.plastic_dissipation,
        balance,
        c(cond.map(|c| c.mass_stabilised.value)),
        c(cond.map(|c| c.mass_consistent.value)),
        c(cond.map(|c| c.mass_lumped.value)),
        c(cfl)
    );
    for e in &r.errors {
        s.push_str(&format!(" {:>16.4e}", e.value));
    }
    s.push_str(&format!(" {:>8.4}", r.timings.total));
    s.push_str(&probe_cells(r));
    s
}

fn header(first: Option<&StepReport>) -> String {
    let mut h = format!(
        "{:>5} {:>7} {:>8} {:>5} {:>10} {:>10} {:>18} {:>11} {:>11} {:>11}",
        "step", "load", "unknowns", "iters", "residual", "cond(K)", "method", "strain U", "work W", "ghost G"
    );
    if first.is_some_and(|r| r.condition_unstabilised.is_some()) {
        h.push_str(&format!(" {:>12}", "cond no-ghost"));
    }
    for e in first.map(|r| r.errors.as_slice()).unwrap_or(&[]) {
        h.push_str(&format!(" {:>15}", e.name));
    }
    h.push_str(&format!(" {:>9} {:>4}", "factor", "cuts"));
    h.push_str(&format!(
        " {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>8}",
        "map s", "pat s", "asm s", "fact s", "solve s", "cond s", "upd s", "total s"
    ));
    if let Some(r) = first {
        h.push_str(&probe_header(r));
    }
    h
}

fn row(r: &StepReport) -> String {
    let (cond, method) = r.condition.map_or(("-".to_string(), "off"), |c| {
        (format!("{:.3e}", c.value), c.method.label())
    });
    let mut s = format!(
        "{:>5} {:>7.4} {:>8} {:>5} {:>10.3e} {:>10} {:>18} {:>11.4e} {:>11.4e} {:>11.4e}",
        r.step,
        r.load_factor,
        r.unknowns,
        r.iterations,
        r.residuals.last().copied().unwrap_or(f64::NAN),
        cond,
        method,
        r.energy.strain,
        r.energy.external_work,
        r.energy.ghost
    );
    if let Some(c) = r.condition_unstabilised {
        s.push_str(&format!(" {:>12.3e}", c.value));
    }
    for e in &r.errors {
        s.push_str(&format!(" {:>15.4e}", e.value));
    }
    let cuts = r.solver.as_ref().map_or(0, |s| s.cutbacks.len());
    let factor = r.solver.as_ref().map_or("-".to_string(), factor_label);
    s.push_str(&format!(" {:>9} {:>4}", factor, cuts));
    let t = &r.timings;
    s.push_str(&format!(
        " {:>7.4} {:>7.4} {:>7.4} {:>7.4} {:>7.4} {:>7.4} {:>7.4} {:>8.4}",
        t.mapping, t.pattern, t.assembly, t.factorisation, t.solve, t.condition, t.update, t.total
    ));
    s.push_str(&probe_cells(r));
    s
}

/// The run table on stdout, as an observer of the runner.
struct Table {
    quiet: bool,
    last: Option<StepReport>,
    total_time: f64,
    /// Every phase's time summed over the steps, and the cutbacks taken.
    phases: mpmlab::report::Timings,
    cutbacks: usize,
}

impl Observer for Table {
    fn stepped(&mut self, _sim: &Simulation, r: &StepReport) -> Option<String> {
        if !self.quiet {
            match (&r.dynamics, self.last.is_none()) {
                (Some(_), true) => out!("{}", dynamics_header(r)),
                (None, true) => out!("{}", header(Some(r))),
                _ => {}
            }
            out!("{}", if r.dynamics.is_some() { dynamics_row(r) } else { row(r) });
        }
        for c in r.cutbacks() {
            out!(
                "       cutback in step {}: {} failed and was halved: {}",
                r.step,
                r.cutback_span(c),
                c.reason
            );
        }
        self.total_time += r.timings.total;
        self.phases.add(&r.timings);
        self.cutbacks += r.cutbacks().len();
        self.last = Some(r.clone());
        None
    }
}

fn run(args: &RunArgs) -> Result<ExitCode> {
    let (path, record, force, cadence, quiet) = (
        args.scene.as_path(),
        args.record.as_deref(),
        args.force,
        &args.cadence,
        args.quiet,
    );
    let limits = &limits(args.max_memory);
    if force && record.is_none() && args.csv.is_none() {
        eprintln!("error: --force needs --record FILE or --csv FILE");
        return Ok(ExitCode::from(2));
    }
    let vtk = &args.vtk;
    if record.is_none() && cadence.given() {
        eprintln!("error: --record-every, --record-dt, --record-fields and --record-sync need --record FILE");
        return Ok(ExitCode::from(2));
    }
    if let Some(r) = record {
        if let Err(e) = check_record_target(r, Some(path), force) {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(2));
        }
    }
    if let Some(c) = &args.csv {
        let ours = |m: &[u8]| m.starts_with(b"step,");
        if let Err(e) = check_output_target("--csv", c, Some(path), force, "a step table", "run.csv", ours) {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(2));
        }
        if record.is_some_and(|r| r == c.as_path()) {
            eprintln!("error: --csv and --record name the same file");
            return Ok(ExitCode::from(2));
        }
    }
    let (mut sim, text) = match load(path, limits) {
        Ok(s) => s,
        Err(code) => return Ok(code),
    };
    if let Err(code) = use_threads(&mut sim, args.threads, quiet) {
        return Ok(code);
    }
    if let Some(file) = &args.resume {
        match sim.resume_from(file, &text) {
            Ok(step) => out!("resumed from {} at step {step}", file.display()),
            Err(e) => {
                eprintln!("error: {e}");
                return Ok(ExitCode::from(2));
            }
        }
    }
    let mut checkpoints = match &args.checkpoint {
        Some(dir) => {
            let every = args.checkpoint_every.map_or(usize::MAX, |n| n as usize);
            match mpmlab::checkpoint::Checkpointer::create(dir, every, &text) {
                Ok(c) => Some(c),
                Err(e) => {
                    eprintln!("error: {e}");
                    return Ok(ExitCode::from(3));
                }
            }
        }
        None => None,
    };
    let settings = match cadence.settings(&sim) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(2));
        }
    };
    let mut recorder = match record {
        Some(p) => match cadence.create(p, &text, &sim, settings) {
            Ok(r) => {
                if let Some(f) = &args.resume {
                    let _ = r.event(
                        &format!("resumed from checkpoint {} at step {}", f.display(), sim.step_index()),
                        "INFO",
                    );
                }
                Some(r)
            }
            Err(e) => {
                eprintln!("error: {e}");
                return Ok(ExitCode::from(3));
            }
        },
        None => None,
    };
    let mut csv = match &args.csv {
        Some(p) => match mpmlab::csv::CsvWriter::create(p, &sim) {
            Ok(w) => Some(w),
            Err(e) => {
                eprintln!("error: {e}");
                return Ok(ExitCode::from(3));
            }
        },
        None => None,
    };
    let mut vtk = match vtk.open(&sim) {
        Ok(v) => v,
        Err(code) => return Ok(code),
    };
    let m = sim.model();
    let u = m.units;
    out!(
        "scene `{}`: grid {}x{} h={} {}, {} points, {} {} steps; {}",
        m.name,
        m.grid.nx,
        m.grid.ny,
        m.grid.h,
        u.of(Quantity::Length),
        sim.points().len(),
        m.analysis.load_steps,
        if sim.time().is_some() { "time" } else { "load" },
        u.describe()
    );
    let mut code = ExitCode::SUCCESS;
    let mut table = Table {
        quiet,
        last: None,
        total_time: 0.0,
        phases: Default::default(),
        cutbacks: 0,
    };
    // Ctrl-C or SIGTERM: cancel the running step, keep the last good state
    // and close the recording; a second one ends the process at once.
    let stop = stop_on_signals();
    let mut detached = Vec::new();
    let end = mpmlab::runner::run(
        &mut sim,
        // The recorder first: a printed step line means the step is in the
        // file (`Recorder::sync`), whatever happens to the process next.
        &mut [&mut recorder, &mut table, &mut csv, &mut checkpoints, &mut vtk],
        &stop,
        &mut detached,
    );
    for d in &detached {
        eprintln!("error: {d}; continuing without it");
        code = ExitCode::from(3);
    }
    match end {
        RunEnd::Finished => {}
        RunEnd::Failed(f) => {
            eprintln!("error: {f}");
            code = ExitCode::from(1);
        }
        RunEnd::Stopped { after } => {
            // The last good state, to resume from.
            if let Some(c) = checkpoints.as_mut() {
                match c.write(&sim) {
                    Ok(p) => eprintln!("checkpoint of step {after}: {}", p.display()),
                    Err(e) => eprintln!("error: {e}"),
                }
            }
            let text = format!("interrupted after step {after}: the run stops here");
            eprintln!("{text}");
            if let Some(rec) = recorder.as_mut() {
                let _ = rec.event(&text, "WARN");
            }
            code = ExitCode::from(130);
        }
    }
    let (last, total_time, phases) = (table.last, table.total_time, table.phases);
    let (en, force, len) = (u.of(Quantity::Energy), u.of(Quantity::Force), u.of(Quantity::Length));
    let cutbacks = table.cutbacks;
    if let Some(r) = &last {
        let errs: Vec<String> = r
            .errors
            .iter()
            .map(|e| format!("{} = {:.4e}", e.name, e.value))
            .collect();
        out!(
            "summary: {}/{} steps, {:.3} s in steps, final strain energy {:.6e} {en}, work {:.6e} {en}{}{}{}",
            sim.step_index(),
            sim.load_steps(),
            total_time,
            r.energy.strain,
            r.energy.external_work,
            // The ghost penalty's share of the work (quasi-static, ghost on).
            if r.energy.ghost != 0.0 {
                format!(", ghost penalty {:.6e} {en}", r.energy.ghost)
            } else {
                String::new()
            },
            r.condition.map_or(String::new(), |c| format!(
                ", {} {:.3e} ({})",
                // Explicit dynamics conditions the mass it solves with.
                r.dynamics
                    .as_ref()
                    .map_or("cond(K)".to_string(), |d| format!("cond(M {})", d.mass.label())),
                c.value,
                c.method.label()
            )),
            if errs.is_empty() {
                String::new()
            } else {
                format!(", {}", errs.join(", "))
            }
        );
    }
    if last.is_some() {
        let p = &phases;
        out!(
            "phases (s): mapping {:.3}, pattern {:.3}, assembly {:.3}, factorisation {:.3}, solve {:.3}, \
             condition {:.3}, update {:.3}, other {:.3}; {} cutbacks; peak memory {:.0} MB",
            p.mapping,
            p.pattern,
            p.assembly,
            p.factorisation,
            p.solve,
            p.condition,
            p.update,
            p.other(),
            cutbacks,
            mpmlab::sweep::peak_rss_kb() as f64 / 1024.0
        );
    }
    if let Some((r, d)) = last.as_ref().and_then(|r| r.dynamics.as_ref().map(|d| (r, d))) {
        out!(
            "dynamics: t = {:.6} s, kinetic {:.6e} {en}, strain {:.6e} {en}, plastic {:.6e} {en}, initial {:.6e} {en}, balance error {:.3e} {en}, momentum ({:.6e}, {:.6e}) {}",
            d.time,
            r.energy.kinetic,
            r.energy.strain,
            r.energy.plastic_dissipation,
            d.initial_energy,
            d.energy_error,
            d.momentum[0],
            d.momentum[1],
            u.of(Quantity::Momentum)
        );
    }
    if let Some(r) = &last {
        for b in &r.ibm {
            out!(
                "implicit boundary `{}` (step {}): reaction ({:.6e}, {:.6e}) {force}, violation {:.2e} {len} (rms {:.2e} {len}), {} cells cut{}",
                b.name,
                r.step,
                b.reaction[0],
                b.reaction[1],
                b.violation,
                b.violation_rms,
                b.cut_cells,
                if b.fit_regularisation > 0.0 {
                    format!(", fit regularised (weight {:e})", b.fit_regularisation)
                } else {
                    String::new()
                }
            );
        }
        for b in &r.boundaries {
            out!(
                "boundary `{}` (start of step {}): length {:.6} {len}{}, {} cells cut, traction resultant ({:.6e}, {:.6e}) {force}{}",
                b.name,
                r.step,
                b.length,
                b.area.map_or(String::new(), |a| format!(", area {a:.6} {}", u.of(Quantity::Area))),
                b.cells_cut,
                b.resultant[0],
                b.resultant[1],
                if b.lost > 0.0 { format!(", LOST {:.3e} {force} on inactive nodes", b.lost) } else { String::new() }
            );
        }
    }
    if let Some(r) = &last {
        for p in &r.probes {
            let cols: Vec<String> = p
                .columns()
                .iter()
                .map(|(k, q, v)| format!("{k} {v:.6e} {}", u.of(*q)))
                .collect();
            out!("probe `{}` (step {}): {}", p.name, r.step, cols.join(", "));
        }
    }
    if let (Some(c), Some(dir)) = (&checkpoints, &args.checkpoint) {
        if let Some(step) = c.last() {
            let f = dir.join(mpmlab::checkpoint::file_name(step));
            out!(
                "checkpoint: {} (resume: mpmlab run {} --resume {})",
                f.display(),
                path.display(),
                f.display()
            );
        }
    }
    if let Some(c) = &csv {
        out!("step table: {}", c.path().display());
    }
    if let Some(mut rec) = recorder {
        let p = rec.path().display().to_string();
        // The last state reached, whatever the cadence.
        let _ = rec.log_final_state(&sim);
        let _ = rec.event(
            if code == ExitCode::SUCCESS {
                "run complete"
            } else {
                "run ended early"
            },
            "INFO",
        );
        match rec.finish() {
            Ok(size) => {
                out!("recording: {p}  (replay: rerun {p})");
                out!("recording size: {size}");
            }
            Err(e) => {
                eprintln!("error: {e}");
                code = ExitCode::from(3);
            }
        }
    }
    if let Some(v) = vtk {
        match v.finish(&sim) {
            Ok(summary) => out!("vtk: {summary}"),
            Err(e) => {
                eprintln!("error: {e}");
                code = ExitCode::from(3);
            }
        }
    }
    Ok(code)
}

/// Arguments of `mpmlab sweep`.
#[derive(clap::Args)]
struct SweepArgs {
    /// Scene file (not with --preset or --collect).
    scene: Option<PathBuf>,
    /// `key=v1,v2,...`; keys: h, ppc, delta_over_h, gamma_k, gamma_m,
    /// steps, tolerance, mass, ... or a dotted scene path
    /// (`analysis.max_iterations`, `body.0.basis`).
    #[arg(long = "vary", value_name = "KEY=V1,V2,...")]
    vary: Vec<String>,
    /// A paper study: plate-hole-h, delta, beam-stability, column-gamma.
    #[arg(long, conflicts_with = "scene")]
    preset: Option<String>,
    /// Runs at a time (each single-threaded, in its own process), 1 or more.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..))]
    jobs: u16,
    /// Sweep folder (default sweeps/<scene or preset>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write one command per pending run to <out>/jobs.txt instead of running.
    #[arg(long)]
    emit_jobs: bool,
    /// Record each run to <out>/recordings/<id>.rrd (with the scene's
    /// `[record]` settings, which `--vary record.every=...` can change);
    /// the CSV then holds the recording's size per step and per point.
    #[arg(long)]
    record: bool,
    /// Require a refinement study: `--vary h=...` with three or more cell
    /// sizes, from which every probe and energy gets its observed order,
    /// Richardson-extrapolated value and grid convergence index (also
    /// computed, without this flag, whenever h takes three values).
    #[arg(long)]
    estimate: bool,
    /// Find the cheapest discretisation meeting an error target instead of
    /// a cross product: `error:<name>=TOL` (against the exact solution) or
    /// `probe:<name>:<key>=TOL` / `energy:<name>=TOL` (relative GCI of
    /// three refinements). Refines h coarse to fine at the scene's points
    /// per cell and twice them, predicting from the observed order.
    #[arg(long, value_name = "QUANTITY=TOL", conflicts_with_all = ["vary", "preset", "emit_jobs", "record"])]
    target: Option<String>,
    /// Seconds of runs a --target search may spend.
    #[arg(long, default_value_t = 300.0, requires = "target")]
    budget: f64,
    /// With --target: other settings to search, each value a family of
    /// its own refined in h (`body.0.placement=centres,clipped`,
    /// `body.0.basis=standard,gimp`, `steps=10,20`, `gamma_k=0,1e5`).
    #[arg(long = "try", value_name = "KEY=V1,V2,...", requires = "target")]
    tries: Vec<String>,
    /// Merge the results in this sweep folder (from --emit-jobs runs) and chart them.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["scene", "preset", "vary", "emit_jobs"])]
    collect: Option<PathBuf>,
}

/// `mpmlab sweep --collect DIR`: merge the results, warn about runs
/// without a result and failed runs; exit 1 when nothing was collected.
fn collect(dir: &Path) -> Result<ExitCode> {
    use mpmlab::sweep::{driver, Folder};
    let folder = Folder(dir.to_path_buf());
    let order: Vec<String> = std::fs::read_to_string(dir.join("runs.txt"))
        .map(|t| t.lines().filter(|l| !l.is_empty()).map(str::to_string).collect())
        .unwrap_or_default();
    if !dir.is_dir() || (order.is_empty() && !folder.results().is_dir() && !folder.csv().is_file()) {
        eprintln!(
            "error: {} is not a sweep folder (no runs.txt, results/ or sweep.csv)",
            dir.display()
        );
        return Ok(ExitCode::from(2));
    }
    let found = folder.collect();
    let missing: Vec<&String> = order.iter().filter(|id| !found.contains_key(*id)).collect();
    let listed = |ids: &[&String]| {
        let mut s = ids.iter().take(10).map(|s| s.as_str()).collect::<Vec<_>>().join(", ");
        if ids.len() > 10 {
            s.push_str(&format!(", ... ({} more)", ids.len() - 10));
        }
        s
    };
    if !missing.is_empty() {
        eprintln!(
            "warning: {} of {} runs have no result (not run yet, or their process died): {}",
            missing.len(),
            order.len(),
            listed(&missing)
        );
    }
    let collected: Vec<_> = if order.is_empty() {
        found.values().collect()
    } else {
        order.iter().filter_map(|id| found.get(id)).collect()
    };
    let failed: Vec<&String> = collected.iter().filter(|r| !r.completed).map(|r| &r.id).collect();
    if !failed.is_empty() {
        eprintln!(
            "warning: {} of {} collected runs did not complete: {}",
            failed.len(),
            collected.len(),
            listed(&failed)
        );
    }
    if collected.is_empty() {
        eprintln!("error: nothing to collect in {}: no run has a result", dir.display());
        return Ok(ExitCode::from(1));
    }
    let title = dir
        .file_name()
        .map_or("sweep".into(), |n| n.to_string_lossy().into_owned());
    out!("{}", driver::finish(&folder, &title).map_err(anyhow::Error::msg)?);
    Ok(ExitCode::SUCCESS)
}

/// Every run's scene must parse (every --vary key names a scene field,
/// every value has its type and range) before anything is written or run.
/// Runs whose scene then fails validation (an `h` that does not divide the
/// grid) are warned about and become failed rows, unless every run does.
fn validate_runs(base: &str, fixed: &[(String, String)], runs: &[mpmlab::sweep::Run]) -> Result<(), String> {
    let mut texts = Vec::new();
    for r in runs {
        let settings: Vec<String> = r.settings.iter().map(|(k, v)| format!("{k}={v}")).collect();
        let what = format!("run `{}` ({})", r.id, settings.join(" "));
        let text = mpmlab::sweep::run_scene(base, fixed, r).map_err(|e| format!("{what}: {e}"))?;
        if let Err(e) = Scene::parse(&text, &r.id) {
            return Err(format!(
                "{what} is not a valid scene: field `{}`: {}",
                e.field, e.message
            ));
        }
        texts.push((text, what));
    }
    let mut invalid = Vec::new();
    for (text, what) in &texts {
        if let Err(e) = Model::from_text(text, "run") {
            invalid.push(format!(
                "{what} is not a valid scene: field `{}`: {}",
                e.field, e.message
            ));
        }
    }
    if !invalid.is_empty() && invalid.len() == texts.len() {
        return Err(format!(
            "no run is a valid scene; the first: {}",
            invalid.swap_remove(0)
        ));
    }
    for w in invalid {
        eprintln!("warning: {w}; it will be a failed row");
    }
    Ok(())
}

/// `mpmlab sweep`: plan, run (or emit) and summarise. Exit 2 for bad
/// arguments or scenes, including any run whose settings make an invalid
/// scene (checked before anything runs); failed runs are rows of the
/// table, not errors.
fn sweep(a: SweepArgs) -> Result<ExitCode> {
    use mpmlab::sweep::{driver, expand, presets, Folder, Vary};
    if let Some(dir) = a.collect {
        return collect(&dir);
    }
    let (name, path, fixed, mut varies) = match (&a.preset, &a.scene) {
        (Some(p), _) => {
            let pr = presets::preset(p)
                .with_context(|| format!("no preset `{p}`; presets: {}", presets::NAMES.join(", ")))?;
            out!("preset `{}`: {}", pr.name, pr.about);
            let path = PathBuf::from("scenarios").join(format!("{}.toml", pr.scene));
            (pr.name.to_string(), path, pr.fixed, pr.vary)
        }
        (None, Some(s)) => (
            s.file_stem()
                .map_or("sweep".into(), |n| n.to_string_lossy().into_owned()),
            s.clone(),
            Vec::new(),
            Vec::new(),
        ),
        (None, None) => anyhow::bail!("give a scene file, --preset NAME or --collect DIR"),
    };
    if let Some(t) = &a.target {
        let mut tries = Vec::new();
        for t in &a.tries {
            match Vary::parse(t) {
                Ok(v) => tries.push(v),
                Err(e) => {
                    eprintln!("error: --try {e}");
                    return Ok(ExitCode::from(2));
                }
            }
        }
        return target_search(&name, &path, a.out.clone(), t, a.budget, tries);
    }
    for v in &a.vary {
        varies.push(Vary::parse(v).map_err(anyhow::Error::msg)?);
    }
    if varies.is_empty() {
        anyhow::bail!("nothing to vary: give --vary KEY=V1,V2,...");
    }
    if a.estimate {
        let sizes = |v: &Vary| {
            let mut x: Vec<String> = v.values.clone();
            x.sort();
            x.dedup();
            x.len()
        };
        if !varies
            .iter()
            .any(|v| (v.key == "h" || v.key == "grid.h") && sizes(v) >= 3)
        {
            eprintln!("error: --estimate needs a refinement study: --vary h=V1,V2,V3 (three or more cell sizes)");
            return Ok(ExitCode::from(2));
        }
    }
    // The base scene must be valid before anything is written.
    let base = match mpmlab::scene::read_scene_text(&path) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(2));
        }
    };
    if let Err(code) = load(&path, &Limits::default()) {
        return Ok(code);
    }
    if let Err(e) = validate_runs(&base, &fixed, &expand(&varies)) {
        eprintln!("error: --vary: {e}");
        return Ok(ExitCode::from(2));
    }
    let folder = Folder(a.out.unwrap_or_else(|| PathBuf::from("sweeps").join(&name)));
    let runs = driver::prepare(&folder, &base, &fixed, &varies).map_err(anyhow::Error::msg)?;
    let todo = driver::pending(&folder, &runs);
    let exe = std::env::current_exe().context("cannot find the mpmlab executable")?;
    out!(
        "sweep `{name}` in {}: {} runs, {} already done",
        folder.0.display(),
        runs.len(),
        runs.len() - todo.len()
    );
    if a.emit_jobs {
        let p = driver::emit_jobs(&folder, &exe, &todo, a.record).map_err(anyhow::Error::msg)?;
        let p = std::path::absolute(&p).unwrap_or(p);
        out!(
            "wrote {} commands to {} (absolute paths: run them from any directory, e.g. `parallel < {}`), then `mpmlab sweep --collect {}`",
            todo.len(),
            p.display(),
            p.display(),
            folder.0.display()
        );
        return Ok(ExitCode::SUCCESS);
    }
    driver::execute(&folder, &exe, &todo, usize::from(a.jobs), a.record, &|line| {
        out!("{line}")
    });
    out!("{}", driver::finish(&folder, &name).map_err(anyhow::Error::msg)?);
    Ok(ExitCode::SUCCESS)
}

/// Arguments of `mpmlab verify`.
#[derive(clap::Args)]
struct VerifyArgs {
    /// Only the rows CI runs (about a minute); the full set takes longer.
    #[arg(long)]
    quick: bool,
    /// Also write the rows as CSV
    /// (`benchmark,quantity,paper,ours,ratio,tolerance,pass,why`).
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
    /// Rewrite the generated table of this Markdown file (between its
    /// `verify` markers; e.g. docs/verification.md) with the rows.
    #[arg(long, value_name = "FILE")]
    write_docs: Option<PathBuf>,
    /// Folder of the shipped scenes.
    #[arg(long, default_value = "scenarios")]
    scenes: PathBuf,
}

/// `mpmlab verify`: the papers' numbers against ours. Exit 0 when every
/// row passes, 1 when one fails, 130 when interrupted.
fn verify(a: &VerifyArgs) -> Result<ExitCode> {
    use mpmlab::verify;
    if !a.scenes.is_dir() {
        eprintln!("error: {}: no such folder of scenes", a.scenes.display());
        return Ok(ExitCode::from(2));
    }
    if a.quick && a.write_docs.is_some() {
        eprintln!("error: --write-docs needs the full set (without --quick)");
        return Ok(ExitCode::from(2));
    }
    let stop = stop_on_signals();
    let verify::Verified { rows, tables } = verify::verify(&a.scenes, a.quick, &stop, &mut |line| eprintln!("{line}"));
    if stop.load(std::sync::atomic::Ordering::Relaxed) {
        eprintln!("interrupted");
        return Ok(ExitCode::from(130));
    }
    out!("{}", verify::table(&rows));
    if let Some(p) = &a.csv {
        std::fs::write(p, verify::csv(&rows)).with_context(|| format!("cannot write {}", p.display()))?;
        out!("csv: {}", p.display());
    }
    if let Some(p) = &a.write_docs {
        let doc = std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?;
        let mut doc = verify::replace_section(&doc, "rows", &verify::markdown(&rows));
        for (name, table) in &tables {
            doc = verify::replace_section(&doc, name, table);
        }
        std::fs::write(p, doc).with_context(|| format!("cannot write {}", p.display()))?;
        out!("table written into {}", p.display());
    }
    Ok(if rows.iter().all(|r| r.pass) {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// `mpmlab sweep SCENE --target Q=TOL`: the cheapest run meeting a target
/// (exit 0 when one does, 1 when none did within the budget).
fn target_search(
    name: &str,
    path: &Path,
    out: Option<PathBuf>,
    target: &str,
    budget: f64,
    tries: Vec<mpmlab::sweep::Vary>,
) -> Result<ExitCode> {
    use mpmlab::scene::Placement;
    use mpmlab::sweep::{driver, target, Folder};
    let t = match target::Target::parse(target) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: --target {e}");
            return Ok(ExitCode::from(2));
        }
    };
    if !(budget > 0.0 && budget.is_finite()) {
        eprintln!("error: --budget must be a positive number of seconds");
        return Ok(ExitCode::from(2));
    }
    let base = match mpmlab::scene::read_scene_text(path) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(2));
        }
    };
    let scene = match mpmlab::scene::Scene::parse(&base, &path.display().to_string()) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(2));
        }
    };
    if let Err(code) = load(path, &Limits::default()) {
        return Ok(code);
    }
    if !tries.is_empty() {
        if let Err(e) = validate_runs(&base, &[], &mpmlab::sweep::expand(&tries)) {
            eprintln!("error: --try: {e}");
            return Ok(ExitCode::from(2));
        }
    }
    // Points per cell is a setting of the search only where every body
    // places its points per cell.
    let ppc = scene
        .bodies
        .iter()
        .all(|b| b.lattice.is_none() && b.placement != Placement::Polar)
        .then(|| scene.bodies.first().map(|b| b.points_per_cell))
        .flatten();
    let folder = Folder(out.unwrap_or_else(|| PathBuf::from("sweeps").join(format!("{name}-target"))));
    let exe = std::env::current_exe().context("cannot find the mpmlab executable")?;
    out!(
        "searching {} for {} <= {:e} within {budget} s of runs, in {}",
        path.display(),
        t.quantity,
        t.tol,
        folder.0.display()
    );
    let found = target::search(
        &folder,
        &exe,
        &base,
        target::Start {
            h: scene.grid.h,
            ppc,
            tries,
        },
        &t,
        budget,
        &|line| out!("{line}"),
    )
    .map_err(anyhow::Error::msg)?;
    out!("{}", driver::finish(&folder, name).map_err(anyhow::Error::msg)?);
    out!("{}", target::report(&found));
    Ok(if found.best.is_some() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// `mpmlab replay FILE`: the rerun viewer on a recording, if installed;
/// otherwise the exact command that installs the matching viewer (exit 1).
/// `mpmlab repair IN OUT`: 0 repaired (or copied, when IN was complete),
/// 2 bad arguments or an IN that is not a recording or holds nothing
/// whole, 3 OUT cannot be written.
fn repair(input: &Path, output: &Path, force: bool) -> ExitCode {
    use mpmlab::record::repair::RepairError;
    let same = matches!(
        (std::fs::canonicalize(input), std::fs::canonicalize(output)),
        (Ok(a), Ok(b)) if a == b
    );
    if same {
        eprintln!(
            "error: the output {} is the input itself; give another path (the input is left as it is)",
            output.display()
        );
        return ExitCode::from(2);
    }
    if let Err(e) = check_output_target(
        "output",
        output,
        None,
        force,
        "a rerun recording",
        "repaired.rrd",
        is_rrd,
    ) {
        eprintln!("error: {e}");
        return ExitCode::from(2);
    }
    match mpmlab::record::repair::repair(input, output) {
        Ok(r) => {
            out!("repaired {} into {}: {r}", input.display(), output.display());
            ExitCode::SUCCESS
        }
        Err(e @ RepairError::Write { .. }) => {
            eprintln!("error: {e}");
            ExitCode::from(3)
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}

fn replay(file: &Path) -> Result<ExitCode> {
    use mpmlab::record::RERUN_VERSION;
    if !file.is_file() {
        anyhow::bail!("{}: no such recording", file.display());
    }
    let viewer = std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|d| d.join("rerun"))
            .find(|p| p.is_file())
    });
    let Some(viewer) = viewer else {
        out!(
            "the rerun viewer is not installed; install the version that reads these recordings and open it with:\n  pip install rerun-sdk=={RERUN_VERSION}\n  rerun {}",
            file.display()
        );
        return Ok(ExitCode::from(1));
    };
    let status = std::process::Command::new(&viewer)
        .arg(file)
        .status()
        .with_context(|| format!("cannot start {}", viewer.display()))?;
    Ok(if status.success() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// `mpmlab tui --sweep DIR`: the sweep view.
fn sweep_view(dir: &Path) -> Result<ExitCode> {
    if !dir.join("runs.txt").exists() && !dir.join("sweep.csv").exists() {
        anyhow::bail!("{} is not a sweep folder (no runs.txt or sweep.csv)", dir.display());
    }
    let folder = mpmlab::sweep::Folder(dir.to_path_buf());
    let title = dir
        .file_name()
        .map_or("sweep".into(), |n| n.to_string_lossy().into_owned());
    mpmlab::tui::sweep::run(&folder, &title).context("terminal")?;
    Ok(ExitCode::SUCCESS)
}

/// `mpmlab sweep-run`: one run, its result row to `result`.
fn sweep_run(scene: &Path, result: &Path, record: Option<&Path>) -> Result<ExitCode> {
    let r = mpmlab::sweep::run_file_recorded(scene, record);
    if let Some(dir) = result.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    std::fs::write(result, mpmlab::sweep::to_csv(std::slice::from_ref(&r)))
        .with_context(|| format!("cannot write {}", result.display()))?;
    Ok(ExitCode::SUCCESS)
}

fn timestamp() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}{m:02}{d:02}-{:02}{:02}{:02}",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// The scenes of `dir` in the picker; `None` when the user quits.
fn pick_scene(dir: &Path) -> Result<Option<PathBuf>> {
    use mpmlab::tui::picker::{pick, Entry, Picker};
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    paths.sort();
    let entries: Vec<Entry> = paths
        .into_iter()
        .filter_map(|path| {
            let text = mpmlab::scene::read_scene_text(&path).ok()?;
            let s = Scene::parse(&text, &path.display().to_string()).ok()?;
            Some(Entry {
                path,
                name: s.scene.name,
                description: s.scene.description.split_whitespace().collect::<Vec<_>>().join(" "),
            })
        })
        .collect();
    let default = entries
        .iter()
        .position(|e| e.path == Path::new(DEFAULT_SCENE))
        .unwrap_or(0);
    let picker = Picker {
        entries,
        selected: default,
        default,
    };
    Ok(pick(picker).context("terminal UI")?.map(|e| e.path))
}

fn tui(
    scene: Option<&Path>,
    record: Option<PathBuf>,
    no_record: bool,
    force: bool,
    cadence: &RecordArgs,
    engine: &Engine,
    resume: Option<&Path>,
) -> Result<ExitCode> {
    let (limits, threads) = (&engine.limits, engine.threads);
    if resume.is_some() && scene.is_none() {
        eprintln!("error: --resume needs the scene file the checkpoint was written for");
        return Ok(ExitCode::from(2));
    }
    if let Some(r) = &record {
        if let Err(e) = check_record_target(r, scene, force) {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(2));
        }
    }
    let (mut sim, text) = match scene {
        Some(p) => match load(p, limits) {
            Ok(s) => s,
            Err(code) => return Ok(code),
        },
        None if Path::new(DEFAULT_SCENE).exists() => {
            // The scene picker, the default highlighted (only on a terminal).
            use std::io::IsTerminal;
            let path = if std::io::stdin().is_terminal() {
                match pick_scene(Path::new("scenarios"))? {
                    Some(p) => p,
                    None => return Ok(ExitCode::SUCCESS),
                }
            } else {
                PathBuf::from(DEFAULT_SCENE)
            };
            match load(&path, limits) {
                Ok(s) => s,
                Err(code) => return Ok(code),
            }
        }
        None => match Simulation::from_scene_text(DEFAULT_SCENE_TEXT, DEFAULT_SCENE) {
            Ok(s) => (s, DEFAULT_SCENE_TEXT.to_string()),
            Err(e) => {
                eprintln!("error: {e}");
                return Ok(ExitCode::from(2));
            }
        },
    };
    if let Err(code) = use_threads(&mut sim, threads, true) {
        return Ok(code);
    }
    if let Some(file) = resume {
        if let Err(e) = sim.resume_from(file, &text) {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(2));
        }
    }
    let recorder = if no_record {
        None
    } else {
        let path =
            record.unwrap_or_else(|| PathBuf::from(format!("recordings/{}-{}.rrd", sim.model().name, timestamp())));
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        }
        let settings = match cadence.settings(&sim) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("error: {e}");
                return Ok(ExitCode::from(2));
            }
        };
        match cadence.create(&path, &text, &sim, settings) {
            Ok(r) => {
                if let Some(f) = resume {
                    let _ = r.event(
                        &format!(
                            "resumed from checkpoint {} at step {}: this recording is a branch from there",
                            f.display(),
                            sim.step_index()
                        ),
                        "INFO",
                    );
                }
                Some(r)
            }
            Err(e) => {
                eprintln!("error: {e}");
                return Ok(ExitCode::from(3));
            }
        }
    };
    let path = recorder.as_ref().map(|r| r.path().display().to_string());
    mpmlab::tui::run(sim, text, recorder).context("terminal UI")?;
    if let Some(p) = path {
        out!("recording: {p}  (replay: rerun {p})");
    }
    Ok(ExitCode::SUCCESS)
}
