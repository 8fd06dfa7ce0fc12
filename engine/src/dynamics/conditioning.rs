//! Conditioning of the explicit step's mass matrices (G 3.5): the
//! condition numbers of the consistent, stabilised and lumped masses, and
//! with each the CFL number `C = 1 / (h sqrt(lambda_max(K, M)))` (s/m),
//! `lambda_max` the largest eigenvalue of `K x = lambda M x` found by power
//! iteration. The step computes them on its first sub-step when
//! `condition_every` asks; [`conditioning`] at any configuration.

use crate::assembly::{Mapping, Pattern, Storage};
use crate::bulk::blocks_of;
use crate::ghost::{self, GhostFace};
use crate::linalg::{self, Condition, ConditionMethod, Factor, SparseRef};
use crate::report::Conditioning;
use crate::scene::ConditionMode;
use crate::state::Simulation;

use super::mass::{consistent_mass, lumped_mass, PointsOnGrid};
use super::{dot, norm};

/// Condition number of an SPD matrix, or `inf` when it cannot be factorised.
fn spd_condition(m: SparseRef<'_>, mode: ConditionMode, dense_limit: usize) -> (Condition, Option<Factor>) {
    match linalg::cholesky(m) {
        Ok(f) => {
            let limit = match mode {
                ConditionMode::Dense => usize::MAX,
                ConditionMode::Lanczos => 0,
                _ => dense_limit,
            };
            (linalg::condition(m, &f, limit), Some(f))
        }
        // Not numerically positive definite: its smallest eigenvalue is at
        // or below round-off of the largest; dense eigenvalues say where.
        Err(_) => {
            let ev = (m.nrows() <= dense_limit)
                .then(|| linalg::dense_eigenvalues(m))
                .flatten();
            let (lo, hi) = ev.map_or((0.0, f64::NAN), |e| (e[0], e[e.len() - 1]));
            (
                Condition {
                    value: f64::INFINITY,
                    lambda_min: lo,
                    lambda_max: hi,
                    method: ConditionMethod::NotPositiveDefinite,
                },
                None,
            )
        }
    }
}

/// Largest eigenvalue of `K x = lambda M x` (0 if none is positive), by
/// power iteration on `M^-1 K` with the Rayleigh quotient `x.Kx / x.Mx`,
/// from a fixed pseudo-random start; stops when it settles to 1e-8
/// relative (at most 2000 iterations). `K` is stored in full, `M` applied
/// through `m_mul` and `m_solve`. The iteration finds the eigenvalue of
/// largest magnitude; where that is negative (an indefinite `K`), it runs
/// again on `K - lambda_neg M`, whose eigenvalues `lambda_i - lambda_neg`
/// are all `>= 0`, and the largest is `lambda_neg` plus its dominant one.
/// Infinite for a mass that is not positive.
fn generalised_lambda_max(
    k: SparseRef<'_>,
    m_mul: impl Fn(&[f64]) -> Vec<f64>,
    m_solve: impl Fn(&[f64]) -> Vec<f64>,
) -> f64 {
    let dominant = power_iteration(k, &m_mul, &m_solve, 0.0);
    if dominant < 0.0 {
        (dominant + power_iteration(k, &m_mul, &m_solve, dominant)).max(0.0)
    } else {
        dominant
    }
}

/// The eigenvalue of largest magnitude of `(K - shift M) x = mu M x`.
fn power_iteration(
    k: SparseRef<'_>,
    m_mul: &impl Fn(&[f64]) -> Vec<f64>,
    m_solve: &impl Fn(&[f64]) -> Vec<f64>,
    shift: f64,
) -> f64 {
    let n = k.nrows();
    let k_mul = |x: &[f64], mx: &[f64]| {
        let mut y: Vec<f64> = mx.iter().map(|m| -shift * m).collect();
        let (ri, v) = (k.row_idx(), k.val());
        for c in 0..n {
            for i in k.symbolic().col_range(c) {
                y[ri[i] as usize] += v[i] * x[c];
            }
        }
        y
    };
    let mut rand = crate::linalg::XorShift::new(0x2545_f491_4f6c_dd1d);
    let mut x: Vec<f64> = (0..n).map(|_| rand.centred()).collect();
    let mut last = 0.0;
    for _ in 0..2000 {
        let mx = m_mul(&x);
        let kx = k_mul(&x, &mx);
        let (xkx, xmx) = (dot(&x, &kx), dot(&x, &mx));
        if !(xmx > 0.0) || !xkx.is_finite() {
            return f64::INFINITY;
        }
        let lambda = xkx / xmx;
        if lambda <= 0.0 && norm(&kx) == 0.0 {
            return 0.0;
        }
        if (lambda - last).abs() <= 1e-8 * lambda.abs() {
            return lambda;
        }
        last = lambda;
        let z = m_solve(&kx);
        let nz = norm(&z);
        if !(nz > 0.0 && nz.is_finite()) {
            return lambda;
        }
        x = z.iter().map(|v| v / nz).collect();
    }
    last
}

