//! The adaptive-KL learning-rate rule of rl_games.

use serde::{Deserialize, Serialize};

/// Adaptive learning rate: divide by `factor` when the KL divergence exceeds twice the target,
/// multiply by it when the KL falls under half the target, within `[min_lr, max_lr]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AdaptiveKl {
    /// Target KL divergence per minibatch.
    pub kl_threshold: f32,
    /// The factor of each change (rl_games: 1.5).
    pub factor: f64,
    /// Lower bound of the learning rate.
    pub min_lr: f64,
    /// Upper bound of the learning rate.
    pub max_lr: f64,
}

impl Default for AdaptiveKl {
    fn default() -> Self {
        AdaptiveKl {
            kl_threshold: 0.008,
            factor: 1.5,
            min_lr: 1e-6,
            max_lr: 1e-2,
        }
    }
}

impl AdaptiveKl {
    /// The next learning rate given the current one and the measured KL.
    pub fn update(&self, lr: f64, kl: f32) -> f64 {
        let thr = self.kl_threshold;
        if kl > 2.0 * thr {
            (lr / self.factor).max(self.min_lr)
        } else if kl < 0.5 * thr {
            (lr * self.factor).min(self.max_lr)
        } else {
            lr
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rl_games_rule() {
        let a = AdaptiveKl {
            kl_threshold: 0.01,
            ..AdaptiveKl::default()
        };
        assert_eq!(a.update(3e-4, 0.021), 3e-4 / 1.5);
        assert_eq!(a.update(3e-4, 0.004), 3e-4 * 1.5);
        // Inside the band [thr/2, 2 thr] (ends included) nothing changes.
        for kl in [0.005, 0.01, 0.02] {
            assert_eq!(a.update(3e-4, kl), 3e-4);
        }
        assert_eq!(a.update(1e-6, 1.0), 1e-6);
        assert_eq!(a.update(9e-3, 0.0), 1e-2);
    }
}
