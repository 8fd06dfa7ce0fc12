//! The rows of [`plan`](super::plan), one function per paper section in
//! the order `plan` calls them: each adds the runs its rows read, then
//! the rows (and any measured table of `docs/verification.md`).

use super::{column, deep_beam, simple_shear, DocTable, Outcome, Outcomes, Plan, Rule};
use crate::scene::{MassKind, StressUpdate};

/// B 4.1: the square under traction, exact with rollers on the grid (4.1.1) and with rollers by IBM (4.1.2 Table 1).
pub(super) fn b_square(p: &mut Plan) {
    // B 4.1.1: traction by a B-spline, rollers on the grid: exact.
    p.run("square-aligned", "square-traction-aligned", |_| {});
    p.check(
        "B 4.1.1",
        "stress error (stress_l2)",
        1e-16,
        Rule::AtMost(1e-12),
        true,
        "exact to round-off: B reports ~1e-16; 1e-12 leaves room for the solver's round-off",
        &["square-aligned"],
        |o| o.run("square-aligned").error("stress_l2"),
    );
    // B 4.1.2 Table 1: rollers by IBM.
    for (angle, rv, rs) in [(45u32, 4.84e-7, 9.68e-9), (60, 4.90e-7, 7.25e-9)] {
        let id = format!("square-ibm-{angle}");
        let scene: &'static str = if angle == 45 {
            "square-traction-ibm-45"
        } else {
            "square-traction-ibm-60"
        };
        p.run(&id, scene, |_| {});
        let i = id.clone();
        p.check(
            "B 4.1.2 Table 1",
            format!("{angle} deg: R_v (displacement_mean_relative)"),
            rv,
            Rule::AtMost(rv),
            true,
            "at or below B's value",
            &[&id],
            move |o| o.run(&i).error("displacement_mean_relative"),
        );
        let i = id.clone();
        p.check(
            "B 4.1.2 Table 1",
            format!("{angle} deg: R_syy (syy_mean_relative)"),
            rs,
            Rule::AtMost(2e-7),
            true,
            "the cells along an IBM roller with normal strain carry 0.24 delta/h of stress error (delta = 1e-6 h; docs/verification.md), above B's digits",
            &[&id],
            move |o| o.run(&i).error("syy_mean_relative"),
        );
    }
}

/// C 5.1: the block on implicit rollers, 1 mm pushed in.
pub(super) fn c_block(p: &mut Plan) {
    for (angle, ru) in [(0u32, 1.573e-9), (30, 1.173e-8), (45, 2.036e-9), (90, 1.573e-9)] {
        let k = [0, 30, 45, 90].iter().position(|a| *a == angle).unwrap_or(0);
        let scene = [
            "block-roller-0",
            "block-roller-30",
            "block-roller-45",
            "block-roller-90",
        ][k];
        let id = format!("block-{angle}");
        p.run(&id, scene, |_| {});
        let i = id.clone();
        p.check(
            "C 5.1",
            format!("{angle} deg: platen force, -s_y'y' x 100 mm (N/mm)"),
            1346.0,
            Rule::Relative(5e-4),
            true,
            "C prints 13.46 MPa: half a unit of its last digit is 3.7e-4",
            &[&id],
            move |o| o.run(&i).probe("top", "fx").hypot(o.run(&i).probe("top", "fy")),
        );
        let i = id.clone();
        p.check(
            "C 5.1 Table 1",
            format!("{angle} deg: r_u (displacement_l2)"),
            ru,
            Rule::AtMost(5e-8),
            true,
            "the band's own error (0.24 delta/h at boundaries with normal strain) puts ours at 8e-9..1.1e-8; C's values need delta ~1e-7 h",
            &[&id],
            move |o| o.run(&i).error("displacement_l2"),
        );
    }
}

