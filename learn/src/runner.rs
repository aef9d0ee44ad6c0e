//! The training loop shared by the learners: run folders, checkpoints, resuming, metrics.

use std::path::{Path, PathBuf};

use crate::checkpoint::{Checkpoint, Identity};
use crate::config::AlgoConfig;
use crate::metrics::{Control, Metrics, MetricsWriter, Observer};
use crate::{BatchStep, LearnError, VecEnvironment};

/// Dimensions and action bounds of an environment batch.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvShape {
    /// Number of environments.
    pub n: usize,
    /// Observation length.
    pub obs_dim: usize,
    /// Action length.
    pub act_dim: usize,
    /// Lower action bounds.
    pub low: Vec<f32>,
    /// Upper action bounds.
    pub high: Vec<f32>,
}

impl EnvShape {
    /// Reads and checks an environment's dimensions and bounds. An infinite bound is taken as
    /// -1 or +1 (Isaac Lab's rl_games wrapper clips such actions to +-1 the same way).
    pub fn of(env: &dyn VecEnvironment) -> Result<Self, LearnError> {
        let (mut low, mut high) = env.action_bounds();
        low.iter_mut()
            .filter(|l| **l == f32::NEG_INFINITY)
            .for_each(|l| *l = -1.0);
        high.iter_mut()
            .filter(|h| **h == f32::INFINITY)
            .for_each(|h| *h = 1.0);
        let s = EnvShape {
            n: env.num_envs(),
            obs_dim: env.obs_dim(),
            act_dim: env.act_dim(),
            low,
            high,
        };
        if s.n == 0 || s.obs_dim == 0 || s.act_dim == 0 {
            return Err(LearnError::Env(
                "num_envs, obs_dim and act_dim must be positive".into(),
            ));
        }
        if s.low.len() != s.act_dim || s.high.len() != s.act_dim {
            return Err(LearnError::Env(
                "action bounds must have act_dim entries each".into(),
            ));
        }
        if s.low
            .iter()
            .zip(&s.high)
            .any(|(l, h)| !(l.is_finite() && h.is_finite() && l < h))
        {
            return Err(LearnError::Env(format!(
                "action bounds must be numbers with low < high (infinities count as -1 and +1): {:?} {:?}",
                s.low, s.high
            )));
        }
        Ok(s)
    }

    /// Checks a batch of observations.
    pub fn check_obs(&self, obs: &[f32], what: &str) -> Result<(), LearnError> {
        if obs.len() != self.n * self.obs_dim {
            return Err(LearnError::Env(format!(
                "{what}: {} observation values, expected {} x {}",
                obs.len(),
                self.n,
                self.obs_dim
            )));
        }
        if obs.iter().any(|x| !x.is_finite()) {
            return Err(LearnError::Env(format!("{what}: non-finite observation")));
        }
        Ok(())
    }
}

/// Resets every env for the `resets`-th restart of a run seeded with `seed` (a seed derived from
/// both, so interrupted and uninterrupted runs restart alike), checks the observations and
/// starts the episode bookkeeping over; returns the observations.
pub(crate) fn restart(
    env: &mut dyn VecEnvironment,
    seed: u64,
    resets: u64,
    shape: &EnvShape,
    tracker: &mut crate::metrics::EpisodeTracker,
) -> Result<Vec<f32>, LearnError> {
    let obs = env
        .reset(crate::rng::Rng::derive(seed, resets).next_u64())
        .map_err(LearnError::Env)?;
    shape.check_obs(&obs, "reset")?;
    tracker.restart();
    Ok(obs)
}

/// Checks a step's lengths and values (final observations present where episodes ended).
pub fn check_step(shape: &EnvShape, s: &BatchStep) -> Result<(), LearnError> {
    shape.check_obs(&s.obs, "step")?;
    let n = shape.n;
    if s.rewards.len() != n
        || s.terminated.len() != n
        || s.truncated.len() != n
        || s.final_obs.len() != n
    {
        return Err(LearnError::Env(format!(
            "step: per-environment vectors must have {n} entries"
        )));
    }
    if s.rewards.iter().any(|r| !r.is_finite()) {
        return Err(LearnError::Env("step: non-finite reward".into()));
    }
    for i in 0..n {
        if s.terminated[i] || s.truncated[i] {
            match &s.final_obs[i] {
                Some(f) if f.len() == shape.obs_dim && f.iter().all(|x| x.is_finite()) => {}
                _ => {
                    return Err(LearnError::Env(format!(
                    "step: environment {i} ended without a finite final observation of length {}",
                    shape.obs_dim
                )))
                }
            }
        }
    }
    Ok(())
}

