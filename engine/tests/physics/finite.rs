//! Finite deformation with Newton-Raphson and Ghost stabilisation (Coombs
//! et al.): global tangent against finite differences, Newton's rate, the
//! column under self-weight (G 5.4) and the elastic beam (G 5.5).

use crate::common;
use common::{error, run_all, sim_with};
use mpmlab_engine::exact::elastica_tip;
use mpmlab_engine::{Simulation, StepFailure};

#[test]
fn global_tangent_matches_finite_differences() {
    // A small beam at a random trial increment of 5% of a cell, with and
    // without ghost, elastic and yielding.
    for (gamma, yield_stress) in [(12.0e6, None), (0.0, None), (12.0e6, Some(5.0e4))] {
        let sim = sim_with("elastic-beam-ghost", |s| {
            s.grid.h = 1.0;
            s.grid.origin = [0.0, -9.0];
            s.analysis.gamma_k = gamma;
            if let Some(y) = yield_stress {
                s.materials[0].model = mpmlab_engine::scene::MaterialModel::VonMises;
                s.materials[0].rho_y = Some(y);
            }
        });
        let e = sim.tangent_check(0.05).unwrap();
        // Central differences with eps = 1e-6 h: truncation ~1e-12, round-off
        // ~1e-16/1e-6 = 1e-10 relative to the force scale.
        assert!(e < 1e-6, "gamma {gamma}, yield {yield_stress:?}: {e:e}");
    }
}

#[test]
fn tangent_of_every_contribution_matches_finite_differences() {
    // The implicit boundaries under finite deformation (band blocks, the
    // in-band points' D-weighted gradients with a wide band, GIMP), with
    // ghost, and the load stiffness of a pressure following the deformed
    // surface. Central differences of 1e-6 h carry ~1e-10 relative
    // round-off (the load stiffness itself is a central difference of the
    // same size, so ~1e-9 at worst): 1e-8 leaves a factor 10 (measured:
    // 5e-12 to 8e-11). A load stiffness missing the closed ring's
    // wrapped columns gives 3.5e-7 here at the ring's 1500 Pa.
    let cases: Vec<(&str, Simulation)> = vec![
        ("block, IBM rollers, GIMP", sim_with("block-roller-finite", |_| {})),
        (
            "block, wide band (points inside it), ghost",
            sim_with("block-roller-finite", |s| {
                s.analysis.delta_over_h = 0.3;
                s.analysis.gamma_k = 100.0;
            }),
        ),
        (
            "cantilever clamped by IBM at 45 deg",
            sim_with("slender-cantilever-finite-45", |s| s.grid.h = 4.0),
        ),
        (
            "follower pressure",
            sim_with("cantilever-follower-pressure-finite", |_| {}),
        ),
        (
            // Every kind of block at once: points, ghost faces, band
            // blocks (a band needs delta above round-off) and load
            // columns, each found by its place in the step's list of
            // blocks.
            "follower pressure, ghost, a wide band",
            sim_with("cantilever-follower-pressure-finite", |s| {
                s.analysis.gamma_k = 1.0e3;
                s.analysis.delta_over_h = 0.25;
                // An implicit roller along the beam's underside (off the
                // grid lines), over its grid supports.
                let other = std::fs::read_to_string(common::scene_path("slender-cantilever-finite-45")).unwrap();
                let mut floor = mpmlab_engine::scene::Scene::parse(&other, "slender-cantilever-finite-45")
                    .unwrap()
                    .ibm[0]
                    .clone();
                floor.name = "floor".into();
                floor.kind = mpmlab_engine::scene::DirichletKind::Roller;
                floor.points = vec![[0.0, 0.75], [12.0, 0.75]];
                floor.material_side = Some(mpmlab_engine::scene::MaterialSide::Left);
                s.ibm.push(floor);
            }),
        ),
        (
            // GIMP stencils move a boundary point by more nodes.
            "follower pressure, GIMP",
            sim_with("cantilever-follower-pressure-finite", |s| {
                s.bodies[0].basis = mpmlab_engine::basis::BasisKind::Gimp;
            }),
        ),
        (
            // A closed curve: its load columns wrap around the last point.
            "follower pressure on a closed ring of tracking points",
            sim_with("cantilever-follower-pressure-finite", |s| {
                follower_ring(s, 10, 0.6, 0.0);
            }),
        ),
        (
            // Tracking points farther apart than a node's support (six on
            // a ring of 0.75 m, h = 0.25 m): no node's column holds two of
            // them, so each point's own segments (its k - 3 ..= k + 2) must
            // all be in it, the wrapped ones too (a range ending at 2 k
            // instead, which drops segments of points 0 and 1: 1.6e-6).
            "follower pressure on a ring of points no node shares",
            sim_with("cantilever-follower-pressure-finite", |s| {
                s.grid.h = 0.25;
                // Counter-clockwise, inside the beam on both sides: say which.
                follower_ring(s, 6, 0.75, 0.1).material_side = Some(mpmlab_engine::scene::MaterialSide::Left);
            }),
        ),
        (
            "F-bar, von Mises footing (IBM, yielding)",
            sim_with("rigid-footing-large", |s| {
                s.analysis.fbar = true;
                s.materials[0].rho_y = Some(1.0e3);
            }),
        ),
        (
            // Points inside a band stay out of the F-bar patches (their
            // motion is the band's, not the grid's): at delta = h/4 the
            // 30 deg block's first rows lie in the bands. Taking them into
            // a patch's J_bar, which the tangent leaves out, measured 2.4e-2.
            "F-bar with points in the implicit boundaries' bands",
            sim_with("block-roller-finite", |s| {
                s.analysis.delta_over_h = 0.25;
                s.analysis.fbar = true;
            }),
        ),
        (
            // GIMP domains of half-length 0.625 h (the 20 x 20 lattice of
            // 5 mm on a 4 mm grid): each point's stencil has up to 4 x 4
            // nodes, the most a stencil holds, in the F-bar coupling too.
            "F-bar, GIMP domains wider than half a cell",
            sim_with("block-roller-finite-aligned", |s| {
                s.grid.h = 4.0;
                s.analysis.fbar = true;
            }),
        ),
        (
            "F-bar, GIMP beam with ghost",
            sim_with("elastic-beam-ghost", |s| {
                s.grid.h = 1.0;
                s.grid.origin = [0.0, -9.0];
                s.analysis.fbar = true;
            }),
        ),
    ];
    for (name, sim) in cases {
        let e = sim.tangent_check(0.05).unwrap_or_else(|f| panic!("{name}: {f}"));
        println!("{name}: tangent vs finite differences {e:.2e}");
        assert!(e < 1e-8, "{name}: {e:e}");
        // The same round-off is a floor: central differences of a nonlinear
        // force never agree with the assembled tangent to the bit, so a
        // check that measured nothing (zero) would pass every case above.
        // 1e-15 is over three orders of magnitude below the smallest
        // measured (4.5e-12).
        assert!(e > 1e-15, "{name}: {e:e}: the check measured nothing");
    }
}

