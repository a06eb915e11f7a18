//! How large buffers are backed.

/// Asks the kernel to back the 2 MiB-aligned part of a buffer with huge pages, for buffers read
/// at scattered places (a frame's tiles, a ray caster's nodes and leaves), where the walks of
/// 4 KiB pages would otherwise add a miss to many reads. Call it before the buffer is first
/// written, so that its pages are faulted in huge. A hint: failure is harmless, and nothing
/// else changes.
pub fn advise_huge_pages(ptr: *mut u8, len: usize) {
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let start = (ptr as usize).div_ceil(HUGE) * HUGE;
        let end = (ptr as usize).saturating_add(len) / HUGE * HUGE;
        if end > start {
            // SAFETY: the range lies inside the caller's allocation; MADV_HUGEPAGE only changes
            // how the kernel backs it, never its contents, and failure is harmless.
            unsafe {
                libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (ptr, len);
}

/// An empty vector with room for `capacity` items whose memory was advised huge pages
/// ([`advise_huge_pages`]) before anything was written to it: fill it within that capacity.
pub fn huge_page_vec<T>(capacity: usize) -> Vec<T> {
    let mut v: Vec<T> = Vec::with_capacity(capacity);
    advise_huge_pages(
        v.as_mut_ptr().cast::<u8>(),
        capacity.saturating_mul(std::mem::size_of::<T>()),
    );
    v
}
