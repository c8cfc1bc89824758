//! How the process's allocator hands memory back, for the commands that bake.

/// Makes every block over 128 KiB its own mapping, returned to the system when freed.
///
/// glibc starts there, but raises the threshold to the size of each mapped block freed
/// (up to 32 MiB), so after the bake's first large free its next vectors come from the
/// heap, where freed pages stay resident: a bake of the dragon peaked at 2.6 times its
/// output file, 1.9 times with the threshold held (BENCHMARKS.md, "Scale"), at no cost
/// in time measured. Without glibc this does nothing.
pub(crate) fn return_large_frees() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[allow(unsafe_code)]
    // SAFETY: mallopt only sets an allocator parameter; it is called before any thread
    // that allocates is started, and an unsupported value is refused (returns 0), not
    // undefined.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 128 * 1024);
    }
}
