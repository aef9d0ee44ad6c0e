//! The interface between learners and a batch of environments.

/// What one step of every environment in a batch returns.
///
/// Environments that end in this step (`terminated` or `truncated`) are reset within the same
/// step: `obs` already holds the first observation of their next episode, and `final_obs` the
/// last observation of the episode that ended (needed to bootstrap a time limit).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BatchStep {
    /// Next observations, `num_envs * obs_dim`, row per environment.
    pub obs: Vec<f32>,
    /// Reward per environment.
    pub rewards: Vec<f32>,
    /// The episode ended in a terminal state (no value beyond it).
    pub terminated: Vec<bool>,
    /// The episode was cut short (time limit): not a terminal state.
    pub truncated: Vec<bool>,
    /// The last observation of an episode that ended this step, per environment.
    pub final_obs: Vec<Option<Vec<f32>>>,
    /// Whether an episode that ended this step succeeded, where the task defines success.
    pub success: Vec<Option<bool>>,
}

/// A batch of environments stepped together (same-step auto-reset).
///
/// Actions are in the environment's own units, within [`action_bounds`](Self::action_bounds);
/// learners map their normalised outputs onto those bounds.
pub trait VecEnvironment {
    /// Number of environments in the batch.
    fn num_envs(&self) -> usize;
    /// Length of one observation.
    fn obs_dim(&self) -> usize;
    /// Length of one action.
    fn act_dim(&self) -> usize;
    /// Lower and upper action bounds, each `act_dim` long. Learners produce actions in
    /// [-1, 1] and map them linearly onto these bounds; an infinite bound counts as -1 or +1.
    fn action_bounds(&self) -> (Vec<f32>, Vec<f32>);
    /// A string naming the task and its interface (for example its id and dimensions).
    /// Checkpoints record it and refuse to resume against an environment with another.
    fn identity(&self) -> String;
    /// Resets every environment from `seed`; returns `num_envs * obs_dim` observations.
    /// An `Err` stops training (no checkpoint is written from that state).
    fn reset(&mut self, seed: u64) -> Result<Vec<f32>, String>;
    /// Steps every environment with `num_envs * act_dim` actions. An `Err` stops training;
    /// an episode that merely failed (a physics blow-up, say) should end as terminated or
    /// truncated instead, with a finite final observation.
    fn step(&mut self, actions: &[f32]) -> Result<BatchStep, String>;
    /// The complete state of the batch (simulation state and RNGs) as bytes, if the
    /// environment can save it. A checkpoint then stores it and a resumed run continues the
    /// same episodes; without it, learners reset every environment at each checkpoint (in
    /// interrupted and uninterrupted runs alike), so resuming stays exact.
    fn save_state(&self) -> Option<Vec<u8>> {
        None
    }
    /// Restores a state written by [`save_state`](Self::save_state).
    fn load_state(&mut self, _state: &[u8]) -> Result<(), String> {
        Err("this environment cannot restore a saved state".into())
    }
}
