//! Analytical solutions the engine is checked against, and error norms.
//!
//! Exact fields are functions of the reference position `X` (where a point
//! was generated); the engine's displacement is `u_p = x_p - X_p`.

use crate::geometry::P2;
use crate::material::LinearElastic;
use crate::points::Points;
use crate::scene::Plane;

/// An exact solution with the material data it needs.
#[derive(Clone, Debug, PartialEq)]
pub enum ExactSolution {
    /// Column under self-weight `rho g` (N/m^3) resting on `base`, free at
    /// `top`, laterally confined (`u_x = 0`): `s_yy = -rho g (top - Y)`,
    /// `s_xx = nu/(1-nu) s_yy` in plane strain (`nu s_yy` in plane stress),
    /// `u_y = -(rho g / M) ((top)(Y - base) - (Y^2 - base^2)/2)` with the
    /// constrained modulus `M`.
    ColumnSelfWeight {
        rho_g: f64,
        base: f64,
        top: f64,
        material: LinearElastic,
    },
    /// Uniaxial stress along y, lateral faces free: `e_yy = strain_yy`,
    /// `s_xx = s_xy = 0`, `u = 0` at `anchor`.
    UniaxialY {
        strain_yy: f64,
        anchor: P2,
        material: LinearElastic,
    },
}

/// One error measure: a name (e.g. `stress_l2`) and its value.
#[derive(Clone, Debug, PartialEq)]
pub struct ErrorNorm {
    pub name: &'static str,
    pub value: f64,
}

impl ExactSolution {
    pub fn name(&self) -> &'static str {
        match self {
            ExactSolution::ColumnSelfWeight { .. } => "column-self-weight",
            ExactSolution::UniaxialY { .. } => "uniaxial-y",
        }
    }

    /// Exact Cauchy stress `[xx, yy, xy]` (Pa) at reference position `x`.
    pub fn stress(&self, x: P2) -> [f64; 3] {
        match self {
            ExactSolution::ColumnSelfWeight {
                rho_g, top, material, ..
            } => {
                let syy = -rho_g * (top - x[1]);
                let sxx = match material.plane {
                    Plane::Strain => material.nu / (1.0 - material.nu) * syy,
                    Plane::Stress => material.nu * syy,
                };
                [sxx, syy, 0.0]
            }
            ExactSolution::UniaxialY {
                strain_yy, material, ..
            } => {
                let m = match material.plane {
                    Plane::Strain => material.e / (1.0 - material.nu * material.nu),
                    Plane::Stress => material.e,
                };
                [0.0, m * strain_yy, 0.0]
            }
        }
    }

    /// Exact displacement (m) at reference position `x`.
    pub fn displacement(&self, x: P2) -> P2 {
        match self {
            ExactSolution::ColumnSelfWeight {
                rho_g,
                base,
                top,
                material: m,
            } => {
                let modulus = match m.plane {
                    Plane::Strain => m.e * (1.0 - m.nu) / ((1.0 + m.nu) * (1.0 - 2.0 * m.nu)),
                    Plane::Stress => m.e / (1.0 - m.nu * m.nu),
                };
                let y = x[1];
                [0.0, -rho_g / modulus * (top * (y - base) - 0.5 * (y * y - base * base))]
            }
            ExactSolution::UniaxialY {
                strain_yy,
                anchor,
                material: m,
            } => {
                let exx = match m.plane {
                    Plane::Strain => -m.nu / (1.0 - m.nu) * strain_yy,
                    Plane::Stress => -m.nu * strain_yy,
                };
                [exx * (x[0] - anchor[0]), strain_yy * (x[1] - anchor[1])]
            }
        }
    }

    /// Error norms of the points' state against this solution, scaled by
    /// `load_factor` (the solutions are linear in the load).
    ///
    /// - `stress_l2`: `sqrt(sum_p V_p |s_p - s(X_p)|^2 / sum_p V_p |s(X_p)|^2)`
    ///   (Frobenius norm of the in-plane stress; C (30) in L2 form);
    /// - `displacement_l2`: the same for the displacement vector (C (29));
    /// - `syy_normalised` (column only): G (31),
    ///   `sum_p |s_yy - s_yy(X_p)| V_p / (rho g (top - base) sum_p V_p)`.
    pub fn errors(&self, pts: &Points, load_factor: f64) -> Vec<ErrorNorm> {
        let (mut ds, mut ns, mut du, mut nu, mut g31, mut vol) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for p in 0..pts.len() {
            let v = pts.vol0[p];
            if v == 0.0 {
                continue;
            }
            let se = self.stress(pts.x0[p]).map(|s| s * load_factor);
            let ue = self.displacement(pts.x0[p]).map(|u| u * load_factor);
            let s = pts.stress[p];
            let u = pts.displacement(p);
            let frob = |a: [f64; 3]| a[0] * a[0] + a[1] * a[1] + 2.0 * a[2] * a[2];
            ds += v * frob([s[0] - se[0], s[1] - se[1], s[2] - se[2]]);
            ns += v * frob(se);
            du += v * ((u[0] - ue[0]).powi(2) + (u[1] - ue[1]).powi(2));
            nu += v * (ue[0] * ue[0] + ue[1] * ue[1]);
            g31 += v * (s[1] - se[1]).abs();
            vol += v;
        }
        let rel = |d: f64, n: f64| if n > 0.0 { (d / n).sqrt() } else { d.sqrt() };
        let mut out = vec![
            ErrorNorm {
                name: "stress_l2",
                value: rel(ds, ns),
            },
            ErrorNorm {
                name: "displacement_l2",
                value: rel(du, nu),
            },
        ];
        if let ExactSolution::ColumnSelfWeight { rho_g, base, top, .. } = self {
            out.push(ErrorNorm {
                name: "syy_normalised",
                value: g31 / (rho_g * load_factor * (top - base) * vol),
            });
        }
        out
    }
}
