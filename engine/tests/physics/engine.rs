//! Engine invariants: energy balance, condition number methods agree,
//! snapshots, and failures as values.

use crate::common;
use common::{run_all, sim_with};
use mpmlab_engine::linalg::ConditionMethod;
use mpmlab_engine::scene::ConditionMode;
use mpmlab_engine::{Params, StepFailure};

#[test]
fn work_equals_strain_energy_in_a_linear_step() {
    // Clapeyron: for one linear step from zero, W = 1/2 f.u = 1/2 u.K.u = U.
    for name in ["column-small-strain", "patch-compression", "fe-equivalence"] {
        let mut sim = sim_with(name, |_| {});
        let r = run_all(&mut sim);
        let (u, w) = (r.energy.strain, r.energy.external_work);
        assert!(u > 0.0);
        // Both are sums of O(1e3) products; the residual is below 1e-8.
        assert!((u - w).abs() < 1e-9 * u, "{name}: U {u:e} W {w:e}");
    }
}

#[test]
fn work_equals_strain_energy_over_several_steps() {
    // Over several steps the points move and their volumes change; the
    // strain energy is the stresses' work on each step's starting volumes,
    // which is what the loads and the supports' reactions pay for, step by
    // step. Where the moved points stay in balance on the new mapping (a
    // uniform stress on whole cells: the patch with grid rollers, the
    // 0 deg block with implicit ones) W = U to round-off; 1/2 s:e on the
    // updated volumes would be off by the volume change (0.2%).
    for name in ["patch-compression", "block-roller-0"] {
        let mut sim = sim_with(name, |s| s.analysis.load_steps = 4);
        let r = run_all(&mut sim);
        let (u, w) = (r.energy.strain, r.energy.external_work);
        println!("{name}: U {u:.9e} W {w:.9e}");
        assert!(u > 0.0 && (u - w).abs() < 1e-8 * u, "{name}: U {u:e} W {w:e}");
    }
}

#[test]
fn implicit_reactions_do_not_count_the_tractions_again() {
    // Pressure through a B-spline on one side, implicit rollers on three:
    // the rollers' reactions are internal minus every external force on
    // their cut cells' nodes, tractions included (before: W = 2U).
    let mut sim = sim_with("square-traction-ibm-45", |_| {});
    let r = run_all(&mut sim);
    let (u, w) = (r.energy.strain, r.energy.external_work);
    assert!(u > 0.0 && (u - w).abs() < 1e-8 * u, "U {u:e} W {w:e}");
}

/// G 5.5's beam: the work the loads do goes into strain energy and the
/// ghost penalty. The penalty acts on each step's increment and the grid
/// is reset, so what it takes up is not given back. Measured (W - U - G as
/// a share of W): after the first step 0.12% (W - U alone: 17%); after 50
/// steps 1.16% (W - U: 3.1%); with gamma_K = 10 E 1.5% (W - U: 13.4%);
/// over 200 steps 0.35%. What remains is the trapezoidal rule along the
/// load path, first order in the step (1.16% -> 0.35% for steps 4 times
/// smaller), whatever gamma_K: hence 0.5% after one step, 2% after 50,
/// and at least halved by steps 4 times smaller.
#[test]
fn work_is_strain_energy_plus_the_ghost_penalty() {
    let run = |gamma_k: f64, steps: usize| {
        let mut sim = sim_with("elastic-beam-ghost", |s| {
            s.analysis.gamma_k = gamma_k;
            s.analysis.load_steps = steps;
        });
        let first = sim.step().unwrap().energy;
        let last = run_all(&mut sim).energy;
        (first, last)
    };
    let rest = |e: &mpmlab_engine::report::Energy| (e.external_work - e.strain - e.ghost) / e.external_work;
    let e = 12.0e6;
    let (first, last) = run(e, 50);
    assert!(first.ghost > 0.0 && last.ghost > first.ghost, "{first:?} {last:?}");
    assert!(rest(&first).abs() < 0.005, "{first:?}");
    assert!(rest(&last).abs() < 0.02, "{last:?}");
    let (_, stiff) = run(10.0 * e, 50);
    assert!(stiff.ghost > 5.0 * last.ghost, "{stiff:?}");
    assert!(rest(&stiff).abs() < 0.02, "{stiff:?}");
    let (_, fine) = run(e, 200);
    assert!(rest(&fine).abs() < 0.5 * rest(&last).abs(), "{fine:?} against {last:?}");
    // Explicit dynamics penalises the mass, not the stiffness: none here.
    let mut sim = sim_with("ghost-collision-elastic", |_| {});
    assert_eq!(sim.step().unwrap().energy.ghost, 0.0);
}

