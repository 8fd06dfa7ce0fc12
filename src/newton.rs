//! One finite-deformation load step: updated Lagrangian, Newton-Raphson
//! (G section 2.1; AMPLE; Charlton et al. 2017).
//!
//! Per step, on the configuration at its start (grid reset):
//!
//! 1. map points to the grid, find the ghost faces, build the (full,
//!    non-symmetric) sparsity pattern once;
//! 2. Newton on the nodal increments `du` (prescribed ones applied from the
//!    start): per point `dF = I + sum_v du_v (x) grad_n S_v`, the material's
//!    `P = tau dF^-T` and `A = dP/d dF` ([`Hencky::respond`]);
//!    `f_int = sum_p P grad_n S V0_p`, `f_G = gamma_K J_G du`;
//!    residual `r = lambda f_ext - f_int - f_G` on the free dofs, converged
//!    when `|r| / (|f_ext| + |reactions|) <= tol`; else assemble
//!    `K = sum_p V0_p A : (grad_n S (x) grad_n S) + gamma_K J_G`, factorise
//!    with sparse LU (symbolic analysis reused across iterations), solve,
//!    update `du`;
//! 3. commit: `F = dF F_n`, `b_e`, Cauchy `s = tau / det F`, positions,
//!    `V = det(dF) V_n`, GIMP domains `l = l_0 diag(U)` (`F = R U`).
//!
//! Every iteration's residual goes into the report; non-convergence, a
//! singular tangent and non-finite values are [`StepFailure`]s that leave
//! the state at the last good step.

use crate::assembly::{Dof, Mapping, Pattern, Storage};
use crate::geometry::P2;
use crate::ghost::{self, GhostFace};
use crate::linalg::{self, Condition};
use crate::material::hencky::{right_stretch, Response};
use crate::scene::ConditionMode;
use crate::simulation::{Energy, Simulation, StepFailure, StepReport, Timings};
use faer::sparse::SparseColMat;
use nalgebra::{Matrix2, Matrix3};
use std::time::Instant;

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// `dF = I + sum_v du_v (x) g_v` over a point's stencil.
pub(crate) fn increment_gradient(st: &crate::basis::Stencil, du: &[P2]) -> Matrix2<f64> {
    let g = st.gradient(|n| du[n]);
    Matrix2::new(1.0 + g[0][0], g[0][1], g[1][0], 1.0 + g[1][1])
}

pub(crate) fn be_matrix(b: [f64; 4]) -> Matrix3<f64> {
    Matrix3::new(b[0], b[2], 0.0, b[2], b[1], 0.0, 0.0, 0.0, b[3])
}

/// Commit point `p`'s deformation increment `df`: `F = dF F_n`,
/// `V = det(dF) V_n`, GIMP domains `l = l_0 diag(U)` (`F = R U`), and with
/// the material's response (points with volume) the Cauchy stress
/// `s = tau / det F`, `b_e`, dissipation and yield flag. Returns the
/// point's stored energy and its dissipation so far (J).
pub(crate) fn commit_point(
    sim: &Simulation,
    pts: &mut crate::points::Points,
    p: usize,
    df: &Matrix2<f64>,
    r: Option<&Response>,
) -> Option<(f64, f64)> {
    let fo = pts.def_grad[p];
    let f = df * Matrix2::new(fo[0], fo[1], fo[2], fo[3]);
    pts.def_grad[p] = [f[(0, 0)], f[(0, 1)], f[(1, 0)], f[(1, 1)]];
    pts.vol[p] *= df.determinant();
    let (l0, u) = (pts.lp0[p], right_stretch(&f));
    pts.lp[p] = [l0[0] * u[(0, 0)], l0[1] * u[(1, 1)]];
    let r = r?;
    let s = r.tau / f.determinant();
    pts.stress[p] = [s[(0, 0)], s[(1, 1)], s[(0, 1)]];
    pts.szz[p] = s[(2, 2)];
    pts.b_e[p] = [r.b_e[(0, 0)], r.b_e[(1, 1)], r.b_e[(0, 1)], r.b_e[(2, 2)]];
    pts.dissipation[p] += r.dissipation * pts.vol0[p];
    pts.yielding[p] = r.yielding;
    Some((pts.vol0[p] * sim.hencky(p).stored_energy(&r.b_e), pts.dissipation[p]))
}

pub(crate) struct Iterate {
    responses: Vec<Option<Response>>,
    fint_free: Vec<f64>,
    fint_fixed: Vec<f64>,
}

