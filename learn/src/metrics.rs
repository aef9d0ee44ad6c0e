//! Per-iteration metrics (written as JSON lines) and the observer hook of the training loops.

use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::LearnError;

/// What one training iteration reports (a PPO update, or `steps_per_iteration` SAC steps).
/// Fields that do not apply to an algorithm (or an iteration without finished episodes) are
/// `None`: `null` in the JSON line.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Algorithm (`"ppo"` or `"sac"`).
    pub algo: String,
    /// Iterations completed, this one included.
    pub iteration: u64,
    /// Environment steps so far (all environments together).
    pub env_steps: u64,
    /// Wall-clock seconds of training so far (resumed runs continue the count).
    pub wall_s: f64,
    /// Environment steps per second in this iteration.
    pub steps_per_s: f64,
    /// Episodes that ended in this iteration.
    pub episodes: u64,
    /// Mean return of those episodes.
    pub return_mean: Option<f64>,
    /// Mean length of those episodes.
    pub length_mean: Option<f64>,
    /// Fraction of those episodes (with a success flag) that succeeded.
    pub success_rate: Option<f64>,
    /// Learning rate at the end of the iteration (PPO), actor learning rate (SAC).
    pub lr: Option<f64>,
    /// Mean actor (surrogate) loss.
    pub actor_loss: Option<f64>,
    /// Mean critic loss.
    pub critic_loss: Option<f64>,
    /// Mean policy entropy.
    pub entropy: Option<f64>,
    /// Mean KL divergence between the rollout policy and the updated one (PPO).
    pub approx_kl: Option<f64>,
    /// Fraction of samples whose ratio left the clipping range (PPO).
    pub clip_fraction: Option<f64>,
    /// Mean bounds loss (PPO).
    pub bounds_loss: Option<f64>,
    /// Mean gradient norm before clipping.
    pub grad_norm: Option<f64>,
    /// Temperature (SAC).
    pub alpha: Option<f64>,
    /// Mean Q value of sampled batches (SAC).
    pub q_mean: Option<f64>,
}

impl Metrics {
    /// One line for a progress display: iteration, env steps (of `total`), steps/s, return,
    /// success and the algorithm's main diagnostics.
    pub fn progress_line(&self, total: u64) -> String {
        let mut s = format!(
            "{} it {} | {}/{} steps | {:.0} steps/s",
            self.algo, self.iteration, self.env_steps, total, self.steps_per_s
        );
        if let Some(r) = self.return_mean {
            s += &format!(" | return {r:.3}");
        }
        if let Some(x) = self.success_rate {
            s += &format!(" | success {:.0}%", 100.0 * x);
        }
        if let Some(kl) = self.approx_kl {
            s += &format!(" | kl {kl:.4}");
        }
        if let Some(a) = self.alpha {
            s += &format!(" | alpha {a:.4}");
        }
        s
    }
}

/// Appends metrics to `metrics.jsonl` in a run folder, one JSON object per line.
pub struct MetricsWriter {
    path: PathBuf,
}

impl MetricsWriter {
    /// The writer of `dir/metrics.jsonl`. When resuming from a checkpoint taken at
    /// `keep_through_iteration`, lines of later iterations (written before an interruption)
    /// are dropped so the file matches the resumed run; otherwise the file starts empty.
    pub fn open(dir: &Path, keep_through_iteration: Option<u64>) -> Result<Self, LearnError> {
        let path = dir.join("metrics.jsonl");
        let kept = match (keep_through_iteration, std::fs::read_to_string(&path)) {
            (Some(last), Ok(text)) => text
                .lines()
                .filter(|l| {
                    serde_json::from_str::<Metrics>(l)
                        .map(|m| m.iteration <= last)
                        .unwrap_or(false)
                })
                .map(|l| format!("{l}\n"))
                .collect::<String>(),
            _ => String::new(),
        };
        crate::checkpoint::write_atomic(&path, kept.as_bytes())?;
        Ok(MetricsWriter { path })
    }

    /// Appends one line.
    pub fn write(&mut self, m: &Metrics) -> Result<(), LearnError> {
        let mut line = serde_json::to_string(m).map_err(|e| LearnError::Io(e.to_string()))?;
        line.push('\n');
        let mut f = std::fs::OpenOptions::new()
            .append(true)
            .create(true)
            .open(&self.path)
            .map_err(|e| LearnError::Io(format!("{}: {e}", self.path.display())))?;
        f.write_all(line.as_bytes())
            .map_err(|e| LearnError::Io(format!("{}: {e}", self.path.display())))
    }
}

