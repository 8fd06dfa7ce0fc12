//! Inertia as a contribution of an implicit step: Newmark time stepping
//! (the trapezoidal rule, or Bossak's alpha method) on the grid of an
//! updated-Lagrangian step, the grid reset every step.
//!
//! At the step's start the points' velocities are mapped to the grid with
//! the step's mass `M` (G (10)), `M v_n = sum_p m_p S_p^T v_p`, and the
//! grid's acceleration is the one the forces on it give: `M a_n = f_ext -
//! f_int(s_n) - f_c`, with the points' stresses `s_n` and the implicit
//! boundaries' force `f_c` at the end of the last step (the grid is fixed
//! in space, so it is carried over node by node). With Bossak's alpha that
//! force balances the inertia `M ((1 - alpha) a_n + alpha a_{n-1})`, so
//! `a_n` follows from the last step's start acceleration `a_{n-1}` (kept
//! per node; at the run's start `M a_0` balances it alone). An acceleration in
//! equilibrium with the stresses on the grid the step runs on makes the
//! trapezoidal rule conserve the grid's energy exactly for a linear
//! response (measured: to 1e-12 of it over 1000 steps); accelerations
//! carried by the points and mapped back (`M a_n = sum_p m_p S_p^T a_p`)
//! lose energy at every step where `M^-1` of the mapped field is not the
//! field (measured: 8.7% of G 5.2's energy against 1.3%). Over the step,
//! the nodes' whole motion `u = d + d^a` fixes Newmark's acceleration and
//! velocity
//!
//! ```text
//! a_{n+1}(u) = (u - dt v_n - dt^2 (1/2 - beta) a_n) / (beta dt^2)
//! v_{n+1}    = v_n + dt ((1 - gamma) a_n + gamma a_{n+1})
//! ```
//!
//! and the inertial force `f_I = M ((1 - alpha) a_{n+1} + alpha a_n)`
//! joins the residual `r = f_ext - f_int - ... - f_I`, its block `(1 -
//! alpha) M / (beta dt^2)` the tangent. `M` is lumped `diag(sum_p m_p
//! S_vp)`, consistent `sum_p m_p S_p^T S_p` (G (9)) or stabilised `M +
//! gamma_M J_G` (G (20)), with the same blocks as the stiffness: the
//! point groups and the ghost faces. The trapezoidal rule is `alpha = 0,
//! beta = 1/4, gamma = 1/2`; Bossak's `alpha` in `[-1/3, 0]` takes `gamma
//! = 1/2 - alpha`, `beta = (1 - alpha)^2 / 4` (Wood, Bossak and
//! Zienkiewicz 1980).
//!
//! After the step the points take the grid's change of velocity (FLIP:
//! `v_p += sum_v S_vp (v_{n+1} - v_n)`; PIC: `v_p = sum_v S_vp v_{n+1}`)
//! and move with the displacement like every implicit step's points (`x_p
//! += D S d + S d^a`).
//!
//! The FLIP transfer changes the points' kinetic energy by exactly the
//! grid's less `1/2 dv.(M - M_c) dv`, `dv = v_{n+1} - v_n`, `M_c` the
//! consistent mass (`sum_p m_p v_p . S dv = (M v_n) . dv` and `sum_p m_p |S
//! dv|^2 = dv.M_c dv`): nothing with the consistent mass, the ghost term
//! `gamma_M J_G` with the stabilised one. A Newmark step's `dv` is far
//! larger than an explicit step's, so the ghost mass penalty of implicit
//! dynamics defaults to a thousandth of G's `rho/4`
//! ([`crate::model::Model::gamma_m`]): it only has to make `M` invertible
//! for the mapping (the tangent's conditioning is the ghost stiffness'
//! job, G (27)).

use super::contribution::{At, Contribution};
use super::frame::Frame;
use crate::assembly::{Dof, Mapping};
use crate::dynamics::GridMass;
use crate::geometry::P2;
use crate::ghost::{self, GhostFace};
use crate::linalg::norm;
use crate::points::Points;
use crate::report::StepFailure;
use crate::scene::{Integrator, MassKind, VelocityUpdate};
use crate::state::Simulation;

