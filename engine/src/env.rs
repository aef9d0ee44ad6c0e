//! Gymnasium-style environments: [`Env`] (one world) and [`VecEnv`] (N worlds stepped in
//! parallel with rayon).
//!
//! Buffers are flat and row-major: observations `n_envs x obs_dim` (f32), actions
//! `n_envs x act_dim` (f32; a `Discrete` action is one f32 holding the integer). Autoreset is
//! **same-step** ([`AutoresetMode::SameStep`], Gymnasium's `SAME_STEP`): when an episode ends,
//! the returned observation is already the first of the next episode, and the last observation
//! and info of the finished one are in `info.final_observation` / `info.final_info`.
//!
//! Determinism: each env has its own world and RNG; the step of one env never reads another, so
//! results are bit-identical for any number of envs and threads.

use std::collections::BTreeMap;

use bevy_ecs::prelude::*;
use rayon::prelude::*;

use crate::app::{SimApp, SimErrors};
use crate::rng::EnvRng;
pub use crate::signals::{ActionBuffer, ObservationBuffer, Space, Spaces, StepSignals};
use crate::state::{state_hash, Snapshot};

/// How finished episodes are reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AutoresetMode {
    /// Reset in the same `step` call; final observation and info in the info (Gymnasium `SAME_STEP`).
    SameStep,
}

/// Per-env information of a step or reset.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EnvInfo {
    /// Task success, when defined.
    pub success: Option<bool>,
    /// Why the episode ended with an error (physics blow-up, non-finite action, plugin failure).
    pub error: Option<String>,
    /// Named diagnostics of the step.
    pub values: BTreeMap<String, f64>,
    /// Set on the step an episode ends: its return and length.
    pub episode: Option<EpisodeStats>,
    /// Same-step autoreset: the last observation of the finished episode.
    pub final_observation: Option<Vec<f32>>,
    /// Same-step autoreset: the info of the finished episode's last step.
    pub final_info: Option<Box<EnvInfo>>,
}

/// Summary of a finished episode.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EpisodeStats {
    /// Sum of rewards.
    pub r#return: f64,
    /// Number of env steps.
    pub length: u64,
    /// Success at the end, when defined.
    pub success: Option<bool>,
    /// Whether it ended with an error.
    pub error: bool,
}

/// The result of one env step.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StepOutcome {
    /// Observation (of the next episode when this one ended).
    pub observation: Vec<f32>,
    /// Reward (0 on a step that ended with an error).
    pub reward: f64,
    /// Terminal state reached.
    pub terminated: bool,
    /// Episode cut short.
    pub truncated: bool,
    /// Info.
    pub info: EnvInfo,
}

/// One environment: an app with a spawned scene and the snapshot it resets to.
pub struct Env {
    /// The app (world and schedules).
    pub app: SimApp,
    initial: Snapshot,
    /// Hash of the spawn state (what state files must match).
    fingerprint: u64,
    pub(crate) episode_return: f64,
    /// Errors that ended episodes since creation.
    pub error_count: u64,
    /// Reset finished episodes inside `step` (same-step autoreset; default true). With false,
    /// the world keeps the final state until the caller calls `reset`.
    pub autoreset: bool,
    /// What failed in the last reset pass; the next step ends the episode with it.
    pub(crate) reset_error: Option<String>,
}

impl Env {
    /// Wraps an app whose scene is spawned; the current state becomes the reset state.
    pub fn new(mut app: SimApp) -> Self {
        app.world.init_resource::<Spaces>();
        let initial = Snapshot::take(&app.world);
        let fingerprint = state_hash(&app.world);
        Self {
            app,
            initial,
            fingerprint,
            episode_return: 0.0,
            error_count: 0,
            autoreset: true,
            reset_error: None,
        }
    }

    /// Bit-exact hash of the state the env was made with (its scene as spawned): state files
    /// of another scene are refused by it.
    pub fn fingerprint(&self) -> u64 {
        self.fingerprint
    }

