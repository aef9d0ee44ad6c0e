//! The `modesuite bench learn` suite: what the learners cost beside the envs they train on
//! (issue 29's throughput target). On [`LEARN_BENCH_TASK`] with 16 envs, for one thread and for
//! all of `--threads`, in one process:
//!
//! - `vecenv_x16`: the bare [`modesuite_engine::VecEnv`] stepped with actions like an untrained
//!   Gaussian policy's (standard normal, clipped to +-1 and mapped into the bounds as the
//!   learners map theirs, [`rescale`]), timed before and after the
//!   trainings below (the figure is the mean of the two; `before`/`after` in the JSON);
//! - `ppo_x16`: `train --algo ppo` with the task's hyper-parameters (16 iterations of 16 x 32
//!   env steps at scale 1), into a temporary run folder (checkpoints included, as in a run);
//! - `sac_x16`: `train --algo sac` with the task's hyper-parameters but gradient steps from the
//!   first step (`learning_starts=0`) and iterations of 16 vectorised steps.
//!
//! Each training logs its envs' calls ([`crate::learning::EnvCall`]), and a fresh bare
//! `VecEnv` of the same envs and threads then replays them: the same resets and actions, so the
//! same states bit for bit (checked on every step's rewards), stepped without the learner.
//! Steps/s are env steps (all envs together) per second of wall time. Extra JSON keys of the
//! learners: `env_steps`, `wall_s`, `env_s` (stepping and resetting the envs inside the run),
//! `learner_share` (1 - env_s / wall_s), `replay_s` and `replay_steps_per_s` (the replay),
//! `vs_vecenv` (steps/s over the replay's: issue 29's target for PPO, at least 0.7) and
//! `vs_random_vecenv` (over `vecenv_x16`'s: a policy's actions move the robot into contacts that
//! cost the solvers more than random jitter does).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use modesuite_engine::bench::{BenchOptions, BenchRecord};
use modesuite_learn::rng::Rng;
use modesuite_learn::runner::rescale;
use serde_json::json;

use crate::gym::layout::ActLayout;
use crate::learning::{train, EnvCall, TrainRequest};
use crate::make::{make_vec, MakeOptions};

/// The task of the suite (issue 29 states its throughput target on it).
pub const LEARN_BENCH_TASK: &str = "MoDe-Franka-Place-v0";

/// Envs of every case.
const ENVS: usize = 16;

/// Env steps per second of the bare `VecEnv` of `threads` threads over `vec_steps` steps.
fn vecenv_rate(threads: usize, vec_steps: usize) -> Result<f64, String> {
    let mut venv = make_vec(LEARN_BENCH_TASK, &MakeOptions::default(), ENVS, threads)
        .map_err(|e| e.to_string())?;
    venv.reset(Some(0));
    let act = ActLayout::of(&venv.spaces().action)?;
    let (low, high) = (&act.low, &act.high);
    let mut rng = Rng::new(0);
    let mut raw = vec![0.0f32; ENVS * low.len()];
    let t = Instant::now();
    for _ in 0..vec_steps {
        for a in raw.iter_mut() {
            *a = rng.normal() as f32;
        }
        // into the bounds as the learners map their actions
        let actions = rescale(&raw, low, high);
        venv.step(&actions).map_err(|e| e.to_string())?;
    }
    Ok((ENVS * vec_steps) as f64 / t.elapsed().as_secs_f64())
}

/// Seconds a fresh bare `VecEnv` of `threads` threads takes to replay a training's env calls;
/// an error if a step's rewards differ from the training's (the replay must be the same work).
fn replay(calls: &[EnvCall], threads: usize) -> Result<f64, String> {
    let mut venv = make_vec(LEARN_BENCH_TASK, &MakeOptions::default(), ENVS, threads)
        .map_err(|e| e.to_string())?;
    let t = Instant::now();
    for (i, call) in calls.iter().enumerate() {
        match call {
            EnvCall::Reset(seed) => {
                venv.reset(Some(*seed));
            }
            EnvCall::Step {
                actions,
                reward_sum,
            } => {
                let out = venv.step(actions).map_err(|e| e.to_string())?;
                let sum: f64 = out.rewards.iter().sum();
                if sum.to_bits() != reward_sum.to_bits() {
                    return Err(format!(
                        "bench learn: the replay diverged at call {i} (rewards {sum} against {reward_sum})"
                    ));
                }
            }
        }
    }
    Ok(t.elapsed().as_secs_f64())
}

