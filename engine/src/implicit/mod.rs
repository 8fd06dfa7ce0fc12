//! The implicit core, shared by the small-strain step ([`crate::linear`])
//! and the Newton step ([`crate::newton`]):
//!
//! - [`Frame`]: what a step fixes at its start: the points on the grid
//!   (stencils, groups, dofs), the implicit boundaries' prescribed motion
//!   `d^a` and bands (C section 3), the ghost faces (G 4.2);
//! - [`Assembly`]: the step's [`Contribution`]s in one list, the sparsity
//!   pattern of their blocks (built once per step), the residual
//!   `r = f_ext - sum_c f_c` and the tangent `K = sum_c K_c` at an iterate;
//! - [`finish`]: commit the step's new point state and build its report.
//!
//! The small-strain step is the core with one solve and the linear
//! response (its points' stiffness `B^T D B`); the Newton step iterates
//! on the residual with the points' finite-deformation response.

pub(crate) mod band;
pub(crate) mod bbar;
mod contribution;
mod frame;
mod ghost;
mod inertia;
mod loads;
mod points;
mod traction;

pub(crate) use crate::linalg::norm;
pub(crate) use contribution::{At, Contribution};
pub(crate) use frame::{Closed, Frame, Interval};
pub(crate) use inertia::{Inertia, Newmark};

use crate::assembly::{Pattern, Storage};
use crate::boundary::BoundaryReport;
use crate::bulk::{evaluate_reusing, Iterate};
use crate::geometry::P2;
use crate::ibm::IbmReport;
use crate::linalg::{Condition, SparseRef};
use crate::points::Points;
use crate::report::{Energy, SolverReport, StepFailure, StepReport, Timings};
use crate::solver::Symmetry;
use crate::state::Simulation;

/// The residual of a finite-deformation step and its parts at one iterate.
pub(crate) struct Residual {
    /// The points' response.
    pub it: Iterate,
    /// `f_ext - sum_c f_c` on the free dofs.
    pub r: Vec<f64>,
    /// External force at this iterate (free dofs).
    pub fext: Vec<f64>,
    /// The norm the residual is measured against: external forces plus
    /// the reactions the contributions carry (grid supports, implicit
    /// boundaries).
    pub scale: f64,
}

/// A step's contributions in one list and the pattern of their blocks.
pub(crate) struct Assembly {
    pub list: Vec<Box<dyn Contribution>>,
    /// Symmetric unless a contribution is not: decides the storage and
    /// the factorisation.
    pub symmetry: Symmetry,
    pub pattern: Pattern,
    /// The pattern's blocks: [`Merged`].
    blocks: Merged,
    /// The responses' buffer of a residual no longer needed
    /// ([`Assembly::recycle`]), for the next one.
    spare: std::sync::Mutex<Vec<Option<crate::material::hencky::Response>>>,
}

/// The pattern's blocks, one per distinct node list: contributions whose
/// blocks are the same list (the same slice, as the inertia's and the
/// points' are the point groups') are summed into one block before it is
/// scattered, which halves the scatter of a dynamic step's tangent.
struct Merged {
    /// How many blocks the contributions have in all.
    total: usize,
    /// Per pattern block, the index of its first member among all blocks.
    first: Vec<usize>,
    /// Per pattern block `b`, its members `members[start[b]..start[b +
    /// 1]]`: (contribution, its block index), in the list's order.
    start: Vec<usize>,
    members: Vec<(usize, usize)>,
}

