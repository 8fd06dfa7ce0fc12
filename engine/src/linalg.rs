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

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky};
use faer::sparse::linalg::solvers::{Lu, SymbolicLu};
use faer::sparse::linalg::SymbolicSupernodalParams;
use faer::sparse::SparseColMatRef;

/// A reduced matrix as every solver routine reads it: its values over a
/// pattern it may share ([`crate::assembly::Pattern::matrix`]).
pub type SparseRef<'a> = SparseColMatRef<'a, Ix, f64>;

/// The sparse index type of every pattern, matrix and factor structure:
/// 32 bits, as direct solvers use by default (CHOLMOD's `int` version,
/// MUMPS), half the memory of 64-bit indices (at 10^5 unknowns 4 MB of a
/// step's pattern and 6 MB of its Cholesky analysis). A pattern of more
/// than 2^32 entries is refused ([`crate::assembly::Pattern::new`]).
pub type Ix = u32;
use faer::{Conj, Mat, Par, Side};
use std::sync::Arc;

/// The symbolic Cholesky analysis of a pattern (ordering, elimination
/// tree, supernodes), shared by every matrix of that pattern.
pub type CholeskySymbolic = Arc<SymbolicCholesky<Ix>>;

/// The Cholesky factor of the reduced stiffness: the analysis and the
/// values of `L`.
#[derive(Clone, Debug)]
pub struct Factor {
    symbolic: CholeskySymbolic,
    values: Vec<f64>,
}

impl Factor {
    /// The buffer of `L`'s values, for the next factor of the same size
    /// ([`cholesky_reusing`]).
    pub fn into_values(self) -> Vec<f64> {
        self.values
    }

    /// Overwrite `x` with `A^-1 x`.
    pub fn solve_in_place(&self, x: &mut Mat<f64>) {
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(x.ncols(), par()));
        LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
            Conj::No,
            x.as_mut(),
            par(),
            MemStack::new(&mut mem),
        );
        crate::vector_state::after_wide_kernels();
    }
}

fn par() -> Par {
    faer::get_global_parallelism()
}

/// Why a factorisation failed.
#[derive(Clone, Debug, PartialEq)]
pub enum FactorError {
    /// The matrix is not positive definite (singular or indefinite): some
    /// unknown is not held by stiffness or supports.
    NotPositiveDefinite {
        pivot: usize,
    },
    /// The factor does not fit: its estimate (from the symbolic analysis)
    /// would take the process beyond `budget`, or (`budget` `None`) its
    /// memory could not be allocated.
    Memory {
        /// What needs the memory (`the Cholesky factor of 12480 unknowns (3.1e6 entries)`).
        what: String,
        bytes: u64,
        /// The process's resident memory before it (0 where unknown).
        in_use: u64,
        budget: Option<u64>,
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
            FactorError::Memory {
                what,
                bytes,
                in_use,
                budget: Some(budget),
            } => write!(
                f,
                "{what} needs an estimated {}, which with the {} in use exceeds the {} allowed (--max-memory)",
                crate::model::bytes(*bytes),
                crate::model::bytes(*in_use),
                crate::model::bytes(*budget)
            ),
            FactorError::Memory {
                what,
                bytes,
                in_use,
                budget: None,
            } => write!(
                f,
                "{} could not be allocated ({} in use)",
                sized(what, *bytes),
                crate::model::bytes(*in_use)
            ),
            FactorError::Other(s) => write!(f, "{s}"),
        }
    }
}

/// `12.3 MB for the factor`, or `memory for the factor` when the size is
/// not known (0).
pub fn sized(what: &str, bytes: u64) -> String {
    if bytes == 0 {
        format!("memory for {what}")
    } else {
        format!("{} for {what}", crate::model::bytes(bytes))
    }
}

impl FactorError {
    /// The step failure this makes at `step`: out of memory, or a singular
    /// system.
    pub fn at_step(self, step: usize) -> crate::StepFailure {
        match self {
            FactorError::Memory {
                what,
                bytes,
                in_use,
                budget,
            } => crate::StepFailure::OutOfMemory {
                step,
                what,
                bytes,
                in_use,
                budget,
            },
            e => crate::StepFailure::Singular {
                step,
                reason: e.to_string(),
            },
        }
    }

