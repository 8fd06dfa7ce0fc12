//! The factorisation of a reduced tangent, chosen by its structure, and its
//! inertia (the lab's stability diagnostic).
//!
//! - A **symmetric** tangent (Hencky elasticity, associative von Mises
//!   plasticity, the ghost term `gamma_K J_G`, the implicit boundary's band,
//!   dead loads) is stored as its lower triangle and factorised by sparse
//!   Cholesky `K = L L^T`. The symbolic analysis (fill-reducing ordering,
//!   elimination tree, supernodes) is computed once per pattern and reused
//!   by every iteration of a step.
//! - When Cholesky meets a non-positive pivot, the same symbolic analysis
//!   gives `K = L D L^T` (unit `L`, diagonal `D`, no pivoting, as the direct
//!   solvers of most implicit FE codes). By Sylvester's law of inertia the
//!   number of negative entries of `D` is the number of negative
//!   eigenvalues of `K`: on an equilibrium path, a negative pivot is a loss
//!   of stability (limit point, bifurcation) or a spurious mode (a tiny cut
//!   cell without ghost stabilisation). Without pivoting, `L D L^T` can
//!   lose accuracy on an indefinite matrix: every solve checks its backward
//!   error and falls back to LU when it is above `1e-8`.
//! - A **non-symmetric** tangent (follower tractions' load stiffness,
//!   F-bar) is stored whole and factorised by sparse LU with partial
//!   pivoting (symbolic analysis reused); its inertia is not available.

use crate::linalg::{self, FactorError, Ix, SparseRef};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{LdltRef, LltRef, SymbolicCholesky, SymbolicCholeskyRaw};
use faer::sparse::linalg::solvers::SymbolicLu;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, Mat, Par};
use std::sync::Arc;

/// Which factorisation solved a system.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FactorKind {
    /// Sparse Cholesky `L L^T` (symmetric positive definite).
    Cholesky,
    /// Sparse `L D L^T` after a non-positive Cholesky pivot (symmetric
    /// indefinite).
    Ldlt,
    /// Sparse LU with partial pivoting (non-symmetric, or `L D L^T` not
    /// accurate enough).
    Lu,
}

impl FactorKind {
    pub fn label(self) -> &'static str {
        match self {
            FactorKind::Cholesky => "cholesky",
            FactorKind::Ldlt => "ldlt",
            FactorKind::Lu => "lu",
        }
    }
}

/// How a matrix is stored: its lower triangle (symmetric) or every entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Symmetry {
    Symmetric,
    General,
}

/// The symbolic analysis of one pattern, reused for every matrix of it.
#[derive(Clone)]
pub enum Symbolic {
    Cholesky(Arc<SymbolicCholesky<Ix>>),
    /// The LU analysis and an estimate of its factor (partial pivoting
    /// decides the fill only numerically).
    Lu(SymbolicLu<Ix>, Estimate),
}

/// What a factor will take, known before it is computed.
#[derive(Clone, Debug)]
pub struct Estimate {
    pub what: String,
    pub bytes: u64,
}

impl Symbolic {
    /// Analyse the pattern of `a` (its lower triangle when `symmetry` is
    /// [`Symmetry::Symmetric`]).
    pub fn new(a: SparseRef<'_>, symmetry: Symmetry) -> Result<Symbolic, FactorError> {
        match symmetry {
            Symmetry::Symmetric => linalg::cholesky_symbolic(a).map(Symbolic::Cholesky),
            Symmetry::General => {
                let lu = linalg::lu_symbolic(a)?;
                let chol = linalg::cholesky_symbolic(lower_of_sum(a)?.as_ref())?;
                Ok(Symbolic::Lu(lu, lu_estimate(&chol, a.compute_nnz())))
            }
        }
    }

