//! Reinforcement learning on the simulator: the bridge from [`VecEnv`] to the learners of
//! `modesuite-learn` ([`SimEnv`]), the `train` command, and learned policies as a
//! [`modesuite_tasks::expert::Policy`] for `run --policy DIR` and `eval`.
//!
//! A run folder (`train --out DIR`) holds `config.ron`, `metrics.jsonl`, `checkpoint.bin` and
//! `policy/` (`policy.json` + `weights.bpk`); the policy's note records the target, the action
//! modes and the command, so `eval DIR` needs nothing else. Hyper-parameters: the learner's
//! defaults, then `scenes/<task>/<algo>.ron` next to the task's scenes, then `--config FILE`,
//! then each `--set key=value`, then `--seed`.

use crate::inputs::Observer;
use modesuite_learn::policy::ChunkPlayer;
use std::path::{Path, PathBuf};

use modesuite_engine::codec::{Decoder, Encoder};
use modesuite_engine::prelude::*;
use modesuite_learn::{
    AlgoConfig, BatchStep, Control, LearnError, Metrics, PpoConfig, RunOptions, SacConfig,
    VecEnvironment,
};
use serde_json::json;

use crate::gym::layout::{ActLayout, ObsLayout};
use crate::make::{self, MakeError, MakeOptions};

/// Seed of the first evaluation episode when `eval` is not given one: far from the seeds
/// training resets with (the training seed plus the env index).
pub const EVAL_SEED: u64 = 1_000_000;

/// First bytes of [`SimEnv`]'s saved environments (inside a learner's checkpoint).
const SIM_ENV_STATE: &[u8] = b"modesuite-simenv-1\n";

/// A call a [`SimEnv`] passed on to its [`VecEnv`], logged when asked
/// ([`TrainRequest::log_env_calls`]): `bench learn` replays a training's env work without the
/// learner.
#[derive(Clone, Debug, PartialEq)]
pub enum EnvCall {
    /// `VecEnv::reset(Some(seed))`.
    Reset(u64),
    /// `VecEnv::step(actions)`, with the sum of the rewards it returned (to check a replay).
    Step {
        /// The actions of every env, row-major.
        actions: Vec<f32>,
        /// The sum of the step's rewards (f64, in env order).
        reward_sum: f64,
    },
}

/// A [`VecEnv`] of state observations and continuous actions, as the learners see it.
///
/// An episode that ends in an error (a physics blow-up, a non-finite action) is cut short by
/// the simulator, not by the task. By default the learner sees it truncated, with the last
/// observation before the failing step as its final observation, so the return goes on from
/// that state's value. Counted as terminal without a penalty, a blow-up ended the per-step
/// penalties of the tasks' distance rewards, and PPO on Franka Drag learned to blow the belt up
/// (19 of 20 evaluation episodes ended in errors after 25,600 steps). With an error penalty
/// ([`SimEnv::with_error_penalty`], the learners' `error_penalty`) it is terminal with that
/// reward: a failure then costs more than going on, and policies learn to avoid it.
pub struct SimEnv {
    vec: VecEnv,
    identity: String,
    obs_dim: usize,
    act: ActLayout,
    /// Each env's observation before the current step (for episodes that end in errors).
    last_obs: Vec<f32>,
    /// Seconds spent stepping and resetting the envs (the rest of a run is the learner's).
    pub env_seconds: f64,
    /// Reward of a terminal failure; `None`: failures truncate.
    error_penalty: Option<f32>,
    /// Reward added to the step on which the task ends an episode as failed.
    failure_penalty: Option<f32>,
    /// The calls passed on to the envs, when logged.
    log: Option<Vec<EnvCall>>,
}