    /// Observation and action spaces.
    pub fn spaces(&self) -> Spaces {
        self.app.world.resource::<Spaces>().clone()
    }

    /// Starts a new episode; with a seed, the env's RNG is reseeded first.
    pub fn reset(&mut self, seed: Option<u64>) -> (Vec<f32>, EnvInfo) {
        let rng = *self.app.world.resource::<EnvRng>();
        // The env's own snapshot of its own world: restoring it cannot mismatch, but if it
        // ever did, the reset reports it like any failed reset event.
        let restored = self.initial.restore(&mut self.app.world);
        *self.app.world.resource_mut::<EnvRng>() = match seed {
            Some(s) => EnvRng::from_seed(s),
            None => rng,
        };
        self.app.world.resource_mut::<SimErrors>().current.clear();
        if let Err(e) = restored {
            self.app
                .world
                .resource_mut::<SimErrors>()
                .raise(format!("restoring the initial state: {e}"));
        }
        *self.app.world.resource_mut::<StepSignals>() = StepSignals::default();
        self.app.run_reset_pass();
        self.episode_return = 0.0;
        // A reset event that failed (bad randomisation, a plugin error) is reported here; the
        // first step then ends the episode with the same error.
        let errs = &self.app.world.resource::<SimErrors>().current;
        self.reset_error = (!errs.is_empty()).then(|| format!("reset: {}", errs.join("; ")));
        let info = EnvInfo {
            error: self.reset_error.clone(),
            ..EnvInfo::default()
        };
        (self.observation(), info)
    }

    /// What failed in the last reset pass, if anything (also in that reset's info): the next
    /// step ends the episode with it. After a same-step autoreset this is the new episode's
    /// reset error, which [`Env::step`] does not return in its info.
    pub fn pending_reset_error(&self) -> Option<&str> {
        self.reset_error.as_deref()
    }

    /// The current observation buffer.
    pub fn observation(&self) -> Vec<f32> {
        self.app.world.resource::<ObservationBuffer>().0.clone()
    }

    /// One step with same-step autoreset.
    pub fn step(&mut self, action: &[f32]) -> StepOutcome {
        let spaces = self.app.world.resource::<Spaces>().clone();
        *self.app.world.resource_mut::<StepSignals>() = StepSignals::default();
        let mut error = None;
        match spaces.action.check(action) {
            Ok(()) => {
                self.app.world.resource_mut::<ActionBuffer>().0.clear();
                self.app
                    .world
                    .resource_mut::<ActionBuffer>()
                    .0
                    .extend_from_slice(action);
                self.app.step();
                let errs = &self.app.world.resource::<SimErrors>().current;
                if !errs.is_empty() {
                    error = Some(errs.join("; "));
                }
                if let Some(e) = self.reset_error.take() {
                    error = Some(match error {
                        Some(later) => format!("{e}; {later}"),
                        None => e,
                    });
                }
            }
            Err(e) => {
                // Never reaches the solver: the episode ends here.
                self.app
                    .world
                    .resource_mut::<SimErrors>()
                    .raise(format!("action{e}"));
                error = Some(format!("action{e}"));
            }
        }
        let signals = self.app.world.resource::<StepSignals>().clone();
        let mut reward = signals.reward;
        if !reward.is_finite() {
            error.get_or_insert_with(|| format!("reward = {reward}: non-finite"));
        }
        // A step that failed (physics blow-up, bad action, plugin error) measured a state that
        // is not the physics': its reward is 0 (the terms stay in `info.values`).
        if error.is_some() {
            reward = 0.0;
        }
        let terminated = signals.terminated && error.is_none();
        let truncated = signals.truncated || error.is_some();
        self.episode_return += reward;
        let mut info = EnvInfo {
            success: signals.success,
            error: error.clone(),
            values: signals.values,
            ..EnvInfo::default()
        };
        let mut observation = self.observation();
        if error.is_some() {
            self.error_count += 1;
        }
        if terminated || truncated {
            let length = self.app.world.resource::<crate::SimClock>().episode_steps;
            info.episode = Some(EpisodeStats {
                r#return: self.episode_return,
                length,
                success: signals.success,
                error: error.is_some(),
            });
            if !self.autoreset {
                return StepOutcome {
                    observation,
                    reward,
                    terminated,
                    truncated,
                    info,
                };
            }
            let final_info = info.clone();
            let (obs, _) = self.reset(None);
            info = EnvInfo {
                final_observation: Some(std::mem::replace(&mut observation, obs)),
                final_info: Some(Box::new(final_info.clone())),
                ..final_info
            };
        }
        StepOutcome {
            observation,
            reward,
            terminated,
            truncated,
            info,
        }
    }

