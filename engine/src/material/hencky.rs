//! Finite-strain elasto-plasticity: Hencky (logarithmic) elasticity with
//! linear Kirchhoff stress and von Mises perfect plasticity, return map in
//! principal logarithmic strain space (G section 2.1; Charlton, Coombs &
//! Augarde 2017; AMPLE), plane strain.
//!
//! For a step's deformation gradient increment `dF` (in-plane, `dF_zz = 1`)
//! and the elastic left Cauchy-Green tensor at the start of the step `b_n`:
//! `b_tr = dF b_n dF^T = Q diag(l_a) Q^T`, trial strains `e_a = ln(l_a)/2`,
//! Kirchhoff stress `t_a = K sum(e) + 2 mu dev(e)_a`; if `rho = |dev t| > rho_y`
//! the deviator is scaled back to the yield surface (radial return).
//!
//! The tangent is that of `P = t dF^-T` (the force per original volume
//! against the start-of-step gradients) with respect to `dF`, obtained from
//! the Daleckii-Krein form of the derivatives of isotropic tensor functions
//! in the eigenbasis of `b_tr`: `d ln b` has off-diagonal factors
//! `(ln l_a - ln l_b)/(l_a - l_b)` (-> `1/l_a` for repeated eigenvalues,
//! evaluated stably) and `dt` has `(t_a - t_b)/(e_a - e_b) = 2 mu c` with
//! `c = rho_y/rho_tr` when yielding, 1 otherwise. Repeated eigenvalues need
//! no special case. It is the same tangent as G's spatial
//! `a = (1/2J) D L T - s_il d_jk` written against the start-of-step
//! configuration, and the tests check it by finite differences.

use nalgebra::{Matrix2, Matrix3};

/// Elastic constants and optional yield strength `rho_y = sqrt(2 J2)` (Pa).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hencky {
    pub e: f64,
    pub nu: f64,
    pub yield_stress: Option<f64>,
}

/// The response at one point for one trial `dF`.
#[derive(Clone, Debug)]
pub struct Response {
    /// Kirchhoff stress (3 x 3, `t_xz = t_yz = 0`).
    pub tau: Matrix3<f64>,
    /// Elastic left Cauchy-Green tensor after the return map.
    pub b_e: Matrix3<f64>,
    /// `P = tau dF^-T`, in-plane.
    pub p: Matrix2<f64>,
    /// `A[i][j][k][l] = dP_ij / d dF_kl`, in-plane.
    pub a: [[[[f64; 2]; 2]; 2]; 2],
    /// Plastic dissipation density of this increment (J per original m^3):
    /// `tau : d e_p` in principal space.
    pub dissipation: f64,
    pub yielding: bool,
}

/// The principal return map's result for one trial strain.
struct Principal {
    /// Kirchhoff principal stresses `t_a` (Pa).
    tau: [f64; 3],
    /// Elastic principal logarithmic strains after the return.
    e_e: [f64; 3],
    /// Principal tangent `d t_a / d e_b` (3 x 3, Pa).
    d: Matrix3<f64>,
    /// Shear factor `c = rho_y / rho_tr` when yielding, 1 otherwise.
    c: f64,
    /// Whether the trial stress lay outside the yield surface.
    yielding: bool,
}

/// Eigen-decomposition of a plane-strain symmetric tensor (in-plane block
/// and the zz value): rotation angle of the in-plane eigenvectors and
/// eigenvalues `[l1, l2, l_zz]`.
fn eig_plane(b: &Matrix3<f64>) -> (Matrix3<f64>, [f64; 3]) {
    let (a, c, d) = (b[(0, 0)], b[(0, 1)], b[(1, 1)]);
    let m = 0.5 * (a + d);
    let r = (0.25 * (a - d) * (a - d) + c * c).sqrt();
    let th = 0.5 * (2.0 * c).atan2(a - d);
    let (s, co) = th.sin_cos();
    let q = Matrix3::new(co, -s, 0.0, s, co, 0.0, 0.0, 0.0, 1.0);
    (q, [m + r, m - r, b[(2, 2)]])
}

/// `(ln x - ln y)/(x - y)`, continuous through `x = y` (-> `1/y`).
fn log_divided_difference(x: f64, y: f64) -> f64 {
    let t = x / y - 1.0;
    if t.abs() < 1e-300 {
        1.0 / y
    } else if t.abs() < 1e-4 {
        // ln(1+t)/t by its series: exact to round-off here.
        (1.0 - t / 2.0 + t * t / 3.0 - t * t * t / 4.0) / y
    } else {
        t.ln_1p() / (t * y)
    }
}

impl Hencky {
    fn moduli(&self) -> (f64, f64) {
        (self.e / (3.0 * (1.0 - 2.0 * self.nu)), self.e / (2.0 * (1.0 + self.nu)))
    }