    /// What the numeric factor will take.
    pub fn estimate(&self) -> Estimate {
        match self {
            Symbolic::Cholesky(s) => Estimate {
                what: linalg::factor_what("Cholesky", s),
                bytes: linalg::cholesky_bytes(s),
            },
            Symbolic::Lu(_, e) => e.clone(),
        }
    }
}

/// The LU factor of a matrix whose `A + A^T` has the Cholesky analysis
/// `chol`: without pivoting, `L` and `U` have the pattern of the Cholesky
/// factor's `L` and its transpose (values and row indices, 16 bytes an
/// entry), and faer copies the matrix (`nnz` entries). Row pivoting adds
/// fill this does not count; the tangents here are diagonally dominant
/// enough that it stays small.
fn lu_estimate(chol: &SymbolicCholesky<Ix>, nnz: usize) -> Estimate {
    let entries = 2 * chol.len_val();
    Estimate {
        what: format!(
            "the LU factor of {} unknowns (about {:.2e} entries)",
            chol.nrows(),
            entries as f64
        ),
        bytes: (16 * entries + 16 * nnz) as u64,
    }
}

/// The lower triangle of the pattern of `A + A^T` (values 1).
fn lower_of_sum(a: SparseRef<'_>) -> Result<SparseColMat<Ix, f64>, FactorError> {
    let ri = a.row_idx();
    let mut t = Vec::new();
    t.try_reserve_exact(ri.len())
        .map_err(|_| FactorError::allocation("the pattern of A + A^T", 16 * ri.len()))?;
    for c in 0..a.ncols() {
        let col = c as Ix;
        for &r in &ri[a.symbolic().col_range(c)] {
            t.push(Triplet::new(r.max(col), r.min(col), 1.0));
        }
    }
    SparseColMat::try_new_from_triplets(a.nrows(), a.ncols(), &t).map_err(|e| FactorError::Other(format!("{e:?}")))
}

/// A copy of `a` with its own pattern, reserved fallibly.
fn owned(a: SparseRef<'_>) -> Result<SparseColMat<Ix, f64>, FactorError> {
    let fail = || FactorError::allocation("a copy of the matrix", 16 * a.compute_nnz());
    let symbolic = a.symbolic().to_owned().map_err(|_| fail())?;
    let mut values = Vec::new();
    values.try_reserve_exact(a.val().len()).map_err(|_| fail())?;
    values.extend_from_slice(a.val());
    Ok(SparseColMat::new(symbolic, values))
}

/// A factorised reduced tangent.
pub struct Factorisation {
    kind: Factor,
    /// Negative pivots of `L D L^T` (0 for Cholesky; `None` for LU).
    negative_pivots: Option<usize>,
    /// The memory budget of a fallback to LU during a solve.
    budget: u64,
}

enum Factor {
    Cholesky(Arc<SymbolicCholesky<Ix>>, Vec<f64>),
    /// The factor, and the matrix (lower triangle) for the backward-error
    /// check of each solve.
    Ldlt(Arc<SymbolicCholesky<Ix>>, Vec<f64>, SparseColMat<Ix, f64>),
    Lu(linalg::LuFactor),
}

fn par() -> Par {
    faer::get_global_parallelism()
}

/// LU of the symmetric `a` (lower triangle) made whole, within `budget`;
/// `s` is the Cholesky analysis of its pattern.
fn whole_lu(s: &SymbolicCholesky<Ix>, a: SparseRef<'_>, budget: u64) -> Result<Factor, FactorError> {
    let e = lu_estimate(s, 2 * a.compute_nnz());
    linalg::check_memory(|| e.what.clone(), e.bytes, budget)?;
    let whole = symmetrised(a)?;
    Ok(Factor::Lu(linalg::lu(
        &linalg::lu_symbolic(whole.as_ref())?,
        whole.as_ref(),
        || e.what.clone(),
        e.bytes,
    )?))
}

