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

/// Defines `$vis fn $name(avx2: bool, args...) -> ret` that calls the `#[inline(always)]`
/// function `$body(args...)` either in an AVX2-enabled copy (`$avx`, where `avx2` is true) or in
/// the baseline one. Callers pass `avx2` true only where [`have_avx2`] said so.
///
/// ```
/// #[inline(always)]
/// fn sum_body(x: &[f64]) -> f64 {
///     x.iter().sum()
/// }
/// modesuite_engine::avx2_dispatch! {
///     /// The sum of `x`.
///     fn sum / sum_avx2 => sum_body(x: &[f64]) -> f64
/// }
/// let x = [0.1, 0.2, 0.3];
/// let avx2 = modesuite_engine::simd::have_avx2();
/// assert_eq!(sum(avx2, &x).to_bits(), sum(false, &x).to_bits());
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
        $vis fn $name(avx2: bool, $($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                // SAFETY: callers pass `avx2` true only where `have_avx2()` found the feature.
                return unsafe { $avx($($arg),*) };
            }
            let _ = avx2;
            $body($($arg),*)
        }
    };
}
