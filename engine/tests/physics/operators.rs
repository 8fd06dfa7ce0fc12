//! The papers' operators, pinned against their formulas written out by hand
//! here, independently of how the engine assembles them:
//!
//! - G (22)-(23), (27): the ghost matrix `J_G = (h^3/3) int [[d_n N]] [[d_n N]]^T`
//!   of one face and of a 2x2 patch (sMPM and GIMP), and its `h^2` scaling;
//! - G (24) and 3.3: the stabilised mass `M + gamma_M J_G` with the default
//!   `gamma_M = rho/4`, through the momentum it maps to grid velocities;
//! - C (16): the Dirichlet function `d(phi)` and its derivative; the band's
//!   own integral (C (18)-(21)) at delta/h = 0.1, 0.25, 0.5 and the stiffness
//!   of a one-cell 1D problem solved by the engine, against closed forms;
//!   under finite deformation, a band point's deformation gradient against
//!   central differences of its motion `D S d + S d^a`;
//! - B (13)-(17): B-spline traction weights on a straight and a circular
//!   boundary against exact line integrals;
//! - the Hencky / von Mises return map against closed-form pure shear and
//!   uniaxial strain.

use mpmlab_engine::assembly::Mapping;
use mpmlab_engine::boundary::bspline::BSpline;
use mpmlab_engine::boundary::{traction_forces, Boundary, Traction};
use mpmlab_engine::ghost::{self, GhostCells, GhostFace};
use mpmlab_engine::grid::Grid;
use mpmlab_engine::ibm::dirichlet_function;
use mpmlab_engine::material::hencky::Hencky;
use mpmlab_engine::scene::MassKind;
use mpmlab_engine::Simulation;
use nalgebra::{DMatrix, DVector, Matrix2, Matrix3};
use std::collections::BTreeMap;

fn sim(text: &str) -> Simulation {
    Simulation::from_scene_text(text, "operators.toml").unwrap_or_else(|e| panic!("{e}"))
}

/// An implicit boundary through `points` with the material on its
/// `side` (1: left of the direction of travel), no prescribed value and no
/// exact field.
fn polyline(
    name: &str,
    kind: mpmlab_engine::scene::DirichletKind,
    points: Vec<[f64; 2]>,
    side: f64,
) -> mpmlab_engine::ibm::IbmBoundary {
    mpmlab_engine::ibm::IbmBoundary {
        name: name.into(),
        kind,
        points,
        side,
        value: [0.0, 0.0],
        gauss_points: 2,
        exact_field: false,
        fit_regularisation: None,
        moves: false,
        spline: None,
    }
}

// ---------------------------------------------------------------------------
// Ghost stabilisation (G 3.2-3.4)
// ---------------------------------------------------------------------------

/// A face between two cells, described by hand: `Vertical(i, j)` is the
/// face between cells `(i, j)` and `(i + 1, j)`; `Horizontal(i, j)` between
/// `(i, j)` and `(i, j + 1)`.
#[derive(Clone, Copy, Debug)]
enum Face {
    Vertical(usize, usize),
    Horizontal(usize, usize),
}

/// G (22)-(23) written out for one face of a grid with `nx` cells per row
/// and cell size `h`, as entries `(node, node, value)`.
///
/// Across the face the six nodes lie on three lines (the `+` cell's far
/// line, the shared line, the `-` cell's far line) and along it on two. On
/// the face the bilinear functions' normal derivatives are `-+1/h` times the
/// 1D hat along the face, so the jump of the normal derivative of a field
/// with nodal values `u` is `sum_k a_k u_k`, `a = (-1, 2, -1)/h` across times
/// `phi_l(s)` along (`phi_0 = 1 - s/h`, `phi_1 = s/h`). With
/// `int_0^h phi_l phi_m ds = h/3` (l = m) or `h/6`:
/// `J[(c, l), (c', m)] = (h^3/3) (v_c v_c' / h^2) (h/3 or h/6)`
/// `                   = h^2 v_c v_c' (1/9 or 1/18)`, `v = (-1, 2, -1)`.
fn hand_face(face: Face, nx: usize, h: f64) -> Vec<(usize, usize, f64)> {
    let node = |i: usize, j: usize| j * (nx + 1) + i;
    let v = [-1.0, 2.0, -1.0];
    // (across index, along index) -> node
    let at = |c: usize, l: usize| match face {
        Face::Vertical(i, j) => node(i + c, j + l),
        Face::Horizontal(i, j) => node(i + l, j + c),
    };
    let mut out = Vec::new();
    for c in 0..3 {
        for l in 0..2 {
            for c2 in 0..3 {
                for l2 in 0..2 {
                    let along = if l == l2 { 1.0 / 9.0 } else { 1.0 / 18.0 };
                    out.push((at(c, l), at(c2, l2), h * h * v[c] * v[c2] * along));
                }
            }
        }
    }
    out
}

fn hand_matrix(faces: &[Face], grid: &Grid) -> DMatrix<f64> {
    let n = grid.num_nodes();
    let mut m = DMatrix::zeros(n, n);
    for &f in faces {
        for (a, b, v) in hand_face(f, grid.nx, grid.h) {
            m[(a, b)] += v;
        }
    }
    m
}

/// The engine's faces summed into a node-by-node matrix.
fn engine_matrix(faces: &[GhostFace], grid: &Grid) -> DMatrix<f64> {
    let n = grid.num_nodes();
    let mut m = DMatrix::zeros(n, n);
    for f in faces {
        for r in 0..6 {
            for c in 0..6 {
                m[(f.nodes[r], f.nodes[c])] += f.j[r][c];
            }
        }
    }
    m
}

fn max_abs(m: &DMatrix<f64>) -> f64 {
    m.iter().fold(0.0f64, |a, v| a.max(v.abs()))
}

#[test]
fn ghost_face_matrix_is_g23_with_weight_h3_over_3() {
    // One face on a 3 x 3 grid: the centre cell and its right (then upper)
    // neighbour are the only active cells, so both are boundary cells and
    // their shared face is the whole of Gamma (G 4.2).
    for h in [1.0, 0.25] {
        // The origin enters only where the face is drawn (below).
        let origin = [-0.75, 1.5];
        let grid = Grid {
            origin,
            h,
            nx: 3,
            ny: 3,
        };
        let fill = vec![1.0; grid.num_cells()];
        for (active, face) in [([4, 5], Face::Vertical(1, 1)), ([4, 7], Face::Horizontal(1, 1))] {
            let faces = ghost::faces(&grid, &active, &fill);
            assert_eq!(faces.len(), 1, "h {h}, cells {active:?}");
            let (got, want) = (engine_matrix(&faces, &grid), hand_matrix(&[face], &grid));
            // Two-point Gauss along the face integrates the quadratic
            // a a^T exactly: agreement to round-off (entries ~h^2).
            let err = max_abs(&(&got - &want));
            assert!(err < 1e-14 * h * h, "h {h}, {face:?}: {err:e}\n{got}\n{want}");
            // The weight itself: the shared node's diagonal entry is
            // (h^3/3) (2/h)^2 (h/3) = 4 h^2 / 9 (h^3/2 would give 2 h^2/3).
            let shared = match face {
                Face::Vertical(..) => 1 + 4 + 1, // node (2, 1) on a 4-node row
                Face::Horizontal(..) => 2 * 4 + 1,
            };
            assert!((got[(shared, shared)] - 4.0 * h * h / 9.0).abs() < 1e-15 * h * h);
            // Where the face is drawn (TUI, recordings): the grid line
            // i = 2 from j = 1 to 2 between cells (1, 1) and (2, 1), or
            // j = 2 from i = 1 to 2 between (1, 1) and (1, 2). Origin and h
            // are short binary fractions, so every sum is exact.
            let at = |i: f64, j: f64| [origin[0] + i * h, origin[1] + j * h];
            let want = match face {
                Face::Vertical(..) => (at(2.0, 1.0), at(2.0, 2.0)),
                Face::Horizontal(..) => (at(1.0, 2.0), at(2.0, 2.0)),
            };
            assert_eq!(ghost::face_segment(&grid, &faces[0]), want, "h {h}, {face:?}");
        }
    }
}