    /// Stored energy per reference volume of the elastic state `b_e`:
    /// `1/2 lambda tr(e)^2 + mu e:e` with `e = ln(b_e)/2` (J/m^3).
    ///
    /// `b_e` is a plane-strain tensor (in-plane block and the zz value, as
    /// every `b_e` here is): its principal values in closed form, the
    /// in-plane pair `m +- r` with the smaller as `det / (m + r)` (no
    /// cancellation when one stretch is small).
    pub fn stored_energy(&self, b_e: &Matrix3<f64>) -> f64 {
        let (k, mu) = self.moduli();
        let lambda = k - 2.0 * mu / 3.0;
        let (a, c, d) = (b_e[(0, 0)], b_e[(0, 1)], b_e[(1, 1)]);
        let l1 = 0.5 * (a + d) + (0.25 * (a - d) * (a - d) + c * c).sqrt();
        let l2 = (a * d - c * c) / l1;
        let e = [0.5 * l1.ln(), 0.5 * l2.ln(), 0.5 * b_e[(2, 2)].ln()];
        let tr = e[0] + e[1] + e[2];
        0.5 * lambda * tr * tr + mu * (e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    }

    /// Principal return map of the trial strains `e_tr` (radial return to
    /// the von Mises cylinder).
    fn principal(&self, e_tr: [f64; 3]) -> Principal {
        let (k, mu) = self.moduli();
        let vol = e_tr[0] + e_tr[1] + e_tr[2];
        let dev = e_tr.map(|e| e - vol / 3.0);
        let s_tr = dev.map(|e| 2.0 * mu * e);
        let rho = (s_tr.iter().map(|s| s * s).sum::<f64>()).sqrt();
        let one = Matrix3::from_element(1.0);
        let idev = Matrix3::identity() - one / 3.0;
        match self.yield_stress {
            Some(ry) if rho > ry => {
                let c = ry / rho;
                let n = nalgebra::Vector3::new(s_tr[0] / rho, s_tr[1] / rho, s_tr[2] / rho);
                let s = s_tr.map(|v| v * c);
                let tau = [0, 1, 2].map(|a| k * vol + s[a]);
                let e_e = [0, 1, 2].map(|a| vol / 3.0 + s[a] / (2.0 * mu));
                let d = one * k + (idev - n * n.transpose()) * (2.0 * mu * c);
                Principal {
                    tau,
                    e_e,
                    d,
                    c,
                    yielding: true,
                }
            }
            _ => {
                let tau = [0, 1, 2].map(|a| k * vol + s_tr[a]);
                Principal {
                    tau,
                    e_e: e_tr,
                    d: one * k + idev * (2.0 * mu),
                    c: 1.0,
                    yielding: false,
                }
            }
        }
    }

    /// Stress, updated elastic state and tangent for the increment `df`
    /// from the elastic left Cauchy-Green tensor `b_n`.
    pub fn respond(&self, df: &Matrix2<f64>, b_n: &Matrix3<f64>) -> Response {
        self.response(df, b_n, true)
    }

    /// As [`Hencky::respond`] without the tangent (`a` is zero): what an
    /// explicit step needs.
    pub fn respond_stress(&self, df: &Matrix2<f64>, b_n: &Matrix3<f64>) -> Response {
        self.response(df, b_n, false)
    }

    fn response(&self, df: &Matrix2<f64>, b_n: &Matrix3<f64>, with_tangent: bool) -> Response {
        let f3 = Matrix3::new(df[(0, 0)], df[(0, 1)], 0.0, df[(1, 0)], df[(1, 1)], 0.0, 0.0, 0.0, 1.0);
        let b_tr = f3 * b_n * f3.transpose();
        let (q, l) = eig_plane(&b_tr);
        let e_tr = l.map(|v| 0.5 * v.ln());
        let Principal {
            tau: tau_p,
            e_e,
            d: dp,
            c,
            yielding,
        } = self.principal(e_tr);
        let (_, mu) = self.moduli();
        let tau = q * Matrix3::from_diagonal(&nalgebra::Vector3::from(tau_p)) * q.transpose();
        let b_e = q * Matrix3::from_diagonal(&nalgebra::Vector3::from(e_e.map(|e| (2.0 * e).exp()))) * q.transpose();
        let dissipation = (0..3).map(|a| tau_p[a] * (e_tr[a] - e_e[a])).sum::<f64>();
        let finv = f3.try_inverse().unwrap_or_else(|| Matrix3::from_element(f64::NAN));
        let finv_t = finv.transpose();
        let p3 = tau * finv_t;
        // d tau for a symmetric perturbation db of b_tr.
        let g = |a: usize, b: usize| log_divided_difference(l[a], l[b]);
        let dtau = |db: &Matrix3<f64>| {
            let bp = q.transpose() * db * q;
            let mut ep = Matrix3::zeros();
            for a in 0..3 {
                for b in 0..3 {
                    ep[(a, b)] = 0.5 * g(a, b) * bp[(a, b)];
                }
            }
            let mut tp = Matrix3::zeros();
            for a in 0..3 {
                for b in 0..3 {
                    tp[(a, b)] = if a == b {
                        (0..3).map(|m| dp[(a, m)] * ep[(m, m)]).sum()
                    } else {
                        2.0 * mu * c * ep[(a, b)]
                    };
                }
            }
            q * tp * q.transpose()
        };
        let bn_ft = b_n * f3.transpose();
        let mut a = [[[[0.0; 2]; 2]; 2]; 2];
        for k in (0..2).filter(|_| with_tangent) {
            for l2 in 0..2 {
                let mut e = Matrix3::zeros();
                e[(k, l2)] = 1.0;
                let db = e * bn_ft + (e * bn_ft).transpose();
                let dt = dtau(&db);
                let dp3 = dt * finv_t - tau * finv_t * e.transpose() * finv_t;
                for i in 0..2 {
                    for j in 0..2 {
                        a[i][j][k][l2] = dp3[(i, j)];
                    }
                }
            }
        }
        Response {
            tau,
            b_e,
            p: Matrix2::new(p3[(0, 0)], p3[(0, 1)], p3[(1, 0)], p3[(1, 1)]),
            a,
            dissipation,
            yielding,
        }
    }
}

/// Right stretch `U` of a 2 x 2 deformation gradient (`F = R U`).
pub fn right_stretch(f: &Matrix2<f64>) -> Matrix2<f64> {
    let c = f.transpose() * f;
    let (a, b, d) = (c[(0, 0)], c[(0, 1)], c[(1, 1)]);
    let m = 0.5 * (a + d);
    let r = (0.25 * (a - d) * (a - d) + b * b).sqrt();
    let th = 0.5 * (2.0 * b).atan2(a - d);
    let (s, co) = th.sin_cos();
    let q = Matrix2::new(co, -s, s, co);
    let l = Matrix2::new((m + r).sqrt(), 0.0, 0.0, (m - r).max(0.0).sqrt());
    q * l * q.transpose()
}

#[cfg(test)]
mod tests {
    use super::{log_divided_difference, Hencky};
    use nalgebra::Matrix3;