#[test]
fn dense_and_lanczos_condition_numbers_agree() {
    let cond = |mode| {
        let mut sim = sim_with("column-small-strain", |s| s.analysis.condition = mode);
        run_all(&mut sim).condition.unwrap()
    };
    let d = cond(ConditionMode::Dense);
    let l = cond(ConditionMode::Lanczos);
    assert_eq!(d.method, ConditionMethod::Dense);
    assert_eq!(l.method, ConditionMethod::Lanczos);
    // Lanczos stops when the extreme Ritz values settle to 1e-10; well
    // separated extremes converge to that accuracy.
    assert!(
        (d.value - l.value).abs() < 1e-6 * d.value,
        "dense {:e} lanczos {:e}",
        d.value,
        l.value
    );
    assert!(d.value > 10.0);
}

#[test]
fn snapshot_restore_redoes_a_step_identically() {
    let mut sim = sim_with("column-small-strain", |s| s.analysis.load_steps = 3);
    sim.step().unwrap();
    let snap = sim.snapshot();
    let a = sim.step().unwrap();
    let pa = sim.points().clone();
    sim.restore(&snap);
    assert_eq!(sim.step_index(), 1);
    let b = sim.step().unwrap();
    assert_eq!(a.residuals, b.residuals);
    assert_eq!(a.energy, b.energy);
    assert_eq!(pa.x, sim.points().x);
    assert_eq!(pa.stress, sim.points().stress);
}

#[test]
fn stepping_past_the_end_is_a_value() {
    let mut sim = sim_with("patch-compression", |_| {});
    run_all(&mut sim);
    assert!(sim.finished());
    assert_eq!(sim.step(), Err(StepFailure::Finished { steps: 1 }));
}

#[test]
fn unsupported_body_fails_cleanly() {
    let mut sim = sim_with("column-small-strain", |s| s.dirichlet.clear());
    let before = sim.points().x.clone();
    match sim.step() {
        Err(StepFailure::Singular { step: 1, reason }) => assert!(reason.contains("not positive definite"), "{reason}"),
        other => panic!("expected a singular-system failure, got {other:?}"),
    }
    assert_eq!(sim.step_index(), 0);
    assert_eq!(sim.points().x, before);
    assert!(sim.points().stress.iter().flatten().all(|s| s.is_finite()));
}

#[test]
fn tolerance_is_enforced() {
    let mut sim = sim_with("column-small-strain", |_| {});
    let p = sim.params().clone();
    sim.set_params(Params { tolerance: 1e-30, ..p });
    match sim.step() {
        // The solve and two rounds of refinement, all above 1e-30.
        Err(StepFailure::NotConverged { step: 1, residuals, .. }) => assert_eq!(residuals.len(), 4),
        other => panic!("expected NotConverged, got {other:?}"),
    }
    assert_eq!(sim.step_index(), 0);
}

#[test]
fn progress_streams_residuals_and_can_cancel_a_step() {
    use mpmlab_engine::simulation::{Progress, StepFailure};
    use std::sync::{Arc, Mutex};
    // The finite-deformation beam: every Newton residual reaches the hook;
    // returning false at the second one cancels the step, leaving step 0.
    let mut sim = common::sim_with("elastic-beam-ghost", |_| {});
    let seen: Arc<Mutex<Vec<Progress>>> = Arc::default();
    let s = seen.clone();
    sim.set_progress(Some(Box::new(move |p| {
        s.lock().unwrap().push(p.clone());
        p.iteration < 1
    })));
    match sim.step() {
        Err(StepFailure::Cancelled { step: 1, residuals }) => assert_eq!(residuals.len(), 2),
        other => panic!("{other:?}"),
    }
    assert_eq!(sim.step_index(), 0);
    let p = seen.lock().unwrap().clone();
    assert_eq!(p.iter().map(|p| p.iteration).collect::<Vec<_>>(), [0, 1]);
    assert!(p.iter().all(|p| p.step == 1 && p.residual.is_finite()));
    // Without the hook the same step completes, and the hook saw what the
    // report holds.
    sim.set_progress(None);
    let r = sim.step().unwrap();
    assert_eq!(r.residuals[..2], [p[0].residual, p[1].residual]);
}

