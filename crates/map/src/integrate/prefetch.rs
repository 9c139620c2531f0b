//! Cache hints for the images a block reads. A block's voxels project to a small rectangle
//! of pixels, row after image row; read one voxel at a time, each new cache line of that
//! rectangle is a miss the voxel waits for. Asked for all at once when the block starts, the
//! lines arrive together. Hints change no result.

use std::ops::RangeInclusive;

use voxpan_core::Image;

/// Asks the CPU to bring the cache line holding `value` into its nearest cache: a hint that
/// reads nothing and cannot fault.
#[inline(always)]
fn prefetch<T>(value: &T) {
    let address = (value as *const T).cast::<i8>();
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch only hints at a valid address; SSE is part of every x86-64 CPU.
    unsafe {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        _mm_prefetch::<_MM_HINT_T0>(address)
    };
    #[cfg(target_arch = "aarch64")]
    // SAFETY: PRFM only hints at a valid address: it neither reads into a register nor faults.
    unsafe {
        std::arch::asm!("prfm pldl1keep, [{0}]", in(reg) address, options(nostack, readonly, preserves_flags))
    };
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    let _ = address;
}

/// Hints every cache line of `image` within `columns` × `rows` (inclusive, inside the image).
pub(crate) fn prefetch_rect<T>(
    image: &Image<T>,
    columns: RangeInclusive<usize>,
    rows: RangeInclusive<usize>,
) {
    let (width, pixels) = (image.width(), image.pixels());
    let per_line = (64 / size_of::<T>()).max(1);
    for v in rows {
        let row = &pixels[v * width..(v + 1) * width];
        for u in columns.clone().step_by(per_line) {
            prefetch(&row[u]);
        }
        // The rectangle's last pixel may start a line the steps skipped.
        prefetch(&row[*columns.end()]);
    }
}
