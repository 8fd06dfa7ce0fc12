//! Point fields that observers colour by: what each is called and its
//! unit here; its values at a state are in `values.rs` (so that the scene model
//! can name fields without depending on the simulation).

mod values;

/// A scalar per point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Field {
    SigmaXx,
    SigmaYy,
    SigmaXy,
    DisplacementMagnitude,
    /// Accumulated plastic strain `sum |d e_p|`: for the perfectly plastic
    /// von Mises return map the dissipation increment per reference volume
    /// is `rho_y |d e_p|`, so it is the dissipated work over `V0 rho_y`
    /// (zero for elastic materials).
    PlasticStrain,
    /// Speed `|v|` (explicit dynamics; m/s).
    Speed,
    /// Error against the scene's exact solution: `|u - u_exact|` where the
    /// exact displacement is known, else `|s_yy - s_yy,exact|`; zero
    /// without an exact solution.
    Error,
}

impl Field {
    pub const ALL: [Field; 7] = [
        Field::SigmaYy,
        Field::SigmaXx,
        Field::SigmaXy,
        Field::DisplacementMagnitude,
        Field::PlasticStrain,
        Field::Speed,
        Field::Error,
    ];

    pub fn label(self) -> &'static str {
        match self {
            Field::SigmaXx => "sigma_xx (Pa)",
            Field::SigmaYy => "sigma_yy (Pa)",
            Field::SigmaXy => "sigma_xy (Pa)",
            Field::DisplacementMagnitude => "|u| (m)",
            Field::PlasticStrain => "plastic strain",
            Field::Speed => "|v| (m/s)",
            Field::Error => "error vs exact",
        }
    }

    /// A short name for files and recordings (`sigma_yy`, `speed`, ...).
    pub fn key(self) -> &'static str {
        match self {
            Field::SigmaXx => "sigma_xx",
            Field::SigmaYy => "sigma_yy",
            Field::SigmaXy => "sigma_xy",
            Field::DisplacementMagnitude => "displacement_magnitude",
            Field::PlasticStrain => "plastic_strain",
            Field::Speed => "speed",
            Field::Error => "error",
        }
    }
}