/// Reads every line of a `metrics.jsonl` file.
pub fn read_metrics(path: &Path) -> Result<Vec<Metrics>, LearnError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| LearnError::Io(format!("{}: {e}", path.display())))?;
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            serde_json::from_str(l).map_err(|e| LearnError::Io(format!("{}: {e}", path.display())))
        })
        .collect()
}

/// Whether a training loop goes on after an iteration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    /// Keep training.
    Continue,
    /// Write a checkpoint now and return (as an interrupted run would have been).
    Stop,
}

/// Sees each iteration's metrics (a progress bar, say) and may stop the run.
pub trait Observer {
    /// Called after every iteration, after its metrics line is written.
    fn on_iteration(&mut self, metrics: &Metrics) -> Control;
}

/// An observer that does nothing.
pub struct Silent;

impl Observer for Silent {
    fn on_iteration(&mut self, _: &Metrics) -> Control {
        Control::Continue
    }
}

impl<F: FnMut(&Metrics) -> Control> Observer for F {
    fn on_iteration(&mut self, metrics: &Metrics) -> Control {
        self(metrics)
    }
}

/// Episode bookkeeping per environment: running return and length, and the episodes that
/// ended since the last drain.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EpisodeTracker {
    /// Return so far of each environment's current episode.
    pub ret: Vec<f64>,
    /// Length so far of each environment's current episode.
    pub len: Vec<u64>,
    done_returns: Vec<f64>,
    done_lengths: Vec<u64>,
    successes: Vec<bool>,
}

impl EpisodeTracker {
    /// A tracker for `n` environments.
    pub fn new(n: usize) -> Self {
        EpisodeTracker {
            ret: vec![0.0; n],
            len: vec![0; n],
            ..Default::default()
        }
    }

    /// Records one batched step.
    pub fn record(&mut self, step: &crate::BatchStep) {
        for i in 0..self.ret.len() {
            self.ret[i] += step.rewards[i] as f64;
            self.len[i] += 1;
            if step.terminated[i] || step.truncated[i] {
                self.done_returns.push(self.ret[i]);
                self.done_lengths.push(self.len[i]);
                if let Some(s) = step.success.get(i).copied().flatten() {
                    self.successes.push(s);
                }
                self.ret[i] = 0.0;
                self.len[i] = 0;
            }
        }
    }

    /// Forgets the current episodes (after the environments were reset).
    pub fn restart(&mut self) {
        self.ret.iter_mut().for_each(|r| *r = 0.0);
        self.len.iter_mut().for_each(|l| *l = 0);
    }

    /// Returns, lengths and success flags of the episodes ended since the last drain.
    pub fn take_finished(&mut self) -> (Vec<f64>, Vec<u64>, Vec<bool>) {
        (
            std::mem::take(&mut self.done_returns),
            std::mem::take(&mut self.done_lengths),
            std::mem::take(&mut self.successes),
        )
    }

    /// Fills the episode fields of `m` with the episodes ended since the last call.
    pub fn drain_into(&mut self, m: &mut Metrics) {
        let n = self.done_returns.len();
        m.episodes = n as u64;
        if n > 0 {
            m.return_mean = Some(self.done_returns.iter().sum::<f64>() / n as f64);
            m.length_mean = Some(self.done_lengths.iter().sum::<u64>() as f64 / n as f64);
        }
        if !self.successes.is_empty() {
            let s = self.successes.iter().filter(|s| **s).count();
            m.success_rate = Some(s as f64 / self.successes.len() as f64);
        }
        self.done_returns.clear();
        self.done_lengths.clear();
        self.successes.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn progress_line_and_json_round_trip() {
        let m = Metrics {
            algo: "ppo".into(),
            iteration: 3,
            env_steps: 1536,
            steps_per_s: 1234.4,
            return_mean: Some(-9.5),
            success_rate: Some(0.75),
            approx_kl: Some(0.0081),
            ..Default::default()
        };
        assert_eq!(
            m.progress_line(10_000),
            "ppo it 3 | 1536/10000 steps | 1234 steps/s | return -9.500 | success 75% | kl 0.0081"
        );
        let line = serde_json::to_string(&m).unwrap();
        let back: Metrics = serde_json::from_str(&line).unwrap();
        assert_eq!(back, m);
    }
}