impl SimEnv {
    /// Wraps `vec`, made from `target` with `actions` (both recorded in the identity that
    /// checkpoints check). Images and discrete actions are refused.
    pub fn new(vec: VecEnv, target: &str, actions: Option<&str>) -> Result<Self, String> {
        let spaces = vec.spaces().clone();
        let obs = ObsLayout::of(&spaces.observation)?;
        let ObsLayout::Flat { dim: obs_dim } = obs else {
            return Err(format!(
                "{target}: the learners take state observations only (this one is a Dict with images)"
            ));
        };
        let act = ActLayout::of(&spaces.action)?;
        if act.discrete.is_some() {
            return Err(format!(
                "{target}: the learners take continuous actions (this env's are Discrete)"
            ));
        }
        let name = Path::new(target)
            .file_name()
            .map_or(target.to_string(), |f| f.to_string_lossy().into_owned());
        let identity = format!(
            "{name} actions {} obs {obs_dim} act {}",
            actions.unwrap_or("(scene)"),
            act.dim
        );
        Ok(Self {
            vec,
            identity,
            obs_dim,
            act,
            last_obs: Vec::new(),
            env_seconds: 0.0,
            error_penalty: None,
            failure_penalty: None,
            log: None,
        })
    }

    /// Logs every reset and step passed on to the envs ([`SimEnv::take_log`]).
    pub fn with_log(mut self) -> Self {
        self.log = Some(Vec::new());
        self
    }

    /// The calls logged so far (`None` when not logging).
    pub fn take_log(&mut self) -> Option<Vec<EnvCall>> {
        self.log.take()
    }

    /// Ends episodes that fail (a physics blow-up) as terminal states with reward `penalty`
    /// instead of truncating them; `None` truncates (see [`SimEnv`]).
    pub fn with_error_penalty(mut self, penalty: Option<f32>) -> Self {
        self.error_penalty = penalty;
        self
    }

    /// Adds `penalty` to the reward of the step on which the task ends an episode as failed
    /// (terminated by a termination term, not by success or an error); `None` adds nothing.
    pub fn with_failure_penalty(mut self, penalty: Option<f32>) -> Self {
        self.failure_penalty = penalty;
        self
    }
}

impl VecEnvironment for SimEnv {
    fn num_envs(&self) -> usize {
        self.vec.len()
    }

    fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    fn act_dim(&self) -> usize {
        self.act.dim
    }

    fn action_bounds(&self) -> (Vec<f32>, Vec<f32>) {
        (self.act.low.clone(), self.act.high.clone())
    }

    fn identity(&self) -> String {
        self.identity.clone()
    }

    /// Every env's state file ([`Env::save_state`]) and the observations before the current
    /// step, so that a checkpoint continues the episodes under way instead of resetting every
    /// env (which cut PPO's training episodes at 320 steps: 10 iterations of 32 steps per env
    /// between checkpoints). `None` when some env cannot save its state (the learners then
    /// reset the envs at each checkpoint, in resumed and uninterrupted runs alike).
    fn save_state(&self) -> Option<Vec<u8>> {
        let mut e = Encoder::after(SIM_ENV_STATE.to_vec());
        e.put(&(self.vec.len() as u64));
        for env in self.vec.envs() {
            e.put(&env.save_state().ok()?);
        }
        e.put(&self.last_obs);
        e.into_bytes().ok()
    }