/// C 5.2 Tables 2 and 3: the deep beam's corner A against FE.
pub(super) fn c_beam(p: &mut Plan) {
    p.run("beam-fe-10", "deep-beam-self-weight", deep_beam(10.0, 2, true));
    for (n, paper, unit, quick) in [
        (3usize, 1.6653e-3, 1e-7, true),
        (5, 5.9450e-4, 1e-8, false),
        (10, 1.4812e-4, 1e-8, true),
        (15, 6.5788e-5, 1e-9, false),
        (20, 3.6998e-5, 1e-9, false),
    ] {
        let id = format!("beam-10-{n}");
        p.run(&id, "deep-beam-self-weight", deep_beam(10.0, n, false));
        let i = id.clone();
        p.check(
            "C 5.2 Table 2",
            format!("h = 10 mm, {n}^2 points: u_A error against FE"),
            paper,
            Rule::Absolute(0.5 * unit + 2e-8),
            quick,
            "C's digits (half a unit of the last) plus 2e-8, the band's O(delta/h) share of u_A",
            &[&id, "beam-fe-10"],
            move |o| corner_a_error(o.run(&i), o.run("beam-fe-10")),
        );
    }
    for (h, paper, unit, quick) in [
        (10.0, 9.313e-4, 1e-7, true),
        (5.0, 3.110e-4, 1e-7, false),
        (2.0, 7.558e-5, 1e-8, false),
    ] {
        let (mp, fe) = (format!("beam-{h}-4"), format!("beam-fe-{h}"));
        if h != 10.0 {
            p.run(&fe, "deep-beam-self-weight", deep_beam(h, 2, true));
        }
        p.run(&mp, "deep-beam-self-weight", deep_beam(h, 4, false));
        let (m, f) = (mp.clone(), fe.clone());
        p.check(
            "C 5.2 Table 3",
            format!("h = {h} mm, 4^2 points: u_A error against FE"),
            paper,
            Rule::Absolute(0.5 * unit + 2e-8),
            quick,
            "C's digits (half a unit of the last) plus 2e-8, the band's O(delta/h) share of u_A",
            &[&mp, &fe],
            move |o| corner_a_error(o.run(&m), o.run(&f)),
        );
    }
}

/// C 5.3: simple shear, every edge by IBM, at offsets across the cells.
pub(super) fn c_shear(p: &mut Plan) {
    for a in [0.0, 25.0, 99.999] {
        let id = format!("shear-{a}");
        p.run(&id, "simple-shear-sweep", simple_shear(a));
        let i = id.clone();
        p.check(
            "C 5.3",
            format!("offset {a} mm: stress error (stress_l2)"),
            2e-8,
            Rule::AtMost(2e-8),
            true,
            "C: below 2e-8 at every offset",
            &[&id],
            move |o| o.run(&i).error("stress_l2"),
        );
    }
}

/// B 4.2: the follower-pressure cantilever, points refined with h.
pub(super) fn b_cantilever(p: &mut Plan) {
    for (h, lattice) in [(1.5, [56usize, 16usize]), (0.75, [112, 32]), (0.375, [224, 64])] {
        p.run(&format!("cantilever-{h}"), "cantilever-follower-pressure", move |s| {
            s.grid.h = h;
            s.grid.origin = [0.0, 1.75 - 1.5 * (6.0 / 1.5 + 1.0)];
            s.grid.size = [11.0 * 1.5, 1.5 * (6.0 / 1.5 + 1.0) + 3.0];
            s.dirichlet[1].node = Some([0.0, 1.75]);
            s.bodies[0].lattice = Some(lattice);
        });
    }
    p.check(
        "B 4.2 Fig. 12",
        "mid-tip deflection (m), Richardson limit of h = 1.5, 0.75, 0.375",
        2.8220,
        Rule::Relative(0.02),
        false,
        "the FE reference is a converged number; the extrapolation of three refinements lands within 2%",
        &["cantilever-1.5", "cantilever-0.75", "cantilever-0.375"],
        |o| {
            let tip = |id: &str| -o.run(id).boundary_point("tip", 1)[1];
            let (a, b, c) = (tip("cantilever-1.5"), tip("cantilever-0.75"), tip("cantilever-0.375"));
            let rate = ((b - a) / (c - b)).log2();
            c + (c - b) / (2f64.powf(rate) - 1.0)
        },
    );
}