    /// Memory for `what` (`bytes`) could not be allocated.
    pub fn allocation(what: impl Into<String>, bytes: usize) -> FactorError {
        FactorError::Memory {
            what: what.into(),
            bytes: bytes as u64,
            in_use: resident_bytes().unwrap_or(0),
            budget: None,
        }
    }
}

pub use crate::procfs::resident_bytes;

/// Refuse an allocation of `bytes` for `what` that would take the process's
/// resident memory beyond `budget` (`u64::MAX`: no check).
pub fn check_memory(what: impl FnOnce() -> String, bytes: u64, budget: u64) -> Result<(), FactorError> {
    if budget == u64::MAX {
        return Ok(());
    }
    let in_use = resident_bytes().unwrap_or(0);
    if in_use.saturating_add(bytes) <= budget {
        return Ok(());
    }
    Err(FactorError::Memory {
        what: what(),
        bytes,
        in_use,
        budget: Some(budget),
    })
}

/// Bytes a numeric Cholesky or `L D L^T` with analysis `s` allocates: the
/// values of `L` (counted by the symbolic analysis, fill-in included) and
/// faer's workspace.
pub fn cholesky_bytes(s: &SymbolicCholesky<Ix>) -> u64 {
    let scratch = s
        .factorize_numeric_ldlt_scratch::<f64>(par(), Default::default())
        .size_bytes()
        .max(
            s.factorize_numeric_llt_scratch::<f64>(par(), Default::default())
                .size_bytes(),
        );
    (8 * s.len_val()).saturating_add(scratch) as u64
}

/// A factor's description for messages.
pub fn factor_what(kind: &str, s: &SymbolicCholesky<Ix>) -> String {
    format!(
        "the {kind} factor of {} unknowns ({:.2e} entries)",
        s.nrows(),
        s.len_val() as f64
    )
}

/// Sparse Cholesky factorisation of a symmetric matrix given by its lower triangle.
pub fn cholesky(a: SparseRef<'_>) -> Result<Factor, FactorError> {
    cholesky_with(&cholesky_symbolic(a)?, a, u64::MAX)
}

/// [`cholesky`] refused beyond a memory budget ([`check_memory`]).
pub fn cholesky_within(a: SparseRef<'_>, budget: u64) -> Result<Factor, FactorError> {
    cholesky_with(&cholesky_symbolic(a)?, a, budget)
}

/// Symbolic Cholesky analysis (ordering, elimination tree) of a pattern, to
/// reuse for every matrix of that pattern.
///
/// Supernodes are not relaxed: faer by default merges small adjacent
/// supernodes when the merged block is mostly nonzero, storing and
/// computing its zeros. Without merging, the 10^5-unknown linear block's
/// factor is 73 MB instead of 81 MB, its analysis about 3 MB larger (more
/// supernodes, each with its row indices), the step's peak 7 MB lower
/// (167 to 160 MB), and the factorisation as fast within the noise at 10^5
/// and 10^6 unknowns. Every shipped scene prints the same numbers either
/// way; larger systems may differ at round-off.
pub fn cholesky_symbolic(a: SparseRef<'_>) -> Result<CholeskySymbolic, FactorError> {
    cholesky_symbolic_relaxed(a, false)
}

/// [`cholesky_symbolic`], with faer's default merging of small supernodes
/// when `relaxed`: the implicit dynamic step's scalar mass (GIMP block of
/// 65,536 points, two parts of 16,500 unknowns) factorises in 33 instead
/// of 41 ms that way.
pub fn cholesky_symbolic_relaxed(a: SparseRef<'_>, relaxed: bool) -> Result<CholeskySymbolic, FactorError> {
    let params = CholeskySymbolicParams {
        supernodal_params: if relaxed {
            SymbolicSupernodalParams::default()
        } else {
            SymbolicSupernodalParams { relax: None }
        },
        ..Default::default()
    };
    factorize_symbolic_cholesky(a.symbolic(), Side::Lower, Default::default(), params)
        .map(Arc::new)
        .map_err(|e| match e {
            faer::sparse::FaerError::OutOfMemory => {
                FactorError::allocation(format!("the symbolic analysis of {} unknowns", a.nrows()), 0)
            }
            e => FactorError::Other(format!("{e:?}")),
        })
}