impl Merged {
    /// The pattern's blocks of `own` (per contribution, its node lists).
    fn new(own: &[Vec<&[usize]>]) -> Merged {
        let mut seen: std::collections::HashMap<(usize, usize), usize> = std::collections::HashMap::new();
        let mut first = Vec::new();
        let mut of = Vec::new();
        let mut total = 0;
        for (c, blocks) in own.iter().enumerate() {
            for (k, nodes) in blocks.iter().enumerate() {
                // Identity, not content: one slice of one frame.
                let key = (nodes.as_ptr() as usize, nodes.len());
                let b = *seen.entry(key).or_insert_with(|| {
                    first.push(total);
                    first.len() - 1
                });
                of.push((b, c, k));
                total += 1;
            }
        }
        // Stable: members keep the list's order within a block.
        of.sort_by_key(|m| m.0);
        let mut start = vec![0; first.len() + 1];
        for m in &of {
            start[m.0 + 1] += 1;
        }
        for b in 0..first.len() {
            start[b + 1] += start[b];
        }
        Merged {
            total,
            first,
            start,
            members: of.into_iter().map(|(_, c, k)| (c, k)).collect(),
        }
    }

    /// The node lists of the pattern's blocks from every block `all`.
    fn nodes<'a>(&self, all: &[&'a [usize]]) -> Vec<&'a [usize]> {
        self.first.iter().map(|&i| all[i]).collect()
    }
}

impl Assembly {
    /// The pattern of every contribution's blocks, in the list's order.
    pub fn new(frame: &Frame, list: Vec<Box<dyn Contribution>>) -> Result<Assembly, StepFailure> {
        let symmetry = if list.iter().all(|c| c.symmetric(frame)) {
            Symmetry::Symmetric
        } else {
            Symmetry::General
        };
        let storage = match symmetry {
            Symmetry::Symmetric => Storage::Lower,
            Symmetry::General => Storage::Full,
        };
        let own: Vec<Vec<&[usize]>> = list.iter().map(|c| c.blocks(frame)).collect();
        let blocks = Merged::new(&own);
        let all: Vec<&[usize]> = own.into_iter().flatten().collect();
        let pattern = Pattern::new(&frame.map.dofs, &blocks.nodes(&all), storage).map_err(|e| e.at_step(frame.step))?;
        drop(all);
        Ok(Assembly {
            list,
            symmetry,
            pattern,
            blocks,
            spare: std::sync::Mutex::new(Vec::new()),
        })
    }

    /// The matrix of `values` over the step's pattern.
    pub fn matrix<'v>(&'v self, values: &'v [f64]) -> SparseRef<'v> {
        self.pattern.matrix(values)
    }

    /// Every contribution's blocks at `at`: the matrix's values over the
    /// pattern and `K_fc du_c`, the free rows' coupling to the step's
    /// prescribed increments.
    pub fn stiffness(&self, at: &At) -> Result<(Vec<f64>, Vec<f64>), StepFailure> {
        let frame = at.frame;
        let all: Vec<&[usize]> = self.list.iter().flat_map(|c| c.blocks(frame)).collect();
        if all.len() != self.blocks.total {
            return Err(StepFailure::Internal {
                step: frame.step,
                message: "a contribution's blocks changed within the step".into(),
            });
        }
        let nodes = self.blocks.nodes(&all);
        // The first failure in block order (the same for any number of
        // threads).
        let failure = std::sync::Mutex::new(None::<(usize, StepFailure)>);
        let fail = |b: usize, e: StepFailure| {
            let mut f = failure.lock().unwrap_or_else(|e| e.into_inner());
            if f.as_ref().is_none_or(|(first, _)| b < *first) {
                *f = Some((b, e));
            }
        };
        let pool = frame.sim.pool.as_deref();
        let assembled = self.pattern.assemble_on(&frame.map.dofs, &nodes, pool, |b, out, more| {
            let m2 = 2 * nodes[b].len();
            let members = &self.blocks.members[self.blocks.start[b]..self.blocks.start[b + 1]];
            let Some((&(c, k), rest)) = members.split_first() else {
                out.clear();
                out.resize(m2 * m2, 0.0);
                return;
            };
            if let Err(e) = self.list[c].block(k, at, out) {
                fail(b, e);
                out.clear();
            }
            // A block of the wrong size is a bug of its contribution: a
            // failure naming it, not a panic in the assembly.
            if out.len() != m2 * m2 {
                fail(
                    b,
                    StepFailure::Internal {
                        step: frame.step,
                        message: format!(
                            "the {} contribution's block {k} has {} values for {} nodes",
                            self.list[c].name(),
                            out.len(),
                            m2 / 2
                        ),
                    },
                );
                out.clear();
                out.resize(m2 * m2, 0.0);
            }
            // The block's other members added to it, in the list's order.
            for &(c, k) in rest {
                if let Err(e) = self.list[c].add_block(k, at, out, more) {
                    fail(b, e);
                }
            }
        });
        let failure = failure.into_inner().unwrap_or_else(|e| e.into_inner()).map(|(_, e)| e);
        match (failure, assembled) {
            (Some(e), _) => Err(e),
            (None, Err(e)) => Err(e.at_step(frame.step)),
            (None, Ok(k)) => Ok(k),
        }
    }