impl Factorisation {
    /// The buffer of the factor's values, for the next factor of the same
    /// analysis ([`Factorisation::new_reusing`]); empty for LU.
    pub fn into_values(self) -> Vec<f64> {
        match self.kind {
            Factor::Cholesky(_, v) | Factor::Ldlt(_, v, _) => v,
            Factor::Lu(_) => Vec::new(),
        }
    }

    /// Factorise `a` with the analysis of its pattern: Cholesky, then
    /// `L D L^T` at a non-positive pivot, then LU (of the matrix made whole)
    /// when `L D L^T` meets an exactly zero pivot; LU for general matrices.
    /// A factor whose estimate ([`Symbolic::estimate`]) would take the
    /// process beyond `budget` bytes is refused before it is computed
    /// ([`linalg::check_memory`]), and one whose memory cannot be allocated
    /// is an error, not an abort.
    pub fn new(symbolic: &Symbolic, a: SparseRef<'_>, budget: u64) -> Result<Factorisation, FactorError> {
        Factorisation::new_reusing(symbolic, a, budget, Vec::new())
    }

    /// [`Factorisation::new`] writing a Cholesky or `L D L^T` factor into
    /// `spare`, the values of an earlier factor of the same analysis
    /// ([`Factorisation::into_values`]), when it is large enough: a Newton
    /// step's iterations after its first reuse one buffer instead of
    /// having the system zero fresh pages for each.
    pub fn new_reusing(
        symbolic: &Symbolic,
        a: SparseRef<'_>,
        budget: u64,
        spare: Vec<f64>,
    ) -> Result<Factorisation, FactorError> {
        let e = symbolic.estimate();
        linalg::check_memory(|| e.what.clone(), e.bytes, budget)?;
        let s = match symbolic {
            Symbolic::Lu(s, _) => {
                return Ok(Factorisation {
                    kind: Factor::Lu(linalg::lu(s, a, || e.what.clone(), e.bytes)?),
                    negative_pivots: None,
                    budget,
                })
            }
            Symbolic::Cholesky(s) => s,
        };
        let mut values = linalg::factor_values_in(s, spare, || e.what.clone())?;
        let llt = linalg::numeric_llt(s, a, &mut values)?.is_ok();
        if llt && values.iter().all(|v| v.is_finite()) {
            return Ok(Factorisation {
                kind: Factor::Cholesky(s.clone(), values),
                negative_pivots: Some(0),
                budget,
            });
        }
        let ldlt = linalg::numeric_ldlt(s, a, &mut values)?;
        if ldlt && values.iter().all(|v| v.is_finite()) {
            let d = pivots(s, &values);
            return Ok(Factorisation {
                negative_pivots: Some(d.iter().filter(|&&x| x < 0.0).count()),
                kind: Factor::Ldlt(s.clone(), values, owned(a)?),
                budget,
            });
        }
        drop(values);
        Ok(Factorisation {
            kind: whole_lu(s, a, budget)?,
            negative_pivots: None,
            budget,
        })
    }

    pub fn kind(&self) -> FactorKind {
        match self.kind {
            Factor::Cholesky(..) => FactorKind::Cholesky,
            Factor::Ldlt(..) => FactorKind::Ldlt,
            Factor::Lu(_) => FactorKind::Lu,
        }
    }

    /// Negative eigenvalues of the matrix (`L D L^T` pivots; 0 after a
    /// successful Cholesky; `None` after LU).
    pub fn negative_pivots(&self) -> Option<usize> {
        self.negative_pivots
    }