#[test]
fn every_ghost_face_is_drawn_on_the_grid_line_between_its_cells() {
    // Each pair of neighbouring cells of a 4 x 3 grid (more columns than
    // rows, so a row index is never taken for a column index unnoticed) as
    // the only active cells: their one face is the grid line between them,
    // one cell long. Origin and h are short binary fractions, so every sum
    // is exact.
    let grid = Grid {
        origin: [-0.75, 1.5],
        h: 0.25,
        nx: 4,
        ny: 3,
    };
    let fill = vec![1.0; grid.num_cells()];
    let at = |i: usize, j: usize| [grid.origin[0] + i as f64 * grid.h, grid.origin[1] + j as f64 * grid.h];
    let mut drawn = 0;
    for j in 0..grid.ny {
        for i in 0..grid.nx {
            let c = j * grid.nx + i;
            if i + 1 < grid.nx {
                let faces = ghost::faces(&grid, &[c, c + 1], &fill);
                assert_eq!(faces.len(), 1, "cells ({i}, {j}) and ({}, {j})", i + 1);
                assert_eq!(
                    ghost::face_segment(&grid, &faces[0]),
                    (at(i + 1, j), at(i + 1, j + 1)),
                    "({i}, {j}) right"
                );
                drawn += 1;
            }
            if j + 1 < grid.ny {
                let faces = ghost::faces(&grid, &[c, c + grid.nx], &fill);
                assert_eq!(faces.len(), 1, "cells ({i}, {j}) and ({i}, {})", j + 1);
                assert_eq!(
                    ghost::face_segment(&grid, &faces[0]),
                    (at(i, j + 1), at(i + 1, j + 1)),
                    "({i}, {j}) up"
                );
                drawn += 1;
            }
        }
    }
    // 3 x 3 vertical and 4 x 2 horizontal faces.
    assert_eq!(drawn, 17);
}

#[test]
fn ghost_faces_of_a_2x2_patch_for_smpm_and_gimp() {
    // A 2 x 2-cell body in the middle of a 4 x 4 grid (h = 0.5): all four
    // cells are active and boundary cells, Gamma is the four faces inside
    // the patch. GIMP domains of the 2 x 2 points per cell end exactly on
    // the patch's edges, so they reach no further cell (overlaps of zero
    // width count as none) and give the same face set.
    for basis in ["standard", "gimp"] {
        let s = sim(&format!(
            r#"
[scene]
name = "patch"
[grid]
origin = [0.0, 0.0]
size = [2.0, 2.0]
h = 0.5
[[material]]
name = "m"
E = 1.0e6
nu = 0.3
density = 1000.0
[[body]]
name = "b"
material = "m"
points_per_cell = 2
basis = "{basis}"
region = {{ shape = "rectangle", min = [0.5, 0.5], max = [1.5, 1.5] }}
[analysis]
load_steps = 1
"#
        ));
        let m = s.model();
        let map = Mapping::build(&m.grid, s.points(), &m.bodies, &m.dirichlet, 0.0).expect("memory for the mapping");
        let faces = ghost::faces_of(&m.grid, &map, GhostCells::Reached);
        assert_eq!(faces.len(), 4, "{basis}");
        let want = hand_matrix(
            &[
                Face::Vertical(1, 1),
                Face::Vertical(1, 2),
                Face::Horizontal(1, 1),
                Face::Horizontal(2, 1),
            ],
            &m.grid,
        );
        let got = engine_matrix(&faces, &m.grid);
        let err = max_abs(&(&got - &want));
        assert!(err < 1e-14, "{basis}: {err:e}");
        // The patch's centre node is the shared node of all four faces:
        // 4 x 4 h^2/9 = 4/9 at h = 0.5.
        let centre = 2 * 5 + 2;
        assert!((got[(centre, centre)] - 16.0 * 0.25 / 9.0).abs() < 1e-15, "{basis}");
    }
}

/// 1D GIMP weight of a node at distance `d` for a domain of half-length `l`
/// (Bardenhagen & Kober 2004, as in the design notes), written out here.
fn gimp_1d(d: f64, l: f64, h: f64) -> f64 {
    let a = d.abs();
    if a < l {
        1.0 - (d * d + l * l) / (2.0 * h * l)
    } else if a < h - l {
        1.0 - a / h
    } else if a < h + l {
        (h + l - a).powi(2) / (4.0 * h * l)
    } else {
        0.0
    }
}

fn hat(d: f64, h: f64) -> f64 {
    (1.0 - d.abs() / h).max(0.0)
}

#[test]
fn stabilised_mass_maps_momentum_with_gamma_rho_over_4() {
    // G (9), (10), (24) and 3.3: grid velocities solve
    // (M + gamma_M J_G) v = sum_p m_p S_p v_p with gamma_M = rho/4 by
    // default. Two one-cell bodies side by side, one moving uniformly, the
    // other with a velocity gradient, so the mapped field is not linear
    // (a plain step would be: its projection is odd about the face) and
    // J_G (one face) changes it: gamma_M J_G's entries (rho h^2/36 ..
    // rho h^2/9) are as large as M's, and the mapped velocities move by
    // 0.07 (m/s, of velocities ~1) between the consistent and the
    // stabilised mass, so a factor 2 in gamma_M or 3/2 in the face weight
    // shows by orders above the 1e-12 round-off.
    let (rho, h) = (800.0, 0.5);
    let (va, vb) = ([1.0, -0.5], [-0.25, 2.0]);
    let grad = [[0.8, 0.3], [-0.5, 1.2]];
    for basis in ["standard", "gimp"] {
        let s = sim(&format!(
            r#"
[scene]
name = "two-cells"
[grid]
origin = [0.0, 0.0]
size = [2.0, 1.5]
h = {h}
[[material]]
name = "m"
E = 1.0e6
nu = 0.3
density = {rho}
[[body]]
name = "a"
material = "m"
points_per_cell = 2
basis = "{basis}"
region = {{ shape = "rectangle", min = [0.5, 0.5], max = [1.0, 1.0] }}
velocity = [{}, {}]
velocity_gradient = [[{}, {}], [{}, {}]]
velocity_centre = [0.75, 0.75]
[[body]]
name = "b"
material = "m"
points_per_cell = 2
basis = "{basis}"
region = {{ shape = "rectangle", min = [1.0, 0.5], max = [1.5, 1.0] }}
velocity = [{}, {}]
[analysis]
kind = "explicit-dynamics"
duration = 1.0
load_steps = 10
mass = "stabilised"
"#,
            va[0], va[1], grad[0][0], grad[0][1], grad[1][0], grad[1][1], vb[0], vb[1]
        ));
        let grid = &s.model().grid;
        let pts = s.points();
        assert_eq!(pts.len(), 8);
        // Hand weights: bilinear, or GIMP with the points' domains.
        let weight = |p: usize, n: usize| {
            let xn = [grid.origin[0] + (n % 5) as f64 * h, grid.origin[1] + (n / 5) as f64 * h];
            let (x, l) = (pts.x[p], pts.lp[p]);
            if basis == "standard" {
                hat(x[0] - xn[0], h) * hat(x[1] - xn[1], h)
            } else {
                gimp_1d(x[0] - xn[0], l[0], h) * gimp_1d(x[1] - xn[1], l[1], h)
            }
        };
        let nodes: Vec<usize> = (0..grid.num_nodes())
            .filter(|&n| (0..pts.len()).any(|p| weight(p, n) > 0.0))
            .collect();
        assert_eq!(nodes.len(), 6, "{basis}");
        let idx: BTreeMap<usize, usize> = nodes.iter().enumerate().map(|(i, &n)| (n, i)).collect();
        let k = nodes.len();
        let mut m = DMatrix::zeros(k, k);
        let mut mom: [DVector<f64>; 2] = [DVector::zeros(k), DVector::zeros(k)];
        for p in 0..pts.len() {
            // Each point: a quarter of a cell of density rho.
            assert!((pts.mass[p] - rho * h * h / 4.0).abs() < 1e-12 * rho * h * h);
            let x = pts.x[p];
            let v = if x[0] < 1.0 {
                let d = [x[0] - 0.75, x[1] - 0.75];
                [
                    va[0] + grad[0][0] * d[0] + grad[0][1] * d[1],
                    va[1] + grad[1][0] * d[0] + grad[1][1] * d[1],
                ]
            } else {
                vb
            };
            for (&a, &i) in &idx {
                for (&b, &j) in &idx {
                    m[(i, j)] += pts.mass[p] * weight(p, a) * weight(p, b);
                }
                for c in 0..2 {
                    mom[c][i] += pts.mass[p] * weight(p, a) * v[c];
                }
            }
        }
        // One face, between cells (1, 1) and (2, 1), on the 4-cell-wide grid.
        let jg = hand_matrix(&[Face::Vertical(1, 1)], grid);
        for (&a, &i) in &idx {
            for (&b, &j) in &idx {
                m[(i, j)] += rho / 4.0 * jg[(a, b)];
            }
        }
        let chol = m.clone().cholesky().expect("M~ is positive definite");
        let want: [DVector<f64>; 2] = [chol.solve(&mom[0]), chol.solve(&mom[1])];
        let got = s.map_velocities(MassKind::Stabilised).unwrap();
        assert_eq!(got.len(), 6, "{basis}");
        // cond(M~) is ~1e1 here: the two solves agree to round-off.
        for (n, v) in &got {
            let i = idx[n];
            for c in 0..2 {
                assert!(
                    (v[c] - want[c][i]).abs() < 1e-12,
                    "{basis}: node {n} component {c}: {} vs {}",
                    v[c],
                    want[c][i]
                );
            }
        }
        // The ghost term matters here: the consistent mass alone maps a
        // different field (so this test sees gamma_M and the face weight).
        let plain = s.map_velocities(MassKind::Consistent).unwrap();
        let moved = plain
            .iter()
            .zip(&got)
            .map(|((_, a), (_, b))| (a[0] - b[0]).abs().max((a[1] - b[1]).abs()))
            .fold(0.0, f64::max);
        assert!(moved > 0.05, "{basis}: {moved}");
        // The default itself (checked last, so the velocities above are the
        // physical check of it).
        assert_eq!(s.params().gamma_m, rho / 4.0, "G 3.3 default");
    }
}

