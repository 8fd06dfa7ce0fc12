//! Error estimates without an exact solution, from a refinement sweep:
//! the observed order, the Richardson-extrapolated value and Roache's grid
//! convergence index (GCI), as ASME V&V 20 recommends them.
//!
//! The procedure is Celik et al. (2008), "Procedure for estimation and
//! reporting of uncertainty due to discretization in CFD applications",
//! J. Fluids Eng. 130(7), 078001, for three solutions `phi1, phi2, phi3` on
//! cell sizes `h1 < h2 < h3` (ratios `r21 = h2/h1`, `r32 = h3/h2`, which
//! need not be equal):
//!
//! - differences `e21 = phi2 - phi1`, `e32 = phi3 - phi2`; with
//!   `phi = phi_ext + C h^p` their ratio is
//!   `e32/e21 = r21^p (r32^p - 1)/(r21^p - 1)`, Celik's equation for the
//!   observed order `p`, which is solved here by bisection. The ratio
//!   exceeds `ln r32 / ln r21` (1 for equal ratios) for every `p > 0`:
//!   above it the triple converges monotonically, below `-ln r32 / ln r21`
//!   it oscillates and converges, in between it diverges;
//! - extrapolated value `phi_ext = (r21^p phi1 - phi2) / (r21^p - 1)`;
//! - the fine solution's estimated error `|phi1 - phi_ext| = |e21| / (r21^p - 1)`;
//! - `GCI_fine = Fs |e21| / (r21^p - 1)` with the factor of safety
//!   `Fs = 1.25` of a three-grid study, and `Fs = 3` (Roache's two-grid
//!   value) when the observed order is outside `[0.5, 4]`, where the
//!   solutions are not in their asymptotic range and `p` is not to be
//!   trusted, or when the next coarser triple does not confirm the order
//!   (within 25%): three values alone cannot tell a pre-asymptotic range
//!   from the asymptotic one (on the plate with a hole a monotone triple
//!   of order 2.2 overestimated its error 45 times), so a trusted estimate
//!   needs four refinements.
//!
//! Oscillatory convergence has no order: its estimate is half the range of
//! the three values (Stern et al. 2001). A diverging triple has none.
//!
//! A point probe's value tends to the field at the position it asks for as
//! the points are refined, so where the scene has an exact solution the
//! estimate is checked against `|phi1 - exact|` (the effectivity
//! `estimate / true error`, 1 for a perfect estimate).

use super::{groups_without, RunResult};

/// Factor of safety of a three-grid study (Roache).
pub const FS_THREE: f64 = 1.25;
/// Factor of safety when the observed order is not credible.
pub const FS_UNRELIABLE: f64 = 3.0;
/// Observed orders outside this range are flagged and get [`FS_UNRELIABLE`].
pub const CREDIBLE_ORDER: (f64, f64) = (0.5, 4.0);
/// Successive triples confirm each other when their orders differ by at
/// most this share.
pub const ORDER_AGREEMENT: f64 = 0.25;
/// Differences below this share of the value are round-off: the quantity
/// is resolved on all three grids.
pub const ROUND_OFF: f64 = 1e-10;

/// How a triple of solutions behaves under refinement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Behaviour {
    /// Monotone convergence with an order in [`CREDIBLE_ORDER`], confirmed
    /// by the next coarser triple's order (within [`ORDER_AGREEMENT`]).
    Monotone,
    /// Monotone with a credible order that no coarser triple confirms
    /// (there is none, or its order differs): three values cannot tell a
    /// pre-asymptotic range from the asymptotic one.
    Unconfirmed,
    /// Monotone convergence with an order outside it: not yet asymptotic.
    NotAsymptotic,
    /// The differences change sign and shrink.
    Oscillatory,
    /// The differences do not shrink.
    Diverging,
    /// Both differences at round-off.
    Resolved,
}

