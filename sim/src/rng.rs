//! Seeded randomness: a portable stream and derived per-episode seeds.
//!
//! All randomness in this crate comes from [`SimRng`], a ChaCha8 stream (`rand_chacha`) of which
//! only the raw 64-bit words are used; uniform and Gaussian numbers are formed here from those
//! words, so the same seed yields the same numbers on every platform and with every `rand`
//! version that keeps ChaCha8's word stream.

use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::{Rng, SeedableRng};

/// A seeded random stream.
#[derive(Debug, Clone)]
pub struct SimRng {
    inner: ChaCha8Rng,
    spare_normal: Option<f64>,
}

impl SimRng {
    /// A stream from a 64-bit seed.
    pub fn new(seed: u64) -> Self {
        Self {
            inner: ChaCha8Rng::seed_from_u64(seed),
            spare_normal: None,
        }
    }

    /// The next raw 64-bit word.
    pub fn next_u64(&mut self) -> u64 {
        self.inner.next_u64()
    }

    /// Uniform in `[0, 1)` with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[lo, hi)`.
    pub fn uniform_in(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal (Box–Muller, both values used).
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare_normal.take() {
            return z;
        }
        // 1 - u is in (0, 1], so the logarithm is finite.
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
        self.spare_normal = Some(r * s);
        r * c
    }

    /// The stream as it will be after `n` more calls of [`SimRng::normal`], without drawing
    /// them (one seek of the ChaCha counter): the calls on the result give the numbers that
    /// calls `n + 1, n + 2, …` on `self` would. Lets several threads draw consecutive parts of
    /// one stream of normals, bitwise as one thread would.
    pub fn after_normals(&self, n: usize) -> SimRng {
        let mut r = self.clone();
        let mut n = n;
        if n > 0 && r.spare_normal.take().is_some() {
            n -= 1;
        }
        // Every pair of normals takes two 64-bit words, four 32-bit ChaCha words.
        let pairs = (n / 2) as u128;
        let pos = r.inner.get_word_pos() + 4 * pairs;
        r.inner.set_word_pos(pos);
        if n % 2 == 1 {
            r.normal();
        }
        r
    }

    /// `true` with probability `p`.
    pub fn bernoulli(&mut self, p: f64) -> bool {
        self.uniform() < p
    }
}

/// A seed derived from a master seed, a stream label and an index (SplitMix64 finaliser over
/// the three), so episode `i` gets the same seed whatever the number of threads.
pub fn derive_seed(master: u64, stream: u64, index: u64) -> u64 {
    let mut z = master
        ^ stream.wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ index.wrapping_mul(0xD1B5_4A32_D192_ED03);
    for _ in 0..2 {
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
    }
    z
}

/// Stream labels for [`derive_seed`], so exploration and noise never share numbers.
pub(crate) mod stream {
    pub const EPISODE: u64 = 1;
    pub const EXPLORE: u64 = 2;
    pub const NOISE: u64 = 3;
    pub const PERTURB: u64 = 4;
}

/// Checks a perturbation fraction (`[0, 1)`) for the `perturbed` helpers.
pub(crate) fn check_fraction(what: &'static str, fraction: f64) -> Result<(), crate::SimError> {
    if fraction.is_finite() && (0.0..1.0).contains(&fraction) {
        Ok(())
    } else {
        Err(crate::SimError::Input {
            what,
            message: format!("must be within [0, 1) (e.g. 0.1 for ±10 %), got {fraction}"),
        })
    }
}

/// Seeded factors uniform in `[1 − fraction, 1 + fraction]`, one per call, for the
/// `perturbed` helpers.
pub(crate) struct Perturb {
    rng: SimRng,
    fraction: f64,
}

impl Perturb {
    pub(crate) fn new(seed: u64, fraction: f64) -> Self {
        Self {
            rng: SimRng::new(derive_seed(seed, stream::PERTURB, 0)),
            fraction,
        }
    }

    /// `v` times the next factor.
    pub(crate) fn scale(&mut self, v: &mut f64) {
        *v *= 1.0 + self.fraction * (2.0 * self.rng.uniform() - 1.0);
    }
}