/// The time integrator's constants for one step of size `dt` (s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Newmark {
    pub dt: f64,
    pub beta: f64,
    pub gamma: f64,
    /// Bossak's `alpha` (0: Newmark's rule with `beta`, `gamma`).
    pub alpha: f64,
}

impl Newmark {
    /// The scene's integrator over a step of `dt` (s).
    pub fn of(sim: &Simulation, dt: f64) -> Newmark {
        let a = &sim.model.analysis;
        match a.integrator {
            Integrator::Trapezoidal => Newmark {
                dt,
                beta: 0.25,
                gamma: 0.5,
                alpha: 0.0,
            },
            Integrator::Bossak => {
                let alpha = a.bossak_alpha;
                Newmark {
                    dt,
                    beta: 0.25 * (1.0 - alpha) * (1.0 - alpha),
                    gamma: 0.5 - alpha,
                    alpha,
                }
            }
        }
    }

    /// `a_{n+1}` of a node that moves by `u` over the step from velocity
    /// `v` and acceleration `a`.
    fn acceleration(&self, u: f64, v: f64, a: f64) -> f64 {
        let dt = self.dt;
        (u - dt * v - dt * dt * (0.5 - self.beta) * a) / (self.beta * dt * dt)
    }

    /// The factor of the mass in the tangent: `(1 - alpha) / (beta dt^2)`.
    fn stiffness_factor(&self) -> f64 {
        (1.0 - self.alpha) / (self.beta * self.dt * self.dt)
    }
}

/// The step's mass, per the scene: its kind and ghost penalty (`gamma_M`
/// is used only by the stabilised mass).
#[derive(Clone, Copy, Debug)]
struct MassOf {
    kind: MassKind,
    gamma_m: f64,
}

/// Inertia in one implicit step: the integrator, the mass, and the grid's
/// velocity and acceleration at the step's start.
pub(crate) struct Inertia {
    pub scheme: Newmark,
    mass: MassOf,
    /// The faces of the ghost mass penalty (G 4.2; none unless the mass is
    /// stabilised).
    faces: Vec<GhostFace>,
    /// `v_n`, `a_n` per grid node (m/s, m/s^2).
    pub v0: Vec<P2>,
    pub a0: Vec<P2>,
    /// `|M (v_n / (beta dt) + (1/(2 beta) - 1) a_n)|` on the free dofs
    /// (N): the inertial force of the step's start motion, which the
    /// residual is measured against with the loads and the reactions
    /// (else a body in free flight has no force to measure it by).
    scale: f64,
    /// How the points take the grid's new velocity.
    update: VelocityUpdate,
}

