//! Refinement study of the thick cylinder (B 4.3, `scenarios/thick-cylinder.toml`):
//! the deformed inner and outer radius errors and the `displacement_l2` /
//! `stress_l2` errors against Lame, for several arrangements of points.
//!
//! `cargo run --release --example cylinder_study -- <study> [finest h] [chord tolerance]`
//! with `<study>` one of
//! - `paper`: polar points refined with the grid (the scene's 16 x 32 at
//!   h = 1, doubled each way as h halves), standard basis;
//! - `test`: the same from 8 x 16 at h = 1 (`thick_cylinder_radii_converge`);
//! - `paper-gimp`: the same points with the GIMP basis;
//! - `fixed-h`: h = 1/4 with 1x, 2x, 4x the paper's points each way;
//! - `faster`: polar points doubled each way per halving, from 4x the scene's
//!   count at h = 1 (more points per cell at every h);
//! - `centres-N` / `clipped-N`: N x N points per cell on the annulus-sector
//!   region; the inner and outer B-splines through explicit tracking points
//!   on the two circles (layers of points need the polar lattice);
//! - `centres-gimp-N` / `clipped-gimp-N`: the same with the GIMP basis and
//!   one more cell of grid below and left (clipped: singular at h = 1, the
//!   nodes beyond the symmetry lines held by slivers of domains).
//! - `quadrature`: no runs; each cell's point rule for the polar lattice
//!   (and 4 x 4 clipped points) against the cell's exact volume and first
//!   moment, for the cells wholly inside the annulus.
//!
//! The output is in docs/verification.md; the assertions are in
//! `engine/tests/physics/boundary_scenes.rs`.

use mpmlab::basis::BasisKind;
use mpmlab::exact::ExactSolution;
use mpmlab::scene::{Placement, RegionSpec, Scene};
use mpmlab::{Model, Simulation};
use std::path::PathBuf;

/// Mean relative error of the deformed radius along a boundary spline.
fn radius_error(sim: &Simulation, name: &str, r: f64) -> f64 {
    let exact = sim.model().exact.clone().unwrap();
    let target = r + exact.displacement([r, 0.0])[0];
    let (_, spline) = sim.boundary_splines().into_iter().find(|(n, _)| n == name).unwrap();
    let s = spline.unwrap();
    let per = 1000 / s.segments.len() + 1;
    let samples = s.sample(per);
    samples
        .iter()
        .map(|p| (p[0].hypot(p[1]) - target).abs() / target)
        .sum::<f64>()
        / samples.len() as f64
}

/// `n` tracking points on the circle of radius `r` over the quarter, a hair
/// (1e-9 rad) inside the symmetry lines like the polar lattice's.
fn arc(r: f64, n: usize) -> Vec<[f64; 2]> {
    let (t0, t1) = (1e-9, std::f64::consts::FRAC_PI_2 - 1e-9);
    (0..n)
        .map(|j| {
            let t = t0 + (t1 - t0) * j as f64 / (n - 1) as f64;
            [r * t.cos(), r * t.sin()]
        })
        .collect()
}

/// A change to the scene before it is built.
type Edit = Box<dyn FnOnce(&mut Scene)>;

struct Row {
    h: f64,
    points: usize,
    inner: f64,
    outer: f64,
    disp: f64,
    stress: f64,
}

fn run(text: &str, h: f64, edit: impl FnOnce(&mut Scene)) -> Row {
    let name = "thick-cylinder";
    let mut scene = Scene::parse(text, name).unwrap_or_else(|e| panic!("{e}"));
    scene.grid.h = h;
    edit(&mut scene);
    let mut sim = Simulation::new(Model::build(&scene, text, name).unwrap_or_else(|e| panic!("{e}")));
    let mut last = None;
    while !sim.finished() {
        last = Some(sim.step().unwrap_or_else(|f| panic!("{f}")));
    }
    let r = last.unwrap();
    let err = |n: &str| r.errors.iter().find(|e| e.name == n).unwrap().value;
    assert!(matches!(sim.model().exact, Some(ExactSolution::Lame { .. })));
    Row {
        h,
        points: sim.points().vol0.iter().filter(|&&v| v > 0.0).count(),
        inner: radius_error(&sim, "inner", 1.0),
        outer: radius_error(&sim, "outer", 5.0),
        disp: err("displacement_l2"),
        stress: err("stress_l2"),
    }
}