impl Behaviour {
    pub fn label(self) -> &'static str {
        match self {
            Behaviour::Monotone => "monotone",
            Behaviour::Unconfirmed => "unconfirmed",
            Behaviour::NotAsymptotic => "not asymptotic",
            Behaviour::Oscillatory => "oscillatory",
            Behaviour::Diverging => "diverging",
            Behaviour::Resolved => "resolved",
        }
    }
}

/// The estimate of one quantity from three refinements.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// The runs' shared other settings (`runs` when h is the only one).
    pub group: String,
    /// `probe:<name>:<key>` or `energy:<name>`.
    pub quantity: String,
    /// Run ids, fine to coarse.
    pub ids: [String; 3],
    /// Cell sizes, fine to coarse.
    pub h: [f64; 3],
    /// The quantity on each, fine to coarse.
    pub values: [f64; 3],
    /// Observed order `p` (NaN when there is none).
    pub order: f64,
    /// `phi_ext` (NaN when there is none).
    pub extrapolated: f64,
    /// Estimated error of the fine value, `|phi1 - phi_ext|` (NaN: none).
    pub error: f64,
    /// `GCI_fine` as an absolute error bound (NaN: none).
    pub gci: f64,
    pub behaviour: Behaviour,
    /// The exact value, where the scene has one for this quantity.
    pub exact: Option<f64>,
}

impl Estimate {
    /// `|phi1 - exact|`, where the exact value is known.
    pub fn true_error(&self) -> Option<f64> {
        self.exact.map(|e| (self.values[0] - e).abs())
    }

    /// Estimated over true error (1: perfect; NaN where either is
    /// unknown or the true error is zero).
    pub fn effectivity(&self) -> f64 {
        match self.true_error() {
            Some(t) if t > 0.0 => self.error / t,
            _ => f64::NAN,
        }
    }

    /// `GCI_fine` relative to the fine value.
    pub fn relative_gci(&self) -> f64 {
        self.gci / self.values[0].abs()
    }
}

