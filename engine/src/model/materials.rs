//! `[[material]]`: elasticity and von Mises yield, checked per analysis kind.

use super::*;

/// The scene's materials, checked.
pub(super) fn build(scene: &Scene) -> Result<Vec<Material>, FieldError> {
    let mut materials: Vec<Material> = Vec::new();
    if scene.materials.is_empty() {
        return Err(FieldError::new("material", "at least one [[material]] is needed"));
    }
    let finite_kind = scene.analysis.kind != crate::scene::AnalysisKind::QuasiStaticLinear;
    for (k, m) in scene.materials.iter().enumerate() {
        let f = |n: &str| format!("material[{k}].{n}");
        if materials.iter().any(|x| x.name == m.name) {
            return Err(FieldError::new(
                f("name"),
                format!("material `{}` is defined twice", m.name),
            ));
        }
        let ys = match m.model {
            MaterialModel::LinearElastic => {
                if m.yield_stress.is_some() {
                    return Err(FieldError::new(f("yield_stress"), "only for model = \"von-mises\""));
                }
                None
            }
            MaterialModel::VonMises => {
                if !finite_kind {
                    return Err(FieldError::new(
                        f("model"),
                        "von Mises plasticity needs kind = \"quasi-static-finite\", \"explicit-dynamics\" or \"dynamic-implicit\"",
                    ));
                }
                match m.yield_stress {
                    Some(y) if y > 0.0 && y.is_finite() => Some(y),
                    _ => {
                        return Err(FieldError::new(
                            f("yield_stress"),
                            "von Mises needs a positive yield_stress",
                        ))
                    }
                }
            }
        };
        if finite_kind && m.plane != crate::scene::Plane::Strain {
            return Err(FieldError::new(
                f("plane"),
                "the finite-deformation and explicit analyses are plane strain",
            ));
        }
        // Dynamics has the mass to carry a step: E = 0 is a stress-free
        // material (G 5.1.2's stretching ghost).
        let dynamic = scene.analysis.kind.is_dynamic();
        if !((m.e > 0.0 || (dynamic && m.e == 0.0)) && m.e.is_finite()) {
            return Err(FieldError::new(
                f("E"),
                format!(
                    "Young's modulus must be positive{}, got {}",
                    if dynamic { " or zero" } else { "" },
                    number(m.e)
                ),
            ));
        }
        if !(m.nu > -1.0 && m.nu < 0.5) {
            return Err(FieldError::new(
                f("nu"),
                format!("Poisson's ratio must lie in (-1, 0.5), got {}", number(m.nu)),
            ));
        }
        if !(m.density >= 0.0 && m.density.is_finite()) {
            return Err(FieldError::new(f("density"), "must be non-negative"));
        }
        materials.push(Material {
            name: m.name.clone(),
            elastic: LinearElastic {
                e: m.e,
                nu: m.nu,
                density: m.density,
                plane: m.plane,
            },
            yield_stress: ys,
        });
    }

    Ok(materials)
}
