//! The buffers and spaces through which an env talks to its systems: the step's action, the
//! observation, the step's signals (reward, termination, success, diagnostics) and the declared
//! spaces. Plain resources below the application layer; [`crate::env`] re-exports them.

use std::collections::BTreeMap;

use bevy_ecs::prelude::*;

/// The raw action of this env for the current step (written by the env before `EnvStep`).
#[derive(Resource, Debug, Clone, Default)]
pub struct ActionBuffer(pub Vec<f32>);

/// The flat observation of this env (written by `Observe` systems).
#[derive(Resource, Debug, Clone, Default)]
pub struct ObservationBuffer(pub Vec<f32>);

/// What `Evaluate` systems report for the current step (cleared before each step).
#[derive(Resource, Debug, Clone, Default)]
pub struct StepSignals {
    /// Reward of this step.
    pub reward: f64,
    /// The episode reached a terminal state (success or failure of the MDP).
    pub terminated: bool,
    /// The episode was cut short (time limit, error).
    pub truncated: bool,
    /// Task success, when the task defines it.
    pub success: Option<bool>,
    /// Named scalar diagnostics (reward terms, distances...).
    pub values: BTreeMap<String, f64>,
}

impl StepSignals {
    /// Adds `value` to the step reward and to its `reward/<term>` diagnostic.
    pub fn add_reward(&mut self, term: &str, value: f64) {
        self.reward += value;
        *self.values.entry(format!("reward/{term}")).or_default() += value;
    }
}

/// A space, as Gymnasium declares them.
#[derive(Debug, Clone, PartialEq)]
pub enum Space {
    /// A box of f32 values with per-element bounds (row-major `shape`).
    Box {
        /// Lower bounds (len = product of shape); -inf allowed.
        low: Vec<f32>,
        /// Upper bounds; +inf allowed.
        high: Vec<f32>,
        /// Shape.
        shape: Vec<usize>,
    },
    /// Integers 0..n, stored as one f32 in flat buffers.
    Discrete {
        /// Number of values.
        n: u64,
    },
    /// Named sub-spaces, flattened in order.
    Dict(Vec<(String, Space)>),
}

impl Space {
    /// An unbounded box of `dim` values.
    pub fn unbounded(dim: usize) -> Self {
        Space::Box {
            low: vec![f32::NEG_INFINITY; dim],
            high: vec![f32::INFINITY; dim],
            shape: vec![dim],
        }
    }

    /// Number of f32 values in a flat buffer of this space.
    pub fn flat_dim(&self) -> usize {
        match self {
            Space::Box { shape, .. } => shape.iter().product(),
            Space::Discrete { .. } => 1,
            Space::Dict(items) => items.iter().map(|(_, s)| s.flat_dim()).sum(),
        }
    }

    /// Checks a flat value: length, finiteness, bounds (boxes are clipped by action terms, so only
    /// non-finite values and out-of-range discrete values are errors). `Err` names the index.
    pub fn check(&self, x: &[f32]) -> Result<(), String> {
        if x.len() != self.flat_dim() {
            return Err(format!(
                "length {} but the space has {} values",
                x.len(),
                self.flat_dim()
            ));
        }
        if let Some((i, v)) = x.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(format!("[{i}] = {v}: values must be finite"));
        }
        let mut offset = 0;
        self.check_discrete(x, &mut offset)
    }

    fn check_discrete(&self, x: &[f32], offset: &mut usize) -> Result<(), String> {
        match self {
            Space::Box { .. } => *offset += self.flat_dim(),
            Space::Discrete { n } => {
                let v = x[*offset];
                if v < 0.0 || v.fract() != 0.0 || (v as u64) >= *n {
                    return Err(format!(
                        "[{offset}] = {v}: a Discrete({n}) value is an integer in 0..{n}"
                    ));
                }
                *offset += 1;
            }
            Space::Dict(items) => {
                for (_, s) in items {
                    s.check_discrete(x, offset)?;
                }
            }
        }
        Ok(())
    }
}

/// Observation and action spaces of an env (set by the task; empty boxes by default).
#[derive(Resource, Debug, Clone, PartialEq)]
pub struct Spaces {
    /// Observation space.
    pub observation: Space,
    /// Action space.
    pub action: Space,
}

impl Default for Spaces {
    fn default() -> Self {
        Self {
            observation: Space::unbounded(0),
            action: Space::unbounded(0),
        }
    }
}
