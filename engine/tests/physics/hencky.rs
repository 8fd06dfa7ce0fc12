//! The finite-strain material: the tangent of `P = tau dF^-T` against
//! finite differences, elastic and plastic, with distinct and repeated
//! principal stretches; the return map lands on the yield surface.

use mpmlab_engine::material::hencky::{right_stretch, Hencky};
use nalgebra::{Matrix2, Matrix3};

fn check_tangent(m: &Hencky, df: Matrix2<f64>, bn: Matrix3<f64>) -> f64 {
    let r = m.respond(&df, &bn);
    let scale =
        r.a.iter()
            .flatten()
            .flatten()
            .flatten()
            .fold(0.0f64, |a, v| a.max(v.abs()));
    let mut worst = 0.0f64;
    let eps = 1e-7;
    for k in 0..2 {
        for l in 0..2 {
            let (mut fp, mut fm) = (df, df);
            fp[(k, l)] += eps;
            fm[(k, l)] -= eps;
            let (pp, pm) = (m.respond(&fp, &bn).p, m.respond(&fm, &bn).p);
            for i in 0..2 {
                for j in 0..2 {
                    let fd = (pp[(i, j)] - pm[(i, j)]) / (2.0 * eps);
                    worst = worst.max((fd - r.a[i][j][k][l]).abs() / scale);
                }
            }
        }
    }
    worst
}

#[test]
fn elastic_tangent_matches_finite_differences() {
    let m = Hencky {
        e: 12.0e6,
        nu: 0.2,
        yield_stress: None,
    };
    let bn = Matrix3::new(1.1, 0.05, 0.0, 0.05, 0.95, 0.0, 0.0, 0.0, 1.02);
    for df in [
        Matrix2::new(1.05, 0.1, -0.03, 0.97),
        Matrix2::new(0.8, -0.3, 0.2, 1.3),
        Matrix2::new(1.0, 0.0, 0.0, 1.0),
    ] {
        // Central differences with eps = 1e-7 on a smooth map: truncation
        // ~1e-14 relative, round-off ~1e-16/1e-7 = 1e-9 relative.
        let e = check_tangent(&m, df, bn);
        assert!(e < 1e-6, "{df}: {e:e}");
    }
}

#[test]
fn repeated_stretches_need_no_special_case() {
    // b_n = I and dF = s I: all principal stretches in the plane equal.
    let m = Hencky {
        e: 1.0e6,
        nu: 0.3,
        yield_stress: None,
    };
    for s in [1.0, 1.1, 0.9] {
        let e = check_tangent(&m, Matrix2::new(s, 0.0, 0.0, s), Matrix3::identity());
        assert!(e < 1e-6, "s = {s}: {e:e}");
    }
    // And in-plane equal to out-of-plane (pure rotation of I).
    let (c, sn) = (0.3f64.cos(), 0.3f64.sin());
    let e = check_tangent(&m, Matrix2::new(c, -sn, sn, c), Matrix3::identity());
    assert!(e < 1e-6, "rotation: {e:e}");
}

#[test]
fn plastic_tangent_matches_finite_differences_and_returns_to_yield() {
    let m = Hencky {
        e: 1.0e6,
        nu: 0.3,
        yield_stress: Some(2.0e4),
    };
    let bn = Matrix3::new(1.01, 0.004, 0.0, 0.004, 0.99, 0.0, 0.0, 0.0, 1.0);
    for df in [
        Matrix2::new(1.05, 0.02, 0.01, 0.96),
        Matrix2::new(1.0, 0.08, 0.0, 1.0),
        Matrix2::new(1.04, 0.0, 0.0, 1.04),
    ] {
        let r = m.respond(&df, &bn);
        let tau = r.tau;
        let p = (tau[(0, 0)] + tau[(1, 1)] + tau[(2, 2)]) / 3.0;
        let dev = tau - Matrix3::identity() * p;
        let rho = dev.norm();
        if r.yielding {
            // On the yield surface to round-off.
            assert!((rho - 2.0e4).abs() < 1e-8 * 2.0e4, "rho {rho}");
            assert!(r.dissipation > 0.0);
        } else {
            assert!(rho <= 2.0e4);
        }
        let e = check_tangent(&m, df, bn);
        assert!(e < 1e-6, "{df}: {e:e}");
    }
    // The first two increments yield, the isotropic one does not.
    assert!(m.respond(&Matrix2::new(1.05, 0.02, 0.01, 0.96), &bn).yielding);
    assert!(
        !m.respond(&Matrix2::new(1.0, 0.0, 0.0, 1.0), &Matrix3::identity())
            .yielding
    );
}

#[test]
fn right_stretch_is_symmetric_and_recovers_f() {
    let f = Matrix2::new(1.2, 0.3, -0.1, 0.9);
    let u = right_stretch(&f);
    assert!((u - u.transpose()).norm() < 1e-14);
    // R = F U^-1 is a rotation.
    let r = f * u.try_inverse().unwrap();
    assert!((r.transpose() * r - Matrix2::identity()).norm() < 1e-12);
    assert!((r.determinant() - 1.0).abs() < 1e-12);
}