// ---------------------------------------------------------------------------
// Implicit boundary method (C 3)
// ---------------------------------------------------------------------------

#[test]
fn dirichlet_function_is_c16() {
    // C (16): d = 1 - (1 - phi/delta)^2 in the band, 0 outside the material,
    // 1 beyond the band; d' = (2/delta)(1 - phi/delta).
    for delta in [1e-6, 0.3, 2.0] {
        for t in [-0.5, 0.0, 0.1, 0.25, 0.5, 0.75, 0.9, 1.0, 1.5] {
            let (d, dd) = dirichlet_function(t * delta, delta);
            let (want, dwant) = if t <= 0.0 {
                (0.0, 0.0)
            } else if t >= 1.0 {
                (1.0, 0.0)
            } else {
                (2.0 * t - t * t, 2.0 * (1.0 - t) / delta)
            };
            // Exact up to the rounding of phi/delta.
            assert!(
                (d - want).abs() < 1e-15,
                "delta {delta}, phi/delta {t}: d {d} vs {want}"
            );
            assert!(
                (dd - dwant).abs() < 1e-14 / delta,
                "delta {delta}, phi/delta {t}: d' {dd} vs {dwant}"
            );
        }
    }
}

/// C (16) by hand: `d` and `d'` at signed distance `phi`.
fn c16(phi: f64, delta: f64) -> (f64, f64) {
    let t = phi / delta;
    if t <= 0.0 {
        (0.0, 0.0)
    } else if t >= 1.0 {
        (1.0, 0.0)
    } else {
        (2.0 * t - t * t, 2.0 * (1.0 - t) / delta)
    }
}

type M2 = [[f64; 2]; 2];

fn mat_mul(a: &M2, b: &M2) -> M2 {
    let mut c = [[0.0; 2]; 2];
    for i in 0..2 {
        for j in 0..2 {
            c[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j];
        }
    }
    c
}

fn mat_add(a: &M2, b: &M2) -> M2 {
    [
        [a[0][0] + b[0][0], a[0][1] + b[0][1]],
        [a[1][0] + b[1][0], a[1][1] + b[1][1]],
    ]
}

fn mat_close(a: &M2, b: &M2, tol: f64) -> bool {
    (0..2).all(|i| (0..2).all(|j| (a[i][j] - b[i][j]).abs() <= tol))
}

#[test]
fn dirichlet_matrix_of_fixed_and_roller_boundaries_is_c_section_3() {
    // C 3 (and the ibm module's doc): with phi the distance into the
    // material and n the inward normal (grad phi = n), a fixed boundary has
    // D = d I and dD/dx_j = d' n_j I; a roller D = I - (1 - d) n n^T and
    // dD/dx_j = d' n_j n n^T; several boundaries multiply, D = D_1 D_2 with
    // the product rule for the gradient. Written out here for a horizontal
    // boundary (material above) and one inclined at 60 degrees (material
    // to its lower right), at points inside both bands, inside one, beyond
    // them and outside the material; beyond a polyline's ends a boundary
    // does not act (D = I).
    use mpmlab_engine::ibm::{d_total, in_band};
    use mpmlab_engine::scene::DirichletKind;
    let delta = 0.5;
    let th = 60f64.to_radians();
    let t2 = [th.cos(), th.sin()];
    let line = |kind, a: [f64; 2], b: [f64; 2], side: f64| polyline("b", kind, vec![a, b], side);
    // Inward normals: (0, 1) for the base; (sin 60, -cos 60) for the
    // inclined line travelled from -3 t2 to 3 t2 with the material on its
    // right (side -1).
    let n1 = [0.0, 1.0];
    let n2 = [th.sin(), -th.cos()];
    let by_hand = |kind: DirichletKind, n: [f64; 2], phi: f64| -> (M2, [M2; 2]) {
        let (d, dd) = c16(phi, delta);
        match kind {
            DirichletKind::Fixed => (
                [[d, 0.0], [0.0, d]],
                [0, 1].map(|j| [[dd * n[j], 0.0], [0.0, dd * n[j]]]),
            ),
            DirichletKind::Roller => {
                let nn = [[n[0] * n[0], n[0] * n[1]], [n[1] * n[0], n[1] * n[1]]];
                (
                    [
                        [1.0 - (1.0 - d) * nn[0][0], -(1.0 - d) * nn[0][1]],
                        [-(1.0 - d) * nn[1][0], 1.0 - (1.0 - d) * nn[1][1]],
                    ],
                    [0, 1].map(|j| nn.map(|r| r.map(|v| dd * n[j] * v))),
                )
            }
        }
    };
    // Points: (x, phi_1, phi_2); phi_2 = x . n2 (the line passes the origin).
    let points: Vec<[f64; 2]> = vec![
        [0.5, 0.2],
        [0.9, 0.1],
        [1.6, 0.35],
        [0.5, 0.7],
        [2.0, -0.1],
        [0.3, 0.45],
    ];
    // Round-off of a few products of numbers of order 1/delta.
    let tol = 1e-14;
    for k1 in [DirichletKind::Fixed, DirichletKind::Roller] {
        for k2 in [DirichletKind::Fixed, DirichletKind::Roller] {
            let b1 = line(k1, [-3.0, 0.0], [3.0, 0.0], 1.0);
            let b2 = line(k2, [-3.0 * t2[0], -3.0 * t2[1]], [3.0 * t2[0], 3.0 * t2[1]], -1.0);
            for &x in &points {
                let (phi1, phi2) = (x[1], x[0] * n2[0] + x[1] * n2[1]);
                let (d1, g1) = by_hand(k1, n1, phi1);
                let (d2, g2) = by_hand(k2, n2, phi2);
                // Each alone.
                for (b, d, g) in [(&b1, d1, g1), (&b2, d2, g2)] {
                    let (dm, gm) = d_total(std::slice::from_ref(b), x, delta);
                    assert!(mat_close(&dm, &d, tol), "{k1:?}/{k2:?} at {x:?}: D {dm:?} vs {d:?}");
                    for j in 0..2 {
                        assert!(
                            mat_close(&gm[j], &g[j], tol / delta),
                            "{x:?}: dD/dx_{j} {:?} vs {:?}",
                            gm[j],
                            g[j]
                        );
                    }
                }
                // Both, in the order listed.
                let (dm, gm) = d_total(&[b1.clone(), b2.clone()], x, delta);
                let want = mat_mul(&d1, &d2);
                assert!(
                    mat_close(&dm, &want, tol),
                    "{k1:?}/{k2:?} at {x:?}: D {dm:?} vs {want:?}"
                );
                for j in 0..2 {
                    let wg = mat_add(&mat_mul(&g1[j], &d2), &mat_mul(&d1, &g2[j]));
                    assert!(
                        mat_close(&gm[j], &wg, tol / delta),
                        "{x:?}: dD/dx_{j} {:?} vs {wg:?}",
                        gm[j]
                    );
                }
                // In a band: 0 <= phi < delta for either.
                let inside = |p: f64| p < delta;
                assert_eq!(
                    in_band(&[b1.clone(), b2.clone()], x, delta),
                    inside(phi1) || inside(phi2),
                    "{x:?}"
                );
            }
            // Past the base's right end (x > 3), 0.1 above its line: the
            // base does not act there (and the inclined line is 3 away).
            let x = [3.5, 0.1];
            let (dm, gm) = d_total(&[b1.clone(), b2.clone()], x, delta);
            let id = [[1.0, 0.0], [0.0, 1.0]];
            assert!(
                mat_close(&dm, &id, 0.0) && gm.iter().all(|g| mat_close(g, &[[0.0; 2]; 2], 0.0)),
                "{dm:?} {gm:?}"
            );
            assert!(!in_band(std::slice::from_ref(&b1), x, delta));
        }
    }
}

