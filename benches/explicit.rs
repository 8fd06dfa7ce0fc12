//! Explicit dynamics at memory speed.
//!
//! First a throughput table: point-steps per second of mpmlab's explicit
//! step on a 1 m elastic block of 102,400 points (160 x 160 cells of
//! h = 1/160 m inside a 2 m grid, 2 x 2 points per cell, E = 1 kPa,
//! nu = 0.3, rho = 1000 kg/m^3, velocity (0.1, 0.05) m/s, standard basis,
//! USF, FLIP, dt = 1e-4 s, no conditioning) with the lumped and the
//! stabilised consistent mass, next to a minimal single-threaded kernel of
//! the same physics written here (lumped mass, USF, FLIP, Hencky with a
//! closed-form 2 x 2 eigen decomposition, structure-of-arrays points, no
//! allocation per step), and their ratios, all measured in one run; then
//! the same two runs with the material updates on two threads
//! (`--threads 2`) and their speed-ups.
//!
//! Then criterion's timings of one step of the plastic ghost collision
//! (G 5.3: 4828 GIMP points, h = 0.05 m) with each mass matrix, and of the
//! mass conditioning that `condition_every` asks for.
//!
//! `cargo bench --bench explicit` (`EXPLICIT_BENCH_STEPS=n` sets the steps
//! timed per run of the table, 20 by default).

use criterion::{criterion_group, Criterion};
use mpmlab::scene::{MassKind, Scene};
use mpmlab::{Model, Simulation};
use std::time::Instant;

fn sim(mass: MassKind) -> Simulation {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/scenarios/ghost-collision-plastic.toml");
    let text = std::fs::read_to_string(path).expect("shipped scene");
    let mut scene = Scene::parse(&text, path).expect("valid scene");
    scene.analysis.mass = mass;
    scene.analysis.condition_every = 0;
    Simulation::new(Model::build(&scene, &text, path).expect("valid scene"))
}

/// The issue's block: 1 m square of 160 x 160 cells (h = 1/160 m) with
/// 2 x 2 points per cell in a 2 m grid, moving at (0.1, 0.05) m/s.
const BLOCK: &str = r#"
[scene]
name = "explicit-block"
description = "A translating elastic block for explicit throughput."

[grid]
origin = [0.0, 0.0]
size = [2.0, 2.0]
h = 0.00625

[[material]]
name = "soft"
E = 1000.0
nu = 0.3
density = 1000.0

[[body]]
name = "block"
material = "soft"
points_per_cell = 2
region = { shape = "rectangle", min = [0.5, 0.5], max = [1.5, 1.5] }
velocity = [0.1, 0.05]

[analysis]
kind = "explicit-dynamics"
duration = 0.01
load_steps = 100
mass = "MASS"
stress_update = "usf"
velocity_update = "flip"
condition_every = 0
"#;

fn block(mass: &str) -> Simulation {
    let text = BLOCK.replace("MASS", mass);
    Simulation::from_scene_text(&text, "explicit-block.toml").expect("valid scene")
}

/// Seconds for `steps` steps of mpmlab on the block (one step first, out
/// of the timing, so caches and buffers are warm as in a long run).
fn time_mpmlab(mass: &str, steps: usize, threads: usize) -> (usize, f64) {
    let mut s = block(mass);
    assert_eq!(s.set_threads(threads), Ok(threads));
    s.step().expect("first step");
    let t = Instant::now();
    for _ in 0..steps {
        s.step().expect("a step");
    }
    (s.points().len(), t.elapsed().as_secs_f64())
}

