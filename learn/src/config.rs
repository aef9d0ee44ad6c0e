//! Hyper-parameters of the learners (serde; RON files with every field optional).

use serde::{Deserialize, Serialize};
use std::path::Path;

use crate::lr::AdaptiveKl;
use crate::nets::Activation;
use crate::LearnError;

/// PPO hyper-parameters. Defaults follow rl_games' `a2c_continuous` as Isaac Lab configures it
/// for manipulation (Franka cabinet): see each field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PpoConfig {
    /// Seed of every random choice (weights, noise, minibatch order, environment resets).
    pub seed: u64,
    /// Hidden layer widths (default 256-128-64).
    pub hidden: Vec<usize>,
    /// Hidden nonlinearity (default ELU).
    pub activation: Activation,
    /// Separate actor and critic networks (default false: one shared trunk, two heads).
    pub separate: bool,
    /// Steps per environment per rollout (rl_games `horizon_length`; default 32, so 16
    /// environments give 512 samples per update; Isaac Lab's configs use 16 to 96 with
    /// thousands of environments).
    pub horizon: usize,
    /// Samples per minibatch (default 4096; at most `horizon * num_envs` is used).
    pub minibatch_size: usize,
    /// Passes over each rollout (rl_games `mini_epochs`; default 5).
    pub mini_epochs: usize,
    /// Discount (default 0.99).
    pub gamma: f32,
    /// GAE lambda (rl_games `tau`; default 0.95).
    pub lambda: f32,
    /// Surrogate clipping range (rl_games `e_clip`; default 0.2).
    pub clip: f32,
    /// Clip the value loss around the rollout's values with the same range (default true).
    pub clip_value: bool,
    /// Initial learning rate (default 5e-4).
    pub learning_rate: f64,
    /// Adaptive-KL learning rate; `None` keeps the rate fixed (default: threshold 0.008).
    pub adaptive_kl: Option<AdaptiveKl>,
    /// Adam epsilon (default 1e-8, PyTorch's).
    pub adam_eps: f32,
    /// Weight of the value loss: `loss = actor + 0.5 * critic_coef * value - ...` (default 4).
    pub critic_coef: f32,
    /// Weight of the entropy bonus (default 0).
    pub entropy_coef: f32,
    /// Weight of the bounds loss on the action mean beyond +-1.1 (default 1e-4).
    pub bounds_loss_coef: f32,
    /// Global gradient-norm limit; `None` disables clipping (default 1.0).
    pub grad_norm: Option<f32>,
    /// Normalise observations with running statistics (default true).
    pub normalize_obs: bool,
    /// Clip normalised observations to +-this (default 5).
    pub obs_clip: f32,
    /// Learn the value of normalised returns (rl_games `normalize_value`; default true).
    pub normalize_value: bool,
    /// Normalise advantages over each rollout (default true).
    pub normalize_advantage: bool,
    /// Bootstrap time-limit steps from the final observation's value (default true). When
    /// false, time limits are treated as terminal states.
    pub bootstrap_truncation: bool,
    /// Initial log standard deviation of the state-independent policy noise (default 0).
    pub init_log_std: f32,
    /// What an episode ended by a simulation failure (a physics blow-up) teaches. `None`
    /// (default): it ends like a time limit, bootstrapped from the value of the last good
    /// observation, so the failure neither costs nor pays. `Some(r)`: it ends as a terminal
    /// state with reward `r`, so that a policy learns to avoid what breaks the simulation
    /// (crushing a rod into a wall, say); `r` should be below the discounted return of going on
    /// (about the worst step reward / (1 - gamma)). Applied by the simulator's training env
    /// (`modesuite train`); set per task in its `<algo>.ron`.
    pub error_penalty: Option<f32>,
    /// What an episode the task ends as failed teaches (a termination term fired: Lift's belt
    /// on the robot's body, say). `None` (default): nothing beyond the task's rewards. In a task
    /// whose every step costs (the distance rewards), ending early pays, and a policy learns to
    /// fail at once (PPO on Franka Lift ended every episode after 13 steps). `Some(r)`: `r` is
    /// added to the failing step's reward; like `error_penalty` it should be below the
    /// discounted return of going on. Applied by the simulator's training env; set per task in
    /// its `<algo>.ron`.
    pub failure_penalty: Option<f32>,
}

impl Default for PpoConfig {
    fn default() -> Self {
        PpoConfig {
            seed: 0,
            hidden: vec![256, 128, 64],
            activation: Activation::Elu,
            separate: false,
            horizon: 32,
            minibatch_size: 4096,
            mini_epochs: 5,
            gamma: 0.99,
            lambda: 0.95,
            clip: 0.2,
            clip_value: true,
            learning_rate: 5e-4,
            adaptive_kl: Some(AdaptiveKl::default()),
            adam_eps: 1e-8,
            critic_coef: 4.0,
            entropy_coef: 0.0,
            bounds_loss_coef: 1e-4,
            grad_norm: Some(1.0),
            normalize_obs: true,
            obs_clip: 5.0,
            normalize_value: true,
            normalize_advantage: true,
            bootstrap_truncation: true,
            init_log_std: 0.0,
            error_penalty: None,
            failure_penalty: None,
        }
    }
}

