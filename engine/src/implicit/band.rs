//! An implicit boundary's band as a contribution of an implicit step
//! (C (18)-(27)): per cut cell the block `int_band B_bar^T C B_bar - B^T C B`
//! and the band's force `K_band d + f_d` on the increment, with `f_d =
//! int_band (B_bar - B)^T C B d^a` ([`crate::ibm::IbmStep::band`]). The band's
//! force is the boundary's reaction on its cells' nodes.

use super::contribution::{At, Contribution};
use super::frame::Frame;
use crate::assembly::Dof;
use crate::bulk::{evaluate_with, Iterate};
use crate::geometry::P2;
use crate::ibm::{self, BandBlock, BandMaterial, IbmReport, IbmStep};
use crate::material::mul3;
use crate::points::Points;
use crate::report::StepFailure;

/// The band's blocks (`K_band`, symmetric) and `f_d` per grid node.
pub(crate) struct Band {
    pub blocks: Vec<BandBlock>,
    pub f_d: Vec<P2>,
}

impl Band {
    /// The band of the step's implicit boundaries (none without them),
    /// integrated with the points' elastic moduli.
    pub fn of(frame: &Frame) -> Option<Band> {
        let s = frame.ibm.as_ref()?;
        let (sim, grid) = (frame.sim, &frame.sim.model.grid);
        let pts = &sim.state.points;
        let material = BandMaterial::new(grid, &pts.x, &pts.vol, &|p| sim.material_of(p).d_matrix());
        let (blocks, f_d) = s.band(grid, &material);
        Some(Band { blocks, f_d })
    }

    /// `K_band d + f_d`, per node.
    pub fn force(&self, d: &[P2]) -> Vec<P2> {
        let mut f = self.f_d.clone();
        for (nodes, k) in &self.blocks {
            let m2 = 2 * nodes.len();
            for (a, &na) in nodes.iter().enumerate() {
                for i in 0..2 {
                    let row = &k[(2 * a + i) * m2..(2 * a + i + 1) * m2];
                    f[na][i] += nodes
                        .iter()
                        .enumerate()
                        .map(|(b, &nb)| row[2 * b] * d[nb][0] + row[2 * b + 1] * d[nb][1])
                        .sum::<f64>();
                }
            }
        }
        f
    }
}

impl Contribution for Band {
    fn name(&self) -> &'static str {
        "band"
    }

    fn blocks<'a>(&'a self, _frame: &'a Frame) -> Vec<&'a [usize]> {
        self.blocks.iter().map(|b| b.0.as_slice()).collect()
    }

    /// Subtract `K_band d + f_d` on the free dofs; its size is the
    /// implicit boundaries' reaction.
    fn internal(&self, at: &At, r: &mut [f64]) -> f64 {
        let fb = self.force(at.d);
        let mut sq = 0.0;
        for (n, f) in fb.iter().enumerate() {
            for c in 0..2 {
                if let Some(i) = at.frame.free(n, c) {
                    r[i] -= f[c];
                    sq += f[c] * f[c];
                }
            }
        }
        sq.sqrt()
    }

    fn prescribed(&self, _frame: &Frame, f_d: &mut [P2]) {
        for (f, b) in f_d.iter_mut().zip(&self.f_d) {
            f[0] += b[0];
            f[1] += b[1];
        }
    }

    fn block(&self, k: usize, _at: &At, out: &mut Vec<f64>) -> Result<(), StepFailure> {
        out.clear();
        out.extend_from_slice(&self.blocks[k].1);
        Ok(())
    }
}

/// A small-strain step's update of the points inside a band (C (18),
/// (27)): their strain by `B_bar` (`de += (B_bar - B) d`, `s += D de`) and
/// their motion by `D N d + N d^a` (`x += (D - I) N d` on top of the plain
/// update in `points`); then each implicit boundary's report and the work
/// its reaction did ([`small_strain_reports`]). `nodal_d` is the solved
/// increment per grid node, `ext` the loads per unit load factor on the
/// free dofs.
pub(crate) fn small_strain_update(
    frame: &Frame,
    s: &IbmStep,
    points: &mut Points,
    nodal_d: &[P2],
    ext: &[f64],
) -> (Vec<IbmReport>, f64) {
    let (sim, map) = (frame.sim, &frame.map);
    let pts = &sim.state.points;
    let d_of = |p: usize| sim.material_of(p).d_matrix();
    for p in (0..points.len()).filter(|&p| s.in_band[p]) {
        let st = map.stencils.get(p);
        let (bb, plain) = s.point_b(st, pts.x[p]);
        let (dm, _) = ibm::d_total(s.bs, pts.x[p], s.delta);
        let mut de = [0.0; 3];
        let mut dx = [0.0; 2];
        for (k, (n, w, _)) in st.iter().enumerate() {
            for c in 0..2 {
                for r in 0..3 {
                    de[r] += (bb[k][r][c] - plain[k][r][c]) * nodal_d[n][c];
                }
                for i in 0..2 {
                    dx[i] += ((dm[i][c]) - if i == c { 1.0 } else { 0.0 }) * w * nodal_d[n][c];
                }
            }
        }
        let ds = mul3(&d_of(p), de);
        for r in 0..3 {
            points.stress[p][r] += ds[r];
            points.strain[p][r] += de[r];
        }
        points.x[p] = [points.x[p][0] + dx[0], points.x[p][1] + dx[1]];
    }
    small_strain_reports(frame, s, points, nodal_d, ext)
}