/// B 4.4.1: plate with a hole, Neumann; rates over h = 1/4 .. 1/16.
pub(super) fn b_plate_neumann(p: &mut Plan) {
    let plate: Vec<String> = [0.25, 0.125, 0.0625].iter().map(|h| format!("plate-{h}")).collect();
    for (id, h) in plate.iter().zip([0.25, 0.125, 0.0625]) {
        p.run(id, "plate-hole-neumann", move |s| {
            s.grid.h = h;
            s.bodies[0].points_per_cell = 8;
        });
    }
    let plate_ids: Vec<&str> = plate.iter().map(String::as_str).collect();
    for (name, paper, bound) in [("displacement_l2", 2.0, 1.7), ("stress_l2", 1.0, 0.85)] {
        let ids = plate.clone();
        p.check(
            "B 4.4.1 Fig. 17",
            format!("rate of {name}, h = 1/4..1/16, 8^2 points"),
            paper,
            Rule::AtLeast(bound),
            false,
            "B: about 2 and 1; a fitted slope over three grids within 15% below",
            &plate_ids,
            move |o| {
                let e: Vec<f64> = ids.iter().map(|id| o.run(id).error(name)).collect();
                slope(&[0.25, 0.125, 0.0625], &e)
            },
        );
    }
}

/// G 5.4 Table 4: the column at h = 50/512, gamma_K/E = 1e-6.
pub(super) fn g_column(p: &mut Plan) {
    p.run("column-512", "column-self-weight", column(512, 1e-6 * 10.0e3));
    p.check(
        "G 5.4 Table 4",
        "h = 50/512 m, gamma_K/E = 1e-6: syy_normalised",
        4.938e-5,
        Rule::Absolute(0.0005e-5),
        false,
        "G's digits: the penalty is a millionth of the bulk, the run is G's plain GIMP",
        &["column-512"],
        |o| o.run("column-512").error("syy_normalised"),
    );
    for (g, paper) in [(1.0, 4.938e-5), (1e6, 4.962e-5)] {
        let id = format!("column-512-{g}");
        p.run(&id, "column-self-weight", column(512, g * 10.0e3));
        let i = id.clone();
        p.check(
            "G 5.4 Table 4",
            format!("h = 50/512 m, gamma_K/E = {g:e}: syy_normalised"),
            paper,
            Rule::Relative(0.0049),
            false,
            "G's own spread over gamma_K (0.49%): with the penalty active our ghost faces are not G's (docs/verification.md)",
            &[&id],
            move |o| o.run(&i).error("syy_normalised"),
        );
    }
}

/// B 4.4.2: the Kirsch displacement on the outer spline by IBM.
pub(super) fn b_plate_dirichlet(p: &mut Plan) {
    let hs = [0.5, 0.25, 0.125, 0.0625, 0.03125];
    let dirichlet: Vec<String> = hs.iter().map(|h| format!("plate-dirichlet-{h}")).collect();
    for (id, h) in dirichlet.iter().zip(hs) {
        p.run(id, "plate-hole-dirichlet", move |s| {
            s.grid.h = h;
            s.bodies[0].points_per_cell = 8;
            // Automatic: the plain fit, regularised only where it is singular.
            s.ibm[0].fit_regularisation = None;
        });
    }
    let ids: Vec<&str> = dirichlet.iter().map(String::as_str).collect();
    let d = dirichlet.clone();
    p.check(
        "B 4.4.2 Fig. 20",
        "rate of the boundary fit (rms deviation), h = 1/2..1/32",
        2.26,
        Rule::AtLeast(1.9),
        false,
        "about 2 or better: the rms deviation is the norm the least-squares fit minimises (ours 2.07)",
        &ids,
        move |o| {
            let e: Vec<f64> = d
                .iter()
                .map(|id| {
                    o.run(id)
                        .reports
                        .last()
                        .and_then(|r| r.ibm.first())
                        .map_or(f64::NAN, |b| b.violation_rms)
                })
                .collect();
            slope(&hs, &e)
        },
    );
    let d = dirichlet.clone();
    p.tables.push(DocTable {
        name: "plate-hole-dirichlet",
        runs: dirichlet.clone(),
        render: Box::new(move |o| plate_dirichlet_table(o, &d, hs)),
    });
}