/// The observed order of `(h, phi)` fine to coarse, the convergence ratio
/// and the behaviour ([`Behaviour`]); the order is NaN where there is none.
///
/// `scale` is the size round-off is measured against: at least the values'
/// own, larger for a component that is zero where its kin are not (a
/// shear stress among normal ones).
pub fn observed_order(h: [f64; 3], phi: [f64; 3], scale: f64) -> (f64, Behaviour) {
    let (e21, e32) = (phi[1] - phi[0], phi[2] - phi[1]);
    let scale = phi.iter().fold(scale.abs(), |m, v| m.max(v.abs()));
    if e21.abs() <= ROUND_OFF * scale && e32.abs() <= ROUND_OFF * scale {
        return (f64::NAN, Behaviour::Resolved);
    }
    if e21 == 0.0 {
        // Exact on the two finer grids: no order to observe, nothing left.
        return (f64::INFINITY, Behaviour::Resolved);
    }
    let (r21, r32) = (h[1] / h[0], h[2] / h[1]);
    // With phi = phi_ext + C h^p, e32/e21 = r21^p (r32^p - 1)/(r21^p - 1),
    // which grows from ln r32 / ln r21 (p -> 0) without bound: a ratio
    // above that threshold converges, one below it does not.
    let ratio = e32 / e21;
    let threshold = r32.ln() / r21.ln();
    if ratio.abs() <= threshold {
        return (f64::NAN, Behaviour::Diverging);
    }
    if ratio < 0.0 {
        return (f64::NAN, Behaviour::Oscillatory);
    }
    // Solve g(p) = ln(e32/e21) for p by bisection (g increases with p).
    let g = |p: f64| p * r21.ln() + ((r32.powf(p) - 1.0) / (r21.powf(p) - 1.0)).ln() - ratio.ln();
    let (mut lo, mut hi) = (1e-9, 50.0);
    if g(hi) < 0.0 {
        return (hi, Behaviour::NotAsymptotic);
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if g(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-13 * hi {
            break;
        }
    }
    let p = 0.5 * (lo + hi);
    let credible = p >= CREDIBLE_ORDER.0 && p <= CREDIBLE_ORDER.1;
    (
        p,
        if credible {
            Behaviour::Monotone
        } else {
            Behaviour::NotAsymptotic
        },
    )
}

/// The estimate for one quantity on three runs, fine to coarse.
pub fn estimate(h: [f64; 3], phi: [f64; 3], scale: f64) -> (f64, Behaviour, f64, f64, f64) {
    let (p, b) = observed_order(h, phi, scale);
    let e21 = phi[1] - phi[0];
    let r21 = h[1] / h[0];
    match b {
        Behaviour::Monotone | Behaviour::Unconfirmed | Behaviour::NotAsymptotic => {
            let rp = r21.powf(p);
            let error = e21.abs() / (rp - 1.0);
            let fs = if b == Behaviour::Monotone {
                FS_THREE
            } else {
                FS_UNRELIABLE
            };
            (p, b, (rp * phi[0] - phi[1]) / (rp - 1.0), error, fs * error)
        }
        Behaviour::Oscillatory => {
            let lo = phi.iter().cloned().fold(f64::INFINITY, f64::min);
            let hi = phi.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            let half = 0.5 * (hi - lo);
            (p, b, f64::NAN, half, half)
        }
        Behaviour::Resolved => {
            let d = e21.abs().max((phi[2] - phi[1]).abs());
            (p, b, phi[0], d, d)
        }
        Behaviour::Diverging => (p, b, f64::NAN, f64::NAN, f64::NAN),
    }
}

/// Estimates of every quantity of every run triple: in each group of
/// completed runs that share every setting but `h_key`, each three
/// successive refinements (finest triple first).
pub fn estimates(results: &[RunResult], h_key: &str) -> Vec<Estimate> {
    let mut out = Vec::new();
    for (group, runs) in groups_without(results, h_key) {
        // Coarse to fine; one run per h (a repeated h would give no ratio).
        let mut runs = runs;
        runs.dedup_by(|a, b| a.setting(h_key) == b.setting(h_key));
        for w in runs.windows(3).rev() {
            let [coarse, medium, fine] = [w[0], w[1], w[2]];
            let h = [fine, medium, coarse].map(|r| r.setting(h_key).unwrap_or(f64::NAN));
            if !h.iter().all(|v| v.is_finite() && *v > 0.0) {
                continue;
            }
            let quantities = fine.quantities();
            for (q, v1) in quantities.iter().cloned() {
                let find = |r: &RunResult| r.quantities().into_iter().find(|(n, _)| *n == q).map(|x| x.1);
                let (Some(v2), Some(v3)) = (find(medium), find(coarse)) else {
                    continue;
                };
                let values = [v1, v2, v3];
                let scale = quantities
                    .iter()
                    .filter(|(n, _)| kin(n) == kin(&q))
                    .fold(0.0f64, |m, (_, v)| m.max(v.abs()));
                let (order, behaviour, extrapolated, error, gci) = estimate(h, values, scale);
                out.push(Estimate {
                    group: group.clone(),
                    exact: fine.exact_value(&q),
                    quantity: q,
                    ids: [fine.id.clone(), medium.id.clone(), coarse.id.clone()],
                    h,
                    values,
                    order,
                    extrapolated,
                    error,
                    gci,
                    behaviour,
                });
            }
        }
    }
    confirm(&mut out);
    out
}

/// A monotone triple is trusted only when the next coarser triple of the
/// same quantity (sharing its two coarser runs) is monotone with an order
/// within [`ORDER_AGREEMENT`]; otherwise it is [`Behaviour::Unconfirmed`]
/// and its GCI takes [`FS_UNRELIABLE`].
fn confirm(est: &mut [Estimate]) {
    let raw: Vec<(String, String, f64, Behaviour, f64)> = est
        .iter()
        .map(|e| (e.group.clone(), e.quantity.clone(), e.h[0], e.behaviour, e.order))
        .collect();
    for e in est.iter_mut().filter(|e| e.behaviour == Behaviour::Monotone) {
        let coarser = raw
            .iter()
            .find(|(g, q, h, _, _)| *g == e.group && *q == e.quantity && *h == e.h[1]);
        let agrees = coarser
            .is_some_and(|(_, _, _, b, p)| *b == Behaviour::Monotone && (e.order / p - 1.0).abs() <= ORDER_AGREEMENT);
        if !agrees {
            e.behaviour = Behaviour::Unconfirmed;
            e.gci = FS_UNRELIABLE * e.error;
        }
    }
}

/// Quantities measured in the same unit on the same target: a probe's
/// displacements (`probe:<name>:u`), its stresses (`:s`), its forces
/// (`:f`); the energies.
fn kin(q: &str) -> &str {
    match q.rsplit_once(':') {
        Some((target, key)) if q.starts_with("probe:") => &q[..target.len() + 2.min(key.len())],
        _ => "energy",
    }
}

fn num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:e}")
    } else {
        String::new()
    }
}

