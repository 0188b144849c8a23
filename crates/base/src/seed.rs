//! Reproducible random streams: [`mix`] turns a `(seed, stream)` pair into the seed of an
//! independent generator, so that a stream depends on its own index only (not on how many
//! numbers other streams drew).

/// SplitMix64 finaliser of the pair `(seed, stream)`: neighbouring streams of one seed get
/// unrelated values. The arithmetic is fixed: every seed the project derives depends on it.
pub fn mix(seed: u64, stream: u64) -> u64 {
    let mut z = seed
        ^ stream
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add(0x632B_E59B_D9B4_E019);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::mix;

    /// Values of the mixer as it was in `scbg-synth` and `scbg-train` before it moved here;
    /// a change would change every generated scene and every training run.
    #[test]
    fn fixed_values() {
        assert_eq!(mix(0, 0), 0x6DB6_CA64_564D_AEAA);
        assert_eq!(mix(0, 1), 0x5CC6_0547_7769_02BA);
        assert_eq!(mix(1, 0), 0x9AC9_032E_2439_7F11);
        assert_eq!(mix(42, 7), 0x2448_0789_CC68_6D62);
        assert_eq!(mix(u64::MAX, u64::MAX), 0xEEF3_A5E0_613B_863D);
        assert_eq!(
            mix(0x0123_4567_89AB_CDEF, 123_456_789),
            0x85C2_AB1E_D036_CD2E
        );
    }
}