/// The minimal reference kernel: the same block and physics in flat arrays.
mod reference {
    /// Points as structure of arrays (SI units; `f` and `b` row-major
    /// `[xx, xy, yx, yy]` and `[xx, yy, xy, zz]`).
    pub struct Block {
        pub x: Vec<[f64; 2]>,
        pub v: Vec<[f64; 2]>,
        pub m: Vec<f64>,
        pub vol0: Vec<f64>,
        pub f: Vec<[f64; 4]>,
        pub b: Vec<[f64; 4]>,
        // Grid (nodes row by row) and its per-step arrays.
        pub n: usize,
        pub h: f64,
        pub gm: Vec<f64>,
        pub gp: Vec<[f64; 2]>,
        pub gf: Vec<[f64; 2]>,
        pub gv: Vec<[f64; 2]>,
        pub ga: Vec<[f64; 2]>,
        pub kappa: f64,
        pub mu: f64,
    }

    impl Block {
        pub fn new() -> Block {
            let (h, cells, rho) = (1.0 / 160.0, 320usize, 1000.0);
            let (e, nu) = (1000.0, 0.3);
            let mut x = Vec::new();
            for j in 0..320 {
                for i in 0..320 {
                    let p = [0.5 + (i as f64 + 0.5) * h / 2.0, 0.5 + (j as f64 + 0.5) * h / 2.0];
                    x.push(p);
                }
            }
            let np = x.len();
            let vol = h * h / 4.0;
            let nn = (cells + 1) * (cells + 1);
            Block {
                x,
                v: vec![[0.1, 0.05]; np],
                m: vec![vol * rho; np],
                vol0: vec![vol; np],
                f: vec![[1.0, 0.0, 0.0, 1.0]; np],
                b: vec![[1.0, 1.0, 0.0, 1.0]; np],
                n: cells + 1,
                h,
                gm: vec![0.0; nn],
                gp: vec![[0.0; 2]; nn],
                gf: vec![[0.0; 2]; nn],
                gv: vec![[0.0; 2]; nn],
                ga: vec![[0.0; 2]; nn],
                kappa: e / (3.0 * (1.0 - 2.0 * nu)),
                mu: e / (2.0 * (1.0 + nu)),
            }
        }

        /// Base node and the four bilinear weights and gradients.
        #[inline(always)]
        fn basis(&self, x: [f64; 2]) -> (usize, [f64; 4], [[f64; 2]; 4]) {
            let (sx, sy) = (x[0] / self.h, x[1] / self.h);
            let (i, j) = (sx.floor(), sy.floor());
            let (a, b) = (sx - i, sy - j);
            let k = 1.0 / self.h;
            let w = [(1.0 - a) * (1.0 - b), a * (1.0 - b), (1.0 - a) * b, a * b];
            let g = [
                [-k * (1.0 - b), -k * (1.0 - a)],
                [k * (1.0 - b), -k * a],
                [-k * b, k * (1.0 - a)],
                [k * b, k * a],
            ];
            (j as usize * self.n + i as usize, w, g)
        }