    /// Bit-exact hash of the env state.
    pub fn state_hash(&self) -> u64 {
        state_hash(&self.app.world)
    }
}

/// The result of a vectorised step, flat and row-major.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VecStep {
    /// Observations, `n_envs x obs_dim`.
    pub observations: Vec<f32>,
    /// Rewards, one per env.
    pub rewards: Vec<f64>,
    /// Terminated flags.
    pub terminated: Vec<bool>,
    /// Truncated flags.
    pub truncated: Vec<bool>,
    /// Infos.
    pub infos: Vec<EnvInfo>,
}

/// Errors of the vectorised env's own API (wrong buffer sizes, thread pool).
#[derive(Debug, thiserror::Error)]
pub enum VecEnvError {
    /// The action buffer has the wrong length.
    #[error(
        "actions: length {got} but {n_envs} envs x {act_dim} action values = {expected} expected"
    )]
    ActionLength {
        /// Given length.
        got: usize,
        /// Expected length.
        expected: usize,
        /// Number of envs.
        n_envs: usize,
        /// Values per env.
        act_dim: usize,
    },
    /// The thread pool could not be created.
    #[error("thread pool: {0}")]
    ThreadPool(String),
    /// Building an env failed.
    #[error("{0}")]
    Build(String),
    /// Envs disagree on their spaces.
    #[error("env {0} has different spaces than env 0")]
    SpaceMismatch(usize),
}

/// N environments stepped in parallel.
pub struct VecEnv {
    envs: Vec<Env>,
    /// Worker threads; `None` for one thread: the envs then step on the calling thread (a
    /// one-thread pool cost 4-6 % per env in hand-offs between threads on fast FEM tasks).
    pool: Option<rayon::ThreadPool>,
    spaces: Spaces,
    /// The autoreset mode (always same-step).
    pub autoreset: AutoresetMode,
}

impl VecEnv {
    /// Wraps envs; `threads = 0` uses all cores.
    pub fn new(envs: Vec<Env>, threads: usize) -> Result<Self, VecEnvError> {
        if envs.is_empty() {
            return Err(VecEnvError::Build("a VecEnv needs at least one env".into()));
        }
        let spaces = envs[0].spaces();
        if let Some(i) = envs.iter().position(|e| e.spaces() != spaces) {
            return Err(VecEnvError::SpaceMismatch(i));
        }
        let pool = if threads == 1 {
            None
        } else {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .map_err(|e| VecEnvError::ThreadPool(e.to_string()))?;
            // `threads = 0` on a one-core machine
            (pool.current_num_threads() > 1).then_some(pool)
        };
        Ok(Self {
            envs,
            pool,
            spaces,
            autoreset: AutoresetMode::SameStep,
        })
    }

