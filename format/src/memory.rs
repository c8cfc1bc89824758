//! How much memory this process may use, for budgets that follow the machine, and
//! allocations that fail as errors rather than aborting the process.
//!
//! Every allocation an input sizes (a ray count, a crossing list, a mesh's triangles)
//! either has a budget, decided before the work, or is made with [`try_vec`], whose
//! failure is an [`AllocError`] naming what and how much, never the allocator's abort.
//!
//! # Example
//! ```
//! use octrace_format::memory;
//! let usable = memory::usable_bytes();
//! assert!(usable >= 1 << 20);
//! assert!(memory::share(4) <= usable / 4 + 1);
//! let small: Vec<u32> = memory::try_vec(1000, "test rays").unwrap();
//! assert_eq!(small.len(), 1000);
//! let error = memory::try_vec::<u64>(usize::MAX / 8, "test rays").unwrap_err();
//! assert!(error.to_string().contains("test rays"));
//! ```

/// The fallback where the system does not say how much memory it has: 8 GiB.
const UNKNOWN_MEMORY: u64 = 8 << 30;

/// Bytes of physical memory, where the system says.
pub fn physical_bytes() -> Option<u64> {
    #[cfg(unix)]
    {
        // SAFETY: sysconf reads a system value; it takes no pointer and has no
        // precondition (an unknown name returns -1).
        let (pages, size) = unsafe { (libc::sysconf(libc::_SC_PHYS_PAGES), libc::sysconf(libc::_SC_PAGESIZE)) };
        if pages > 0 && size > 0 {
            return Some((pages as u64).saturating_mul(size as u64));
        }
    }
    None
}

/// The process's address-space limit (`ulimit -v`, `prlimit --as`), where one is set.
pub fn address_space_limit() -> Option<u64> {
    #[cfg(unix)]
    {
        let mut limit = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
        // SAFETY: getrlimit writes one rlimit through a pointer to a live local.
        let got = unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut limit) };
        if got == 0 && limit.rlim_cur != libc::RLIM_INFINITY {
            #[allow(clippy::unnecessary_cast)] // rlim_t is not u64 on every Unix
            return Some(limit.rlim_cur as u64);
        }
    }
    None
}

/// The memory this process may use: the smaller of the machine's physical memory and
/// the process's address-space limit (8 GiB where neither is known).
pub fn usable_bytes() -> u64 {
    match (physical_bytes(), address_space_limit()) {
        (Some(p), Some(a)) => p.min(a),
        (Some(m), None) | (None, Some(m)) => m,
        (None, None) => UNKNOWN_MEMORY,
    }
}

/// `1 / parts` of [`usable_bytes`]: the default of a budget that may take that share.
pub fn share(parts: u64) -> u64 {
    usable_bytes() / parts.max(1)
}

/// An allocation that could not be made: what it was for and its size.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{what} need {bytes} bytes, more than this process could allocate")]
pub struct AllocError {
    /// What the memory was for (a plural: "rays", "crossings").
    pub what: &'static str,
    /// The bytes asked for.
    pub bytes: u64,
}

/// A vector of `n` default values, or an [`AllocError`] where the memory cannot be had
/// (the allocator refused, or `n` values do not fit the address space), never an abort.
pub fn try_vec<T: Clone + Default>(n: usize, what: &'static str) -> Result<Vec<T>, AllocError> {
    let mut v = try_with_capacity(n, what)?;
    v.resize(n, T::default());
    Ok(v)
}

/// An empty vector with room for `n` values, or an [`AllocError`] ([`try_vec`]).
pub fn try_with_capacity<T>(n: usize, what: &'static str) -> Result<Vec<T>, AllocError> {
    let mut v = Vec::new();
    v.try_reserve_exact(n)
        .map_err(|_| AllocError { what, bytes: (n as u64).saturating_mul(std::mem::size_of::<T>() as u64) })?;
    Ok(v)
}

/// A vector of `n` zeroed plain values ([`try_vec`] for `bytemuck` types).
pub fn try_vec_zeroed<T: bytemuck::Zeroable + Copy>(n: usize) -> Result<Vec<T>, AllocError> {
    let mut v = try_with_capacity(n, "values")?;
    v.resize(n, T::zeroed());
    Ok(v)
}