        pub fn step(&mut self, dt: f64) {
            let n = self.n;
            self.gm.fill(0.0);
            self.gp.fill([0.0; 2]);
            self.gf.fill([0.0; 2]);
            for p in 0..self.x.len() {
                let (base, w, _) = self.basis(self.x[p]);
                for (k, node) in [base, base + 1, base + n, base + n + 1].into_iter().enumerate() {
                    let mw = self.m[p] * w[k];
                    self.gm[node] += mw;
                    self.gp[node][0] += mw * self.v[p][0];
                    self.gp[node][1] += mw * self.v[p][1];
                }
            }
            for i in 0..self.gm.len() {
                if self.gm[i] > 0.0 {
                    self.gv[i] = [self.gp[i][0] / self.gm[i], self.gp[i][1] / self.gm[i]];
                }
            }
            for p in 0..self.x.len() {
                let (base, _, g) = self.basis(self.x[p]);
                let nodes = [base, base + 1, base + n, base + n + 1];
                let mut l = [0.0; 4];
                for k in 0..4 {
                    let v = self.gv[nodes[k]];
                    l[0] += v[0] * g[k][0];
                    l[1] += v[0] * g[k][1];
                    l[2] += v[1] * g[k][0];
                    l[3] += v[1] * g[k][1];
                }
                let df = [1.0 + dt * l[0], dt * l[1], dt * l[2], 1.0 + dt * l[3]];
                // b_tr = dF b dF^T (in plane), b_zz unchanged.
                let b = self.b[p];
                let (b00, b11, b01) = (b[0], b[1], b[2]);
                let t00 = df[0] * b00 + df[1] * b01;
                let t01 = df[0] * b01 + df[1] * b11;
                let t10 = df[2] * b00 + df[3] * b01;
                let t11 = df[2] * b01 + df[3] * b11;
                let (c00, c11, c01) = (
                    t00 * df[0] + t01 * df[1],
                    t10 * df[2] + t11 * df[3],
                    t00 * df[2] + t01 * df[3],
                );
                // Closed-form eigen decomposition of the in-plane block.
                let mid = 0.5 * (c00 + c11);
                let r = (0.25 * (c00 - c11) * (c00 - c11) + c01 * c01).sqrt();
                let th = 0.5 * (2.0 * c01).atan2(c00 - c11);
                let (s, co) = th.sin_cos();
                let e = [0.5 * (mid + r).ln(), 0.5 * (mid - r).ln(), 0.5 * b[3].ln()];
                let tr = e[0] + e[1] + e[2];
                let t = [0, 1, 2].map(|a| self.kappa * tr + 2.0 * self.mu * (e[a] - tr / 3.0));
                let tau00 = co * co * t[0] + s * s * t[1];
                let tau11 = s * s * t[0] + co * co * t[1];
                let tau01 = co * s * (t[0] - t[1]);
                self.b[p] = [c00, c11, c01, b[3]];
                // P = tau dF^-T.
                let det = df[0] * df[3] - df[1] * df[2];
                let inv_t = [df[3] / det, -df[2] / det, -df[1] / det, df[0] / det];
                let pk = [
                    tau00 * inv_t[0] + tau01 * inv_t[2],
                    tau00 * inv_t[1] + tau01 * inv_t[3],
                    tau01 * inv_t[0] + tau11 * inv_t[2],
                    tau01 * inv_t[1] + tau11 * inv_t[3],
                ];
                let v0 = self.vol0[p];
                for k in 0..4 {
                    let f = &mut self.gf[nodes[k]];
                    f[0] -= v0 * (pk[0] * g[k][0] + pk[1] * g[k][1]);
                    f[1] -= v0 * (pk[2] * g[k][0] + pk[3] * g[k][1]);
                }
                let fo = self.f[p];
                self.f[p] = [
                    df[0] * fo[0] + df[1] * fo[2],
                    df[0] * fo[1] + df[1] * fo[3],
                    df[2] * fo[0] + df[3] * fo[2],
                    df[2] * fo[1] + df[3] * fo[3],
                ];
            }
            for i in 0..self.gm.len() {
                if self.gm[i] > 0.0 {
                    let a = [self.gf[i][0] / self.gm[i], self.gf[i][1] / self.gm[i]];
                    self.ga[i] = a;
                    self.gv[i] = [self.gv[i][0] + dt * a[0], self.gv[i][1] + dt * a[1]];
                }
            }
            for p in 0..self.x.len() {
                let (base, w, _) = self.basis(self.x[p]);
                let (mut a, mut v) = ([0.0; 2], [0.0; 2]);
                for (k, node) in [base, base + 1, base + n, base + n + 1].into_iter().enumerate() {
                    a[0] += w[k] * self.ga[node][0];
                    a[1] += w[k] * self.ga[node][1];
                    v[0] += w[k] * self.gv[node][0];
                    v[1] += w[k] * self.gv[node][1];
                }
                self.v[p] = [self.v[p][0] + dt * a[0], self.v[p][1] + dt * a[1]];
                self.x[p] = [self.x[p][0] + dt * v[0], self.x[p][1] + dt * v[1]];
            }
        }
    }
}

