//! The unit system a scene is written in, for labels only.
//!
//! The engine computes in whatever consistent units the scene's numbers
//! are in; `[scene] units` says which, so that every label (run table, TUI,
//! CSV headers, recording, charts) names the right unit. The scenes are
//! two-dimensional: forces, energies, masses and volumes are per unit
//! thickness out of the plane, and their labels say so (`N/m`, `J/m`).
//!
//! | system | length | force | stress | mass | time | energy |
//! |---|---|---|---|---|---|---|
//! | `SI` | m | N | Pa | kg | s | J |
//! | `mm-N-MPa` | mm | N | MPa | t (1000 kg) | s | N mm (mJ) |
//! | `m-kN-kPa` | m | kN | kPa | t (1000 kg) | s | kJ |

use serde::Deserialize;

/// A consistent unit system (force = mass x length / time^2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
pub enum Units {
    /// m, N, Pa, kg, s.
    #[default]
    #[serde(rename = "SI", alias = "si")]
    Si,
    /// mm, N, MPa, tonne, s (densities in t/mm^3, gravity in mm/s^2).
    #[serde(rename = "mm-N-MPa", alias = "mm-n-mpa")]
    MmNMpa,
    /// m, kN, kPa, tonne, s (geotechnical; densities in t/m^3).
    #[serde(rename = "m-kN-kPa", alias = "m-kn-kpa")]
    MKnKpa,
}

/// A kind of quantity that carries a unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quantity {
    Length,
    /// An area in the plane (a boundary's enclosed area).
    Area,
    Stress,
    /// A force per unit thickness (2D nodal forces, reactions, resultants).
    Force,
    /// An energy per unit thickness.
    Energy,
    /// A mass per unit thickness.
    Mass,
    /// A momentum per unit thickness.
    Momentum,
    Velocity,
    Time,
    /// Mass per volume (also the ghost mass penalty gamma_M).
    Density,
}

impl Units {
    /// The scene file's spelling.
    pub fn name(self) -> &'static str {
        match self {
            Units::Si => "SI",
            Units::MmNMpa => "mm-N-MPa",
            Units::MKnKpa => "m-kN-kPa",
        }
    }

    /// The unit of `q` (per unit thickness where `q` is).
    pub fn of(self, q: Quantity) -> &'static str {
        use Quantity::*;
        match (self, q) {
            (Units::Si, Length) => "m",
            (Units::Si, Area) => "m^2",
            (Units::Si, Stress) => "Pa",
            (Units::Si, Force) => "N/m",
            (Units::Si, Energy) => "J/m",
            (Units::Si, Mass) => "kg/m",
            (Units::Si, Momentum) => "kg/s",
            (Units::Si, Velocity) => "m/s",
            (Units::Si, Density) => "kg/m^3",
            (Units::MmNMpa, Length) => "mm",
            (Units::MmNMpa, Area) => "mm^2",
            (Units::MmNMpa, Stress) => "MPa",
            (Units::MmNMpa, Force) => "N/mm",
            (Units::MmNMpa, Energy) => "N mm/mm",
            (Units::MmNMpa, Mass) => "t/mm",
            (Units::MmNMpa, Momentum) => "t/s",
            (Units::MmNMpa, Velocity) => "mm/s",
            (Units::MmNMpa, Density) => "t/mm^3",
            (Units::MKnKpa, Length) => "m",
            (Units::MKnKpa, Area) => "m^2",
            (Units::MKnKpa, Stress) => "kPa",
            (Units::MKnKpa, Force) => "kN/m",
            (Units::MKnKpa, Energy) => "kJ/m",
            (Units::MKnKpa, Mass) => "t/m",
            (Units::MKnKpa, Momentum) => "t/s",
            (Units::MKnKpa, Velocity) => "m/s",
            (Units::MKnKpa, Density) => "t/m^3",
            (_, Time) => "s",
        }
    }

    /// One line for a run's header: the system and the per-thickness rule.
    pub fn describe(self) -> String {
        use Quantity::*;
        format!(
            "units {}: lengths {}, stresses {}, time {}; forces ({}) and energies ({}) per unit thickness",
            self.name(),
            self.of(Length),
            self.of(Stress),
            self.of(Time),
            self.of(Force),
            self.of(Energy)
        )
    }

    /// `name (unit)`, the form labels take.
    pub fn label(self, name: &str, q: Quantity) -> String {
        format!("{name} ({})", self.of(q))
    }
}