/// Material response and internal force for nodal increments `du`.
pub(crate) fn evaluate(sim: &Simulation, map: &Mapping, du: &[P2]) -> Iterate {
    let pts = &sim.state.points;
    let mut it = Iterate {
        responses: Vec::with_capacity(pts.len()),
        fint_free: vec![0.0; map.dofs.n_free],
        fint_fixed: vec![0.0; map.dofs.constrained.len()],
    };
    for p in 0..pts.len() {
        if pts.vol0[p] == 0.0 {
            it.responses.push(None);
            continue;
        }
        let st = &map.stencils[p];
        let r = sim
            .hencky(p)
            .respond(&increment_gradient(st, du), &be_matrix(pts.b_e[p]));
        let v0 = pts.vol0[p];
        for (n, _, g) in st.iter() {
            for i in 0..2 {
                let f = (r.p[(i, 0)] * g[0] + r.p[(i, 1)] * g[1]) * v0;
                match map.dofs.node_dof[n][i] {
                    Dof::Free(k) => it.fint_free[k] += f,
                    Dof::Fixed(k) => it.fint_fixed[k] += f,
                    Dof::Inactive => {}
                }
            }
        }
        it.responses.push(Some(r));
    }
    it
}

/// Tangent block of a point group: `sum_p V0 A_ijkl g_a,j g_b,l`.
fn group_tangent(sim: &Simulation, map: &Mapping, it: &Iterate, b: usize, out: &mut Vec<f64>) {
    let g = &map.groups[b];
    let m2 = 2 * g.nodes.len();
    out.clear();
    out.resize(m2 * m2, 0.0);
    for &p in &g.points {
        let Some(r) = &it.responses[p] else { continue };
        let st = &map.stencils[p];
        let v0 = sim.state.points.vol0[p];
        for a in 0..st.len {
            let ga = st.dw[a];
            for bb in 0..st.len {
                let gb = st.dw[bb];
                for i in 0..2 {
                    for k in 0..2 {
                        let mut s = 0.0;
                        for j in 0..2 {
                            for l in 0..2 {
                                s += r.a[i][j][k][l] * ga[j] * gb[l];
                            }
                        }
                        out[(2 * a + i) * m2 + 2 * bb + k] += v0 * s;
                    }
                }
            }
        }
    }
}

/// Assemble the reduced tangent, with or without the ghost term.
pub(crate) fn tangent(
    sim: &Simulation,
    map: &Mapping,
    pattern: &Pattern,
    blocks: &[&[usize]],
    faces: &[GhostFace],
    it: &Iterate,
    gamma: f64,
) -> SparseColMat<usize, f64> {
    let ng = map.groups.len();
    pattern
        .assemble_with(&map.dofs, blocks, |b, out| {
            if b < ng {
                group_tangent(sim, map, it, b, out)
            } else {
                faces[b - ng].stiffness(gamma, out)
            }
        })
        .0
}

/// The ghost faces of this step (none when `gamma_K = 0`).
fn ghost_faces(sim: &Simulation, map: &Mapping) -> Vec<GhostFace> {
    if sim.params.gamma_k > 0.0 {
        ghost::faces_of(&sim.model.grid, map, sim.model.analysis.ghost_cells)
    } else {
        Vec::new()
    }
}

/// Assembly blocks: the point groups, then the ghost faces.
pub(crate) fn blocks_of<'a>(map: &'a Mapping, faces: &'a [GhostFace]) -> Vec<&'a [usize]> {
    let mut blocks: Vec<&[usize]> = map.groups.iter().map(|g| g.nodes.as_slice()).collect();
    blocks.extend(faces.iter().map(|f| f.nodes.as_slice()));
    blocks
}

fn condition_of(k: &SparseColMat<usize, f64>) -> Condition {
    match linalg::lu_symbolic(k).and_then(|s| linalg::lu(&s, k)) {
        Ok(f) => linalg::one_norm_condition(k, &f),
        Err(_) => Condition {
            value: f64::INFINITY,
            lambda_min: 0.0,
            lambda_max: f64::NAN,
            method: linalg::ConditionMethod::OneNormEstimate,
        },
    }
}