fn time_reference(steps: usize) -> (usize, f64) {
    let mut b = reference::Block::new();
    b.step(1e-4);
    let t = Instant::now();
    for _ in 0..steps {
        b.step(1e-4);
    }
    let s = t.elapsed().as_secs_f64();
    assert!(b.x.iter().all(|x| x[0].is_finite() && x[1].is_finite()));
    (b.x.len(), s)
}

/// The throughput table: mpmlab (lumped, stabilised) against the minimal
/// kernel, point-steps per second and ratios from one run.
fn throughput() {
    println!(
        "machine: {} cores available (ratios measured in this one run)",
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    let steps = std::env::var("EXPLICIT_BENCH_STEPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20usize);
    let rate = |(n, s): (usize, f64)| (n * steps) as f64 / s;
    let (n, t_ref) = time_reference(steps);
    let reference = rate((n, t_ref));
    let (n_l, t_l) = time_mpmlab("lumped", steps, 1);
    let lumped = rate((n_l, t_l));
    let (n_s, t_s) = time_mpmlab("stabilised", steps, 1);
    let stabilised = rate((n_s, t_s));
    let (_, t_l2) = time_mpmlab("lumped", steps, 2);
    let (_, t_s2) = time_mpmlab("stabilised", steps, 2);
    println!("explicit block, {n_l} points, {steps} steps of 1e-4 s (single thread unless named):");
    println!(
        "  {:<28} {:>14} {:>10} {:>12}",
        "run", "point-steps/s", "s/step", "vs minimal"
    );
    for (name, r, t) in [
        ("minimal kernel (lumped)", reference, t_ref),
        ("mpmlab lumped", lumped, t_l),
        ("mpmlab stabilised", stabilised, t_s),
        ("mpmlab lumped, 2 threads", rate((n_l, t_l2)), t_l2),
        ("mpmlab stabilised, 2 threads", rate((n_s, t_s2)), t_s2),
    ] {
        println!(
            "  {name:<28} {r:>14.3e} {:>10.4} {:>11.1}%",
            t / steps as f64,
            100.0 * r / reference
        );
    }
    println!("  stabilised / lumped time: {:.2}x", t_s / t_l);
    println!(
        "  speed-up at 2 threads (--threads 2): lumped {:.2}x, stabilised {:.2}x",
        t_l / t_l2,
        t_s / t_s2
    );
    // The ratios explicit dynamics is held to, as the solver bench's.
    println!();
    println!(
        "ratios, {} cores, one run:",
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!("  {:<50} {:>9} {:>8}  met", "measure", "measured", "target");
    let share = 100.0 * lumped / reference;
    for (what, shown, target, met) in [
        (
            "explicit lumped, % of the minimal kernel",
            format!("{share:.1}"),
            ">= 30",
            share >= 30.0,
        ),
        (
            "explicit stabilised / lumped step",
            format!("{:.2}", t_s / t_l),
            "<= 2",
            t_s / t_l <= 2.0,
        ),
    ] {
        println!(
            "  {what:<50} {shown:>9} {target:>8}  {}",
            if met { "yes" } else { "NO" }
        );
    }
    assert_eq!((n, n_s), (n_l, n_l));
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("explicit-step");
    g.sample_size(20);
    for (name, mass) in [
        ("lumped", MassKind::Lumped),
        ("stabilised (pattern reused)", MassKind::Stabilised),
    ] {
        let mut s = sim(mass);
        // A step first, so the stabilised mass's pattern is cached.
        s.step().expect("first step");
        let snap = s.snapshot();
        g.bench_function(name, |b| {
            b.iter(|| {
                s.restore(&snap);
                s.step().expect("a step")
            })
        });
    }
    let s = sim(MassKind::Stabilised);
    g.bench_function("conditioning (3 masses, CFL numbers)", |b| b.iter(|| s.conditioning()));
    g.finish();
}

criterion_group!(benches, bench);

fn main() {
    throughput();
    benches();
    Criterion::default().configure_from_args().final_summary();
}