/// A zeroed buffer for the values of a factor of `s`, allocated so that a
/// failure is an error naming `what`, not an abort.
pub fn factor_values(s: &SymbolicCholesky<Ix>, what: impl FnOnce() -> String) -> Result<Vec<f64>, FactorError> {
    let mut values = Vec::new();
    values
        .try_reserve_exact(s.len_val())
        .map_err(|_| FactorError::allocation(what(), 8 * s.len_val()))?;
    values.resize(s.len_val(), 0.0);
    Ok(values)
}

/// [`factor_values`] in `spare` (an earlier factor's values) when it
/// holds enough: zeroed again, without fresh pages from the system.
pub fn factor_values_in(
    s: &SymbolicCholesky<Ix>,
    mut spare: Vec<f64>,
    what: impl FnOnce() -> String,
) -> Result<Vec<f64>, FactorError> {
    if spare.capacity() < s.len_val() {
        // Freed first: the two are never held at once.
        drop(spare);
        return factor_values(s, what);
    }
    spare.clear();
    spare.resize(s.len_val(), 0.0);
    Ok(spare)
}

/// A factorisation's workspace, allocated fallibly.
pub fn workspace(req: faer::dyn_stack::StackReq) -> Result<MemBuffer, FactorError> {
    MemBuffer::try_new(req).map_err(|_| FactorError::allocation("the factorisation's workspace", req.size_bytes()))
}

/// Numeric `L L^T` of `a` into `values` (the analysis `s` of its pattern):
/// `Ok(Err(pivot))` at the first non-positive pivot.
pub fn numeric_llt(
    s: &SymbolicCholesky<Ix>,
    a: SparseRef<'_>,
    values: &mut [f64],
) -> Result<Result<(), usize>, FactorError> {
    let mut mem = workspace(s.factorize_numeric_llt_scratch::<f64>(par(), Default::default()))?;
    let done = s.factorize_numeric_llt(
        values,
        a.as_ref(),
        Side::Lower,
        Default::default(),
        par(),
        MemStack::new(&mut mem),
        Default::default(),
    );
    crate::vector_state::after_wide_kernels();
    Ok(done.map(|_| ()).map_err(|e| match e {
        faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index } => index,
    }))
}

/// Numeric `L D L^T` of `a` into `values` (the analysis `s` of its
/// pattern): whether faer completed it (its pivots may be of either sign).
pub fn numeric_ldlt(s: &SymbolicCholesky<Ix>, a: SparseRef<'_>, values: &mut [f64]) -> Result<bool, FactorError> {
    let mut mem = workspace(s.factorize_numeric_ldlt_scratch::<f64>(par(), Default::default()))?;
    let done = s.factorize_numeric_ldlt(
        values,
        a.as_ref(),
        Side::Lower,
        Default::default(),
        par(),
        MemStack::new(&mut mem),
        Default::default(),
    );
    crate::vector_state::after_wide_kernels();
    Ok(done.is_ok())
}

/// Numeric Cholesky with a symbolic analysis of the same pattern, refused
/// when its estimate ([`cholesky_bytes`]) exceeds `budget`
/// ([`check_memory`]); an allocation that fails is an error too.
pub fn cholesky_with(symbolic: &CholeskySymbolic, a: SparseRef<'_>, budget: u64) -> Result<Factor, FactorError> {
    cholesky_reusing(symbolic, a, budget, Vec::new())
}

