//! Room for the traversal's nodes and triangles in memory the kernel may back with 2 MiB
//! pages (Linux's transparent huge pages, `madvise(MADV_HUGEPAGE)`): a ray reads a few cache
//! lines in each of many 4 KiB pages, so on large scenes larger pages save TLB misses. Only a
//! hint: where the kernel declines it, or the allocator hands back memory already in use, or
//! elsewhere than Linux, the pages stay ordinary and nothing else changes.

/// Size of a huge page.
const HUGE: usize = 2 << 20;

/// An empty vector with room for `n` elements whose whole 2 MiB pages are advised for huge
/// pages before anything is written to them (a vector of less than two such pages is left
/// alone).
pub(in crate::ray) fn with_capacity<T>(n: usize) -> Vec<T> {
    let mut v = Vec::with_capacity(n);
    let bytes = n.saturating_mul(std::mem::size_of::<T>());
    #[cfg(target_os = "linux")]
    if bytes >= 2 * HUGE {
        let at = v.as_mut_ptr() as usize;
        let (start, end) = (at.next_multiple_of(HUGE), (at + bytes) / HUGE * HUGE);
        if start < end {
            // SAFETY: `[start, end)` lies inside `v`'s allocation, which holds no values yet;
            // the advice changes how the kernel backs those pages, not what they hold.
            unsafe {
                libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = bytes;
    v
}

/// `n` copies of `x` in a vector from [`with_capacity`].
pub(in crate::ray) fn filled<T: Clone>(n: usize, x: T) -> Vec<T> {
    let mut v = with_capacity(n);
    v.resize(n, x);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vectors_get_their_room_and_values() {
        for n in [0, 1, 1000, 5 * HUGE / 8 + 5] {
            let v: Vec<u64> = filled(n, 7);
            assert!(v.len() == n && v.iter().all(|&x| x == 7));
            assert!(with_capacity::<u64>(n).capacity() >= n);
        }
    }
}