    fn load_state(&mut self, state: &[u8]) -> Result<(), String> {
        let Some(body) = state.strip_prefix(SIM_ENV_STATE) else {
            return Err("the saved environments are not a modesuite SimEnv state".into());
        };
        let mut d = Decoder::new(body, "saved environments");
        d.take_len("envs", self.vec.len())
            .map_err(|e| e.to_string())?;
        let files = (0..self.vec.len())
            .map(|_| d.take::<Vec<u8>>())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| e.to_string())?;
        let last_obs: Vec<f32> = d.take().map_err(|e| e.to_string())?;
        d.finish().map_err(|e| e.to_string())?;
        for (i, (env, bytes)) in self.vec.envs_mut().iter_mut().zip(files).enumerate() {
            env.load_state(&bytes)
                .map_err(|e| format!("saved env {i}: {e}"))?;
        }
        self.last_obs = last_obs;
        Ok(())
    }

    fn reset(&mut self, seed: u64) -> Result<Vec<f32>, String> {
        let t = std::time::Instant::now();
        let obs = self.vec.reset(Some(seed)).0;
        self.env_seconds += t.elapsed().as_secs_f64();
        if let Some(log) = &mut self.log {
            log.push(EnvCall::Reset(seed));
        }
        self.last_obs.clone_from(&obs);
        Ok(obs)
    }

    fn step(&mut self, actions: &[f32]) -> Result<BatchStep, String> {
        let t = std::time::Instant::now();
        let out = self.vec.step(actions).map_err(|e| e.to_string())?;
        self.env_seconds += t.elapsed().as_secs_f64();
        if let Some(log) = &mut self.log {
            log.push(EnvCall::Step {
                actions: actions.to_vec(),
                reward_sum: out.rewards.iter().sum(),
            });
        }
        let n = out.rewards.len();
        let mut step = BatchStep {
            obs: out.observations,
            rewards: out.rewards.iter().map(|r| *r as f32).collect(),
            terminated: out.terminated,
            truncated: out.truncated,
            final_obs: Vec::with_capacity(n),
            success: Vec::with_capacity(n),
        };
        let dim = self.obs_dim;
        for (i, info) in out.infos.into_iter().enumerate() {
            // an episode ended by an error failed, where the task defines success
            let success = info.episode.and_then(|e| e.success.map(|s| s && !e.error));
            step.success.push(success);
            if info.error.is_some() {
                match self.error_penalty {
                    Some(penalty) => {
                        step.terminated[i] = true;
                        step.truncated[i] = false;
                        step.rewards[i] = penalty;
                    }
                    None => {
                        step.terminated[i] = false;
                        step.truncated[i] = true;
                    }
                }
                let before = self.last_obs.get(i * dim..(i + 1) * dim);
                step.final_obs.push(before.map(<[f32]>::to_vec));
                continue;
            }
            if let (Some(penalty), true, Some(false)) =
                (self.failure_penalty, step.terminated[i], success)
            {
                step.rewards[i] += penalty;
            }
            step.final_obs.push(info.final_observation.map(|mut o| {
                for v in o.iter_mut().filter(|v| !v.is_finite()) {
                    *v = 0.0;
                }
                o
            }));
        }
        // a blown-up episode's next first observation is finite (the reset restored it); the
        // step's other observations come from live worlds
        for v in step.obs.iter_mut().filter(|v| !v.is_finite()) {
            *v = 0.0;
        }
        self.last_obs.clone_from(&step.obs);
        Ok(step)
    }
}

/// What `train` was asked.
#[derive(Debug, Clone)]
pub struct TrainRequest {
    /// Task id or scene file with a task section.
    pub target: String,
    /// `ppo` or `sac`.
    pub algo: String,
    /// Seed of the learner and of the env resets.
    pub seed: Option<u64>,
    /// Env steps (all envs together) to train for.
    pub env_steps: Option<u64>,
    /// Envs stepped together.
    pub envs: usize,
    /// Threads stepping the envs (0: all cores).
    pub threads: usize,
    /// The run folder.
    pub out: PathBuf,
    /// A RON file of hyper-parameters (`Ppo((...))` or `Sac((...))`).
    pub config: Option<PathBuf>,
    /// `key=value` overrides of single hyper-parameters (values in JSON, else strings).
    pub set: Vec<String>,
    /// Checkpoint every this many iterations.
    pub checkpoint_every: u64,
    /// Action modes replacing the scene's (RON).
    pub actions: Option<String>,
    /// The command line, recorded with the policy.
    pub command: String,
    /// Log the envs' calls into [`TrainOutcome::env_calls`] (`bench learn`).
    pub log_env_calls: bool,
}

/// Default env steps of a run when neither the command nor the task's file gives them.
pub fn default_env_steps(algo: &str) -> u64 {
    if algo == "sac" {
        1_000_000
    } else {
        5_000_000
    }
}

/// The task folder of a task id (`scenes/place` for `MoDe-Franka-Place-v0`), if it is one.
fn task_folder(target: &str) -> Option<PathBuf> {
    let (_, task) = modesuite_tasks::parse_id(target).ok()?;
    Some(make::scenes_dir().join(task.to_lowercase()))
}