/// A closed ring of `n` tracking points of radius `r` (m) about the
/// follower-pressure cantilever's centre line (5, 1.75), the first at angle
/// `phase` (rad), carrying the beam's top pressure: a closed curve's load
/// columns.
fn follower_ring(
    s: &mut mpmlab_engine::scene::Scene,
    n: usize,
    r: f64,
    phase: f64,
) -> &mut mpmlab_engine::scene::BoundarySpec {
    let mut ring = s.boundaries[0].clone();
    ring.name = "ring".into();
    ring.layer = None;
    ring.closed = true;
    ring.points = Some(
        (0..n)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / n as f64 + phase;
                [5.0 + r * a.cos(), 1.75 + r * a.sin()]
            })
            .collect(),
    );
    s.boundaries.push(ring);
    s.boundaries.last_mut().expect("pushed above")
}

#[test]
fn load_stiffness_holds_in_any_units() {
    // The follower-pressure cantilever with every length times 1e-6 (a
    // micrometre-sized beam; E and the pressure, hence the stresses and
    // strains, unchanged) is the metre-sized one in other units: its
    // tangent matches finite differences as well. The spline's
    // collinearity tolerance is relative to its longest chord; an absolute
    // one (1e-12 m^2) would take every triple of this beam's tracking
    // points for collinear (their cross products are about 0.05 h L =
    // 1e-14 m^2 here) in the load stiffness's perturbed curves, but not in
    // the residual's (measured: 1.3e-7 at 1e-6, against 4.8e-11 and
    // 5.3e-11 as built). 1e-8 as in
    // `tangent_of_every_contribution_matches_finite_differences`.
    let scaled = |f: f64| sim_with("cantilever-follower-pressure-finite", |s| common::scale_lengths(s, f));
    for f in [1.0, 1e-6] {
        let e = scaled(f)
            .tangent_check(0.05)
            .unwrap_or_else(|e| panic!("lengths x {f}: {e}"));
        println!("lengths x {f:e}: tangent vs finite differences {e:.2e}");
        assert!(e < 1e-8, "lengths x {f:e}: {e:e}");
    }
}

/// Asymptotic Newton rates of a run: per step, from the last three
/// residuals above `floor` when they decrease.
fn newton_rates(sim: &mut Simulation, floor: f64) -> Vec<f64> {
    let mut rates = Vec::new();
    while !sim.finished() {
        let r = sim.step().unwrap_or_else(|f| panic!("{f}"));
        let res: Vec<f64> = r.residuals.iter().copied().filter(|&x| x > floor).collect();
        if let [.., a, b, c] = res[..] {
            if c < b && b < a {
                rates.push((c / b).ln() / (b / a).ln());
            }
        }
        println!("residuals {:?}", r.residuals);
    }
    rates
}

#[test]
fn follower_pressure_keeps_newton_quadratic() {
    // B 4.2's pressure on the deformed top surface under finite
    // deformation: with its load stiffness in the tangent Newton keeps its
    // quadratic rate (median >= 1.8, as for the beam below).
    let mut sim = sim_with("cantilever-follower-pressure-finite", |s| {
        s.analysis.tolerance = 1e-12;
        s.analysis.max_iterations = 20;
    });
    // The residuals end at ~5e-15 here, so those above 1e-12 are clear of
    // round-off.
    let mut rates = newton_rates(&mut sim, 1e-12);
    println!("asymptotic rates {rates:?}");
    assert!(rates.len() >= 3, "{rates:?}");
    rates.sort_by(f64::total_cmp);
    let median = rates[rates.len() / 2];
    assert!(median >= 1.8, "median rate {median} of {rates:?}");
}

#[test]
fn newton_converges_quadratically() {
    let mut sim = sim_with("elastic-beam-ghost", |s| {
        s.analysis.tolerance = 1e-12;
        s.analysis.max_iterations = 20;
    });
    let mut rates = Vec::new();
    for _ in 0..5 {
        let r = sim.step().unwrap();
        // Asymptotic rate from the last three residuals clear of round-off
        // (the floor is ~1e-13 here, so above 1e-10) once they decrease.
        let res: Vec<f64> = r.residuals.iter().copied().filter(|&x| x > 1e-10).collect();
        if let [.., a, b, c] = res[..] {
            if c < b && b < a {
                rates.push((c / b).ln() / (b / a).ln());
            }
        }
        println!("residuals {:?}", r.residuals);
    }
    println!("asymptotic rates {rates:?}");
    assert!(rates.len() >= 4);
    // A single triple still carries the pre-asymptotic constant (the first
    // of the three may be only just inside the quadratic region), so each
    // step must be clearly superlinear and the median at least 1.8.
    let mut sorted = rates.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    assert!(median >= 1.8, "median rate {median} of {rates:?}");
    assert!(sorted[0] >= 1.3, "{rates:?}");
}

fn column_error(cells_tall: usize, gamma: f64) -> f64 {
    let mut sim = sim_with("column-self-weight", mpmlab_engine::verify::column(cells_tall, gamma));
    let r = run_all(&mut sim);
    error(&r, "syy_normalised")
}

