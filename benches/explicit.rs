//! Cost of one explicit time step of the plastic ghost collision (G 5.3:
//! 4828 GIMP points, h = 0.05 m) with each mass matrix, and of the mass
//! conditioning that `condition_every` asks for.
//!
//! `cargo bench --bench explicit`

use criterion::{criterion_group, criterion_main, Criterion};
use mpmlab::scene::{MassKind, Scene};
use mpmlab::{Model, Simulation};

fn sim(mass: MassKind) -> Simulation {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/scenarios/ghost-collision-plastic.toml");
    let text = std::fs::read_to_string(path).expect("shipped scene");
    let mut scene = Scene::parse(&text, path).expect("valid scene");
    scene.analysis.mass = mass;
    scene.analysis.condition_every = 0;
    Simulation::new(Model::build(&scene, &text, path).expect("valid scene"))
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
criterion_main!(benches);
