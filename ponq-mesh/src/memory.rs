//! Process-wide allocator settings for the command-line programs.
//!
//! The mesher allocates and frees arrays of tens of megabytes stage after stage (the
//! Delaunay's tet arena, the output tets, the half-edges). glibc's allocator hands blocks that
//! large to the kernel on `free` and asks for fresh ones on the next `malloc`, and every page
//! of a fresh block costs a page fault and zeroing on first touch. [`keep_freed_memory`] makes
//! it keep freed memory for the next stage instead. A one-shot program loses nothing by it
//! (the memory goes back at exit); a library does not call it on its user's behalf.

/// Asks glibc's `malloc` to serve blocks up to 32 MiB from its heap and not to return freed
/// heap memory to the kernel, so that each meshing stage reuses the pages the previous one
/// freed. Measured (`ponq-mesh` on `mesh_bench`'s 109k-point PoNQ, fresh processes,
/// `perf stat`): 26k page faults instead of 35k. Does nothing on other platforms. Call it once,
/// at the start of `main`, before any other thread allocates.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `mallopt` only changes the allocator's tuning parameters; glibc serialises it
    // with allocations, and both values are in the ranges its manual documents (the mmap
    // threshold at most 32 MiB on 64-bit systems).
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
    }
}
