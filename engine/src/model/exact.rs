//! `[exact]`: analytical solutions with the bodies' material and the scene's gravity.

use super::*;

pub(super) fn build_exact(
    spec: &ExactSpec,
    materials: &[Material],
    bodies: &[Body],
    gravity: P2,
) -> Result<ExactSolution, FieldError> {
    let values: Vec<f64> = match *spec {
        ExactSpec::ColumnFinite { base, top } | ExactSpec::ColumnSelfWeight { base, top } => vec![base, top],
        ExactSpec::UniaxialY { strain_yy, anchor } => vec![strain_yy, anchor[0], anchor[1]],
        ExactSpec::ConfinedY {
            stress_yy,
            base,
            angle_deg,
            about,
        } => vec![stress_yy, base, angle_deg, about[0], about[1]],
        ExactSpec::ConfinedYFinite {
            stretch,
            base,
            angle_deg,
            about,
        } => vec![stretch, base, angle_deg, about[0], about[1]],
        ExactSpec::Lame {
            pressure,
            r_inner,
            r_outer,
            center,
        } => vec![pressure, r_inner, r_outer, center[0], center[1]],
        ExactSpec::Kirsch { stress, radius } => vec![stress, radius],
        ExactSpec::SimpleShear { shear, x0 } => vec![shear, x0],
        ExactSpec::FreeMotion {} => Vec::new(),
    };
    if !values.iter().all(|v| v.is_finite()) {
        return Err(FieldError::new("exact", "parameters must be finite"));
    }
    let material = materials[bodies[0].material].elastic;
    if bodies.iter().any(|b| materials[b.material].elastic != material) {
        return Err(FieldError::new(
            "exact",
            "exact solutions need every body to share one material",
        ));
    }
    match *spec {
        ExactSpec::ColumnSelfWeight { base, top } => Ok(ExactSolution::ColumnSelfWeight {
            rho_g: column_weight(base, top, gravity, &material)?,
            base,
            top,
            material,
        }),
        ExactSpec::ColumnFinite { base, top } => Ok(ExactSolution::ColumnFinite {
            rho_g: column_weight(base, top, gravity, &material)?,
            base,
            top,
        }),
        ExactSpec::ConfinedY {
            stress_yy,
            base,
            angle_deg,
            about,
        } => Ok(ExactSolution::ConfinedY {
            stress_yy,
            base,
            angle: angle_deg.to_radians(),
            about,
            material,
        }),
        ExactSpec::ConfinedYFinite {
            stretch,
            base,
            angle_deg,
            about,
        } => {
            if !(stretch > 0.0 && stretch.is_finite()) {
                return Err(FieldError::new("exact.stretch", "must be positive"));
            }
            Ok(ExactSolution::ConfinedFinite {
                stretch,
                base,
                angle: angle_deg.to_radians(),
                about,
                material,
            })
        }
        ExactSpec::Lame {
            pressure,
            r_inner,
            r_outer,
            center,
        } => {
            if !(r_inner > 0.0 && r_outer > r_inner) {
                return Err(FieldError::new("exact.r_outer", "need 0 < r_inner < r_outer"));
            }
            Ok(ExactSolution::Lame {
                p: pressure,
                a: r_inner,
                b: r_outer,
                center,
                material,
            })
        }
        ExactSpec::Kirsch { stress, radius } => {
            if !(radius > 0.0) {
                return Err(FieldError::new("exact.radius", "must be positive"));
            }
            Ok(ExactSolution::Kirsch {
                s: stress,
                a: radius,
                material,
            })
        }
        ExactSpec::SimpleShear { shear, x0 } => Ok(ExactSolution::SimpleShear { g: shear, x0, material }),
        ExactSpec::FreeMotion {} => Err(FieldError::new("exact.name", "free-motion is built by the caller")),
        ExactSpec::UniaxialY { strain_yy, anchor } => {
            if !strain_yy.is_finite() || !anchor.iter().all(|a| a.is_finite()) {
                return Err(FieldError::new("exact", "parameters must be finite"));
            }
            Ok(ExactSolution::UniaxialY {
                strain_yy,
                anchor,
                material,
            })
        }
    }
}

/// The unit weight `rho g` of a column solution, checking its geometry and gravity.
pub(super) fn column_weight(base: f64, top: f64, gravity: P2, material: &LinearElastic) -> Result<f64, FieldError> {
    if !(top > base) {
        return Err(FieldError::new("exact.top", "must exceed `base`"));
    }
    if gravity[0] != 0.0 || !(gravity[1] < 0.0) {
        return Err(FieldError::new(
            "loads.gravity",
            "the column solution needs gravity = [0, -g] with g > 0",
        ));
    }
    Ok(-material.density * gravity[1])
}
