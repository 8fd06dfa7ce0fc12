//! G Table 5 in full for the elastic beam (G 5.5): every grid size and
//! point count, with and without ghost stabilisation, as a markdown table.
//!
//! `cargo run --release --example beam_table` (about a minute; the output is
//! in docs/verification.md). The assertions on this problem are in
//! `engine/tests/physics/finite.rs` (`beam_stability_ghost_completes_where_plain_gimp_fails`,
//! `beam_tip_follows_the_elastica`); this is the report.

use mpmlab::scene::Scene;
use mpmlab::{Model, Simulation, StepFailure};
use std::path::PathBuf;

/// Steps completed, total and largest Newton iterations, tip displacement.
type BeamRun = (usize, usize, usize, [f64; 2]);

/// Run the beam, or the failure with the number of steps completed.
fn beam(text: &str, h: f64, n: usize, gamma: f64) -> Result<BeamRun, (usize, StepFailure)> {
    let name = "elastic-beam-ghost";
    let mut scene = Scene::parse(text, name).unwrap_or_else(|e| panic!("{e}"));
    scene.grid.h = h;
    scene.bodies[0].points_per_cell = n;
    scene.analysis.gamma_k = gamma;
    let mut sim = Simulation::new(Model::build(&scene, text, name).unwrap_or_else(|e| panic!("{e}")));
    let (mut total, mut most) = (0, 0);
    while !sim.finished() {
        match sim.step() {
            Ok(r) => {
                total += r.iterations;
                most = most.max(r.iterations);
            }
            Err(f) => return Err((sim.step_index(), f)),
        }
    }
    // Tip: mean displacement of the two loaded points.
    let loads = &sim.model().point_loads;
    let u: Vec<[f64; 2]> = loads.iter().map(|l| sim.points().displacement(l.point)).collect();
    Ok((
        sim.step_index(),
        total,
        most,
        [0.5 * (u[0][0] + u[1][0]), 0.5 * (u[0][1] + u[1][1])],
    ))
}

fn main() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios/elastic-beam-ghost.toml");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    println!(
        "| h (m) | points/cell | ghost | completed steps | Newton iterations (total / max per step) | tip (x, y) m |"
    );
    println!("|---|---|---|---|---|---|");
    for h in [0.5, 0.25, 0.125] {
        for n in 2..=6 {
            for gamma in [12.0e6, 0.0] {
                let g = if gamma > 0.0 { "yes" } else { "no" };
                match beam(&text, h, n, gamma) {
                    Ok((steps, total, most, tip)) => println!(
                        "| {h} | {} | {g} | {steps} | {total} / {most} | ({:.3}, {:.3}) |",
                        n * n,
                        tip[0],
                        tip[1]
                    ),
                    Err((done, f)) => println!(
                        "| {h} | {} | {g} | {done} (fails at step {}) | - | - |",
                        n * n,
                        f.step()
                    ),
                }
            }
        }
    }
}
