//! With points at the 2x2 Gauss points of every cell and Gauss weights as
//! volumes, one small-strain step is a bilinear finite-element solve. This
//! test writes that finite-element solve independently (its own shape
//! functions, quadrature, assembly and dense solver) and compares.

use crate::common;
use common::{run_all, sim_with};

const H: f64 = 0.25;
const NX: usize = 8; // cells along the beam [0, 2]
const NY: usize = 2; // cells across [0.25, 0.75]
const Y0: f64 = 0.25;
const E: f64 = 2.0e9;
const NU: f64 = 0.25;
const RHO_G: f64 = 7800.0 * 9.81;

fn node(i: usize, j: usize) -> usize {
    j * (NX + 1) + i
}

/// Bilinear shape functions and x/y derivatives on cell (ci, cj) at (x, y).
fn shape(ci: usize, cj: usize, x: f64, y: f64) -> ([usize; 4], [f64; 4], [[f64; 2]; 4]) {
    let (xi, eta) = ((x - ci as f64 * H) / H, (y - Y0 - cj as f64 * H) / H);
    let nodes = [node(ci, cj), node(ci + 1, cj), node(ci + 1, cj + 1), node(ci, cj + 1)];
    let n = [(1.0 - xi) * (1.0 - eta), xi * (1.0 - eta), xi * eta, (1.0 - xi) * eta];
    let d = [
        [-(1.0 - eta) / H, -(1.0 - xi) / H],
        [(1.0 - eta) / H, -xi / H],
        [eta / H, xi / H],
        [-eta / H, (1.0 - xi) / H],
    ];
    (nodes, n, d)
}

fn dmat() -> [[f64; 3]; 3] {
    let c = E / (1.0 - NU * NU);
    [[c, c * NU, 0.0], [c * NU, c, 0.0], [0.0, 0.0, c * (1.0 - NU) / 2.0]]
}

/// Gaussian elimination with partial pivoting.
fn solve_dense(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for k in 0..n {
        let p = (k..n).max_by(|&i, &j| a[i][k].abs().total_cmp(&a[j][k].abs())).unwrap();
        a.swap(k, p);
        b.swap(k, p);
        for i in k + 1..n {
            let f = a[i][k] / a[k][k];
            for j in k..n {
                a[i][j] -= f * a[k][j];
            }
            b[i] -= f * b[k];
        }
    }
    let mut x = vec![0.0; n];
    for k in (0..n).rev() {
        x[k] = (b[k] - (k + 1..n).map(|j| a[k][j] * x[j]).sum::<f64>()) / a[k][k];
    }
    x
}

#[test]
fn gauss_points_reproduce_bilinear_fe() {
    let g = 1.0 / 3f64.sqrt();
    let gauss = [0.5 * H * (1.0 - g), 0.5 * H * (1.0 + g)];
    let nn = (NX + 1) * (NY + 1);
    let mut k = vec![vec![0.0; 2 * nn]; 2 * nn];
    let mut f = vec![0.0; 2 * nn];
    let d = dmat();
    for cj in 0..NY {
        for ci in 0..NX {
            for gy in gauss {
                for gx in gauss {
                    let (x, y) = (ci as f64 * H + gx, Y0 + cj as f64 * H + gy);
                    let (nodes, n, dn) = shape(ci, cj, x, y);
                    let w = H * H / 4.0; // Gauss weight 1 x 1 times the Jacobian
                    for a in 0..4 {
                        f[2 * nodes[a] + 1] -= n[a] * RHO_G * w;
                        for b in 0..4 {
                            let ba = [[dn[a][0], 0.0], [0.0, dn[a][1]], [dn[a][1], dn[a][0]]];
                            let bb = [[dn[b][0], 0.0], [0.0, dn[b][1]], [dn[b][1], dn[b][0]]];
                            for i in 0..2 {
                                for j in 0..2 {
                                    let mut s = 0.0;
                                    for p in 0..3 {
                                        for q in 0..3 {
                                            s += ba[p][i] * d[p][q] * bb[q][j];
                                        }
                                    }
                                    k[2 * nodes[a] + i][2 * nodes[b] + j] += s * w;
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    // Tip load on the Gauss point nearest (2.0, 0.45): last cell column,
    // lower cell row's upper Gauss point row.
    let (lx, ly) = ((NX - 1) as f64 * H + gauss[1], Y0 + gauss[1]);
    let (nodes, n, _) = shape(NX - 1, 0, lx, ly);
    for a in 0..4 {
        f[2 * nodes[a] + 1] += n[a] * -1.0e4;
    }
    // Fix the nodes on x = 0.
    let free: Vec<usize> = (0..2 * nn).filter(|&dof| (dof / 2) % (NX + 1) != 0).collect();
    let kr = free.iter().map(|&i| free.iter().map(|&j| k[i][j]).collect()).collect();
    let fr = free.iter().map(|&i| f[i]).collect();
    let ur = solve_dense(kr, fr);
    let mut u = vec![0.0; 2 * nn];
    for (i, &dof) in free.iter().enumerate() {
        u[dof] = ur[i];
    }

    let mut sim = sim_with("fe-equivalence", |_| {});
    run_all(&mut sim);
    let pts = sim.points();
    assert_eq!(pts.len(), 4 * NX * NY);
    let umax = u.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut smax = 0.0f64;
    let mut worst = (0.0f64, 0.0f64);
    for p in 0..pts.len() {
        let [x, y] = pts.x0[p];
        let (ci, cj) = ((x / H) as usize, ((y - Y0) / H) as usize);
        let (nodes, n, dn) = shape(ci, cj, x, y);
        let mut up = [0.0; 2];
        let mut eps = [0.0; 3];
        for a in 0..4 {
            let (ux, uy) = (u[2 * nodes[a]], u[2 * nodes[a] + 1]);
            up[0] += n[a] * ux;
            up[1] += n[a] * uy;
            eps[0] += dn[a][0] * ux;
            eps[1] += dn[a][1] * uy;
            eps[2] += dn[a][1] * ux + dn[a][0] * uy;
        }
        let s: Vec<f64> = (0..3).map(|i| (0..3).map(|j| d[i][j] * eps[j]).sum()).collect();
        let du = pts.displacement(p);
        worst.0 = worst.0.max((du[0] - up[0]).abs().max((du[1] - up[1]).abs()));
        for i in 0..3 {
            worst.1 = worst.1.max((pts.stress[p][i] - s[i]).abs());
            smax = smax.max(s[i].abs());
        }
    }
    // Both solve the same 48x48 system (condition ~1e4) in double precision:
    // agreement to ~1e-12 relative; 1e-10 leaves room for pivot order.
    assert!(
        worst.0 < 1e-10 * umax,
        "displacement difference {:e} (max {umax:e})",
        worst.0
    );
    assert!(worst.1 < 1e-10 * smax, "stress difference {:e} (max {smax:e})", worst.1);
    assert!(umax > 1e-6, "the beam must actually deflect: {umax}");
}