/// The point rule of each cell wholly inside the annulus against exact cell
/// integrals: RMS and largest over those cells of the relative errors of the
/// cell's volume (sum of point volumes / h^2 - 1) and of its first moment
/// (sum of V_p (xi_p - 1/2) / h^2, exact 0; xi the local coordinate in 0..1
/// along x). A point rule exact for both in every cell passes the patch test
/// (the stiffness integrand against a constant strain is linear in a cell).
fn cell_quadrature(text: &str, h: f64, edit: impl FnOnce(&mut Scene)) -> [f64; 4] {
    let name = "thick-cylinder";
    let mut scene = Scene::parse(text, name).unwrap();
    scene.grid.h = h;
    edit(&mut scene);
    let sim = Simulation::new(Model::build(&scene, text, name).unwrap());
    let pts = sim.points();
    let n = (6.0 / h).round() as usize;
    let mut vol = vec![0.0; n * n];
    let mut mom = vec![0.0; n * n];
    for p in 0..pts.len() {
        let [x, y] = pts.x0[p];
        let (i, j) = ((x / h).floor() as usize, (y / h).floor() as usize);
        let xi = x / h - i as f64;
        vol[j * n + i] += pts.vol0[p];
        mom[j * n + i] += pts.vol0[p] * (xi - 0.5);
    }
    let (mut sv, mut mv, mut sm, mut mm, mut count) = (0.0, 0.0f64, 0.0, 0.0f64, 0.0);
    for j in 0..n {
        for i in 0..n {
            let (x0, y0) = (i as f64 * h, j as f64 * h);
            if x0.hypot(y0) < 1.0 || (x0 + h).hypot(y0 + h) > 5.0 {
                continue;
            }
            let ev = vol[j * n + i] / (h * h) - 1.0;
            let em = mom[j * n + i] / (h * h);
            sv += ev * ev;
            sm += em * em;
            mv = mv.max(ev.abs());
            mm = mm.max(em.abs());
            count += 1.0;
        }
    }
    [(sv / count).sqrt(), mv, (sm / count).sqrt(), mm]
}

