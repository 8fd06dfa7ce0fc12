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
    /// Finite-deformation column under self-weight (G (30)): Cauchy
    /// `s_yy = -rho0 g (top - Y)`; no displacement solution is used.
    ColumnFinite { rho_g: f64, base: f64, top: f64 },
    /// Uniform `s_yy = stress_yy` with `u_x = 0`: `s_xx = nu/(1-nu) s_yy`
    /// (plane strain) or `nu s_yy` (plane stress), `u_y = s_yy/M (Y - base)`.
    ConfinedY {
        stress_yy: f64,
        base: f64,
        /// Rotation of the block's frame (rad) about `about`.
        angle: f64,
        about: P2,
        material: LinearElastic,
    },
    /// Confined compression under finite deformation (Hencky elasticity):
    /// the block's frame stretched by `s(lambda) = 1 + lambda (stretch - 1)`
    /// along y' with x' and z held: logarithmic strain `e = ln s` along y',
    /// Kirchhoff `tau_y'y' = M e`, `tau_x'x' = tau_zz = lambda_L e` (Lame's
    /// `lambda_L`), Cauchy `s = tau / J` with `J = s`;
    /// `u_y' = (s - 1)(Y' - base)`. Not linear in the load: use
    /// [`ExactSolution::fields`].
    ConfinedFinite {
        stretch: f64,
        base: f64,
        angle: f64,
        about: P2,
        material: LinearElastic,
    },
    /// Lame's thick cylinder under internal pressure `p`:
    /// `s_rr = A - B/r^2`, `s_tt = A + B/r^2`, `A = p a^2/(b^2 - a^2)`,
    /// `B = p a^2 b^2/(b^2 - a^2)`; plane strain
    /// `u_r = (1+nu)/E ((1-2nu) A r + B/r)`, plane stress `u_r = ((1-nu) A r + (1+nu) B/r)/E`.
    Lame {
        p: f64,
        a: f64,
        b: f64,
        center: P2,
        material: LinearElastic,
    },
    /// Kirsch: infinite plate, hole of radius `a` at the origin, remote
    /// `s_xx = s` (B (42)-(46)).
    Kirsch { s: f64, a: f64, material: LinearElastic },
    /// Simple shear `u = (0, g (x - x0))`, `s_xy = mu g`.
    SimpleShear { g: f64, x0: f64, material: LinearElastic },
    /// Free motion of stress-free bodies (explicit dynamics, G 5.1): every
    /// point keeps its initial velocity, `u = t v0(X)`, with
    /// `v0 = velocity + L (X - centre)` of its body and `t = load factor x
    /// duration`; the error is the largest `|u_p - t v0(X_p)|` (m).
    FreeMotion {
        /// Per body: `(velocity, L, centre)`.
        fields: Vec<(P2, [[f64; 2]; 2], P2)>,
        duration: f64,
    },
}

/// The initial velocity `velocity + L (x - centre)`.
pub fn velocity_field(field: &(P2, [[f64; 2]; 2], P2), x: P2) -> P2 {
    let (v, l, c) = field;
    let d = [x[0] - c[0], x[1] - c[1]];
    [
        v[0] + l[0][0] * d[0] + l[0][1] * d[1],
        v[1] + l[1][0] * d[0] + l[1][1] * d[1],
    ]
}

/// The constrained modulus `s_yy / e_yy` with `e_xx = 0`.
fn constrained_modulus(m: &LinearElastic) -> f64 {
    match m.plane {
        Plane::Strain => m.e * (1.0 - m.nu) / ((1.0 + m.nu) * (1.0 - 2.0 * m.nu)),
        Plane::Stress => m.e / (1.0 - m.nu * m.nu),
    }
}

/// `nu/(1-nu)` in plane strain, `nu` in plane stress: `s_xx / s_yy` with `e_xx = 0`.
fn lateral_ratio(m: &LinearElastic) -> f64 {
    match m.plane {
        Plane::Strain => m.nu / (1.0 - m.nu),
        Plane::Stress => m.nu,
    }
}

