//! `[exact]`: analytical solutions with the bodies' material and the scene's gravity.

use super::*;

/// The scene's `[exact]` solution, if any: free motion from the bodies'
/// velocity fields, any other from [`build_exact`].
pub(super) fn build_exact_solution(
    scene: &Scene,
    materials: &[Material],
    bodies: &[Body],
    gravity: P2,
) -> Result<Option<ExactSolution>, FieldError> {
    match &scene.exact {
        None => Ok(None),
        Some(ExactSpec::FreeMotion {}) => free_motion(scene, materials, bodies).map(Some),
        Some(spec) => Ok(Some(build_exact(spec, materials, bodies, gravity)?)),
    }
}

/// The free-motion solution: each body moving with its initial velocity
/// field over the explicit run's duration, exact only for stress-free
/// bodies when the field has a gradient.
fn free_motion(scene: &Scene, materials: &[Material], bodies: &[Body]) -> Result<ExactSolution, FieldError> {
    let duration = match (scene.analysis.kind, scene.analysis.duration) {
        (kind, Some(d)) if kind.is_dynamic() => d,
        _ => {
            return Err(FieldError::new(
                "exact.name",
                "free-motion needs kind = \"explicit-dynamics\" or \"dynamic-implicit\" with a duration",
            ))
        }
    };
    let strained = bodies
        .iter()
        .zip(&scene.bodies)
        .any(|(b, spec)| materials[b.material].elastic.e != 0.0 && spec.velocity_gradient.is_some());
    if scene.bodies.iter().any(|b| b.velocity_mode.is_some()) {
        return Err(FieldError::new(
            "exact.name",
            "free motion keeps each point's initial velocity: a vibration mode (velocity_mode) does not",
        ));
    }
    if strained {
        return Err(FieldError::new(
            "exact.name",
            "free motion with a velocity gradient is exact only for stress-free (E = 0) bodies",
        ));
    }
    let fields = scene
        .bodies
        .iter()
        .map(|b| {
            (
                b.velocity,
                b.velocity_gradient.unwrap_or([[0.0; 2]; 2]),
                b.velocity_centre,
            )
        })
        .collect();
    Ok(ExactSolution::FreeMotion { fields, duration })
}

fn build_exact(
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