#[test]
fn band_quadrature_integrates_the_strip_along_an_inclined_boundary() {
    // The band 0 <= phi <= delta along a boundary is a strip of length L
    // and width delta; its Gauss points (along each piece of the boundary
    // in a cell, 3 across) must integrate polynomials in the distance
    // along it (s) and across it (phi) exactly: int 1 = L delta,
    // int s = L^2 delta / 2, int phi = L delta^2 / 2, int phi^2 = L delta^3 / 3,
    // int s phi = L^2 delta^2 / 4, for a polyline of two inclined segments
    // crossing several cells, with the material on either side.
    use mpmlab_engine::scene::DirichletKind;
    let grid = Grid {
        origin: [-0.5, 0.25],
        h: 0.5,
        nx: 6,
        ny: 6,
    };
    let th = 30f64.to_radians();
    let (a, len) = ([0.1, 0.4], 2.2);
    let t = [th.cos(), th.sin()];
    let b = [a[0] + len * t[0], a[1] + len * t[1]];
    // Split into two collinear segments at an uneven point: the pieces of
    // both together tile the line.
    let m = [a[0] + 0.37 * len * t[0], a[1] + 0.37 * len * t[1]];
    for side in [1.0, -1.0] {
        let n = [-side * t[1], side * t[0]];
        let boundary = polyline("b", DirichletKind::Fixed, vec![a, m, b], side);
        for delta in [0.1, 0.02] {
            let pts = boundary.band_points(&grid, delta);
            // 2 Gauss points along each piece, 3 across; the line crosses
            // 6 grid lines and the two segments join between them: 8 pieces.
            assert_eq!(pts.len(), 8 * 6, "side {side}");
            let mut mom = [0.0; 5];
            for &(x, w) in &pts {
                let d = [x[0] - a[0], x[1] - a[1]];
                let (s, phi) = (d[0] * t[0] + d[1] * t[1], d[0] * n[0] + d[1] * n[1]);
                assert!(
                    (-1e-14..=len + 1e-14).contains(&s) && (0.0..=delta).contains(&phi),
                    "{x:?}"
                );
                for (k, f) in [1.0, s, phi, phi * phi, s * phi].into_iter().enumerate() {
                    mom[k] += w * f;
                }
            }
            let want = [
                len * delta,
                len * len * delta / 2.0,
                len * delta * delta / 2.0,
                len * delta.powi(3) / 3.0,
                len * len * delta * delta / 4.0,
            ];
            for k in 0..5 {
                // Exact quadrature: round-off of a sum of ~40 terms.
                assert!(
                    (mom[k] - want[k]).abs() < 1e-14 * want[k],
                    "side {side}, delta {delta}, moment {k}: {} vs {}",
                    mom[k],
                    want[k]
                );
            }
        }
    }
}

/// Closed form of the one-cell band problem (derivation in the test below):
/// the stiffness `E kappa` of the symmetric mode `(d_0, d_1)` with the band
/// of relative width `r = delta/h`.
fn band_kappa(r: f64) -> [[f64; 2]; 2] {
    let k00 = 4.0 / (3.0 * r) - 2.0 / 3.0 + 2.0 * r / 15.0;
    let k01 = -1.0 / 6.0 - 2.0 * r / 15.0;
    let k11 = 1.0 + 2.0 * r / 15.0;
    [[k00, k01], [k01, k11]]
}

#[test]
fn band_stiffness_of_one_cell_matches_the_closed_form() {
    // One cell [0, h]^2 on rollers at x = 0 and x = h (u_x = 0), its base
    // y = 0 fixed by the implicit boundary method, loaded by gravity on its
    // single point at the centre (so no point lies inside the band, and the
    // point integrates the plain part exactly). Widths 0.1 h and 0.25 h,
    // where the shape of d matters: at 0.5 h this one-point cell is not
    // usable (from delta/h ~ 0.35 the band's "- B^T C B" makes the
    // hourglass mode, which one point cannot see, indefinite), and with
    // more points per cell some lie inside the band, where the engine's
    // points take B_bar on top of the band integral (see the closing notes
    // of this work).
    // Plane strain with nu = 0: s_yy = E e_yy. With nodal u_y = d_0 on the
    // base and d_1 on the top (the load is symmetric), the trial field is
    // u_y = d(y) ((1 - y/h) d_0 + (y/h) d_1), so with t = y/delta, r = delta/h,
    // d = 2t - t^2 and d' = (2 - 2t)/delta, in the band
    //   psi_1' = (4t - 3t^2)/h,  psi_0' = ((2 - 2t)/r - (4t - 3t^2))/h
    // and above it psi_1' = -psi_0' = 1/h. The energy (E/2) h int (psi')^2 dy
    // gives E kappa with int (2-2t)^2 = 4/3, int (2-2t)(4t-3t^2) = 5/6,
    // int (4t-3t^2)^2 = 17/15:
    //   kappa_00 = 4/(3r) - 2/3 + 2r/15, kappa_01 = -1/6 - 2r/15,
    //   kappa_11 = 1 + 2r/15.
    // The load m g/4 on each node gives E kappa d = (m g / 2) (1, 1). The
    // point then moves by (d_0 + d_1)/2 and carries s_yy = E (d_1 - d_0)/h.
    // Any other shape of d (a linear ramp: kappa_11 = 1 + r/3) or a wrong
    // d' changes both by percents at these widths.
    let (h, e, rho, g) = (2.0, 1.0e6, 500.0, -10.0);
    for r in [0.1, 0.25] {
        let s = {
            let mut s = sim(&format!(
                r#"
[scene]
name = "band-1d"
[grid]
origin = [0.0, 0.0]
size = [{h}, {h}]
h = {h}
[[material]]
name = "m"
E = {e}
nu = 0.0
density = {rho}
plane = "strain"
[[body]]
name = "cell"
material = "m"
points_per_cell = 1
region = {{ shape = "rectangle", min = [0.0, 0.0], max = [{h}, {h}] }}
[[dirichlet]]
kind = "roller"
x = 0.0
[[dirichlet]]
kind = "roller"
x = {h}
[[ibm]]
name = "base"
kind = "fixed"
points = [[0.0, 0.0], [{h}, 0.0]]
[loads]
gravity = [0.0, {g}]
[analysis]
load_steps = 1
delta_over_h = {r}
tolerance = 1e-12
"#
            ));
            s.step().unwrap_or_else(|f| panic!("{f}"));
            s
        };
        let k = band_kappa(r);
        let f = rho * h * h * g / 2.0 / e;
        let det = k[0][0] * k[1][1] - k[0][1] * k[0][1];
        let d0 = f * (k[1][1] - k[0][1]) / det;
        let d1 = f * (k[0][0] - k[0][1]) / det;
        let pts = s.points();
        assert_eq!(pts.len(), 1);
        let u = pts.displacement(0);
        let syy = pts.stress[0][1];
        let (u_want, s_want) = (0.5 * (d0 + d1), e * (d1 - d0) / h);
        println!(
            "delta/h {r}: u_y {:.12e} (closed form {u_want:.12e}), s_yy {syy:.12e} ({s_want:.12e})",
            u[1]
        );
        // A 4-dof solve with cond ~1e2 and exact band quadrature (3 Gauss
        // points across integrate the degree-4 integrand exactly): round-off.
        assert!(
            (u[1] - u_want).abs() < 1e-12 * u_want.abs(),
            "r {r}: {} vs {u_want}",
            u[1]
        );
        assert!((syy - s_want).abs() < 1e-12 * s_want.abs(), "r {r}: {syy} vs {s_want}");
        assert!(u[0].abs() < 1e-15 && pts.stress[0][0].abs() < 1e-9 * s_want.abs());
    }
}

