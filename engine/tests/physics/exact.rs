//! The analytical solutions are consistent: stresses equal Hooke's law
//! applied to the displacement gradient (central differences), and the
//! boundary conditions hold.

use mpmlab_engine::exact::ExactSolution;
use mpmlab_engine::material::{mul3, LinearElastic};
use mpmlab_engine::scene::Plane;

fn check_hooke(e: &ExactSolution, m: &LinearElastic, points: &[[f64; 2]]) {
    let d = m.d_matrix();
    for &x in points {
        let eps = 1e-6;
        let du = |k: usize| {
            let (mut a, mut b) = (x, x);
            a[k] += eps;
            b[k] -= eps;
            let (ua, ub) = (e.displacement(a), e.displacement(b));
            [(ua[0] - ub[0]) / (2.0 * eps), (ua[1] - ub[1]) / (2.0 * eps)]
        };
        let (dx, dy) = (du(0), du(1));
        let strain = [dx[0], dy[1], dy[0] + dx[1]];
        let s = mul3(&d, strain);
        let exact = e.stress(x);
        let scale = exact.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        // Central differences: O(eps^2 u''') truncation plus 1e-16/eps round-off.
        for k in 0..3 {
            assert!(
                (s[k] - exact[k]).abs() < 1e-6 * scale,
                "{} at {x:?}: {s:?} vs {exact:?}",
                e.name()
            );
        }
    }
}

fn material(plane: Plane) -> LinearElastic {
    LinearElastic {
        e: 10.0e6,
        nu: 0.2,
        density: 0.0,
        plane,
    }
}

#[test]
fn kirsch_is_consistent() {
    for plane in [Plane::Stress, Plane::Strain] {
        let m = material(plane);
        let e = ExactSolution::Kirsch {
            s: 10.0e6,
            a: 0.5,
            material: m,
        };
        let pts = [[0.6, 0.1], [1.0, 1.0], [0.2, 1.3], [1.9, 0.4], [0.0, 0.8], [0.7, 0.0]];
        check_hooke(&e, &m, &pts);
        // Traction-free hole: s.n = 0 on r = a.
        for k in 0..=8 {
            let t = std::f64::consts::FRAC_PI_2 * k as f64 / 8.0;
            let (c, sn) = (t.cos(), t.sin());
            let s = e.stress([0.5 * c, 0.5 * sn]);
            let tr = [s[0] * c + s[2] * sn, s[2] * c + s[1] * sn];
            assert!(tr[0].abs() < 1e-6 * 1e7 && tr[1].abs() < 1e-6 * 1e7, "{tr:?}");
        }
        // Far field: s_xx -> S.
        let far = e.stress([1e4, 3e3]);
        assert!((far[0] - 1e7).abs() < 1e-3 * 1e7 && far[1].abs() < 1e-3 * 1e7);
        // Symmetry: u_x = 0 on x = 0, u_y = 0 on y = 0.
        assert!(e.displacement([0.0, 1.2])[0].abs() < 1e-12 && e.displacement([1.2, 0.0])[1].abs() < 1e-12);
    }
}

#[test]
fn lame_is_consistent() {
    for plane in [Plane::Stress, Plane::Strain] {
        let m = material(plane);
        let e = ExactSolution::Lame {
            p: 7.56e5,
            a: 1.0,
            b: 5.0,
            center: [0.0, 0.0],
            material: m,
        };
        check_hooke(&e, &m, &[[1.2, 0.3], [2.0, 2.0], [0.4, 4.5], [3.0, 0.1]]);
        // s_rr = -p on the inner surface and 0 on the outer.
        let s = e.stress([1.0, 0.0]);
        assert!((s[0] + 7.56e5).abs() < 1e-6 * 7.56e5);
        let s = e.stress([0.0, 5.0]);
        assert!(s[1].abs() < 1e-6 * 7.56e5);
    }
}

#[test]
fn plane_strain_out_of_plane_stress_is_lambda_times_the_trace() {
    // Plane strain (e_zz = 0): s_zz = lambda (e_xx + e_yy) with
    // lambda = E nu / ((1 + nu)(1 - 2 nu)), which in terms of the in-plane
    // stresses of Hooke's law is nu (s_xx + s_yy); plane stress: 0. Checked
    // on strains of every kind (uniaxial, biaxial, shear, mixed); exact to
    // round-off of a few products.
    for nu in [0.0, 0.2, 0.3, 0.45] {
        for plane in [Plane::Strain, Plane::Stress] {
            let m = LinearElastic {
                e: 7.0e6,
                nu,
                density: 0.0,
                plane,
            };
            let lambda = m.e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
            for strain in [
                [1e-3, 0.0, 0.0],
                [0.0, -2e-3, 0.0],
                [0.0, 0.0, 5e-3],
                [1e-3, 4e-3, -3e-3],
            ] {
                let s = mul3(&m.d_matrix(), strain);
                let want = match plane {
                    Plane::Strain => lambda * (strain[0] + strain[1]),
                    Plane::Stress => 0.0,
                };
                let got = m.szz(s);
                assert!(
                    (got - want).abs() <= 1e-12 * m.e * 5e-3,
                    "nu {nu}, {plane:?}, {strain:?}: {got} vs {want}"
                );
            }
        }
    }
}
