//! Reinforcement learning for modesuite: PPO (as rl_games runs it) and SAC on burn's pure-Rust
//! `flex` CPU backend.
//!
//! The crate knows nothing of the simulator: learners drive any [`VecEnvironment`]. A run
//! lives in a folder (`config.ron`, `checkpoint.bin`, `metrics.jsonl`, `policy/`):
//!
//! ```no_run
//! use modesuite_learn::{envs::PointReach, train, AlgoConfig, Policy, PpoConfig, RunOptions, Silent};
//! let mut env = PointReach::new(16);
//! let cfg = AlgoConfig::Ppo(PpoConfig::default());
//! let summary = train(&cfg, &mut env, &RunOptions::new("runs/reach", 100_000), &mut Silent)?;
//! let policy = Policy::load("runs/reach")?;
//! let action = policy.act(&[0.5, -0.2, 0.0, 0.0]);
//! # Ok::<(), modesuite_learn::LearnError>(())
//! ```
#![warn(missing_docs)]

pub mod actors;
pub mod bc;
pub mod checkpoint;
pub mod chunks;
pub mod config;
pub mod dist;
pub mod encoder;
pub mod env;
pub mod envs;
pub mod eval;
pub mod gae;
pub mod lr;
pub mod metrics;
pub mod nets;
pub mod normalize;
pub mod policy;
pub mod ppo;
pub mod rng;
pub mod runner;
pub mod sac;
pub mod tensors;

pub use config::{AlgoConfig, PpoConfig, SacConfig};
pub use env::{BatchStep, VecEnvironment};
pub use eval::{evaluate, EvalSummary};
pub use metrics::{read_metrics, Control, Metrics, Observer, Silent};
pub use policy::{Policy, PolicyMeta};
pub use runner::{RunOptions, RunSummary};

/// Trains (or resumes) a run of either algorithm in `opts.dir` until
/// `opts.total_env_steps`; see [`runner::run`].
pub fn train(
    cfg: &AlgoConfig,
    env: &mut dyn VecEnvironment,
    opts: &RunOptions,
    observer: &mut dyn Observer,
) -> Result<RunSummary, LearnError> {
    match cfg {
        AlgoConfig::Ppo(c) => {
            let mut t = ppo::Ppo::new(c, env)?;
            runner::run(&mut t, env, opts, observer)
        }
        AlgoConfig::Sac(c) => {
            let mut t = sac::Sac::new(c, env)?;
            runner::run(&mut t, env, opts, observer)
        }
    }
}

/// The configuration a run folder was started with (its `config.ron`), to resume it.
pub fn run_config(dir: &std::path::Path) -> Result<AlgoConfig, LearnError> {
    AlgoConfig::load(&dir.join("config.ron"))
}

/// Errors of training, checkpoints and policies.
#[derive(Debug, thiserror::Error)]
pub enum LearnError {
    /// A configuration that does not parse or is out of range.
    #[error("configuration: {0}")]
    Config(String),
    /// Reading or writing a file failed.
    #[error("i/o: {0}")]
    Io(String),
    /// A checkpoint or policy file is malformed.
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    /// A checkpoint or policy from another format version, algorithm or environment.
    #[error("incompatible: {0}")]
    Incompatible(String),
    /// The environment broke its contract (wrong lengths, non-finite values).
    #[error("environment: {0}")]
    Env(String),
    /// A loss became NaN or infinite; no checkpoint is written from such a state.
    #[error("training diverged: {0}")]
    Diverged(String),
    /// A weights file (an image encoder's) that does not load: wrong format, names or shapes.
    #[error("weights: {0}")]
    Weights(String),
}