    /// Builds `n` envs with `make(i)` (each returns an app with its scene spawned).
    pub fn build<E: std::fmt::Display>(
        n: usize,
        threads: usize,
        make: impl Fn(usize) -> Result<SimApp, E>,
    ) -> Result<Self, VecEnvError> {
        let envs = (0..n)
            .map(|i| {
                make(i)
                    .map(Env::new)
                    .map_err(|e| VecEnvError::Build(e.to_string()))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Self::new(envs, threads)
    }

    /// Number of envs.
    pub fn len(&self) -> usize {
        self.envs.len()
    }

    /// Whether there are no envs (never true for a built VecEnv).
    pub fn is_empty(&self) -> bool {
        self.envs.is_empty()
    }

    /// Threads in the pool.
    pub fn threads(&self) -> usize {
        self.pool
            .as_ref()
            .map_or(1, rayon::ThreadPool::current_num_threads)
    }

    /// `f(i, env)` for every env, in the pool or (one thread) on the calling thread; results in
    /// env order either way.
    fn map_envs<R: Send>(&mut self, f: impl Fn(usize, &mut Env) -> R + Sync + Send) -> Vec<R> {
        let envs = &mut self.envs;
        match &self.pool {
            Some(pool) => pool.install(|| {
                envs.par_iter_mut()
                    .enumerate()
                    .map(|(i, e)| f(i, e))
                    .collect()
            }),
            None => envs.iter_mut().enumerate().map(|(i, e)| f(i, e)).collect(),
        }
    }

    /// The spaces of each env.
    pub fn spaces(&self) -> &Spaces {
        &self.spaces
    }

    /// The envs (read access, e.g. for state dumps).
    pub fn envs(&self) -> &[Env] {
        &self.envs
    }

    /// Mutable access to the envs.
    pub fn envs_mut(&mut self) -> &mut [Env] {
        &mut self.envs
    }

    /// Resets every env; with a seed, env i is seeded with `seed + i`.
    pub fn reset(&mut self, seed: Option<u64>) -> (Vec<f32>, Vec<EnvInfo>) {
        let results = self.map_envs(|i, e| e.reset(seed.map(|s| s.wrapping_add(i as u64))));
        let mut obs = Vec::with_capacity(self.envs.len() * self.spaces.observation.flat_dim());
        let mut infos = Vec::with_capacity(self.envs.len());
        for (o, i) in results {
            obs.extend_from_slice(&o);
            infos.push(i);
        }
        (obs, infos)
    }

    /// Resets the envs whose `mask` entry is true (every env without a mask), env `i` with
    /// `seeds[i]` (`None`: its RNG goes on); `None` in the result for envs left alone.
    ///
    /// # Panics
    /// When `seeds` or `mask` has another length than the number of envs.
    pub fn reset_each(
        &mut self,
        seeds: &[Option<u64>],
        mask: Option<&[bool]>,
    ) -> Vec<Option<(Vec<f32>, EnvInfo)>> {
        let n = self.envs.len();
        assert_eq!(seeds.len(), n, "one seed per env");
        if let Some(m) = mask {
            assert_eq!(m.len(), n, "one mask entry per env");
        }
        self.map_envs(|i, e| mask.is_none_or(|m| m[i]).then(|| e.reset(seeds[i])))
    }

    /// Steps every env with its row of `actions` (`n_envs x act_dim`).
    pub fn step(&mut self, actions: &[f32]) -> Result<VecStep, VecEnvError> {
        let act_dim = self.spaces.action.flat_dim();
        let n = self.envs.len();
        if actions.len() != n * act_dim {
            return Err(VecEnvError::ActionLength {
                got: actions.len(),
                expected: n * act_dim,
                n_envs: n,
                act_dim,
            });
        }
        let outcomes = self.map_envs(|i, e| e.step(&actions[i * act_dim..(i + 1) * act_dim]));
        let mut out = VecStep {
            observations: Vec::with_capacity(n * self.spaces.observation.flat_dim()),
            rewards: Vec::with_capacity(n),
            terminated: Vec::with_capacity(n),
            truncated: Vec::with_capacity(n),
            infos: Vec::with_capacity(n),
        };
        for o in outcomes {
            out.observations.extend_from_slice(&o.observation);
            out.rewards.push(o.reward);
            out.terminated.push(o.terminated);
            out.truncated.push(o.truncated);
            out.infos.push(o.info);
        }
        Ok(out)
    }

    /// Bit-exact state hash of each env.
    pub fn state_hashes(&self) -> Vec<u64> {
        self.envs.iter().map(Env::state_hash).collect()
    }
}
