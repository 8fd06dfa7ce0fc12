//! The vector registers' state between faer's kernels and this crate's
//! own arithmetic (one function, imported by the linear algebra and the
//! drivers, importing nothing).

/// Leave the upper halves of the vector registers clean (`vzeroupper`)
/// after faer's dense kernels, which are hand-written 512-bit assembly on
/// CPUs that have it and return with those halves in use. Until something
/// clears them, every instruction of this crate's scalar (SSE) code pays
/// for them: measured on the points' material response (Hencky's log,
/// exp and their tangent), 79 ms per Newton residual against 17 ms clean,
/// and threads started meanwhile inherit the state. Call after a faer
/// numeric routine and before a long loop of the crate's own arithmetic;
/// it changes no value.
#[inline]
pub(crate) fn after_wide_kernels() {
    #[cfg(all(target_arch = "x86_64", not(target_feature = "avx")))]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX (checked above), and code built without
        // it keeps nothing in the registers' upper halves, which alone
        // `vzeroupper` clears.
        unsafe { std::arch::asm!("vzeroupper", options(nomem, nostack, preserves_flags)) }
    }
}
