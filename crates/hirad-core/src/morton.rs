//! Morton (Z-order) codes of 3-D grid coordinates of 21 bits each: sorting by code keeps
//! nearby cells together, and a cell of `2^m` grid units per axis is a run of codes sharing
//! the bits above `3m` (`code >> 3m`).

/// Spread the low 21 bits of `v` to every third bit.
#[inline]
pub fn part1by2(v: u32) -> u64 {
    let mut x = (v as u64) & 0x1f_ffff;
    x = (x | x << 32) & 0x001f_0000_0000_ffff;
    x = (x | x << 16) & 0x001f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// Morton code of grid coordinates (21 bits each; x in the lowest bit).
#[inline]
pub fn morton(q: [u32; 3]) -> u64 {
    part1by2(q[0]) | part1by2(q[1]) << 1 | part1by2(q[2]) << 2
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_interleaves_bits() {
        assert_eq!(morton([1, 0, 0]), 1);
        assert_eq!(morton([0, 1, 0]), 2);
        assert_eq!(morton([0, 0, 1]), 4);
        assert_eq!(morton([3, 0, 0]), 0b1001);
        let m = (1u32 << 21) - 1;
        assert_eq!(morton([m, m, m]), (1u64 << 63) - 1);
    }
}