/// Rows `ids` of a row-major matrix with `dim` columns.
pub fn gather_rows(src: &[f32], dim: usize, ids: &[usize]) -> Vec<f32> {
    let mut out = Vec::with_capacity(ids.len() * dim);
    for &i in ids {
        out.extend_from_slice(&src[i * dim..(i + 1) * dim]);
    }
    out
}

/// Maps normalised actions (clamped to [-1, 1]) onto `[low, high]`, row by row.
pub fn rescale(a: &[f32], low: &[f32], high: &[f32]) -> Vec<f32> {
    let d = low.len();
    a.iter()
        .enumerate()
        .map(|(k, x)| {
            let (l, h) = (low[k % d], high[k % d]);
            l + (x.clamp(-1.0, 1.0) + 1.0) * 0.5 * (h - l)
        })
        .collect()
}

/// What the training loop needs from a learner.
pub trait Trainer {
    /// `"ppo"` or `"sac"`.
    fn algo(&self) -> &'static str;
    /// Iterations done.
    fn iteration(&self) -> u64;
    /// Environment steps done.
    fn env_steps(&self) -> u64;
    /// One iteration.
    fn iterate(&mut self, env: &mut dyn VecEnvironment) -> Result<Metrics, LearnError>;
    /// Hash of the exact bits of every trained parameter.
    fn param_hash(&self) -> u64;
    /// The configuration.
    fn config(&self) -> AlgoConfig;
    /// Puts the whole learner state into a checkpoint.
    fn write_state(&self, c: &mut Checkpoint) -> Result<(), LearnError>;
    /// Restores the learner state from a checkpoint.
    fn read_state(&mut self, c: &Checkpoint) -> Result<(), LearnError>;
    /// Resets every environment (seeded from the run's seed and a reset counter) and forgets
    /// the episodes in progress.
    fn restart_episodes(&mut self, env: &mut dyn VecEnvironment) -> Result<(), LearnError>;
    /// Writes the deployable policy into `dir`.
    fn write_policy(&self, dir: &Path, identity: &Identity, note: &str) -> Result<(), LearnError>;
}

/// Where and how long a run trains.
///
/// Resuming is bit-exact (same parameters, optimiser state, normalisers, replay buffer, RNGs
/// and metrics as an uninterrupted run on one thread) from any checkpoint when the
/// environment implements [`VecEnvironment::save_state`]. Without it, the environments are
/// reset after every checkpoint, so a run killed at any moment resumes exactly from its last
/// periodic checkpoint; a checkpoint written because an observer stopped the run between
/// periodic ones then resumes correctly but not identically to an uninterrupted run.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Run folder: `config.ron`, `checkpoint.bin`, `metrics.jsonl`, `policy/`.
    pub dir: PathBuf,
    /// Train until this many environment steps (all environments together).
    pub total_env_steps: u64,
    /// Write a checkpoint (and the policy) every this many iterations; 0: only at the end.
    pub checkpoint_every: u64,
    /// Continue from the folder's checkpoint if there is one. When false, a folder that
    /// already holds a checkpoint is refused (runs are not overwritten).
    pub resume: bool,
    /// Free text stored with the exported policy (the command that made it, say).
    pub note: String,
}

impl RunOptions {
    /// Options with a checkpoint every 10 iterations, resuming.
    pub fn new(dir: impl Into<PathBuf>, total_env_steps: u64) -> Self {
        RunOptions {
            dir: dir.into(),
            total_env_steps,
            checkpoint_every: 10,
            resume: true,
            note: String::new(),
        }
    }
}

/// How a run ended.
#[derive(Clone, Debug, PartialEq)]
pub struct RunSummary {
    /// Iterations done (including those before a resume).
    pub iterations: u64,
    /// Environment steps done.
    pub env_steps: u64,
    /// Whether the run resumed from a checkpoint.
    pub resumed: bool,
    /// Why the environments saved in the checkpoint could not be restored on resume (a state
    /// file of another build, say): they were reset instead, and the run goes on, no longer
    /// bit-identical to an uninterrupted one.
    pub envs_reset: Option<String>,
    /// Whether an observer stopped it before `total_env_steps`.
    pub stopped: bool,
    /// The last iteration's metrics, if any iteration ran in this call.
    pub last: Option<Metrics>,
    /// Hash of the exact bits of every trained parameter at the end.
    pub param_hash: u64,
}

/// The path of a run folder's checkpoint.
pub fn checkpoint_path(dir: &Path) -> PathBuf {
    dir.join("checkpoint.bin")
}

/// Writes the checkpoint and the policy; returns whether the environment state was saved.
fn save(
    t: &dyn Trainer,
    env: &mut dyn VecEnvironment,
    opts: &RunOptions,
    identity: &Identity,
) -> Result<bool, LearnError> {
    let mut c = Checkpoint::new(identity.clone(), t.config().to_ron());
    t.write_state(&mut c)?;
    let env_state = env.save_state();
    if let Some(s) = &env_state {
        c.put_bytes("env_state", s.clone());
    }
    c.save(&checkpoint_path(&opts.dir))?;
    t.write_policy(&opts.dir.join("policy"), identity, &opts.note)?;
    Ok(env_state.is_some())
}

