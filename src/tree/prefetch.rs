//! Hints that ask the processor to start loading memory the program is
//! about to read: cache lines of an address range or of a value. None reads
//! memory the program can observe, and none faults, whatever the address.

/// The address range of a slice.
#[inline]
pub(super) fn as_bytes_range<T>(items: &[T]) -> core::ops::Range<usize> {
    let start = items.as_ptr() as usize;
    start..start + core::mem::size_of_val(items)
}

/// Cache lines prefetched at most per call.
const PREFETCH_LINES: usize = 16;

/// Prefetches the cache lines of an address range (at most
/// [`PREFETCH_LINES`] of them) into every cache level. A hint only: it
/// reads no memory the program can observe and never faults.
#[inline]
pub(super) fn prefetch(range: core::ops::Range<usize>) {
    prefetch_lines(range, PREFETCH_LINES);
}

/// Prefetches the cache lines of an address range, at most `most` of
/// them, into every cache level.
#[inline]
pub(super) fn prefetch_lines(range: core::ops::Range<usize>, most: usize) {
    let mut line = range.start & !63;
    let end = range.end.min(range.start + most * 64);
    while line < end {
        prefetch_line(line);
        line += 64;
    }
}

/// Prefetches the cache lines of `value`, as [`prefetch`] its range: as
/// many lines as a value of its size can touch wherever it starts (at most
/// [`PREFETCH_LINES`]), a number known when compiling, so that the loop
/// unrolls.
#[inline(always)]
pub(super) fn prefetch_value<T>(value: &T) {
    let start = core::ptr::from_ref(value) as usize & !63;
    let lines = (size_of::<T>() + 126) / 64;
    for k in 0..lines.min(PREFETCH_LINES) {
        prefetch_line(start + 64 * k);
    }
}

/// Prefetches the cache line holding `address` into every cache level.
#[inline(always)]
pub(super) fn prefetch_line(address: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // SAFETY: a prefetch is a hint that never dereferences the address
        // architecturally and cannot fault, whatever the address.
        #[allow(unsafe_code)]
        unsafe {
            _mm_prefetch::<_MM_HINT_T0>(address as *const i8);
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = address;
}
