//! Material point state, stored as a struct of arrays.

use crate::geometry::P2;
use std::collections::TryReserveError;

/// A copy of `v`, reserved fallibly.
fn try_clone<T: Clone>(v: &[T]) -> Result<Vec<T>, TryReserveError> {
    let mut c = Vec::new();
    c.try_reserve_exact(v.len())?;
    c.extend_from_slice(v);
    Ok(c)
}

/// Which of the per-point arrays that not every analysis reads a run
/// keeps ([`Points::keep`]): the others are empty, and their readers take
/// the value they would hold (identity, zero, not yielding). Small strain
/// keeps `strain`; finite deformation `def_grad`, `b_e`, `szz`,
/// `dissipation`, `yielding` and `lp0`; explicit dynamics those and `v`.
/// At 200,704 points a linear run keeps 127 bytes a point of 240 (26 MB
/// less at its peak).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tracked {
    /// `strain`.
    pub strain: bool,
    /// `def_grad`, `b_e`, `szz`, `dissipation`, `yielding`, `lp0`.
    pub finite: bool,
    /// `v`.
    pub velocity: bool,
}

/// All material points of a model. Index `p` runs over every array; the
/// arrays of a field the run does not track ([`Tracked`]) are empty.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct Points {
    /// Current position (m).
    pub x: Vec<P2>,
    /// Position at generation (m): the reference coordinate `X` exact
    /// solutions are evaluated at.
    pub x0: Vec<P2>,
    /// Current volume (m^3 per unit thickness).
    pub vol: Vec<f64>,
    pub vol0: Vec<f64>,
    /// Mass (kg per unit thickness).
    pub mass: Vec<f64>,
    /// Cauchy stress `[xx, yy, xy]` (Pa).
    pub stress: Vec<[f64; 3]>,
    /// Small strain `[xx, yy, gamma_xy]` accumulated over the steps.
    pub strain: Vec<[f64; 3]>,
    /// GIMP domain half-lengths (m).
    pub lp: Vec<P2>,
    /// Index of the body the point belongs to.
    pub body: Vec<usize>,
    /// Deformation gradient `[xx, xy, yx, yy]` (finite deformation).
    pub def_grad: Vec<[f64; 4]>,
    /// Elastic left Cauchy-Green tensor `[xx, yy, xy, zz]` (finite deformation).
    pub b_e: Vec<[f64; 4]>,
    /// Out-of-plane Cauchy stress (Pa).
    pub szz: Vec<f64>,
    /// Plastic work dissipated so far (J per unit thickness).
    pub dissipation: Vec<f64>,
    /// Whether the last step yielded.
    pub yielding: Vec<bool>,
    /// GIMP half-lengths at generation (m).
    pub lp0: Vec<P2>,
    /// Velocity (m/s; explicit dynamics).
    pub v: Vec<P2>,
}

impl Points {
    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Keep the arrays `tracked` names, empty the others, and release the
    /// spare capacity left by pushing the points one by one.
    pub fn keep(&mut self, tracked: Tracked) {
        if !tracked.strain {
            self.strain = Vec::new();
        }
        if !tracked.finite {
            self.def_grad = Vec::new();
            self.b_e = Vec::new();
            self.szz = Vec::new();
            self.dissipation = Vec::new();
            self.yielding = Vec::new();
            self.lp0 = Vec::new();
        }
        if !tracked.velocity {
            self.v = Vec::new();
        }
        self.shrink_to_fit();
    }

    /// Whether every array holds `n` entries, those `tracked` leaves out
    /// `n` or none (a checkpoint's points, before [`Points::keep`]).
    pub fn fits(&self, n: usize, tracked: Tracked) -> bool {
        let kept = |l: usize, keep: bool| l == n || (!keep && l == 0);
        [
            self.x.len(),
            self.x0.len(),
            self.vol.len(),
            self.vol0.len(),
            self.mass.len(),
            self.stress.len(),
            self.lp.len(),
            self.body.len(),
        ]
        .iter()
        .all(|&l| l == n)
            && kept(self.strain.len(), tracked.strain)
            && [
                self.def_grad.len(),
                self.b_e.len(),
                self.szz.len(),
                self.dissipation.len(),
                self.yielding.len(),
                self.lp0.len(),
            ]
            .iter()
            .all(|&l| kept(l, tracked.finite))
            && kept(self.v.len(), tracked.velocity)
    }

    /// Velocity of point `p` (m/s): zero where velocities are not tracked.
    pub fn velocity(&self, p: usize) -> P2 {
        self.v.get(p).copied().unwrap_or([0.0; 2])
    }

