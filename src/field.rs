//! Point fields that observers colour by.

use crate::simulation::Simulation;

/// A scalar per point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Field {
    SigmaXx,
    SigmaYy,
    SigmaXy,
    DisplacementMagnitude,
}

impl Field {
    pub const ALL: [Field; 4] = [
        Field::SigmaYy,
        Field::SigmaXx,
        Field::SigmaXy,
        Field::DisplacementMagnitude,
    ];

    pub fn label(self) -> &'static str {
        match self {
            Field::SigmaXx => "sigma_xx (Pa)",
            Field::SigmaYy => "sigma_yy (Pa)",
            Field::SigmaXy => "sigma_xy (Pa)",
            Field::DisplacementMagnitude => "|u| (m)",
        }
    }

    /// The field's value at every point.
    pub fn values(self, sim: &Simulation) -> Vec<f64> {
        let pts = sim.points();
        (0..pts.len())
            .map(|p| match self {
                Field::SigmaXx => pts.stress[p][0],
                Field::SigmaYy => pts.stress[p][1],
                Field::SigmaXy => pts.stress[p][2],
                Field::DisplacementMagnitude => {
                    let u = pts.displacement(p);
                    u[0].hypot(u[1])
                }
            })
            .collect()
    }
}