#[test]
fn column_converges_with_and_without_ghost() {
    let cells = [8, 16, 32, 64];
    for gamma in [0.0, 10.0e3] {
        let e: Vec<f64> = cells.iter().map(|&n| column_error(n, gamma)).collect();
        let rates: Vec<f64> = e.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
        println!("gamma {gamma}: errors {e:?}, rates {rates:?}");
        // G Fig. 16: between 1 and 2. The overall slope over the four grids
        // must lie there (single pairs wobble as points cross cells).
        let overall = (e[0] / e[3]).log2() / 3.0;
        assert!((0.9..=2.2).contains(&overall), "gamma {gamma}: rate {overall}");
    }
    // With and without ghost nearly equal on the finest grid (G Fig. 16).
    let (a, b) = (column_error(64, 0.0), column_error(64, 10.0e3));
    assert!((a - b).abs() < 0.1 * a, "{a} vs {b}");
}

#[test]
fn column_error_is_insensitive_to_gamma_on_a_fine_grid() {
    // G Table 4: at h = 50/2^9 twelve orders of gamma_K/E (seven values)
    // change the error by 0.49%.
    let gammas = [1e-6, 1e-4, 1e-2, 1.0, 1e2, 1e4, 1e6];
    let e: Vec<f64> = gammas.iter().map(|g| column_error(512, g * 10.0e3)).collect();
    let (lo, hi) = e
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &v| (a.min(v), b.max(v)));
    println!(
        "h = 50/512, gamma/E = {gammas:?}: {e:?}; spread {:.3}%",
        100.0 * (hi - lo) / lo
    );
    // All seven of G's values: G's spread is 0.49%; ours is 0.57%, the
    // lowest value (4.9256e-5 at gamma_K/E = 1e2) below G's range: our
    // penalised face set is not G's (docs/verification.md). Asserted
    // within 0.6%, and the three values 1e-6, 1, 1e6 within G's 0.49%.
    assert!((hi - lo) / lo < 0.006, "{e:?}");
    let three = [e[0], e[3], e[6]];
    let (lo3, hi3) = three
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &v| (a.min(v), b.max(v)));
    assert!((hi3 - lo3) / lo3 < 0.0049, "{three:?}");
    // At gamma_K/E = 1e-6 the penalty is a millionth of the bulk stiffness:
    // the run is plain GIMP on G's grid, points and load steps, so it must
    // give G's 4.938e-5 to G's digits (within half a unit of the last one;
    // measured 4.9378e-5). With the penalty active our face set is not G's
    // (docs/verification.md), and the other columns differ in the fourth
    // digit (4.9365e-5 against 4.938e-5 at 1, 4.9535e-5 against 4.962e-5
    // at 1e6).
    assert!(
        (e[0] - 4.938e-5).abs() < 0.0005e-5,
        "{:e} vs G Table 4's 4.938e-5",
        e[0]
    );
}

/// Steps completed, total and largest Newton iterations, tip displacement.
type BeamRun = (usize, usize, usize, [f64; 2]);