    /// Plastic work point `p` dissipated (J per unit thickness): zero where
    /// finite-deformation fields are not tracked.
    pub fn dissipation_at(&self, p: usize) -> f64 {
        self.dissipation.get(p).copied().unwrap_or(0.0)
    }

    /// Elastic left Cauchy-Green tensor of point `p` (`[xx, yy, xy, zz]`):
    /// the identity where finite-deformation fields are not tracked (a
    /// small-strain run's material tangent, evaluated on demand).
    pub fn b_e_at(&self, p: usize) -> [f64; 4] {
        self.b_e.get(p).copied().unwrap_or([1.0, 1.0, 0.0, 1.0])
    }

    /// Whether point `p` yielded in the last step.
    pub fn yielding_at(&self, p: usize) -> bool {
        self.yielding.get(p).copied().unwrap_or(false)
    }

    /// Release the spare capacity left by pushing the points one by one.
    pub fn shrink_to_fit(&mut self) {
        self.x.shrink_to_fit();
        self.x0.shrink_to_fit();
        self.vol.shrink_to_fit();
        self.vol0.shrink_to_fit();
        self.mass.shrink_to_fit();
        self.stress.shrink_to_fit();
        self.strain.shrink_to_fit();
        self.lp.shrink_to_fit();
        self.body.shrink_to_fit();
        self.def_grad.shrink_to_fit();
        self.b_e.shrink_to_fit();
        self.szz.shrink_to_fit();
        self.dissipation.shrink_to_fit();
        self.yielding.shrink_to_fit();
        self.lp0.shrink_to_fit();
        self.v.shrink_to_fit();
    }

    /// Room for `n` more points in every array, or the bytes that could not
    /// be had (nothing is then reserved beyond what was).
    pub fn try_reserve(&mut self, n: usize) -> Result<(), u64> {
        let bytes = (n as u64).saturating_mul(Points::BYTES_PER_POINT);
        let fail = |_| bytes;
        self.x.try_reserve_exact(n).map_err(fail)?;
        self.x0.try_reserve_exact(n).map_err(fail)?;
        self.vol.try_reserve_exact(n).map_err(fail)?;
        self.vol0.try_reserve_exact(n).map_err(fail)?;
        self.mass.try_reserve_exact(n).map_err(fail)?;
        self.stress.try_reserve_exact(n).map_err(fail)?;
        self.strain.try_reserve_exact(n).map_err(fail)?;
        self.lp.try_reserve_exact(n).map_err(fail)?;
        self.body.try_reserve_exact(n).map_err(fail)?;
        self.def_grad.try_reserve_exact(n).map_err(fail)?;
        self.b_e.try_reserve_exact(n).map_err(fail)?;
        self.szz.try_reserve_exact(n).map_err(fail)?;
        self.dissipation.try_reserve_exact(n).map_err(fail)?;
        self.yielding.try_reserve_exact(n).map_err(fail)?;
        self.lp0.try_reserve_exact(n).map_err(fail)?;
        self.v.try_reserve_exact(n).map_err(fail)?;
        Ok(())
    }

    /// Bytes one point takes in every array.
    pub const BYTES_PER_POINT: u64 = (2 * 16 + 3 * 8 + 2 * 24 + 16 + 8 + 2 * 32 + 2 * 8 + 1 + 16 + 16) as u64;

    /// A copy of the fields a small-strain step writes (`x`, `vol`, `lp`,
    /// `stress`, `strain`), the others left empty: the step computes the new
    /// state into it while the points stay as they were, and
    /// [`Points::take_written`] moves it in once the step has passed its
    /// checks (88 of the 240 bytes of a point). Reserved fallibly.
    pub(crate) fn small_strain_copy(&self) -> Result<Points, TryReserveError> {
        Ok(Points {
            x: try_clone(&self.x)?,
            vol: try_clone(&self.vol)?,
            lp: try_clone(&self.lp)?,
            stress: try_clone(&self.stress)?,
            strain: try_clone(&self.strain)?,
            ..Points::default()
        })
    }

    /// As [`Points::small_strain_copy`], the fields a finite-deformation
    /// step writes: `x`, `vol`, `lp`, `stress`, `def_grad`, `b_e`, `szz`,
    /// `dissipation`, `yielding` (145 of the 240 bytes of a point).
    pub(crate) fn finite_copy(&self) -> Result<Points, TryReserveError> {
        Ok(Points {
            x: try_clone(&self.x)?,
            vol: try_clone(&self.vol)?,
            lp: try_clone(&self.lp)?,
            stress: try_clone(&self.stress)?,
            def_grad: try_clone(&self.def_grad)?,
            b_e: try_clone(&self.b_e)?,
            szz: try_clone(&self.szz)?,
            dissipation: try_clone(&self.dissipation)?,
            yielding: try_clone(&self.yielding)?,
            ..Points::default()
        })
    }

