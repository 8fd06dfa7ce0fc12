//! What a recording costs: the wall time of a whole run with a recording
//! (default cadence and fields, from creating the file to closing it)
//! over the same run without one, on
//!
//! - `explicit`: the 102,400-point explicit block
//!   (`benches/scenes/explicit-block.toml`, 100 steps), and
//! - `newton`: the G 5.5 beam refined to h = 1/24 m (23,040 points,
//!   10 Newton load steps of at most 30 iterations).
//!
//! Runs alternate (without, with) `MPMLAB_BENCH_REPEATS` times (default
//! 3) so that both see the same machine; the ratios of the medians and of
//! the fastest runs are printed with the recording's size, and the time
//! the engine's thread spent in the recorder's calls (creating the file,
//! logging the steps, closing it), which the machine's other load
//! disturbs less than the wall times.
//!
//! `cargo bench --bench record` (or `-- explicit`, `-- newton` for one).

use mpmlab::record::Recorder;
use mpmlab::scene::Scene;
use mpmlab::{Model, Simulation};
use std::path::Path;
use std::time::Instant;

struct Case {
    name: &'static str,
    scene: &'static str,
    edit: fn(&mut Scene),
}

const CASES: [Case; 2] = [
    Case {
        name: "explicit",
        scene: "benches/scenes/explicit-block.toml",
        edit: |_| {},
    },
    Case {
        name: "newton",
        scene: "scenarios/elastic-beam-ghost.toml",
        edit: |s| {
            s.grid.h /= 12.0;
            s.analysis.load_steps = 10;
            s.analysis.max_iterations = 30;
        },
    },
];

fn simulation(case: &Case) -> (Simulation, String) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(case.scene);
    let text = std::fs::read_to_string(&path).expect("scene");
    let file = path.display().to_string();
    let mut scene = Scene::parse(&text, &file).expect("valid scene");
    (case.edit)(&mut scene);
    (
        Simulation::new(Model::build(&scene, &text, &file).expect("valid scene")),
        text,
    )
}

/// One run to the end (or its first failure, reported): wall seconds,
/// the seconds spent in the recorder's calls and, when recorded, the
/// recording's size.
fn run(case: &Case, record: Option<&Path>) -> (f64, f64, Option<mpmlab::record::RecordingSize>) {
    let (mut sim, text) = simulation(case);
    let start = Instant::now();
    let mut in_recorder = 0.0;
    let t = Instant::now();
    let mut rec = record.map(|p| Recorder::create(p, &text, &sim, false).expect("recording"));
    in_recorder += t.elapsed().as_secs_f64();
    while !sim.finished() {
        match sim.step() {
            Ok(r) => {
                if let Some(rec) = rec.as_mut() {
                    let t = Instant::now();
                    rec.log_step(&r, &sim).expect("recorded");
                    in_recorder += t.elapsed().as_secs_f64();
                }
            }
            Err(f) => {
                eprintln!("record/{}: {f}", case.name);
                break;
            }
        }
    }
    let t = Instant::now();
    let size = rec.map(|r| r.finish().expect("recording closed"));
    in_recorder += t.elapsed().as_secs_f64();
    (start.elapsed().as_secs_f64(), in_recorder, size)
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

fn main() {
    let repeats: usize = std::env::var("MPMLAB_BENCH_REPEATS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3)
        .max(1);
    let only: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with("--")).collect();
    let rrd = std::env::temp_dir().join(format!("mpmlab-bench-record-{}.rrd", std::process::id()));
    for case in CASES
        .iter()
        .filter(|c| only.is_empty() || only.iter().any(|o| c.name.contains(o.as_str())))
    {
        let (mut without, mut with, mut inside, mut size) = (Vec::new(), Vec::new(), Vec::new(), None);
        for k in 0..repeats {
            let (t0, _, _) = run(case, None);
            let (t1, r, s) = run(case, Some(&rrd));
            println!(
                "record/{} run {}: {t0:.3} s without, {t1:.3} s with a recording ({r:.3} s of it in the recorder's calls)",
                case.name,
                k + 1
            );
            without.push(t0);
            with.push(t1);
            inside.push(r);
            size = s;
        }
        let min = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
        println!(
            "record/{}: median {:.3} s without, {:.3} s with: ratio {:.3}; fastest {:.3} s / {:.3} s: ratio {:.3}",
            case.name,
            median(&without),
            median(&with),
            median(&with) / median(&without),
            min(&without),
            min(&with),
            min(&with) / min(&without)
        );
        println!(
            "record/{}: the recorder's calls took {:.3} s (median), {:.1}% of the median unrecorded run",
            case.name,
            median(&inside),
            100.0 * median(&inside) / median(&without)
        );
        if let Some(s) = size {
            println!("record/{}: recording {s}", case.name);
        }
    }
    let _ = std::fs::remove_file(&rrd);
}
