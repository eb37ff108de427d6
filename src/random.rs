//! The project's one random-number generator, SplitMix64, and its output mixer.
//!
//! Everything random in ffstream is drawn from here with an explicit seed: the kernels'
//! samples (seeded per pair and per use by `formfactor::sampling`, so that rows are the
//! same for any thread or rank count), the built-in scenes' box and building layouts,
//! and the data of the tests and benchmarks. Nothing reads the clock or the OS.

/// SplitMix64 (Steele, Lea & Flood 2014): tiny, fast, and good enough to drive
/// stratified jitter. The state is a plain counter, so a stream is fully determined
/// by its seed. The one seeded generator of the project: the kernels draw from it
/// (seeded by `formfactor::sampling::pair_seed`), the built-in scenes place their boxes
/// and buildings with it, and the tests and benchmarks make their data with it.
#[derive(Clone, Copy, Debug)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        SplitMix64 { state: seed }
    }

    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.state)
    }

    /// Uniform in [0, 1) with 53 random bits.
    #[inline]
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [0, 1) with 24 random bits (every value exact in f32).
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    /// Uniform integer in [0, n), 0 for n = 0 (the high word of a 64 × 64-bit
    /// product: bias below n / 2⁶⁴).
    #[inline]
    pub fn below(&mut self, n: usize) -> usize {
        ((u128::from(self.next_u64()) * n as u128) >> 64) as usize
    }

    /// Shuffles `v` in place (Fisher–Yates).
    pub fn shuffle<T>(&mut self, v: &mut [T]) {
        for k in (1..v.len()).rev() {
            v.swap(k, self.below(k + 1));
        }
    }
}

/// The SplitMix64 output function (a bijective 64-bit mixer).
#[inline]
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