    /// Move in the fields a step wrote into `next` (those it holds, as
    /// [`Points::small_strain_copy`] and [`Points::finite_copy`] make it);
    /// the others stay.
    pub(crate) fn take_written(&mut self, next: Points) {
        fn take<T>(into: &mut Vec<T>, from: Vec<T>) {
            if !from.is_empty() {
                *into = from;
            }
        }
        take(&mut self.x, next.x);
        take(&mut self.x0, next.x0);
        take(&mut self.vol, next.vol);
        take(&mut self.vol0, next.vol0);
        take(&mut self.mass, next.mass);
        take(&mut self.stress, next.stress);
        take(&mut self.strain, next.strain);
        take(&mut self.lp, next.lp);
        take(&mut self.body, next.body);
        take(&mut self.def_grad, next.def_grad);
        take(&mut self.b_e, next.b_e);
        take(&mut self.szz, next.szz);
        take(&mut self.dissipation, next.dissipation);
        take(&mut self.yielding, next.yielding);
        take(&mut self.lp0, next.lp0);
        take(&mut self.v, next.v);
    }

    /// Displacement since generation (m).
    pub fn displacement(&self, p: usize) -> P2 {
        [self.x[p][0] - self.x0[p][0], self.x[p][1] - self.x0[p][1]]
    }

    pub fn push(&mut self, x: P2, vol: f64, density: f64, lp: P2, body: usize) {
        self.x.push(x);
        self.x0.push(x);
        self.vol.push(vol);
        self.vol0.push(vol);
        self.mass.push(vol * density);
        self.stress.push([0.0; 3]);
        self.strain.push([0.0; 3]);
        self.lp.push(lp);
        self.body.push(body);
        self.def_grad.push([1.0, 0.0, 0.0, 1.0]);
        self.b_e.push([1.0, 1.0, 0.0, 1.0]);
        self.szz.push(0.0);
        self.dissipation.push(0.0);
        self.yielding.push(false);
        self.lp0.push(lp);
        self.v.push([0.0; 2]);
    }

    /// Kinetic energy `sum_p 1/2 m_p |v_p|^2` (J per unit thickness).
    pub fn kinetic_energy(&self) -> f64 {
        self.v
            .iter()
            .zip(&self.mass)
            .map(|(v, m)| 0.5 * m * (v[0].powi(2) + v[1].powi(2)))
            .sum()
    }

    /// Momentum `sum_p m_p v_p` (kg m/s per unit thickness).
    pub fn momentum(&self) -> P2 {
        self.v
            .iter()
            .zip(&self.mass)
            .fold([0.0; 2], |a, (v, m)| [a[0] + m * v[0], a[1] + m * v[1]])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LINEAR: Tracked = Tracked {
        strain: true,
        finite: false,
        velocity: false,
    };

    #[test]
    fn untracked_arrays_are_empty_and_read_as_their_initial_values() {
        let mut pts = Points::default();
        pts.push([0.5, 0.5], 0.25, 1000.0, [0.25, 0.25], 0);
        pts.push([1.5, 0.5], 0.25, 1000.0, [0.25, 0.25], 0);
        let full = pts.clone();
        pts.keep(LINEAR);
        assert!(pts.def_grad.is_empty() && pts.b_e.is_empty() && pts.szz.is_empty());
        assert!(pts.dissipation.is_empty() && pts.yielding.is_empty() && pts.lp0.is_empty() && pts.v.is_empty());
        assert_eq!((pts.strain.len(), pts.x.len()), (2, 2));
        // What the readers see is what a point holds at generation.
        assert_eq!(pts.velocity(1), full.v[1]);
        assert_eq!(pts.b_e_at(1), full.b_e[1]);
        assert_eq!(pts.dissipation_at(1), full.dissipation[1]);
        assert_eq!(pts.yielding_at(1), full.yielding[1]);
        assert_eq!((pts.kinetic_energy(), pts.momentum()), (0.0, [0.0; 2]));
        // A checkpoint's points fit with the untracked arrays full or empty,
        // not with a tracked one missing or any array short.
        assert!(pts.fits(2, LINEAR) && full.fits(2, LINEAR));
        let finite = Tracked {
            strain: false,
            finite: true,
            velocity: false,
        };
        assert!(!pts.fits(2, finite) && full.fits(2, finite));
        let mut short = full.clone();
        short.x0.pop();
        assert!(!short.fits(2, LINEAR));
        let mut half = full;
        half.b_e.pop();
        assert!(!half.fits(2, LINEAR));
    }
}
