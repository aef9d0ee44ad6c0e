//! Evaluation of a deterministic policy on an environment batch.

use crate::metrics::EpisodeTracker;
use crate::runner::{check_step, EnvShape};
use crate::{LearnError, VecEnvironment};

/// Results of evaluation episodes.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalSummary {
    /// Return of each episode, in the order they ended.
    pub returns: Vec<f64>,
    /// Length of each episode.
    pub lengths: Vec<u64>,
    /// Success flags of the episodes that report one.
    pub successes: Vec<bool>,
}

impl EvalSummary {
    /// Mean return.
    pub fn return_mean(&self) -> f64 {
        self.returns.iter().sum::<f64>() / self.returns.len().max(1) as f64
    }

    /// Success rate, where the environment reports success.
    pub fn success_rate(&self) -> Option<f64> {
        (!self.successes.is_empty()).then(|| {
            self.successes.iter().filter(|s| **s).count() as f64 / self.successes.len() as f64
        })
    }
}

/// Runs `act` (observations in, actions out, both batched) from `env.reset(seed)` until
/// `episodes` episodes have ended; episodes are kept in the order they ended (with several
/// environments, short episodes end first).
pub fn evaluate(
    env: &mut dyn VecEnvironment,
    episodes: usize,
    seed: u64,
    mut act: impl FnMut(&[f32]) -> Vec<f32>,
) -> Result<EvalSummary, LearnError> {
    let shape = EnvShape::of(env)?;
    let mut obs = env.reset(seed).map_err(LearnError::Env)?;
    shape.check_obs(&obs, "reset")?;
    let mut tracker = EpisodeTracker::new(env.num_envs());
    let mut out = EvalSummary {
        returns: Vec::new(),
        lengths: Vec::new(),
        successes: Vec::new(),
    };
    while out.returns.len() < episodes {
        let step = env.step(&act(&obs)).map_err(LearnError::Env)?;
        check_step(&shape, &step)?;
        tracker.record(&step);
        let (r, l, s) = tracker.take_finished();
        out.returns.extend(r);
        out.lengths.extend(l);
        out.successes.extend(s);
        obs = step.obs;
    }
    out.returns.truncate(episodes);
    out.lengths.truncate(episodes);
    out.successes.truncate(episodes);
    Ok(out)
}
