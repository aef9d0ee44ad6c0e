//! Run-time choice between a kernel's baseline build and an AVX2 build of the same code.
//!
//! A kernel written as plain lane arithmetic (`[f64; 4]` or `[f64; 8]` accumulators in a fixed
//! order) is compiled twice by [`avx2_dispatch!`](crate::avx2_dispatch): once for the build's
//! baseline target and once with `#[target_feature(enable = "avx2")]`, where LLVM turns the lanes
//! into 256-bit instructions. Rust never contracts a multiplication and an addition into a fused
//! multiply-add, and square roots and divisions are correctly rounded, so both copies give the
//! same bits: results do not depend on the CPU. Used by the cloth kernels
//! (`modesuite_pbd::lanes`) and the FEM factorisation (`modesuite_fem::sparse`).

/// Whether the AVX2 copies made by [`avx2_dispatch!`](crate::avx2_dispatch) can run on this
/// machine (detected once by the standard library, then a cached load).
#[inline]
pub fn have_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Which copy of an [`avx2_dispatch!`](crate::avx2_dispatch) kernel runs: the baseline one, or
/// the AVX2 one. A value asking for AVX2 can only be made by [`Simd::detect`], which checks the
/// CPU, so safe code cannot run AVX2 instructions on a machine without them; [`Simd::baseline`]
/// is always available (tests compare the two copies). Copied like a `bool`, and as cheap.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Simd {
    /// True only where [`have_avx2`] found the feature (the field is private: see [`Simd::detect`]).
    avx2: bool,
}

impl Simd {
    /// The baseline copies, on any machine.
    #[inline]
    pub const fn baseline() -> Self {
        Simd { avx2: false }
    }

    /// The AVX2 copies where this machine has AVX2 ([`have_avx2`]), the baseline ones elsewhere.
    #[inline]
    pub fn detect() -> Self {
        Simd { avx2: have_avx2() }
    }

    /// Whether the AVX2 copies run.
    #[inline]
    pub const fn avx2(self) -> bool {
        self.avx2
    }
}

/// Defines `$vis fn $name(simd: Simd, args...) -> ret` that calls the `#[inline(always)]`
/// function `$body(args...)` either in an AVX2-enabled copy (`$avx`, where [`Simd::avx2`] is
/// true, which [`Simd::detect`] allows only where the CPU has AVX2) or in the baseline one.
///
/// ```
/// use modesuite_engine::simd::Simd;
///
/// #[inline(always)]
/// fn sum_body(x: &[f64]) -> f64 {
///     x.iter().sum()
/// }
/// modesuite_engine::avx2_dispatch! {
///     /// The sum of `x`.
///     fn sum / sum_avx2 => sum_body(x: &[f64]) -> f64
/// }
/// let x = [0.1, 0.2, 0.3];
/// assert_eq!(
///     sum(Simd::detect(), &x).to_bits(),
///     sum(Simd::baseline(), &x).to_bits()
/// );
/// ```
#[macro_export]
macro_rules! avx2_dispatch {
    ($(#[$m:meta])* $vis:vis fn $name:ident / $avx:ident
        => $body:ident($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)?) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        #[allow(clippy::too_many_arguments)]
        fn $avx($($arg: $ty),*) $(-> $ret)? {
            $body($($arg),*)
        }
        $(#[$m])*
        #[inline(never)]
        #[allow(clippy::too_many_arguments)]
        $vis fn $name(simd: $crate::simd::Simd, $($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            if simd.avx2() {
                // SAFETY: a `Simd` with `avx2()` true is made only by `Simd::detect`, where
                // `have_avx2()` found the feature.
                return unsafe { $avx($($arg),*) };
            }
            let _ = simd;
            $body($($arg),*)
        }
    };
}

/// Runs `f` with subnormal floats flushed to zero (x86-64 SSE: MXCSR's flush-to-zero and
/// denormals-are-zero bits), restoring the caller's setting afterwards.
///
/// Why: rapier and parry (`f32`) load three-component vectors into four-lane registers whose
/// unused lane holds whatever lies next in memory; where that is a small integer (an index, a
/// handle) its bits are a subnormal `f32`, and every packed multiply on it takes a microcode
/// assist of about a hundred cycles. The lane's result is discarded, so results do not change,
/// but the speed then depends on where data happen to land: one build of Franka Uncover spent
/// 5x the time in parry's point projection (18 % of the step) for that alone. Real values that
/// small (below 1.2e-38 in `f32`, 2.2e-308 in `f64`) would become zero; none decided anything in
/// the 16 tasks' expert episodes, whose final states are byte-identical with and without the
/// flush. The setting is the same on every run and thread, so results stay deterministic.
#[inline]
pub fn flush_denormals<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    #[allow(deprecated)] // the MXCSR intrinsics have no replacement outside inline assembly
    {
        use std::arch::x86_64::{_mm_getcsr, _mm_setcsr};
        // flush-to-zero (bit 15) and denormals-are-zero (bit 6)
        const FTZ_DAZ: u32 = (1 << 15) | (1 << 6);
        // SAFETY: SSE is part of the x86-64 baseline; only the two flush bits change, and the
        // caller's value is put back.
        let old = unsafe { _mm_getcsr() };
        unsafe { _mm_setcsr(old | FTZ_DAZ) };
        let out = f();
        unsafe { _mm_setcsr(old) };
        out
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        f()
    }
}

#[cfg(test)]
mod tests {
    use std::hint::black_box;

    #[test]
    fn flush_denormals_flushes_inside_and_restores_after() {
        let half_min = || black_box(f32::MIN_POSITIVE) * black_box(0.5f32);
        assert!(half_min().is_subnormal());
        let inside = super::flush_denormals(half_min);
        #[cfg(target_arch = "x86_64")]
        assert_eq!(inside.to_bits(), 0, "a subnormal result inside: {inside:e}");
        #[cfg(not(target_arch = "x86_64"))]
        assert!(inside.is_subnormal());
        assert!(
            half_min().is_subnormal(),
            "the caller's setting was not restored"
        );
    }
}
