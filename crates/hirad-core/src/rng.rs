//! SplitMix64, exactly as `experiments.md` §2 defines it, so that other programs can draw
//! bit-identical samples. Also used for every seeded choice in the library (per-element seeds,
//! never per-thread, so results do not depend on the thread count).

/// SplitMix64 generator.
#[derive(Clone, Debug)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// Generator whose state starts at `seed`.
    #[inline]
    pub fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// Next 64-bit output.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform double in [0, 1): `(next() >> 11) · 2⁻⁵³`.
    #[inline]
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform float in [0, 1).
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    /// Generator for item `index` of a stream `seed`: independent of thread scheduling.
    pub fn for_item(seed: u64, index: u64) -> Self {
        let mut g = SplitMix64::new(seed ^ index.wrapping_mul(0xD6E8_FEB8_6659_FD93));
        g.next_u64();
        g
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spec_test_vector_seed_1() {
        let mut g = SplitMix64::new(1);
        assert_eq!(g.next_u64(), 0x910a_2dec_8902_5cc1);
        let mut g = SplitMix64::new(1);
        let want = [
            0.5665615751722809,
            0.7457817572627011,
            0.9710027535867962,
            0.4443592170557721,
            0.44426470082635805,
            0.762894391911761,
        ];
        for w in want {
            assert_eq!(g.next_f64(), w);
        }
    }
}