    /// The residual at unknowns `d` (grid-prescribed components included)
    /// with the points' finite-deformation response: `f_ext` from every
    /// contribution in the list's order, then each one's force subtracted.
    pub fn residual(&self, frame: &Frame, d: &[P2]) -> Result<Residual, StepFailure> {
        let motion = frame.motion(d);
        let spare = std::mem::take(&mut *self.spare.lock().unwrap_or_else(|e| e.into_inner()));
        let it = evaluate_reusing(frame.sim, &frame.map, &motion, frame.band_view(d), spare)
            .map_err(|e| e.at_step(frame.step))?;
        let at = At {
            frame,
            d,
            motion: &motion,
            points: Some(&it),
            stabilised: true,
        };
        let mut fext = vec![0.0; frame.map.dofs.n_free];
        for c in &self.list {
            c.external(&at, &mut fext)?;
        }
        let mut r = fext.clone();
        let mut reaction = 0.0;
        for c in &self.list {
            reaction += c.internal(&at, &mut r);
        }
        Ok(Residual {
            scale: norm(&fext) + reaction,
            it,
            r,
            fext,
        })
    }

    /// Keep `res`'s buffers for the next residual: a residual no longer
    /// needed (the last iterate's, once its tangent is factorised).
    pub fn recycle(&self, res: Residual) {
        *self.spare.lock().unwrap_or_else(|e| e.into_inner()) = res.it.into_responses();
    }

    /// The force of the contributions named `name` at unknowns `d` with
    /// the points' response `it` (free dofs): what they subtract from the
    /// residual.
    pub fn force_of(&self, name: &str, frame: &Frame, d: &[P2], it: &Iterate) -> Vec<f64> {
        let motion = frame.motion(d);
        let at = At {
            frame,
            d,
            motion: &motion,
            points: Some(it),
            stabilised: true,
        };
        let mut r = vec![0.0; frame.map.dofs.n_free];
        for c in self.list.iter().filter(|c| c.name() == name) {
            c.internal(&at, &mut r);
        }
        r.iter().map(|v| -v).collect()
    }

    /// The tangent of the residual at `d` (its negative derivative), with
    /// or without the stabilisation terms: its values over the pattern.
    pub fn tangent(&self, frame: &Frame, res: &Residual, d: &[P2], stabilised: bool) -> Result<Vec<f64>, StepFailure> {
        let motion = frame.motion(d);
        let at = At {
            frame,
            d,
            motion: &motion,
            points: Some(&res.it),
            stabilised,
        };
        Ok(self.stiffness(&at)?.0)
    }
}

/// The response of a step's material points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Response {
    /// Small strain, linear elastic: one solve, the loads fixed.
    Linear,
    /// Finite deformation (Hencky, von Mises, F-bar): Newton, with the
    /// dead loads and the tractions (which follow the points) as
    /// contributions.
    Finite,
}