/// The columns of `estimates.csv`.
pub const CSV_COLUMNS: &[&str] = &[
    "group",
    "quantity",
    "run_fine",
    "h_fine",
    "h_medium",
    "h_coarse",
    "value_fine",
    "value_medium",
    "value_coarse",
    "behaviour",
    "order",
    "extrapolated",
    "error_estimate",
    "gci",
    "relative_gci",
    "exact",
    "true_error",
    "effectivity",
];

/// `estimates.csv`: one row per estimate, full precision.
pub fn to_csv(est: &[Estimate]) -> String {
    let mut s = CSV_COLUMNS.join(",");
    s.push('\n');
    for e in est {
        let row = [
            super::csv_field(&e.group),
            e.quantity.clone(),
            e.ids[0].clone(),
            num(e.h[0]),
            num(e.h[1]),
            num(e.h[2]),
            num(e.values[0]),
            num(e.values[1]),
            num(e.values[2]),
            e.behaviour.label().into(),
            num(e.order),
            num(e.extrapolated),
            num(e.error),
            num(e.gci),
            num(e.relative_gci()),
            e.exact.map_or(String::new(), num),
            e.true_error().map_or(String::new(), num),
            num(e.effectivity()),
        ];
        s.push_str(&row.join(","));
        s.push('\n');
    }
    s
}

/// The summary's table: the finest triple of each group and quantity.
pub fn summary(est: &[Estimate], h_key: &str) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let finest = finest(est);
    if finest.is_empty() {
        return s;
    }
    let _ = writeln!(
        s,
        "error estimates from the three finest {h_key} (Richardson extrapolation, GCI with Fs = {FS_THREE}; Celik et al. 2008):"
    );
    let _ = writeln!(
        s,
        "  {:<24} {:<24} {:>10} {:>13} {:>6} {:>13} {:>10} {:>10} {:>10} {:>6}  behaviour",
        "group", "quantity", h_key, "value", "order", "extrapolated", "estimate", "GCI", "true err", "est/tr"
    );
    for e in finest {
        let opt = |v: f64, f: &dyn Fn(f64) -> String| if v.is_finite() { f(v) } else { "-".into() };
        let _ = writeln!(
            s,
            "  {:<24} {:<24} {:>10} {:>13.6e} {:>6} {:>13} {:>10} {:>10} {:>10} {:>6}  {}",
            e.group,
            e.quantity,
            e.h[0],
            e.values[0],
            opt(e.order, &|v| format!("{v:.2}")),
            opt(e.extrapolated, &|v| format!("{v:.6e}")),
            opt(e.error, &|v| format!("{v:.2e}")),
            opt(e.gci, &|v| format!("{v:.2e}")),
            e.true_error().map_or("-".into(), |v| format!("{v:.2e}")),
            opt(e.effectivity(), &|v| format!("{v:.2}")),
            e.behaviour.label()
        );
    }
    s
}