impl Inertia {
    /// Inertia of the step `frame` over `scheme`: the mass of its points,
    /// the grid's start velocity mapped from them and the start
    /// acceleration `M ((1 - alpha) a_n + alpha a_{n-1}) = r` of the
    /// out-of-balance force `r = f_ext - f_int - f_c` (free dofs), with
    /// the last step's start acceleration `previous` per node (empty at
    /// the run's start: `M a_0 = r`).
    pub fn new(frame: &Frame, scheme: Newmark, r: &[f64], previous: &[P2]) -> Result<Inertia, StepFailure> {
        let sim = frame.sim;
        let a = &sim.model.analysis;
        let gamma_m = sim.params.gamma_m;
        let kind = match a.mass {
            MassKind::Stabilised if gamma_m == 0.0 => MassKind::Consistent,
            k => k,
        };
        let map = &frame.map;
        let faces = if kind == MassKind::Stabilised {
            ghost::faces_of(&sim.model.grid, map, a.ghost_cells)
        } else {
            Vec::new()
        };
        let pts = &sim.state.points;
        let grid_mass = GridMass::new(sim, map, &faces, kind, gamma_m, sim.model.max_memory).map_err(|e| {
            match e.at_step(frame.step) {
                StepFailure::Singular { step, reason } => StepFailure::Singular {
                    step,
                    reason: format!(
                        "the {} mass that maps the points' velocities to the grid: {}{}",
                        kind.label(),
                        reason.replacen("the stiffness matrix", "it", 1),
                        if kind == MassKind::Consistent {
                            " (G 3.3: the consistent mass is singular where points barely touch nodes; \
                             mass = \"stabilised\" adds gamma_M J_G)"
                        } else {
                            ""
                        }
                    ),
                },
                other => other,
            }
        })?;
        let (v0, mut a0) = grid_mass.map_points_and_solve(map, &pts.mass, &pts.v, r);
        grid_mass.recycle(sim);
        if !previous.is_empty() && scheme.alpha != 0.0 {
            let alpha = scheme.alpha;
            for (a, p) in a0.iter_mut().zip(previous) {
                for c in 0..2 {
                    a[c] = (a[c] - alpha * p[c]) / (1.0 - alpha);
                }
            }
        }
        let mut inertia = Inertia {
            scheme,
            mass: MassOf { kind, gamma_m },
            faces,
            v0,
            a0,
            scale: 0.0,
            update: a.velocity_update,
        };
        let start = inertia.effective(map, &vec![[0.0; 2]; inertia.v0.len()]);
        let f = inertia.mass_times(map, pts, &start, true);
        inertia.scale = norm(&free_values(frame, &f));
        for (what, v) in [("velocity", &inertia.v0), ("acceleration", &inertia.a0)] {
            if v.iter().flatten().any(|x| !x.is_finite()) {
                return Err(StepFailure::NonFinite {
                    step: frame.step,
                    what: format!("grid {what} mapped from the points (mass {})", kind.label()),
                    residuals: Vec::new(),
                });
            }
        }
        Ok(inertia)
    }

    /// `a_{n+1}` per node for the nodes' whole motion `motion`.
    pub fn acceleration(&self, map: &Mapping, motion: &[P2]) -> Vec<P2> {
        let s = &self.scheme;
        let mut a = vec![[0.0; 2]; motion.len()];
        for (n, dofs) in map.dofs.node_dof.iter().enumerate() {
            for c in 0..2 {
                if dofs[c] != Dof::Inactive {
                    a[n][c] = s.acceleration(motion[n][c], self.v0[n][c], self.a0[n][c]);
                }
            }
        }
        a
    }

    /// The acceleration the inertial force acts with: `(1 - alpha)
    /// a_{n+1} + alpha a_n` per node.
    fn effective(&self, map: &Mapping, motion: &[P2]) -> Vec<P2> {
        let alpha = self.scheme.alpha;
        let mut a = self.acceleration(map, motion);
        for (a, a0) in a.iter_mut().zip(&self.a0) {
            a[0] = (1.0 - alpha) * a[0] + alpha * a0[0];
            a[1] = (1.0 - alpha) * a[1] + alpha * a0[1];
        }
        a
    }

    /// `v_{n+1}` per node from `a_{n+1}`.
    pub fn velocity(&self, a1: &[P2]) -> Vec<P2> {
        let s = &self.scheme;
        let mut v = self.v0.clone();
        for ((v, a0), a1) in v.iter_mut().zip(&self.a0).zip(a1) {
            for c in 0..2 {
                v[c] += s.dt * ((1.0 - s.gamma) * a0[c] + s.gamma * a1[c]);
            }
        }
        v
    }

