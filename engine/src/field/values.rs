//! A field's values at the simulation's current state.

use super::Field;
use crate::simulation::Simulation;

impl Field {
    /// The field's value at every point.
    pub fn values(self, sim: &Simulation) -> Vec<f64> {
        let pts = sim.points();
        if self == Field::Error {
            return error_values(sim);
        }
        (0..pts.len())
            .map(|p| match self {
                Field::SigmaXx => pts.stress[p][0],
                Field::SigmaYy => pts.stress[p][1],
                Field::SigmaXy => pts.stress[p][2],
                Field::DisplacementMagnitude => {
                    let u = pts.displacement(p);
                    u[0].hypot(u[1])
                }
                Field::PlasticStrain => {
                    let m = sim.model().bodies[pts.body[p]].material;
                    match sim.model().materials[m].yield_stress {
                        Some(y) if pts.vol0[p] > 0.0 => pts.dissipation_at(p) / (pts.vol0[p] * y),
                        _ => 0.0,
                    }
                }
                Field::Speed => {
                    let v = pts.velocity(p);
                    v[0].hypot(v[1])
                }
                Field::Error => 0.0,
            })
            .collect()
    }
}

impl Field {
    /// The field's label in the scene's units ([`Field::label`]).
    pub fn label_for(self, sim: &Simulation) -> String {
        self.label(sim.model().units, exact_gives_displacement(sim))
    }
}

/// Whether the scene's exact solution gives a displacement (the error
/// field is then `|u - u_exact|`, else `|s_yy - s_yy,exact|`).
fn exact_gives_displacement(sim: &Simulation) -> bool {
    use crate::exact::ExactSolution;
    match &sim.model().exact {
        None | Some(ExactSolution::FreeMotion { .. }) => true,
        Some(e) => sim
            .points()
            .x0
            .first()
            .is_none_or(|&x| e.fields(x, 1.0).1.iter().all(|v| v.is_finite())),
    }
}

/// Per point error against the exact solution at the current load factor.
fn error_values(sim: &Simulation) -> Vec<f64> {
    use crate::exact::ExactSolution;
    let pts = sim.points();
    let Some(exact) = &sim.model().exact else {
        return vec![0.0; pts.len()];
    };
    let lambda = sim.load_factor();
    (0..pts.len())
        .map(|p| {
            let u = pts.displacement(p);
            let ue = match exact {
                ExactSolution::FreeMotion { fields, duration } => {
                    crate::exact::velocity_field(&fields[pts.body[p]], pts.x0[p]).map(|v| v * lambda * duration)
                }
                _ => exact.fields(pts.x0[p], lambda).1,
            };
            let e = if ue.iter().all(|v| v.is_finite()) {
                (u[0] - ue[0]).hypot(u[1] - ue[1])
            } else {
                (pts.stress[p][1] - exact.fields(pts.x0[p], lambda).0[1]).abs()
            };
            if e.is_finite() {
                e
            } else {
                0.0
            }
        })
        .collect()
}