/// A learner's training of `env_steps` in a fresh temporary folder: (steps/s, extra keys).
fn train_rate(
    algo: &str,
    threads: usize,
    env_steps: u64,
    set: &[&str],
) -> Result<(f64, BTreeMap<String, serde_json::Value>), String> {
    let out: PathBuf = std::env::temp_dir().join(format!(
        "modesuite-bench-learn-{}-{algo}-{threads}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&out);
    let req = TrainRequest {
        target: LEARN_BENCH_TASK.into(),
        algo: algo.into(),
        seed: Some(0),
        env_steps: Some(env_steps),
        envs: ENVS,
        threads,
        out: out.clone(),
        config: None,
        set: set.iter().map(|s| s.to_string()).collect(),
        checkpoint_every: 10,
        actions: None,
        command: format!("modesuite bench learn ({algo}, {threads} threads)"),
        log_env_calls: true,
    };
    let outcome = train(&req, |_| {});
    let _ = std::fs::remove_dir_all(&out);
    let outcome = outcome.map_err(|e| format!("bench learn {algo}: {e}"))?;
    let done = outcome.summary.env_steps;
    let calls = outcome
        .env_calls
        .as_deref()
        .ok_or("bench learn: the training logged no env calls")?;
    let replay_s = replay(calls, threads)?;
    let mut extra = BTreeMap::new();
    extra.insert("replay_s".into(), json!(replay_s));
    extra.insert("replay_steps_per_s".into(), json!(done as f64 / replay_s));
    extra.insert("vs_vecenv".into(), json!(replay_s / outcome.wall_seconds));
    extra.insert("task".into(), json!(LEARN_BENCH_TASK));
    extra.insert("env_steps".into(), json!(done));
    extra.insert("wall_s".into(), json!(outcome.wall_seconds));
    extra.insert("env_s".into(), json!(outcome.env_seconds));
    extra.insert(
        "learner_share".into(),
        json!(1.0 - outcome.env_seconds / outcome.wall_seconds),
    );
    Ok((done as f64 / outcome.wall_seconds, extra))
}

/// The suite's cases (see the module docs), for one thread and for all of `opts.threads`.
pub fn learn_cases(opts: &BenchOptions) -> Result<Vec<BenchRecord>, String> {
    let threads = crate::benches::thread_counts(opts)?;
    // PPO: whole iterations of 16 envs x 32 steps (at least one)
    let ppo_iters = ((16.0 * opts.scale) as u64).max(1);
    let ppo_steps = ppo_iters * 32 * ENVS as u64;
    let sac_iters = ((8.0 * opts.scale) as u64).max(1);
    let sac_steps = sac_iters * 16 * ENVS as u64;
    let mut out = Vec::new();
    for t in threads {
        let before = vecenv_rate(t, (ppo_steps / ENVS as u64) as usize)?;
        let (ppo, mut ppo_extra) = train_rate("ppo", t, ppo_steps, &[])?;
        let (sac, mut sac_extra) = train_rate(
            "sac",
            t,
            sac_steps,
            &["learning_starts=0", "steps_per_iteration=16"],
        )?;
        let after = vecenv_rate(t, (ppo_steps / ENVS as u64) as usize)?;
        let bare = 0.5 * (before + after);
        let mut extra = BTreeMap::new();
        extra.insert("task".into(), json!(LEARN_BENCH_TASK));
        extra.insert("before".into(), json!(before));
        extra.insert("after".into(), json!(after));
        out.push(BenchRecord::new("vecenv_x16", bare, t, ENVS, extra));
        ppo_extra.insert("vs_random_vecenv".into(), json!(ppo / bare));
        out.push(BenchRecord::new("ppo_x16", ppo, t, ENVS, ppo_extra));
        sac_extra.insert("vs_random_vecenv".into(), json!(sac / bare));
        out.push(BenchRecord::new("sac_x16", sac, t, ENVS, sac_extra));
    }
    Ok(out)
}