/// The measured table of B 4.4.2 (runs `ids` at cell sizes `hs`): the
/// boundary fit's rms and largest deviation and the two error norms per
/// grid, and their fitted rates.
fn plate_dirichlet_table(o: &Outcomes, ids: &[String], hs: [f64; 5]) -> String {
    let mut t = String::from(
        "| h (m) | fit error, rms (m) | fit error, largest (m) | displacement_l2 | stress_l2 |\n|---|---|---|---|---|\n",
    );
    let mut cols: Vec<[f64; 4]> = Vec::new();
    for (id, h) in ids.iter().zip(hs) {
        let r = o.run(id);
        let b = r.reports.last().and_then(|x| x.ibm.first());
        let row = [
            b.map_or(f64::NAN, |b| b.violation_rms),
            b.map_or(f64::NAN, |b| b.violation),
            r.error("displacement_l2"),
            r.error("stress_l2"),
        ];
        t.push_str(&format!(
            "| 1/{} | {:.3e} | {:.3e} | {:.3e} | {:.3e} |\n",
            (1.0 / h).round(),
            row[0],
            row[1],
            row[2],
            row[3]
        ));
        cols.push(row);
    }
    let rate = |k: usize| slope(&hs, &cols.iter().map(|c| c[k]).collect::<Vec<_>>());
    t.push_str(&format!(
        "| fitted rate | {:.2} | {:.2} | {:.2} | {:.2} |\n",
        rate(0),
        rate(1),
        rate(2),
        rate(3)
    ));
    t
}

/// C 5.5 pushed to collapse: Prandtl's (2 + pi) c_u under a smooth footing.
pub(super) fn c_footing(p: &mut Plan) {
    p.run("footing-large", "rigid-footing-large", |_| {});
    p.check(
        "C 5.5 / Prandtl",
        "limit pressure q / c_u (mean of the last 8 steps), F-bar",
        2.0 + std::f64::consts::PI,
        Rule::Relative(0.05),
        false,
        "a coarse Q4 mesh errs from above: 4.9% at h = B/20",
        &["footing-large"],
        |o| {
            let r = o.run("footing-large");
            let m = r.sim.model();
            let (Some(ibm), Some(c)) = (m.ibm.first(), m.materials.first().and_then(|x| x.yield_stress)) else {
                return f64::NAN;
            };
            let half_width = (ibm.points[0][0] - ibm.points[1][0]).abs();
            let c_u = c / 2f64.sqrt();
            let last = &r.reports[r.reports.len().saturating_sub(8)..];
            if last.len() < 8 {
                return f64::NAN;
            }
            last.iter()
                .map(|x| -x.ibm[0].reaction[1] / half_width / c_u)
                .sum::<f64>()
                / 8.0
        },
    );
}

