//! The material points' contribution to a finite-deformation step, shared
//! by the Newton and the explicit drivers: the material's response and
//! internal force at trial nodal increments, `f_int = sum_p P : G V0_p`,
//! and the tangent blocks of the point groups, `sum_p V0 G_a : A : G_b`
//! (with `G_a[l] = e_l (x) grad S_a`, or the implicit boundary's
//! [`GradOp`] for points inside a band).
//!
//! With F-bar (`analysis.fbar`, against volumetric locking in nearly
//! incompressible plastic flow; de Souza Neto et al. 1996, as used in
//! implicit MPM by Coombs et al. 2018) each point group (the points of one
//! cell under the standard basis) is a patch: `dF_bar_p = c_p dF_p` with
//! `c_p = (J_bar / J_p)^(1/2)` (plane strain), `J_p = det dF_p` and `J_bar`
//! the patch's mean of `J` weighted by the start-of-step volumes. The
//! stress comes from `dF_bar`, the geometry from `dF`:
//! `P_p = tau(dF_bar_p) dF_p^-T = c_p P_bar_p`. Its tangent couples the
//! points of a patch: `dP_p = c_p^2 A_p : dF_p + dc_p Q_p` with
//! `Q_p = P_bar_p + c_p A_p : dF_p` and
//! `dc_p = (c_p/2) (sum_q v_q J_q dF_q^-T : d dF_q / (J_bar V) - dF_p^-T : d dF_p)`.
//! Points inside an implicit boundary's band stay out of the patches.

use crate::assembly::{try_filled, try_with_capacity, Dof, Mapping, Pattern};
use crate::geometry::P2;
use crate::ghost::GhostFace;
use crate::ibm::GradOp;
use crate::kinematics::{be_matrix, increment_gradient};
use crate::linalg::FactorError;
use crate::material::hencky::Response;
use crate::state::Simulation;
use faer::sparse::SparseColMat;
use nalgebra::Matrix2;

/// F-bar at one trial increment: per point its data (points in a patch),
/// per group `(J_bar, sum of start-of-step volumes)`.
type FbarPatches = (Vec<Option<FbarPoint>>, Vec<(f64, f64)>);

/// A point's F-bar data at one trial increment.
#[derive(Clone, Debug)]
pub(crate) struct FbarPoint {
    /// `c = (J_bar / J)^(1/2)`.
    c: f64,
    /// `J = det dF`.
    j: f64,
    /// `dF^-T`.
    finv_t: Matrix2<f64>,
    /// `Q = P_bar + c A : dF`.
    q: Matrix2<f64>,
}

/// The points' response at one trial increment.
pub(crate) struct Iterate {
    pub(crate) responses: Vec<Option<Response>>,
    pub(crate) fint_free: Vec<f64>,
    pub(crate) fint_fixed: Vec<f64>,
    /// With F-bar: per point its data (points in a patch), per group
    /// `(J_bar, sum of start-of-step volumes)`.
    fbar: Option<FbarPatches>,
}

impl Iterate {
    /// The responses' buffer, for [`evaluate_reusing`].
    pub(crate) fn into_responses(self) -> Vec<Option<Response>> {
        self.responses
    }
}

/// The implicit boundaries as the points see them: per point its band
/// operators (if it lies in a band), the unknowns `d` and `d^a` per node.
pub(crate) type BandView<'a> = (&'a [Option<Vec<GradOp>>], &'a [P2], &'a [P2]);

/// Material response and internal force of the points for nodal
/// increments `total` (`d + d^a`), with the in-band points' operators
/// `ops` acting on the unknowns `d` (and `grad(S d^a)`).
/// Its per-point and per-dof buffers are reserved fallibly: memory that
/// cannot be had is an error naming them, not an abort.
pub(crate) fn evaluate_with(
    sim: &Simulation,
    map: &Mapping,
    total: &[P2],
    band: Option<BandView>,
) -> Result<Iterate, FactorError> {
    evaluate_reusing(sim, map, total, band, Vec::new())
}