/// SAC hyper-parameters. Defaults follow CleanRL's continuous SAC and rl_games' learned
/// temperature: see each field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SacConfig {
    /// Seed of every random choice.
    pub seed: u64,
    /// Hidden widths of the actor and of each Q network (default 256-256).
    pub hidden: Vec<usize>,
    /// Hidden nonlinearity (default ReLU).
    pub activation: Activation,
    /// Replay buffer capacity in transitions (default 1,000,000).
    pub buffer_size: usize,
    /// Transitions per gradient step (default 256).
    pub batch_size: usize,
    /// Environment steps (all environments together) of uniform random actions before
    /// learning starts (default 5000).
    pub learning_starts: u64,
    /// Gradient steps per batched environment step (default 1).
    pub gradient_steps: usize,
    /// Discount (default 0.99).
    pub gamma: f32,
    /// Polyak coefficient of the target networks (default 0.005).
    pub tau: f32,
    /// Actor learning rate (default 3e-4).
    pub actor_lr: f64,
    /// Critic learning rate (default 1e-3).
    pub critic_lr: f64,
    /// Temperature learning rate (default 3e-4).
    pub alpha_lr: f64,
    /// Initial temperature (default 1).
    pub init_alpha: f32,
    /// Learn the temperature (default true).
    pub learn_alpha: bool,
    /// Target entropy; `None` means `-act_dim` (default).
    pub target_entropy: Option<f32>,
    /// Bounds of the actor's log standard deviation (default -5, 2).
    pub log_std_bounds: (f32, f32),
    /// Global gradient-norm limit for every network; `None` disables (default).
    pub grad_norm: Option<f32>,
    /// Batched environment steps per logged iteration (default 1000).
    pub steps_per_iteration: usize,
    /// What an episode ended by a simulation failure (a physics blow-up) teaches. `None`
    /// (default): it ends like a time limit, bootstrapped from the value of the last good
    /// observation, so the failure neither costs nor pays. `Some(r)`: it ends as a terminal
    /// state with reward `r`, so that a policy learns to avoid what breaks the simulation
    /// (crushing a rod into a wall, say); `r` should be below the discounted return of going on
    /// (about the worst step reward / (1 - gamma)). Applied by the simulator's training env
    /// (`modesuite train`); set per task in its `<algo>.ron`.
    pub error_penalty: Option<f32>,
    /// Reward added to the step on which the task ends an episode as failed, as
    /// [`PpoConfig::failure_penalty`] (default `None`).
    pub failure_penalty: Option<f32>,
}

impl Default for SacConfig {
    fn default() -> Self {
        SacConfig {
            seed: 0,
            hidden: vec![256, 256],
            activation: Activation::Relu,
            buffer_size: 1_000_000,
            batch_size: 256,
            learning_starts: 5000,
            gradient_steps: 1,
            gamma: 0.99,
            tau: 0.005,
            actor_lr: 3e-4,
            critic_lr: 1e-3,
            alpha_lr: 3e-4,
            init_alpha: 1.0,
            learn_alpha: true,
            target_entropy: None,
            log_std_bounds: (-5.0, 2.0),
            grad_norm: None,
            steps_per_iteration: 1000,
            error_penalty: None,
            failure_penalty: None,
        }
    }
}

/// Either learner's configuration, as a RON file names it: `Ppo((...))` or `Sac((...))`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum AlgoConfig {
    /// Proximal policy optimisation.
    Ppo(PpoConfig),
    /// Soft actor-critic.
    Sac(SacConfig),
}

