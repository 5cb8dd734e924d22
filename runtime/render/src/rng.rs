//! The seeded stream of uniform numbers behind the procedural volumes and the path tracer's
//! per-sample streams: SplitMix64 (Steele, Lea & Flood 2014), `rand_xoshiro`'s, with a stream
//! per (seed, pixel, sample) and the two draws the renderers take from it.

use rand_xoshiro::rand_core::{RngCore, SeedableRng};

/// A SplitMix64 generator.
#[derive(Debug, Clone)]
pub struct SplitMix64(rand_xoshiro::SplitMix64);

impl SplitMix64 {
    /// The generator whose state is `state`.
    pub fn new(state: u64) -> Self {
        Self(rand_xoshiro::SplitMix64::seed_from_u64(state))
    }

    /// The stream of sample `sample` of pixel `pixel` under `seed`: the state is a hash of the
    /// three, so streams do not depend on the order in which samples are taken.
    pub fn stream(seed: u64, pixel: u64, sample: u64) -> Self {
        let a = Self::new(seed ^ 0x5DEE_CE66_D1CE_4E5B).next_u64()
            ^ pixel.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        let b = Self::new(a).next_u64() ^ sample.wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        Self::new(b)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }

    /// Uniform in [0, 1) (the top 53 bits).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Exponential with rate 1.
    pub fn exp(&mut self) -> f64 {
        -(1.0 - self.uniform()).ln()
    }
}

#[cfg(test)]
mod tests {
    use super::SplitMix64;

    /// The first outputs from state 1234567, computed from the algorithm's definition with
    /// Python's exact integers (x += 0x9E3779B97F4A7C15, then the two xor-shift-multiplies).
    #[test]
    fn the_reference_sequence() {
        let mut r = SplitMix64::new(1_234_567);
        let want = [
            6_457_827_717_110_365_317,
            3_203_168_211_198_807_973,
            9_817_491_932_198_370_423,
        ];
        for w in want {
            assert_eq!(r.next_u64(), w);
        }
    }
}