pub(crate) fn finite_step(sim: &mut Simulation) -> Result<StepReport, StepFailure> {
    let step = sim.state.step + 1;
    let steps = sim.load_steps();
    let (lambda0, lambda1) = ((step - 1) as f64 / steps as f64, step as f64 / steps as f64);
    let start = Instant::now();
    let mut timings = Timings::default();
    let params = sim.params.clone();

    // 1. Map points, ghost faces, pattern.
    let model = &sim.model;
    let map = Mapping::build(
        &model.grid,
        &sim.state.points,
        &model.bodies,
        &model.dirichlet,
        lambda1 - lambda0,
    );
    let (forces, boundaries) = sim.nodal_forces(&map, step, lambda1)?;
    let fext: Vec<f64> = forces.ext.iter().map(|f| lambda1 * f).collect();
    let gamma = params.gamma_k;
    let faces = ghost_faces(sim, &map);
    let blocks = blocks_of(&map, &faces);
    let pattern = Pattern::new(&map.dofs, &blocks, Storage::Full);
    timings.assembly += start.elapsed().as_secs_f64();

    // 2. Newton.
    let mut du = vec![[0.0; 2]; model.grid.num_nodes()];
    for &(n, c, v) in &map.dofs.constrained {
        du[n][c] = v;
    }
    let mut residuals = Vec::new();
    let mut symbolic = None;
    // The last tangent and its LU factor, reused for the condition number.
    let mut last = None;
    let mut iterations = 0;
    let it = loop {
        let t = Instant::now();
        let it = evaluate(sim, &map, &du);
        // Ghost force f_G = gamma J_G du on the free rows.
        let mut fg = vec![0.0; map.dofs.n_free];
        for f in &faces {
            for r in 0..6 {
                for c in 0..2 {
                    let Dof::Free(row) = map.dofs.node_dof[f.nodes[r]][c] else {
                        continue;
                    };
                    fg[row] += gamma * (0..6).map(|k| f.j[r][k] * du[f.nodes[k]][c]).sum::<f64>();
                }
            }
        }
        let r: Vec<f64> = (0..map.dofs.n_free)
            .map(|i| fext[i] - it.fint_free[i] - fg[i])
            .collect();
        let denom = norm(&fext) + norm(&it.fint_fixed);
        let rel = norm(&r) / if denom > 0.0 { denom } else { 1.0 };
        residuals.push(rel);
        timings.assembly += t.elapsed().as_secs_f64();
        if !sim.report_progress(step, iterations, rel) {
            return Err(StepFailure::Cancelled { step, residuals });
        }
        if !rel.is_finite() {
            return Err(StepFailure::NonFinite {
                step,
                what: "Newton residual".into(),
                residuals,
            });
        }
        if rel <= params.tolerance {
            break it;
        }
        if iterations >= params.max_iterations {
            return Err(StepFailure::NotConverged {
                step,
                residuals,
                tolerance: params.tolerance,
            });
        }
        let t = Instant::now();
        let k = tangent(sim, &map, &pattern, &blocks, &faces, &it, gamma);
        timings.assembly += t.elapsed().as_secs_f64();
        let t = Instant::now();
        if symbolic.is_none() {
            symbolic = Some(linalg::lu_symbolic(&k).map_err(|e| StepFailure::Singular {
                step,
                reason: e.to_string(),
            })?);
        }
        let lu = linalg::lu(symbolic.as_ref().expect("set above"), &k).map_err(|e| StepFailure::Singular {
            step,
            reason: e.to_string(),
        })?;
        timings.factorisation += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let dd = linalg::solve_lu(&lu, &r, false);
        timings.solve += t.elapsed().as_secs_f64();
        if dd.iter().any(|v| !v.is_finite()) {
            return Err(StepFailure::Singular {
                step,
                reason: format!(
                    "the tangent is numerically singular (non-finite Newton correction at iteration {})",
                    iterations + 1
                ),
            });
        }
        for (n, d) in map.dofs.node_dof.iter().enumerate() {
            for c in 0..2 {
                if let Dof::Free(i) = d[c] {
                    du[n][c] += dd[i];
                }
            }
        }
        last = Some((k, lu));
        iterations += 1;
    };

    // Condition numbers of the last tangent, with and without ghost.
    let t = Instant::now();
    let (condition, condition_unstabilised) = if params.condition == ConditionMode::Off || map.dofs.n_free == 0 {
        (None, None)
    } else {
        let with = match &last {
            Some((k, lu)) => linalg::one_norm_condition(k, lu),
            None => condition_of(&tangent(sim, &map, &pattern, &blocks, &faces, &it, gamma)),
        };
        let without =
            (!faces.is_empty()).then(|| condition_of(&tangent(sim, &map, &pattern, &blocks, &faces, &it, 0.0)));
        (Some(with), without)
    };
    timings.condition = t.elapsed().as_secs_f64();

    // 3. Commit into a copy of the points.
    let t = Instant::now();
    let mut pts = sim.state.points.clone();
    let (mut strain_energy, mut dissipation) = (0.0, 0.0);
    for p in 0..pts.len() {
        let st = &map.stencils[p];
        let u = st.interpolate(|n| du[n]);
        let df = increment_gradient(st, &du);
        pts.x[p] = [pts.x[p][0] + u[0], pts.x[p][1] + u[1]];
        if let Some((w, d)) = commit_point(sim, &mut pts, p, &df, it.responses[p].as_ref()) {
            strain_energy += w;
            dissipation += d;
        }
    }
    crate::simulation::check_points(&sim.model.grid, &pts, step, &residuals)?;
    let mut work = 0.0;
    for (n, d) in map.dofs.node_dof.iter().enumerate() {
        for c in 0..2 {
            match d[c] {
                Dof::Free(i) => work += 0.5 * (lambda0 + lambda1) * forces.ext[i] * du[n][c],
                Dof::Fixed(i) => work += 0.5 * (forces.int_fixed[i] + it.fint_fixed[i]) * du[n][c],
                Dof::Inactive => {}
            }
        }
    }
    let max_increment = du.iter().map(|u| u[0].hypot(u[1])).fold(0.0, f64::max);
    timings.update = t.elapsed().as_secs_f64();

    sim.commit(pts, step, work, &map, &faces, iterations);
    let errors = match &sim.model.exact {
        Some(e) => e.errors(&sim.state.points, lambda1),
        None => Vec::new(),
    };
    timings.total = start.elapsed().as_secs_f64();
    Ok(StepReport {
        step,
        load_steps: steps,
        load_factor: lambda1,
        unknowns: map.dofs.n_free,
        active_nodes: map.dofs.active_nodes,
        active_cells: map.active_cells.len(),
        residual_norm: norm(&fext),
        residuals,
        timings,
        energy: Energy {
            strain: strain_energy,
            external_work: sim.state.external_work,
            plastic_dissipation: dissipation,
            kinetic: 0.0,
        },
        condition,
        condition_unstabilised,
        iterations,
        ghost_faces: faces.len(),
        ibm: Vec::new(),
        errors,
        max_increment,
        boundaries,
        dynamics: None,
    })
}

