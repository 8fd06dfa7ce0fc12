//! Partition of unity and gradient sums of both bases, and finite-difference
//! checks of the GIMP gradients, at random points.

use mpmlab_engine::basis::{stencil, BasisKind};
use mpmlab_engine::grid::Grid;
use proptest::prelude::*;

fn grid(h: f64, ox: f64, oy: f64) -> Grid {
    Grid {
        origin: [ox, oy],
        h,
        nx: 7,
        ny: 5,
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    #[test]
    fn standard_partition_of_unity(h in 0.01f64..10.0, ox in -5.0f64..5.0, oy in -5.0f64..5.0,
                                   sx in 0.0f64..=7.0, sy in 0.0f64..=5.0) {
        let g = grid(h, ox, oy);
        let x = [ox + sx * h, oy + sy * h];
        let owned = stencil(&g, BasisKind::Standard, x, [0.0; 2]);
        let s = owned.view();
        let sum: f64 = (0..s.len()).map(|k| s.w(k)).sum();
        let dsum = (0..s.len()).map(|k| s.dw(k)).fold([0.0, 0.0], |a, d| [a[0] + d[0], a[1] + d[1]]);
        // Sums of 4 terms of size <= 1 (weights) and <= 1/h (gradients).
        prop_assert!((sum - 1.0).abs() < 1e-14, "sum {}", sum);
        prop_assert!(dsum[0].abs() * h < 1e-14 && dsum[1].abs() * h < 1e-14, "{:?}", dsum);
        prop_assert!((0..s.len()).all(|k| s.w(k) >= -1e-15));
    }

    #[test]
    fn gimp_partition_of_unity(h in 0.01f64..10.0, ox in -5.0f64..5.0, oy in -5.0f64..5.0,
                               lx in 0.01f64..=0.5, ly in 0.01f64..=0.5,
                               sx in 0.0f64..=1.0, sy in 0.0f64..=1.0) {
        let g = grid(h, ox, oy);
        let lp = [lx * h, ly * h];
        // Keep the domain inside the grid, where unity holds.
        let x = [ox + lp[0] + sx * (7.0 * h - 2.0 * lp[0]), oy + lp[1] + sy * (5.0 * h - 2.0 * lp[1])];
        let owned = stencil(&g, BasisKind::Gimp, x, lp);
        let s = owned.view();
        let sum: f64 = (0..s.len()).map(|k| s.w(k)).sum();
        let dsum = (0..s.len()).map(|k| s.dw(k)).fold([0.0, 0.0], |a, d| [a[0] + d[0], a[1] + d[1]]);
        // Up to 9 terms; gradients of size 1/l.
        prop_assert!((sum - 1.0).abs() < 1e-13, "sum {}", sum);
        prop_assert!(dsum[0].abs() * lp[0] < 1e-13 && dsum[1].abs() * lp[1] < 1e-13, "{:?}", dsum);
        prop_assert!((0..s.len()).all(|k| s.w(k) >= -1e-15));
    }

    #[test]
    fn gimp_gradient_matches_finite_differences(lx in 0.05f64..=0.5, sx in 0.1f64..=0.9, sy in 0.1f64..=0.9) {
        let g = grid(1.0, 0.0, 0.0);
        let lp = [lx, 0.3];
        let x = [1.0 + sx * 5.0, 1.0 + sy * 3.0];
        let eps = 1e-6;
        // The weights' second derivative jumps where a node is l, h - l or
        // h + l away (h = 1 here): a central difference straddling such a
        // kink is off by up to eps / (2 h l) = 1e-5, so points within 2 eps
        // of one are left out (a set of measure 8 eps per node and
        // direction; without this the check fails about once in 10^5
        // cases, as seen in a long run of the suite).
        let kinked = |c: f64, l: f64| {
            (-1..=7).any(|n| [l, 1.0 - l, 1.0 + l].iter().any(|k| ((c - n as f64).abs() - k).abs() < 2.0 * eps))
        };
        prop_assume!(!kinked(x[0], lp[0]) && !kinked(x[1], lp[1]));
        let owned = stencil(&g, BasisKind::Gimp, x, lp);
        let s = owned.view();
        for d in 0..2 {
            let mut xp = x; xp[d] += eps;
            let mut xm = x; xm[d] -= eps;
            let sp = stencil(&g, BasisKind::Gimp, xp, lp);
            let sm = stencil(&g, BasisKind::Gimp, xm, lp);
            for k in 0..s.len() {
                let w = |st: mpmlab_engine::basis::StencilView| (0..st.len()).find(|&j| st.node(j) == s.node(k)).map_or(0.0, |j| st.w(j));
                let fd = (w(sp.view()) - w(sm.view())) / (2.0 * eps);
                // GIMP weights are C1 and piecewise quadratic (second
                // derivatives <= 1/(h l)): away from the kinks the central
                // difference is exact but for round-off 1e-16/eps.
                prop_assert!((fd - s.dw(k)[d]).abs() < 1e-7, "node {} dir {}: fd {} vs {}", s.node(k), d, fd, s.dw(k)[d]);
            }
        }
    }
}

/// The seeds of this module's past property failures are where proptest
/// reads them, so every run replays them first (the file holds 1).
#[test]
fn saved_failure_seeds_replay() {
    assert_eq!(crate::common::saved_seeds(file!()), 1);
}