/// Every method's contribution to an implicit step, in the one order of
/// the list: the material points, the ghost penalty (G (27)), the
/// implicit boundaries' band (C (18)-(27)), under finite deformation
/// the dead loads (`dead`: body forces and point loads at the step's load
/// factor) and each B-spline boundary's traction with its load stiffness,
/// and in implicit dynamics the inertia (`inertia`, Newmark).
/// A new method adds its contribution here.
pub(crate) fn contributions(
    frame: &Frame,
    response: Response,
    dead: Vec<f64>,
    inertia: Option<std::sync::Arc<Inertia>>,
) -> Result<Vec<Box<dyn Contribution>>, StepFailure> {
    let mut list: Vec<Box<dyn Contribution>> = match response {
        Response::Linear => vec![Box::new(points::SmallStrainPoints)],
        Response::Finite => vec![Box::new(points::FinitePoints)],
    };
    list.push(Box::new(ghost::GhostPenalty));
    if let Some(band) = band::Band::of(frame) {
        list.push(Box::new(band));
    }
    if response == Response::Finite {
        list.push(Box::new(loads::DeadLoads { ext: dead }));
        for load in traction::TractionLoad::all_of(frame)? {
            list.push(Box::new(load));
        }
    }
    if let Some(inertia) = inertia {
        list.push(Box::new(inertia));
    }
    Ok(list)
}

/// What a converged implicit step hands to [`finish`].
pub(crate) struct Done {
    /// The fields the step wrote ([`Points::take_written`]).
    pub points: Points,
    /// The step number the state takes (a load step's earlier sub-steps
    /// keep the previous one).
    pub committed_step: usize,
    /// The nodes' whole motion over the step `d + d^a` (m, per grid node).
    pub motion: Vec<P2>,
    /// Strain energy after the step and plastic work dissipated in it (J).
    pub strain_energy: f64,
    pub dissipation: f64,
    /// Work of loads, supports and implicit boundaries over the step (J).
    pub work: f64,
    pub iterations: usize,
    pub residuals: Vec<f64>,
    /// `|r|` the residual is measured against (N).
    pub residual_norm: f64,
    pub condition: (Option<Condition>, Option<Condition>),
    pub ibm: Vec<IbmReport>,
    pub boundaries: Vec<BoundaryReport>,
    pub solver: SolverReport,
}

/// Commit a converged implicit step into `sim` (the points, the work, the
/// ghost penalty's force and work over the step's whole motion, the
/// moving implicit boundaries) and report it. `start` is when the step
/// began (for its total time).
pub(crate) fn finish(
    sim: &mut Simulation,
    frame: Closed,
    done: Done,
    mut timings: Timings,
    start: std::time::Instant,
) -> StepReport {
    let (step, (path0, path1)) = (frame.step, frame.path);
    let faces = frame.faces;
    let active_cells = frame.active_cells.len();
    // The penalty's force and work on the nodes' whole motion d + d^a.
    let ghost_force = crate::ghost::force(&faces, frame.gamma, &done.motion);
    let ghost = crate::ghost::step_work(&sim.state.ghost_force, &ghost_force, &done.motion);
    let max_increment = done.motion.iter().map(|u| u[0].hypot(u[1])).fold(0.0, f64::max);
    sim.state.ghost_energy += ghost;
    sim.state.ghost_force = ghost_force;
    sim.commit_quasi_static(
        done.points,
        done.committed_step,
        done.work,
        frame.active_cells,
        &faces,
        done.iterations,
        path1 - path0,
    );
    let errors = sim.exact_errors(path1);
    timings.total = start.elapsed().as_secs_f64();
    StepReport {
        unknowns: frame.unknowns,
        active_nodes: frame.active_nodes,
        active_cells,
        residual_norm: done.residual_norm,
        residuals: done.residuals,
        timings,
        energy: Energy {
            strain: done.strain_energy,
            external_work: sim.state.external_work,
            plastic_dissipation: done.dissipation,
            ghost: sim.state.ghost_energy,
            ..Energy::default()
        },
        condition: done.condition.0,
        condition_unstabilised: done.condition.1,
        iterations: done.iterations,
        ghost_faces: faces.len(),
        ibm: done.ibm,
        errors,
        max_increment,
        boundaries: done.boundaries,
        solver: Some(done.solver),
        ..StepReport::new(step, sim.load_steps(), path1)
    }
}
