//! Probes: named quantities followed through a run (`[[probe]]` in a
//! scene): the material point nearest a position (its displacement and
//! stress: a beam's tip, a corner), a B-spline boundary (its traction
//! resultant and the mean displacement of its tracking points) or an
//! implicit boundary (its reaction and its prescribed displacement: a
//! footing's load against its settlement).
//!
//! Every step's report carries the probes' values ([`StepReport::probes`]),
//! so the run table, the CSV file, the TUI, the recording and the sweeps
//! read the same numbers.

use crate::geometry::P2;
use crate::simulation::{Simulation, StepReport};
use crate::units::Quantity;

/// What a probe follows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProbeTarget {
    /// Material point `p` (the nearest to the probe's position at the start).
    Point(usize),
    /// B-spline boundary `b` of the model.
    Boundary(usize),
    /// Implicit boundary `b` of the model.
    Ibm(usize),
}

/// A named probe of a model.
#[derive(Clone, Debug, PartialEq)]
pub struct Probe {
    pub name: String,
    pub target: ProbeTarget,
}

/// A probe's values at a state.
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeValue {
    pub name: String,
    /// Displacement since the start (length): the point's; the mean over a
    /// boundary's tracking points; an implicit boundary's prescribed
    /// displacement at the load factor (a spline-following one: the mean
    /// of its spline's tracking points).
    pub u: P2,
    /// A point's Cauchy stress `[xx, yy, xy]`.
    pub stress: Option<[f64; 3]>,
    /// Force per unit thickness: a boundary's traction resultant at the
    /// step's load factor, or the reaction an implicit boundary exerts on
    /// the material (zero before the first step; NaN, unknown, for a state
    /// resumed from a checkpoint before its first step).
    pub force: Option<P2>,
}

impl ProbeValue {
    /// The values as `(key, quantity, value)`: `ux`, `uy`, then `sxx`,
    /// `syy`, `sxy` for a point or `fx`, `fy` for a boundary. The keys of a
    /// probe are the same at every step.
    pub fn columns(&self) -> Vec<(&'static str, Quantity, f64)> {
        let mut c = vec![("ux", Quantity::Length, self.u[0]), ("uy", Quantity::Length, self.u[1])];
        if let Some(s) = self.stress {
            c.extend([
                ("sxx", Quantity::Stress, s[0]),
                ("syy", Quantity::Stress, s[1]),
                ("sxy", Quantity::Stress, s[2]),
            ]);
        }
        if let Some(f) = self.force {
            c.extend([("fx", Quantity::Force, f[0]), ("fy", Quantity::Force, f[1])]);
        }
        c
    }
}

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
                let (u, stress, force) = match probe.target {
                    ProbeTarget::Point(p) => (pts.displacement(p), Some(pts.stress[p]), None),
                    ProbeTarget::Boundary(b) => {
                        let name = &m.boundaries[b].name;
                        let f = report
                            .and_then(|r| r.boundaries.iter().find(|x| &x.name == name))
                            .map_or(unknown, |x| x.resultant);
                        (mean_displacement(self, &m.boundaries[b].points), None, Some(f))
                    }
                    ProbeTarget::Ibm(b) => {
                        let ib = &m.ibm[b];
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
                        (u, None, Some(f))
                    }
                };
                ProbeValue {
                    name: probe.name.clone(),
                    u,
                    stress,
                    force,
                }
            })
            .collect()
    }
}