/// The hyper-parameters of a request: defaults, the task's `<algo>.ron`, `--config`, `--set`,
/// `--seed`. Returns them and the files read.
pub fn resolve_config(req: &TrainRequest) -> Result<(AlgoConfig, Vec<PathBuf>), String> {
    let mut cfg = match req.algo.as_str() {
        "ppo" => AlgoConfig::Ppo(PpoConfig::default()),
        "sac" => AlgoConfig::Sac(SacConfig::default()),
        other => return Err(format!("--algo {other}: ppo or sac")),
    };
    let mut files = Vec::new();
    let task_file = task_folder(&req.target).map(|d| d.join(format!("{}.ron", req.algo)));
    for path in task_file
        .into_iter()
        .filter(|p| p.is_file())
        .chain(req.config.clone())
    {
        cfg = AlgoConfig::load(&path).map_err(|e| e.to_string())?;
        if cfg.algo() != req.algo {
            return Err(format!(
                "{}: a {} configuration, but --algo {}",
                path.display(),
                cfg.algo(),
                req.algo
            ));
        }
        files.push(path);
    }
    for kv in &req.set {
        cfg = set_field(&cfg, kv)?;
    }
    if let Some(s) = req.seed {
        cfg.set_seed(s);
    }
    cfg.validate().map_err(|e| e.to_string())?;
    Ok((cfg, files))
}

/// `cfg` with one field replaced: `key=value`, the value read as JSON (`3e-4`, `[128, 128]`,
/// `null`, `true`) or else as a string.
pub fn set_field(cfg: &AlgoConfig, kv: &str) -> Result<AlgoConfig, String> {
    let bad = |m: &str| format!("--set {kv}: {m}");
    let mut v = serde_json::to_value(cfg).map_err(|e| bad(&e.to_string()))?;
    let fields = v
        .as_object_mut()
        .and_then(|o| o.values_mut().next())
        .and_then(|inner| inner.as_object_mut())
        .ok_or_else(|| bad("unreadable configuration"))?;
    set_json_field(fields, kv)?;
    serde_json::from_value(v).map_err(|e| bad(&e.to_string()))
}

/// Replaces one existing field of a serialised configuration: `key=value`, the value read as
/// JSON or else as a string; an unknown key is an error listing the valid ones.
pub fn set_json_field(
    fields: &mut serde_json::Map<String, serde_json::Value>,
    kv: &str,
) -> Result<(), String> {
    let bad = |m: &str| format!("--set {kv}: {m}");
    let (key, value) = kv
        .split_once('=')
        .ok_or_else(|| bad("key=value, e.g. learning_rate=3e-4"))?;
    if !fields.contains_key(key.trim()) {
        let mut names: Vec<&str> = fields.keys().map(String::as_str).collect();
        names.sort();
        return Err(bad(&format!(
            "no such hyper-parameter; valid: {}",
            names.join(", ")
        )));
    }
    let parsed = serde_json::from_str(value.trim())
        .unwrap_or_else(|_| serde_json::Value::String(value.trim().to_string()));
    fields.insert(key.trim().to_string(), parsed);
    Ok(())
}

/// How a `train` call went: the learner's summary and where this call's time went.
#[derive(Debug, Clone)]
pub struct TrainOutcome {
    /// The learner's summary.
    pub summary: modesuite_learn::RunSummary,
    /// Wall-clock seconds of this call's training (after the envs were made).
    pub wall_seconds: f64,
    /// Of which stepping and resetting the envs.
    pub env_seconds: f64,
    /// The envs' calls, when [`TrainRequest::log_env_calls`] asked for them.
    pub env_calls: Option<Vec<EnvCall>>,
}

