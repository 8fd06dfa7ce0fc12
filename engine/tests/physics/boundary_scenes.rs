//! The B-spline boundary benchmarks of Bing et al. (2019): traction through
//! splines on an aligned square (exact), a thick cylinder (Lame), a plate
//! with a hole (Kirsch) and a cantilever under follower pressure.

use crate::common;
use common::{error, run_all, sim_with};
use mpmlab_engine::exact::ExactSolution;
use mpmlab_engine::scene::Placement;
use mpmlab_engine::Simulation;

#[test]
fn square_traction_aligned_is_exact() {
    let mut sim = sim_with("square-traction-aligned", |_| {});
    let r = run_all(&mut sim);
    // B 4.1.1 reports ~1e-16: the uniform state lies in the discrete space
    // and the consistent traction loads are exact; allow round-off of a
    // 9-unknown solve (cond ~ 10).
    assert!(error(&r, "stress_l2") < 1e-12, "{:e}", error(&r, "stress_l2"));
    assert!(
        error(&r, "displacement_l2") < 1e-12,
        "{:e}",
        error(&r, "displacement_l2")
    );
    for s in &sim.points().stress {
        assert!(
            (s[1] + 8000.0).abs() < 1e-8 && (s[0] + 8000.0 / 3.0).abs() < 1e-8 && s[2].abs() < 1e-8,
            "{s:?}"
        );
    }
    // The resultant is the pressure times the 1 m edge.
    let b = &r.boundaries[0];
    assert!(
        (b.resultant[1] + 8000.0).abs() < 1e-9 && b.resultant[0].abs() < 1e-9,
        "{:?}",
        b.resultant
    );
    assert!((b.length - 1.0).abs() < 1e-14 && b.cells_cut == 2 && b.lost == 0.0);
}

/// Mean relative error of the deformed radius of boundary `name`, sampled at
/// 1000 points on its spline, against the Lame radius `r + u_r(r)` at `r`.
fn radius_error(sim: &Simulation, name: &str, r: f64) -> f64 {
    let exact = sim.model().exact.clone().unwrap();
    let ExactSolution::Lame { .. } = exact else { panic!() };
    let target = r + exact.displacement([r, 0.0])[0];
    let (_, spline) = sim.boundary_splines().into_iter().find(|(n, _)| n == name).unwrap();
    let s = spline.unwrap();
    let n = 1000;
    let per = n / s.segments.len() + 1;
    let samples = s.sample(per);
    samples
        .iter()
        .map(|p| (p[0].hypot(p[1]) - target).abs() / target)
        .sum::<f64>()
        / samples.len() as f64
}

#[test]
fn thick_cylinder_radii_converge() {
    let run = |h: f64, nr: usize, nc: usize| {
        let mut sim = sim_with("thick-cylinder", |s| {
            s.grid.h = h;
            s.bodies[0].radial_points = Some(nr);
            s.bodies[0].circumferential_points = Some(nc);
        });
        run_all(&mut sim);
        (radius_error(&sim, "inner", 1.0), radius_error(&sim, "outer", 5.0))
    };
    // Grid and points refined together (about 1.5 points per cell across).
    // Past h = 1/8 this arrangement stalls: `thick_cylinder_polar_points_stall`.
    let joint: Vec<(f64, f64)> = [(1.0, 8, 16), (0.5, 16, 32), (0.25, 32, 64), (0.125, 64, 128)]
        .iter()
        .map(|&(h, nr, nc)| run(h, nr, nc))
        .collect();
    println!("joint refinement h = 1, 1/2, 1/4, 1/8 (inner, outer): {joint:?}");
    // B Fig. 15: the errors fall with refinement, and the inner radius
    // (where u_r varies fastest) is much worse than the outer.
    for w in joint.windows(2) {
        assert!(w[1].0 < w[0].0 && w[1].1 < w[0].1, "{joint:?}");
    }
    for e in &joint {
        assert!(e.0 > 3.0 * e.1, "inner {} vs outer {}", e.0, e.1);
    }
    // Points refined on a fixed grid also help.
    let (a, b) = (run(0.5, 16, 32), run(0.5, 32, 64));
    println!("h = 1/2, 16x32 vs 32x64 points: {a:?} {b:?}");
    assert!(b.0 < a.0 && b.1 < a.1);
}

