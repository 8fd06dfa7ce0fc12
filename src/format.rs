//! One formatter per reported quantity, shared by the run table
//! (`mpmlab run`), the terminal UI, the CSV step table and recordings, so
//! that a quantity reads the same wherever it is shown.

use crate::dynamics::DynamicsReport;
use crate::report::SolverReport;
use crate::solver::FactorKind;

/// The factorisation of a step's last system and the tangent's inertia:
/// `chol`, `ldlt-3` (three negative pivots: three negative eigenvalues, a
/// loss of stability or a spurious mode), `lu`; `-` when the step solved
/// nothing.
pub fn factor_label(s: &SolverReport) -> String {
    match (s.factorisation, s.negative_pivots) {
        (None, _) => "-".to_string(),
        (Some(FactorKind::Cholesky), _) => "chol".to_string(),
        (Some(FactorKind::Ldlt), Some(n)) => format!("ldlt-{n}"),
        (Some(k), _) => k.label().to_string(),
    }
}

/// The energy balance error over the initial energy (`None` when the
/// initial energy is zero: nothing to compare with).
pub fn relative_balance(d: &DynamicsReport) -> Option<f64> {
    (d.initial_energy > 0.0).then(|| d.energy_error / d.initial_energy)
}

/// `v` in scientific notation with `digits` after the point; `-` for none.
pub fn sci_or_dash(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".to_string(), |v| format!("{v:.digits$e}"))
}

/// A file's size: `1.23 GB`, `12.3 MB`, `45.6 kB`, `789 B` (recordings,
/// ParaView series; the engine's memory estimates have their own,
/// `model::bytes`).
pub fn human_bytes(b: f64) -> String {
    if b >= 1e9 {
        format!("{:.2} GB", b / 1e9)
    } else if b >= 1e6 {
        format!("{:.1} MB", b / 1e6)
    } else if b >= 1e3 {
        format!("{:.1} kB", b / 1e3)
    } else {
        format!("{b:.0} B")
    }
}