    /// Solve `A x = b`. An `L D L^T` solve whose backward error
    /// `|A x - b| / |b|` exceeds `1e-8` is redone by LU (and the factor
    /// kind then says so for the rest of its life).
    pub fn solve(&mut self, b: &[f64]) -> Result<Vec<f64>, FactorError> {
        let x = self.solve_once(b);
        if let Factor::Ldlt(s, _, a) = &self.kind {
            let r = linalg::sym_lower_mul(a.as_ref(), &x);
            let num: f64 = r.iter().zip(b).map(|(r, b)| (r - b) * (r - b)).sum::<f64>().sqrt();
            let den: f64 = b.iter().map(|b| b * b).sum::<f64>().sqrt();
            if !(num <= 1e-8 * den.max(f64::MIN_POSITIVE)) {
                let lu = whole_lu(s, a.as_ref(), self.budget)?;
                self.kind = lu;
                return Ok(self.solve_once(b));
            }
        }
        Ok(x)
    }

    /// Solve `A^T x = b` (the same as [`Factorisation::solve`] for the
    /// symmetric factors, without the backward-error check).
    pub fn solve_transpose(&self, b: &[f64]) -> Vec<f64> {
        match &self.kind {
            Factor::Lu(f) => linalg::solve_lu(f, b, true),
            _ => self.solve_once(b),
        }
    }

    fn solve_once(&self, b: &[f64]) -> Vec<f64> {
        match &self.kind {
            Factor::Lu(f) => linalg::solve_lu(f, b, false),
            Factor::Cholesky(s, v) => {
                let mut x = Mat::<f64>::from_fn(b.len(), 1, |i, _| b[i]);
                let mut mem = MemBuffer::new(s.solve_in_place_scratch::<f64>(1, par()));
                LltRef::new(s, v).solve_in_place_with_conj(Conj::No, x.as_mut(), par(), MemStack::new(&mut mem));
                crate::vector_state::after_wide_kernels();
                (0..b.len()).map(|i| x[(i, 0)]).collect()
            }
            Factor::Ldlt(s, v, _) => {
                let mut x = Mat::<f64>::from_fn(b.len(), 1, |i, _| b[i]);
                let mut mem = MemBuffer::new(s.solve_in_place_scratch::<f64>(1, par()));
                LdltRef::new(s, v).solve_in_place_with_conj(Conj::No, x.as_mut(), par(), MemStack::new(&mut mem));
                crate::vector_state::after_wide_kernels();
                (0..b.len()).map(|i| x[(i, 0)]).collect()
            }
        }
    }
}

/// The pivots `D` of an `L D L^T` factor, in the factor's (permuted) order.
fn pivots(s: &SymbolicCholesky<Ix>, values: &[f64]) -> Vec<f64> {
    match s.raw() {
        SymbolicCholeskyRaw::Simplicial(sym) => {
            let cp = sym.col_ptr();
            (0..sym.nrows()).map(|k| values[cp[k] as usize]).collect()
        }
        SymbolicCholeskyRaw::Supernodal(sym) => {
            let f = faer::sparse::linalg::cholesky::supernodal::SupernodalLdltRef::new(sym, values);
            let mut d = Vec::with_capacity(sym.nrows());
            for k in 0..sym.n_supernodes() {
                let m = f.supernode(k).val();
                for j in 0..m.ncols() {
                    d.push(m[(j, j)]);
                }
            }
            d
        }
    }
}

/// The whole matrix of a symmetric one given by its lower triangle.
fn symmetrised(a: SparseRef<'_>) -> Result<SparseColMat<Ix, f64>, FactorError> {
    let (ri, v) = (a.row_idx(), a.val());
    let mut t = Vec::new();
    t.try_reserve_exact(2 * v.len())
        .map_err(|_| FactorError::allocation("the whole matrix for LU", 32 * v.len()))?;
    for c in 0..a.ncols() {
        let col = c as Ix;
        for k in a.symbolic().col_range(c) {
            t.push(faer::sparse::Triplet::new(ri[k], col, v[k]));
            if ri[k] != col {
                t.push(faer::sparse::Triplet::new(col, ri[k], v[k]));
            }
        }
    }
    SparseColMat::try_new_from_triplets(a.nrows(), a.ncols(), &t).map_err(|e| FactorError::Other(format!("{e:?}")))
}
