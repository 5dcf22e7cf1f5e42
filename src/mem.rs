//! Giving freed heap memory back to the system.
//!
//! glibc's malloc keeps memory a program frees for its next allocations, in
//! one arena per thread that allocated concurrently (tokio's workers get
//! several). After a crowd of WebSocket clients has come and gone, almost all
//! of their buffers are free again, yet the process stays as large as at the
//! peak (measured: 10 MiB idle, 90 MiB after 500 clients left, for good).
//! `malloc_trim(0)` returns the free pages of every arena; the daemon calls
//! it when the last WebSocket client leaves, a moment when nothing is
//! streaming. Elsewhere (musl, other systems) this does nothing.

/// Returns the heap's free pages to the system; `true` if any were released.
pub fn release_free_memory() -> bool {
    trim()
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn trim() -> bool {
    // SAFETY: malloc_trim only walks glibc's own arenas under their locks;
    // it takes no pointer from us and is safe to call from any thread.
    unsafe { libc::malloc_trim(0) == 1 }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn trim() -> bool {
    false
}

#[cfg(test)]
mod tests {
    #[test]
    fn trims_after_a_large_free() {
        let big: Vec<Vec<u8>> = (0..64).map(|_| vec![1u8; 64 * 1024]).collect();
        drop(big);
        // Whether pages come back depends on the heap's layout; the call
        // itself must be harmless at any time.
        let _ = super::release_free_memory();
    }
}
