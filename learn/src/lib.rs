//! Reinforcement learning for modesuite: PPO (as rl_games runs it) and SAC on burn's pure-Rust
//! `flex` CPU backend.
//!
//! The crate knows nothing of the simulator: learners drive any [`VecEnvironment`].
#![warn(missing_docs)]

pub mod checkpoint;
pub mod config;
pub mod dist;
pub mod env;
pub mod gae;
pub mod lr;
pub mod metrics;
pub mod nets;
pub mod normalize;
pub mod rng;
pub mod tensors;

pub use config::{AlgoConfig, PpoConfig, SacConfig};
pub use env::{BatchStep, VecEnvironment};
pub use metrics::{read_metrics, Control, Metrics, Observer, Silent};

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
}