/// Runs a learner to `opts.total_env_steps`, resuming from and writing checkpoints.
pub fn run(
    t: &mut dyn Trainer,
    env: &mut dyn VecEnvironment,
    opts: &RunOptions,
    observer: &mut dyn Observer,
) -> Result<RunSummary, LearnError> {
    let identity = Identity {
        algo: t.algo().to_string(),
        env: env.identity(),
        num_envs: env.num_envs(),
    };
    std::fs::create_dir_all(&opts.dir)
        .map_err(|e| LearnError::Io(format!("{}: {e}", opts.dir.display())))?;
    let ckpt = checkpoint_path(&opts.dir);
    let mut resumed = false;
    let mut envs_reset = None;
    if ckpt.exists() {
        if !opts.resume {
            return Err(LearnError::Config(format!(
                "{} already holds a checkpoint; resume it or choose another folder",
                opts.dir.display()
            )));
        }
        let c = Checkpoint::load(&ckpt)?;
        c.check_identity(&identity)?;
        let saved = AlgoConfig::from_ron(&c.config_ron)?;
        if saved != t.config() {
            return Err(LearnError::Incompatible(format!(
                "the configuration differs from the one {} was trained with (see its config.ron)",
                opts.dir.display()
            )));
        }
        t.read_state(&c)?;
        let restored = if c.has("env_state") {
            env.load_state(c.bytes("env_state")?)
        } else {
            Err("the checkpoint holds no environment state".into())
        };
        if let Err(why) = restored {
            if c.has("env_state") {
                envs_reset = Some(why);
            }
            t.restart_episodes(env)?;
        }
        resumed = true;
    } else {
        crate::checkpoint::write_atomic(
            &opts.dir.join("config.ron"),
            t.config().to_ron().as_bytes(),
        )?;
    }
    let mut writer = MetricsWriter::open(&opts.dir, resumed.then(|| t.iteration()))?;
    let mut last = None;
    let mut stopped = false;
    while t.env_steps() < opts.total_env_steps {
        let m = t.iterate(env)?;
        writer.write(&m)?;
        let control = observer.on_iteration(&m);
        last = Some(m);
        let done = t.env_steps() >= opts.total_env_steps;
        stopped = control == Control::Stop && !done;
        let periodic =
            opts.checkpoint_every > 0 && t.iteration().is_multiple_of(opts.checkpoint_every);
        // Without a saved environment state, the environments are reset after each
        // checkpoint (the same reset happens when a run resumes from it).
        if (periodic || done || stopped) && !save(t, env, opts, &identity)? {
            t.restart_episodes(env)?;
        }
        if stopped {
            break;
        }
    }
    Ok(RunSummary {
        iterations: t.iteration(),
        env_steps: t.env_steps(),
        resumed,
        envs_reset,
        stopped,
        last,
        param_hash: t.param_hash(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::PointReach;

    struct Bounds(PointReach, Vec<f32>, Vec<f32>);
    impl VecEnvironment for Bounds {
        fn num_envs(&self) -> usize {
            1
        }
        fn obs_dim(&self) -> usize {
            4
        }
        fn act_dim(&self) -> usize {
            2
        }
        fn action_bounds(&self) -> (Vec<f32>, Vec<f32>) {
            (self.1.clone(), self.2.clone())
        }
        fn identity(&self) -> String {
            String::new()
        }
        fn reset(&mut self, seed: u64) -> Result<Vec<f32>, String> {
            self.0.reset(seed)
        }
        fn step(&mut self, a: &[f32]) -> Result<BatchStep, String> {
            self.0.step(a)
        }
    }

    #[test]
    fn bounds_rescaling_and_infinities() {
        let env = Bounds(
            PointReach::new(1),
            vec![f32::NEG_INFINITY, 0.0],
            vec![f32::INFINITY, 4.0],
        );
        let s = EnvShape::of(&env).unwrap();
        assert_eq!(
            (s.low.clone(), s.high.clone()),
            (vec![-1.0, 0.0], vec![1.0, 4.0])
        );
        assert_eq!(
            rescale(&[0.5, 0.5, -3.0, 2.0], &s.low, &s.high),
            vec![0.5, 3.0, -1.0, 4.0]
        );
        let bad = Bounds(PointReach::new(1), vec![f32::NAN, 0.0], vec![1.0, 4.0]);
        assert!(EnvShape::of(&bad).is_err());
        let bad = Bounds(PointReach::new(1), vec![2.0, 0.0], vec![f32::INFINITY, 4.0]);
        assert!(EnvShape::of(&bad).is_err());
    }
}
