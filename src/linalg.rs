//! Linear algebra on the reduced system: sparse Cholesky (faer) and
//! condition numbers.
//!
//! Matrices are stored as their lower triangle (what the Cholesky reads).
//!
//! Condition numbers `kappa_2 = lambda_max / lambda_min` of symmetric
//! positive definite matrices: exact dense eigenvalues for small systems;
//! above a size limit, Lanczos with full reorthogonalisation for
//! `lambda_max(A)` and for `lambda_max(A^-1) = 1/lambda_min(A)` through the
//! Cholesky factor already computed. Dense eigenvalues resolve `lambda_min`
//! only down to about `1e-16 lambda_max`; when the dense answer is near that
//! floor, `lambda_min` is taken from Lanczos on the inverse instead, which
//! stays accurate for graded matrices (tiny basis values). The method used is
//! part of the answer.

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::SparseColMat;
use faer::{Mat, Side};

/// The Cholesky factor of the reduced stiffness.
pub type Factor = Llt<usize, f64>;

/// Why a factorisation failed.
#[derive(Clone, Debug, PartialEq)]
pub enum FactorError {
    /// The matrix is not positive definite (singular or indefinite): some
    /// unknown is not held by stiffness or supports.
    NotPositiveDefinite {
        pivot: usize,
    },
    Other(String),
}

impl std::fmt::Display for FactorError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FactorError::NotPositiveDefinite { pivot } => write!(
                f,
                "the stiffness matrix is not positive definite (pivot {pivot} of the permuted system): \
                 a rigid-body mode is unrestrained or a node is held by almost no material"
            ),
            FactorError::Other(s) => write!(f, "{s}"),
        }
    }
}

/// Sparse Cholesky factorisation of a symmetric matrix given by its lower triangle.
pub fn cholesky(a: &SparseColMat<usize, f64>) -> Result<Factor, FactorError> {
    let symbolic = SymbolicLlt::try_new(a.symbolic(), Side::Lower).map_err(|e| FactorError::Other(format!("{e:?}")))?;
    Llt::try_new_with_symbolic(symbolic, a.as_ref(), Side::Lower).map_err(|e| match e {
        faer::sparse::linalg::LltError::Numeric(faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot {
            index,
        }) => FactorError::NotPositiveDefinite { pivot: index },
        other => FactorError::Other(format!("{other:?}")),
    })
}

/// Solve `A x = b` with the factor.
pub fn solve(factor: &Factor, b: &[f64]) -> Vec<f64> {
    let mut x = Mat::<f64>::from_fn(b.len(), 1, |i, _| b[i]);
    factor.solve_in_place(&mut x);
    (0..b.len()).map(|i| x[(i, 0)]).collect()
}

/// `y = A x` for a symmetric matrix stored as its lower triangle.
pub fn sym_lower_mul(a: &SparseColMat<usize, f64>, x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    let (cp, ri, v) = (a.col_ptr(), a.row_idx(), a.val());
    for c in 0..a.ncols() {
        for k in cp[c]..cp[c + 1] {
            let r = ri[k];
            y[r] += v[k] * x[c];
            if r != c {
                y[c] += v[k] * x[r];
            }
        }
    }
    y
}

/// How a condition number was obtained.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConditionMethod {
    /// Dense symmetric eigenvalues (exact to round-off).
    Dense,
    /// Dense `lambda_max`; `lambda_min` by Lanczos on the inverse because the
    /// dense value hit the round-off floor.
    DenseLanczosInverse,
    /// Lanczos for `lambda_max` and Lanczos on the inverse for `lambda_min`.
    Lanczos,
}

impl ConditionMethod {
    pub fn label(self) -> &'static str {
        match self {
            ConditionMethod::Dense => "dense",
            ConditionMethod::DenseLanczosInverse => "dense+lanczos-inv",
            ConditionMethod::Lanczos => "lanczos",
        }
    }
}

/// A 2-norm condition number with its extreme eigenvalues.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Condition {
    pub value: f64,
    pub lambda_min: f64,
    pub lambda_max: f64,
    pub method: ConditionMethod,
}

