//! Threads in implicit steps: the points' responses and the tangent's
//! blocks are computed on the simulation's threads, and the forces and
//! the matrix are summed in point and block order afterwards, so a run on
//! any number of threads is the serial run to the bit. Each scene here
//! runs its first steps on 1 and on 3 threads (more threads than this
//! machine's cores, and an odd number, so the split of points and blocks
//! among them differs from any power of two), and every report's numbers
//! and every point field after them must be the same bits.

use crate::common::{point_bits, sim_with};
use mpmlab_engine::{Simulation, StepReport};

/// The numbers of a step's report that the threads could change: Newton's
/// residual history, the energies, the largest increment and the
/// implicit boundaries' reactions.
fn report_bits(r: &StepReport) -> Vec<u64> {
    let mut bits: Vec<u64> = r.residuals.iter().map(|v| v.to_bits()).collect();
    let e = &r.energy;
    bits.extend(
        [
            e.strain,
            e.external_work,
            e.plastic_dissipation,
            e.ghost,
            e.kinetic,
            r.max_increment,
            r.residual_norm,
        ]
        .map(f64::to_bits),
    );
    for b in &r.ibm {
        bits.extend(b.reaction.iter().map(|v| v.to_bits()));
    }
    bits.push(r.iterations as u64);
    bits
}

/// The first `steps` steps of shipped scene `name` on `threads` threads:
/// every report's numbers and the points' fields after them, as bits.
fn run(name: &str, steps: usize, threads: usize) -> (Vec<Vec<u64>>, Vec<u64>, usize) {
    let mut sim: Simulation = sim_with(name, |s| s.analysis.condition_every = 0);
    assert_eq!(sim.set_threads(threads), Ok(threads));
    let reports = (0..steps)
        .map(|_| report_bits(&sim.step().unwrap_or_else(|f| panic!("{name}, {threads} threads: {f}"))))
        .collect();
    (reports, point_bits(&sim), sim.points().len())
}

/// `name`'s first `steps` steps on 3 threads equal the serial ones to the
/// bit; its points are many enough to be split among the threads.
fn same_on_threads(name: &str, steps: usize) {
    let (serial, points_1, n) = run(name, steps, 1);
    let (threaded, points_3, _) = run(name, steps, 3);
    // The points are split in chunks of at least 64: with more than 192
    // points each of the three threads can get a chunk.
    assert!(n > 3 * 64, "{name} has {n} points: too few to split");
    for (k, (a, b)) in serial.iter().zip(&threaded).enumerate() {
        assert_eq!(a, b, "{name}: step {} differs on 3 threads", k + 1);
    }
    assert_eq!(points_1, points_3, "{name}: the points differ on 3 threads");
}

#[test]
fn newton_with_f_bar_and_an_implicit_boundary_is_the_serial_run_on_threads() {
    // Quasi-static finite deformation: von Mises with F-bar patches, a
    // rigid footing pressed as an implicit boundary (its band's points
    // have their own operators), two steps.
    same_on_threads("rigid-footing-large", 2);
}

#[test]
fn implicit_dynamics_with_the_stabilised_mass_is_the_serial_run_on_threads() {
    // Newmark steps of G 5.2's collision: the stabilised mass's inertia
    // blocks merged into the points', its ghost faces, three steps.
    same_on_threads("ghost-collision-implicit", 3);
}

#[test]
fn small_strain_b_bar_is_the_serial_run_on_threads() {
    // The linear step's tangent blocks with B-bar patches.
    same_on_threads("cook-membrane-incompressible", 1);
}