#[test]
fn band_integral_is_c18_for_any_width() {
    // The band's own integral, without points: its Gauss points (along and
    // 3 across) with B_bar = B1 + B2 of C (19)-(21), summed as
    // int_band B_bar^T C B_bar, for the base y = 0 of one cell [0, h]^2,
    // against the band part of the closed form above (t = y/delta,
    // r = delta/h, symmetric mode u_y = d_0 below, d_1 above, u_x = 0):
    //   E [[4/(3r) - 5/3 + 17r/15, 5/6 - 17r/15], [., 17r/15]].
    // Here delta/h = 0.5 is open to the test (no point is involved).
    use mpmlab_engine::ibm::{b_bar, d_total, grid_stencil};
    use mpmlab_engine::scene::DirichletKind;
    let (h, e) = (2.0, 1.0e6);
    let grid = Grid {
        origin: [0.0, 0.0],
        h,
        nx: 1,
        ny: 1,
    };
    let base = polyline("base", DirichletKind::Fixed, vec![[0.0, 0.0], [h, 0.0]], 1.0);
    // Plane strain, nu = 0: C = diag(E, E, E/2); only e_yy enters here.
    for r in [0.1, 0.25, 0.5] {
        let delta = r * h;
        let mut k = [[0.0; 2]; 2];
        let mut area = 0.0;
        for (x, w) in base.band_points(&grid, delta) {
            area += w;
            let owned = grid_stencil(&grid, x);
            let st = owned.view();
            let (d, g) = d_total(std::slice::from_ref(&base), x, delta);
            let ops = b_bar(st, &d, &g);
            // e_yy of the mode's two shapes: row 1 (yy), column 1 (u_y).
            let mut eyy = [0.0; 2];
            for (node, (b1, b2)) in st.nodes().zip(&ops) {
                let row = node / 2; // 0: base nodes, 1: top nodes (2 per row)
                eyy[row] += b1[1][1] + b2[1][1];
            }
            for a in 0..2 {
                for b in 0..2 {
                    k[a][b] += w * e * eyy[a] * eyy[b];
                }
            }
        }
        assert!((area - delta * h).abs() < 1e-14 * delta * h, "band area {area}");
        let want = [
            [
                4.0 / (3.0 * r) - 5.0 / 3.0 + 17.0 * r / 15.0,
                5.0 / 6.0 - 17.0 * r / 15.0,
            ],
            [5.0 / 6.0 - 17.0 * r / 15.0, 17.0 * r / 15.0],
        ];
        for a in 0..2 {
            for b in 0..2 {
                // Exact quadrature (degree 4 across, 2 along): round-off of
                // the largest entry, E 4/(3r).
                assert!(
                    (k[a][b] - e * want[a][b]).abs() < 1e-13 * e / r,
                    "delta/h {r}: K[{a}][{b}] = {} vs {}",
                    k[a][b],
                    e * want[a][b]
                );
            }
        }
    }
}

// ---------------------------------------------------------------------------
// B-spline traction (B 3.4)
// ---------------------------------------------------------------------------

#[test]
fn band_deformation_gradient_is_the_derivative_of_the_motion() {
    // Under finite deformation a point in a band moves by
    // u(x) = D(x) S(x) d + S(x) d^a (C section 3's displacement with the
    // prescribed field, `IbmStep::point_increment`), so its increment's
    // deformation gradient
    // must be dF = I + grad u: the band's operators G_k[l] carry D's own
    // gradient, and grad(S d^a) the prescribed field's. Checked here by
    // central differences of the motion, with nodal increments d and d^a
    // that have both components everywhere, at points across a fixed and a
    // roller boundary inclined at 30 degrees and at a corner of two, for
    // the standard basis and GIMP, at delta/h = 0.25 and 0.5 (where D is
    // far from 1).
    use mpmlab_engine::basis::{stencil, BasisKind};
    use mpmlab_engine::bulk::band_gradient;
    use mpmlab_engine::ibm::{in_band, IbmStep};
    use mpmlab_engine::scene::DirichletKind;
    let h = 0.5;
    let grid = Grid {
        origin: [-2.0, -2.0],
        h,
        nx: 8,
        ny: 8,
    };
    let th = 30f64.to_radians();
    let t = [th.cos(), th.sin()];
    let line = |kind, a: [f64; 2], b: [f64; 2]| polyline("b", kind, vec![a, b], 1.0);
    let inclined = |kind| line(kind, [-1.9 * t[0], -1.9 * t[1]], [1.9 * t[0], 1.9 * t[1]]);
    // A second boundary at right angles to the first, through the origin.
    let crossing = |kind| line(kind, [1.9 * t[1], -1.9 * t[0]], [-1.9 * t[1], 1.9 * t[0]]);
    // Increments of a few per cent of h, different at every node.
    let nodes = grid.num_nodes();
    let d: Vec<[f64; 2]> = (0..nodes)
        .map(|n| {
            let n = n as f64;
            [0.03 * h * (1.3 * n + 0.2).sin(), 0.02 * h * (0.7 * n).cos()]
        })
        .collect();
    let da: Vec<[f64; 2]> = (0..nodes)
        .map(|n| {
            let n = n as f64;
            [0.04 * h * (1.1 * n).cos(), -0.025 * h * (0.9 * n + 1.0).sin()]
        })
        .collect();
    // Points at distance phi delta from the inclined line, s along it.
    let inward = |phi: f64, s: f64| [s * t[0] - phi * t[1], s * t[1] + phi * t[0]];
    let eps = 1e-6 * h;
    let mut checked = 0;
    for r in [0.25, 0.5] {
        let delta = r * h;
        for set in [
            vec![inclined(DirichletKind::Fixed)],
            vec![inclined(DirichletKind::Roller)],
            vec![inclined(DirichletKind::Fixed), crossing(DirichletKind::Roller)],
        ] {
            let step = IbmStep {
                bs: &set,
                delta,
                da: da.clone(),
                in_band: vec![],
                fit_regularisation: 0.0,
            };
            for (phi, s) in [(0.2, 0.37), (0.55, 0.41), (0.8, 0.93), (0.35, 1.27)] {
                let x = inward(phi * delta, s);
                assert!(in_band(&set, x, delta), "{x:?} lies in a band");
                for (kind, lp) in [(BasisKind::Standard, [0.0; 2]), (BasisKind::Gimp, [0.2 * h; 2])] {
                    let at = |x: [f64; 2]| stencil(&grid, kind, x, lp);
                    let owned = at(x);
                    let st = owned.view();
                    let ops = step.gradient_ops(st, x).expect("a point in a band has band operators");
                    let df = band_gradient(st, &ops, &d, &da);
                    for j in 0..2 {
                        let mut xp = x;
                        let mut xm = x;
                        xp[j] += eps;
                        xm[j] -= eps;
                        let (sp, sm) = (at(xp), at(xm));
                        // Both sides see the same nodes (no grid line
                        // within eps of the points chosen).
                        assert_eq!(sp.view().key(), sm.view().key(), "{x:?}");
                        let up = step.point_increment(sp.view(), xp, &d);
                        let um = step.point_increment(sm.view(), xm, &d);
                        for i in 0..2 {
                            let fd = if i == j { 1.0 } else { 0.0 } + (up[i] - um[i]) / (2.0 * eps);
                            // Central differences: truncation eps^2 |u'''|
                            // with u''' of order |d| / delta^3 (D is
                            // quadratic in phi): about 1e-12 here; round-off
                            // 1e-16 |u| / eps, about 1e-11. The increments'
                            // gradients are of order 0.1, so 1e-8 separates
                            // any wrong term.
                            assert!(
                                (df[(i, j)] - fd).abs() < 1e-8,
                                "{kind:?} delta/h {r}, {} boundaries, at {x:?}: dF[{i}][{j}] = {} vs {fd}",
                                set.len(),
                                df[(i, j)]
                            );
                        }
                    }
                    checked += 1;
                }
            }
        }
    }
    assert_eq!(checked, 2 * 3 * 4 * 2);
}

/// `int N_v(x(t)) dt` over `t in [a, b]` for a smooth path inside one cell
/// sub-interval, composite Simpson with `n` (even) panels.
fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
    let hh = (b - a) / n as f64;
    let mut s = f(a) + f(b);
    for i in 1..n {
        s += if i % 2 == 1 { 4.0 } else { 2.0 } * f(a + i as f64 * hh);
    }
    s * hh / 3.0
}

