//! B-bar: the small-strain counterpart of F-bar (`analysis.fbar` in a
//! `quasi-static-linear` analysis), against volumetric locking of nearly
//! incompressible materials.
//!
//! The patches are F-bar's ([`crate::bulk`]): the point groups (the points
//! with volume whose stencils share one node set; one cell's points under
//! the standard basis), without the points inside an implicit boundary's
//! band. F-bar's plane-strain `dF_bar_p = (J_bar / J_p)^(1/2) dF_p`
//! linearised about `dF = I` gives the strain
//!
//! ```text
//! eps_bar_p = eps_p + 1/2 (e_bar - e_p) m,   m = [1, 1, 0],
//! e_p = eps_xx + eps_yy,  e_bar = sum_q V_q e_q / sum_q V_q  (q in p's patch),
//! ```
//!
//! so `B_bar_p = B_p + 1/2 m (b_bar - b_p)` with `b_p` the volumetric row
//! `[dS_a/dx, dS_a/dy]_a` and `b_bar` its volume-weighted patch mean (de
//! Souza Neto, Peric and Owen, *Computational Methods for Plasticity*,
//! 2008, section 15.2: the B-bar method). The stiffness
//! `K = sum_p B_bar^T D B_bar V_p` stays symmetric and couples only the
//! nodes a patch already couples, so the pattern is unchanged; the
//! internal force is `sum_p B_bar^T s V_p` and the strain update
//! `eps += B_bar du`.

use crate::assembly::Mapping;
use crate::basis::StencilView;
use crate::geometry::P2;
use crate::ibm::Op;
use crate::points::Points;

/// The patches of a small-strain step: per point its patch (a group
/// index), per patch the volume-weighted mean of its points' volumetric
/// rows, node by node in the group's node order.
pub(crate) struct Bbar {
    patch_of: Vec<Option<usize>>,
    means: Vec<Vec<P2>>,
}

impl Bbar {
    /// The patches of `map`'s groups, leaving out the points `in_band`.
    pub fn new(map: &Mapping, pts: &Points, in_band: impl Fn(usize) -> bool) -> Bbar {
        let mut patch_of = vec![None; pts.len()];
        let mut means = Vec::with_capacity(map.groups.len());
        for (k, g) in map.groups.iter().enumerate() {
            let mut mean = vec![[0.0; 2]; g.nodes.len()];
            let mut volume = 0.0;
            for &p in g.points.iter().filter(|&&p| pts.vol[p] > 0.0 && !in_band(p)) {
                let v = pts.vol[p];
                for (a, m) in mean.iter_mut().enumerate() {
                    let dw = map.stencils.get(p).dw(a);
                    m[0] += v * dw[0];
                    m[1] += v * dw[1];
                }
                volume += v;
                patch_of[p] = Some(k);
            }
            if volume > 0.0 {
                for m in &mut mean {
                    *m = [m[0] / volume, m[1] / volume];
                }
            }
            means.push(mean);
        }
        Bbar { patch_of, means }
    }

    /// Point `p`'s `B_bar` per node of its stencil, or `None` for a point
    /// in no patch (in a band, or without volume).
    pub fn op(&self, map: &Mapping, p: usize) -> Option<Vec<Op>> {
        let mean = &self.means[self.patch_of[p]?];
        let st = map.stencils.get(p);
        Some(
            (0..st.len())
                .map(|a| {
                    let [bx, by] = st.dw(a);
                    let dx = 0.5 * (mean[a][0] - bx);
                    let dy = 0.5 * (mean[a][1] - by);
                    [[bx + dx, dy], [dx, by + dy], [by, bx]]
                })
                .collect(),
        )
    }

    /// `eps_bar = B_bar u` for a point's operator `op` (from [`Bbar::op`])
    /// on stencil `st`, for nodal values `nodal` (per grid node).
    pub fn strain(op: &[Op], st: StencilView, nodal: &[P2]) -> [f64; 3] {
        let mut e = [0.0; 3];
        for (a, n) in st.nodes().enumerate() {
            for (r, row) in op[a].iter().enumerate() {
                e[r] += row[0] * nodal[n][0] + row[1] * nodal[n][1];
            }
        }
        e
    }
}
