//! `[analysis]`: the solver settings, checked alone, against the analysis
//! kind and against the grid.

use super::*;

/// The solver settings of `[analysis]` every kind uses: load steps,
/// Newton's tolerance, iterations and cutbacks, the Ghost penalty, F-bar,
/// the dense eigenvalue limit and the blow-up factor.
pub(super) fn validate_solver(a: &AnalysisSpec) -> Result<(), FieldError> {
    if !(1..=1_000_000).contains(&a.load_steps) {
        return Err(FieldError::new("analysis.load_steps", "must be between 1 and 1000000"));
    }
    if !(a.tolerance > 0.0 && a.tolerance < 1.0) {
        return Err(FieldError::new("analysis.tolerance", "must lie in (0, 1)"));
    }
    if !(1..=1000).contains(&a.max_iterations) {
        return Err(FieldError::new("analysis.max_iterations", "must be between 1 and 1000"));
    }
    if a.max_cutbacks > 20 {
        return Err(FieldError::new(
            "analysis.max_cutbacks",
            "must be at most 20 (an increment of 2^-20 of a load step)",
        ));
    }
    if !(a.gamma_k >= 0.0 && a.gamma_k.is_finite()) {
        return Err(FieldError::new("analysis.gamma_k", "must be zero (off) or positive"));
    }
    if a.fbar && a.kind == crate::scene::AnalysisKind::ExplicitDynamics {
        return Err(FieldError::new(
            "analysis.fbar",
            "F-bar modifies the implicit paths only: kind = \"quasi-static-finite\" or \"dynamic-implicit\" \
             (F-bar), or \"quasi-static-linear\" (its small-strain counterpart, B-bar)",
        ));
    }
    if !a.update_points && a.kind != crate::scene::AnalysisKind::QuasiStaticLinear {
        return Err(FieldError::new(
            "analysis.update_points",
            "only the small-strain analysis (kind = \"quasi-static-linear\") can stay on one configuration: \
             the others follow the material by their definition",
        ));
    }
    if a.dense_limit > MAX_DENSE_LIMIT {
        return Err(FieldError::new(
            "analysis.dense_limit",
            format!("must be at most {MAX_DENSE_LIMIT}, got {}", a.dense_limit),
        ));
    }
    if !a.blowup_factor.is_finite() {
        return Err(FieldError::new("analysis.blowup_factor", "must be finite"));
    }
    Ok(())
}

/// What the analysis kind needs of the rest of the scene: dynamics
/// (explicit or implicit) its settings ([`validate_dynamic`]), a density
/// in every material and at most the free-motion exact solution; the
/// other kinds no `duration`.
pub(super) fn validate_kind(
    scene: &Scene,
    dirichlet: &[GridDirichlet],
    materials: &[Material],
) -> Result<(), FieldError> {
    let a = &scene.analysis;
    if a.kind.is_dynamic() {
        validate_dynamic(a, dirichlet)?;
        // Dynamics divides by mass: every material needs density.
        if let Some(k) = materials.iter().position(|m| !(m.density() > 0.0)) {
            return Err(FieldError::new(
                format!("material[{k}].density"),
                "dynamics needs a positive density",
            ));
        }
        // Static exact solutions grow with the load factor; dynamic
        // loads act in full from the start, so only free motion applies.
        if matches!(scene.exact, Some(ref e) if !matches!(e, ExactSpec::FreeMotion {})) {
            return Err(FieldError::new(
                "exact.name",
                "dynamics supports the free-motion exact solution only",
            ));
        }
    } else if a.duration.is_some() {
        return Err(FieldError::new(
            "analysis.duration",
            "only for kind = \"explicit-dynamics\" or \"dynamic-implicit\"",
        ));
    }
    Ok(())
}

/// Settings a dynamic analysis needs: its duration, the ghost mass
/// penalty, the blow-up factor, supports that hold (moving grid supports
/// are not time-dependent conditions: an implicit boundary moves, in
/// implicit dynamics), and implicit dynamics' integrator.
fn validate_dynamic(a: &AnalysisSpec, dirichlet: &[GridDirichlet]) -> Result<(), FieldError> {
    if a.kind == crate::scene::AnalysisKind::DynamicImplicit
        && a.integrator == crate::scene::Integrator::Bossak
        && !(-1.0 / 3.0..=0.0).contains(&a.bossak_alpha)
    {
        return Err(FieldError::new(
            "analysis.bossak_alpha",
            format!(
                "must lie in [-1/3, 0] (second order and unconditionally stable there), got {}",
                a.bossak_alpha
            ),
        ));
    }
    match a.duration {
        Some(d) if d > 0.0 && d.is_finite() => {}
        Some(_) => return Err(FieldError::new("analysis.duration", "must be positive")),
        None => {
            return Err(FieldError::new(
                "analysis.duration",
                "dynamics needs the simulated time `duration` (s)",
            ))
        }
    }
    if let Some(g) = a.gamma_m {
        if !(g >= 0.0 && g.is_finite()) {
            return Err(FieldError::new("analysis.gamma_m", "must be zero (off) or positive"));
        }
    }
    if !(a.blowup_factor > 1.0) {
        return Err(FieldError::new("analysis.blowup_factor", "must exceed 1"));
    }
    if dirichlet.iter().any(|d| d.value.iter().flatten().any(|v| *v != 0.0)) {
        return Err(FieldError::new(
            "dirichlet",
            "dynamics supports fixed and roller grid supports only (zero values); a prescribed motion is an \
             implicit boundary's `displacement` under kind = \"dynamic-implicit\"",
        ));
    }
    Ok(())
}

/// The analysis with the implicit boundaries' band width resolved: `delta`
/// (m) in `(0, h]`, when given, sets `delta_over_h`, which must lie in
/// `(0, 1]`.
pub(super) fn resolve_delta(a: &AnalysisSpec, grid: &Grid) -> Result<AnalysisSpec, FieldError> {
    let mut a = a.clone();
    if let Some(d) = a.delta {
        if !(d > 0.0 && d <= grid.h) {
            return Err(FieldError::new("analysis.delta", "must lie in (0, h]"));
        }
        a.delta_over_h = d / grid.h;
    }
    if !(a.delta_over_h > 0.0 && a.delta_over_h <= 1.0) {
        return Err(FieldError::new("analysis.delta_over_h", "must lie in (0, 1]"));
    }
    Ok(a)
}