impl Simulation {
    /// The finite-strain material of point `p`'s body.
    pub(crate) fn hencky(&self, p: usize) -> crate::material::hencky::Hencky {
        let body = &self.model.bodies[self.state.points.body[p]];
        let m = self.model.materials[body.material];
        crate::material::hencky::Hencky {
            e: m.e,
            nu: m.nu,
            yield_stress: self.model.yield_stress[body.material],
        }
    }

    /// Largest relative difference between the assembled finite-deformation
    /// tangent (with the ghost term) and central finite differences of the
    /// out-of-balance force, at a reproducible pseudo-random trial increment
    /// of size `amplitude * h`, along 4 pseudo-random directions. A
    /// diagnostic for developers and the test suite.
    pub fn tangent_check(&self, amplitude: f64) -> f64 {
        let model = &self.model;
        let map = Mapping::build(&model.grid, &self.state.points, &model.bodies, &model.dirichlet, 0.0);
        let gamma = self.params.gamma_k;
        let faces = ghost_faces(self, &map);
        let blocks = blocks_of(&map, &faces);
        let pattern = Pattern::new(&map.dofs, &blocks, Storage::Full);
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rand = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let h = model.grid.h;
        let mut du = vec![[0.0; 2]; model.grid.num_nodes()];
        for (n, d) in map.dofs.node_dof.iter().enumerate() {
            for c in 0..2 {
                if let Dof::Free(_) = d[c] {
                    du[n][c] = amplitude * h * rand();
                }
            }
        }
        // Internal plus ghost force on the free dofs.
        let force = |du: &[P2]| {
            let it = evaluate(self, &map, du);
            let mut f = it.fint_free;
            for face in &faces {
                for r in 0..6 {
                    for c in 0..2 {
                        if let Dof::Free(row) = map.dofs.node_dof[face.nodes[r]][c] {
                            f[row] += gamma * (0..6).map(|k| face.j[r][k] * du[face.nodes[k]][c]).sum::<f64>();
                        }
                    }
                }
            }
            f
        };
        let it = evaluate(self, &map, &du);
        let k = tangent(self, &map, &pattern, &blocks, &faces, &it, gamma);
        let (cp, ri, val) = (k.col_ptr(), k.row_idx(), k.val());
        let mut worst = 0.0f64;
        for _ in 0..4 {
            let v: Vec<f64> = (0..map.dofs.n_free).map(|_| rand()).collect();
            let mut kv = vec![0.0; map.dofs.n_free];
            for c in 0..k.ncols() {
                for idx in cp[c]..cp[c + 1] {
                    kv[ri[idx]] += val[idx] * v[c];
                }
            }
            let eps = 1e-6 * h;
            let shifted = |sign: f64| {
                let mut d = du.clone();
                for (n, dd) in map.dofs.node_dof.iter().enumerate() {
                    for c in 0..2 {
                        if let Dof::Free(i) = dd[c] {
                            d[n][c] += sign * eps * v[i];
                        }
                    }
                }
                force(&d)
            };
            let (fp, fm) = (shifted(1.0), shifted(-1.0));
            let fd: Vec<f64> = fp.iter().zip(&fm).map(|(a, b)| (a - b) / (2.0 * eps)).collect();
            let diff: Vec<f64> = fd.iter().zip(&kv).map(|(a, b)| a - b).collect();
            worst = worst.max(norm(&diff) / norm(&kv).max(1e-300));
        }
        worst
    }
}