/// [`cholesky_with`] writing the factor's values into `spare` (a buffer
/// of an earlier factor, [`Factor::into_values`]) when it is large
/// enough: a step that factorises a matrix of the same size every time
/// reuses its memory instead of having fresh pages zeroed by the system.
pub fn cholesky_reusing(
    symbolic: &CholeskySymbolic,
    a: SparseRef<'_>,
    budget: u64,
    spare: Vec<f64>,
) -> Result<Factor, FactorError> {
    let s = symbolic;
    check_memory(|| factor_what("Cholesky", s), cholesky_bytes(s), budget)?;
    let mut values = factor_values_in(s, spare, || factor_what("Cholesky", s))?;
    numeric_llt(s, a, &mut values)?.map_err(|pivot| FactorError::NotPositiveDefinite { pivot })?;
    Ok(Factor {
        symbolic: s.clone(),
        values,
    })
}

/// Solve `A x = b` with the factor.
pub fn solve(factor: &Factor, b: &[f64]) -> Vec<f64> {
    let mut x = Mat::<f64>::from_fn(b.len(), 1, |i, _| b[i]);
    factor.solve_in_place(&mut x);
    (0..b.len()).map(|i| x[(i, 0)]).collect()
}

/// `y = A x` for a symmetric matrix stored as its lower triangle.
pub fn sym_lower_mul(a: SparseRef<'_>, x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    let (ri, v) = (a.row_idx(), a.val());
    for c in 0..a.ncols() {
        for k in a.symbolic().col_range(c) {
            let r = ri[k] as usize;
            y[r] += v[k] * x[c];
            if r != c {
                y[c] += v[k] * x[r];
            }
        }
    }
    y
}

/// Sparse LU factor of a non-symmetric reduced tangent.
pub type LuFactor = Lu<Ix, f64>;

/// Symbolic LU analysis of a pattern, reused across Newton iterations.
/// faer reserves its workspace fallibly but allocates COLAMD's elimination
/// tree and postorder (`n` indices each) infallibly: twice the memory the
/// analysis takes is reserved and released first, so that a process short
/// of it gets an error here rather than an abort inside faer.
pub fn lu_symbolic(a: SparseRef<'_>) -> Result<SymbolicLu<Ix>, FactorError> {
    let (m, n, nnz) = (a.nrows(), a.ncols(), a.compute_nnz());
    let scratch = faer::sparse::linalg::colamd::order_scratch::<Ix>(m, n, nnz).size_bytes();
    let probe = scratch
        .saturating_add(8 * (m + 1 + nnz))
        .saturating_add(8 * 16 * m.max(n))
        .saturating_mul(2);
    if Vec::<u8>::new().try_reserve_exact(probe).is_err() {
        return Err(FactorError::allocation(
            format!("the symbolic LU analysis of {n} unknowns"),
            probe,
        ));
    }
    SymbolicLu::try_new(a.symbolic()).map_err(|e| match e {
        faer::sparse::FaerError::OutOfMemory => {
            FactorError::allocation(format!("the symbolic LU analysis of {} unknowns", a.nrows()), 0)
        }
        e => FactorError::Other(format!("{e:?}")),
    })
}

/// Numeric LU with a symbolic analysis of the same pattern. A structurally
/// singular matrix or a factor with non-finite entries is an error. faer
/// reserves the factor's memory fallibly as partial pivoting grows it; a
/// reservation that fails is a memory failure naming `what` (the factor,
/// `bytes` its estimate before pivoting), not an abort.
pub fn lu(
    symbolic: &SymbolicLu<Ix>,
    a: SparseRef<'_>,
    what: impl FnOnce() -> String,
    bytes: u64,
) -> Result<LuFactor, FactorError> {
    use faer::sparse::linalg::LuError;
    let f = Lu::try_new_with_symbolic(symbolic.clone(), a.as_ref()).map_err(|e| match e {
        LuError::SymbolicSingular { index } => FactorError::NotPositiveDefinite { pivot: index },
        LuError::Generic(faer::sparse::FaerError::OutOfMemory) => FactorError::allocation(what(), bytes as usize),
        other => FactorError::Other(format!("{other:?}")),
    });
    crate::vector_state::after_wide_kernels();
    f
}

