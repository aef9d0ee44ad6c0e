//! Per-env deterministic random numbers.
//!
//! xoshiro256** seeded through SplitMix64, written here so the stream is fixed by this code
//! alone (a crate update can never change an episode). Every random draw of an env comes from its
//! [`EnvRng`], which is part of the env state (snapshots and determinism hashes include it).

use bevy_ecs::prelude::*;

use crate::state::{StateHasher, Stateful};

/// The random number generator of one environment.
#[derive(Resource, Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct EnvRng {
    s: [u64; 4],
}

fn splitmix64(x: &mut u64) -> u64 {
    *x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *x;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl EnvRng {
    /// A generator whose stream is fully determined by `seed`.
    pub fn from_seed(seed: u64) -> Self {
        let mut x = seed;
        let s = [
            splitmix64(&mut x),
            splitmix64(&mut x),
            splitmix64(&mut x),
            splitmix64(&mut x),
        ];
        Self { s }
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let result = self.s[1].wrapping_mul(5).rotate_left(7).wrapping_mul(9);
        let t = self.s[1] << 17;
        self.s[2] ^= self.s[0];
        self.s[3] ^= self.s[1];
        self.s[1] ^= self.s[2];
        self.s[0] ^= self.s[3];
        self.s[2] ^= t;
        self.s[3] = self.s[3].rotate_left(45);
        result
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal (Box-Muller; one draw of two uniforms per call).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// Uniform integer in [0, n); `n` must be > 0 (returns 0 for n == 0).
    pub fn below(&mut self, n: u64) -> u64 {
        if n == 0 {
            return 0;
        }
        // Lemire's multiply-shift with rejection for exact uniformity.
        loop {
            let x = self.next_u64();
            let m = (x as u128) * (n as u128);
            let low = m as u64;
            if low >= n.wrapping_neg() % n {
                return (m >> 64) as u64;
            }
        }
    }
}

crate::persist_by_serde!(EnvRng);

impl Stateful for EnvRng {
    fn save_state(&self) -> Box<dyn std::any::Any + Send + Sync> {
        Box::new(*self)
    }
    fn load_state(
        &mut self,
        state: &(dyn std::any::Any + Send + Sync),
    ) -> Result<(), crate::codec::StateError> {
        crate::state::restore_clone(self, state)
    }
    fn hash_state(&self, h: &mut StateHasher) {
        for w in self.s {
            h.write_u64(w);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_stream_and_uniform_in_range() {
        let mut a = EnvRng::from_seed(7);
        let mut b = EnvRng::from_seed(7);
        let mut c = EnvRng::from_seed(8);
        let xs: Vec<u64> = (0..100).map(|_| a.next_u64()).collect();
        let ys: Vec<u64> = (0..100).map(|_| b.next_u64()).collect();
        let zs: Vec<u64> = (0..100).map(|_| c.next_u64()).collect();
        assert_eq!(xs, ys);
        assert_ne!(xs, zs);
        let mut r = EnvRng::from_seed(1);
        let n = 100_000;
        let mut mean = 0.0;
        for _ in 0..n {
            let u = r.range(-2.0, 3.0);
            assert!((-2.0..3.0).contains(&u));
            mean += u / n as f64;
        }
        println!("uniform(-2,3) mean {mean:.4} (expected 0.5 +- 0.02)");
        assert!((mean - 0.5).abs() < 0.02);
        let counts = (0..60_000).fold([0u32; 6], |mut acc, _| {
            acc[r.below(6) as usize] += 1;
            acc
        });
        for c in counts {
            assert!((9_500..10_500).contains(&c), "{counts:?}");
        }
    }
}
