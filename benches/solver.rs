//! The solver benchmark: one table of phase times, unknowns and peak
//! memory for the scenes that size the implicit solver, each run as its own
//! `mpmlab run` process (so each peak memory is its own), and the ratios the
//! solver is held to:
//!
//! - a linear block of 10^5 unknowns (standard basis, 2x2 points per cell)
//!   with the default condition estimate and with conditioning off;
//! - the same at 10^6 unknowns (one load step each; skip with
//!   `MPMLAB_BENCH_SMALL=1`);
//! - a 65,536-point GIMP block, linear and finite deformation: one Newton
//!   iteration against one linear step on the same grid and points; and
//!   4 implicit dynamic steps against 4 quasi-static Newton steps;
//! - the 102,400-point finite-deformation block, 40 load steps;
//! - the 102,400-point explicit block (point-steps per second);
//! - a finite-deformation block of about 10^5 unknowns, one step on one
//!   thread and on two (`--threads 2`).
//!
//! `cargo bench --bench solver`. Times are wall-clock, one run each, on
//! whatever else the machine is doing: compare ratios within one run.

use std::path::{Path, PathBuf};
use std::process::Command;

/// What one `mpmlab run` printed, summed over its steps.
#[derive(Debug, Default)]
struct Run {
    name: String,
    unknowns: usize,
    steps: usize,
    iterations: usize,
    points: usize,
    /// mapping, pattern, assembly, factorisation, solve, condition, update, other
    phases: [f64; 8],
    total: f64,
    peak_mb: f64,
}

fn block(name: &str, cells: usize, basis: &str, kind: &str, steps: usize, condition: &str) -> String {
    // Implicit dynamics: one step of 0.1 s each (the block starts at rest
    // and falls onto its rollers under gravity).
    let duration = if kind == "dynamic-implicit" {
        format!("duration = {}\n", 0.1 * steps as f64)
    } else {
        String::new()
    };
    format!(
        r#"[scene]
name = "{name}"
[grid]
origin = [0.0, 0.0]
size = [{cells}.0, {cells}.0]
h = 1.0
[[material]]
name = "m"
E = 1.0e8
nu = 0.3
density = 1000.0
[[body]]
name = "block"
material = "m"
points_per_cell = 2
basis = "{basis}"
region = {{ shape = "rectangle", min = [0.0, 0.0], max = [{cells}.0, {cells}.0] }}
[[dirichlet]]
kind = "roller"
x = 0.0
[[dirichlet]]
kind = "roller"
x = {cells}.0
[[dirichlet]]
kind = "roller"
y = 0.0
[loads]
gravity = [0.0, -10.0]
[analysis]
kind = "{kind}"
load_steps = {steps}
condition = "{condition}"
{duration}"#
    )
}

fn num(s: &str) -> &str {
    s.trim_matches(|c: char| !c.is_ascii_digit() && c != '.' && c != '-' && c != 'e')
}

fn run(dir: &Path, name: &str, scene: &str, steps: Option<usize>, threads: usize) -> Run {
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, scene).expect("write the bench scene");
    let out = Command::new(env!("CARGO_BIN_EXE_mpmlab"))
        // The scene's memory estimate is an upper bound made for refusing
        // hostile scenes; the 10^6-unknown block is meant to run.
        .args(["run", path.to_str().expect("utf-8 path"), "--max-memory", "20G"])
        .args(["--threads", &threads.to_string()])
        .output()
        .expect("run mpmlab");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{name}: {text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut r = Run {
        name: name.into(),
        ..Default::default()
    };
    // The step table's columns, right-aligned under their headers (the
    // quasi-static and dynamic tables differ, and some headers are two
    // words): where each header ends.
    let (mut unknowns_end, mut iters_end) = (None, None);
    let ending_at = |line: &str, end: Option<usize>| -> Option<usize> {
        let head = line.get(..end?)?;
        head.rsplit(' ').next().and_then(|w| w.parse().ok())
    };
    for line in text.lines() {
        let t: Vec<&str> = line.split_whitespace().collect();
        if t.first() == Some(&"step") {
            unknowns_end = line.find("unknowns").map(|i| i + "unknowns".len());
            iters_end = line.find("iters").map(|i| i + "iters".len());
        } else if line.starts_with("scene `") {
            r.points = t
                .iter()
                .position(|w| *w == "points,")
                .map_or(0, |i| t[i - 1].parse().unwrap_or(0));
        } else if t.first().is_some_and(|w| w.parse::<usize>().is_ok()) && t.len() > 3 {
            r.steps += 1;
            r.unknowns = r.unknowns.max(ending_at(line, unknowns_end).unwrap_or(0));
            r.iterations += ending_at(line, iters_end).unwrap_or(0);
        } else if let Some(rest) = line.strip_prefix("phases (s): ") {
            let v: Vec<f64> = rest
                .split([',', ';'])
                .filter_map(|f| f.split_whitespace().last().and_then(|x| num(x).parse().ok()))
                .collect();
            r.phases.copy_from_slice(&v[..8]);
            r.peak_mb = rest
                .split("peak memory ")
                .nth(1)
                .and_then(|m| m.split_whitespace().next())
                .and_then(|m| m.parse().ok())
                .unwrap_or(0.0);
        } else if let Some(rest) = line.strip_prefix("summary: ") {
            r.total = rest
                .split(", ")
                .nth(1)
                .and_then(|f| f.split_whitespace().next())
                .and_then(|x| x.parse().ok())
                .unwrap_or(f64::NAN);
        }
    }
    if let Some(s) = steps {
        r.steps = s;
    }
    r
}

