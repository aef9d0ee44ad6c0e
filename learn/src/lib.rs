//! Reinforcement learning for modesuite: PPO (as rl_games runs it) and SAC on burn's pure-Rust
//! `flex` CPU backend.
//!
//! The crate knows nothing of the simulator: learners drive any [`VecEnvironment`].
#![warn(missing_docs)]

pub mod dist;
pub mod env;
pub mod gae;
pub mod lr;
pub mod normalize;
pub mod rng;
pub mod tensors;

pub use env::{BatchStep, VecEnvironment};
