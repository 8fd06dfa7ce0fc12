//! The ghost penalty as a contribution of an implicit step (G (27)).

use super::contribution::{At, Contribution};
use super::frame::Frame;
use crate::ghost::force;
use crate::report::StepFailure;

/// The ghost penalty of an implicit step as a contribution (G (27)): the
/// force `f_G = gamma_K J_G (d + d^a)` on the nodes' whole motion (a linear
/// field leaves its normal derivative without jumps; the unknowns `d` alone
/// have them where `d^a` ends) and its stiffness `K_G = gamma_K J_G`, one
/// block per face ([`crate::implicit::Frame::faces`]). It is the step's
/// stabilisation: the tangent without it is the one whose condition it
/// improves.
pub(crate) struct GhostPenalty;

impl Contribution for GhostPenalty {
    fn name(&self) -> &'static str {
        "ghost"
    }

    fn blocks<'a>(&'a self, frame: &'a Frame) -> Vec<&'a [usize]> {
        frame.faces.iter().map(|f| f.nodes.as_slice()).collect()
    }

    fn internal(&self, at: &At, r: &mut [f64]) -> f64 {
        let frame = at.frame;
        if frame.faces.is_empty() {
            return 0.0;
        }
        let mut fg = vec![0.0; r.len()];
        for f in &frame.faces {
            for row in 0..6 {
                for c in 0..2 {
                    let Some(i) = frame.free(f.nodes[row], c) else {
                        continue;
                    };
                    fg[i] += frame.gamma * (0..6).map(|k| f.j[row][k] * at.motion[f.nodes[k]][c]).sum::<f64>();
                }
            }
        }
        for (r, f) in r.iter_mut().zip(&fg) {
            *r -= f;
        }
        0.0
    }

    /// `J_G d^a`: the penalty acts on the nodes' whole motion.
    fn prescribed(&self, frame: &Frame, f_d: &mut [[f64; 2]]) {
        if let Some(s) = &frame.ibm {
            for (n, f) in force(&frame.faces, frame.gamma, &s.da).iter().enumerate() {
                f_d[n][0] += f[0];
                f_d[n][1] += f[1];
            }
        }
    }

    fn block(&self, k: usize, at: &At, out: &mut Vec<f64>) -> Result<(), StepFailure> {
        let gamma = if at.stabilised { at.frame.gamma } else { 0.0 };
        at.frame.faces[k].stiffness(gamma, out);
        Ok(())
    }
}