    /// `M x` per node for the nodal field `x` (the ghost mass term only
    /// when `stabilised`).
    fn mass_times(&self, map: &Mapping, pts: &Points, x: &[P2], stabilised: bool) -> Vec<P2> {
        let mut f = vec![[0.0; 2]; x.len()];
        for p in 0..pts.len() {
            let m = pts.mass[p];
            if m == 0.0 {
                continue;
            }
            let st = map.stencils.get(p);
            match self.mass.kind {
                MassKind::Lumped => {
                    for (n, w, _) in st.iter() {
                        f[n][0] += m * w * x[n][0];
                        f[n][1] += m * w * x[n][1];
                    }
                }
                _ => {
                    let xp = st.interpolate(|n| x[n]);
                    for (n, w, _) in st.iter() {
                        f[n][0] += m * w * xp[0];
                        f[n][1] += m * w * xp[1];
                    }
                }
            }
        }
        if stabilised {
            for (f, g) in f.iter_mut().zip(ghost::force(&self.faces, self.mass.gamma_m, x)) {
                f[0] += g[0];
                f[1] += g[1];
            }
        }
        f
    }

    /// The inertial force `f_I` per node at the nodes' whole motion.
    pub fn force(&self, frame: &Frame, motion: &[P2]) -> Vec<P2> {
        let a = self.effective(&frame.map, motion);
        self.mass_times(&frame.map, &frame.sim.state.points, &a, true)
    }

    /// The kinetic energy `v.M v / 2` of grid velocities `v` (J).
    pub fn kinetic_energy(&self, frame: &Frame, v: &[P2]) -> f64 {
        let mv = self.mass_times(&frame.map, &frame.sim.state.points, v, true);
        0.5 * mv.iter().zip(v).map(|(f, v)| f[0] * v[0] + f[1] * v[1]).sum::<f64>()
    }

    /// The points' velocities after the step whose nodes moved by
    /// `motion`, and the grid's `v_{n+1}`.
    pub fn point_update(&self, frame: &Frame, motion: &[P2]) -> (Vec<P2>, Vec<P2>) {
        let (map, pts) = (&frame.map, &frame.sim.state.points);
        let a1 = self.acceleration(map, motion);
        let v1 = self.velocity(&a1);
        let mut v = Vec::with_capacity(pts.len());
        for p in 0..pts.len() {
            let st = map.stencils.get(p);
            let vp = match self.update {
                VelocityUpdate::Flip => {
                    let dv = st.interpolate(|n| [v1[n][0] - self.v0[n][0], v1[n][1] - self.v0[n][1]]);
                    let old = pts.velocity(p);
                    [old[0] + dv[0], old[1] + dv[1]]
                }
                VelocityUpdate::Pic => st.interpolate(|n| v1[n]),
            };
            v.push(vp);
        }
        (v, v1)
    }

    /// `f - f_I` on the free dofs: the inertial force at the nodes' whole
    /// motion `motion`, or with `None` the start's `M a_n`, taken from
    /// `f` (free dofs): the force the implicit boundaries react to.
    pub fn less_inertia(&self, frame: &Frame, f: &[f64], motion: Option<&[P2]>) -> Vec<f64> {
        let fi = match motion {
            Some(u) => self.force(frame, u),
            None => self.mass_times(&frame.map, &frame.sim.state.points, &self.a0, true),
        };
        let fi = free_values(frame, &fi);
        f.iter().zip(&fi).map(|(f, i)| f - i).collect()
    }

    /// The mass's kind in use (stabilised only with `gamma_M > 0`).
    pub fn mass_kind(&self) -> MassKind {
        self.mass.kind
    }
}

/// The free components of a per-node field, by free dof.
fn free_values(frame: &Frame, f: &[P2]) -> Vec<f64> {
    let mut out = vec![0.0; frame.map.dofs.n_free];
    for (n, dofs) in frame.map.dofs.node_dof.iter().enumerate() {
        for c in 0..2 {
            if let Dof::Free(i) = dofs[c] {
                out[i] = f[n][c];
            }
        }
    }
    out
}

