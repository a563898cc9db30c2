//! PCG32 random number generator (O'Neill 2014): small state, good statistics, seekable streams.

/// A PCG32 generator. Each (seed, stream) pair gives an independent sequence, so a work unit can
/// derive its own generator from (render seed, tile, sample) and results do not depend on the
/// thread schedule.
#[repr(C)]
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
    inc: u64,
}

const MULT: u64 = 6364136223846793005;

impl Rng {
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut r = Rng {
            state: 0,
            inc: (stream << 1) | 1,
        };
        r.next_u32();
        r.state = r.state.wrapping_add(seed);
        r.next_u32();
        r
    }

    /// An independent generator derived from this one's state and `j` (this one is not
    /// advanced): the `j`-th branch of a path split into several (MCPT's `branches`).
    pub fn branch(&self, j: u64) -> Rng {
        Rng::new(Rng::hash(&[self.state, self.inc, j]), 2)
    }

    /// Mixes several integers into a seed (SplitMix64 finaliser), for per-unit generators.
    pub fn hash(values: &[u64]) -> u64 {
        let mut h = 0x9E37_79B9_7F4A_7C15u64;
        for &v in values {
            h ^= v
                .wrapping_add(0x9E37_79B9_7F4A_7C15)
                .wrapping_add(h << 6)
                .wrapping_add(h >> 2);
            h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            h ^= h >> 31;
        }
        h
    }

    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(MULT).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform float in [0, 1): 24 random mantissa bits, never exactly 1.
    #[inline]
    pub fn uniform(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    #[inline]
    pub fn uniform2(&mut self) -> glam::Vec2 {
        glam::Vec2::new(self.uniform(), self.uniform())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_is_in_range_and_has_right_mean() {
        let mut r = Rng::new(7, 3);
        let n = 200_000;
        let mut sum = 0.0f64;
        for _ in 0..n {
            let u = r.uniform();
            assert!((0.0..1.0).contains(&u));
            sum += u as f64;
        }
        assert!((sum / n as f64 - 0.5).abs() < 0.005);
    }

    #[test]
    fn streams_differ() {
        let mut a = Rng::new(1, 1);
        let mut b = Rng::new(1, 2);
        let same = (0..64).filter(|_| a.next_u32() == b.next_u32()).count();
        assert!(same < 4);
    }
}
