//! Timing of the linear step's phases, with the calls the linear driver
//! makes (mapping, pattern from the point groups, assembly of the group
//! stiffnesses, Cholesky, solve) and the factorisations Newton chooses
//! between (Cholesky and LU of the same matrix), for a scene of about
//! 100,000 unknowns: a 224 x 224 cell block (2x2 points per cell, 200,704
//! points) under self-weight on rollers. The whole-run table with peak
//! memory and the solver's ratios is `cargo bench --bench solver`.
//!
//! `cargo bench --bench step`

use criterion::{criterion_group, criterion_main, Criterion};
use mpmlab::assembly::{Mapping, Pattern, Storage};
use mpmlab::linalg;
use mpmlab::scene::ConditionMode;
use mpmlab::{Model, Simulation};

const N: usize = 224;

fn scene() -> String {
    format!(
        r#"
[scene]
name = "bench-block"
[grid]
origin = [0.0, 0.0]
size = [{n}.0, {n}.0]
h = 1.0
[[material]]
name = "m"
E = 1.0e7
nu = 0.3
density = 1000.0
[[body]]
name = "block"
material = "m"
points_per_cell = 2
region = {{ shape = "rectangle", min = [0.0, 0.0], max = [{n}.0, {n}.0] }}
[[dirichlet]]
kind = "roller"
x = 0.0
[[dirichlet]]
kind = "roller"
x = {n}.0
[[dirichlet]]
kind = "roller"
y = 0.0
[loads]
gravity = [0.0, -10.0]
[analysis]
load_steps = 1000
condition = "off"
"#,
        n = N
    )
}

fn bench(c: &mut Criterion) {
    let model = Model::from_text(&scene(), "bench.toml").expect("bench scene");
    let d = model.materials[0].d_matrix();
    let d_of = |_p: usize| d;
    let map = Mapping::build(&model.grid, &model.points, &model.bodies, &model.dirichlet, 0.0)
        .expect("memory for the mapping");
    println!("unknowns: {}, points: {}", map.dofs.n_free, model.points.len());
    let mut g = c.benchmark_group("step-100k");
    g.sample_size(10);
    g.bench_function("map points to grid", |b| {
        b.iter(|| Mapping::build(&model.grid, &model.points, &model.bodies, &model.dirichlet, 0.0))
    });
    let blocks: Vec<&[usize]> = map.groups.iter().map(|g| g.nodes.as_slice()).collect();
    g.bench_function("pattern", |b| {
        b.iter(|| Pattern::new(&map.dofs, &blocks, Storage::Lower))
    });
    let pattern = Pattern::new(&map.dofs, &blocks, Storage::Lower).unwrap();
    let assemble = || {
        pattern
            .assemble_with(&map.dofs, &blocks, |b, out| {
                map.group_stiffness(&map.groups[b], &model.points, &d_of, out)
            })
            .unwrap()
    };
    g.bench_function("assemble stiffness", |b| b.iter(assemble));
    let (values, _) = assemble();
    let k = pattern.matrix(&values);
    {
        use mpmlab::solver::{Factorisation, Symbolic, Symmetry};
        let symbolic = Symbolic::new(k, Symmetry::Symmetric).unwrap();
        g.bench_function("newton: cholesky (numeric, symbolic reused)", |b| {
            b.iter(|| Factorisation::new(&symbolic, k, u64::MAX).unwrap())
        });
        let whole = Pattern::new(&map.dofs, &blocks, Storage::Full).unwrap();
        let (full_values, _) = whole
            .assemble_with(&map.dofs, &blocks, |b, out| {
                map.group_stiffness(&map.groups[b], &model.points, &d_of, out)
            })
            .unwrap();
        let kf = whole.matrix(&full_values);
        let lu = Symbolic::new(kf, Symmetry::General).unwrap();
        g.bench_function("newton: LU of the same matrix (numeric, symbolic reused)", |b| {
            b.iter(|| Factorisation::new(&lu, kf, u64::MAX).unwrap())
        });
    }
    g.bench_function("cholesky (symbolic + numeric)", |b| {
        b.iter(|| linalg::cholesky(k).unwrap())
    });
    let factor = linalg::cholesky(k).unwrap();
    let rhs = vec![1.0; map.dofs.n_free];
    g.bench_function("solve", |b| b.iter(|| linalg::solve(&factor, &rhs)));
    g.bench_function("whole step (condition off)", |b| {
        let mut sim = Simulation::new(model.clone());
        assert_eq!(sim.params().condition, ConditionMode::Off);
        let snap = sim.snapshot();
        b.iter(|| {
            sim.restore(&snap);
            sim.step().unwrap()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
