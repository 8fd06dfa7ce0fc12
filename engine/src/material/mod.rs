//! Constitutive models. Stress and strain use Voigt order `[xx, yy, xy]`
//! with engineering shear strain `gamma_xy = 2 e_xy`.

pub mod hencky;

use crate::scene::Plane;

/// Isotropic linear elasticity: Young's modulus `e` (Pa), Poisson's ratio
/// `nu`, mass density (kg/m^3), in plane strain or plane stress.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearElastic {
    pub e: f64,
    pub nu: f64,
    pub density: f64,
    pub plane: Plane,
}

impl LinearElastic {
    /// The 3x3 elasticity matrix `D` with `s = D e` (Pa).
    pub fn d_matrix(&self) -> [[f64; 3]; 3] {
        let (e, nu) = (self.e, self.nu);
        match self.plane {
            Plane::Strain => {
                let lambda = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
                let mu = e / (2.0 * (1.0 + nu));
                [
                    [lambda + 2.0 * mu, lambda, 0.0],
                    [lambda, lambda + 2.0 * mu, 0.0],
                    [0.0, 0.0, mu],
                ]
            }
            Plane::Stress => {
                let c = e / (1.0 - nu * nu);
                [[c, c * nu, 0.0], [c * nu, c, 0.0], [0.0, 0.0, c * (1.0 - nu) / 2.0]]
            }
        }
    }

    /// Out-of-plane stress `s_zz` (zero in plane stress).
    pub fn szz(&self, s: [f64; 3]) -> f64 {
        match self.plane {
            Plane::Strain => self.nu * (s[0] + s[1]),
            Plane::Stress => 0.0,
        }
    }
}

/// A material of the scene: its elasticity and, for von Mises plasticity,
/// its yield strength. One type for every analysis: the small-strain
/// paths read [`Material::d_matrix`], the finite-deformation and explicit
/// paths [`Material::hencky`].
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    pub elastic: LinearElastic,
    /// Von Mises yield strength `rho_y = sqrt(2 J2)` (Pa); `None`: elastic.
    pub yield_stress: Option<f64>,
    /// How the scene gave the strength (`rho_y`, `sigma_y` or `c_u`).
    pub strength: Option<crate::scene::Strength>,
}

impl Material {
    /// The small-strain elasticity matrix `C` (Pa), Voigt `[xx, yy, xy]`.
    pub fn d_matrix(&self) -> [[f64; 3]; 3] {
        self.elastic.d_matrix()
    }

    /// Mass density (kg/m^3).
    pub fn density(&self) -> f64 {
        self.elastic.density
    }

    /// The finite-strain response: Hencky elasticity with the same `E`,
    /// `nu`, and von Mises plasticity where a yield strength is given.
    pub fn hencky(&self) -> hencky::Hencky {
        hencky::Hencky {
            e: self.elastic.e,
            nu: self.elastic.nu,
            yield_stress: self.yield_stress,
        }
    }
}

/// `D e` for a 3x3 matrix and a Voigt vector.
pub fn mul3(d: &[[f64; 3]; 3], e: [f64; 3]) -> [f64; 3] {
    [
        d[0][0] * e[0] + d[0][1] * e[1] + d[0][2] * e[2],
        d[1][0] * e[0] + d[1][1] * e[1] + d[1][2] * e[2],
        d[2][0] * e[0] + d[2][1] * e[1] + d[2][2] * e[2],
    ]
}

#[cfg(test)]
mod tests {
    use super::mul3;

    /// `mul3` is the full product `D e`: every entry of a general
    /// (non-symmetric, anisotropic) D counts, not only the isotropic
    /// pattern the shipped materials fill. Small integers: exact.
    #[test]
    fn mul3_is_the_matrix_vector_product() {
        let d = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]];
        assert_eq!(mul3(&d, [1.0, 10.0, 100.0]), [321.0, 654.0, 987.0]);
    }
}
