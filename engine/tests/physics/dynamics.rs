//! Explicit dynamics against G section 5.1-5.3 and G 2.6/3.5: exact paths
//! of free motion, mass conditioning, energy balance, momentum.

use crate::common;
use common::{error, point_bits, sim_with};
use mpmlab_engine::linalg::ConditionMethod;
use mpmlab_engine::scene::{ConditionMode, MassKind, RegionSpec, StressUpdate, VelocityUpdate};
use mpmlab_engine::simulation::StepFailure;
use mpmlab_engine::Simulation;

/// Every step's report of a run to the end (panics on failure).
fn run(sim: &mut Simulation) -> Vec<mpmlab_engine::StepReport> {
    let mut out = Vec::new();
    while !sim.finished() {
        out.push(sim.step().unwrap_or_else(|f| panic!("{f}")));
    }
    out
}

#[test]
fn ghost_region_has_the_papers_area() {
    // G 5.2: W0 = 2.14726 J for two ghosts of rho = 1000 kg/m^3 at
    // |v| = 0.1 sqrt(2) m/s, i.e. 0.107363 m^2 each. The outline is chosen
    // for that area with exact arcs; the flattened arcs lose less than 1e-3.
    let r = RegionSpec::Ghost {
        min: [0.3, 0.3],
        size: 0.4,
    }
    .build("region")
    .unwrap();
    let area = r.area();
    assert!((area / 0.107363 - 1.0).abs() < 1e-3, "{area}");
    // G's three resolutions (Table 2): 646, 2389 and 9613 points per ghost;
    // lattices of 31^2, 60^2 and 120^2 over the 0.4 m box come within 3%.
    for (n, g) in [(31, 646.0), (60, 2389.0), (120, 9613.0)] {
        let sim = sim_with("stretching-ghost", |s| s.bodies[0].lattice = Some([n, n]));
        let count = sim.points().len() as f64;
        println!("lattice {n}^2: {count} points (G {g})");
        assert!((count / g - 1.0).abs() < 0.03, "{count} vs {g}");
    }
    // Eye holes: the eye centres are outside the region, the head inside.
    assert!(!r.contains([0.3 + 0.4 * 0.32, 0.3 + 0.4 * 0.6]));
    assert!(r.contains([0.5, 0.3 + 0.4 * 0.9]));
}

#[test]
fn stretching_ghost_follows_the_exact_path() {
    // G 5.1.2: with the Ghost-stabilised consistent mass the linear velocity
    // field is in the grid's span and is mapped exactly (J_G does not
    // penalise linear fields), so FLIP and PIC both keep every point on its
    // exact path. G: error < 1e-13 m. Our bound 1e-12 m allows round-off
    // accumulated over 1000 steps with cond(M~) ~ 1e2.
    for update in [VelocityUpdate::Flip, VelocityUpdate::Pic] {
        let mut sim = sim_with("stretching-ghost", |s| {
            s.analysis.velocity_update = update;
            s.analysis.condition_every = 0;
        });
        let reports = run(&mut sim);
        assert_eq!(reports.len(), 1000);
        let worst = reports.iter().map(|r| error(r, "displacement_max")).fold(0.0, f64::max);
        println!("stretching ghost, stabilised {update:?}: largest error over all steps {worst:.3e} m");
        assert!(worst < 1e-12, "{update:?}: {worst:e}");
        // F = (1 + t) I: the volume has grown by (1 + 1)^2.
        let pts = sim.points();
        for p in 0..pts.len() {
            assert!((pts.vol[p] / pts.vol0[p] - 4.0).abs() < 1e-9);
        }
    }
    // Lumped FLIP: the nodal velocities of a non-uniform field are wrong,
    // so positions drift (G Fig. 11c: up to 3e-2 m).
    let mut sim = sim_with("stretching-ghost", |s| {
        s.analysis.mass = MassKind::Lumped;
        s.analysis.condition_every = 0;
    });
    let last = run(&mut sim).pop().unwrap();
    let e = error(&last, "displacement_max");
    println!("stretching ghost, lumped FLIP: error at 1 s {e:.3e} m");
    // G Fig. 11c's colour bar ends at 3e-2 m, read to one digit; ours
    // 3.375e-2 m (12.5% above): within 20% of G's. (Was anywhere in
    // 1e-4..1e-1.)
    assert!((e / 3e-2 - 1.0).abs() < 0.2, "{e}");
}

#[test]
fn unstabilised_consistent_mass_fails_cleanly() {
    // G 5.1.2: "not possible to use the non-stabilised consistent mass
    // matrix ... diverging after 21 time steps". It must end in a reported
    // failure, with the state left at the last good step and no NaNs. At
    // the paper's fixed time step (`max_cutbacks = 0`): the failure is a
    // singular mass now, which is never cut back, but a divergence would be
    // retried at dt / 2^k and could move it.
    let mut sim = sim_with("stretching-ghost", |s| {
        s.analysis.mass = MassKind::Consistent;
        s.analysis.condition_every = 0;
        s.analysis.max_cutbacks = 0;
    });
    let failure = loop {
        match sim.step() {
            Ok(_) => assert!(sim.step_index() < 1000, "it should not complete"),
            Err(f) => break f,
        }
    };
    println!("unstabilised consistent mass: {failure}");
    assert!(
        matches!(failure, StepFailure::Diverged { .. } | StepFailure::Singular { .. }),
        "{failure}"
    );
    assert_eq!(sim.step_index() + 1, failure.step());
    let pts = sim.points();
    assert!((0..pts.len()).all(|p| pts.x[p].iter().chain(&pts.v[p]).all(|v| v.is_finite())));
    // Stepping again fails again rather than running on.
    assert!(sim.step().is_err());
}

#[test]
fn translating_ghost_conditioning_and_velocity_mapping() {
    // G 5.1.1 / Table 2 (coarse ghost, h = 0.0312 m, gamma_M = rho/4):
    // stabilised max 4.3e5, unstabilised 1.9e41, lumped 1.7e10. Every 10th
    // of the 1000 positions is checked.
    let mut sim = sim_with("translating-ghost", |s| s.analysis.condition_every = 10);
    let (mut stab, mut cons, mut lump) = (0.0f64, 0.0f64, 0.0f64);
    let mut worst_velocity = 0.0f64;
    while !sim.finished() {
        let r = sim.step().unwrap_or_else(|f| panic!("{f}"));
        if let Some(c) = r.dynamics.as_ref().unwrap().conditioning {
            stab = stab.max(c.mass_stabilised.value);
            cons = cons.max(c.mass_consistent.value);
            lump = lump.max(c.mass_lumped.value);
            // The points move at (1, 1) m/s: the stabilised consistent mass
            // maps that constant field to (1, 1) at every active node (G:
            // max error 3.3e-13; round-off with cond ~1e2 allows 1e-12).
            for (_, v) in sim.map_velocities(MassKind::Stabilised).unwrap() {
                worst_velocity = worst_velocity.max((v[0] - 1.0).abs()).max((v[1] - 1.0).abs());
            }
        }
    }
    println!("max cond: stabilised {stab:.3e}, consistent {cons:.3e}, lumped {lump:.3e}; velocity error {worst_velocity:.2e}");
    // Stabilised: bounded (G: ~4e5; ours 2.7e2, see docs/verification.md,
    // our face set also covers cells only a GIMP domain reaches). Asserted
    // below 1e3, a margin of 3.7 over the measured value (was 1e6).
    assert!(stab < 1e3, "{stab:e}");
    // Unstabilised: beyond 1e20 at some positions. Most positions are
    // singular to working precision (the Cholesky breaks down with the
    // smallest eigenvalue at -1e-16 of the largest), reported as infinite.
    assert!(cons > 1e20, "{cons:e}");
    // Lumped: many orders above the stabilised one (G: 1e10-1e11).
    assert!(lump > 1e3 * stab, "{lump:e}");
    assert!(worst_velocity < 1e-12, "{worst_velocity:e}");
    // The rigid translation itself is exact with the stabilised mass.
    let r = sim.points();
    for p in 0..r.len() {
        let u = r.displacement(p);
        assert!((u[0] - 0.5).abs() < 1e-12 && (u[1] - 0.5).abs() < 1e-12);
    }
}

#[test]
fn a_point_leaving_the_grid_ends_the_run_where_the_whole_step_takes_it() {
    // G 5.1.1's ghost (stress-free, moving rigidly at (1, 1) m/s, which the
    // stabilised mass maps exactly) on its grid shifted by (-0.5, -0.5) m,
    // so that its GIMP domains reach the grid's right and top edges (0.5 m)
    // after about 110 steps of dt = 5e-4 s; and, mirrored, on its own grid
    // moving at (-1, -1) m/s, so that they reach the left and bottom edges
    // (0 m) after about 70. A point that leaves the grid leaves it at any
    // time step, so the step is not cut back (though the scene allows
    // cutbacks): the failure names where the whole step takes the domain's
    // corner, and the state stays at the step's start.
    for (s, origin, edge) in [(1.0, -0.5, 0.5), (-1.0, 0.0, 0.0)] {
        let mut sim = sim_with("translating-ghost", |sc| {
            sc.grid.origin = [origin; 2];
            sc.bodies[0].velocity = [s; 2];
            sc.analysis.condition_every = 0;
        });
        assert!(sim.model().analysis.max_cutbacks > 0);
        let (dt, tol) = (0.5 / 1000.0, 1e-9 * 0.03125);
        let (failure, x, lp) = loop {
            let (x, lp) = (sim.points().x.clone(), sim.points().lp.clone());
            if let Err(f) = sim.step() {
                break (f, x, lp);
            }
            assert!(sim.step_index() < 200, "the ghost never left the grid");
        };
        let StepFailure::LeftGrid {
            step,
            point,
            position,
            domain: true,
        } = failure
        else {
            panic!("velocity {s}: expected a GIMP domain leaving the grid: {failure}");
        };
        assert_eq!(step, sim.step_index() + 1);
        assert!(!failure.to_string().contains("cutback"), "{failure}");
        // The step before kept every domain inside; this one takes the
        // reported point's past the edge, by the whole step's motion dt (s, s).
        let past = |x: f64, l: f64| s * x + l > s * edge + tol;
        assert!((0..x.len()).all(|p| (0..2).all(|d| !past(x[p][d], lp[p][d]))));
        let moved = [0, 1].map(|d| x[point][d] + s * dt);
        let corner = [0, 1].map(|d| {
            if past(moved[d], lp[point][d]) {
                moved[d] + s * lp[point][d]
            } else {
                moved[d]
            }
        });
        assert!(corner != moved, "velocity {s}: {corner:?}");
        // Round-off of ~110 rigid steps (velocities exact to 1e-12, G 5.1.1).
        assert!(
            (position[0] - corner[0]).abs() < 1e-12 && (position[1] - corner[1]).abs() < 1e-12,
            "velocity {s}: reported {position:?}, the whole step gives {corner:?}"
        );
        assert_eq!(sim.points().x, x, "the state must stay at the step's start");
    }
}