fn node_hat(grid: &Grid, n: usize, x: [f64; 2]) -> f64 {
    let (i, j) = (n % (grid.nx + 1), n / (grid.nx + 1));
    hat(x[0] - grid.origin[0] - i as f64 * grid.h, grid.h) * hat(x[1] - grid.origin[1] - j as f64 * grid.h, grid.h)
}

fn summed(forces: &[(usize, [f64; 2])], n: usize) -> Vec<[f64; 2]> {
    let mut out = vec![[0.0; 2]; n];
    for (k, f) in forces {
        out[*k][0] += f[0];
        out[*k][1] += f[1];
    }
    out
}

#[test]
fn straight_boundary_traction_is_the_exact_line_integral() {
    // B (13)-(17) on a straight boundary through collinear points: the
    // spline is the line itself, and the nodal forces are t int N_v ds,
    // exact with Gauss points per piece (N_v along a line is quadratic in
    // each cell). Reference: Simpson per piece between the crossings of the
    // grid lines (exact for quadratics).
    let grid = Grid {
        origin: [0.0, 0.0],
        h: 1.0,
        nx: 3,
        ny: 2,
    };
    let (a, b) = ([0.3, 0.2], [2.7, 1.4]);
    let q: Vec<[f64; 2]> = (0..5)
        .map(|k| {
            let t = k as f64 / 4.0;
            [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
        })
        .collect();
    let spline = BSpline::interpolate(&q, false, &[false; 5]).unwrap();
    let t = [3.0, -7.0];
    let boundary = Boundary {
        name: "line".into(),
        points: (0..5).collect(),
        closed: false,
        corners: vec![false; 5],
        gauss_points: 3,
        traction: Some(Traction::Vector(t)),
        outward: 1.0,
    };
    let (forces, report) = traction_forces(&boundary, &spline, &grid, None, &|_| true, 1.0);
    let got = summed(&forces, grid.num_nodes());
    // Crossings: x = 1 at t = 0.7/2.4, x = 2 at 1.7/2.4, y = 1 at 0.8/1.2.
    let mut breaks = [0.0, 0.7 / 2.4, 1.7 / 2.4, 0.8 / 1.2, 1.0];
    breaks.sort_by(f64::total_cmp);
    let len = (2.4f64).hypot(1.2);
    for n in 0..grid.num_nodes() {
        let path = |s: f64| node_hat(&grid, n, [a[0] + s * 2.4, a[1] + s * 1.2]);
        let w: f64 = breaks.windows(2).map(|p| simpson(path, p[0], p[1], 2)).sum::<f64>() * len;
        for c in 0..2 {
            assert!(
                (got[n][c] - w * t[c]).abs() < 1e-13 * len * 7.0,
                "node {n}: {:?} vs {}",
                got[n],
                w * t[c]
            );
        }
    }
    // Resultant: t times the length.
    assert!((report.resultant[0] - t[0] * len).abs() < 1e-13 * len * 7.0);
    assert!((report.resultant[1] - t[1] * len).abs() < 1e-13 * len * 7.0);
    // Within a load step the report scales with the load factor and the
    // forces stay at factor 1; the share on a node no point touches is
    // lost (reported, not applied).
    let gone = (0..grid.num_nodes())
        .find(|&n| got[n][0] != 0.0)
        .expect("the line loads some node");
    let lambda = 0.35;
    let (partial, report) = traction_forces(&boundary, &spline, &grid, None, &|n| n != gone, lambda);
    let applied = summed(&partial, grid.num_nodes());
    for n in 0..grid.num_nodes() {
        let expected = if n == gone { [0.0; 2] } else { got[n] };
        assert_eq!(applied[n], expected, "node {n}");
    }
    for c in 0..2 {
        assert!((report.resultant[c] - lambda * t[c] * len).abs() < 1e-13 * len * 7.0);
    }
    let lost = lambda * got[gone][0].hypot(got[gone][1]);
    assert!((report.lost - lost).abs() < 1e-15 * lost, "{} vs {lost}", report.lost);
}

/// Nodal forces of a pressure `p` on a circle (centre `c`, radius `rad`)
/// through `k` points, from the spline, and the exact ones on the circle.
fn circle_forces(grid: &Grid, c: [f64; 2], rad: f64, k: usize, p: f64) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    use std::f64::consts::TAU;
    let q: Vec<[f64; 2]> = (0..k)
        .map(|i| {
            let th = TAU * i as f64 / k as f64;
            [c[0] + rad * th.cos(), c[1] + rad * th.sin()]
        })
        .collect();
    let spline = BSpline::interpolate(&q, true, &vec![false; k]).unwrap();
    let boundary = Boundary {
        name: "circle".into(),
        points: (0..k).collect(),
        closed: true,
        corners: vec![false; k],
        gauss_points: 4,
        traction: Some(Traction::Pressure(p)),
        outward: 1.0,
    };
    let (forces, _) = traction_forces(&boundary, &spline, &grid.clone(), None, &|_| true, 1.0);
    let got = summed(&forces, grid.num_nodes());
    // Exact: f_v = -p int N_v(x(th)) n(th) R dth, split where the circle
    // crosses grid lines (N_v is smooth between), composite Simpson with
    // 400 panels per piece (error ~1e-12 relative).
    let mut breaks = vec![0.0, TAU];
    for d in 0..2 {
        for line in 0..=[grid.nx, grid.ny][d] {
            let v = (grid.origin[d] + line as f64 * grid.h - c[d]) / rad;
            if v.abs() < 1.0 {
                let base = if d == 0 { v.acos() } else { v.asin() };
                for th in [
                    base,
                    if d == 0 {
                        TAU - base
                    } else {
                        std::f64::consts::PI - base
                    },
                ] {
                    breaks.push(th.rem_euclid(TAU));
                }
            }
        }
    }
    breaks.sort_by(f64::total_cmp);
    let mut want = vec![[0.0; 2]; grid.num_nodes()];
    for (n, w) in want.iter_mut().enumerate() {
        for comp in 0..2 {
            let f = |th: f64| {
                let x = [c[0] + rad * th.cos(), c[1] + rad * th.sin()];
                let nrm = [th.cos(), th.sin()];
                -p * node_hat(grid, n, x) * nrm[comp] * rad
            };
            w[comp] = breaks.windows(2).map(|b| simpson(f, b[0], b[1], 400)).sum();
        }
    }
    (got, want)
}

#[test]
fn circular_boundary_traction_converges_to_the_exact_line_integral() {
    // B 3.4 on a circle of radius 1.3 h, off the grid's lines: the spline
    // through k points on the circle carries the pressure's nodal forces;
    // they differ from the circle's exact line integrals only by the
    // spline's geometric error.
    let grid = Grid {
        origin: [0.0, 0.0],
        h: 1.0,
        nx: 4,
        ny: 4,
    };
    let (c, rad, p) = ([2.05, 1.95], 1.3, 5.0);
    let mut errs = Vec::new();
    for k in [12, 24, 48] {
        let (got, want) = circle_forces(&grid, c, rad, k, p);
        let err = got
            .iter()
            .zip(&want)
            .map(|(g, w)| (g[0] - w[0]).abs().max((g[1] - w[1]).abs()))
            .fold(0.0, f64::max);
        // Scale: the largest exact nodal force.
        let scale = want.iter().map(|w| w[0].abs().max(w[1].abs())).fold(0.0, f64::max);
        // Closed curve: the pressure's resultant vanishes exactly (sum_v N_v
        // = 1 and n |C'| is C' turned, whose integral round the curve is 0).
        let res = got.iter().fold([0.0, 0.0], |a, g| [a[0] + g[0], a[1] + g[1]]);
        assert!(res[0].abs() < 1e-13 * scale && res[1].abs() < 1e-13 * scale, "{res:?}");
        println!("k = {k}: largest nodal force error {:.3e} of {scale:.3e}", err);
        errs.push(err / scale);
    }
    let rates: Vec<f64> = errs.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
    println!("relative errors {errs:?}, rates {rates:?}");
    // The local cubic's geometric error on a circle is fourth order in the
    // point spacing (measured 1.7e-4, 1.1e-5, 6.8e-7 relative: rates 3.93,
    // 4.00), and so is the nodal force error: rate 4 within 0.15 (the
    // coarsest pair is not yet asymptotic), and below 1e-6 at 48 points.
    assert!(errs[2] < 1e-6, "{errs:?}");
    for r in &rates {
        assert!((r - 4.0).abs() < 0.15, "{rates:?}");
    }
}

