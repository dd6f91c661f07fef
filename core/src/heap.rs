//! The process heap's policy for large buffers.
//!
//! Refining one tube builds a gradient pyramid and silhouette masks of a few MiB and drops
//! them again. glibc's `malloc` serves blocks above `M_MMAP_THRESHOLD` (128 KiB, raised
//! dynamically) with fresh `mmap`s and gives heap tops above `M_TRIM_THRESHOLD` back to the
//! kernel on `free`, so every tube paid for zeroed pages and page faults on the same buffers:
//! a quarter of the time for a 400 px tube (`cargo bench -p tubeloc-refine --bench refine`).

/// Most bytes that [`keep_freed_memory`] lets `malloc` serve from the heap rather than by
/// `mmap` (8 MiB: a 1024 x 1024 image's per-tube buffers fit; full-resolution images and masks
/// are still mapped and returned when dropped).
pub const HEAP_BLOCK_MAX_BYTES: usize = 8 << 20;

/// Free memory at the top of a heap that `malloc` keeps rather than returning it to the kernel
/// (32 MiB: several tubes' buffers, per allocator arena).
pub const HEAP_KEEP_FREE_BYTES: usize = 32 << 20;

/// Asks the C allocator to keep freed memory for reuse: blocks up to
/// [`HEAP_BLOCK_MAX_BYTES`] come from the heap, freed heap tops of up to
/// [`HEAP_KEEP_FREE_BYTES`] are not returned to the kernel, and no block is served by its own
/// `mmap` (`M_MMAP_MAX` = 0): the segmenter's activations (tens to hundreds of MiB per layer
/// on a large frame, above glibc's 32 MiB ceiling for `M_MMAP_THRESHOLD`) then reuse freed
/// heap instead of faulting in fresh zeroed pages each layer. `tubeloc locate` on a
/// 5472 x 3648 frame (2 cores): 1.6-1.8 s -> 1.26-1.43 s wall, system time 1.0 -> 0.6 s, peak
/// memory 282 -> 284 MiB. Call it once at program start (the `tubeloc` binary and the
/// refinement benchmark do). Returns false where it does not apply (not glibc) or `mallopt`
/// refused.
pub fn keep_freed_memory() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt only sets allocator parameters; all values are in range.
        unsafe { libc::mallopt(libc::M_MMAP_THRESHOLD, HEAP_BLOCK_MAX_BYTES as libc::c_int) == 1 && libc::mallopt(libc::M_TRIM_THRESHOLD, HEAP_KEEP_FREE_BYTES as libc::c_int) == 1 && libc::mallopt(libc::M_MMAP_MAX, 0) == 1 }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn glibc_accepts_the_thresholds() {
        assert!(super::keep_freed_memory());
    }
}
