//! A tiny seeded generator for weight initialisation, identical on every platform.

/// SplitMix64 (Steele, Lea & Flood 2014): 64-bit state, integer arithmetic only, so the same seed
/// gives the same stream on every platform and compiler. Used only for initialisation; not a
/// cryptographic generator.
#[derive(Debug, Clone)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// A generator started from `seed`.
    pub fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) with 53 random bits (exact conversion, no rounding).
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [−bound, bound), computed in `f64` with exactly rounded operations and rounded
    /// once to `f32`.
    pub fn uniform_symmetric(&mut self, bound: f64) -> f32 {
        ((2.0 * self.next_f64() - 1.0) * bound) as f32
    }
}