/// The estimate of the finest triple of each group and quantity.
pub fn finest(est: &[Estimate]) -> Vec<&Estimate> {
    let mut out: Vec<&Estimate> = Vec::new();
    for e in est {
        let better = |o: &&Estimate| o.group == e.group && o.quantity == e.quantity;
        match out.iter().position(better) {
            Some(i) if out[i].h[0] > e.h[0] => out[i] = e,
            Some(_) => {}
            None => out.push(e),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_power_law_gives_its_order_and_limit_exactly() {
        // phi(h) = 2 + 0.3 h^p on unequal ratios: the fixed point recovers
        // p and the limit to round-off, and the estimate is the true error.
        for p in [1.0, 1.5, 2.0, 3.0] {
            let h = [0.1, 0.25, 0.4];
            let phi = h.map(|h: f64| 2.0 + 0.3 * h.powf(p));
            let (order, b, ext, err, gci) = estimate(h, phi, 0.0);
            assert!((order - p).abs() < 1e-9, "{order} vs {p}");
            assert_eq!(b, Behaviour::Monotone);
            assert!((ext - 2.0).abs() < 1e-12);
            assert!((err - 0.3 * 0.1f64.powf(p)).abs() < 1e-12);
            assert!((gci / err - FS_THREE).abs() < 1e-12);
        }
    }

    #[test]
    fn oscillating_diverging_and_resolved_triples_are_named() {
        let h = [0.25, 0.5, 1.0];
        assert_eq!(observed_order(h, [1.0, 1.1, 0.8], 0.0).1, Behaviour::Oscillatory);
        assert_eq!(observed_order(h, [1.0, 1.2, 1.3], 0.0).1, Behaviour::Diverging);
        assert_eq!(observed_order(h, [1.0, 1.0, 1.0 + 1e-13], 0.0).1, Behaviour::Resolved);
        // A shear stress at round-off of the normal stresses beside it.
        assert_eq!(observed_order(h, [5e-11, 2e-11, 1e-11], 1e4).1, Behaviour::Resolved);
        assert_eq!(observed_order(h, [5e-11, 2e-11, 1e-11], 0.0).1, Behaviour::Diverging);
        // Order 8: beyond the credible range, so Fs = 3.
        let phi = h.map(|h: f64| 1.0 + h.powi(8));
        let (p, b, _, err, gci) = estimate(h, phi, 0.0);
        assert!((p - 8.0).abs() < 1e-6);
        assert_eq!(b, Behaviour::NotAsymptotic);
        assert!((gci / err - FS_UNRELIABLE).abs() < 1e-12);
    }

    fn run(h: f64, v: f64) -> RunResult {
        RunResult {
            id: format!("h={h}"),
            settings: vec![("h".into(), h.to_string())],
            completed: true,
            probes: vec![("p:uy".into(), v)],
            ..Default::default()
        }
    }

    #[test]
    fn a_triple_is_trusted_only_when_the_coarser_one_confirms_its_order() {
        // A clean power law over four sizes: the finer triple is confirmed
        // (same order), the coarsest has nothing to confirm it.
        let clean: Vec<RunResult> = [1.0, 0.5, 0.25, 0.125].iter().map(|&h| run(h, 1.0 + h * h)).collect();
        let est = estimates(&clean, "h");
        let at = |est: &[Estimate], h: f64| est.iter().find(|e| e.h[0] == h).unwrap().behaviour;
        assert_eq!(at(&est, 0.125), Behaviour::Monotone);
        assert_eq!(at(&est, 0.25), Behaviour::Unconfirmed);
        // Pre-asymptotic: the order drifts from 0.19 (not credible) to 1.67.
        let drift: Vec<RunResult> = [(1.0, 1.9), (0.5, 1.5), (0.25, 1.15), (0.125, 1.04)]
            .iter()
            .map(|&(h, v)| run(h, v))
            .collect();
        let est = estimates(&drift, "h");
        let fine = est.iter().find(|e| e.h[0] == 0.125).unwrap();
        assert_eq!(fine.behaviour, Behaviour::Unconfirmed, "{fine:?}");
        assert!((fine.gci / fine.error - FS_UNRELIABLE).abs() < 1e-12);
    }
}