// ---------------------------------------------------------------------------
// Hencky elasticity with von Mises plasticity (G 2.1)
// ---------------------------------------------------------------------------

fn diag3(a: f64, b: f64, c: f64) -> Matrix3<f64> {
    Matrix3::from_diagonal(&nalgebra::Vector3::new(a, b, c))
}

fn close3(a: &Matrix3<f64>, b: &Matrix3<f64>, tol: f64) -> bool {
    (a - b).abs().max() <= tol
}

#[test]
fn return_map_matches_closed_form_pure_shear_and_uniaxial_strain() {
    let (e, nu) = (12.0e6, 0.3);
    let (k, mu) = (e / (3.0 * (1.0 - 2.0 * nu)), e / (2.0 * (1.0 + nu)));
    let lam = 1.05f64;
    let ln = lam.ln();
    let s2 = 2f64.sqrt();
    let i3 = Matrix3::identity();

    // Pure shear dF = diag(lam, 1/lam) from b_n = I: Hencky strains
    // (ln lam, -ln lam, 0), no volume change, rho_tr = 2 sqrt(2) mu ln lam.
    let rho_tr = 2.0 * s2 * mu * ln;
    let elastic = Hencky {
        e,
        nu,
        yield_stress: Some(1.01 * rho_tr),
    };
    let f = Matrix2::new(lam, 0.0, 0.0, 1.0 / lam);
    let r = elastic.respond(&f, &i3);
    // Round-off of logs and an eigen-decomposition: 1e-12 of the stress.
    let tol = 1e-12 * rho_tr;
    assert!(!r.yielding && r.dissipation == 0.0);
    assert!(
        close3(&r.tau, &diag3(2.0 * mu * ln, -2.0 * mu * ln, 0.0), tol),
        "{}",
        r.tau
    );
    assert!(close3(&r.b_e, &diag3(lam * lam, 1.0 / (lam * lam), 1.0), 1e-14));
    // P = tau dF^-T.
    assert!((r.p[(0, 0)] - 2.0 * mu * ln / lam).abs() < tol && (r.p[(1, 1)] + 2.0 * mu * ln * lam).abs() < tol);

    // Yielding at rho_y = rho_tr / 2: radial return to the surface,
    // tau = (rho_y/sqrt 2) (1, -1, 0), elastic strains s/(2 mu), and the
    // dissipation tau : (e_tr - e_e) = sqrt(2) rho_y ln lam - rho_y^2/(2 mu).
    let ry = 0.5 * rho_tr;
    let plastic = Hencky {
        e,
        nu,
        yield_stress: Some(ry),
    };
    let r = plastic.respond(&f, &i3);
    let ee = ry / (2.0 * s2 * mu);
    assert!(r.yielding);
    assert!(close3(&r.tau, &diag3(ry / s2, -ry / s2, 0.0), tol), "{}", r.tau);
    assert!(
        close3(&r.b_e, &diag3((2.0 * ee).exp(), (-2.0 * ee).exp(), 1.0), 1e-14),
        "{}",
        r.b_e
    );
    let diss = s2 * ry * ln - ry * ry / (2.0 * mu);
    assert!(
        (r.dissipation - diss).abs() < 1e-10 * diss,
        "{} vs {diss}",
        r.dissipation
    );
    // A second increment of the same shear from the returned state stays on
    // the surface (perfect plasticity): the same stress.
    let r2 = plastic.respond(&f, &r.b_e);
    assert!(close3(&r2.tau, &r.tau, tol), "{}", r2.tau);
    // Rotated: dF = R diag(lam, 1/lam) gives tau = R tau_0 R^T (objectivity).
    let th = 0.3f64;
    let rot = Matrix2::new(th.cos(), -th.sin(), th.sin(), th.cos());
    let rr = plastic.respond(&(rot * f), &i3);
    let r3 = Matrix3::new(th.cos(), -th.sin(), 0.0, th.sin(), th.cos(), 0.0, 0.0, 0.0, 1.0);
    assert!(close3(&rr.tau, &(r3 * r.tau * r3.transpose()), tol), "{}", rr.tau);

    // Uniaxial strain dF = diag(lam, 1): e = (ln lam, 0, 0), volumetric
    // ln lam, deviator ln lam (2, -1, -1)/3, rho_tr = 2 mu ln lam sqrt(6)/3.
    let f = Matrix2::new(lam, 0.0, 0.0, 1.0);
    let r = Hencky {
        e,
        nu,
        yield_stress: None,
    }
    .respond(&f, &i3);
    let lame = k - 2.0 * mu / 3.0;
    let t_ax = (k + 4.0 * mu / 3.0) * ln;
    let tol = 1e-12 * t_ax;
    assert!(close3(&r.tau, &diag3(t_ax, lame * ln, lame * ln), tol), "{}", r.tau);
    let rho_tr = 2.0 * mu * ln * 6f64.sqrt() / 3.0;
    let ry = 0.4 * rho_tr;
    let r = Hencky {
        e,
        nu,
        yield_stress: Some(ry),
    }
    .respond(&f, &i3);
    // The mean stress is untouched; the deviator is scaled to rho_y along
    // n = (2, -1, -1)/sqrt 6.
    let s6 = 6f64.sqrt();
    let want = diag3(k * ln + 2.0 * ry / s6, k * ln - ry / s6, k * ln - ry / s6);
    assert!(r.yielding && close3(&r.tau, &want, tol), "{}\n{want}", r.tau);
}

