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

use crate::linalg::{self, FactorError};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, LdltRef, LltRef, SymbolicCholesky, SymbolicCholeskyRaw,
};
use faer::sparse::linalg::solvers::SymbolicLu;
use faer::sparse::SparseColMat;
use faer::{Conj, Mat, Par, Side};
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
    Cholesky(Arc<SymbolicCholesky<usize>>),
    Lu(SymbolicLu<usize>),
}

impl Symbolic {
    /// Analyse the pattern of `a` (its lower triangle when `symmetry` is
    /// [`Symmetry::Symmetric`]).
    pub fn new(a: &SparseColMat<usize, f64>, symmetry: Symmetry) -> Result<Symbolic, FactorError> {
        match symmetry {
            Symmetry::Symmetric => {
                factorize_symbolic_cholesky(a.symbolic(), Side::Lower, Default::default(), Default::default())
                    .map(|s| Symbolic::Cholesky(Arc::new(s)))
                    .map_err(|e| FactorError::Other(format!("{e:?}")))
            }
            Symmetry::General => linalg::lu_symbolic(a).map(Symbolic::Lu),
        }
    }
}

/// A factorised reduced tangent.
pub struct Factorisation {
    kind: Factor,
    /// Negative pivots of `L D L^T` (0 for Cholesky; `None` for LU).
    negative_pivots: Option<usize>,
}

enum Factor {
    Cholesky(Arc<SymbolicCholesky<usize>>, Vec<f64>),
    /// The factor, and the matrix (lower triangle) for the backward-error
    /// check of each solve.
    Ldlt(Arc<SymbolicCholesky<usize>>, Vec<f64>, SparseColMat<usize, f64>),
    Lu(linalg::LuFactor),
}

fn par() -> Par {
    faer::get_global_parallelism()
}

fn oom() -> FactorError {
    FactorError::Other("out of memory for the factor".into())
}

impl Factorisation {
    /// Factorise `a` with the analysis of its pattern: Cholesky, then
    /// `L D L^T` at a non-positive pivot, then LU (of the matrix made whole)
    /// when `L D L^T` meets an exactly zero pivot; LU for general matrices.
    pub fn new(symbolic: &Symbolic, a: &SparseColMat<usize, f64>) -> Result<Factorisation, FactorError> {
        let s = match symbolic {
            Symbolic::Lu(s) => {
                return Ok(Factorisation {
                    kind: Factor::Lu(linalg::lu(s, a)?),
                    negative_pivots: None,
                })
            }
            Symbolic::Cholesky(s) => s,
        };
        let mut values = Vec::new();
        values.try_reserve_exact(s.len_val()).map_err(|_| oom())?;
        values.resize(s.len_val(), 0.0);
        let llt = {
            let mut mem = MemBuffer::try_new(s.factorize_numeric_llt_scratch::<f64>(par(), Default::default()))
                .map_err(|_| oom())?;
            s.factorize_numeric_llt(
                &mut values,
                a.as_ref(),
                Side::Lower,
                Default::default(),
                par(),
                MemStack::new(&mut mem),
                Default::default(),
            )
            .is_ok()
        };
        if llt && values.iter().all(|v| v.is_finite()) {
            return Ok(Factorisation {
                kind: Factor::Cholesky(s.clone(), values),
                negative_pivots: Some(0),
            });
        }
        let ldlt = {
            let mut mem = MemBuffer::try_new(s.factorize_numeric_ldlt_scratch::<f64>(par(), Default::default()))
                .map_err(|_| oom())?;
            s.factorize_numeric_ldlt(
                &mut values,
                a.as_ref(),
                Side::Lower,
                Default::default(),
                par(),
                MemStack::new(&mut mem),
                Default::default(),
            )
            .is_ok()
        };
        if ldlt && values.iter().all(|v| v.is_finite()) {
            let d = pivots(s, &values);
            return Ok(Factorisation {
                negative_pivots: Some(d.iter().filter(|&&x| x < 0.0).count()),
                kind: Factor::Ldlt(s.clone(), values, a.clone()),
            });
        }
        drop(values);
        let whole = symmetrised(a)?;
        let lu = linalg::lu(&linalg::lu_symbolic(&whole)?, &whole)?;
        Ok(Factorisation {
            kind: Factor::Lu(lu),
            negative_pivots: None,
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
        if let Factor::Ldlt(_, _, a) = &self.kind {
            let r = linalg::sym_lower_mul(a, &x);
            let num: f64 = r.iter().zip(b).map(|(r, b)| (r - b) * (r - b)).sum::<f64>().sqrt();
            let den: f64 = b.iter().map(|b| b * b).sum::<f64>().sqrt();
            if !(num <= 1e-8 * den.max(f64::MIN_POSITIVE)) {
                let whole = symmetrised(a)?;
                self.kind = Factor::Lu(linalg::lu(&linalg::lu_symbolic(&whole)?, &whole)?);
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
                (0..b.len()).map(|i| x[(i, 0)]).collect()
            }
            Factor::Ldlt(s, v, _) => {
                let mut x = Mat::<f64>::from_fn(b.len(), 1, |i, _| b[i]);
                let mut mem = MemBuffer::new(s.solve_in_place_scratch::<f64>(1, par()));
                LdltRef::new(s, v).solve_in_place_with_conj(Conj::No, x.as_mut(), par(), MemStack::new(&mut mem));
                (0..b.len()).map(|i| x[(i, 0)]).collect()
            }
        }
    }
}

/// The pivots `D` of an `L D L^T` factor, in the factor's (permuted) order.
fn pivots(s: &SymbolicCholesky<usize>, values: &[f64]) -> Vec<f64> {
    match s.raw() {
        SymbolicCholeskyRaw::Simplicial(sym) => {
            let cp = sym.col_ptr();
            (0..sym.nrows()).map(|k| values[cp[k]]).collect()
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
fn symmetrised(a: &SparseColMat<usize, f64>) -> Result<SparseColMat<usize, f64>, FactorError> {
    let (cp, ri, v) = (a.col_ptr(), a.row_idx(), a.val());
    let mut t = Vec::with_capacity(2 * v.len());
    for c in 0..a.ncols() {
        for k in cp[c]..cp[c + 1] {
            t.push(faer::sparse::Triplet::new(ri[k], c, v[k]));
            if ri[k] != c {
                t.push(faer::sparse::Triplet::new(c, ri[k], v[k]));
            }
        }
    }
    SparseColMat::try_new_from_triplets(a.nrows(), a.ncols(), &t).map_err(|e| FactorError::Other(format!("{e:?}")))
}