fn main() {
    // Criterion's arguments (`--bench`) are accepted and ignored.
    let dir: PathBuf = std::env::temp_dir().join(format!("mpmlab-solver-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let small = std::env::var_os("MPMLAB_BENCH_SMALL").is_some();
    let mut runs = Vec::new();
    let mut go_on = |name: &str, scene: String, steps: Option<usize>, threads: usize| {
        eprintln!("running {name} ...");
        let r = run(&dir, name, &scene, steps, threads);
        runs.push(r);
        runs.len() - 1
    };
    let mut go = |name: &str, scene: String, steps: Option<usize>| go_on(name, scene, steps, 1);
    let lin5 = go(
        "linear-1e5",
        block("linear-1e5", 224, "standard", "quasi-static-linear", 1, "auto"),
        None,
    );
    let lin5off = go(
        "linear-1e5-off",
        block("linear-1e5-off", 224, "standard", "quasi-static-linear", 1, "off"),
        None,
    );
    let (lin6, lin6off) = if small {
        (None, None)
    } else {
        (
            Some(go(
                "linear-1e6",
                block("linear-1e6", 708, "standard", "quasi-static-linear", 1, "auto"),
                None,
            )),
            Some(go(
                "linear-1e6-off",
                block("linear-1e6-off", 708, "standard", "quasi-static-linear", 1, "off"),
                None,
            )),
        )
    };
    let gimp_lin = go(
        "gimp-linear",
        block("gimp-linear", 128, "gimp", "quasi-static-linear", 1, "off"),
        None,
    );
    let gimp_fin = go(
        "gimp-finite",
        block("gimp-finite", 128, "gimp", "quasi-static-finite", 1, "off"),
        None,
    );
    let fin40 = go(
        "finite-102400",
        block("finite-102400", 160, "gimp", "quasi-static-finite", 40, "off"),
        None,
    );
    let explicit_scene =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/scenes/explicit-block.toml"))
            .expect("the explicit block scene");
    let expl = go("explicit-102400", explicit_scene, None);
    // Threads: a finite-deformation block of about 10^5 unknowns (224 x
    // 224 cells, GIMP, 200,704 points), one load step on one thread and
    // on two.
    let fin5 = block("finite-1e5", 224, "gimp", "quasi-static-finite", 1, "off");
    let fin5_1 = go_on("finite-1e5", fin5.clone(), None, 1);
    let fin5_2 = go_on("finite-1e5-2thr", fin5, None, 2);
    // The same block, 4 steps each, quasi-static and implicit dynamic
    // (the same 2 Newton iterations a step); and the block 100x stiffer,
    // whose points move too little for the two runs' stencils (and so
    // their tangents' patterns) to differ. Each pair is timed three
    // times, alternating, and each run keeps its fastest: one run each
    // scatters the ratio by +-0.1 on two busy cores.
    let mut pairs = Vec::new();
    for (suffix, stiffen) in [("", false), ("-stiff", true)] {
        let scene = |name: &str, kind: &str| {
            let b = block(name, 128, "gimp", kind, 4, "off");
            if stiffen {
                b.replace("E = 1.0e8", "E = 1.0e10")
            } else {
                b
            }
        };
        let (qs, dy) = (format!("gimp-static-4{suffix}"), format!("gimp-dynamic-4{suffix}"));
        let (mut q, mut d) = (None, None);
        for _ in 0..3 {
            let rq = run(&dir, &qs, &scene(&qs, "quasi-static-finite"), None, 1);
            let rd = run(&dir, &dy, &scene(&dy, "dynamic-implicit"), None, 1);
            if q.as_ref().is_none_or(|b: &Run| rq.total < b.total) {
                q = Some(rq);
            }
            if d.as_ref().is_none_or(|b: &Run| rd.total < b.total) {
                d = Some(rd);
            }
        }
        runs.extend([q.expect("three runs"), d.expect("three runs")]);
        pairs.push((runs.len() - 2, runs.len() - 1));
    }

    // Ratios are of one run on this machine: say what it has.
    println!(
        "machine: {} cores available (ratios measured in this one run)",
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!(
        "{:<16} {:>9} {:>5} {:>5} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9} {:>8}",
        "run",
        "unknowns",
        "steps",
        "iters",
        "map s",
        "pat s",
        "asm s",
        "fact s",
        "solve s",
        "cond s",
        "upd s",
        "other s",
        "total s",
        "peak MB"
    );
    for r in &runs {
        let p = &r.phases;
        println!(
            "{:<16} {:>9} {:>5} {:>5} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>9.3} {:>8.0}",
            r.name,
            r.unknowns,
            r.steps,
            r.iterations,
            p[0],
            p[1],
            p[2],
            p[3],
            p[4],
            p[5],
            p[6],
            p[7],
            r.total,
            r.peak_mb
        );
    }
    println!();
    // Every ratio the solver is held to, one row each: what was measured
    // in this run, its target, and whether it is met.
    let mut rows: Vec<(String, String, String, bool)> = Vec::new();
    let mut row = |what: String, value: f64, shown: String, target: f64, at_most: bool| {
        let met = if at_most { value <= target } else { value >= target };
        let bound = if at_most { "<=" } else { ">=" };
        rows.push((what, shown, format!("{bound} {target}"), met));
    };
    let cond_share = |r: &Run| r.phases[5] / r.total;
    let l5 = &runs[lin5];
    let share = 100.0 * cond_share(l5);
    row(
        "condition estimate, % of the linear 1e5 step".into(),
        share.round(),
        format!("{share:.0}"),
        20.0,
        true,
    );
    let per_1e5 = runs[lin5off].peak_mb / (runs[lin5off].unknowns as f64 / 1e5);
    row(
        "linear path peak MB per 1e5 unknowns".into(),
        per_1e5.round(),
        format!("{per_1e5:.0}"),
        150.0,
        true,
    );
    if let (Some(a), Some(b)) = (lin6, lin6off) {
        let r = runs[a].total / runs[b].total;
        row(
            "linear 1e6 step, estimate on / off".into(),
            r,
            format!("{r:.2}"),
            2.0,
            true,
        );
    }
    let (gl, gf) = (&runs[gimp_lin], &runs[gimp_fin]);
    let r = (gf.total / gf.iterations.max(1) as f64) / gl.total;
    row(
        "Newton iteration / linear step, same points".into(),
        r,
        format!("{r:.2}"),
        1.5,
        true,
    );
    let r = gf.peak_mb / gl.peak_mb;
    row(
        "Newton / linear peak memory, same points".into(),
        r,
        format!("{r:.2}"),
        2.0,
        true,
    );
    for (&(q, d), what) in pairs.iter().zip(["", ", 100x stiffer"]) {
        let (qs, dy) = (&runs[q], &runs[d]);
        let per_step = (dy.total / dy.steps.max(1) as f64) / (qs.total / qs.steps.max(1) as f64);
        println!(
            "one implicit dynamic step / one quasi-static Newton step{what}: {per_step:.2}x per step, {:.2}x per iteration ({} and {} iterations; fastest of 3 each)",
            (dy.total / dy.iterations.max(1) as f64) / (qs.total / qs.iterations.max(1) as f64),
            dy.iterations,
            qs.iterations
        );
        row(
            format!("implicit dynamic / quasi-static step{what}"),
            per_step,
            format!("{per_step:.2}"),
            1.2,
            true,
        );
    }
    // One Newton iteration: its residual and tangent (assembly), its
    // factorisation and solve, per iteration; the step's mapping and
    // pattern are once per step.
    let per_iteration = |r: &Run| (r.phases[2] + r.phases[3] + r.phases[4]) / r.iterations.max(1) as f64;
    let (t1, t2) = (&runs[fin5_1], &runs[fin5_2]);
    println!(
        "two threads, {} unknowns, {} Newton iterations: an iteration {:.3} s against {:.3} s on one, its assembly {:.2}x faster, the step {:.2}x; the factorisation and solve ({:.0}% of an iteration on one thread) run on one",
        t1.unknowns,
        t1.iterations,
        per_iteration(t2),
        per_iteration(t1),
        t1.phases[2] / t2.phases[2],
        t1.total / t2.total,
        100.0 * (t1.phases[3] + t1.phases[4]) / t1.iterations.max(1) as f64 / per_iteration(t1)
    );
    let r = per_iteration(t1) / per_iteration(t2);
    row(
        "1e5-unknown Newton iteration, 2 threads / 1".into(),
        r,
        format!("{r:.2}"),
        1.6,
        false,
    );
    let f = &runs[fin40];
    row(
        "102,400-point finite block, 40 steps, s".into(),
        f.total,
        format!("{:.1}", f.total),
        60.0,
        true,
    );
    row(
        "102,400-point finite block, 40 steps, MB".into(),
        f.peak_mb,
        format!("{:.0}", f.peak_mb),
        500.0,
        true,
    );
    let e = &runs[expl];
    println!(
        "explicit block: {:.3e} point-steps per second ({} points, {} steps in {:.2} s, the process timed; `cargo bench --bench explicit` has its ratios)",
        e.points as f64 * e.steps as f64 / e.total,
        e.points,
        e.steps,
        e.total
    );
    println!();
    println!(
        "ratios, {} cores, one run:",
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!("  {:<50} {:>9} {:>8}  met", "measure", "measured", "target");
    for (what, shown, target, met) in &rows {
        println!(
            "  {what:<50} {shown:>9} {target:>8}  {}",
            if *met { "yes" } else { "NO" }
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