/// G 5.5 Table 5: the GIMP beam with and without Ghost stiffness.
pub(super) fn g_beam(p: &mut Plan) {
    for (h, n) in [(0.5, 2usize), (0.25, 2)] {
        let id = format!("beam-ghost-{h}-{n}");
        p.run(&id, "elastic-beam-ghost", move |s| {
            s.grid.h = h;
            s.bodies[0].points_per_cell = n;
        });
        let i = id.clone();
        p.check(
            "G 5.5 Table 5",
            format!("h = {h}, {n}^2 points, Ghost: load steps completed"),
            50.0,
            Rule::Absolute(0.0),
            h == 0.5,
            "every stabilised run completes",
            &[&id],
            move |o| o.run(&i).steps(),
        );
    }
    p.run("beam-plain-0.25-2", "elastic-beam-ghost", |s| {
        s.grid.h = 0.25;
        s.bodies[0].points_per_cell = 2;
        s.analysis.gamma_k = 0.0;
    });
    p.check(
        "G 5.5 Table 5",
        "h = 0.25, 2^2 points, no Ghost: steps completed before failing",
        11.0,
        Rule::AtMost(22.0),
        false,
        "G stops after 11 steps; at condition numbers of 1e20-1e22 round-off decides the step (docs/verification.md): within twice G's",
        &["beam-plain-0.25-2"],
        |o| {
            let r = o.run("beam-plain-0.25-2");
            if r.failure.is_some() {
                r.steps()
            } else {
                f64::NAN
            }
        },
    );
    p.run("beam-ghost-0.125-2", "elastic-beam-ghost", |s| {
        s.grid.h = 0.125;
        s.bodies[0].points_per_cell = 2;
    });
    let (_, dy) = crate::exact::elastica_tip(10.0 * (1.0 - 0.2 * 0.2));
    p.check(
        "G 5.5 / Molstad 1977",
        "h = 0.125, Ghost: tip deflection (m) against the elastica",
        10.0 * dy,
        Rule::Relative(0.05),
        false,
        "the elastica is a thin inextensible beam; shear, axial strain and the load 0.03 m from the end leave a few percent",
        &["beam-ghost-0.125-2"],
        |o| -o.run("beam-ghost-0.125-2").loaded_points()[1],
    );
}

/// G 5.1-5.2: the dynamics of the ghosts, stretching (5.1.2) and colliding (5.2 Table 3).
pub(super) fn g_dynamics(p: &mut Plan) {
    // G 5.1.2: the stretching ghost, stabilised consistent mass.
    p.run("stretching", "stretching-ghost", |_| {});
    p.check(
        "G 5.1.2",
        "largest displacement error over 1 s (m)",
        1e-13,
        Rule::AtMost(1e-12),
        true,
        "G: below 1e-13 m; 1e-12 allows the round-off of 1000 steps",
        &["stretching"],
        |o| largest_error(o.run("stretching"), "displacement_max"),
    );
    // G 5.2 Table 3: the elastic collision, USF, stabilised mass.
    for steps in [1000usize, 2000] {
        p.run(&format!("collision-{steps}"), "ghost-collision-elastic", move |s| {
            s.analysis.load_steps = steps;
            s.analysis.mass = MassKind::Stabilised;
            s.analysis.stress_update = StressUpdate::Usf;
            s.analysis.condition_every = 0;
            s.analysis.gamma_m = None;
        });
    }
    p.check(
        "G 5.2 Table 3",
        "h = 0.1, 1000 steps, USF stabilised: mean energy error",
        0.888e-3,
        Rule::Relative(0.35),
        false,
        "our ghosts are G's outline filled by a lattice (W0 0.6% below G's), and the error lives on the contact",
        &["collision-1000"],
        |o| mean_energy_error(o.run("collision-1000")),
    );
    p.check(
        "G 5.2 Table 3",
        "energy error at 2000 over 1000 steps",
        0.445 / 0.888,
        Rule::Absolute(0.015),
        false,
        "first order in dt: 1/2 up to O(dt) terms",
        &["collision-1000", "collision-2000"],
        |o| mean_energy_error(o.run("collision-2000")) / mean_energy_error(o.run("collision-1000")),
    );
}

/// Relative error of corner A's vertical displacement against the FE run.
fn corner_a_error(mp: &Outcome, fe: &Outcome) -> f64 {
    let (a, b) = (mp.boundary_point("", 2)[1], fe.boundary_point("", 2)[1]);
    ((a - b) / b).abs()
}

/// The largest value of the error `name` over every step of a run.
fn largest_error(o: &Outcome, name: &str) -> f64 {
    o.reports
        .iter()
        .flat_map(|r| r.errors.iter().filter(|e| e.name == name).map(|e| e.value))
        .fold(0.0, f64::max)
}