/// [`evaluate_with`] writing the responses into `spare` (an earlier
/// iterate's, [`Iterate::into_responses`]) when it holds one per point:
/// a Newton step's residuals then reuse one buffer (about 330 bytes a
/// point) instead of having fresh pages zeroed by the system each time.
pub(crate) fn evaluate_reusing(
    sim: &Simulation,
    map: &Mapping,
    total: &[P2],
    band: Option<BandView>,
    spare: Vec<Option<Response>>,
) -> Result<Iterate, FactorError> {
    let pts = &sim.state.points;
    let in_band = |p: usize| band.is_some_and(|(ops, _, _)| ops[p].is_some());
    // F-bar: each group's volume-weighted mean J of its points' dF.
    let fbar_c = match sim.model.analysis.fbar {
        true => Some(try_filled(pts.len(), None, "the points' F-bar factors")?),
        false => None,
    };
    let fbar = fbar_c.map(|mut c| {
        let groups: Vec<(f64, f64)> = map
            .groups
            .iter()
            .map(|g| {
                let (mut sj, mut sv) = (0.0, 0.0);
                let members: Vec<(usize, Matrix2<f64>)> = g
                    .points
                    .iter()
                    .filter(|&&p| pts.vol0[p] > 0.0 && !in_band(p))
                    .map(|&p| (p, increment_gradient(map.stencils.get(p), total)))
                    .collect();
                for &(p, df) in &members {
                    sj += pts.vol[p] * df.determinant();
                    sv += pts.vol[p];
                }
                let jbar = if sv > 0.0 { sj / sv } else { 1.0 };
                for (p, df) in members {
                    c[p] = Some(((jbar / df.determinant()).sqrt(), df));
                }
                (jbar, sv)
            })
            .collect();
        (c, groups)
    });
    // Each point's response (parallel on the simulation's threads, each
    // point on its own), then the forces summed in point order: any
    // number of threads gives the serial result to the bit.
    let respond = |p: usize| -> (Option<Response>, Option<FbarPoint>) {
        if pts.vol0[p] == 0.0 {
            return (None, None);
        }
        let st = map.stencils.get(p);
        let be = be_matrix(pts.b_e_at(p));
        if let Some((ops, d, da)) = band.and_then(|(ops, d, da)| ops[p].as_ref().map(|o| (o, d, da))) {
            return (Some(sim.hencky(p).respond(&band_gradient(st, ops, d, da), &be)), None);
        }
        let Some((c, df)) = fbar.as_ref().and_then(|(c, _)| c[p]) else {
            return (Some(sim.hencky(p).respond(&increment_gradient(st, total), &be)), None);
        };
        let r = sim.hencky(p).respond(&(df * c), &be);
        let mut q = r.p;
        for i in 0..2 {
            for j in 0..2 {
                for k in 0..2 {
                    for l in 0..2 {
                        q[(i, j)] += c * r.a[i][j][k][l] * df[(k, l)];
                    }
                }
            }
        }
        let point = FbarPoint {
            c,
            j: df.determinant(),
            finv_t: df.try_inverse().map_or(Matrix2::zeros(), |m| m.transpose()),
            q,
        };
        (Some(r), Some(point))
    };
    // Every entry is written below: a spare of the right length is used
    // as it is.
    let mut responses = spare;
    if responses.len() != pts.len() {
        responses = try_with_capacity(pts.len(), "the points' material responses")?;
        responses.resize(pts.len(), None);
    }
    let n_fbar = if fbar.is_some() { pts.len() } else { 0 };
    let mut fbar_points: Vec<Option<FbarPoint>> = try_filled(n_fbar, None, "the points' F-bar operators")?;
    sim.for_each_point(&mut responses, &mut fbar_points, |p, r, f| {
        let (rp, fp) = respond(p);
        *r = rp;
        if let Some(f) = f {
            *f = fp;
        }
    });
    let mut it = Iterate {
        responses,
        fint_free: try_filled(map.dofs.n_free, 0.0, "the internal forces")?,
        fint_fixed: try_filled(map.dofs.constrained.len(), 0.0, "the reactions")?,
        fbar: None,
    };
    let mut add = |n: usize, i: usize, f: f64| match map.dofs.node_dof[n][i] {
        Dof::Free(k) => it.fint_free[k] += f,
        Dof::Fixed(k) => it.fint_fixed[k] += f,
        Dof::Inactive => {}
    };
    for p in 0..pts.len() {
        let Some(r) = &it.responses[p] else { continue };
        let st = map.stencils.get(p);
        let v0 = pts.vol0[p];
        if let Some(ops) = band.and_then(|(ops, _, _)| ops[p].as_ref()) {
            for (k, (n, _, _)) in st.iter().enumerate() {
                for l in 0..2 {
                    let mut f = 0.0;
                    for i in 0..2 {
                        for j in 0..2 {
                            f += r.p[(i, j)] * ops[k][l][i][j];
                        }
                    }
                    add(n, l, f * v0);
                }
            }
            continue;
        }
        // P = tau(dF_bar) dF^-T = c P_bar in an F-bar patch.
        let pm = match fbar_points.get(p).and_then(|f| f.as_ref()) {
            Some(f) => r.p * f.c,
            None => r.p,
        };
        for (n, _, g) in st.iter() {
            for i in 0..2 {
                add(n, i, (pm[(i, 0)] * g[0] + pm[(i, 1)] * g[1]) * v0);
            }
        }
    }
    it.fbar = fbar.map(|(_, g)| (fbar_points, g));
    Ok(it)
}