fn cfl(h: f64, lambda_max: f64) -> Option<f64> {
    if lambda_max == 0.0 {
        None
    } else if !lambda_max.is_finite() {
        Some(0.0)
    } else {
        Some(1.0 / (h * lambda_max.sqrt()))
    }
}

/// Mass conditioning and CFL numbers for a mapping and its ghost faces.
pub(super) fn conditioning_on(
    sim: &Simulation,
    map: &Mapping,
    faces: &[GhostFace],
) -> Result<Conditioning, linalg::FactorError> {
    let (mode, limit) = (sim.params.condition, sim.params.dense_limit);
    let masses = &sim.state.points.mass;
    let blocks = blocks_of(map, faces);
    let pattern = Pattern::new(&map.dofs, &blocks, Storage::Lower)?;
    let points = PointsOnGrid::of(sim);
    let mc = consistent_mass(map, &map.dofs, &pattern, &blocks, faces, &points, 0.0)?;
    let ms = consistent_mass(map, &map.dofs, &pattern, &blocks, faces, &points, sim.params.gamma_m)?;
    let (cond_c, fact_c) = spd_condition(mc.as_ref(), mode, limit);
    let (cond_s, fact_s) = spd_condition(ms.as_ref(), mode, limit);
    let lumped = lumped_mass(map, masses);
    let (lo, hi) = lumped
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), &d| (lo.min(d), hi.max(d)));
    let cond_l = Condition {
        value: if lo > 0.0 { hi / lo } else { f64::INFINITY },
        lambda_min: lo,
        lambda_max: hi,
        method: ConditionMethod::Dense,
    };
    // Stiffness: the material tangent at the current state, with and
    // without the ghost term.
    let full = Pattern::new(&map.dofs, &blocks, Storage::Full)?;
    let zero = vec![[0.0; 2]; map.dofs.node_dof.len()];
    let it = crate::bulk::evaluate(sim, map, &zero)?;
    let k = crate::bulk::tangent(sim, map, &full, &blocks, faces, &it, 0.0)?;
    let ks = crate::bulk::tangent(sim, map, &full, &blocks, faces, &it, sim.params.gamma_k)?;
    let h = sim.model.grid.h;
    let with = |k: SparseRef<'_>, m: SparseRef<'_>, f: &Option<Factor>| match f {
        Some(f) => cfl(
            h,
            generalised_lambda_max(k, |x| linalg::sym_lower_mul(m, x), |b| linalg::solve(f, b)),
        ),
        None => Some(0.0),
    };
    Ok(Conditioning {
        mass_consistent: cond_c,
        mass_stabilised: cond_s,
        mass_lumped: cond_l,
        cfl_consistent: with(k.as_ref(), mc.as_ref(), &fact_c),
        cfl_stabilised: with(ks.as_ref(), ms.as_ref(), &fact_s),
        cfl_lumped: if lo > 0.0 {
            cfl(
                h,
                generalised_lambda_max(
                    k.as_ref(),
                    |x| x.iter().zip(&lumped).map(|(x, d)| x * d).collect(),
                    |b| b.iter().zip(&lumped).map(|(b, d)| b / d).collect(),
                ),
            )
        } else {
            Some(0.0)
        },
        stiffness: None,
        stiffness_stabilised: None,
    })
}

