//! `[[material]]`: elasticity and von Mises yield, checked per analysis kind.

use super::*;
use crate::scene::Strength;

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
        if let Some(y) = m.yield_stress {
            return Err(FieldError::new(
                f("yield_stress"),
                format!(
                    "the key is gone, as ambiguous: it was G's radius rho_y = sqrt(2 J2); write rho_y = {y:e} \
                     for the same material, or give the uniaxial sigma_y or the undrained c_u"
                ),
            ));
        }
        let given: Vec<Strength> = [
            m.rho_y.map(Strength::RhoY),
            m.sigma_y.map(Strength::SigmaY),
            m.c_u.map(Strength::CU),
        ]
        .into_iter()
        .flatten()
        .collect();
        let strength = match m.model {
            MaterialModel::LinearElastic => {
                if let Some(g) = given.first() {
                    return Err(FieldError::new(f(g.key()), "only for model = \"von-mises\""));
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
                match given.as_slice() {
                    [] => {
                        return Err(FieldError::new(
                            f("rho_y"),
                            "von Mises needs its strength: rho_y (G's radius sqrt(2 J2)), sigma_y (uniaxial) or c_u (undrained shear)",
                        ))
                    }
                    [g] => {
                        let v = match *g {
                            Strength::RhoY(v) | Strength::SigmaY(v) | Strength::CU(v) => v,
                        };
                        if !(v > 0.0 && v.is_finite()) {
                            return Err(FieldError::new(f(g.key()), "must be positive"));
                        }
                        Some(*g)
                    }
                    [a, b, ..] => {
                        return Err(FieldError::new(
                            f(b.key()),
                            format!("give one of rho_y, sigma_y and c_u, not {} and {}", a.key(), b.key()),
                        ))
                    }
                }
            }
        };
        let ys = strength.map(Strength::rho_y);
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
            strength,
        });
    }

    Ok(materials)
}

#[cfg(test)]
mod tests {
    use crate::scene::Strength;

    /// The three strengths of one von Mises material: uniaxial tension
    /// at yield has `s_1 = sigma_y`, `s_2 = s_3 = 0`, so `J2 = sigma_y^2 /
    /// 3` and `sqrt(2 J2) = sqrt(2/3) sigma_y`; pure shear `tau = c_u` has
    /// `J2 = c_u^2`, so `sqrt(2 J2) = sqrt(2) c_u`. Round-off: 1e-15.
    #[test]
    fn the_three_von_mises_strengths_agree() {
        let rho = 2.0e4;
        for st in [
            Strength::RhoY(rho),
            Strength::SigmaY(rho * 1.5f64.sqrt()),
            Strength::CU(rho / 2f64.sqrt()),
        ] {
            assert!((st.rho_y() - rho).abs() <= 1e-15 * rho, "{st:?}");
            let [r, s, c] = st.all();
            let j2_uniaxial = s * s / 3.0;
            assert!(((2.0 * j2_uniaxial).sqrt() - r).abs() <= 1e-15 * rho, "{st:?}");
            assert!(((2.0 * c * c).sqrt() - r).abs() <= 1e-15 * rho, "{st:?}");
        }
    }
}