/// G 5.2's mean energy error `(1/(nt W0)) sum |W_kin + W_eps - W0|`.
fn mean_energy_error(o: &Outcome) -> f64 {
    let Some(w0) = o
        .reports
        .first()
        .and_then(|r| r.dynamics.as_ref())
        .map(|d| d.initial_energy)
    else {
        return f64::NAN;
    };
    o.reports
        .iter()
        .map(|r| (r.energy.kinetic + r.energy.strain - w0).abs())
        .sum::<f64>()
        / (o.reports.len() as f64 * w0)
}

/// Least-squares slope of `ln y` against `ln x`.
fn slope(xs: &[f64], ys: &[f64]) -> f64 {
    let (lx, ly): (Vec<f64>, Vec<f64>) = (xs.iter().map(|x| x.ln()).collect(), ys.iter().map(|y| y.ln()).collect());
    let n = lx.len() as f64;
    let (mx, my) = (lx.iter().sum::<f64>() / n, ly.iter().sum::<f64>() / n);
    lx.iter().zip(&ly).map(|(x, y)| (x - mx) * (y - my)).sum::<f64>() / lx.iter().map(|x| (x - mx).powi(2)).sum::<f64>()
}

/// Implicit dynamics (Newmark on the implicit core): the exact solutions
/// its scenes carry, and G 5.2 at ten times the explicit step.
pub(super) fn newmark(p: &mut Plan) {
    // A block sliding on a frictionless inclined roller: g sin(30) t^2 / 2.
    p.run("incline-slide", "incline-slide-implicit", |_| {});
    p.check(
        "Newmark: incline",
        "mean slide along the roller at 0.1 s (m)",
        9.81 * 0.5 * 0.01 / 2.0,
        Rule::Relative(1e-3),
        true,
        "exact: g sin(30 deg) t^2 / 2; the roller's band carries a force along it of order delta/h (4e-6 measured)",
        &["incline-slide"],
        |o| {
            let pts = o.run("incline-slide").sim.points();
            let down = [-(30f64.to_radians().cos()), -(30f64.to_radians().sin())];
            let m: f64 = pts.mass.iter().sum();
            (0..pts.len())
                .map(|q| {
                    let u = pts.displacement(q);
                    pts.mass[q] * (u[0] * down[0] + u[1] * down[1])
                })
                .sum::<f64>()
                / m
        },
    );
    // A bar in its first axial mode: period 4 L / c = 4 s, amplitude kept.
    p.run("axial-vibration", "axial-vibration-implicit", |_| {});
    p.check(
        "Newmark: axial bar",
        "period over 10 periods (s)",
        4.0,
        Rule::Relative(5e-3),
        true,
        "exact 4 L / c; the trapezoidal rule lengthens it by (omega dt)^2 / 12 = 0.2%",
        &["axial-vibration"],
        |o| tip_period_and_amplitude(o.run("axial-vibration")).0,
    );
    p.check(
        "Newmark: axial bar",
        "tip amplitude, 10th period over 1st",
        1.0,
        Rule::Relative(1e-2),
        true,
        "the trapezoidal rule's amplification is unitary; peaks sampled 40 times a period",
        &["axial-vibration"],
        |o| tip_period_and_amplitude(o.run("axial-vibration")).1,
    );
    // G 5.1.2 implicitly: the stabilised consistent mass maps the linear
    // field exactly, Newmark moves every point on its path.
    p.run("stretching-implicit", "stretching-ghost-implicit", |_| {});
    p.check(
        "Newmark: G 5.1.2",
        "largest displacement error over 1 s, 100 steps (m)",
        1e-13,
        Rule::AtMost(1e-12),
        true,
        "G: below 1e-13 m explicitly; exact to round-off",
        &["stretching-implicit"],
        |o| largest_error(o.run("stretching-implicit"), "displacement_max"),
    );
    // G 5.2 at ten times the explicit step (100 steps over 3.5 s).
    p.run("collision-implicit", "ghost-collision-implicit", |_| {});
    p.check(
        "Newmark: G 5.2",
        "h = 0.1, 100 steps (10x explicit): mean energy error",
        0.888e-3,
        Rule::AtMost(6e-3),
        true,
        "G Table 3's value is explicit at 1000 steps (ours 1.15e-3); the FLIP transfer loses 1/2 dv.gamma_M J_G dv a step",
        &["collision-implicit"],
        |o| mean_energy_error(o.run("collision-implicit")),
    );
}