/// Per-cell point quadrature of the cells wholly inside the annulus: RMS over
/// them of the relative error of the cell's volume, sum of V_p / h^2 - 1.
fn cell_volume_rms(sim: &Simulation, h: f64) -> f64 {
    let pts = sim.points();
    let n = (6.0 / h).round() as usize;
    let mut vol = vec![0.0; n * n];
    for (x, v) in pts.x0.iter().zip(&pts.vol0) {
        vol[(x[1] / h).floor() as usize * n + (x[0] / h).floor() as usize] += v;
    }
    let (mut sum, mut count) = (0.0, 0.0);
    for j in 0..n {
        for i in 0..n {
            let (x0, y0) = (i as f64 * h, j as f64 * h);
            if x0.hypot(y0) >= 1.0 && (x0 + h).hypot(y0 + h) <= 5.0 {
                sum += (vol[j * n + i] / (h * h) - 1.0).powi(2);
                count += 1.0;
            }
        }
    }
    (sum / count).sqrt()
}

#[test]
fn thick_cylinder_polar_points_stall() {
    // The arrangement of `thick_cylinder_radii_converge` (8 x 16 polar points
    // at h = 1, doubled each way as h halves) continued to h = 1/32.
    let run = |h: f64, k: usize| {
        let mut sim = sim_with("thick-cylinder", |s| {
            s.grid.h = h;
            s.bodies[0].radial_points = Some(8 * k);
            s.bodies[0].circumferential_points = Some(16 * k);
        });
        let cells = cell_volume_rms(&sim, h);
        let r = run_all(&mut sim);
        (radius_error(&sim, "outer", 5.0), error(&r, "displacement_l2"), cells)
    };
    let [a, b, c] = [(0.125, 8), (0.0625, 16), (0.03125, 32)].map(|(h, k)| run(h, k));
    println!("h = 1/8, 1/16, 1/32 (outer radius, displacement_l2, cell volume RMS): {a:?} {b:?} {c:?}");
    // Measured 6.3e-5, 1.8e-4, 2.4e-4 (outer) and 3.7e-3, 2.4e-3, 3.1e-3
    // (displacement): the outer error grows 2.8x and then 1.35x; asserted
    // only that it grows at both halvings and that the displacement error at
    // h = 1/32 is no better than half that at h = 1/8 (second order would
    // give a sixteenth).
    assert!(b.0 > a.0 && c.0 > b.0, "{a:?} {b:?} {c:?}");
    assert!(c.1 > 0.5 * a.1, "{a:?} {c:?}");
    // The cause: the lattice is not aligned with the cells, so each cell's
    // point rule misses its own volume by a fraction that depends only on the
    // points per cell, not on h (measured 12.2%, 11.8%, 11.6% RMS): the cell
    // integrals keep an O(1) error. Asserted constant within 10%.
    assert!(a.2 > 0.1 && (c.2 / a.2 - 1.0).abs() < 0.1, "{a:?} {c:?}");
    // Twice the points each way at the same h cuts it (measured 4.0%, and
    // 1.4%, 0.5% for 4x and 8x; asserted below half).
    let d = run(0.0625, 32);
    println!("h = 1/16, 256 x 512 points: {d:?}");
    assert!(d.2 < 0.5 * b.2, "{b:?} {d:?}");
}

#[test]
fn thick_cylinder_clipped_points_converge() {
    // The shipped scene at h = 1/2 .. 1/16: 2 x 2 clipped points per cell
    // integrate every inner cell exactly for linear integrands.
    let hs = [0.5, 0.25, 0.125, 0.0625];
    let errs: Vec<[f64; 4]> = hs
        .iter()
        .map(|&h| {
            let mut sim = sim_with("thick-cylinder-converging", |s| s.grid.h = h);
            let r = run_all(&mut sim);
            [
                radius_error(&sim, "inner", 1.0),
                radius_error(&sim, "outer", 5.0),
                error(&r, "displacement_l2"),
                error(&r, "stress_l2"),
            ]
        })
        .collect();
    println!("h = 1/2 .. 1/16 (inner, outer, displacement_l2, stress_l2): {errs:?}");
    // Observed orders per halving: 1.91 / 1.96 / 1.99 (inner radius),
    // 1.92 / 1.97 / 1.99 (outer), 1.94 / 1.98 / 2.00 (displacement), 0.94 /
    // 0.99 / 1.00 (stress), and the same to h = 1/64 (examples/cylinder_study).
    // The lowest, at the coarsest halving, less 0.1 for the margin.
    for w in errs.windows(2) {
        let rate = |k: usize| (w[0][k] / w[1][k]).log2();
        for (k, least) in [(0, 1.8), (1, 1.8), (2, 1.8), (3, 0.85)] {
            assert!(rate(k) > least, "quantity {k}: rate {} ({errs:?})", rate(k));
        }
    }
}