#[test]
fn a_panic_inside_a_step_is_a_failure_value_and_the_state_survives() {
    use mpmlab_engine::simulation::Progress;
    // An observer that panics stands in for a bug anywhere inside the step:
    // step_guarded turns it into StepFailure::Internal, and since a step
    // commits only at its end the state stays at step 0.
    let mut sim = sim_with("elastic-beam-ghost", |_| {});
    let before = sim.points().x.clone();
    sim.set_progress(Some(Box::new(|p: &Progress| {
        if p.iteration == 1 {
            panic!("deliberate panic at iteration 1");
        }
        true
    })));
    match sim.step_guarded() {
        Err(StepFailure::Internal { step: 1, message }) => {
            assert!(message.contains("deliberate panic"), "{message}")
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(sim.step_index(), 0);
    assert_eq!(sim.points().x, before);
    // The simulation carries on: the same step completes without the hook.
    sim.set_progress(None);
    assert_eq!(sim.step_guarded().unwrap().step, 1);
}

/// The 2D five-point Laplacian on an `m x m` grid shifted by `sigma`,
/// lower triangle: eigenvalues `4 - 2 cos(i pi/(m+1)) - 2 cos(j pi/(m+1)) -
/// sigma`, `i, j = 1..m`.
fn shifted_laplacian(m: usize, sigma: f64) -> (faer::sparse::SparseColMat<mpmlab_engine::linalg::Ix, f64>, usize) {
    use faer::sparse::{SparseColMat, Triplet};
    let id = |i: usize, j: usize| (i * m + j) as mpmlab_engine::linalg::Ix;
    let mut t = Vec::new();
    for i in 0..m {
        for j in 0..m {
            t.push(Triplet::new(id(i, j), id(i, j), 4.0 - sigma));
            if i + 1 < m {
                t.push(Triplet::new(id(i + 1, j), id(i, j), -1.0));
            }
            if j + 1 < m {
                t.push(Triplet::new(id(i, j + 1), id(i, j), -1.0));
            }
        }
    }
    let a = SparseColMat::try_new_from_triplets(m * m, m * m, &t).unwrap();
    let angle = |k: usize| (k as f64 * std::f64::consts::PI / (m + 1) as f64).cos();
    let negative = (1..=m)
        .flat_map(|i| (1..=m).map(move |j| (i, j)))
        .filter(|&(i, j)| 4.0 - 2.0 * angle(i) - 2.0 * angle(j) < sigma)
        .count();
    (a, negative)
}

#[test]
fn symmetric_indefinite_factor_counts_negative_eigenvalues() {
    use mpmlab_engine::solver::{FactorKind, Factorisation, Symbolic, Symmetry};
    // Sylvester's law of inertia: the L D L^T pivots have as many negative
    // entries as the matrix has negative eigenvalues. Small grids take
    // faer's simplicial path, large ones the supernodal one; shifts chosen
    // away from eigenvalues (none within 1e-3 of sigma here).
    for (m, sigma) in [(3, 0.0), (3, 2.5), (6, 1.5), (40, 0.37), (40, 2.01), (60, 5.3)] {
        let (a, negative) = shifted_laplacian(m, sigma);
        let symbolic = Symbolic::new(a.as_ref(), Symmetry::Symmetric).unwrap();
        let mut f = Factorisation::new(&symbolic, a.as_ref(), u64::MAX).unwrap();
        let expect = if negative == 0 {
            FactorKind::Cholesky
        } else {
            FactorKind::Ldlt
        };
        assert_eq!(f.kind(), expect, "m = {m}, sigma = {sigma}");
        assert_eq!(f.negative_pivots(), Some(negative), "m = {m}, sigma = {sigma}");
        // The solve is accurate: x = A^-1 (A x0) recovers x0 to the
        // condition number (at most ~1e3 for these shifts) times eps.
        let x0: Vec<f64> = (0..m * m).map(|i| ((i * 7919) % 13) as f64 - 6.0).collect();
        let b = mpmlab_engine::linalg::sym_lower_mul(a.as_ref(), &x0);
        let x = f.solve(&b).unwrap();
        let err = x.iter().zip(&x0).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(err < 1e-9, "m = {m}, sigma = {sigma}: {err:e}");
    }
}

#[test]
fn condition_estimate_is_a_close_lower_bound() {
    // Above `dense_limit` the default is a short Lanczos run at each end:
    // its Ritz values are lower bounds of lambda_max and 1/lambda_min, so
    // the estimate is at most the dense value, and within the 1e-2 settling
    // tolerance times a few (geometric convergence) of it.
    let cond = |limit: usize, mode| {
        let mut sim = sim_with("column-small-strain", |s| {
            s.analysis.condition = mode;
            s.analysis.dense_limit = limit;
        });
        run_all(&mut sim).condition.unwrap()
    };
    let exact = cond(1500, ConditionMode::Dense);
    let est = cond(0, ConditionMode::Auto);
    assert_eq!(est.method, ConditionMethod::Estimate);
    assert!(est.value <= exact.value * (1.0 + 1e-12), "{est:?} vs {exact:?}");
    assert!(est.value >= 0.95 * exact.value, "{est:?} vs {exact:?}");
}

#[test]
fn a_released_mapping_is_restored_to_the_same_stencils_and_groups() {
    // The linear step frees the stencils and point groups while its factor
    // is built and rebuilds them for the update: the rebuilt ones must be
    // the mapping's own, bit for bit, or the update would move the points
    // with other weights than the stiffness was assembled with.
    use mpmlab_engine::assembly::Mapping;
    use mpmlab_engine::basis::BasisKind;
    for basis in [BasisKind::Standard, BasisKind::Gimp] {
        let sim = sim_with("translating-domain", |s| s.bodies[0].basis = basis);
        let m = sim.model();
        let build = || Mapping::build(&m.grid, sim.points(), &m.bodies, &m.dirichlet, 0.0).unwrap();
        let want = build();
        let mut map = build();
        map.release();
        assert!(map.stencils.is_empty() && map.groups.is_empty(), "{basis:?}");
        map.restore(&m.grid, sim.points(), &m.bodies).unwrap();
        assert_eq!(map.stencils.len(), sim.points().len(), "{basis:?}");
        for (a, b) in map.stencils.iter().zip(want.stencils.iter()) {
            assert_eq!(a.key(), b.key(), "{basis:?}");
            let (wa, wb): (Vec<_>, Vec<_>) = (a.iter().collect(), b.iter().collect());
            assert_eq!(wa, wb, "{basis:?}");
        }
        let nodes = |m: &Mapping| {
            m.groups
                .iter()
                .map(|g| (g.nodes.clone(), g.points.clone()))
                .collect::<Vec<_>>()
        };
        assert_eq!(nodes(&map), nodes(&want), "{basis:?}");
        assert!(!want.groups.is_empty());
    }
}

#[test]
fn every_phase_a_step_runs_is_timed_and_the_phases_fit_in_its_total() {
    // The step table's phases (mapping, pattern, assembly, factorisation,
    // solve, update) are each accumulated from a clock around code that
    // runs in every step of these scenes, so each is above 0 (the clock
    // counts nanoseconds; each phase does microseconds of work at least),
    // and they are disjoint parts of the step: their sum is at most the
    // step's total. A linear step, Newton steps (several iterations, each
    // assembling, factorising and solving) and explicit steps with the
    // consistent mass (the explicit step times no mapping or pattern
    // phase). Nothing here bounds how long a phase takes.
    for (scene, steps) in [
        ("block-roller-30", 1),
        ("block-roller-finite-aligned", 2),
        ("ghost-collision-elastic", 2),
    ] {
        let explicit = scene.starts_with("ghost");
        let mut sim = sim_with(scene, |_| {});
        for _ in 0..steps {
            let r = sim.step().unwrap_or_else(|f| panic!("{scene}: {f}"));
            let t = r.timings;
            for (name, v) in t.named() {
                // The condition phase runs only in the steps it is asked
                // for; the explicit step has no mapping or pattern phase.
                if name == "condition" || name == "total" || (explicit && (name == "mapping" || name == "pattern")) {
                    continue;
                }
                assert!(v > 0.0, "{scene} step {}: {name} {v}", r.step);
            }
            assert!(
                t.other() >= 0.0,
                "{scene} step {}: phases exceed the total: {t:?}",
                r.step
            );
        }
    }
}