/// The axial bar's period (s) from the upward zero crossings of its tip
/// probe's `ux`, and its peak amplitude in the last 4 s period over the
/// first's.
fn tip_period_and_amplitude(o: &Outcome) -> (f64, f64) {
    let h: Vec<(f64, f64)> = std::iter::once((0.0, 0.0))
        .chain(o.reports.iter().map(|r| {
            let t = r.dynamics.as_ref().map_or(f64::NAN, |d| d.time);
            let ux = r
                .probes
                .iter()
                .find(|p| p.name == "tip")
                .and_then(|p| p.columns().into_iter().find(|c| c.0 == "ux"))
                .map_or(f64::NAN, |c| c.2);
            (t, ux)
        }))
        .collect();
    let up: Vec<f64> = h
        .windows(2)
        .filter(|w| w[0].1 < 0.0 && w[1].1 >= 0.0)
        .map(|w| w[0].0 + (w[1].0 - w[0].0) * w[0].1 / (w[0].1 - w[1].1))
        .collect();
    if up.len() < 2 {
        return (f64::NAN, f64::NAN);
    }
    let period = (up[up.len() - 1] - up[0]) / (up.len() - 1) as f64;
    let end = h.last().map_or(0.0, |x| x.0);
    let peak = |from: f64| {
        h.iter()
            .filter(|(t, _)| *t >= from && *t < from + 4.0)
            .map(|(_, u)| u.abs())
            .fold(0.0, f64::max)
    };
    (period, peak(end - 4.0) / peak(0.0))
}

/// Cook's membrane (Cook 1974), against an independent finite-element
/// reference (`scripts/cook_reference.py`: scikit-fem, Q2 in plane stress,
/// Taylor-Hood Q2-Q1 displacement-pressure near incompressibility, meshes
/// to 128 x 128 extrapolated; bars 0.001, 0.012, 0.0033, 0.0019); the
/// literature's 23.96 is the middle of the loaded edge. Small strain on
/// one configuration, h = 1 (48 cells across), bilinear bases: first
/// order in h (the clamped edge's corners are singular), 0.2-0.7% here.
pub(super) fn cook(p: &mut Plan) {
    p.run("cook", "cook-membrane", |_| {});
    p.run("cook-incompressible", "cook-membrane-incompressible", |_| {});
    p.run("cook-incompressible-plain", "cook-membrane-incompressible", |s| {
        s.analysis.fbar = false
    });
    let why = "first order in h at h = 1 (48 cells across), under 1% (0.5% for the mid-edge in plane stress)";
    for (id, what, probe, reference, tol) in [
        (
            "cook",
            "plane stress: u_y at the middle of the loaded edge (48, 52)",
            "mid",
            23.9677,
            0.005,
        ),
        (
            "cook",
            "plane stress: u_y at the top corner (48, 60)",
            "corner",
            25.189,
            0.01,
        ),
        (
            "cook-incompressible",
            "nu = 0.4999, B-bar (fbar): u_y at the top corner (48, 60)",
            "corner",
            7.7713,
            0.01,
        ),
        (
            "cook-incompressible",
            "nu = 0.4999, B-bar (fbar): u_y at the middle of the loaded edge",
            "mid",
            7.4047,
            0.01,
        ),
    ] {
        p.check(
            "Cook / FE reference",
            what,
            reference,
            Rule::Relative(tol),
            true,
            why,
            &[id],
            move |o| o.run(id).probe(probe, "uy"),
        );
    }
    p.check(
        "Cook / FE reference",
        "nu = 0.4999 without B-bar: u_y at the corner (locks)",
        7.7713,
        Rule::AtMost(0.8 * 7.7713),
        true,
        "volumetric locking: the plain small-strain B moves the corner at least 20% too little",
        &["cook-incompressible-plain"],
        |o| o.run("cook-incompressible-plain").probe("corner", "uy"),
    );
}