#[test]
fn plate_hole_neumann_converges() {
    let hs = [0.5, 0.25, 0.125, 0.0625, 0.03125];
    let errs: Vec<(f64, f64)> = hs
        .iter()
        .map(|&h| {
            let mut sim = sim_with("plate-hole-neumann", |s| {
                s.grid.h = h;
                s.bodies[0].points_per_cell = 8;
                assert_eq!(s.bodies[0].placement, Placement::Centres);
            });
            let r = run_all(&mut sim);
            (error(&r, "displacement_l2"), error(&r, "stress_l2"))
        })
        .collect();
    println!(
        "h, displacement_l2, stress_l2: {:?}",
        hs.iter().zip(&errs).collect::<Vec<_>>()
    );
    // Least-squares slope of log error against log h over all five grids.
    let slope = |f: &dyn Fn(&(f64, f64)) -> f64| {
        let xs: Vec<f64> = hs.iter().map(|h| h.ln()).collect();
        let ys: Vec<f64> = errs.iter().map(|e| f(e).ln()).collect();
        let (mx, my) = (xs.iter().sum::<f64>() / 5.0, ys.iter().sum::<f64>() / 5.0);
        let num: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
        num / xs.iter().map(|x| (x - mx).powi(2)).sum::<f64>()
    };
    let (ru, rs) = (slope(&|e| e.0), slope(&|e| e.1));
    println!("rates: displacement {ru:.2}, stress {rs:.2}");
    // B Fig. 17: about 2 for displacement and 1 for stress. Points at
    // sub-cell centres approximate the curved boundary to O(h/8) in volume,
    // which bends the finest pairs; the fitted slopes must stay within 15%.
    assert!(ru > 1.7, "displacement rate {ru}");
    assert!(rs > 0.85, "stress rate {rs}");
}

#[test]
fn plate_hole_clipped_keeps_the_stress_rate_at_4x4_points() {
    // Issue 17: with its own 4x4 centres placement the shipped plate's
    // stress rate falls to 0.59-0.72 between successive grids (the whole
    // sub-cells' stair-case along the hole carries an O(1) stress error).
    // Clipped sub-cells with Ghost stiffness (E/100) on the cut cells keep
    // it: measured 0.93 and 0.96 over h = 1/8 .. 1/32, displacement 1.82
    // and 1.81. Asserted per pair: stress >= 0.9 (the bound),
    // displacement >= 1.7 (B Fig. 17: about 2; 15% below it).
    let hs = [0.125, 0.0625, 0.03125];
    let errs: Vec<(f64, f64)> = hs
        .iter()
        .map(|&h| {
            let mut sim = sim_with("plate-hole-neumann-clipped", |s| s.grid.h = h);
            let r = run_all(&mut sim);
            (error(&r, "displacement_l2"), error(&r, "stress_l2"))
        })
        .collect();
    println!(
        "h, displacement_l2, stress_l2: {:?}",
        hs.iter().zip(&errs).collect::<Vec<_>>()
    );
    for w in errs.windows(2) {
        let (ru, rs) = ((w[0].0 / w[1].0).log2(), (w[0].1 / w[1].1).log2());
        println!("rates: displacement {ru:.3}, stress {rs:.3}");
        assert!(rs >= 0.9, "stress rate {rs}");
        assert!(ru >= 1.7, "displacement rate {ru}");
    }
    // And it beats the centres placement's stress at the finest grid.
    let mut centres = sim_with("plate-hole-neumann", |s| s.grid.h = 0.03125);
    let c = error(&run_all(&mut centres), "stress_l2");
    assert!(errs[2].1 < 0.7 * c, "{} vs centres {c}", errs[2].1);
}

/// Mid-tip downward deflection of the cantilever scene with grid size `h`,
/// a lattice of points, `pressure` (Pa) over `steps` load steps.
fn cantilever_tip(h: f64, lattice: [usize; 2], pressure: f64, steps: usize) -> Result<f64, mpmlab_engine::StepFailure> {
    cantilever_tip_with(h, lattice, pressure, steps, 0.0)
}