/// N x N points per cell by `placement` on the annulus sector (chord
/// tolerance `chord`), with the inner and outer B-splines through tracking
/// points on the circles: `layer = "inner"` needs the polar lattice (on other
/// placements every point has its own angle, so the "layer" is every point
/// and the scene is refused: the material side cannot be told).
fn sub_cell_points(s: &mut Scene, placement: Placement, n: usize, basis: BasisKind, chord: Option<f64>) {
    let b = &mut s.bodies[0];
    b.placement = placement;
    b.points_per_cell = n;
    b.basis = basis;
    b.radial_points = None;
    b.circumferential_points = None;
    if basis == BasisKind::Gimp {
        // As for the polar points: room for the domains across the symmetry lines.
        s.grid.origin = [-1.0, -1.0];
        s.grid.size = [7.0, 7.0];
    }
    let b = &mut s.bodies[0];
    if let (Some(t), RegionSpec::AnnulusSector { tolerance, .. }) = (chord, &mut b.region) {
        *tolerance = Some(t);
    }
    // Enough tracking points that the circle's own interpolation error
    // (order 4) is far below the errors measured: 33 on the quarter, as in
    // `scenarios/thick-cylinder-converging.toml`.
    for (bd, r) in s.boundaries.iter_mut().zip([1.0, 5.0]) {
        bd.layer = None;
        bd.center = None;
        bd.points = Some(arc(r, 33));
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let study = args.get(1).map(String::as_str).unwrap_or("paper");
    if study == "quadrature" {
        let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios/thick-cylinder.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        println!("| h (m) | points | volume error RMS | max | first moment error RMS | max |");
        println!("|---|---|---|---|---|---|");
        let mut cases = Vec::new();
        for k in [1, 2] {
            for h in [0.25f64, 0.125, 0.0625, 0.03125] {
                let m = k * (1.0 / h).round() as usize;
                cases.push((h, 8 * m, 16 * m));
            }
        }
        for m in [2, 4, 8] {
            cases.push((0.0625, 8 * 16 * m, 16 * 16 * m));
        }
        for (h, nr, nc) in cases {
            let q = cell_quadrature(&text, h, |s| {
                s.bodies[0].radial_points = Some(nr);
                s.bodies[0].circumferential_points = Some(nc);
            });
            println!(
                "| {h} | {nr} x {nc} | {:.2e} | {:.2e} | {:.2e} | {:.2e} |",
                q[0], q[1], q[2], q[3]
            );
        }
        for h in [0.25, 0.0625] {
            let q = cell_quadrature(&text, h, |s| {
                sub_cell_points(s, Placement::Clipped, 4, BasisKind::Standard, None)
            });
            println!(
                "| {h} | clipped 4 x 4 | {:.2e} | {:.2e} | {:.2e} | {:.2e} |",
                q[0], q[1], q[2], q[3]
            );
        }
        return;
    }
    let finest: f64 = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(1.0 / 16.0);
    // Chord tolerance of the annulus sector for `centres`/`clipped` (m).
    let chord: Option<f64> = args.get(3).map(|s| s.parse().unwrap());
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios/thick-cylinder.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut hs = vec![1.0];
    while *hs.last().unwrap() > finest * 1.0001 {
        hs.push(hs.last().unwrap() / 2.0);
    }
    println!("study {study}");
    println!("| h (m) | points | inner radius | outer radius | displacement_l2 | stress_l2 |");
    println!("|---|---|---|---|---|---|");
    let mut rows: Vec<Row> = Vec::new();
    let polar = |k: usize, basis: BasisKind| {
        move |s: &mut Scene| {
            s.bodies[0].radial_points = Some(8 * k);
            s.bodies[0].circumferential_points = Some(16 * k);
            s.bodies[0].basis = basis;
            if basis == BasisKind::Gimp {
                // GIMP domains of the points on the symmetry lines reach
                // across them: one more cell of grid below and left.
                s.grid.origin = [-1.0, -1.0];
                s.grid.size = [7.0, 7.0];
            }
        }
    };
    let cases: Vec<(f64, Edit)> = match study {
        "paper" | "paper-gimp" | "faster" | "test" => {
            let basis = if study == "paper-gimp" {
                BasisKind::Gimp
            } else {
                BasisKind::Standard
            };
            let k0 = match study {
                "test" => 1,
                "faster" => 8,
                _ => 2,
            };
            hs.iter()
                .map(|&h| {
                    let k = k0 * (1.0 / h).round() as usize;
                    (h, Box::new(polar(k, basis)) as Edit)
                })
                .collect()
        }
        "fixed-h" => [4, 8, 16]
            .iter()
            .map(|&k| (0.25, Box::new(polar(2 * k, BasisKind::Standard)) as Edit))
            .collect(),
        other => {
            let mut parts = other.split('-').collect::<Vec<_>>();
            let n: usize = parts.pop().unwrap().parse().expect("N points per cell");
            let placement = match parts[0] {
                "centres" => Placement::Centres,
                "clipped" => Placement::Clipped,
                _ => panic!("unknown study {other}"),
            };
            let basis = if parts.get(1) == Some(&"gimp") {
                BasisKind::Gimp
            } else {
                BasisKind::Standard
            };
            hs.iter()
                .map(|&h| {
                    let edit = move |s: &mut Scene| sub_cell_points(s, placement, n, basis, chord);
                    (h, Box::new(edit) as Edit)
                })
                .collect()
        }
    };
    for (h, edit) in cases {
        let t = std::time::Instant::now();
        let row = run(&text, h, edit);
        println!(
            "| {} | {} | {:.3e} | {:.3e} | {:.3e} | {:.3e} | ({:.1} s)",
            row.h,
            row.points,
            row.inner,
            row.outer,
            row.disp,
            row.stress,
            t.elapsed().as_secs_f64()
        );
        rows.push(row);
    }
    if rows.len() > 1 && rows[0].h != rows[1].h {
        println!("rates per halving (log2 ratio): inner, outer, displacement_l2, stress_l2");
        for w in rows.windows(2) {
            let r = |a: f64, b: f64| (a / b).log2();
            println!(
                "  h {} -> {}: {:.2} {:.2} {:.2} {:.2}",
                w[0].h,
                w[1].h,
                r(w[0].inner, w[1].inner),
                r(w[0].outer, w[1].outer),
                r(w[0].disp, w[1].disp),
                r(w[0].stress, w[1].stress)
            );
        }
    }
}