/// `dF = I + sum_k sum_l d_kl G_k[l] + grad(S d^a)` of a point inside a
/// band ([`GradOp`]): the gradient of its motion
/// [`IbmStep::point_increment`](crate::ibm::IbmStep::point_increment)
/// `x -> x + D S d + S d^a`, for the nodal unknowns `d` and prescribed
/// increments `d^a` (m, indexed by grid node) of the stencil `st`.
pub fn band_gradient(st: crate::basis::StencilView, ops: &[GradOp], d: &[P2], da: &[P2]) -> Matrix2<f64> {
    let ga = st.gradient(|n| da[n]);
    let mut df = Matrix2::new(1.0 + ga[0][0], ga[0][1], ga[1][0], 1.0 + ga[1][1]);
    for (k, (n, _, _)) in st.iter().enumerate() {
        for l in 0..2 {
            for i in 0..2 {
                for j in 0..2 {
                    df[(i, j)] += ops[k][l][i][j] * d[n][l];
                }
            }
        }
    }
    df
}

/// Material response and internal force for nodal increments `du`
/// (no implicit boundaries).
pub(crate) fn evaluate(sim: &Simulation, map: &Mapping, du: &[P2]) -> Result<Iterate, FactorError> {
    evaluate_with(sim, map, du, None)
}