/// Inertia as a contribution: its blocks are the point groups' and the
/// ghost faces', its force `f_I` and its block `(1 - alpha) M / (beta
/// dt^2)`. Shared with the driver, which reads the grid's motion after
/// the step.
impl Contribution for std::sync::Arc<Inertia> {
    fn name(&self) -> &'static str {
        "inertia"
    }

    fn blocks<'a>(&'a self, frame: &'a Frame) -> Vec<&'a [usize]> {
        let mut b: Vec<&[usize]> = frame.map.groups.iter().map(|g| g.nodes.as_slice()).collect();
        b.extend(self.faces.iter().map(|f| f.nodes.as_slice()));
        b
    }

    fn internal(&self, at: &At, r: &mut [f64]) -> f64 {
        let f = free_values(at.frame, &self.force(at.frame, at.motion));
        for (r, f) in r.iter_mut().zip(&f) {
            *r -= f;
        }
        norm(&f) + self.scale
    }

    fn block(&self, k: usize, at: &At, out: &mut Vec<f64>) -> Result<(), StepFailure> {
        let groups = at.frame.map.groups.len();
        if k >= groups {
            let gamma = if at.stabilised {
                self.mass.gamma_m * self.scheme.stiffness_factor()
            } else {
                0.0
            };
            self.faces[k - groups].stiffness(gamma, out);
            return Ok(());
        }
        let m2 = 2 * at.frame.map.groups[k].nodes.len();
        out.clear();
        out.resize(m2 * m2, 0.0);
        self.add_group_block(k, at, out);
        Ok(())
    }

    /// A point group's block is `(scalar) (x) I_2`: its x-y entries are
    /// zeros, so only the x-x and y-y ones are added.
    fn add_block(&self, k: usize, at: &At, out: &mut [f64], scratch: &mut Vec<f64>) -> Result<(), StepFailure> {
        let map = &at.frame.map;
        if k >= map.groups.len() || out.len() != (2 * map.groups[k].nodes.len()).pow(2) {
            return super::contribution::add_formed(self, k, at, out, scratch);
        }
        self.add_group_block(k, at, out);
        Ok(())
    }
}

impl Inertia {
    /// Add point group `k`'s block `(1 - alpha) / (beta dt^2) sum_p m_p
    /// S_a S_b (x) I_2` (the lumped mass: its diagonal) to `out`, row-major
    /// `2n x 2n` over the group's `n` nodes.
    fn add_group_block(&self, k: usize, at: &At, out: &mut [f64]) {
        let (map, pts) = (&at.frame.map, &at.frame.sim.state.points);
        let c0 = self.scheme.stiffness_factor();
        // A group's points share one stencil node list, the group's
        // (`assembly::groups`): a stencil's index is the block's.
        let g = &map.groups[k];
        let n = g.nodes.len();
        let m2 = 2 * n;
        // The scalar block `sum_p m_p c0 S_a S_b` and a point's weights on
        // the stack for stencils of up to 4 x 4 nodes (GIMP's).
        const SMALL: usize = 16;
        let (mut small, mut large) = ([0.0; SMALL * SMALL + SMALL], Vec::new());
        let buffer: &mut [f64] = if n <= SMALL {
            &mut small[..n * n + n]
        } else {
            large.resize(n * n + n, 0.0);
            &mut large
        };
        let (scalar, w) = buffer.split_at_mut(n * n);
        for &p in &g.points {
            let m = pts.mass[p] * c0;
            if m == 0.0 {
                continue;
            }
            let st = map.stencils.get(p);
            debug_assert_eq!(st.len(), n);
            for (b, w) in w.iter_mut().enumerate() {
                *w = st.w(b);
            }
            for a in 0..n {
                let wa = m * w[a];
                match self.mass.kind {
                    MassKind::Lumped => scalar[a * n + a] += wa,
                    _ => {
                        for (s, wb) in scalar[a * n..(a + 1) * n].iter_mut().zip(&*w) {
                            *s += wa * wb;
                        }
                    }
                }
            }
        }
        for a in 0..n {
            for b in 0..n {
                let v = scalar[a * n + b];
                out[2 * a * m2 + 2 * b] += v;
                out[(2 * a + 1) * m2 + 2 * b + 1] += v;
            }
        }
    }
}