#[test]
fn translating_domain_mass_conditioning() {
    // G 2.6 / 3.5, Table 1 and Figs. 6-7: 8 points translated a/h = 0..2.
    // Without ghost the consistent mass spikes by many orders whenever a
    // point (sMPM) or a GIMP domain barely enters a cell; with gamma_M =
    // rho/4 (and gamma_K = 1 for the CFL number) it stays near 1e1-1e2 and
    // the CFL number hardly depends on the position.
    println!("| basis | a/h | cond M | cond M~ | cond M lumped | cond K | cond K~ | CFL M | CFL M~ |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for basis in [
        mpmlab_engine::basis::BasisKind::Standard,
        mpmlab_engine::basis::BasisKind::Gimp,
    ] {
        // sMPM: a point exactly on a grid line gives a node of zero weight
        // (a degenerate, exactly singular matrix); sample around those
        // positions instead (the lattice's points lie on lines at a/h =
        // 0.25 mod 0.5). GIMP: positions just past a grid line, where a
        // domain barely enters a new cell.
        let mut positions: Vec<f64> = (0..=200)
            .map(|k| k as f64 / 100.0)
            .filter(|a| {
                basis == mpmlab_engine::basis::BasisKind::Gimp || (a * 4.0).fract() != 0.0 || (a * 2.0).fract() == 0.0
            })
            .collect();
        positions.extend([1e-3, 1e-5, 1e-7, 1.0 + 1e-3, 1.0 + 1e-5, 1.0 + 1e-7]);
        positions.extend([0.25 + 1e-3, 0.25 + 1e-5, 0.25 + 1e-7, 1.25 + 1e-7]);
        let (mut worst, mut best) = ([0.0f64; 3], [f64::INFINITY; 3]);
        let (mut cfl_s, mut cfl_c) = ((f64::INFINITY, 0.0f64), (f64::INFINITY, 0.0f64));
        for (k, &a) in positions.iter().enumerate() {
            let sim = sim_with("translating-domain", |s| {
                s.bodies[0].basis = basis;
                s.bodies[0].region = RegionSpec::Rectangle {
                    min: [a, 0.0],
                    max: [2.0 + a, 1.0],
                };
            });
            let c = sim.conditioning().unwrap();
            let v = [c.mass_consistent.value, c.mass_stabilised.value, c.mass_lumped.value];
            for i in 0..3 {
                worst[i] = worst[i].max(v[i]);
                best[i] = best[i].min(v[i]);
            }
            let (s, u) = (c.cfl_stabilised.unwrap(), c.cfl_consistent.unwrap());
            cfl_s = (cfl_s.0.min(s), cfl_s.1.max(s));
            cfl_c = (cfl_c.0.min(u), cfl_c.1.max(u));
            if k % 25 == 0 || k + 10 > positions.len() {
                println!(
                    "| {basis:?} | {a} | {:.3e} | {:.3e} | {:.3e} | {:.3e} | {:.3e} | {u:.3e} | {s:.3e} |",
                    v[0],
                    v[1],
                    v[2],
                    c.stiffness.unwrap().value,
                    c.stiffness_stabilised.unwrap().value
                );
            }
        }
        println!(
            "{basis:?}: max cond M {:.3e}, M~ {:.3e}, lumped {:.3e}; CFL M~ in [{:.3e}, {:.3e}], M in [{:.3e}, {:.3e}]",
            worst[0], worst[1], worst[2], cfl_s.0, cfl_s.1, cfl_c.0, cfl_c.1
        );
        // G Table 1: unstabilised 4.7e? (sMPM) and 4.4e43 (GIMP); stabilised 42 and 163.
        assert!(worst[0] > 1e8, "{basis:?}: {worst:?}");
        assert!(worst[1] < 1e3, "{basis:?}: {worst:?}");
        // G Fig. 7: the stabilised CFL number is nearly position independent
        // (measured 0.266..0.312 s/m for sMPM, 17%, and 0.280..0.306 s/m for
        // GIMP, 9%: within 20% here, was a factor 2), the unstabilised one
        // collapses by orders. Its level is held to the measured range
        // with 6% margin either side, so a CFL number off by 2 fails.
        assert!(cfl_s.1 / cfl_s.0 < 1.2, "{basis:?}: {cfl_s:?}");
        assert!(cfl_s.0 > 0.25 && cfl_s.1 < 0.33, "{basis:?}: {cfl_s:?}");
        assert!(cfl_c.1 / cfl_c.0 > 100.0, "{basis:?}: {cfl_c:?}");
    }
}

