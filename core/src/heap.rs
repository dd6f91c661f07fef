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
/// (128 MiB per allocator arena: the freed buffers of one large frame's stages are reused by
/// the next stage instead of being returned and faulted in again). `tubeloc locate` on a
/// 5472 x 3648 frame (2 cores): 32 MiB gave 273,000 page faults, 0.7 s system time and
/// 1.3-1.6 s wall; 128 MiB 104,000, 0.3 s and 0.9-1.2 s, peak 293 -> 305 MiB; 256 MiB and
/// 1 GiB no faster, peak 351 MiB.
pub const HEAP_KEEP_FREE_BYTES: usize = 128 << 20;

/// Free memory that `malloc` keeps at a heap's top when it trims it (`M_TOP_PAD`; glibc's
/// default 128 KiB), and the extra it asks the kernel for each time the heap grows. Without it,
/// [`HEAP_KEEP_FREE_BYTES`] only delays the trim: once a freed top passes that size it is cut
/// back to 128 KiB, and the learned segmenter, whose layers on a 1024 x 1024 Navcam frame at
/// its working scale (about 2560 x 2560) each allocate and free tens of MiB, faulted its
/// activations in again at every layer. `tubeloc detect --method learned` on six such frames
/// (2 cores, medians of three interleaved runs): 5.0 s wall with 4.4 s system time at the
/// default, 1.9 s with 0.2 s at 256 MiB; 64 and 128 MiB were fast in some runs only; peak
/// memory 272 MiB in all.
pub const HEAP_TOP_PAD_BYTES: usize = 256 << 20;

/// Most allocator arenas (`M_ARENA_MAX`). glibc gives each thread that meets a locked arena
/// a new one, up to 8 per core, and each keeps its freed top ([`HEAP_KEEP_FREE_BYTES`]), so
/// peak memory grew with the core count: `locate` on a 5472 x 3648 frame with 16 threads
/// peaked at 533 MiB (664 MiB with the 128 MiB top kept); with 2 arenas 373 MiB, with 1
/// 306 MiB, as fast on 2 cores. The hot loops allocate per tube or per row, not per pixel,
/// so two arenas shared by the threads do not contend measurably.
pub const ALLOCATOR_ARENAS: usize = 2;

/// Asks the C allocator to keep freed memory for reuse: blocks up to
/// [`HEAP_BLOCK_MAX_BYTES`] come from the heap, freed heap tops of up to
/// [`HEAP_KEEP_FREE_BYTES`] are not returned to the kernel and a trim keeps
/// [`HEAP_TOP_PAD_BYTES`], at most [`ALLOCATOR_ARENAS`]
/// arenas keep them, and no block is served by its own
/// `mmap` (`M_MMAP_MAX` = 0): the segmenter's activations (tens to hundreds of MiB per layer
/// on a large frame, above glibc's 32 MiB ceiling for `M_MMAP_THRESHOLD`) then reuse freed
/// heap instead of faulting in fresh zeroed pages each layer. Call it once at program start (the `tubeloc` binary and the
/// refinement benchmark do). Returns false where it does not apply (not glibc) or `mallopt`
/// refused.
pub fn keep_freed_memory() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt only sets allocator parameters; all values are in range.
        unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, HEAP_BLOCK_MAX_BYTES as libc::c_int) == 1
                && libc::mallopt(libc::M_TRIM_THRESHOLD, HEAP_KEEP_FREE_BYTES as libc::c_int) == 1
                && libc::mallopt(libc::M_TOP_PAD, HEAP_TOP_PAD_BYTES as libc::c_int) == 1
                && libc::mallopt(libc::M_MMAP_MAX, 0) == 1
                && libc::mallopt(libc::M_ARENA_MAX, ALLOCATOR_ARENAS as libc::c_int) == 1
        }
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
