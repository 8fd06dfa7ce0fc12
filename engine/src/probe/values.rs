//! A probe's values at a simulation's current state.

use super::{ProbeTarget, ProbeValue};
use crate::geometry::P2;
use crate::simulation::{Simulation, StepReport};

/// Mean displacement of points `idx`.
fn mean_displacement(sim: &Simulation, idx: &[usize]) -> P2 {
    let pts = sim.points();
    let n = idx.len().max(1) as f64;
    let s = idx.iter().fold([0.0; 2], |a, &p| {
        let u = pts.displacement(p);
        [a[0] + u[0], a[1] + u[1]]
    });
    [s[0] / n, s[1] / n]
}

impl Simulation {
    /// Every probe's values at the current state; forces come from
    /// `report`, the step that reached this state (without one: zero at
    /// the start, unknown (NaN) at a later step).
    pub fn probe_values(&self, report: Option<&StepReport>) -> Vec<ProbeValue> {
        let m = self.model();
        let pts = self.points();
        let unknown = if self.step_index() == 0 {
            [0.0; 2]
        } else {
            [f64::NAN; 2]
        };
        m.probes
            .iter()
            .map(|probe| {
                let velocity = |v: P2| probe.velocity.then_some(v);
                let (u, v, stress, force) = match &probe.target {
                    ProbeTarget::Field(fit) => (
                        fit.apply(|p| pts.displacement(p)),
                        velocity(fit.apply(|p| pts.velocity(p))),
                        Some(fit.apply(|p| pts.stress[p])),
                        None,
                    ),
                    ProbeTarget::Point(p) => (
                        pts.displacement(*p),
                        velocity(pts.velocity(*p)),
                        Some(pts.stress[*p]),
                        None,
                    ),
                    ProbeTarget::Boundary(b) => {
                        let name = &m.boundaries[*b].name;
                        let f = report
                            .and_then(|r| r.boundaries.iter().find(|x| &x.name == name))
                            .map_or(unknown, |x| x.resultant);
                        (mean_displacement(self, &m.boundaries[*b].points), None, None, Some(f))
                    }
                    ProbeTarget::Ibm(b) => {
                        let ib = &m.ibm[*b];
                        let f = report
                            .and_then(|r| r.ibm.iter().find(|x| x.name == ib.name))
                            .map_or(unknown, |x| x.reaction);
                        let u = match ib.spline {
                            Some((s, _)) => mean_displacement(self, &m.boundaries[s].points),
                            None => {
                                let (d, l) = (ib.motion(), self.load_factor());
                                [d[0] * l, d[1] * l]
                            }
                        };
                        (u, None, None, Some(f))
                    }
                };
                ProbeValue {
                    name: probe.name.clone(),
                    u,
                    v,
                    stress,
                    force,
                }
            })
            .collect()
    }
}