/// Tangent block of a point group: `sum_p V0 A_ijkl g_a,j g_b,l`, or with
/// a band operator `sum_p V0 G_a : A : G_b`.
pub(crate) fn group_tangent(
    sim: &Simulation,
    map: &Mapping,
    it: &Iterate,
    ops: Option<&[Option<Vec<GradOp>>]>,
    b: usize,
    out: &mut Vec<f64>,
) {
    let g = &map.groups[b];
    let m2 = 2 * g.nodes.len();
    out.clear();
    out.resize(m2 * m2, 0.0);
    let pts = &sim.state.points;
    // F-bar: h_q(b, k) = (dF_q^-T grad S_b)_k, and the patch's
    // H(b, k) = sum_q v_q J_q h_q(b, k) / (J_bar V).
    let fbar = it.fbar.as_ref().map(|(f, groups)| {
        let (jbar, vsum) = groups[b];
        let mut big_h = vec![0.0; m2];
        for &q in &g.points {
            let Some(fq) = &f[q] else { continue };
            let st = map.stencils.get(q);
            for bb in 0..st.len() {
                let h = fq.finv_t * nalgebra::Vector2::new(st.dw(bb)[0], st.dw(bb)[1]);
                for k in 0..2 {
                    big_h[2 * bb + k] += pts.vol[q] * fq.j * h[k] / (jbar * vsum);
                }
            }
        }
        (f, big_h)
    });
    for &p in &g.points {
        let Some(r) = &it.responses[p] else { continue };
        let st = map.stencils.get(p);
        let v0 = sim.state.points.vol0[p];
        if let Some(op) = ops.and_then(|o| o[p].as_ref()) {
            for a in 0..st.len() {
                for l in 0..2 {
                    // (G_a[l] : A)_kq
                    let mut ga = [[0.0; 2]; 2];
                    for i in 0..2 {
                        for j in 0..2 {
                            let gij = op[a][l][i][j];
                            if gij == 0.0 {
                                continue;
                            }
                            for k in 0..2 {
                                for q in 0..2 {
                                    ga[k][q] += gij * r.a[i][j][k][q];
                                }
                            }
                        }
                    }
                    for bb in 0..st.len() {
                        for m in 0..2 {
                            let mut s = 0.0;
                            for k in 0..2 {
                                for q in 0..2 {
                                    s += ga[k][q] * op[bb][m][k][q];
                                }
                            }
                            out[(2 * a + l) * m2 + 2 * bb + m] += v0 * s;
                        }
                    }
                }
            }
            continue;
        }
        let fp = fbar.as_ref().and_then(|(f, h)| f[p].as_ref().map(|fp| (fp, h)));
        let scale = fp.map_or(1.0, |(fp, _)| fp.c * fp.c);
        for a in 0..st.len() {
            let ga = st.dw(a);
            for bb in 0..st.len() {
                let gb = st.dw(bb);
                for i in 0..2 {
                    for k in 0..2 {
                        let mut s = 0.0;
                        for j in 0..2 {
                            for l in 0..2 {
                                s += r.a[i][j][k][l] * ga[j] * gb[l];
                            }
                        }
                        out[(2 * a + i) * m2 + 2 * bb + k] += v0 * scale * s;
                    }
                }
            }
        }
        // F-bar: the patch coupling dc_p Q_p.
        if let Some((fp, big_h)) = fp {
            // h_p(b, k) = (dF_p^-T grad S_b)_k.
            let mut hp = [0.0; 2 * crate::basis::MAX_NODES];
            for bb in 0..st.len() {
                let h = fp.finv_t * nalgebra::Vector2::new(st.dw(bb)[0], st.dw(bb)[1]);
                hp[2 * bb] = h[0];
                hp[2 * bb + 1] = h[1];
            }
            for a in 0..st.len() {
                let qa = fp.q * nalgebra::Vector2::new(st.dw(a)[0], st.dw(a)[1]);
                for l in 0..2 {
                    for col in 0..m2 {
                        out[(2 * a + l) * m2 + col] += v0 * qa[l] * 0.5 * fp.c * (big_h[col] - hp[col]);
                    }
                }
            }
        }
    }
}

/// Assemble the reduced material tangent of the point groups and ghost
/// faces (no implicit boundaries or loads), with or without the ghost term.
pub(crate) fn tangent(
    sim: &Simulation,
    map: &Mapping,
    pattern: &Pattern,
    blocks: &[&[usize]],
    faces: &[GhostFace],
    it: &Iterate,
    gamma: f64,
) -> Result<SparseColMat<crate::linalg::Ix, f64>, crate::linalg::FactorError> {
    let ng = map.groups.len();
    let (values, _) = pattern.assemble_with(&map.dofs, blocks, |b, out| {
        if b < ng {
            group_tangent(sim, map, it, None, b, out)
        } else {
            faces[b - ng].stiffness(gamma, out)
        }
    })?;
    pattern.owned_matrix(values)
}

/// Assembly blocks: the point groups, then the ghost faces.
pub(crate) fn blocks_of<'a>(map: &'a Mapping, faces: &'a [GhostFace]) -> Vec<&'a [usize]> {
    let mut blocks: Vec<&[usize]> = map.groups.iter().map(|g| g.nodes.as_slice()).collect();
    blocks.extend(faces.iter().map(|f| f.nodes.as_slice()));
    blocks
}