/// Condition number of the SPD matrix `a` (lower triangle) with Cholesky
/// factor `factor`: dense when `a` has at most `dense_limit` rows.
pub fn condition(a: &SparseColMat<usize, f64>, factor: &Factor, dense_limit: usize) -> Condition {
    let n = a.nrows();
    if n == 0 {
        return Condition {
            value: 1.0,
            lambda_min: 1.0,
            lambda_max: 1.0,
            method: ConditionMethod::Dense,
        };
    }
    let inverse_min = || 1.0 / lanczos_max(n, |x| solve(factor, x));
    if n <= dense_limit {
        let mut m = Mat::<f64>::zeros(n, n);
        let (cp, ri, v) = (a.col_ptr(), a.row_idx(), a.val());
        for c in 0..n {
            for k in cp[c]..cp[c + 1] {
                m[(ri[k], c)] += v[k];
                if ri[k] != c {
                    m[(c, ri[k])] += v[k];
                }
            }
        }
        if let Ok(ev) = m.self_adjoint_eigenvalues(Side::Lower) {
            let (lo, hi) = (ev[0], ev[n - 1]);
            // Dense eigenvalues are accurate to about n eps lambda_max.
            if lo > 1e-10 * hi {
                return Condition {
                    value: hi / lo,
                    lambda_min: lo,
                    lambda_max: hi,
                    method: ConditionMethod::Dense,
                };
            }
            let lo = inverse_min();
            return Condition {
                value: hi / lo,
                lambda_min: lo,
                lambda_max: hi,
                method: ConditionMethod::DenseLanczosInverse,
            };
        }
    }
    let hi = lanczos_max(n, |x| sym_lower_mul(a, x));
    let lo = inverse_min();
    Condition {
        value: hi / lo,
        lambda_min: lo,
        lambda_max: hi,
        method: ConditionMethod::Lanczos,
    }
}

/// Largest eigenvalue of a symmetric operator of size `n` by Lanczos with
/// full reorthogonalisation, from a fixed pseudo-random start (so results
/// are reproducible). Stops when the largest Ritz value settles to 1e-10
/// relative or after 120 iterations.
pub fn lanczos_max(n: usize, op: impl Fn(&[f64]) -> Vec<f64>) -> f64 {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut q: Vec<f64> = (0..n)
        .map(|_| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 + 0.5
        })
        .collect();
    let nq = dot(&q, &q).sqrt();
    q.iter_mut().for_each(|v| *v /= nq);
    let mut basis: Vec<Vec<f64>> = vec![q];
    let (mut alpha, mut beta) = (Vec::new(), Vec::<f64>::new());
    let mut last = f64::NAN;
    let max_iter = n.min(120);
    for j in 0..max_iter {
        let mut w = op(&basis[j]);
        alpha.push(dot(&w, &basis[j]));
        // Full reorthogonalisation, twice for safety.
        for _ in 0..2 {
            for b in &basis {
                let c = dot(&w, b);
                w.iter_mut().zip(b).for_each(|(wi, bi)| *wi -= c * bi);
            }
        }
        let bnorm = dot(&w, &w).sqrt();
        let ritz = tridiagonal_max(&alpha, &beta);
        let scale = alpha.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        if bnorm <= 1e-14 * scale || j + 1 == max_iter {
            return ritz;
        }
        if j >= 4 && (ritz - last).abs() <= 1e-10 * ritz.abs() {
            return ritz;
        }
        last = ritz;
        beta.push(bnorm);
        basis.push(w.into_iter().map(|v| v / bnorm).collect());
    }
    last
}

/// Largest eigenvalue of the symmetric tridiagonal matrix with diagonal
/// `alpha` and off-diagonal `beta`.
fn tridiagonal_max(alpha: &[f64], beta: &[f64]) -> f64 {
    let m = alpha.len();
    let t = Mat::<f64>::from_fn(m, m, |i, j| {
        if i == j {
            alpha[i]
        } else if i == j + 1 {
            beta[j]
        } else if j == i + 1 {
            beta[i]
        } else {
            0.0
        }
    });
    t.self_adjoint_eigenvalues(Side::Lower).map_or(f64::NAN, |ev| ev[m - 1])
}