/// Trains (or resumes) a run; `progress` receives each iteration's metrics. Errors are
/// [`MakeError::Input`] for what the user can fix in the request (configuration, another run's
/// folder) and [`MakeError::Runtime`] for failures while running (a full disk, a diverged
/// loss, an env breaking its contract).
pub fn train(
    req: &TrainRequest,
    mut progress: impl FnMut(&Metrics),
) -> Result<TrainOutcome, MakeError> {
    let (cfg, _) = resolve_config(req).map_err(MakeError::Input)?;
    let opts = MakeOptions {
        actions: req.actions.clone(),
        ..MakeOptions::default()
    };
    let vec = make::make_vec(&req.target, &opts, req.envs.max(1), req.threads)?;
    let mut env = SimEnv::new(vec, &req.target, req.actions.as_deref())
        .map_err(MakeError::Input)?
        .with_error_penalty(cfg.error_penalty())
        .with_failure_penalty(cfg.failure_penalty());
    if req.log_env_calls {
        env = env.with_log();
    }
    let note = json!({"target": req.target, "actions": req.actions, "algo": req.algo,
                      "envs": req.envs, "command": req.command})
    .to_string();
    let run = RunOptions {
        dir: req.out.clone(),
        total_env_steps: req
            .env_steps
            .unwrap_or_else(|| default_env_steps(&req.algo)),
        checkpoint_every: req.checkpoint_every,
        resume: true,
        note,
    };
    let mut observer = |m: &Metrics| {
        progress(m);
        Control::Continue
    };
    let start = std::time::Instant::now();
    let summary =
        modesuite_learn::train(&cfg, &mut env, &run, &mut observer).map_err(|e| match e {
            LearnError::Incompatible(m) => MakeError::Input(format!(
                "{}: holds another run ({m}); choose another --out or the same settings",
                req.out.display()
            )),
            e @ (LearnError::Config(_) | LearnError::Checkpoint(_) | LearnError::Weights(_)) => {
                MakeError::Input(e.to_string())
            }
            e @ (LearnError::Io(_) | LearnError::Env(_) | LearnError::Diverged(_)) => {
                MakeError::Runtime(e.to_string())
            }
        })?;
    Ok(TrainOutcome {
        summary,
        wall_seconds: start.elapsed().as_secs_f64(),
        env_seconds: env.env_seconds,
        env_calls: env.take_log(),
    })
}

/// What a policy folder says about how it was trained (its note).
#[derive(Debug, Clone)]
pub struct PolicyOrigin {
    /// Task id or scene file.
    pub target: String,
    /// Action modes it was trained with.
    pub actions: Option<String>,
    /// What it observes (the state alone unless the note says otherwise).
    pub inputs: crate::inputs::InputSpec,
}

/// The `policy/` folder of a run folder, or the folder itself when it holds `policy.json`.
pub fn policy_dir(dir: &Path) -> Option<PathBuf> {
    [dir.join("policy"), dir.to_path_buf()]
        .into_iter()
        .find(|d| d.join("policy.json").is_file())
}

/// Loads a learned policy and where it came from.
pub fn load_policy(dir: &Path) -> Result<(modesuite_learn::Policy, PolicyOrigin), String> {
    let pdir = policy_dir(dir).ok_or_else(|| {
        format!(
            "{}: not a policy folder (no policy.json in it or in its policy/)",
            dir.display()
        )
    })?;
    let policy = modesuite_learn::Policy::load(&pdir).map_err(|e| e.to_string())?;
    let origin = origin_of(&pdir, &serde_json::json!({ "note": policy.meta().note }))?;
    Ok((policy, origin))
}

/// A policy folder's `policy.json` (in it or in its `policy/`): the folder and the parsed file.
fn policy_json(dir: &Path) -> Result<(PathBuf, serde_json::Value), String> {
    let pdir = policy_dir(dir).ok_or_else(|| {
        format!(
            "{}: not a policy folder (no policy.json in it or in its policy/)",
            dir.display()
        )
    })?;
    let path = pdir.join("policy.json");
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let meta = serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok((pdir, meta))
}