/// Solve `A x = b` (or `A^T x = b`) with an LU factor.
pub fn solve_lu(factor: &LuFactor, b: &[f64], transpose: bool) -> Vec<f64> {
    let mut x = Mat::<f64>::from_fn(b.len(), 1, |i, _| b[i]);
    if transpose {
        factor.solve_transpose_in_place(&mut x);
    } else {
        factor.solve_in_place(&mut x);
    }
    crate::vector_state::after_wide_kernels();
    (0..b.len()).map(|i| x[(i, 0)]).collect()
}

/// `|A|_1`, the largest column sum of `|a_ij|`, of a matrix with every
/// entry stored or (`lower`) of a symmetric one given by its lower triangle.
pub fn one_norm(a: SparseRef<'_>, lower: bool) -> f64 {
    let (ri, v) = (a.row_idx(), a.val());
    let mut sums = vec![0.0; a.ncols()];
    for c in 0..a.ncols() {
        for k in a.symbolic().col_range(c) {
            let r = ri[k] as usize;
            sums[c] += v[k].abs();
            if lower && r != c {
                sums[r] += v[k].abs();
            }
        }
    }
    sums.into_iter().fold(0.0, f64::max)
}

/// 1-norm condition estimate `|A|_1 est(|A^-1|_1)` of an `n x n` matrix
/// from its norm and solves with `A` and `A^T` (the same for symmetric
/// matrices): Hager's method as refined by Higham (1988), at most 5 pairs
/// of solves, plus Higham's alternating test vector as a lower bound. Lower
/// bound on the true value, usually within a factor of 3.
pub fn one_norm_estimate(
    norm_a: f64,
    n: usize,
    mut solve: impl FnMut(&[f64]) -> Vec<f64>,
    mut solve_t: impl FnMut(&[f64]) -> Vec<f64>,
) -> Condition {
    if n == 0 {
        return Condition {
            value: 1.0,
            lambda_min: 1.0,
            lambda_max: 1.0,
            method: ConditionMethod::OneNormEstimate,
        };
    }
    let mut x = vec![1.0 / n as f64; n];
    let mut est = 0.0f64;
    let mut last_j = usize::MAX;
    for k in 0..5 {
        let y = solve(&x);
        let y1: f64 = y.iter().map(|v| v.abs()).sum();
        if !y1.is_finite() {
            est = f64::INFINITY;
            break;
        }
        if k > 0 && y1 <= est {
            break;
        }
        est = y1;
        let xi: Vec<f64> = y.iter().map(|v| if *v >= 0.0 { 1.0 } else { -1.0 }).collect();
        let z = solve_t(&xi);
        let (j, zmax) = z.iter().enumerate().fold(
            (0, 0.0f64),
            |(bj, bm), (i, v)| if v.abs() > bm { (i, v.abs()) } else { (bj, bm) },
        );
        let zx: f64 = z.iter().zip(&x).map(|(a, b)| a * b).sum();
        if k > 0 && (zmax <= zx || j == last_j) {
            break;
        }
        last_j = j;
        x = vec![0.0; n];
        x[j] = 1.0;
    }
    // Higham's extra vector guards against the few matrices that fool Hager.
    let alt: Vec<f64> = (0..n)
        .map(|i| {
            let s = if i % 2 == 0 { 1.0 } else { -1.0 };
            s * (1.0 + i as f64 / (n.max(2) - 1) as f64)
        })
        .collect();
    let y = solve(&alt);
    let alt_est = 2.0 * y.iter().map(|v| v.abs()).sum::<f64>() / (3.0 * n as f64);
    let inv = est.max(alt_est);
    Condition {
        value: norm_a * inv,
        lambda_min: 1.0 / inv,
        lambda_max: norm_a,
        method: ConditionMethod::OneNormEstimate,
    }
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
    /// The plain three-term Lanczos recurrence for `lambda_max` (checked
    /// every 5 products) and Lanczos on the inverse for `lambda_min` (at
    /// most [`ESTIMATE_ITERATIONS`] solves), each stopped when the Ritz
    /// value settles to [`ESTIMATE_TOLERANCE`]: the default above
    /// `dense_limit` (a fifth or less of a step's time). The extreme Ritz values are lower
    /// bounds of `lambda_max` and `1/lambda_min`, so the estimate is a lower
    /// bound of the condition number, usually within a few percent.
    Estimate,
    /// 1-norm estimate for Newton tangents, through their factor (`lambda_min` and
    /// `lambda_max` then hold `1/|A^-1|_1` and `|A|_1`).
    OneNormEstimate,
    /// The Cholesky factorisation broke down: the matrix is singular to
    /// working precision (condition number infinite); `lambda_min` and
    /// `lambda_max` hold dense eigenvalues when the matrix is small enough
    /// (`lambda_min` then sits at round-off of `lambda_max`, either sign),
    /// else 0 and NaN.
    NotPositiveDefinite,
}