#[test]
fn roller_constraint_weights_are_exact_line_integrals() {
    // The reaction split's weights `W_b(n) = int_Gamma_b N_n P_b ds`
    // (`P_b = n n^T` for a roller, `I` for a fixed boundary), against the
    // same integral by a 20,000-point midpoint rule along the boundary (N_n
    // the grid's bilinear hat, written out here): an inclined polyline
    // crossing several cells, and straight boundaries lying on a vertical
    // and on a horizontal grid line, the material on either side. Along a
    // straight piece inside a cell N_n is quadratic, so the engine's 3
    // Gauss points per piece are exact; the midpoint rule's error is below
    // 1e-8 of the weights here. The engine moves each Gauss point 1e-9 h
    // into the material (to pick the material's cell for a point on a grid
    // line), which gives the nodes one cell inside a grid-aligned boundary
    // weights of that order where the exact ones are 0: within the
    // tolerance too.
    //
    // The weights are lengths: the same problem scaled by 2^-10 (a grid in
    // metres rather than millimetres; a power of two, so every coordinate
    // scales exactly) must give the weights scaled by 2^-10, to the same
    // relative bound. A nudge that did not scale with h would move every
    // Gauss point by a fixed fraction of a smaller cell.
    use mpmlab_engine::scene::DirichletKind;
    for scale in [1.0, 1.0 / 1024.0] {
        let grid = Grid {
            origin: [-0.5 * scale, 0.25 * scale],
            h: 0.5 * scale,
            nx: 6,
            ny: 6,
        };
        let hat = |x: [f64; 2], node: usize| {
            let p = grid.node_position(node);
            let f = |d: f64| (1.0 - d.abs() / grid.h).max(0.0);
            f(x[0] - p[0]) * f(x[1] - p[1])
        };
        let at = |pts: &[[f64; 2]]| pts.iter().map(|p| [p[0] * scale, p[1] * scale]).collect::<Vec<_>>();
        let inclined = at(&[[0.1, 0.4], [0.9, 0.75], [1.7, 1.6]]);
        // On the grid line x = 1.0 (cells 3 | 4) and on y = 1.25 (rows 2 | 3).
        let vertical = at(&[[1.0, 0.6], [1.0, 2.1]]);
        let horizontal = at(&[[0.1, 1.25], [1.7, 1.25]]);
        for (points, side) in [
            (inclined, 1.0),
            (vertical.clone(), 1.0),
            (vertical, -1.0),
            (horizontal.clone(), 1.0),
            (horizontal, -1.0),
        ] {
            for kind in [DirichletKind::Roller, DirichletKind::Fixed] {
                let boundary = polyline("b", kind, points.clone(), side);
                let weights = boundary.constraint_weights(&grid);
                let mut reference = vec![[[0.0; 2]; 2]; grid.num_nodes()];
                for piece in points.windows(2) {
                    let (p, q) = (piece[0], piece[1]);
                    let (d, len) = ([q[0] - p[0], q[1] - p[1]], (q[0] - p[0]).hypot(q[1] - p[1]));
                    let t = [d[0] / len, d[1] / len];
                    let nrm = [-t[1], t[0]];
                    let proj = match kind {
                        DirichletKind::Roller => {
                            [[nrm[0] * nrm[0], nrm[0] * nrm[1]], [nrm[1] * nrm[0], nrm[1] * nrm[1]]]
                        }
                        DirichletKind::Fixed => [[1.0, 0.0], [0.0, 1.0]],
                    };
                    let k = 10_000;
                    for i in 0..k {
                        let s = (i as f64 + 0.5) / k as f64;
                        let x = [p[0] + s * d[0], p[1] + s * d[1]];
                        for (node, w) in reference.iter_mut().enumerate() {
                            let nk = hat(x, node);
                            if nk > 0.0 {
                                for r in 0..2 {
                                    for c in 0..2 {
                                        w[r][c] += nk * len / k as f64 * proj[r][c];
                                    }
                                }
                            }
                        }
                    }
                }
                let total: f64 = reference.iter().map(|w| w[0][0] + w[1][1]).sum();
                assert!(total > 0.5 * scale, "{points:?} {kind:?}: the line carries weight");
                for (node, w) in reference.iter().enumerate() {
                    let got = weights.get(&node).copied().unwrap_or([[0.0; 2]; 2]);
                    for r in 0..2 {
                        for c in 0..2 {
                            assert!(
                                (got[r][c] - w[r][c]).abs() < 1e-8 * total,
                                "scale {scale}, {points:?} side {side} {kind:?} node {node} [{r}][{c}]: {} vs {}",
                                got[r][c],
                                w[r][c]
                            );
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn a_tie_between_points_around_a_band_point_goes_to_the_cell_first_in_order() {
    // A band point in the empty middle cell of a 3 x 3 grid (h = 1), with
    // two points one cell away on either side, at exactly the same
    // distance (1, exact in binary). The nearest point's C is taken; on a
    // tie, that of the cell first in the grid's numbering (cell j nx + i:
    // the lower row, then the left column), so the band's material does
    // not depend on how the search happens to walk the cells around.
    use mpmlab_engine::ibm::BandMaterial;
    let grid = Grid {
        origin: [0.0, 0.0],
        h: 1.0,
        nx: 3,
        ny: 3,
    };
    let c = |k: f64| [[k, 0.0, 0.0], [0.0, k, 0.0], [0.0, 0.0, k]];
    for (xs, want, why) in [
        ([[1.5, 2.5], [1.5, 0.5]], 2.0, "above and below: the row below"),
        ([[2.5, 1.5], [0.5, 1.5]], 2.0, "right and left: the column to the left"),
    ] {
        let material = BandMaterial::new(&grid, &xs, &[1.0, 1.0], &|p| c(1.0 + p as f64));
        assert_eq!(material.at(&grid, [1.5, 1.5]), c(want), "{xs:?}, {why}");
    }
}

#[test]
fn the_band_takes_the_elasticity_of_the_nearest_point_around_it() {
    // Four points on a 6 x 3 grid (h = 1; more columns than rows), each
    // with its own C (the identity times 1 to 4) and volumes 1, 1, 2, 1.
    // A band point takes the C of the nearest material point in its own
    // cell, else in the 3 x 3 cells around it (those inside the grid),
    // else the volume-weighted mean (1 + 2 + 6 + 4) / 5 = 2.6.
    use mpmlab_engine::ibm::BandMaterial;
    let grid = Grid {
        origin: [0.0, 0.0],
        h: 1.0,
        nx: 6,
        ny: 3,
    };
    let xs = [[0.5, 0.5], [2.5, 1.5], [3.6, 2.4], [1.95, 1.5]];
    let vol = [1.0, 1.0, 2.0, 1.0];
    let c = |k: f64| [[k, 0.0, 0.0], [0.0, k, 0.0], [0.0, 0.0, k]];
    let material = BandMaterial::new(&grid, &xs, &vol, &|p| c(1.0 + p as f64));
    for (x, want, why) in [
        ([0.2, 0.9], 1.0, "its own cell (0, 0)"),
        (
            [2.05, 1.5],
            2.0,
            "its own cell (2, 1), though the point of (1, 1) is nearer",
        ),
        (
            [2.5, 0.4],
            2.0,
            "cell (2, 0) is empty: the point of (2, 1), the row above",
        ),
        (
            [3.5, 0.5],
            2.0,
            "cell (3, 0) is empty: the point of (2, 1), the column before",
        ),
        (
            [4.5, 1.8],
            3.0,
            "cell (4, 1) is empty: the point of (3, 2), the only one around",
        ),
        (
            [2.5, 2.5],
            2.0,
            "cell (2, 2) is empty: the point of (2, 1), the row below",
        ),
        (
            [1.2, 0.5],
            1.0,
            "cell (1, 0) is empty: the point of (0, 0) in its own row, \
             nearer than that of (1, 1) above",
        ),
        ([5.5, 0.5], 2.6, "cell (5, 0): no point within a cell, the mean"),
        ([-0.5, 1.0], 2.6, "outside the grid: the mean"),
    ] {
        assert_eq!(material.at(&grid, x), c(want), "{x:?}, {why}");
    }
}

#[test]
fn the_nearest_point_is_nearest_in_both_directions() {
    // Two points in one cell (h = 1), 0.8 apart along y, then along x,
    // each with its own C (the identity times 1 and 2): a band point
    // 0.1 from either takes that one's C. The distance is Euclidean in
    // both coordinates: one that dropped or distorted either coordinate's
    // difference, or compared every pair as equal (the first found), picks
    // the far point for one of the four band points.
    use mpmlab_engine::ibm::BandMaterial;
    let grid = Grid {
        origin: [0.0, 0.0],
        h: 1.0,
        nx: 1,
        ny: 1,
    };
    let c = |k: f64| [[k, 0.0, 0.0], [0.0, k, 0.0], [0.0, 0.0, k]];
    for (xs, near_first, near_second) in [
        ([[0.5, 0.1], [0.5, 0.9]], [0.5, 0.2], [0.5, 0.8]),
        ([[0.1, 0.5], [0.9, 0.5]], [0.2, 0.5], [0.8, 0.5]),
    ] {
        let material = BandMaterial::new(&grid, &xs, &[1.0, 1.0], &|p| c(1.0 + p as f64));
        assert_eq!(material.at(&grid, near_first), c(1.0), "{xs:?} at {near_first:?}");
        assert_eq!(material.at(&grid, near_second), c(2.0), "{xs:?} at {near_second:?}");
    }
}

#[test]
fn the_band_looks_for_points_only_in_cells_of_the_grid() {
    // A band point in the last column (cell (3, 0) of a 4 x 2 grid) with
    // no point in its cell or the cells around it takes the points' mean
    // elasticity (volume-weighted: (1 + 2)/2 here). Its ring reaches past
    // the grid's right edge, where a column index of 4 would read as the
    // first cell of the next row, (0, 1), which holds a point: only the
    // grid's own cells may be searched.
    use mpmlab_engine::ibm::BandMaterial;
    let grid = Grid {
        origin: [0.0, 0.0],
        h: 1.0,
        nx: 4,
        ny: 2,
    };
    let c = |k: f64| [[k, 0.0, 0.0], [0.0, k, 0.0], [0.0, 0.0, k]];
    let xs = [[0.5, 1.5], [0.5, 0.5]];
    let material = BandMaterial::new(&grid, &xs, &[1.0, 1.0], &|p| c(1.0 + p as f64));
    assert_eq!(material.at(&grid, [3.5, 0.5]), c(1.5));
}

#[test]
fn a_partly_filled_cell_on_the_grids_edge_is_cut() {
    // Every cell of a 3 x 3 grid active, so no cell has an inactive
    // neighbour. A cell on the grid's edge still counts as cut by the
    // material's boundary when it is partly filled (`ghost::faces`, fill
    // below 0.9: a body leaving the grid's edge); full, it does not (a body
    // resting on the grid's boundary). With every cell full there is no
    // ghost face; with the left middle cell (0, 1) half full, its three
    // faces with active cells (below, right, above) are ghost faces.
    let grid = Grid {
        origin: [0.0, 0.0],
        h: 1.0,
        nx: 3,
        ny: 3,
    };
    let active: Vec<usize> = (0..9).collect();
    let mut fill = vec![1.0; grid.num_cells()];
    assert_eq!(ghost::faces(&grid, &active, &fill).len(), 0);
    fill[3] = 0.5;
    assert_eq!(ghost::faces(&grid, &active, &fill).len(), 3);
}