/// Run the beam, or the failure with the number of steps completed and
/// the largest condition number of their tangents.
fn beam(h: f64, n: usize, gamma: f64) -> Result<BeamRun, (usize, f64, StepFailure)> {
    let mut sim: Simulation = sim_with("elastic-beam-ghost", |s| {
        s.grid.h = h;
        s.bodies[0].points_per_cell = n;
        s.analysis.gamma_k = gamma;
    });
    let (mut total, mut most, mut kappa) = (0, 0, 0.0f64);
    while !sim.finished() {
        match sim.step() {
            Ok(r) => {
                total += r.iterations;
                most = most.max(r.iterations);
                kappa = r.condition.map_or(kappa, |c| kappa.max(c.value));
            }
            Err(f) => return Err((sim.step_index(), kappa, f)),
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

#[test]
fn beam_stability_ghost_completes_where_plain_gimp_fails() {
    // G Table 5 (coarse part): every stabilised run completes all 50 steps;
    // unstabilised runs fail with a reported failure. h = 0.25, 2x2 points
    // stops after 11 steps in G. Which step fails is not the method's: the
    // unstabilised tangents reach condition numbers of 1e20-1e22 (from
    // step 8 here), beyond 1/eps = 4.5e15, where round-off picks the step
    // (12 here once, 13 after a summation order changed). What is the
    // method's: the failure is a non-convergence, it comes after the
    // tangent has become numerically singular (a completed step with
    // kappa > 1/eps), and it comes within twice G's 11 steps (a run that
    // got much further would no longer show G's instability).
    for (h, n) in [(0.5, 2), (0.5, 3), (0.25, 2)] {
        let (steps, total, most, _) =
            beam(h, n, 12.0e6).unwrap_or_else(|(s, _, f)| panic!("h {h} n {n}: step {s}: {f}"));
        println!("ghost h={h} n={n}: {steps} steps, {total} iterations, at most {most}");
        assert_eq!(steps, 50);
        assert!(most <= 10);
    }
    // G Table 5's plain 2x2 runs: h = 0.5 stops after 5 steps, h = 0.25
    // after 11; h = 0.125's entry is a failure whose step the paper's text
    // does not give legibly, held here to the same bound as h = 0.25
    // (measured: 5, 12 and 10 steps completed).
    for (h, g) in [(0.5, 5), (0.25, 11), (0.125, 11)] {
        match beam(h, 2, 0.0) {
            Err((done, kappa, StepFailure::NotConverged { step, residuals, .. })) => {
                println!(
                    "plain GIMP h={h} n=2 fails at step {step} after {done} steps (kappa {kappa:e}): {residuals:?}"
                );
                assert_eq!(step, done + 1);
                if h == 0.5 {
                    // Decided by the method, not round-off: every completed
                    // tangent is below 1/eps (2.7e13 at most) and step 6's
                    // residual stalls between 1e-1 and 8e-6 against the
                    // tolerance 1e-6 for all 10 iterations. G's 5 stable
                    // steps, exactly.
                    assert!(kappa < 1e-2 / f64::EPSILON, "h {h}: kappa {kappa:e}");
                    assert_eq!(done, g, "h {h}: G's final stable step is {g}");
                } else {
                    assert!(kappa > 1.0 / f64::EPSILON, "h {h}: kappa {kappa:e} before the failure");
                    assert!(step <= 2 * g + 1, "h {h}: failed at step {step}, G after {g} steps");
                }
            }
            other => panic!("h {h}: expected a reported non-convergence, got {other:?}"),
        }
    }
}

#[test]
fn beam_tip_follows_the_elastica() {
    // Plane strain: the bending stiffness is E I / (1 - nu^2), so the load
    // parameter is P L^2 (1 - nu^2) / (E I) = 10 * 0.96.
    let (dx, dy) = elastica_tip(10.0 * (1.0 - 0.2 * 0.2));
    let (_, _, _, tip) = beam(0.125, 2, 12.0e6).unwrap_or_else(|(s, _, f)| panic!("step {s}: {f}"));
    println!(
        "tip displacement {tip:?} m; elastica ({:.4}, {:.4}) m",
        -10.0 * dx,
        -10.0 * dy
    );
    // The elastica is a thin inextensible beam: the 10:1 beam's shear and
    // axial strain, the load applied at mid-depth points 0.03 m from the end
    // and the h = 0.125 grid leave a few percent; 5% of the deflection.
    assert!(
        (tip[1] + 10.0 * dy).abs() < 0.05 * 10.0 * dy,
        "vertical {} vs {}",
        tip[1],
        -10.0 * dy
    );
    assert!(
        (tip[0] + 10.0 * dx).abs() < 0.05 * 10.0 * dy,
        "horizontal {} vs {}",
        tip[0],
        -10.0 * dx
    );
}

#[test]
fn elastica_matches_its_quadrature_solution() {
    // An independent solution of Euler's cantilever, by quadrature instead
    // of the engine's shooting. With lambda = P / (E I) (L = 1),
    // E I theta'' = -P cos(theta), theta(0) = 0, theta'(L) = 0 integrates once to
    // theta'^2 / 2 = lambda (sin theta_0 - sin theta), theta_0 the tip angle.
    // Substituting sin theta = sin theta_0 - u^2 (u from 0 at the tip to
    // sqrt(sin theta_0) at the clamp) removes the square-root singularity:
    //   ds = 2 du / (sqrt(2 lambda) cos theta),   cos theta = sqrt(1 - (s0 - u^2)^2),
    //   L(s0) = int ds = 1 fixes s0 = sin theta_0 (bisection; L grows with s0),
    //   deflection = int sin theta ds, and the horizontal reach is closed:
    //   x = int cos theta ds = sqrt(2 s0 / lambda).
    // The integrand is smooth for theta_0 < 90 deg, so composite Simpson on
    // 20,000 intervals is accurate to ~1e-13; the engine's RK4 shooting claims
    // 1e-10. 1e-8 is the bar, well above both.
    fn quadrature(k: f64) -> (f64, f64) {
        let integrals = |s0: f64| {
            let n = 20_000;
            let b = s0.sqrt();
            let du = b / n as f64;
            let (mut len, mut dy) = (0.0, 0.0);
            for i in 0..=n {
                let u = i as f64 * du;
                let w = if i == 0 || i == n {
                    1.0
                } else if i % 2 == 1 {
                    4.0
                } else {
                    2.0
                };
                let sin = s0 - u * u;
                let ds = 2.0 / ((2.0 * k).sqrt() * (1.0 - sin * sin).sqrt());
                len += w * ds;
                dy += w * ds * sin;
            }
            (len * du / 3.0, dy * du / 3.0)
        };
        let (mut lo, mut hi) = (0.0, 1.0 - 1e-15);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if integrals(mid).0 < 1.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let s0 = 0.5 * (lo + hi);
        (1.0 - (2.0 * s0 / k).sqrt(), integrals(s0).1)
    }
    // From nearly linear to the beam scene's plane-strain 9.6 and beyond.
    for k in [0.1, 1.0, 3.0, 9.6, 10.0, 20.0] {
        let (s, d) = elastica_tip(k);
        let (sq, dq) = quadrature(k);
        assert!(
            (s - sq).abs() < 1e-8 && (d - dq).abs() < 1e-8,
            "k = {k}: shooting ({s}, {d}), quadrature ({sq}, {dq})"
        );
    }
    // Small loads: the linear result k/3 for the deflection, to O(k^3).
    let (_, d) = elastica_tip(1e-4);
    assert!((d - 1e-4 / 3.0).abs() < 1e-10);
}

#[test]
fn von_mises_collapse_runs_through_with_ghost() {
    let mut sim = sim_with("collapse-von-mises", |_| {});
    let mut history = Vec::new();
    let mut work = 0.0;
    while !sim.finished() {
        let r = sim.step().unwrap_or_else(|f| panic!("{f}"));
        history.push((r.energy.plastic_dissipation, r.max_increment, r.iterations));
        work = r.energy.external_work;
    }
    for (k, h) in history.iter().enumerate() {
        println!(
            "step {:>2}: dissipation {:.4e} J, max increment {:.4e} m, {} iterations",
            k + 1,
            h.0,
            h.1,
            h.2
        );
    }
    // Elastic for the first steps (no dissipation), then plastic collapse:
    // most of the work of gravity is dissipated, and the step increments
    // grow by an order of magnitude once the mechanism forms.
    assert!(history[..10].iter().all(|h| h.0 == 0.0));
    let last = history.last().unwrap();
    assert!(last.0 > 0.5 * work, "dissipation {} of work {work}", last.0);
    let late = history[20..].iter().map(|h| h.1).fold(0.0, f64::max);
    assert!(late > 10.0 * history[9].1, "increments {late} vs {}", history[9].1);
}

/// G 2.6's domain (`translating-domain`) translated by `a` (m, h = 1 m),
/// with `edit` applied.
fn translating_domain(a: f64, edit: impl FnOnce(&mut mpmlab_engine::scene::Scene)) -> Simulation {
    sim_with("translating-domain", |s| {
        s.bodies[0].region = mpmlab_engine::scene::RegionSpec::Rectangle {
            min: [a, 0.0],
            max: [2.0 + a, 1.0],
        };
        edit(s);
    })
}

#[test]
fn translating_domain_conditioning() {
    // G 2.6 / Fig. 6: as the GIMP domain crosses cells, the unstabilised
    // stiffness becomes nearly singular whenever a domain barely overlaps a
    // cell; with gamma_K = 1 (E = 1) the condition number stays small.
    let mut worst = (0.0f64, 0.0f64);
    let mut table = Vec::new();
    // A uniform sweep plus positions just past the grid lines, where a
    // domain barely enters a new cell (G samples 5000 positions).
    let mut positions: Vec<f64> = (0..=150).map(|k| k as f64 / 100.0).collect();
    positions.extend([1e-3, 1e-5, 1e-7, 1.0 + 1e-3, 1.0 + 1e-5, 1.0 + 1e-7]);
    for (k, &a) in positions.iter().enumerate() {
        let mut sim = translating_domain(a, |_| {});
        let r = sim.step().unwrap_or_else(|f| panic!("a = {a}: {f}"));
        let (with, without) = (r.condition.unwrap().value, r.condition_unstabilised.unwrap().value);
        worst = (worst.0.max(with), worst.1.max(without));
        if k % 10 == 0 || k % 50 == 1 || k > 150 {
            table.push((a, with, without));
        }
    }
    for (a, w, wo) in &table {
        println!("a/h = {a:.7}: cond with ghost {w:.3e}, without {wo:.3e}");
    }
    println!("largest: with ghost {:.3e}, without {:.3e}", worst.0, worst.1);
    // Spikes of many orders without (G: up to ~1e26 for GIMP stiffness) ...
    assert!(worst.1 > 1e8, "{worst:?}");
    // ... bounded with (G: ~1e1-1e2).
    assert!(worst.0 < 1e3, "{worst:?}");
}

#[test]
fn newton_reports_the_tangents_conditioning_with_and_without_ghost() {
    // G 2.6's domain under finite deformation, unloaded: Newton's tangent
    // is the Hencky material's at zero strain, the small-strain stiffness
    // K of the linear step. Newton reports 1-norm estimates through its
    // factor, the linear step the dense 2-norm condition of the same K.
    // For a symmetric K, kappa_2 <= kappa_1 <= n kappa_2 over its n free
    // dofs (11 here: 8 active nodes, 4 rollers and one fixed node; 16 is
    // taken), and the estimate is a lower bound of kappa_1 (measured:
    // 2.0-2.14 kappa_2). As in G 2.6 the ghost term bounds it, where
    // without it the domain barely entering a cell at a/h = 1e-5 makes K
    // nearly singular (kappa_2 1.3e11).
    for a in [0.25, 1e-3, 1e-5] {
        let at = |kind, mode| {
            let mut sim = translating_domain(a, |s| {
                s.analysis.kind = kind;
                s.analysis.condition = mode;
            });
            let r = sim.step().unwrap_or_else(|f| panic!("a = {a}: {f}"));
            (r.condition.map(|c| c.value), r.condition_unstabilised.map(|c| c.value))
        };
        use mpmlab_engine::scene::AnalysisKind::{QuasiStaticFinite, QuasiStaticLinear};
        use mpmlab_engine::scene::ConditionMode::{Dense, Off};
        let (linear, newton) = (at(QuasiStaticLinear, Dense), at(QuasiStaticFinite, Dense));
        println!("a/h = {a}: kappa_2 {linear:?}, Newton's kappa_1 estimate {newton:?}");
        for (k2, k1) in [(linear.0, newton.0), (linear.1, newton.1)] {
            let (k2, k1) = (k2.unwrap(), k1.expect("Newton reports both"));
            assert!(k2 <= k1 && k1 <= 16.0 * k2, "a/h = {a}: kappa_2 {k2:e}, kappa_1 {k1:e}");
        }
        let (with, without) = (newton.0.unwrap(), newton.1.unwrap());
        assert!(with < 1e3 && without > with, "a/h = {a}: {with:e}, {without:e}");
        if a == 1e-5 {
            assert!(without > 1e10, "{without:e}");
        }
        // Not asked, not measured.
        assert_eq!(at(QuasiStaticFinite, Off), (None, None));
    }
}

/// The largest nodal-free measure of the final state: the points' largest
/// displacement (m).
fn max_displacement(sim: &Simulation) -> f64 {
    let p = sim.points();
    (0..p.len())
        .map(|i| {
            let d = p.displacement(i);
            d[0].hypot(d[1])
        })
        .fold(0.0, f64::max)
}

#[test]
fn load_step_cutback_recovers_what_fixed_increments_cannot() {
    // G 5.2's beam in 3 load steps: Newton does not converge in the first
    // (10 iterations), as with the paper's fixed increments (the scene's
    // `max_cutbacks = 0`).
    let mut fixed = sim_with("elastic-beam-ghost", |s| {
        s.analysis.load_steps = 3;
        s.analysis.max_cutbacks = 0;
    });
    match fixed.step() {
        Err(StepFailure::NotConverged { step: 1, .. }) => {}
        other => panic!("expected step 1 not to converge, got {other:?}"),
    }
    assert_eq!(fixed.step_index(), 0);
    // With cutbacks (4, the default) the first increment is halved and the run
    // completes; every cutback is in the step's report.
    let mut cut = sim_with("elastic-beam-ghost", |s| {
        s.analysis.load_steps = 3;
        s.analysis.max_cutbacks = 4;
    });
    let mut cutbacks = 0;
    while !cut.finished() {
        let r = cut.step().unwrap_or_else(|f| panic!("{f}"));
        let s = r.solver.as_ref().unwrap();
        cutbacks += s.cutbacks.len();
        assert_eq!(s.substeps > 1, !s.cutbacks.is_empty());
        for c in &s.cutbacks {
            assert!(c.to > c.from && c.reason.contains("above tolerance"), "{c:?}");
        }
        assert!((r.load_factor - r.step as f64 / 3.0).abs() < 1e-15);
    }
    assert!(cutbacks >= 1);
    // The end state is the 50-step run's: hyperelasticity is path
    // independent, and only the discretisation (the mapping rebuilt at
    // every converged state, GIMP domains following the points) depends on
    // the increments, at first order in their size: 1.3% between the
    // 3-step and the 50-step run here, so 2% (a wrong cutback, e.g. a lost
    // or doubled increment, moves the tip by the increment's share: 17%).
    let mut fine = sim_with("elastic-beam-ghost", |_| {});
    run_all(&mut fine);
    let (a, b) = (max_displacement(&cut), max_displacement(&fine));
    assert!((a - b).abs() < 0.02 * b, "3 steps with cutbacks {a}, 50 steps {b}");
}

#[test]
fn exhausted_cutbacks_fail_and_restore_the_step_start() {
    // One load step for the whole beam: one halving is not enough; the
    // step fails with Newton's last failure and the state is the start.
    let mut sim = sim_with("elastic-beam-ghost", |s| {
        s.analysis.load_steps = 1;
        s.analysis.max_cutbacks = 1;
    });
    let before = sim.points().x.clone();
    match sim.step() {
        Err(StepFailure::NotConverged { step: 1, .. }) | Err(StepFailure::NonFinite { step: 1, .. }) => {}
        other => panic!("expected step 1 to fail, got {other:?}"),
    }
    assert_eq!(sim.step_index(), 0);
    assert_eq!(sim.points().x, before);
}

/// G 5.4's column with `E` divided by `softer`, its whole self weight in
/// one increment and no cutbacks: a hard first step for Newton.
fn soft_column_in_one_increment(softer: f64, line_search: bool) -> Simulation {
    sim_with("column-self-weight", |s| {
        s.analysis.load_steps = 1;
        s.analysis.max_cutbacks = 0;
        s.analysis.line_search = line_search;
        s.materials[0].e /= softer;
    })
}

#[test]
fn line_search_gives_up_after_ten_halvings() {
    // G 5.4's column loaded by its whole self weight in one increment, with
    // E 100 and 10^4 times too small: within a few iterations no fraction
    // of the Newton correction down to 2^-10 lowers the residual, and the
    // last one tried makes it NaN. The line search halves at most 10 times,
    // then takes the step: the NaN it lands on ends the increment as a
    // non-finite residual, which a cutback may retry. A search that kept
    // halving would never accept a NaN (it is never "better"), and would
    // spend hundreds of residuals per iteration creeping to the iteration
    // limit instead.
    for softer in [1e2, 1e4] {
        let mut sim = soft_column_in_one_increment(softer, true);
        let max_iterations = sim.model().analysis.max_iterations;
        let failure = sim.step().unwrap_err();
        println!("E / {softer:e}: {failure}");
        let StepFailure::NonFinite { residuals, .. } = &failure else {
            panic!("{failure}")
        };
        assert!(residuals.len() <= max_iterations + 1, "{failure}");
        assert!(residuals.last().unwrap().is_nan(), "{failure}");
    }
}

#[test]
fn line_search_carries_an_increment_full_newton_cannot() {
    // G 5.4's column, 5 and 20 times too soft, under its whole self weight
    // in one increment: full Newton corrections overshoot (the residual
    // grows, by 17 times at E / 5) and end in a NaN; halving each one
    // until the residual falls converges within the scene's 10 iterations,
    // every accepted residual below the one before.
    for softer in [5.0, 20.0] {
        let failure = soft_column_in_one_increment(softer, false).step().unwrap_err();
        assert!(matches!(failure, StepFailure::NonFinite { .. }), "{failure}");
        let r = soft_column_in_one_increment(softer, true)
            .step()
            .unwrap_or_else(|f| panic!("E / {softer}: {f}"));
        println!(
            "E / {softer}: full Newton {failure}; with the line search {:?}",
            r.residuals
        );
        assert!(r.residuals.windows(2).all(|w| w[1] <= w[0]), "{:?}", r.residuals);
    }
}

#[test]
fn follower_pressure_work_tends_to_the_strain_energy() {
    // Clapeyron in the linear limit: the work of the pressure over the
    // load path (the trapezoidal rule per step, between the traction on
    // the curve at the start of the step and the one at its end) is the
    // strain energy when the response is linear, whatever the steps. The
    // follower-pressure cantilever at a thousandth of its load and less
    // is nearly linear (tip deflection ~3 mm of 10 m): what remains is
    // the trapezoidal rule on a path bent by the geometry, first order in
    // the step and in the load. Measured over p = 0.15 to 150 Pa and 1 to
    // 3 steps: (W - U)/U = -1.80e-5 p/n (p in Pa) to 1% below 15 Pa
    // (-2.70e-6 at 0.15 Pa and one step; -2.70e-5 at 1.5 Pa; -8.93e-6 at
    // 1.5 Pa in 3 steps). Tolerances: 4e-5 at 1.5 Pa in one step, and the
    // error's 1/n and p scalings to 5% (measured 3.02 and 9.99). Smaller
    // loads reach the round-off of the strains (~1e-9 at 1.5e-3 Pa, where
    // Newton stalls at 1e-7 in three steps).
    let rest = |p: f64, steps: usize| {
        let mut sim = sim_with("cantilever-follower-pressure-finite", |s| {
            s.boundaries[0].traction = Some(mpmlab_engine::scene::TractionSpec::Pressure { value: p });
            s.analysis.load_steps = steps;
        });
        let r = run_all(&mut sim);
        let (u, w) = (r.energy.strain, r.energy.external_work);
        println!(
            "p {p:e} Pa in {steps} steps: U {u:.9e} J W {w:.9e} J, (W - U)/U {:.4e}",
            (w - u) / u
        );
        assert!(u > 0.0 && w.is_finite(), "p {p}, {steps} steps: U {u:e} W {w:e}");
        (w - u) / u
    };
    let (one, three, smaller) = (rest(1.5, 1), rest(1.5, 3), rest(0.15, 1));
    assert!(one.abs() < 4e-5, "{one:e}");
    assert!((one / three - 3.0).abs() < 0.15, "one step {one:e}, three {three:e}");
    assert!(
        (one / smaller - 10.0).abs() < 0.5,
        "1.5 Pa {one:e}, 0.15 Pa {smaller:e}"
    );
}

#[test]
fn prescribed_grid_displacement_work_is_the_strain_energy() {
    // G 5.4's column without its weight, compressed instead in one step by
    // its top grid line moved down 0.05 m (a roller with a prescribed
    // normal displacement): uniaxial strain at stretch s = 0.999, nu = 0.
    // The work is the reactions' (the trapezoidal rule on the prescribed
    // components, the only ones that move and carry force): from none at
    // the start to R = sigma_yy b = E ln(s)/s b at the end (Cauchy stress
    // E ln(s)/J, J = s, on the unchanged width b), so W = -R 0.05/2 and
    // U = E/2 ln(s)^2 b L, both in closed form (W/U - 1 = 5.0042e-4, the
    // trapezoidal rule's). Measured: U and W to 8e-14 and 4e-14 of them
    // (round-off); tolerances 1e-10, far below the rule's 5e-4, so that a
    // work counted from the wrong reactions or with the wrong sign fails.
    //
    // Only the first step has this closed form: after it the column's top
    // is below the grid line the condition holds, the line's later
    // increments reach the material only through the top cell's
    // interpolation, and the column ends shorter by less than 0.05 m
    // (U 7e-4 low in three steps) — the reason moving boundaries here are
    // implicit rollers on the material's curve.
    let (e, b, l, s) = (10.0e3, 1.5625, 50.0, 0.999f64);
    let u_exact = 0.5 * e * s.ln().powi(2) * b * l;
    let w_exact = -0.5 * e * s.ln() / s * b * 0.05;
    let mut sim = sim_with("column-self-weight", |sc| {
        sc.loads.gravity = None;
        sc.exact = None;
        sc.analysis.load_steps = 1;
        sc.dirichlet.push(mpmlab_engine::scene::DirichletSpec {
            kind: mpmlab_engine::scene::DirichletKind::Roller,
            x: None,
            y: Some(l),
            node: None,
            displacement: None,
            normal_displacement: Some(-0.05),
        });
    });
    let r = run_all(&mut sim);
    let (u, w) = (r.energy.strain, r.energy.external_work);
    println!(
        "U {u:.10e} J, W {w:.10e} J: relative errors {:.2e} and {:.2e}; W/U - 1 = {:.6e}",
        (u - u_exact) / u_exact,
        (w - w_exact) / w_exact,
        w / u - 1.0
    );
    assert!(((u - u_exact) / u_exact).abs() < 1e-10, "U {u:e}, exact {u_exact:e}");
    assert!(((w - w_exact) / w_exact).abs() < 1e-10, "W {w:e}, exact {w_exact:e}");
}

#[test]
fn cutback_sizes_follow_each_sub_steps_newton_iterations() {
    // The rule of `cutback::Pending::Regrow`, replayed from what each step did:
    // each Newton attempt of a step starts at iteration 0 of the progress
    // hook and ends converged (relative residual at or below the
    // tolerance) or not (the iteration limit). The whole increment fails
    // first; then from lambda_n with Delta / 2 at depth 1: a failed attempt
    // halves the size (depth + 1); a converged one moves on and doubles the
    // size (depth - 1) if it took at most half the limit (2 its <= limit)
    // and the depth is above 0; an attempt reaching lambda_(n+1) (to
    // 1e-12 Delta) lands on it and ends the step. The failures the replay
    // predicts must be the step's recorded cutbacks, and its converged
    // attempts the step's sub-steps. G 5.2's beam in 4 steps held to 7
    // iterations (as the test below: a converged sub-step above half the
    // limit keeps the size for the next), in 2 steps held to 8 (a
    // sub-step of 4 iterations, inside a cut step, doubles the next) and
    // in 1 step held to 8 (a doubled sub-step followed by more).
    use std::sync::{Arc, Mutex};
    let (mut kept, mut doubled) = (false, false);
    for (steps, max) in [(4, 7), (2, 8), (1, 8)] {
        let mut sim = sim_with("elastic-beam-ghost", |s| {
            s.analysis.load_steps = steps;
            s.analysis.max_cutbacks = 4;
            s.analysis.max_iterations = max;
        });
        let tol = sim.params().tolerance;
        let log: Arc<Mutex<Vec<(usize, f64)>>> = Arc::default();
        let sink = log.clone();
        sim.set_progress(Some(Box::new(move |p| {
            sink.lock().unwrap().push((p.iteration, p.residual));
            true
        })));
        let delta = 1.0 / steps as f64;
        while !sim.finished() {
            log.lock().unwrap().clear();
            let r = sim.step().unwrap_or_else(|f| panic!("{f}"));
            let s = r.solver.as_ref().unwrap();
            let at_step = format!("{steps} steps, limit {max}, step {}", r.step);
            // The step's attempts: (iterations, converged).
            let mut attempts: Vec<(usize, bool)> = Vec::new();
            for &(it, res) in log.lock().unwrap().iter() {
                if it == 0 {
                    attempts.push((0, res <= tol));
                }
                *attempts.last_mut().unwrap() = (it, res <= tol);
            }
            let (l0, l1) = ((r.step - 1) as f64 * delta, r.step as f64 * delta);
            let cuts: Vec<(f64, f64)> = s.cutbacks.iter().map(|c| (c.from, c.to)).collect();
            println!("{at_step}: attempts {attempts:?}, cutbacks {cuts:?}");
            if cuts.is_empty() {
                assert_eq!(attempts.len(), 1, "{at_step}");
                continue;
            }
            assert!(!attempts[0].1, "{at_step}: the whole increment failed");
            let mut failed = vec![(l0, l1)];
            let (mut at, mut size, mut depth, mut substeps) = (l0, 0.5 * delta, 1usize, 0);
            let mut reached = false;
            for (k, &(its, converged)) in attempts.iter().enumerate().skip(1) {
                let last = at + size >= l1 - 1e-12 * delta;
                let to = if last { l1 } else { at + size };
                if !converged {
                    failed.push((at, to));
                    size *= 0.5;
                    depth += 1;
                    continue;
                }
                substeps += 1;
                if last {
                    assert_eq!(k, attempts.len() - 1, "{at_step}: attempts after lambda_(n+1)");
                    reached = true;
                    break;
                }
                at = to;
                if its * 2 <= max && depth > 0 {
                    size *= 2.0;
                    depth -= 1;
                    doubled = true;
                } else {
                    kept = true;
                }
            }
            assert!(reached, "{at_step}: the replay ends short of lambda_(n+1)");
            assert_eq!(substeps, s.substeps, "{at_step}");
            assert_eq!(failed.len(), cuts.len(), "{at_step}: predicted {failed:?}");
            for (f, c) in failed.iter().zip(&cuts) {
                // 1e-12 of Delta: round-off of sums of binary fractions of it.
                assert!(
                    (f.0 - c.0).abs() < 1e-12 * delta && (f.1 - c.1).abs() < 1e-12 * delta,
                    "{at_step}: predicted {failed:?}, recorded {cuts:?}"
                );
            }
        }
    }
    assert!(kept, "a converged sub-step above half the limit was seen");
    assert!(doubled, "a converged sub-step at or below half the limit was seen");
}

#[test]
fn cutbacks_halve_the_increment_from_the_last_converged_state() {
    // G 5.2's beam in 4 load steps with Newton held to 7 iterations: steps
    // 1 and 2 are cut back (step 2 twice), so a cut from a non-zero load
    // factor is seen. The rule (`cutback::Pending::Regrow`): the failed increment
    // lambda_n -> lambda_(n+1) is the first cutback; then the increment is
    // halved at each failure and doubled after an easy one, always from
    // the last converged state and never past lambda_(n+1). So every later
    // cutback spans Delta / 2^j (1 <= j <= max_cutbacks) of the step's
    // Delta = 1/4 and starts on that binary grid from lambda_n (to
    // round-off: 1e-12). With one cutback only, its first half converged
    // and the rest (the half or, doubled, the whole, clipped at
    // lambda_(n+1)) reached lambda_(n+1) in one more increment: two
    // sub-steps, no zero-length sub-step at the end.
    let mut sim = sim_with("elastic-beam-ghost", |s| {
        s.analysis.load_steps = 4;
        s.analysis.max_cutbacks = 4;
        s.analysis.max_iterations = 7;
    });
    let delta = 0.25;
    let mut cut_late = false;
    while !sim.finished() {
        let r = sim.step().unwrap_or_else(|f| panic!("{f}"));
        let s = r.solver.as_ref().unwrap();
        let (l0, l1) = ((r.step - 1) as f64 * delta, r.step as f64 * delta);
        let cuts: Vec<(f64, f64)> = s.cutbacks.iter().map(|c| (c.from, c.to)).collect();
        println!("step {}: {} sub-steps, cutbacks {cuts:?}", r.step, s.substeps);
        assert_eq!(r.load_factor, l1, "step {}", r.step);
        let Some(&first) = cuts.first() else {
            assert_eq!(s.substeps, 1, "step {}", r.step);
            continue;
        };
        assert_eq!(first, (l0, l1), "step {}: the whole increment first", r.step);
        // The step's Newton iterations are those of its converged
        // sub-steps: each took at least one (its load moved) and at most 7.
        assert!(
            (s.substeps..=7 * s.substeps).contains(&r.iterations),
            "step {}: {} iterations in {} sub-steps",
            r.step,
            r.iterations,
            s.substeps
        );
        cut_late |= l0 > 0.0;
        for &(from, to) in &cuts[1..] {
            common::assert_binary_part((from, to), (l0, delta), 4, 1e-12, &format!("step {}", r.step));
        }
        if cuts.len() == 1 {
            assert_eq!(s.substeps, 2, "step {}", r.step);
        }
    }
    assert!(cut_late, "a step from a non-zero load factor was cut back");
}

#[test]
fn a_sub_step_failing_after_a_doubling_is_cut_no_deeper_than_allowed() {
    // The footing of `rigid-footing-large` pushed its whole way in 3 load
    // steps, Newton held to 10 iterations. Step 1 grows harder as it goes:
    // the whole third fails, then its half; the first quarter converges in
    // 5 iterations (at most half the limit), so the size doubles back to a
    // half and the depth drops to 1 (`cutback::Pending::Regrow`); that half fails
    // and so does its half, and eighths of Delta = 1/3 reach lambda_1.
    // Cutbacks: (0, 1/3), (0, 1/6), (1/12, 1/4), (1/12, 1/6), the last
    // two at depths 1 and 2 after the doubling, so 3 cutbacks allowed
    // suffice and 2 do not (the last one needs depth 3). Had the depth not
    // dropped with the doubling, the last cut would need depth 4.
    let run = |max_cutbacks: usize| {
        let mut sim = sim_with("rigid-footing-large", |s| {
            s.analysis.load_steps = 3;
            s.analysis.max_iterations = 10;
            s.analysis.max_cutbacks = max_cutbacks;
        });
        sim.step()
    };
    let r = run(3).unwrap_or_else(|f| panic!("{f}"));
    let s = r.solver.as_ref().unwrap();
    let cuts: Vec<(f64, f64)> = s.cutbacks.iter().map(|c| (c.from, c.to)).collect();
    let d = 1.0 / 3.0;
    let expected = [(0.0, d), (0.0, d / 2.0), (d / 4.0, 3.0 * d / 4.0), (d / 4.0, d / 2.0)];
    assert_eq!(cuts.len(), expected.len(), "cutbacks {cuts:?}");
    for (c, e) in cuts.iter().zip(&expected) {
        // Round-off of sums of binary fractions of Delta.
        assert!(
            (c.0 - e.0).abs() < 1e-12 && (c.1 - e.1).abs() < 1e-12,
            "cutbacks {cuts:?}"
        );
    }
    // The quarter, then six eighths to lambda_1.
    assert_eq!(s.substeps, 7);
    assert_eq!(r.load_factor, d);
    match run(2) {
        Err(StepFailure::NotConverged { step: 1, .. }) => {}
        other => panic!("with 2 cutbacks step 1 must fail to converge: {other:?}"),
    }
}