/// Reports of the implicit boundaries after an update (reaction from
/// the out-of-balance of the new stresses on the nodes of each
/// boundary's cut cells; violation sampled along the boundary), and the
/// work their reactions did in the step (trapezoidal).
fn small_strain_reports(
    frame: &Frame,
    s: &IbmStep,
    new: &Points,
    nodal_d: &[P2],
    ext: &[f64],
) -> (Vec<IbmReport>, f64) {
    let (sim, map) = (frame.sim, &frame.map);
    let (lambda0, lambda1) = (frame.lambda0, frame.lambda1);
    let grid = &sim.model.grid;
    let old = &sim.state.points;
    // Out-of-balance of the material (internal minus every external
    // force on the free dofs) at the start and end of the step: where
    // the implicit boundaries act, it is their reaction.
    let mut residual = vec![[0.0; 2]; grid.num_nodes()];
    let mut residual0 = vec![[0.0; 2]; grid.num_nodes()];
    for p in (0..new.len()).filter(|&p| old.vol[p] > 0.0) {
        let st = map.stencils.get(p);
        // A B-bar patch's point balances with its own operator.
        let bb = match frame.bbar.as_ref().and_then(|b| b.op(map, p)) {
            Some(op) => op,
            None => s.point_b(st, old.x[p]).0,
        };
        for (k, (n, _, _)) in st.iter().enumerate() {
            for c in 0..2 {
                let f = |sig: [f64; 3]| (0..3).map(|r| bb[k][r][c] * sig[r]).sum::<f64>() * old.vol[p];
                residual[n][c] += f(new.stress[p]);
                residual0[n][c] += f(old.stress[p]);
            }
        }
    }
    for (n, d) in map.dofs.node_dof.iter().enumerate() {
        for c in 0..2 {
            if let Dof::Free(i) = d[c] {
                residual[n][c] -= lambda1 * ext[i];
                residual0[n][c] -= lambda0 * ext[i];
            }
        }
    }
    s.reports(
        grid,
        &|n, c| matches!(map.dofs.node_dof[n][c], Dof::Free(_)),
        &residual0,
        &residual,
        nodal_d,
        sim.model.exact.as_ref(),
        lambda1 - lambda0,
    )
}

/// A finite-deformation step's implicit-boundary reports and the work of
/// their reactions: the out-of-balance of the points at the start (zero
/// increment) and the end (response `it`, external force `fext`) of the
/// step on the nodes of each boundary's cut cells ([`IbmStep::reports`]).
/// `start_ext` is the external force per unit load factor at the start of
/// the step, `d` the converged unknowns.
pub(crate) fn finite_reports(
    frame: &Frame,
    s: &IbmStep,
    it: &Iterate,
    fext: &[f64],
    start_ext: &[f64],
    d: &[P2],
) -> Result<(Vec<IbmReport>, f64), StepFailure> {
    let (sim, map, step) = (frame.sim, &frame.map, frame.step);
    let lambda0 = frame.lambda0;
    // Out-of-balance of the points at the start (zero increment) and
    // the end of the step: the implicit boundaries' reactions.
    let zero = vec![[0.0; 2]; d.len()];
    let it0 =
        evaluate_with(sim, map, &zero, Some((&frame.ops[..], &zero[..], &zero[..]))).map_err(|e| e.at_step(step))?;
    // At grid-held dofs the internal force: a node shared with a grid
    // support splits it with that support (`IbmStep::reports`).
    let per_node = |fint: &[f64], fixed: &[f64], ext: &dyn Fn(usize) -> f64| {
        let mut out = vec![[0.0; 2]; d.len()];
        for (n, dofs) in map.dofs.node_dof.iter().enumerate() {
            for c in 0..2 {
                match dofs[c] {
                    Dof::Free(i) => out[n][c] = fint[i] - ext(i),
                    Dof::Fixed(i) => out[n][c] = fixed[i],
                    Dof::Inactive => {}
                }
            }
        }
        out
    };
    let r0 = per_node(&it0.fint_free, &it0.fint_fixed, &|i| lambda0 * start_ext[i]);
    let r1 = per_node(&it.fint_free, &it.fint_fixed, &|i| fext[i]);
    let (reports, w) = s.reports(
        &sim.model.grid,
        &|n, c| matches!(map.dofs.node_dof[n][c], Dof::Free(_)),
        &r0,
        &r1,
        d,
        sim.model.exact.as_ref(),
        frame.path.1 - frame.path.0,
    );
    Ok((reports, w))
}
