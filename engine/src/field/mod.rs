//! Point fields that observers colour by: what each is called and its
//! unit here; its values at a state are in `values.rs` (so that the scene model
//! can name fields without depending on the simulation).

mod values;

use crate::units::{Quantity, Units};

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

    /// The field's name with its unit in `units`. The error is a
    /// displacement where the scene's exact solution gives one
    /// (`exact_displacement`), else a stress.
    pub fn label(self, units: Units, exact_displacement: bool) -> String {
        let q = match self {
            Field::SigmaXx | Field::SigmaYy | Field::SigmaXy => Some(Quantity::Stress),
            Field::DisplacementMagnitude => Some(Quantity::Length),
            Field::PlasticStrain => None,
            Field::Speed => Some(Quantity::Velocity),
            Field::Error if exact_displacement => Some(Quantity::Length),
            Field::Error => Some(Quantity::Stress),
        };
        let name = match self {
            Field::SigmaXx => "sigma_xx",
            Field::SigmaYy => "sigma_yy",
            Field::SigmaXy => "sigma_xy",
            Field::DisplacementMagnitude => "|u|",
            Field::PlasticStrain => "plastic strain",
            Field::Speed => "|v|",
            Field::Error if exact_displacement => "|u - u_exact|",
            Field::Error => "|s_yy - s_yy,exact|",
        };
        match q {
            Some(q) => units.label(name, q),
            None => name.to_string(),
        }
    }

    /// Whether the field takes both signs (a stress component: drawn with
    /// a diverging colour map centred at zero) or is a magnitude.
    pub fn signed(self) -> bool {
        matches!(self, Field::SigmaXx | Field::SigmaYy | Field::SigmaXy)
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
