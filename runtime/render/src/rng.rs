//! SplitMix64 (Steele, Lea & Flood 2014): the seeded stream of uniform numbers behind the
//! procedural volumes and the path tracer's per-sample streams.

/// A SplitMix64 state.
#[derive(Debug, Clone)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// The stream of sample `sample` of pixel `pixel` under `seed`: the state is a hash of the
    /// three, so streams do not depend on the order in which samples are taken.
    pub fn stream(seed: u64, pixel: u64, sample: u64) -> Self {
        let mut r = Self(seed ^ 0x5DEE_CE66_D1CE_4E5B);
        let a = r.next_u64() ^ pixel.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        let mut r = Self(a);
        let b = r.next_u64() ^ sample.wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        Self(b)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
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