/// Mass conditioning and CFL numbers at the current configuration, on
/// demand (any analysis): the consistent, stabilised (`gamma_M` of the
/// parameters) and lumped masses, over the dofs the scene's supports
/// leave free.
pub(crate) fn conditioning(sim: &Simulation) -> Result<Conditioning, linalg::FactorError> {
    let model = &sim.model;
    let map = Mapping::build(&model.grid, &sim.state.points, &model.bodies, &model.dirichlet, 0.0)?;
    let faces = ghost::faces_of(&model.grid, &map, model.analysis.ghost_cells);
    let mut c = conditioning_on(sim, &map, &faces)?;
    let blocks = blocks_of(&map, &faces);
    let lower = Pattern::new(&map.dofs, &blocks, Storage::Lower)?;
    let it = crate::bulk::evaluate(sim, &map, &vec![[0.0; 2]; map.dofs.node_dof.len()])?;
    let (mode, limit) = (sim.params.condition, sim.params.dense_limit);
    let k = |gamma: f64| crate::bulk::tangent(sim, &map, &lower, &blocks, &faces, &it, gamma);
    c.stiffness = Some(spd_condition(k(0.0)?.as_ref(), mode, limit).0);
    c.stiffness_stabilised = Some(spd_condition(k(sim.params.gamma_k)?.as_ref(), mode, limit).0);
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A diagonal stiffness `diag(d)`, stored in full as the CFL's `K` is.
    fn diag(d: &[f64]) -> faer::sparse::SparseColMat<linalg::Ix, f64> {
        let t: Vec<_> = (0..d.len())
            .map(|i| faer::sparse::Triplet::new(i as linalg::Ix, i as linalg::Ix, d[i]))
            .collect();
        faer::sparse::SparseColMat::try_new_from_triplets(d.len(), d.len(), &t).unwrap()
    }

    /// The power iteration of the CFL numbers: for `K = diag(3, 2)`, `M =
    /// diag(1, 4)` the largest eigenvalue of `K x = lambda M x` is 3 (the
    /// iteration settles to 1e-8 relative; 1e-6 leaves room). A mass with
    /// `x.Mx <= 0` (`M = -I`, whose "eigenvalue" with `K = I` would be -1)
    /// has no stable explicit step: infinite `lambda_max`, CFL number 0.
    #[test]
    fn generalised_lambda_max_is_infinite_for_a_mass_that_is_not_positive() {
        let mul = |d: [f64; 2]| move |x: &[f64]| vec![d[0] * x[0], d[1] * x[1]];
        let solve = |d: [f64; 2]| move |b: &[f64]| vec![b[0] / d[0], b[1] / d[1]];
        let k = diag(&[3.0, 2.0]);
        let lambda = generalised_lambda_max(k.as_ref(), mul([1.0, 4.0]), solve([1.0, 4.0]));
        assert!((lambda - 3.0).abs() < 1e-6 * 3.0, "{lambda}");
        let k = diag(&[1.0, 1.0]);
        let lambda = generalised_lambda_max(k.as_ref(), mul([-1.0, -1.0]), solve([-1.0, -1.0]));
        assert_eq!(lambda, f64::INFINITY);
        assert_eq!(cfl(1.0, lambda), Some(0.0));
    }

    /// A Rayleigh quotient at or below zero stops the power iteration only
    /// where `K x = 0` (a stress-free mode, lambda_max 0). For an indefinite
    /// `K = diag(-1, c)` (M = I) arranged so that the iteration's fixed
    /// start `x` has `x.Kx < 0`, the dominant eigenvalue `c > 1` is still
    /// found (to the iteration's 1e-8; 1e-6 leaves room).
    #[test]
    fn generalised_lambda_max_goes_on_past_a_negative_start() {
        // The start `generalised_lambda_max` draws.
        let mut rand = crate::linalg::XorShift::new(0x2545_f491_4f6c_dd1d);
        let (a, b) = (rand.centred(), rand.centred());
        // The larger start component on the negative eigenvalue -1, the
        // other on c, halfway between 1 and the ratio that keeps x.Kx < 0.
        let (big, small, first) = if a.abs() >= b.abs() { (a, b, 0) } else { (b, a, 1) };
        let c = 0.5 * (1.0 + (big / small).powi(2));
        let mut d = [c; 2];
        d[first] = -1.0;
        assert!(d[0] * a * a + d[1] * b * b < 0.0 && c > 1.0);
        let lambda = generalised_lambda_max(diag(&d).as_ref(), |x: &[f64]| x.to_vec(), |b: &[f64]| b.to_vec());
        assert!((lambda - c).abs() < 1e-6 * c, "{lambda}, want {c}");
    }

    #[test]
    fn generalised_lambda_max_scales_with_the_stiffness() {
        // K = s diag(1, 2, 3) against M = I: the largest eigenvalue is 3 s
        // for a stiffness in any unit (s from 1e-12 to 1e12); the settle
        // test is relative, so a tiny K converges as far as a big one.
        // The iteration settles at 1e-8 relative change with error
        // ratio (2/3)^2 per step: 1e-6 of 3 s is room for it.
        for s in [1e-12, 1.0, 1e12] {
            let k = diag(&[s, 2.0 * s, 3.0 * s]);
            let lambda = generalised_lambda_max(k.as_ref(), |x: &[f64]| x.to_vec(), |b: &[f64]| b.to_vec());
            assert!(
                (lambda - 3.0 * s).abs() < 1e-6 * 3.0 * s,
                "s = {s}: {lambda}, want {}",
                3.0 * s
            );
        }
    }

    /// Where the eigenvalue of largest magnitude is negative (an indefinite
    /// `K`, as a compressed body's geometric stiffness can make it), the
    /// CFL number comes from the largest positive eigenvalue: `K = diag(-3,
    /// 1, 0.5)` against `M = I` gives 1, so CFL 1 / (h sqrt 1) (to the
    /// iterations' 1e-8 settle test, twice: 1e-6). With no positive
    /// eigenvalue (`diag(-3, -1)`) there is no stability limit: 0, no CFL
    /// number, never the square root of a negative one.
    #[test]
    fn generalised_lambda_max_is_the_largest_positive_eigenvalue_of_an_indefinite_k() {
        let id = |x: &[f64]| x.to_vec();
        let lambda = generalised_lambda_max(diag(&[-3.0, 1.0, 0.5]).as_ref(), id, id);
        assert!((lambda - 1.0).abs() < 1e-6, "{lambda}");
        let c = cfl(0.5, lambda).unwrap();
        assert!((c - 2.0).abs() < 1e-6, "{c}");
        let lambda = generalised_lambda_max(diag(&[-3.0, -1.0]).as_ref(), id, id);
        assert_eq!(lambda, 0.0);
        assert_eq!(cfl(0.5, lambda), None);
    }
}