/// Kolosov constant.
fn kappa(m: &LinearElastic) -> f64 {
    match m.plane {
        Plane::Strain => 3.0 - 4.0 * m.nu,
        Plane::Stress => (3.0 - m.nu) / (1.0 + m.nu),
    }
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
            ExactSolution::ConfinedY { .. } => "confined-y",
            ExactSolution::ConfinedFinite { .. } => "confined-y-finite",
            ExactSolution::ColumnFinite { .. } => "column-finite",
            ExactSolution::Lame { .. } => "lame",
            ExactSolution::Kirsch { .. } => "kirsch",
            ExactSolution::SimpleShear { .. } => "simple-shear",
            ExactSolution::FreeMotion { .. } => "free-motion",
        }
    }

    /// Exact Cauchy stress `[xx, yy, xy]` (Pa) and displacement (m) at
    /// reference position `x` and load factor `load_factor`.
    pub fn fields(&self, x: P2, load_factor: f64) -> ([f64; 3], P2) {
        match self {
            ExactSolution::ConfinedFinite {
                stretch,
                base,
                angle,
                about,
                material: m,
            } => {
                let s = 1.0 + load_factor * (stretch - 1.0);
                let e = s.ln();
                let lame = m.e * m.nu / ((1.0 + m.nu) * (1.0 - 2.0 * m.nu));
                let (sx, sy) = (lame * e / s, constrained_modulus(m) * e / s);
                let (sn, c) = angle.sin_cos();
                let stress = [c * c * sx + sn * sn * sy, sn * sn * sx + c * c * sy, c * sn * (sx - sy)];
                let (dx, dy) = (x[0] - about[0], x[1] - about[1]);
                let yp = about[1] + (-sn * dx + c * dy);
                let u = (s - 1.0) * (yp - base);
                (stress, [-sn * u, c * u])
            }
            _ => (
                self.stress(x).map(|v| v * load_factor),
                self.displacement(x).map(|v| v * load_factor),
            ),
        }
    }

    /// Exact Cauchy stress `[xx, yy, xy]` (Pa) at reference position `x`
    /// (at load factor 1).
    pub fn stress(&self, x: P2) -> [f64; 3] {
        match self {
            ExactSolution::ConfinedFinite { .. } => self.fields(x, 1.0).0,
            ExactSolution::ColumnSelfWeight {
                rho_g, top, material, ..
            } => {
                let syy = -rho_g * (top - x[1]);
                [lateral_ratio(material) * syy, syy, 0.0]
            }
            // Only s_yy is known in closed form (s_xx depends on the lateral
            // confinement of the finite strain); errors use s_yy alone.
            ExactSolution::ColumnFinite { rho_g, top, .. } => [f64::NAN, -rho_g * (top - x[1]), f64::NAN],
            ExactSolution::UniaxialY {
                strain_yy, material, ..
            } => {
                let m = match material.plane {
                    Plane::Strain => material.e / (1.0 - material.nu * material.nu),
                    Plane::Stress => material.e,
                };
                [0.0, m * strain_yy, 0.0]
            }
            ExactSolution::ConfinedY {
                stress_yy,
                material,
                angle,
                ..
            } => {
                // Uniform in the block frame; rotate: s = R s' R^T.
                let (sx, sy) = (lateral_ratio(material) * stress_yy, *stress_yy);
                let (s, c) = angle.sin_cos();
                [c * c * sx + s * s * sy, s * s * sx + c * c * sy, c * s * (sx - sy)]
            }
            ExactSolution::Lame { p, a, b, center, .. } => {
                let (dx, dy) = (x[0] - center[0], x[1] - center[1]);
                let r2 = dx * dx + dy * dy;
                let big_a = p * a * a / (b * b - a * a);
                let big_b = big_a * b * b;
                let (srr, stt) = (big_a - big_b / r2, big_a + big_b / r2);
                let (c, s) = (dx / r2.sqrt(), dy / r2.sqrt());
                [
                    srr * c * c + stt * s * s,
                    srr * s * s + stt * c * c,
                    (srr - stt) * s * c,
                ]
            }
            ExactSolution::SimpleShear { g, material, .. } => [0.0, 0.0, material.e / (2.0 * (1.0 + material.nu)) * g],
            ExactSolution::FreeMotion { .. } => [0.0; 3],
            ExactSolution::Kirsch { s, a, .. } => {
                let r2 = x[0] * x[0] + x[1] * x[1];
                let th = x[1].atan2(x[0]);
                let (a2, a4) = (a * a / r2, a.powi(4) / (r2 * r2));
                let (c2, c4, s2, s4) = ((2.0 * th).cos(), (4.0 * th).cos(), (2.0 * th).sin(), (4.0 * th).sin());
                [
                    s * (1.0 - a2 * (1.5 * c2 + c4) + 1.5 * a4 * c4),
                    s * (-a2 * (0.5 * c2 - c4) - 1.5 * a4 * c4),
                    s * (-a2 * (0.5 * s2 + s4) + 1.5 * a4 * s4),
                ]
            }
        }
    }

    /// Exact displacement (m) at reference position `x` (at load factor 1).
    pub fn displacement(&self, x: P2) -> P2 {
        match self {
            ExactSolution::ConfinedFinite { .. } => self.fields(x, 1.0).1,
            ExactSolution::ColumnFinite { .. } => [f64::NAN, f64::NAN],
            ExactSolution::SimpleShear { g, x0, .. } => [0.0, g * (x[0] - x0)],
            // The first body's field at load factor 1 (errors use each point's own body).
            ExactSolution::FreeMotion { fields, duration } => velocity_field(&fields[0], x).map(|v| v * duration),
            ExactSolution::ColumnSelfWeight {
                rho_g,
                base,
                top,
                material: m,
            } => {
                let modulus = constrained_modulus(m);
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
            ExactSolution::ConfinedY {
                stress_yy,
                base,
                angle,
                about,
                material,
            } => {
                // Block-frame coordinate y' of x, then u = R (0, e (y' - base)).
                let (s, c) = angle.sin_cos();
                let (dx, dy) = (x[0] - about[0], x[1] - about[1]);
                let yp = about[1] + (-s * dx + c * dy);
                let u = stress_yy / constrained_modulus(material) * (yp - base);
                [-s * u, c * u]
            }
            ExactSolution::Lame {
                p,
                a,
                b,
                center,
                material: m,
            } => {
                let (dx, dy) = (x[0] - center[0], x[1] - center[1]);
                let r = dx.hypot(dy);
                let big_a = p * a * a / (b * b - a * a);
                let big_b = big_a * b * b;
                let ur = match m.plane {
                    Plane::Strain => (1.0 + m.nu) / m.e * ((1.0 - 2.0 * m.nu) * big_a * r + big_b / r),
                    Plane::Stress => ((1.0 - m.nu) * big_a * r + (1.0 + m.nu) * big_b / r) / m.e,
                };
                [ur * dx / r, ur * dy / r]
            }
            ExactSolution::Kirsch { s, a, material: m } => {
                let r = x[0].hypot(x[1]);
                let th = x[1].atan2(x[0]);
                let mu = m.e / (2.0 * (1.0 + m.nu));
                let k = kappa(m);
                let c = a * s / (8.0 * mu);
                let (ar, ar3) = (a / r, (a / r).powi(3));
                [
                    c * (r / a * (k + 1.0) * th.cos() + 2.0 * ar * ((1.0 + k) * th.cos() + (3.0 * th).cos())
                        - 2.0 * ar3 * (3.0 * th).cos()),
                    c * (r / a * (k - 3.0) * th.sin() + 2.0 * ar * ((1.0 - k) * th.sin() + (3.0 * th).sin())
                        - 2.0 * ar3 * (3.0 * th).sin()),
                ]
            }
        }
    }

    /// Error norms of the points' state against this solution at
    /// `load_factor` ([`ExactSolution::fields`]).
    ///
    /// - `stress_l2`: `sqrt(sum_p V_p |s_p - s(X_p)|^2 / sum_p V_p |s(X_p)|^2)`
    ///   (Frobenius norm of the in-plane stress; C (30) in L2 form);
    /// - `displacement_l2`: the same for the displacement vector (C (29));
    /// - `syy_mean_relative`, `displacement_mean_relative`: B (37)-(40),
    ///   `sum_p V_p |e_p| / |exact_p| / sum_p V_p` for `s_yy` and `|u|`
    ///   (points where the exact value is zero are skipped);
    /// - `syy_normalised` (column only): G (31),
    ///   `sum_p |s_yy - s_yy(X_p)| V_p / (rho g (top - base) sum_p V_p)`.
    pub fn errors(&self, pts: &Points, load_factor: f64) -> Vec<ErrorNorm> {
        if let ExactSolution::FreeMotion { fields, duration } = self {
            // G 5.1.2: the largest point displacement error |u_p - t v_p0|.
            let t = load_factor * duration;
            let worst = (0..pts.len())
                .map(|p| {
                    let v = velocity_field(&fields[pts.body[p]], pts.x0[p]);
                    let u = pts.displacement(p);
                    (u[0] - t * v[0]).hypot(u[1] - t * v[1])
                })
                .fold(0.0, f64::max);
            return vec![ErrorNorm {
                name: "displacement_max",
                value: worst,
            }];
        }
        if let ExactSolution::ColumnFinite { rho_g, base, top } = self {
            // G (31): sum_p |s_yy - s_yy(Y_p)| V0_p / (rho0 g l0 V0).
            let (mut e, mut v) = (0.0, 0.0);
            for p in (0..pts.len()).filter(|&p| pts.vol0[p] > 0.0) {
                e += (pts.stress[p][1] - self.stress(pts.x0[p])[1] * load_factor).abs() * pts.vol0[p];
                v += pts.vol0[p];
            }
            return vec![ErrorNorm {
                name: "syy_normalised",
                value: e / (rho_g * load_factor * (top - base) * v),
            }];
        }
        let (mut ds, mut ns, mut du, mut nu, mut g31, mut vol) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for p in 0..pts.len() {
            let v = pts.vol0[p];
            if v == 0.0 {
                continue;
            }
            let (se, ue) = self.fields(pts.x0[p], load_factor);
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
        // B (37)-(40): volume-weighted means of per-point relative errors.
        let (mut bs, mut bu, mut bv) = (0.0, 0.0, 0.0);
        for p in (0..pts.len()).filter(|&p| pts.vol0[p] > 0.0) {
            let (se, ue) = self.fields(pts.x0[p], load_factor);
            let se = se[1];
            let u = pts.displacement(p);
            let v = pts.vol0[p];
            if se != 0.0 {
                bs += v * ((pts.stress[p][1] - se) / se).abs();
            }
            let un = ue[0].hypot(ue[1]);
            if un > 0.0 {
                bu += v * (u[0] - ue[0]).hypot(u[1] - ue[1]) / un;
            }
            bv += v;
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
        out.push(ErrorNorm {
            name: "syy_mean_relative",
            value: bs / bv,
        });
        out.push(ErrorNorm {
            name: "displacement_mean_relative",
            value: bu / bv,
        });
        if let ExactSolution::ConfinedFinite { .. } = self {
            // The largest per-point relative stress error (Frobenius).
            let frob = |a: [f64; 3]| (a[0] * a[0] + a[1] * a[1] + 2.0 * a[2] * a[2]).sqrt();
            let worst = (0..pts.len())
                .filter(|&p| pts.vol0[p] > 0.0)
                .map(|p| {
                    let se = self.fields(pts.x0[p], load_factor).0;
                    let s = pts.stress[p];
                    frob([s[0] - se[0], s[1] - se[1], s[2] - se[2]]) / frob(se)
                })
                .fold(0.0, f64::max);
            out.push(ErrorNorm {
                name: "stress_max_relative",
                value: worst,
            });
        }
        if let ExactSolution::ColumnSelfWeight { rho_g, base, top, .. } = self {
            out.push(ErrorNorm {
                name: "syy_normalised",
                value: g31 / (rho_g * load_factor * (top - base) * vol),
            });
        }
        out
    }
}

/// Tip of the inextensible elastica (Euler's cantilever) under a dead
/// vertical end load with `k = P L^2 / (E I)`: returns `(shortening,
/// deflection)` as fractions of `L` (the tip moves `shortening L` towards the
/// clamp and `deflection L` in the load's direction). Solves
/// `theta'' = k cos(theta)`, `theta(0) = 0`, `theta'(1) = 0` by shooting on
/// `theta'(0)` (bisection) with RK4 on 4000 steps: accurate to ~1e-10.
pub fn elastica_tip(k: f64) -> (f64, f64) {
    // Integrate (theta, theta', x, y) over s in [0, 1].
    let run = |m: f64| {
        let n = 4000;
        let ds = 1.0 / n as f64;
        let f = |y: [f64; 4]| [y[1], k * y[0].cos(), y[0].cos(), y[0].sin()];
        let mut y = [0.0, m, 0.0, 0.0];
        for _ in 0..n {
            let k1 = f(y);
            let k2 = f([0, 1, 2, 3].map(|i| y[i] + 0.5 * ds * k1[i]));
            let k3 = f([0, 1, 2, 3].map(|i| y[i] + 0.5 * ds * k2[i]));
            let k4 = f([0, 1, 2, 3].map(|i| y[i] + ds * k3[i]));
            y = [0, 1, 2, 3].map(|i| y[i] + ds / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
        }
        y
    };
    // theta'(1) > 0 at m = 0 and <= 0 at m = -k.
    let (mut lo, mut hi) = (-k, 0.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if run(mid)[1] > 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
        if hi - lo < 1e-14 * k.max(1.0) {
            break;
        }
    }
    let y = run(0.5 * (lo + hi));
    (1.0 - y[2], -y[3])
}
