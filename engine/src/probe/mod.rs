//! Probes: named quantities followed through a run (`[[probe]]` in a
//! scene): the fields at a material position (displacement, velocity in
//! dynamics, stress: a beam's tip, a corner; fitted from the points around
//! it, `fit.rs`), the material point nearest a position (on request), a
//! B-spline boundary (its traction
//! resultant and the mean displacement of its tracking points) or an
//! implicit boundary (its reaction and its prescribed displacement: a
//! footing's load against its settlement).
//!
//! Every step's report carries the probes' values
//! ([`crate::report::StepReport::probes`]), so the run table, the CSV file,
//! the TUI, the recording and the sweeps read the same numbers. Here the
//! probes and their values; how they are read off a simulation is in
//! `values.rs` (so that the model can hold probes without depending on the
//! simulation).

mod fit;
mod values;

pub use fit::FieldFit;

use crate::geometry::P2;
use crate::units::Quantity;

/// What a probe follows.
#[derive(Clone, Debug, PartialEq)]
pub enum ProbeTarget {
    /// The fields at the probe's material position, fitted from the
    /// points around it ([`FieldFit`]; `point = "field"`, the default).
    Field(FieldFit),
    /// Material point `p`: the one with volume nearest to the probe's
    /// position at the start (`point = "nearest"`).
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
    /// The position asked for (`at`), for a field or point probe: a field
    /// probe's values are the fields' there; a nearest point's tend to
    /// them as the points are refined.
    pub at: Option<P2>,
    /// Whether a field or point probe reports velocities (dynamics).
    pub velocity: bool,
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
    /// Velocity (length/time) of the field or the point, in dynamics.
    pub v: Option<P2>,
    /// The field's or the point's Cauchy stress `[xx, yy, xy]`.
    pub stress: Option<[f64; 3]>,
    /// Force per unit thickness: a boundary's traction resultant at the
    /// step's load factor, or the reaction an implicit boundary exerts on
    /// the material (zero before the first step; NaN, unknown, for a state
    /// resumed from a checkpoint before its first step).
    pub force: Option<P2>,
}

impl ProbeValue {
    /// The values as `(key, quantity, value)`: `ux`, `uy`, then `vx`, `vy`
    /// in dynamics and `sxx`, `syy`, `sxy` for a position, or `fx`, `fy`
    /// for a boundary. The keys of a probe are the same at every step.
    pub fn columns(&self) -> Vec<(&'static str, Quantity, f64)> {
        let mut c = vec![("ux", Quantity::Length, self.u[0]), ("uy", Quantity::Length, self.u[1])];
        if let Some(v) = self.v {
            c.extend([("vx", Quantity::Velocity, v[0]), ("vy", Quantity::Velocity, v[1])]);
        }
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