impl ConditionMethod {
    pub fn label(self) -> &'static str {
        match self {
            ConditionMethod::Dense => "dense",
            ConditionMethod::DenseLanczosInverse => "dense+lanczos-inv",
            ConditionMethod::Lanczos => "lanczos",
            ConditionMethod::Estimate => "estimate",
            ConditionMethod::OneNormEstimate => "1-norm est",
            ConditionMethod::NotPositiveDefinite => "singular",
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

/// Run one small dense product on this thread, so that the matrix-product
/// kernels allocate their per-thread packing buffer (a few MB, which they
/// cannot reserve fallibly) now, while memory is plentiful, rather than in
/// the middle of a step's factorisation or eigenvalues, where failing to
/// get it would abort the process.
/// Skipped when 16 MB cannot be reserved: the warm-up would itself abort,
/// and a run that needs no large dense product can still finish.
pub fn warm_dense_kernels() {
    if Vec::<u8>::new().try_reserve_exact(16 << 20).is_err() {
        return;
    }
    let a = Mat::<f64>::from_fn(96, 96, |i, j| if i == j { 1.0 } else { 0.0 });
    let mut c = Mat::<f64>::zeros(96, 96);
    faer::linalg::matmul::matmul(c.as_mut(), faer::Accum::Replace, a.as_ref(), a.as_ref(), 1.0, Par::Seq);
    crate::vector_state::after_wide_kernels();
    std::hint::black_box(&c);
}

/// Eigenvalues (ascending) of a symmetric matrix given by its lower triangle,
/// densely; `None` when they fail to converge or their memory (the dense
/// matrix and faer's workspace, reserved fallibly) cannot be had: the
/// callers then use Lanczos, which needs no dense matrix.
pub fn dense_eigenvalues(a: SparseRef<'_>) -> Option<Vec<f64>> {
    use faer::linalg::evd;
    let n = a.nrows();
    let mut data: Vec<f64> = Vec::new();
    data.try_reserve_exact(n.checked_mul(n)?).ok()?;
    data.resize(n * n, 0.0);
    let (ri, v) = (a.row_idx(), a.val());
    for c in 0..n {
        for k in a.symbolic().col_range(c) {
            let r = ri[k] as usize;
            data[c * n + r] += v[k];
            if r != c {
                data[r * n + c] += v[k];
            }
        }
    }
    let m = faer::MatRef::from_column_major_slice(&data, n, n);
    let req = evd::self_adjoint_evd_scratch::<f64>(n, evd::ComputeEigenvectors::No, par(), Default::default());
    let mut mem = MemBuffer::try_new(req).ok()?;
    let mut s = faer::diag::Diag::<f64>::zeros(n);
    let done = evd::self_adjoint_evd(m, s.as_mut(), None, par(), MemStack::new(&mut mem), Default::default());
    crate::vector_state::after_wide_kernels();
    done.ok()?;
    Some(s.column_vector().iter().copied().collect())
}

/// Iterations of each Lanczos run of [`ConditionMethod::Estimate`] at most.
pub const ESTIMATE_ITERATIONS: usize = 25;

/// Relative change of the Ritz value that ends an estimate's Lanczos run
/// (after at least 3 iterations). Lanczos converges geometrically at the
/// ends of the spectrum, so the value is then within about this of its
/// limit; the tests check the estimate against dense eigenvalues.
pub const ESTIMATE_TOLERANCE: f64 = 1e-2;

/// How to compute a condition number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Eigen {
    /// Dense eigenvalues (Lanczos on the inverse at the round-off floor).
    Dense,
    /// Lanczos to 1e-10 (at most 120 iterations) at both ends.
    Lanczos,
    /// Lanczos to [`ESTIMATE_TOLERANCE`] (at most [`ESTIMATE_ITERATIONS`])
    /// at both ends.
    Estimate,
}

/// Condition number of the SPD matrix `a` (lower triangle) with Cholesky
/// factor `factor`: dense when `a` has at most `dense_limit` rows, Lanczos
/// above.
pub fn condition(a: SparseRef<'_>, factor: &Factor, dense_limit: usize) -> Condition {
    let how = if a.nrows() <= dense_limit {
        Eigen::Dense
    } else {
        Eigen::Lanczos
    };
    condition_by(a, factor, how, &|| true).expect("never cancelled")
}

/// Condition number of the SPD matrix `a` (lower triangle) with Cholesky
/// factor `factor`, computed as `how` says; `None` when `keep_going`
/// (asked between iterations) returns `false`.
pub fn condition_by(a: SparseRef<'_>, factor: &Factor, how: Eigen, keep_going: &dyn Fn() -> bool) -> Option<Condition> {
    let n = a.nrows();
    if n == 0 {
        return Some(Condition {
            value: 1.0,
            lambda_min: 1.0,
            lambda_max: 1.0,
            method: ConditionMethod::Dense,
        });
    }
    let (iterations, tolerance, method) = match how {
        Eigen::Estimate => (ESTIMATE_ITERATIONS, ESTIMATE_TOLERANCE, ConditionMethod::Estimate),
        _ => (120, 1e-10, ConditionMethod::Lanczos),
    };
    let inverse_min = || lanczos_max_with(n, |x| solve(factor, x), iterations, tolerance, keep_going).map(|m| 1.0 / m);
    if how == Eigen::Dense {
        if let Some(ev) = dense_eigenvalues(a) {
            let (lo, hi) = (ev[0], ev[n - 1]);
            // Dense eigenvalues are accurate to about n eps lambda_max.
            if lo > 1e-10 * hi {
                return Some(Condition {
                    value: hi / lo,
                    lambda_min: lo,
                    lambda_max: hi,
                    method: ConditionMethod::Dense,
                });
            }
            let lo = inverse_min()?;
            return Some(Condition {
                value: hi / lo,
                lambda_min: lo,
                lambda_max: hi,
                method: ConditionMethod::DenseLanczosInverse,
            });
        }
    }
    let hi = match how {
        // Products with `A` are cheap, its top spectrum is clustered: many
        // iterations of the three-term recurrence, no basis kept.
        Eigen::Estimate => lanczos_max_short(n, |x| sym_lower_mul(a, x), 200, ESTIMATE_TOLERANCE, keep_going)?,
        _ => lanczos_max_with(n, |x| sym_lower_mul(a, x), iterations, tolerance, keep_going)?,
    };
    let lo = inverse_min()?;
    Some(Condition {
        value: hi / lo,
        lambda_min: lo,
        lambda_max: hi,
        method,
    })
}

/// A reproducible pseudo-random sequence (xorshift64) for start vectors and
/// test directions: the same seed gives the same numbers on every machine.
pub struct XorShift(u64);

impl XorShift {
    pub fn new(seed: u64) -> XorShift {
        XorShift(seed)
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[-1/2, 1/2)`.
    pub fn centred(&mut self) -> f64 {
        self.unit() - 0.5
    }
}

/// Largest eigenvalue of a symmetric operator of size `n` by Lanczos with
/// full reorthogonalisation, from a fixed pseudo-random start (so results
/// are reproducible), stopped after `max_iter` iterations or when the
/// largest Ritz value settles to `tolerance` relative (full runs: 120 and
/// 1e-10); `None` when `keep_going`, asked before each iteration, returns
/// `false`.
pub fn lanczos_max_with(
    n: usize,
    op: impl Fn(&[f64]) -> Vec<f64>,
    max_iter: usize,
    tolerance: f64,
    keep_going: &dyn Fn() -> bool,
) -> Option<f64> {
    let q = start_vector(n);
    let mut basis: Vec<Vec<f64>> = vec![q];
    let dot = dot_product;
    let (mut alpha, mut beta) = (Vec::new(), Vec::<f64>::new());
    let mut last = f64::NAN;
    let max_iter = n.min(max_iter);
    for j in 0..max_iter {
        if !keep_going() {
            return None;
        }
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
            return Some(ritz);
        }
        // At least 5 iterations to the 1e-10 of full runs, 3 for estimates.
        let least = if tolerance < 1e-6 { 4 } else { 2 };
        if j >= least && (ritz - last).abs() <= tolerance * ritz.abs() {
            return Some(ritz);
        }
        last = ritz;
        beta.push(bnorm);
        basis.push(w.into_iter().map(|v| v / bnorm).collect());
    }
    Some(last)
}

/// Largest eigenvalue of a symmetric operator by the plain three-term
/// Lanczos recurrence (only the last two vectors kept, each new one
/// orthogonalised against them): memory `O(n)` and time `O(n)` per
/// iteration. Losing orthogonality only repeats converged Ritz values; the
/// largest stays a lower bound of `lambda_max` that converges to it. Stops
/// after `max_iter` iterations or when the Ritz value (checked every 5)
/// settles to `tolerance`; `None` when `keep_going` returns `false`.
pub fn lanczos_max_short(
    n: usize,
    op: impl Fn(&[f64]) -> Vec<f64>,
    max_iter: usize,
    tolerance: f64,
    keep_going: &dyn Fn() -> bool,
) -> Option<f64> {
    let mut q = start_vector(n);
    let dot = dot_product;
    let mut prev = vec![0.0; n];
    let (mut alpha, mut beta) = (Vec::new(), Vec::<f64>::new());
    let mut last = f64::NAN;
    let max_iter = n.min(max_iter);
    for j in 0..max_iter {
        if !keep_going() {
            return None;
        }
        let mut w = op(&q);
        let b_prev = beta.last().copied().unwrap_or(0.0);
        w.iter_mut().zip(&prev).for_each(|(wi, pi)| *wi -= b_prev * pi);
        let a = dot(&w, &q);
        alpha.push(a);
        w.iter_mut().zip(&q).for_each(|(wi, qi)| *wi -= a * qi);
        for v in [&q, &prev] {
            let c = dot(&w, v);
            w.iter_mut().zip(v.iter()).for_each(|(wi, vi)| *wi -= c * vi);
        }
        let bnorm = dot(&w, &w).sqrt();
        let scale = alpha.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        let done = bnorm <= 1e-14 * scale || j + 1 == max_iter;
        if done || (j >= 4 && j % 5 == 4) {
            let ritz = tridiagonal_max(&alpha, &beta);
            if done || (ritz - last).abs() <= tolerance * ritz.abs() {
                return Some(ritz);
            }
            last = ritz;
        }
        beta.push(bnorm);
        prev = std::mem::replace(&mut q, w.into_iter().map(|v| v / bnorm).collect());
    }
    Some(last)
}

/// `|v|_2`, summed in order.
pub fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

fn dot_product(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The Lanczos runs' fixed, reproducible start: pseudo-random positive
/// entries, unit length (the same on every machine).
fn start_vector(n: usize) -> Vec<f64> {
    let mut rand = XorShift::new(0x2545_f491_4f6c_dd1d);
    let mut q: Vec<f64> = (0..n).map(|_| rand.unit() + 0.5).collect();
    let nq = dot_product(&q, &q).sqrt();
    q.iter_mut().for_each(|v| *v /= nq);
    q
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
    let ev = t.self_adjoint_eigenvalues(Side::Lower);
    crate::vector_state::after_wide_kernels();
    ev.map_or(f64::NAN, |ev| ev[m - 1])
}