/// Where a policy came from, from its `policy.json`'s note.
fn origin_of(pdir: &Path, meta: &serde_json::Value) -> Result<PolicyOrigin, String> {
    let note: serde_json::Value = meta["note"]
        .as_str()
        .and_then(|n| serde_json::from_str(n).ok())
        .unwrap_or_default();
    let target = note["target"]
        .as_str()
        .ok_or_else(|| format!("{}: the policy does not record its target", pdir.display()))?
        .to_string();
    let actions = note["actions"].as_str().map(str::to_string);
    let inputs = match note.get("inputs") {
        Some(v) => serde_json::from_value(v.clone())
            .map_err(|e| format!("{}: the note's inputs: {e}", pdir.display()))?,
        None => crate::inputs::InputSpec::default(),
    };
    Ok(PolicyOrigin {
        target,
        actions,
        inputs,
    })
}

/// Where a policy folder's policy came from (its `policy.json` note), without loading it.
pub fn policy_origin(dir: &Path) -> Result<PolicyOrigin, String> {
    let (pdir, meta) = policy_json(dir)?;
    origin_of(&pdir, &meta)
}

/// Any policy folder as a policy acting in one env: a trained network (PPO, SAC, BC) or a
/// retrieval policy (`algo: "retrieval"`, [`crate::retrieval`]), observing what its note's
/// inputs say ([`crate::inputs`]).
pub fn load_run_policy(
    dir: &Path,
) -> Result<(Box<dyn modesuite_tasks::expert::Policy>, PolicyOrigin), String> {
    let (pdir, meta) = policy_json(dir)?;
    let origin = origin_of(&pdir, &meta)?;
    let inputs = Observer::new(origin.inputs.clone())?;
    if meta["algo"] == "retrieval" {
        let r = crate::retrieval::Retrieval::load(&pdir)?;
        return Ok((
            Box::new(crate::retrieval::RetrievalPolicy::new(r, inputs)),
            origin,
        ));
    }
    let policy = modesuite_learn::Policy::load(&pdir).map_err(|e| e.to_string())?;
    Ok((Box::new(LearnedPolicy::new(policy, inputs)), origin))
}

/// A learned policy acting in one env (`run --policy DIR`, `eval`). A policy of action chunks
/// plays them as its `policy.json` says: each to its end before it observes again, or
/// ensembled at every step ([`modesuite_learn::policy::ChunkPlayer`]).
pub struct LearnedPolicy {
    /// The network.
    pub policy: modesuite_learn::Policy,
    /// What it observes.
    pub inputs: Observer,
    /// The chunk actions still to play.
    player: ChunkPlayer,
}

impl LearnedPolicy {
    /// `policy` observing `inputs`.
    pub fn new(policy: modesuite_learn::Policy, inputs: Observer) -> Self {
        let m = policy.meta();
        let player = ChunkPlayer::new(m.act_dim, m.chunk, m.ensemble);
        Self {
            policy,
            inputs,
            player,
        }
    }
}

/// Acts in `env` with `f`, a function of the input vector ([`Observer`]) of a policy that takes
/// `obs_dim` values and gives `act_dim`; a mismatched env is an error naming both sizes.
pub fn act_on_inputs(
    inputs: &mut Observer,
    env: &Env,
    action: &mut [f32],
    obs_dim: usize,
    act_dim: usize,
    f: impl FnOnce(&[f32]) -> Vec<f32>,
) -> Result<(), String> {
    let obs = inputs.observe(env)?;
    if obs.len() != obs_dim || action.len() != act_dim {
        return Err(format!(
            "the policy takes {obs_dim} input values ({}) and gives {act_dim} action values; this env gives {} and takes {}",
            inputs.spec().describe(),
            obs.len(),
            action.len()
        ));
    }
    action.copy_from_slice(&f(&obs));
    Ok(())
}

impl modesuite_tasks::expert::Policy for LearnedPolicy {
    fn reset(&mut self, _seed: u64) {
        self.player.reset();
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) -> Result<(), String> {
        let p = &self.policy;
        let ad = p.act_dim();
        if !self.player.needs_chunk() {
            self.player.play(None, action);
            return Ok(());
        }
        let player = &mut self.player;
        act_on_inputs(&mut self.inputs, env, action, p.obs_dim(), ad, |o| {
            let mut a = vec![0.0; ad];
            player.play(Some(&p.act_chunk(o)), &mut a);
            a
        })
    }
}