    /// `(ln x - ln y)/(x - y)` at `x = y (1 + t)` is `ln(1 + t)/(t y)`,
    /// which `ln_1p` gives to round-off for every `t`; the series that
    /// replaces it for |t| < 1e-4 truncates at `t^4/5 < 2e-17`, so the two
    /// agree to a few ulps (bound 1e-15 relative), on both sides of the
    /// switch and on both sides of `t = 0`, and at `x = y` the limit is
    /// `1/y` exactly. A wrong series coefficient changes the result by at
    /// least `t^3/4 ~ 1e-13` at `t = 9e-5`.
    #[test]
    fn stored_energy_is_that_of_the_eigenvalues_of_b_e() {
        // Against nalgebra's general symmetric eigensolver, for plane-strain
        // tensors from near-identity to stretches of 1:1000 in any
        // orientation: the closed form agrees to round-off (1e-12 of the
        // energy, whose terms are O(ln(1000)^2) at most).
        let h = Hencky {
            e: 2.0e5,
            nu: 0.3,
            yield_stress: None,
        };
        for &(l1, l2, lz, th) in &[
            (1.0, 1.0, 1.0, 0.0),
            (1.0 + 1e-9, 1.0 - 1e-9, 1.0, 0.3),
            (1.5, 0.7, 1.1, 0.7),
            (1e3, 1.0, 1e-3, 2.0),
            (0.9, 0.9, 1.2, 1.0),
            (2.0, 1e-3, 0.5, -1.1),
        ] {
            let (s, c) = f64::sin_cos(th);
            let q = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
            let b = q * Matrix3::from_diagonal(&nalgebra::Vector3::new(l1, l2, lz)) * q.transpose();
            let (k, mu) = h.moduli();
            let lambda = k - 2.0 * mu / 3.0;
            let e = b.symmetric_eigenvalues().map(|l| 0.5 * l.ln());
            let reference = 0.5 * lambda * e.sum().powi(2) + mu * e.dot(&e);
            let w = h.stored_energy(&b);
            assert!(
                (w - reference).abs() <= 1e-12 * reference.abs().max(mu),
                "({l1}, {l2}, {lz}, {th}): {w} against {reference}"
            );
        }
    }

    #[test]
    fn log_divided_difference_is_exact_through_equal_arguments() {
        for y in [0.37, 1.0, 2.9] {
            assert_eq!(log_divided_difference(y, y), 1.0 / y, "x = y = {y}");
            for t0 in [9e-5, -9e-5, 3e-5, -1e-6, 1e-9, 2e-4, -2e-4, 0.5, -0.6] {
                let x = y * (1.0 + t0);
                let t = x / y - 1.0;
                let want = t.ln_1p() / (t * y);
                let got = log_divided_difference(x, y);
                assert!(
                    (got - want).abs() < 1e-15 * want.abs(),
                    "y {y}, t {t:e}: {got} vs {want}"
                );
            }
        }
    }
}