/// An explicit-dynamics scene on a 3 x 3 grid of cell size `h` (one
/// material: `E`, nu = 0, density `rho`; lumped mass) with one body whose
/// placement and region are `body`'s lines.
fn one_cell(h: f64, e: f64, rho: f64, body: &str) -> Simulation {
    let text = format!(
        r#"[scene]
name = "one-cell"
description = "One cell of a 3 x 3 grid, its points."
[grid]
origin = [0.0, 0.0]
size = [{size}, {size}]
h = {h}
[[material]]
name = "m"
E = {e}
nu = 0.0
density = {rho}
[[body]]
name = "b"
material = "m"
{body}
[analysis]
kind = "explicit-dynamics"
duration = 0.001
load_steps = 1
mass = "lumped"
"#,
        size = 3.0 * h,
    );
    Simulation::from_scene_text(&text, "one-cell.toml").unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn cfl_number_of_one_cell_is_half_the_inverse_wave_speed() {
    // One cell of side h with one point at its centre (volume V, mass
    // rho V), nu = 0: the gradients there are (+-1, +-1)/(2h), so
    // B B^T = diag(1, 1, 2)/h^2 and, with D = E diag(1, 1, 1/2),
    // lambda_max(K) = E V/h^2 (threefold). The lumped mass puts rho V/4 on
    // each node, so lambda_max(K, M_L) = 4E/(rho h^2) and G 3.5's CFL
    // number C = 1/(h sqrt(lambda_max)) = sqrt(rho/E)/2 = 1/(2c), whatever
    // h. The three eigenvalues are equal, so the power iteration has
    // nothing to separate: the reported number is exact to round-off.
    for (h, e, rho) in [(1.0f64, 4.0f64, 1.0f64), (0.5, 4.0, 1.0), (0.25, 1.0e3, 2.5)] {
        let sim = one_cell(
            h,
            e,
            rho,
            &format!(
                r#"points_per_cell = 1
region = {{ shape = "rectangle", min = [{h}, {h}], max = [{two_h}, {two_h}] }}"#,
                two_h = 2.0 * h
            ),
        );
        let c = sim.conditioning().unwrap().cfl_lumped.unwrap();
        let exact = 0.5 * (rho / e).sqrt();
        println!("h = {h}, E = {e}, rho = {rho}: CFL {c:.15e}, exact {exact:.15e}");
        assert!((c - exact).abs() < 1e-12 * exact, "h = {h}: {c} against {exact}");
    }
}

#[test]
fn cfl_number_of_an_off_centre_point_is_the_closed_form() {
    // One point at local coordinates (xi, eta) of its cell, all four nodes
    // free, nu = 0. Its nodes' lumped masses are m N_i, and with
    // W = diag(1/N_i) the sums over the nodes are
    //   sum_i (dN_i/dx)^2 / N_i = a/h^2,  a = 1/(xi (1 - xi)),
    //   sum_i (dN_i/dy)^2 / N_i = b/h^2,  b = 1/(eta (1 - eta)),
    //   sum_i (dN_i/dx)(dN_i/dy) / N_i = 0,
    // so B W B^T = diag(a, b, a + b)/h^2 and, with D = E diag(1, 1, 1/2)
    // and m = rho V, the nonzero eigenvalues of K = V B^T D B against
    // M_L are E/(rho h^2) times a, b and (a + b)/2: lambda_max =
    // E max(a, b)/(rho h^2) and G 3.5's C = 1/(h sqrt(lambda_max)). At the
    // centre (a = b = 4) this is the test above. Off the centre the
    // masses differ, so the power iteration's solve with M_L must be
    // right: the top eigenvector of K alone is another one.
    //
    // The power iteration stops when two estimates agree to 1e-8; its
    // Rayleigh quotient converges like (lambda_2/lambda_1)^2 per step,
    // here at most (0.72)^2 = 0.52, so what is left is about 1e-8 of
    // lambda, 0.5e-8 of C: the bound 1e-7 leaves a factor 20.
    for (xi, eta, h, e, rho) in [(0.875, 0.5, 1.0f64, 1.0e3f64, 2.0f64), (0.5, 0.125, 0.5, 4.0, 1.0)] {
        let (x, y) = ((1.0 + xi) * h, (1.0 + eta) * h);
        let body = format!(
            r#"points_per_cell = 1
placement = "lattice"
lattice = [1, 1]
region = {{ shape = "rectangle", min = [{x0}, {y0}], max = [{x1}, {y1}] }}"#,
            x0 = x - 0.25 * h,
            x1 = x + 0.25 * h,
            y0 = y - 0.25 * h,
            y1 = y + 0.25 * h,
        );
        let sim = one_cell(h, e, rho, &body);
        let c = sim.conditioning().unwrap().cfl_lumped.unwrap();
        let (a, b) = (1.0 / (xi * (1.0 - xi)), 1.0 / (eta * (1.0 - eta)));
        let exact = 1.0 / (h * (e * a.max(b) / (rho * h * h)).sqrt());
        println!("xi = {xi}, eta = {eta}: CFL {c:.15e}, exact {exact:.15e}");
        assert!(
            (c - exact).abs() < 1e-7 * exact,
            "xi = {xi}, eta = {eta}: {c} against {exact}"
        );
    }
}

#[test]
fn lumped_mass_condition_is_the_largest_over_the_smallest_nodal_weight() {
    // One point at local coordinates (xi, eta) = (3/4, 1/2) of its cell
    // (lattice placement, h = 1): the lumped mass puts m N_i on the cell's
    // four nodes, N = (1 - xi)(1 - eta), xi (1 - eta), ... = 1/8, 3/8, 1/8,
    // 3/8, so cond(M_L) = 3 exactly (every factor is exact in binary).
    // With the point at the centre every node gets m/4: cond(M_L) = 1.
    for (x0, want) in [(1.5, 3.0), (1.25, 1.0)] {
        let body = format!(
            r#"points_per_cell = 1
placement = "lattice"
lattice = [1, 1]
region = {{ shape = "rectangle", min = [{x0}, 1.25], max = [{x1}, 1.75] }}"#,
            x1 = x0 + 0.5
        );
        let sim = one_cell(1.0, 1.0e3, 2.0, &body);
        let c = sim.conditioning().unwrap().mass_lumped;
        assert_eq!(
            (c.value, c.lambda_max / c.lambda_min),
            (want, want),
            "point at x = {}",
            x0 + 0.25
        );
        // The largest lumped mass is m N_max, m = rho V = 2 x 0.25.
        assert_eq!(c.lambda_max, 0.5 * if want == 3.0 { 0.375 } else { 0.25 });
    }
}

#[test]
fn a_node_of_zero_lumped_mass_allows_no_explicit_step() {
    // One point exactly on the grid line x = 2 (lattice placement, h = 1):
    // the standard basis makes all four nodes of its cell active but
    // weights the two at x = 3 by exactly 0, so the lumped mass has zeros
    // on its diagonal. Those unknowns have no inertia, lambda_max(K, M_L)
    // is unbounded and no explicit step is stable: cond(M_L) is infinite
    // and the CFL number 0 (G 3.5), as for the singular consistent mass.
    let body = r#"points_per_cell = 1
placement = "lattice"
lattice = [1, 1]
region = { shape = "rectangle", min = [1.75, 1.25], max = [2.25, 1.75] }"#;
    let sim = one_cell(1.0, 1.0e3, 2.0, body);
    assert_eq!(sim.points().x, vec![[2.0, 1.5]]);
    let c = sim.conditioning().unwrap();
    println!("{:?}", c.mass_lumped);
    println!("CFL lumped {:?}, consistent {:?}", c.cfl_lumped, c.cfl_consistent);
    // Every weight is exact in binary (1/2 and 0): the smallest mass is 0.
    assert_eq!(c.mass_lumped.lambda_min, 0.0);
    assert_eq!(c.mass_lumped.value, f64::INFINITY);
    assert_eq!(c.cfl_lumped, Some(0.0));
    assert_eq!(c.cfl_consistent, Some(0.0));
}

#[test]
fn explicit_ghost_faces_on_populated_cells_are_the_mappings() {
    // The explicit step keeps its own mapping, refilled every step. With
    // `ghost_cells = "populated"` (G 3.1's populated elements: cells that
    // hold a point) its ghost faces must be those the step-independent
    // mapping gives at the same positions.
    use mpmlab_engine::assembly::Mapping;
    use mpmlab_engine::ghost;
    use mpmlab_engine::scene::GhostCells;
    // The standard basis: with GIMP and populated cells, this scene's
    // stabilised mass is singular at the second step ("a node is held by
    // almost no mass"). A boundary's tracking points (no volume, no mass)
    // lie in a cell beside the lower body that holds none of its points:
    // they populate nothing.
    let text = std::fs::read_to_string(common::scene_path("ghost-collision-elastic")).unwrap()
        + "[[boundary]]\nname = \"probe\"\nbody = \"lower-left\"\n\
           points = [[0.45, 0.25], [0.46, 0.25], [0.47, 0.26]]\nmaterial_side = \"left\"\n";
    let mut scene = mpmlab_engine::scene::Scene::parse(&text, "tracked").unwrap();
    scene.analysis.ghost_cells = GhostCells::Populated;
    for b in &mut scene.bodies {
        b.basis = mpmlab_engine::basis::BasisKind::Standard;
    }
    let mut sim = Simulation::new(mpmlab_engine::Model::build(&scene, &text, "tracked").unwrap());
    let probe = sim.model().grid.cell_of([0.45, 0.25]).unwrap();
    for _ in 0..3 {
        let m = sim.model();
        let map = Mapping::build(&m.grid, sim.points(), &m.bodies, &m.dirichlet, 0.0).unwrap();
        assert!(!map.populated_cells.contains(&(probe.1 * m.grid.nx + probe.0)));
        let want: Vec<_> = ghost::faces_of(&m.grid, &map, GhostCells::Populated)
            .iter()
            .map(|f| ghost::face_segment(&m.grid, f))
            .collect();
        assert!(!want.is_empty());
        let r = sim.step().unwrap();
        // The same faces, not only as many: a populated cell more can
        // add as many faces as it takes from its neighbours.
        assert_eq!(r.ghost_faces, want.len(), "step {}", r.step);
        assert_eq!(sim.ghost_faces(), &want[..], "step {}", r.step);
    }
}

/// `(1/(nt W0)) sum_i |W_kin,i + W_eps,i - W0|` (G 5.2).
fn mean_energy_error(reports: &[mpmlab_engine::StepReport]) -> f64 {
    let w0 = reports[0].dynamics.as_ref().unwrap().initial_energy;
    reports
        .iter()
        .map(|r| (r.energy.kinetic + r.energy.strain - w0).abs())
        .sum::<f64>()
        / (reports.len() as f64 * w0)
}

fn collision(
    steps: usize,
    mass: MassKind,
    update: StressUpdate,
    gamma_m: Option<f64>,
) -> Vec<mpmlab_engine::StepReport> {
    let mut sim = sim_with("ghost-collision-elastic", |s| {
        s.analysis.load_steps = steps;
        s.analysis.mass = mass;
        s.analysis.stress_update = update;
        s.analysis.condition_every = 0;
        s.analysis.gamma_m = gamma_m;
    });
    run(&mut sim)
}

#[test]
fn elastic_collision_energy_error() {
    // G Table 3 (coarse ghosts, h = 0.1 m, USF, stabilised): 0.888e-3 at
    // 1000 steps, 0.445e-3 at 2000: first order in dt.
    let e1 = mean_energy_error(&collision(1000, MassKind::Stabilised, StressUpdate::Usf, None));
    let e2 = mean_energy_error(&collision(2000, MassKind::Stabilised, StressUpdate::Usf, None));
    println!(
        "USF stabilised: {e1:.4e} (1000 steps), {e2:.4e} (2000 steps), ratio {:.3}",
        e2 / e1
    );
    // The paper's level. The setting matches G's only up to the bodies:
    // our ghosts are G's outline redrawn and filled by a 641-point lattice
    // (W0 0.6% below G's 2.14726 J), not G's VTK points, and the energy
    // error lives on the contact, where those points differ. Measured
    // 1.1475e-3, 29% above G's 0.888e-3: asserted within 35%.
    assert!((e1 / 0.888e-3 - 1.0).abs() < 0.35, "{e1:e}");
    // What the method gives on our ghosts is held tighter: gamma_M
    // enters the USF energy error through the mapped velocities, and
    // twice G's rho/4 must show.
    // Measured 1.1475e-3 at rho/4 and 1.0838e-3 (5.6% lower) at rho/2; a
    // mean over 1000 steps of a mass conditioned at 84 moves by round-off
    // in far later digits: held within 2% of the measured value.
    let e_half = mean_energy_error(&collision(1000, MassKind::Stabilised, StressUpdate::Usf, Some(500.0)));
    println!(
        "USF stabilised at gamma_M = rho/2: {e_half:.4e} ({:.4} x rho/4)",
        e_half / e1
    );
    assert!((e1 / 1.1475e-3 - 1.0).abs() < 0.02, "{e1:e}");
    assert!(
        (e_half / 1.1475e-3 - 1.0).abs() > 0.02,
        "rho/2 indistinguishable: {e_half:e}"
    );
    // Halving the time step halves the error: USF gains dt^2 a.M a / 2 per
    // step (docs/verification.md), t/dt steps make it first order in dt, so
    // the ratio is 1/2 up to O(dt) terms (G: 0.501; measured 0.506).
    assert!((e2 / e1 - 0.5).abs() < 0.015, "{}", e2 / e1);
    // USL with the lumped mass dissipates an order more than USF (G Table 3:
    // 8.4e-3 against 0.89e-3 at h = 0.1 m, 1000 steps).
    let ul = mean_energy_error(&collision(1000, MassKind::Lumped, StressUpdate::Usl, None));
    println!("USL lumped {ul:.4e}, {:.1} x USF stabilised", ul / e1);
    assert!(ul > 5.0 * e1, "{ul:e} vs {e1:e}");
    // USL with the stabilised mass: per step the scheme loses
    // dt^2 (a.M a / 2 + gamma_M a.J_G a) (docs/verification.md), so its
    // error falls with gamma_M. G reports it an order below USL lumped at
    // gamma_M = rho/4; we measure it above, see the closing note of issue 6.
    let us: Vec<f64> = [250.0, 25.0, 2.5]
        .iter()
        .map(|&g| mean_energy_error(&collision(1000, MassKind::Stabilised, StressUpdate::Usl, Some(g))))
        .collect();
    println!("USL stabilised, gamma_M = rho/4, rho/40, rho/400: {us:?}");
    assert!(us[0] > 2.0 * us[1] && us[1] > 1.5 * us[2], "{us:?}");
    // Sulsky's modified USL (strain from the updated point velocities mapped
    // back) removes that term: per step -dt^2 a.M a / 2, the mirror of USF,
    // which is what G Fig. 13b shows for its stabilised USL.
    let ms = mean_energy_error(&collision(1000, MassKind::Stabilised, StressUpdate::Musl, None));
    println!("MUSL stabilised {ms:.4e} ({:.2} x USF stabilised)", ms / e1);
    // MUSL loses per step what USF gains (dt^2 a.M a / 2), so the mean
    // absolute errors agree to leading order; the O(dt^3) terms and the
    // different paths after contact leave a few percent (measured 1.055):
    // within 10%.
    assert!((ms / e1 - 1.0).abs() < 0.1, "{ms:e} vs {e1:e}");
}

#[test]
fn collision_conserves_momentum() {
    // Rows and columns of J_G sum to zero and the consistent mass's column
    // sums are the lumped masses, so FLIP changes the total momentum by
    // dt sum_n (f_ext - f_int)_n = 0: conserved to round-off.
    let reports = collision(300, MassKind::Stabilised, StressUpdate::Usf, None);
    let sim = sim_with("ghost-collision-elastic", |_| {});
    let pts = sim.points();
    let scale: f64 = (0..pts.len())
        .map(|p| pts.mass[p] * pts.v[p][0].hypot(pts.v[p][1]))
        .sum();
    let p0 = pts.momentum();
    for r in &reports {
        let p = r.dynamics.as_ref().unwrap().momentum;
        assert!((p[0] - p0[0]).hypot(p[1] - p0[1]) < 1e-12 * scale, "{p:?}");
    }
}

#[test]
fn plastic_collision_dissipates() {
    // G 5.3 / Fig. 14 (h = 0.05 m, USF, stabilised): contact near 1.5 s,
    // then plastic dissipation grows; kinetic + strain + dissipated energy
    // stays at W0 up to the scheme's error (about 1e-3 W0 in the elastic
    // case; 2e-2 leaves room for the plastic return map's first-order
    // energy error).
    let mut sim = sim_with("ghost-collision-plastic", |s| s.analysis.condition_every = 0);
    let reports = run(&mut sim);
    let w0 = reports[0].dynamics.as_ref().unwrap().initial_energy;
    let at = |t: f64| reports.iter().find(|r| r.dynamics.as_ref().unwrap().time >= t).unwrap();
    assert_eq!(at(1.0).energy.plastic_dissipation, 0.0, "no yield before contact");
    let (d2, d35) = (
        at(2.0).energy.plastic_dissipation,
        reports.last().unwrap().energy.plastic_dissipation,
    );
    println!("W0 {w0:.5e} J; dissipation at 2 s {d2:.4e} J, at 3.5 s {d35:.4e} J");
    assert!(d2 > 0.0 && d35 > d2, "{d2:e} {d35:e}");
    // Measured 1.4357 J of W0 = 2.14578 J at 3.5 s (0.669 W0; was
    // asserted only above 0.05 W0): held within 0.02 W0, so a dissipation
    // 10% off (0.067 W0) fails.
    assert!((d35 / w0 - 0.669).abs() < 0.02, "{d35:e} of {w0:e}");
    for r in &reports {
        let e = r.energy.kinetic + r.energy.strain + r.energy.plastic_dissipation;
        let d = r.dynamics.as_ref().unwrap();
        assert!((e - w0).abs() < 2e-2 * w0, "t = {}: {e:e} vs {w0:e}", d.time);
        // The reported balance is that sum less the loads' work and W0
        // (here no loads: the work is 0), to round-off.
        let balance = e - r.energy.external_work - w0;
        assert!(
            (d.energy_error - balance).abs() <= 1e-12 * w0,
            "t = {}: balance {:e} vs {balance:e}",
            d.time,
            d.energy_error
        );
    }
}

#[test]
fn populated_cells_leave_domain_only_nodes_unheld() {
    // G 3.1 builds the face set from the elements holding points. Under GIMP
    // a cell that only a domain reaches is then "unpopulated", its outer
    // nodes get no face, and the stabilised mass of the translating ghost
    // becomes singular within a few steps; with every reached cell active
    // (the default) the same steps run with cond(M~) ~ 1e2.
    let steps = 20;
    let mut populated = sim_with("translating-ghost", |s| {
        s.analysis.ghost_cells = mpmlab_engine::scene::GhostCells::Populated;
        s.analysis.condition_every = 0;
    });
    let failure = (0..steps).find_map(|_| populated.step().err());
    println!("populated cells: {failure:?}");
    assert!(matches!(failure, Some(StepFailure::Singular { .. })), "{failure:?}");
    let mut reached = sim_with("translating-ghost", |s| s.analysis.condition_every = 1);
    for _ in 0..steps {
        let r = reached.step().unwrap();
        let c = r.dynamics.unwrap().conditioning.unwrap();
        assert!(c.mass_stabilised.value < 1e3, "{:e}", c.mass_stabilised.value);
    }
}

#[test]
fn explicit_scenes_need_density_and_free_motion_exact_solutions() {
    let path = common::scene_path("ghost-collision-elastic");
    let text = std::fs::read_to_string(&path).unwrap();
    let build = |t: &str| {
        mpmlab_engine::Model::from_text(t, "x.toml")
            .map(|_| ())
            .map_err(|e| e.to_string())
    };
    let e = build(&text.replace("density = 1000.0", "density = 0.0")).unwrap_err();
    assert!(
        e.contains("material[0].density") && e.contains("positive density"),
        "{e}"
    );
    let e = build(&(text.clone() + "\n[exact]\nname = \"simple-shear\"\nshear = 0.1\nx0 = 0.0\n")).unwrap_err();
    assert!(e.contains("free-motion exact solution only"), "{e}");
    assert!(build(&text).is_ok());
}

#[test]
fn threads_give_the_serial_run_to_the_bit() {
    // The material updates run on two threads (4828 points, above the
    // threshold where threads start): every point field after the plastic
    // collision's first 400 steps (yielding starts near step 306) equals the
    // serial run's bit for bit, as do the energies of every step, because
    // each point is updated on its own and forces and energies are summed in
    // point order afterwards.
    let steps = 400;
    let run_with = |threads: usize| {
        let mut sim = sim_with("ghost-collision-plastic", |s| s.analysis.condition_every = 0);
        assert_eq!(sim.set_threads(threads), Ok(threads));
        let reports: Vec<_> = (0..steps)
            .map(|_| sim.step().unwrap_or_else(|f| panic!("{f}")))
            .collect();
        (sim, reports)
    };
    let (serial, rs) = run_with(1);
    let (threaded, rt) = run_with(2);
    assert!(
        rs.last().unwrap().energy.plastic_dissipation > 0.0,
        "the run reaches yield"
    );
    for (a, b) in rs.iter().zip(&rt) {
        assert_eq!(a.energy, b.energy, "step {}", a.step);
    }
    assert_eq!(point_bits(&serial), point_bits(&threaded));
}

#[test]
fn more_threads_than_the_work_splits_into_give_the_serial_run_to_the_bit() {
    // Twelve threads: more than this machine's cores, and more than the
    // chunks (of at least 1024 points) the material update splits the
    // collision's 4828 points into. The first ten steps equal the serial
    // run's bit for bit: only the split of the work among threads depends
    // on their number.
    let run_with = |threads: usize| {
        let mut sim = sim_with("ghost-collision-plastic", |s| s.analysis.condition_every = 0);
        assert_eq!(sim.set_threads(threads), Ok(threads));
        for _ in 0..10 {
            sim.step().unwrap_or_else(|f| panic!("{threads} threads: {f}"));
        }
        point_bits(&sim)
    };
    assert_eq!(run_with(1), run_with(12));
}

/// An elastic ghost (E = 1 kPa, rho = 1000 kg/m^3, h = 0.1 m, GIMP,
/// stabilised consistent mass, USF, FLIP) stretching at 1/s about its
/// centre while it flies along x at `speed` (m/s) under gravity `gx`
/// (m/s^2), for `duration` s in `steps` steps, cut back at most
/// `max_cutbacks` halvings deep.
fn flying_ghost(speed: f64, gx: f64, duration: f64, steps: usize, max_cutbacks: usize) -> Simulation {
    let body = format!(
        r#"
[[body]]
name = "ghost"
material = "jelly"
points_per_cell = 1
basis = "gimp"
placement = "lattice"
lattice = [31, 31]
region = {{ shape = "ghost", min = [0.3, 0.3], size = 0.4 }}
velocity = [{speed:?}, 0.0]
velocity_gradient = [[1.0, 0.0], [0.0, 1.0]]
velocity_centre = [0.5, 0.5]
"#
    );
    jelly("flying-ghost", &body, gx, duration, steps, max_cutbacks, "stabilised")
}

/// A 0.4 m square block of `jelly` (2x2 points per cell) from (0.3, 0.3) to
/// (0.7, 0.7) m on [`jelly`]'s grid.
const JELLY_BLOCK: &str = r#"
[[body]]
name = "block"
material = "jelly"
points_per_cell = 2
region = { shape = "rectangle", min = [0.3, 0.3], max = [0.7, 0.7] }
"#;

/// An explicit run (USF, FLIP, the mass matrix `mass`: "consistent",
/// "stabilised" or "lumped") of `body` made of a 1000 kg/m^3 jelly
/// (E = 1 kPa) on a 3 m x 1 m grid of h = 0.1 m, under gravity `gx`
/// (m/s^2) along x, for `duration` s in `steps` steps, cut back at most
/// `max_cutbacks` halvings deep.
fn jelly(name: &str, body: &str, gx: f64, duration: f64, steps: usize, max_cutbacks: usize, mass: &str) -> Simulation {
    jelly_under(name, body, [gx, 0.0], duration, steps, max_cutbacks, mass)
}

/// [`jelly`] under gravity `g` (m/s^2) in any direction.
fn jelly_under(
    name: &str,
    body: &str,
    g: [f64; 2],
    duration: f64,
    steps: usize,
    max_cutbacks: usize,
    mass: &str,
) -> Simulation {
    let (gx, gy) = (g[0], g[1]);
    let text = format!(
        r#"
[scene]
name = "{name}"

[grid]
origin = [0.0, 0.0]
size = [3.0, 1.0]
h = 0.1

[[material]]
name = "jelly"
E = 1000.0
nu = 0.3
density = 1000.0
{body}
[loads]
gravity = [{gx:?}, {gy:?}]

[analysis]
kind = "explicit-dynamics"
duration = {duration:?}
load_steps = {steps}
mass = "{mass}"
stress_update = "usf"
velocity_update = "flip"
condition_every = 0
max_cutbacks = {max_cutbacks}
"#
    );
    Simulation::new(mpmlab_engine::Model::from_text(&text, &format!("{name}.toml")).unwrap_or_else(|e| panic!("{e}")))
}

#[test]
fn a_time_step_moving_points_past_a_cell_is_cut_back() {
    // 3 m/s for 0.5 s in 10 steps of 0.05 s: the points move 0.15-0.16 m a
    // step, more than a cell (h = 0.1 m), and every step fails at dt; in
    // halves (0.075-0.08 m) they do not. The scheme is stable at dt / 2
    // (c = sqrt((lambda + 2 mu) / rho) ~ 1.2 m/s, c dt / 2 / h ~ 0.3).
    let (duration, steps) = (0.5, 10);
    // The papers' fixed time step: the first step fails, nothing moves.
    let mut fixed = flying_ghost(3.0, 0.0, duration, steps, 0);
    let start = point_bits(&fixed);
    let failure = fixed.step().expect_err("a step of 0.15 m must fail at dt");
    println!("max_cutbacks = 0: {failure}");
    // The message names the mass the step used (here the stabilised one).
    assert!(
        matches!(&failure, StepFailure::Diverged { reason, .. } if reason.contains("more than a cell")
            && reason.contains("the time step is too large or the stabilised mass is ill-conditioned")),
        "{failure}"
    );
    assert_eq!(fixed.step_index(), 0);
    assert_eq!(point_bits(&fixed), start);

    // Cut back: every step is two halves, reported once, at t_n = n dt
    // exactly (dt / 2 + dt / 2 = dt in binary floating point).
    let mut cut = flying_ghost(3.0, 0.0, duration, steps, 4);
    let reports = run(&mut cut);
    assert_eq!(reports.len(), steps);
    let dt = duration / steps as f64;
    for (n, r) in reports.iter().enumerate() {
        let d = r.dynamics.as_ref().unwrap();
        assert_eq!(r.step, n + 1);
        assert_eq!(r.load_steps, steps);
        assert_eq!(d.time, (n + 1) as f64 * dt);
        assert_eq!(d.dt, dt);
        assert_eq!(r.cutbacks().len(), 1, "step {}: {:?}", r.step, r.cutbacks());
        assert_eq!(d.substeps, 2);
        // Each half moves the points 0.075-0.08 m, so some change cells and
        // the second half maps other blocks than the first: the step did
        // not reuse the mass pattern throughout.
        assert!(!d.pattern_reused, "step {}", r.step);
        let c = &r.cutbacks()[0];
        assert!(c.reason.contains("more than a cell"), "{}", c.reason);
        assert!((c.to - c.from - dt).abs() < 1e-15, "{c:?}");
        // A sub-step of dt / 2 moved the points less than a cell.
        assert!(d.max_speed * dt / 2.0 < 0.1, "{}", d.max_speed);
        // The step's increment is that of the whole step, as for a step not
        // cut back (the largest grid speed times dt): more than a cell,
        // which is why it was cut back.
        assert_eq!(r.max_increment, d.max_speed * dt);
        assert!(r.max_increment > 0.1, "step {}: {} m", r.step, r.max_increment);
    }

    // The same as twice the steps at the papers' fixed step: the sub-steps
    // of dt / 2 are the steps of that run (duration / 20 = (duration / 10)
    // / 2 exactly), so the two agree to round-off (measured: bit for bit);
    // 1e-12 of each field's scale leaves room for a different order of sums
    // only, while a lost, doubled or misplaced sub-step moves the points by
    // 0.08 m and changes the stresses at first order.
    let mut fine = flying_ghost(3.0, 0.0, duration, 2 * steps, 0);
    let fine_reports = run(&mut fine);
    // Steps not cut back report the same increment: the largest grid speed
    // times their dt, here less than a cell.
    for r in &fine_reports {
        let d = r.dynamics.as_ref().unwrap();
        assert_eq!(r.max_increment, d.max_speed * d.dt);
        assert!(
            r.max_increment > 0.05 && r.max_increment < 0.1,
            "step {}: {} m",
            r.step,
            r.max_increment
        );
    }
    let (a, b) = (cut.points(), fine.points());
    let close = |x: f64, y: f64, scale: f64| (x - y).abs() <= 1e-12 * scale;
    let stress_scale = (0..b.len())
        .flat_map(|p| b.stress[p])
        .fold(0.0f64, |m, s| m.max(s.abs()));
    assert!(stress_scale > 1.0, "the ghost is stressed: {stress_scale:e} Pa");
    for p in 0..b.len() {
        for k in 0..2 {
            assert!(close(a.x[p][k], b.x[p][k], 1.0), "x {p}: {:?} {:?}", a.x[p], b.x[p]);
            assert!(close(a.v[p][k], b.v[p][k], 3.0), "v {p}: {:?} {:?}", a.v[p], b.v[p]);
        }
        for k in 0..3 {
            assert!(
                close(a.stress[p][k], b.stress[p][k], stress_scale),
                "stress {p}: {:?} {:?}",
                a.stress[p],
                b.stress[p]
            );
        }
    }
    let dx = (0..b.len()).map(|p| (a.x[p][0] - b.x[p][0]).hypot(a.x[p][1] - b.x[p][1]));
    println!(
        "cut back against 2 x the steps: largest position difference {:e} m",
        dx.fold(0.0, f64::max)
    );
    let (rc, rf) = (reports.last().unwrap(), fine_reports.last().unwrap());
    let w = |r: &mpmlab_engine::StepReport| r.energy.kinetic + r.energy.strain;
    assert!(close(w(rc), w(rf), w(rf)), "{} vs {}", w(rc), w(rf));
    assert_eq!(rc.dynamics.as_ref().unwrap().time, rf.dynamics.as_ref().unwrap().time);
}

#[test]
fn exhausted_time_step_cutbacks_fail_and_restore_the_step_start() {
    // Accelerating at 6 m/s^2 in steps of 0.05 s: from step 7 the points
    // move more than a cell per step (6 t dt > 0.1 m) and one cutback
    // suffices; from about t = 0.67 s (6 t dt / 2 > 0.1 m) it does not and,
    // with at most one halving, the step fails. Its first half may pass:
    // the state must still return to the step's start, bit for bit.
    let mut sim = flying_ghost(0.0, 6.0, 1.0, 20, 1);
    let mut cut = 0;
    let (start, failure) = loop {
        let start = point_bits(&sim);
        let step = sim.step_index();
        match sim.step() {
            Ok(r) => {
                cut += r.cutbacks().len();
                assert!(sim.step_index() == step + 1);
                // The reported balance, cut back or not: kinetic + strain +
                // dissipation - the work of gravity (> 0 here) - W0, to
                // round-off of the largest of them.
                let (e, d) = (&r.energy, r.dynamics.as_ref().unwrap());
                let balance = e.kinetic + e.strain + e.plastic_dissipation - e.external_work - d.initial_energy;
                assert!(e.external_work > 0.0);
                assert!(
                    (d.energy_error - balance).abs() <= 1e-12 * e.external_work.max(d.initial_energy),
                    "step {}: {} vs {balance}",
                    r.step,
                    d.energy_error
                );
            }
            Err(f) => break (start, f),
        }
    };
    println!("{cut} cutbacks, then: {failure}");
    assert!(cut > 0, "steps were cut back before the failure");
    let StepFailure::Diverged { step, reason } = &failure else {
        panic!("{failure}")
    };
    assert!(
        reason.contains("more than a cell") && reason.contains("cutback"),
        "{reason}"
    );
    // The message names the step's dt (0.05 s) and, one halving deep, the
    // smallest sub-step tried (0.025 s).
    assert!(
        reason.contains("of the time step 5.000e-2 s (sub-steps down to 2.500e-2 s; analysis.max_cutbacks = 1)"),
        "{reason}"
    );
    assert_eq!(sim.step_index() + 1, *step);
    assert_eq!(point_bits(&sim), start, "the state is the failed step's start");
    // Stepping again fails the same way, from the same state.
    assert_eq!(sim.step().unwrap_err(), failure);
    assert_eq!(point_bits(&sim), start);

    // At 120 m/s^2 from rest, the first step's halves move the points
    // about 0.08 m and 0.16 m: with two halvings the step goes through, the
    // first half passing at one halving and the second cut again ...
    let (dt, g) = (0.05, 120.0);
    let mut deeper = flying_ghost(0.0, g, 1.0, 20, 2);
    let r = deeper.step().unwrap_or_else(|f| panic!("{f}"));
    let c = r.cutbacks();
    assert_eq!(c.len(), 2, "{c:?}");
    assert!(c[1].from == dt / 2.0 && c[1].to == dt, "{c:?}");
    // ... so with one halving the step fails after its first half was
    // committed, and must return to the start bit for bit.
    let mut sim = flying_ghost(0.0, g, 1.0, 20, 1);
    let start = point_bits(&sim);
    let failure = sim.step().unwrap_err();
    println!("after a committed half: {failure}");
    assert!(
        matches!(&failure, StepFailure::Diverged { step: 1, reason } if reason.contains("1 cutback(s)")),
        "{failure}"
    );
    assert_eq!(sim.step_index(), 0);
    assert_eq!(point_bits(&sim), start, "the state is the step's start");
}

#[test]
fn a_late_step_exhausting_two_halvings_names_its_smallest_sub_step() {
    // Accelerating at 30 m/s^2 in steps of 0.05 s with at most two
    // halvings: a step moves the points more than a cell (0.1 m) from about
    // v = 2 m/s (t = 0.07 s), its half from 4 m/s (0.13 s) and its quarter
    // from 8 m/s (0.27 s, 1.1 m travelled: still on the 3 m grid), when the
    // step fails with its two cutbacks: the whole step from t_n, then its
    // first half from t_n (the quarter is not cut again). The message names
    // the smallest sub-step tried, dt / 4, and the state is the step's start.
    let mut sim = flying_ghost(0.0, 30.0, 2.0, 40, 2);
    let (mut cut, mut deepest) = (0, 0);
    let failure = loop {
        let start = point_bits(&sim);
        match sim.step() {
            Ok(r) => {
                cut += r.cutbacks().len();
                deepest = deepest.max(r.cutbacks().len());
            }
            Err(f) => {
                assert_eq!(point_bits(&sim), start, "the state is the failed step's start");
                break f;
            }
        }
        assert!(sim.step_index() < 40, "no step failed");
    };
    println!("{cut} cutbacks before, at most {deepest} in a step, then: {failure}");
    let t = sim.step_index() as f64 * 0.05;
    assert!(t > 0.2, "the failure comes after several steps: t_n = {t} s");
    assert!(deepest >= 2, "steps were cut back twice before the failure");
    let StepFailure::Diverged { reason, .. } = &failure else {
        panic!("{failure}")
    };
    assert!(
        reason.contains(
            "still failing after 2 cutback(s) of the time step 5.000e-2 s (sub-steps down to 1.250e-2 s; analysis.max_cutbacks = 2)"
        ),
        "{reason}"
    );
}

#[test]
fn a_stabilised_mass_without_its_penalty_is_the_consistent_one() {
    // G (20): M_s = M + gamma_M J_G. With gamma_M = 0 the step uses (and
    // reports) the consistent mass; with the default rho/4 the stabilised
    // one; the lumped mass stays lumped with or without a penalty.
    for (mass, gamma_m, want) in [
        (MassKind::Stabilised, Some(0.0), MassKind::Consistent),
        (MassKind::Stabilised, None, MassKind::Stabilised),
        (MassKind::Stabilised, Some(1e-3), MassKind::Stabilised),
        (MassKind::Lumped, None, MassKind::Lumped),
        (MassKind::Consistent, Some(250.0), MassKind::Consistent),
    ] {
        let mut sim = sim_with("ghost-collision-elastic", |s| {
            s.analysis.mass = mass;
            s.analysis.gamma_m = gamma_m;
            s.analysis.condition_every = 0;
        });
        let r = sim.step().unwrap_or_else(|f| panic!("{f}"));
        assert_eq!(
            r.dynamics.as_ref().unwrap().mass,
            want,
            "{mass:?} with gamma_M {gamma_m:?}"
        );
    }
}

#[test]
fn a_cancelled_step_is_not_cut_back() {
    // The step fails at dt (points would move 0.15 m > h) and would be cut
    // back; with the observer's stop flag set it is cancelled instead, at
    // the step's start.
    let mut sim = flying_ghost(3.0, 0.0, 0.5, 10, 4);
    let start = point_bits(&sim);
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    sim.set_cancel(Some(stop.clone()));
    let failure = sim.step().unwrap_err();
    assert!(matches!(failure, StepFailure::Cancelled { step: 1, .. }), "{failure}");
    assert_eq!(sim.step_index(), 0);
    assert_eq!(point_bits(&sim), start);
    // Without the flag the same step goes through cut back.
    stop.store(false, std::sync::atomic::Ordering::SeqCst);
    let r = sim.step().unwrap_or_else(|f| panic!("{f}"));
    assert_eq!(r.cutbacks().len(), 1);
}

#[test]
fn free_fall_kinetic_energy_and_gravity_work_are_closed_forms() {
    // A 0.4 m x 0.4 m block (1000 kg/m^3: M = 160 kg) falls from rest
    // under gravity g along x, on a grid its sides follow. A uniform
    // field is in every mass's range (partition of unity; the ghost mass
    // J_G leaves it alone) and strains nothing, so after step k every
    // grid and point velocity is k g dt: the points' kinetic energy is
    // M (n g dt)^2 / 2, and the work of gravity, summed each step as
    // f . v_{n+1} dt, is M g^2 dt^2 n (n + 1) / 2 (the rule's first-order
    // error is then the energy balance, -M g^2 dt^2 n / 2). The grid's
    // kinetic energy v.M v / 2 is the points' too: the masses' entries
    // (lumped, or consistent with the ghost term) sum to M over a uniform
    // field.
    let (g, dt, steps) = (2.0, 0.01, 10);
    let block = JELLY_BLOCK;
    // Along x and along y: each direction's body force is its own.
    for (mass_matrix, gravity) in [
        ("stabilised", [g, 0.0]),
        ("lumped", [g, 0.0]),
        ("stabilised", [0.0, g]),
        ("lumped", [0.0, g]),
    ] {
        let mut sim = jelly_under("free-fall", block, gravity, dt * steps as f64, steps, 0, mass_matrix);
        let reports = run(&mut sim);
        let mass = 1000.0 * 0.4 * 0.4;
        // Round-off: a mass solve (condition below 1e3) per step, summed
        // over 10 steps: 1e-10 relative leaves a wide margin; the mutant
        // that adds f dt to v instead of multiplying misses by a factor of
        // order 1.
        for r in &reports {
            let (n, dyn_) = (r.step as f64, r.dynamics.as_ref().expect("explicit"));
            let kinetic = 0.5 * mass * (n * g * dt).powi(2);
            let work = mass * g * g * dt * dt * n * (n + 1.0) / 2.0;
            for (what, got) in [("points", r.energy.kinetic), ("grid", dyn_.kinetic_grid)] {
                assert!(
                    (got - kinetic).abs() < 1e-10 * kinetic,
                    "{mass_matrix}, gravity {gravity:?}, step {n}: {what} kinetic energy {got} vs {kinetic}"
                );
            }
            assert!(
                (r.energy.external_work - work).abs() < 1e-10 * work,
                "{mass_matrix}, step {n}: {} vs {work}",
                r.energy.external_work
            );
            let balance = -0.5 * mass * g * g * dt * dt * n;
            assert!(
                (dyn_.energy_error - balance).abs() < 1e-9 * work,
                "{mass_matrix}, step {n}: {} vs {balance}",
                dyn_.energy_error
            );
        }
        // The energies do not see the direction: every point moves at
        // n g dt along g itself (same round-off).
        let v = [0, 1].map(|d| gravity[d] * dt * steps as f64);
        for (i, got) in sim.points().v.iter().enumerate() {
            assert!(
                (0..2).all(|d| (got[d] - v[d]).abs() < 1e-10 * g * dt * steps as f64),
                "{mass_matrix}, gravity {gravity:?}, point {i}: v {got:?} vs {v:?}"
            );
        }
    }
}

#[test]
fn a_tight_energy_guard_counts_strain_energy() {
    // G 5.2's collision (stabilised mass, USF) keeps kinetic + strain
    // energy within about 0.3% of W0 (G Table 3: 0.9e-3 on average). Its
    // largest gain, +0.3%, comes while the ghosts are compressed, with more
    // than half of W0 stored as strain. A guard of 1.001 x W0 (no loads, no
    // dissipation) must stop the run at the first step whose kinetic +
    // strain energy passes it. A guard that missed the strain energy would
    // let the whole run through, as kinetic energy alone stays below W0
    // while the ghosts are in contact.
    let factor = 1.001;
    let mut sim = sim_with("ghost-collision-elastic", |s| {
        s.analysis.condition_every = 0;
        s.analysis.max_cutbacks = 0;
        s.analysis.blowup_factor = factor;
    });
    let mut strain_share = 0.0;
    let failure = loop {
        match sim.step() {
            Ok(r) => {
                let (e, w0) = (&r.energy, r.dynamics.as_ref().unwrap().initial_energy);
                assert!(e.external_work == 0.0 && e.plastic_dissipation == 0.0);
                assert!(
                    e.kinetic + e.strain <= factor * w0,
                    "step {}: accepted at {} x W0",
                    r.step,
                    (e.kinetic + e.strain) / w0
                );
                strain_share = e.strain / (e.kinetic + e.strain);
                assert!(!sim.finished(), "the run passed a {factor} x W0 guard");
            }
            Err(f) => break f,
        }
    };
    println!("1.001 x W0 guard: {failure}; strain share before it {strain_share:.3}");
    assert!(
        matches!(&failure, StepFailure::Diverged { reason, .. } if reason.contains("kinetic + strain energy")),
        "{failure}"
    );
    // The guard trips during contact, not at the start (no strain yet),
    // and its report tells the two energies apart at this ratio.
    assert!(strain_share > 0.5, "strain share {strain_share}");
    assert_eq!(sim.step_index() + 1, failure.step());
    let reason = failure.to_string();
    let number_after = |key: &str| -> f64 {
        let rest = &reason[reason.find(key).unwrap() + key.len()..];
        rest.split_whitespace().next().unwrap().parse().unwrap()
    };
    let (energy, limit) = (number_after("strain energy "), number_after(") = "));
    assert!(energy > limit && energy < 1.01 * limit, "{reason}");
}

#[test]
fn conditioning_is_measured_at_the_first_step_and_every_nth() {
    // `condition_every = 3`: the mass conditioning (dense eigenvalues) is
    // measured at step 1, so a run shows it from its start, and then at
    // every third step; 0 never measures it.
    for (every, expected) in [(3, vec![1, 3, 6]), (0, vec![])] {
        let mut sim = sim_with("translating-ghost", |s| s.analysis.condition_every = every);
        let measured: Vec<usize> = (0..7)
            .map(|_| sim.step().unwrap_or_else(|f| panic!("{f}")))
            .filter(|r| r.dynamics.as_ref().unwrap().conditioning.is_some())
            .map(|r| r.step)
            .collect();
        assert_eq!(measured, expected, "condition_every = {every}");
    }
}

#[test]
fn explicit_points_carry_the_hencky_stress_and_domains_of_their_stretch() {
    // The elastic ghost stretching at 1/s for 0.2 s (4 steps), GIMP: every
    // point's Cauchy stress is the Hencky stress of its own deformation
    // gradient F, sigma = tau / J with tau = lambda tr(e) I + 2 mu e,
    // e = ln(F F^T) / 2 (plane strain: e_zz = 0, tau_zz = lambda tr e;
    // elastic, so b_e = F F^T), written out here from F's eigenvalues; and
    // its GIMP half-lengths are the initial ones times the diagonal of the
    // right stretch U = sqrt(F^T F) (cpGIMP's domain update), by the 2 x 2
    // closed form U = (C + sqrt(det C) I) / sqrt(tr C + 2 sqrt(det C)).
    // Both to round-off of the incremental updates (b_e = dF b_e dF^T step
    // by step): 1e-10 relative.
    let mut sim = flying_ghost(0.0, 0.0, 0.2, 4, 0);
    run(&mut sim);
    let p = sim.points();
    let (e, nu) = (1000.0, 0.3);
    let (k, mu) = (e / (3.0 * (1.0 - 2.0 * nu)), e / (2.0 * (1.0 + nu)));
    let lambda = k - 2.0 * mu / 3.0;
    let scale = (0..p.len())
        .flat_map(|i| p.stress[i])
        .fold(0.0f64, |m, s| m.max(s.abs()));
    assert!(scale > 10.0, "the ghost is stressed: {scale} Pa");
    let mut stretched = 0.0f64;
    for i in 0..p.len() {
        let [f00, f01, f10, f11] = p.def_grad[i];
        let j = f00 * f11 - f01 * f10;
        // b = F F^T and its eigen-decomposition.
        let (a, c, d) = (f00 * f00 + f01 * f01, f00 * f10 + f01 * f11, f10 * f10 + f11 * f11);
        let (m, r) = (0.5 * (a + d), (0.25 * (a - d).powi(2) + c * c).sqrt());
        let th = 0.5 * (2.0 * c).atan2(a - d);
        let (sn, co) = th.sin_cos();
        let (e1, e2) = (0.5 * (m + r).ln(), 0.5 * (m - r).ln());
        let tr = e1 + e2;
        let (t1, t2) = (lambda * tr + 2.0 * mu * e1, lambda * tr + 2.0 * mu * e2);
        let want = [
            (t1 * co * co + t2 * sn * sn) / j,
            (t1 * sn * sn + t2 * co * co) / j,
            (t1 - t2) * sn * co / j,
        ];
        let got = p.stress[i];
        for q in 0..3 {
            assert!(
                (got[q] - want[q]).abs() < 1e-10 * scale,
                "point {i}: {got:?} vs {want:?}"
            );
        }
        assert!(
            (p.szz[i] - lambda * tr / j).abs() < 1e-10 * scale,
            "point {i}: s_zz {}",
            p.szz[i]
        );
        // C = F^T F and U = sqrt(C).
        let (c00, c01, c11) = (f00 * f00 + f10 * f10, f00 * f01 + f10 * f11, f01 * f01 + f11 * f11);
        let sd = (c00 * c11 - c01 * c01).sqrt();
        let den = (c00 + c11 + 2.0 * sd).sqrt();
        let u = [(c00 + sd) / den, (c11 + sd) / den];
        for q in 0..2 {
            let want = p.lp0[i][q] * u[q];
            assert!(
                (p.lp[i][q] - want).abs() < 1e-10 * want,
                "point {i}: l_p {:?} vs {want}",
                p.lp[i]
            );
            stretched = stretched.max(u[q]);
        }
    }
    println!("largest stretch {stretched:.4}, largest stress {scale:.3e} Pa");
    assert!(stretched > 1.1, "the domains are stretched: {stretched}");
}

#[test]
fn explicit_mass_conditioning_follows_the_requested_method() {
    // `analysis.condition`: dense eigenvalues or a Lanczos run at each end
    // of the spectrum, whatever the size (`auto` picks by `dense_limit`).
    // The translating ghost's masses at step 1 (a few hundred dofs, under
    // the dense limit). The stabilised mass: each method is the one asked
    // for, and the two agree as the column's stiffness does (Lanczos stops
    // when the extreme Ritz values settle to 1e-10: 1e-6 relative). The
    // consistent mass of its cut cells is not numerically positive
    // definite (G 5.1.1), whichever method was asked for: its condition is
    // infinite, and under the dense limit its dense eigenvalues say why,
    // the smallest at round-off of the largest (1e-12 relative; below 0
    // or just above).
    let cond = |mode| {
        let mut sim = sim_with("translating-ghost", |s| s.analysis.condition = mode);
        let r = sim.step().unwrap_or_else(|f| panic!("{f}"));
        r.dynamics.unwrap().conditioning.unwrap()
    };
    let (d, l) = (cond(ConditionMode::Dense), cond(ConditionMode::Lanczos));
    let (ds, ls) = (&d.mass_stabilised, &l.mass_stabilised);
    assert_eq!(
        (ds.method, ls.method),
        (ConditionMethod::Dense, ConditionMethod::Lanczos)
    );
    assert!(
        (ds.value - ls.value).abs() < 1e-6 * ds.value,
        "dense {:e}, Lanczos {:e}",
        ds.value,
        ls.value
    );
    for c in [&d.mass_consistent, &l.mass_consistent] {
        assert_eq!(c.method, ConditionMethod::NotPositiveDefinite, "{c:?}");
        assert_eq!(c.value, f64::INFINITY);
        assert!(c.lambda_max > 0.0 && c.lambda_max.is_finite(), "{c:?}");
        assert!(c.lambda_min.abs() < 1e-12 * c.lambda_max, "{c:?}");
    }
    println!("stabilised {ds:?}\nconsistent {:?}", d.mass_consistent);
}

#[test]
fn explicit_cutbacks_halve_the_sub_step_where_it_failed() {
    // The ghost accelerating at 30 m/s^2 in steps of 0.05 s, cut back at
    // most three times: as its speed passes 2, 4 and 8 m/s, steps, their
    // halves and then their quarters move points more than a cell, until a
    // point leaves the 3 m grid (step 8). Each cut is recorded where it
    // happened (`cutback::push_halves`): the whole step [t_n, t_n + dt]
    // first, then each failing half, quarter or eighth, spanning dt / 2^j
    // (j <= max_cutbacks) and starting on that binary grid inside the
    // step. The later parts fail first here (the ghost is faster at their
    // start), so cuts of a second half and of a second quarter (steps 6
    // and 7) are seen. Round-off of the times: 1e-9 of a sub-step.
    let mut sim = flying_ghost(0.0, 30.0, 2.0, 40, 3);
    let dt = 0.05;
    let mut later = 0;
    let failure = loop {
        let r = match sim.step() {
            Ok(r) => r,
            Err(f) => break f,
        };
        let t0 = (r.step - 1) as f64 * dt;
        let cuts: Vec<(f64, f64)> = r.cutbacks().iter().map(|c| (c.from, c.to)).collect();
        println!("step {}: {cuts:?}", r.step);
        let Some(&(a, b)) = cuts.first() else { continue };
        assert!(
            (a - t0).abs() < 1e-12 * dt && (b - t0 - dt).abs() < 1e-12 * dt,
            "step {}: {cuts:?}",
            r.step
        );
        for &(from, to) in &cuts[1..] {
            common::assert_binary_part((from, to), (t0, dt), 3, 1e-9, &format!("step {}", r.step));
            later += (from > t0 + 1e-12 * dt) as usize;
        }
        assert!(sim.step_index() < 40, "no step failed");
    };
    println!("{failure}");
    assert!(later > 0, "a cut that starts past t_n was seen");
}

/// The step's cutbacks `cuts` (s) are the fractions `want` of its time
/// step `dt` (a step starting at 0), to 1e-12 of `dt`: round-off of
/// `t + dt / 2^j` (0.05 s is not binary).
fn assert_cuts(cuts: &[(f64, f64)], want: &[(f64, f64)], dt: f64) {
    assert_eq!(cuts.len(), want.len(), "{cuts:?}");
    for (&(a, b), &(wa, wb)) in cuts.iter().zip(want) {
        assert!(
            (a - wa * dt).abs() < 1e-12 * dt && (b - wb * dt).abs() < 1e-12 * dt,
            "{cuts:?}, want {want:?} of {dt}"
        );
    }
}

/// The ghost of [`flying_ghost`] without its velocity gradient: every
/// point at `speed` m/s along x, accelerated by `gx` m/s^2, in steps of
/// 0.05 s, cut back at most `max_cutbacks` halvings deep.
fn translating_ghost(speed: f64, gx: f64, max_cutbacks: usize) -> Simulation {
    let body = format!(
        r#"
[[body]]
name = "ghost"
material = "jelly"
points_per_cell = 1
basis = "gimp"
placement = "lattice"
lattice = [31, 31]
region = {{ shape = "ghost", min = [0.3, 0.3], size = 0.4 }}
velocity = [{speed:?}, 0.0]
"#
    );
    jelly("translating-ghost", &body, gx, 0.5, 10, max_cutbacks, "stabilised")
}

#[test]
fn a_failing_second_quarter_is_cut_back_no_deeper_than_allowed() {
    // The ghost starting at rest under 200 m/s^2 along x (h = 0.1 m, dt =
    // 0.05 s): a sub-step of dt / 2^j ending at speed u moves the points
    // u dt / 2^j (the stabilised mass reproduces a uniform velocity), and
    // u = 10 tau m/s at the fraction tau of the step. The whole step moves
    // them 0.5 m, each half 0.125 m and 0.25 m: all more than a cell, all
    // cut. The first half's quarters move them 0.031 m and 0.063 m; the
    // second half's 0.094 m (third quarter) and 0.125 m (fourth): the
    // fourth fails once more, two halvings deep; its eighths move them
    // 0.055 m and 0.063 m. Margins: 6% of a cell at the tightest, far
    // beyond the ghost's round-off. So:
    // - max_cutbacks = 2: the fourth quarter, two halvings deep already,
    //   is not cut again, and the step fails with the state at its start
    //   (`cutback::push_halves` gives both halves of a part depth + 1);
    // - max_cutbacks = 3: the step is the first half's two quarters, the
    //   third quarter and the fourth quarter's two eighths, cut at the
    //   whole step, its halves and the fourth quarter.
    let dt = 0.05;
    let mut shallow = translating_ghost(0.0, 200.0, 2);
    let start = point_bits(&shallow);
    let failure = shallow
        .step()
        .expect_err("the fourth quarter must fail and may not be cut");
    println!("max_cutbacks = 2: {failure}");
    // Three cutbacks recorded (the whole step and its halves): the failing
    // fourth quarter is not cut, so the smallest sub-step tried is dt / 4.
    assert!(
        matches!(&failure, StepFailure::Diverged { reason, .. }
            if reason.contains("more than a cell")
                && reason.contains("still failing after 3 cutback(s) of the time step 5.000e-2 s (sub-steps down to 1.250e-2 s")),
        "{failure}"
    );
    assert_eq!(shallow.step_index(), 0);
    assert_eq!(point_bits(&shallow), start);

    let mut deep = translating_ghost(0.0, 200.0, 3);
    let r = deep.step().unwrap_or_else(|f| panic!("max_cutbacks = 3: {f}"));
    let cuts: Vec<(f64, f64)> = r.cutbacks().iter().map(|c| (c.from, c.to)).collect();
    println!("max_cutbacks = 3: {cuts:?}");
    assert_cuts(&cuts, &[(0.0, 1.0), (0.0, 0.5), (0.5, 1.0), (0.75, 1.0)], dt);
    assert_eq!(r.dynamics.as_ref().unwrap().substeps, 5);
    // The ghost's speed after the step: g dt, as for a step not cut.
    let v = &deep.points().v;
    // 1e-9 m/s: round-off of FLIP's increments over five sub-steps.
    assert!(
        v.iter().all(|v| (v[0] - 10.0).abs() < 1e-9 && v[1].abs() < 1e-9),
        "{:?}",
        v[0]
    );
}

#[test]
fn a_step_cut_back_inside_its_cells_reuses_the_mass_pattern() {
    // One cell filled with 2 x 2 points, expanding at L = 12 I 1/s about
    // its centre (no translation), standard basis: the stabilised mass
    // of one cell's four points reproduces that linear
    // field exactly, so the whole step's deformation increment is dF =
    // I + 12 dt I, |dF - I| = 12 sqrt(2) dt = 0.85 for dt = 0.05 s, more
    // than the explicit guard's 1/2 (the step's first attempt reports
    // it); its halves deform the block less than that (0.42 for the
    // first). The points start 0.025 m from the centre in each direction,
    // a quarter cell inside their cell, and stay in it (the test checks
    // where they end): no point changes cell, so every attempt of the
    // step maps the same blocks. The failed whole step factorises the
    // pattern, both halves reuse it, and the step reports the pattern reused
    // (`cutback::Merged::add`: reused only if every sub-step reused it).
    let body = r#"
[[body]]
name = "block"
material = "jelly"
points_per_cell = 1
placement = "lattice"
lattice = [2, 2]
region = { shape = "rectangle", min = [0.3, 0.3], max = [0.4, 0.4] }
velocity_gradient = [[12.0, 0.0], [0.0, 12.0]]
velocity_centre = [0.35, 0.35]
"#;
    let mut sim = jelly("expanding-block", body, 0.0, 0.5, 10, 2, "stabilised");
    let r = sim.step().unwrap_or_else(|f| panic!("{f}"));
    println!("{:?}", r.cutbacks());
    assert_eq!(r.cutbacks().len(), 1, "{:?}", r.cutbacks());
    assert!(
        r.cutbacks()[0].reason.contains("deform by |dF - I| = 8.485e-1"),
        "{}",
        r.cutbacks()[0].reason
    );
    let d = r.dynamics.as_ref().unwrap();
    assert_eq!(d.substeps, 2);
    let x = &sim.points().x;
    assert!(x.iter().flatten().all(|&c| c > 0.3 && c < 0.4), "{x:?}");
    assert!(d.pattern_reused, "every attempt mapped the same cell");
}

#[test]
fn a_step_whose_middle_sub_step_changes_cells_does_not_reuse_the_mass_pattern() {
    // A 2 x 2 block of points 0.01 m apart (x = 0.329, 0.339 m in the cell
    // [0.3, 0.4]) at 8 m/s along x, braked at 110 m/s^2 (h = 0.1 m, dt =
    // 0.05 s, consistent mass: the grid reproduces a uniform velocity).
    // A sub-step of dt / 2^j ending at speed u moves the points u dt / 2^j,
    // with u = 8 - 5.5 tau m/s at the fraction tau of the step: the whole
    // step 0.125 m and its first half 0.131 m, more than a cell, both cut;
    // the first half's quarters 0.083 m and 0.066 m, the second half
    // 0.063 m. Each sub-step maps the points where it starts: the first
    // quarter in the first cell (the failed attempts' pattern: reused),
    // the second quarter in the next cell ([0.41, 0.42] m: a new pattern),
    // the second half still there ([0.48, 0.49] m: reused). Margins: 0.012
    // m from the cells' edges. The step reused the pattern only if every
    // sub-step did (`cutback::Merged::add`): not here, though its first
    // and last sub-steps did.
    let body = r#"
[[body]]
name = "block"
material = "jelly"
points_per_cell = 1
placement = "lattice"
lattice = [2, 2]
region = { shape = "rectangle", min = [0.324, 0.34], max = [0.344, 0.36] }
velocity = [8.0, 0.0]
"#;
    let dt = 0.05;
    let mut sim = jelly("braked-block", body, -110.0, 0.5, 10, 2, "consistent");
    let x0: Vec<f64> = sim.points().x.iter().map(|x| x[0]).collect();
    assert!(
        x0.iter()
            .all(|&x| (x - 0.329).abs() < 1e-12 || (x - 0.339).abs() < 1e-12),
        "{x0:?}"
    );
    let r = sim.step().unwrap_or_else(|f| panic!("{f}"));
    let cuts: Vec<(f64, f64)> = r.cutbacks().iter().map(|c| (c.from, c.to)).collect();
    println!("{cuts:?}");
    assert_cuts(&cuts, &[(0.0, 1.0), (0.0, 0.5)], dt);
    let d = r.dynamics.as_ref().unwrap();
    assert_eq!(d.substeps, 3);
    // Where the step leaves the points: 0.0828 + 0.0656 + 0.0625 m on.
    // 1e-9 m: round-off of three sub-steps.
    let moved = 0.025 * 2.5 + 0.0125 * (6.625 + 5.25);
    for (x, x0) in sim.points().x.iter().zip(&x0) {
        assert!((x[0] - x0 - moved).abs() < 1e-9, "{} from {x0}", x[0]);
    }
    assert!(!d.pattern_reused, "the second quarter mapped a new cell");
}

#[test]
fn a_gimp_domain_a_ten_thousandth_of_a_millimetre_cell_past_the_edge_has_left_the_grid() {
    // Two GIMP points (l_p = h / 2) tiling the right half of a grid of 1 mm
    // cells: the right one's domain ends on the grid's edge (x = 4 mm). In
    // one explicit step of 1e-4 s at speed v along x (stress-free, a uniform
    // velocity the lumped mass reproduces) the domain ends v 1e-4 m
    // past the edge. The edge's tolerance is round-off of the cell (1e-9
    // h, `dynamics::explicit::gimp_domains_inside`): a domain past it by 1e-10 h
    // stays in the grid, one past it by 1e-4 h (0.1 um) has left it, in
    // millimetres as in metres.
    let run = |past: f64| {
        let h = 1e-3;
        let dt = 1e-4;
        let text = format!(
            r#"
[scene]
name = "millimetre-edge"

[grid]
origin = [0.0, 0.0]
size = [0.004, 0.002]
h = {h:?}

[[material]]
name = "jelly"
E = 1000.0
nu = 0.3
density = 1000.0

[[body]]
name = "pair"
material = "jelly"
points_per_cell = 1
basis = "gimp"
placement = "lattice"
lattice = [2, 1]
region = {{ shape = "rectangle", min = [0.002, 0.0005], max = [0.004, 0.0015] }}
velocity = [{v:?}, 0.0]

[analysis]
kind = "explicit-dynamics"
duration = {dt:?}
load_steps = 1
mass = "lumped"
condition_every = 0
"#,
            v = past * h / dt
        );
        let mut sim = Simulation::new(
            mpmlab_engine::Model::from_text(&text, "millimetre-edge.toml").unwrap_or_else(|e| panic!("{e}")),
        );
        let p = sim.points();
        let right = (0..p.len()).max_by(|&a, &b| p.x[a][0].total_cmp(&p.x[b][0])).unwrap();
        // The domain ends on the edge to round-off of 4 mm (1e-18 m).
        assert!(
            (p.x[right][0] + p.lp[right][0] - 0.004).abs() < 1e-15,
            "{:?}",
            p.x[right]
        );
        (sim.step(), right)
    };
    let (inside, _) = run(1e-10);
    inside.unwrap_or_else(|f| panic!("a domain 1e-10 h past the edge is on it: {f}"));
    let (outside, right) = run(1e-4);
    match outside {
        Err(StepFailure::LeftGrid {
            step: 1,
            point,
            position,
            domain: true,
        }) => {
            assert_eq!(point, right);
            // Its domain's corner: 0.1 um past the edge (round-off 1e-15 m).
            assert!((position[0] - 0.004 - 1e-7).abs() < 1e-15, "{position:?}");
        }
        other => panic!("a domain 1e-4 h past the edge must leave the grid: {other:?}"),
    }
}

#[test]
fn tracking_points_activate_no_node_of_a_lumped_step() {
    // A boundary's tracking points have no volume and no mass: they follow
    // the body and carry nothing. Three of them half a cell beyond the
    // block's right edge (x = 0.75 m: their cells reach the nodes at x =
    // 0.8 m, which no point with volume reaches) must not make those nodes
    // part of an explicit lumped step, which would give them zero mass
    // (no explicit step is then stable). With or without the boundary
    // the step has the same active nodes and unknowns, and both runs
    // complete.
    let block = JELLY_BLOCK;
    let tracked = format!(
        r#"{block}
[[boundary]]
name = "edge"
body = "block"
points = [[0.75, 0.4], [0.75, 0.5], [0.75, 0.6]]
"#
    );
    let mut plain = jelly("lumped-block", block, -1.0, 0.02, 2, 0, "lumped");
    let mut with = jelly("lumped-block-tracked", &tracked, -1.0, 0.02, 2, 0, "lumped");
    assert_eq!(with.points().len(), plain.points().len() + 3);
    let (a, b) = (run(&mut plain), run(&mut with));
    for (a, b) in a.iter().zip(&b) {
        // The cells the step reports active are those its points with
        // volume reach, the tracking points' not among them.
        assert!(a.active_cells > 0, "step {}", a.step);
        assert_eq!(
            (a.active_nodes, a.unknowns, a.active_cells),
            (b.active_nodes, b.unknowns, b.active_cells),
            "step {}",
            a.step
        );
    }
}

#[test]
fn a_translating_body_reports_its_momentum() {
    // The ghost at 1 m/s along x, stress-free, no gravity: after a step
    // every point still moves at 1 m/s (the stabilised mass reproduces a
    // uniform velocity), so the step's momentum is the body's mass times
    // (1, 0) kg m/s per unit thickness (round-off of a sum over the
    // points: 1e-12 of it).
    let mut sim = translating_ghost(1.0, 0.0, 0);
    let r = sim.step().unwrap_or_else(|f| panic!("{f}"));
    let mass: f64 = sim.points().mass.iter().sum();
    let p = r.dynamics.as_ref().unwrap().momentum;
    println!("momentum {p:?}, mass {mass}");
    assert!(mass > 0.0);
    assert!((p[0] - mass).abs() < 1e-12 * mass && p[1].abs() < 1e-12 * mass, "{p:?}");
}

#[test]
fn a_point_load_gives_its_impulse_to_a_free_body() {
    // A free block (lumped mass, no gravity, no support) under a point
    // load of (3, -2) N per unit thickness for one explicit step of dt =
    // 0.01 s: with FLIP the points' momentum changes by the grid's
    // sum_v M_v a_v dt = F dt, so it is (0.03, -0.02) kg m/s after the step
    // (round-off of the sums: 1e-12 of it).
    let body = format!(
        r#"{JELLY_BLOCK}
[[loads.point]]
at = [0.52, 0.47]
force = [3.0, -2.0]
"#
    );
    let mut sim = jelly("point-loaded-block", &body, 0.0, 0.01, 1, 0, "lumped");
    let r = sim.step().unwrap_or_else(|f| panic!("{f}"));
    let p = r.dynamics.as_ref().unwrap().momentum;
    println!("momentum {p:?}");
    let want = [0.03, -0.02];
    assert!(
        (p[0] - want[0]).abs() < 1e-12 * 0.03 && (p[1] - want[1]).abs() < 1e-12 * 0.03,
        "{p:?}"
    );
}