impl AlgoConfig {
    /// `"ppo"` or `"sac"`.
    pub fn algo(&self) -> &'static str {
        match self {
            AlgoConfig::Ppo(_) => "ppo",
            AlgoConfig::Sac(_) => "sac",
        }
    }

    /// The seed of the configuration.
    pub fn seed(&self) -> u64 {
        match self {
            AlgoConfig::Ppo(c) => c.seed,
            AlgoConfig::Sac(c) => c.seed,
        }
    }

    /// The reward of an episode ended by a simulation failure, if such an end is terminal
    /// (see [`PpoConfig::error_penalty`]).
    pub fn error_penalty(&self) -> Option<f32> {
        match self {
            AlgoConfig::Ppo(c) => c.error_penalty,
            AlgoConfig::Sac(c) => c.error_penalty,
        }
    }

    /// The reward added to the step on which the task ends an episode as failed (see
    /// [`PpoConfig::failure_penalty`]).
    pub fn failure_penalty(&self) -> Option<f32> {
        match self {
            AlgoConfig::Ppo(c) => c.failure_penalty,
            AlgoConfig::Sac(c) => c.failure_penalty,
        }
    }

    /// Sets the seed.
    pub fn set_seed(&mut self, seed: u64) {
        match self {
            AlgoConfig::Ppo(c) => c.seed = seed,
            AlgoConfig::Sac(c) => c.seed = seed,
        }
    }

    /// Checks value ranges (RON accepts NaN and infinities).
    pub fn validate(&self) -> Result<(), LearnError> {
        let bad = |what: &str| Err(LearnError::Config(what.to_string()));
        match self {
            AlgoConfig::Ppo(c) => {
                let floats = [
                    c.gamma,
                    c.lambda,
                    c.clip,
                    c.adam_eps,
                    c.critic_coef,
                    c.entropy_coef,
                    c.bounds_loss_coef,
                    c.obs_clip,
                    c.init_log_std,
                    c.error_penalty.unwrap_or(0.0),
                    c.failure_penalty.unwrap_or(0.0),
                ];
                if floats.iter().any(|v| !v.is_finite()) || !c.learning_rate.is_finite() {
                    return bad("ppo: every number must be finite");
                }
                if c.horizon == 0 || c.minibatch_size == 0 || c.mini_epochs == 0 {
                    return bad("ppo: horizon, minibatch_size and mini_epochs must be positive");
                }
                if !(0.0..=1.0).contains(&c.gamma) || !(0.0..=1.0).contains(&c.lambda) {
                    return bad("ppo: gamma and lambda must be in [0, 1]");
                }
                if c.hidden.contains(&0) {
                    return bad("ppo: hidden widths must be positive");
                }
                if c.learning_rate <= 0.0 || c.clip <= 0.0 {
                    return bad("ppo: learning_rate and clip must be positive");
                }
            }
            AlgoConfig::Sac(c) => {
                let floats = [
                    c.gamma,
                    c.tau,
                    c.init_alpha,
                    c.log_std_bounds.0,
                    c.log_std_bounds.1,
                    c.error_penalty.unwrap_or(0.0),
                    c.failure_penalty.unwrap_or(0.0),
                ];
                if floats.iter().any(|v| !v.is_finite())
                    || ![c.actor_lr, c.critic_lr, c.alpha_lr]
                        .iter()
                        .all(|v| v.is_finite() && *v > 0.0)
                {
                    return bad("sac: every number must be finite, learning rates positive");
                }
                if c.batch_size == 0 || c.buffer_size < c.batch_size || c.steps_per_iteration == 0 {
                    return bad("sac: need batch_size > 0, buffer_size >= batch_size, steps_per_iteration > 0");
                }
                if !(0.0..=1.0).contains(&c.tau)
                    || !(0.0..=1.0).contains(&c.gamma)
                    || c.init_alpha <= 0.0
                {
                    return bad("sac: tau and gamma in [0, 1], init_alpha > 0");
                }
                if c.hidden.contains(&0) || c.log_std_bounds.0 >= c.log_std_bounds.1 {
                    return bad("sac: hidden widths positive, log_std_bounds increasing");
                }
            }
        }
        Ok(())
    }

    /// Parses RON text and validates it.
    pub fn from_ron(text: &str) -> Result<Self, LearnError> {
        let c: AlgoConfig = ron::from_str(text).map_err(|e| LearnError::Config(format!("{e}")))?;
        c.validate()?;
        Ok(c)
    }

    /// Reads a RON file.
    pub fn load(path: &Path) -> Result<Self, LearnError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| LearnError::Io(format!("{}: {e}", path.display())))?;
        Self::from_ron(&text).map_err(|e| match e {
            LearnError::Config(m) => LearnError::Config(format!("{}: {m}", path.display())),
            other => other,
        })
    }

    /// Pretty RON text (which [`from_ron`](Self::from_ron) reads back exactly).
    pub fn to_ron(&self) -> String {
        ron::ser::to_string_pretty(self, ron::ser::PrettyConfig::default())
            .expect("configurations serialise")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partial_ron_fills_defaults_and_round_trips() {
        let c = AlgoConfig::from_ron("Ppo((hidden: [64, 64], learning_rate: 1e-3, adaptive_kl: Some((kl_threshold: 0.016))))").unwrap();
        let AlgoConfig::Ppo(p) = &c else { panic!() };
        assert_eq!(p.hidden, vec![64, 64]);
        assert_eq!(p.learning_rate, 1e-3);
        assert_eq!(p.adaptive_kl.as_ref().unwrap().kl_threshold, 0.016);
        assert_eq!(p.adaptive_kl.as_ref().unwrap().factor, 1.5);
        assert_eq!(p.gamma, 0.99);
        assert_eq!(AlgoConfig::from_ron(&c.to_ron()).unwrap(), c);
        let s = AlgoConfig::Sac(SacConfig::default());
        assert_eq!(AlgoConfig::from_ron(&s.to_ron()).unwrap(), s);
    }

    #[test]
    fn rejects_unknown_fields_and_nan() {
        let e = AlgoConfig::from_ron("Ppo((learnig_rate: 1e-3))").unwrap_err();
        assert!(format!("{e}").contains("learnig_rate"), "{e}");
        let e = AlgoConfig::from_ron("Sac((gamma: NaN))").unwrap_err();
        assert!(format!("{e}").contains("finite"), "{e}");
    }
}
