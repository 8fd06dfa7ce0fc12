//! An implicit boundary's band as a contribution of an implicit step
//! (C (18)-(27)): per cut cell the block `int_band B_bar^T C B_bar - B^T C B`
//! and the band's force `K_band d + f_d` on the increment, with `f_d =
//! int_band (B_bar - B)^T C B d^a` ([`crate::ibm::IbmStep::band`]). The band's
//! force is the boundary's reaction on its cells' nodes.

use super::contribution::{At, Contribution};
use super::frame::Frame;
use crate::geometry::P2;
use crate::ibm::{BandBlock, BandMaterial};
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