/// [`cantilever_tip`] with Ghost stiffness `gamma_k` (Pa).
fn cantilever_tip_with(
    h: f64,
    lattice: [usize; 2],
    pressure: f64,
    steps: usize,
    gamma_k: f64,
) -> Result<f64, mpmlab_engine::StepFailure> {
    let mut sim = sim_with("cantilever-follower-pressure", |s| {
        s.analysis.gamma_k = gamma_k;
        s.grid.h = h;
        // Room below for the tip (deflections up to ~6 m); whole cells.
        s.grid.origin = [0.0, 1.75 - 1.5 * (6.0 / 1.5 + 1.0)];
        s.grid.size = [11.0 * 1.5, 1.5 * (6.0 / 1.5 + 1.0) + 3.0];
        s.dirichlet[1].node = Some([0.0, 1.75]);
        s.bodies[0].lattice = Some(lattice);
        s.boundaries[0].traction = Some(mpmlab_engine::scene::TractionSpec::Pressure { value: pressure });
        s.analysis.load_steps = steps;
    });
    while !sim.finished() {
        sim.step()?;
    }
    let b = sim.model().boundaries.iter().find(|b| b.name == "tip").unwrap();
    Ok(-sim.points().displacement(b.points[1])[1])
}

#[test]
fn cantilever_follower_pressure_approaches_reference() {
    let a = cantilever_tip(1.5, [56, 16], 1500.0, 5).unwrap();
    let b = cantilever_tip(0.75, [112, 32], 1500.0, 5).unwrap();
    let c = cantilever_tip(0.375, [224, 64], 1500.0, 5).unwrap();
    let rate = ((b - a) / (c - b)).log2();
    let extrapolated = c + (c - b) / (2f64.powf(rate) - 1.0);
    println!("mid-tip deflection: h=1.5 {a:.4}, h=0.75 {b:.4}, h=0.375 {c:.4}; rate {rate:.2}, Richardson {extrapolated:.4} (FE reference 2.8220)");
    let reference = 2.8220;
    // B Fig. 12: monotone approach to the FE value under h and point refinement.
    assert!(a < b && b < c && c < reference, "{a} {b} {c}");
    // The Richardson extrapolation of the three must land on the reference
    // to within 2%: the FE reference is itself a converged number, and the
    // observed rate (~1.7) is stable over the three grids.
    assert!((extrapolated - reference).abs() < 0.02 * reference, "{extrapolated}");
}

#[test]
fn cantilever_3000_pa_variant() {
    // B Fig. 13: 3000 Pa in 10 steps, h = 0.75, 28 x 8 points: 5.09 m. With
    // so few points per cell (about 1 x 3) cells at the top and bottom fibres
    // hold too little material as the beam bends, and plain MPM loses
    // positive definiteness (singular, or so ill-conditioned that the
    // residual stalls): the failure must be reported, not panic.
    match cantilever_tip(0.75, [28, 8], 3000.0, 10) {
        Err(mpmlab_engine::StepFailure::Singular { step, .. })
        | Err(mpmlab_engine::StepFailure::NotConverged { step, .. }) => {
            assert!(step > 1 && step <= 10)
        }
        other => panic!("expected a reported failure, got {other:?}"),
    }
    let d = cantilever_tip(0.75, [112, 32], 3000.0, 10).unwrap();
    println!("3000 Pa, h = 0.75, 112 x 32 points: mid-tip deflection {d:.4} m (paper, 28 x 8 points: 5.09 m)");
    // Four times the points per direction make the beam softer (the 1500 Pa
    // series moves 15% between the two coarsest discretisations); 5% covers
    // the difference in discretisation, not more.
    assert!((d - 5.09).abs() < 0.05 * 5.09, "{d}");
    // The paper's own 28 x 8 points complete all 10 steps once the cut
    // cells' faces carry Ghost stiffness (E/100): 5.2881 m, 3.9% above B's
    // 5.09 m and 0.5% from the 112 x 32 run above (the mid-tip point probe
    // reads 5.27-5.33 m for gamma_K = E/1e4 .. E/10): the difference to B is the discretisation
    // (B's clamp is an implicit boundary, ours the grid line; the 1500 Pa
    // series sits 0.8% above B's FE reference), not the lost positive
    // definiteness, which Ghost removes.
    let g = cantilever_tip_with(0.75, [28, 8], 3000.0, 10, 1.0e4).unwrap();
    println!("3000 Pa, h = 0.75, 28 x 8 points, gamma_K = E/100: {g:.4} m");
    assert!(
        (g - 5.09).abs() < 0.05 * 5.09 && (g / d - 1.0).abs() < 0.02,
        "{g} vs {d}"
    );
}
