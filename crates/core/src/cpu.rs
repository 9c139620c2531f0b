//! Runtime choice of the vector unit for loops the compiler vectorises on its own.
//!
//! voxpan is built for baseline x86-64 (SSE2), so that one binary runs on every robot's CPU.
//! Most x86-64 CPUs of the last decade also have AVX2, where the same loops vectorise twice as
//! wide: [`widest!`](crate::widest) compiles an expression a second time for AVX2 and runs that
//! copy where the CPU has it. Only what is inlined into the expression is compiled that way,
//! so the functions a hot path calls are marked `#[inline(always)]`. Results are bit for bit
//! the baseline's: the features enabled add no fused multiply-adds (Rust never contracts
//! `a * b + c`), and tests compare both paths.

use std::cell::Cell;

thread_local! {
    /// Set while [`as_built`] runs on this thread.
    static AS_BUILT: Cell<bool> = const { Cell::new(false) };
}

/// Evaluates an expression compiled for AVX2 (with BMI1/2, LZCNT and POPCNT, x86-64-v3's
/// integer extensions) where this CPU has them, else as built. The expression is compiled
/// twice, once inside a closure each path calls once, so that each copy is inlined where it
/// is called (a closure shared by both paths is not, and stays baseline code).
///
/// ```
/// let data = vec![1.5f32; 1000];
/// let sum: f32 = voxpan_core::widest!(data.iter().sum());
/// assert_eq!(sum, 1500.0);
/// ```
#[macro_export]
macro_rules! widest {
    ($work:expr) => {{
        #[cfg(target_arch = "x86_64")]
        let result = if $crate::cpu::use_avx2() {
            // SAFETY: the CPU has the features `on_avx2` is compiled for (`use_avx2`).
            unsafe { $crate::cpu::on_avx2(|| $work) }
        } else {
            $work
        };
        #[cfg(not(target_arch = "x86_64"))]
        let result = $work;
        result
    }};
}

/// Whether [`widest!`](crate::widest) takes its AVX2 path on this thread now.
#[inline]
pub fn use_avx2() -> bool {
    has_avx2() && !AS_BUILT.get()
}

/// Runs `work` with every [`widest!`](crate::widest) it reaches on this thread taking the
/// as-built path: the reference the wider path is tested against.
pub fn as_built<R>(work: impl FnOnce() -> R) -> R {
    let before = AS_BUILT.replace(true);
    let result = work();
    AS_BUILT.set(before);
    result
}

/// Whether this CPU has AVX2 and the integer extensions [`widest!`](crate::widest) compiles
/// for (the standard library caches the detection).
pub fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2")
            && std::is_x86_feature_detected!("bmi1")
            && std::is_x86_feature_detected!("bmi2")
            && std::is_x86_feature_detected!("lzcnt")
            && std::is_x86_feature_detected!("popcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Calls `work` from code compiled for AVX2; [`widest!`](crate::widest)'s path there.
///
/// # Safety
/// The CPU must have the features enabled here ([`has_avx2`]).
#[doc(hidden)]
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,bmi1,bmi2,lzcnt,popcnt")]
#[inline]
pub unsafe fn on_avx2<R>(work: impl FnOnce() -> R) -> R {
    work()
}
