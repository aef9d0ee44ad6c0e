//! `modesuite soak`: the 16 tasks stepped with random actions for a long time, resident memory
//! sampled, to find leaks and rare failures (docs/reliability.md).

use std::io::Write;
use std::time::{Duration, Instant};

use serde_json::json;

use super::{io, CliError};
use crate::make::env_for_target;
use modesuite_tasks::expert::{make_policy, PolicyKind};

/// Arguments of `soak`.
#[derive(clap::Args, Debug)]
pub struct SoakArgs {
    /// How long to run, minutes.
    #[arg(long, default_value_t = 60.0)]
    pub minutes: f64,
    /// Warm-up, minutes: memory growth is measured from its end.
    #[arg(long, default_value_t = 5.0)]
    pub warmup_minutes: f64,
    /// Seconds between memory samples.
    #[arg(long, default_value_t = 30.0)]
    pub sample_seconds: f64,
    /// Seed of the first episode of each task and of the random actions.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Allowed resident memory growth after the warm-up, MiB (exit 1 beyond it).
    #[arg(long, default_value_t = 32.0)]
    pub max_growth_mib: f64,
}

/// Resident memory of this process, MiB (Linux; 0 where `/proc` is missing).
pub fn resident_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(0.0, |kib| kib / 1024.0)
}

fn positive(flag: &str, v: f64) -> Result<Duration, CliError> {
    if v.is_finite() && v > 0.0 && v < 1e7 {
        Ok(Duration::from_secs_f64(v))
    } else {
        Err(CliError::input(format!("{flag} = {v}: a positive number")))
    }
}

/// Runs `soak`: one JSON line per memory sample and a summary line.
pub(super) fn soak(args: &SoakArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let total = positive("--minutes", args.minutes * 60.0)?;
    let warmup = positive("--warmup-minutes", args.warmup_minutes * 60.0)?;
    let every = positive("--sample-seconds", args.sample_seconds)?;
    if warmup >= total {
        return Err(CliError::input(
            "--warmup-minutes must be shorter than --minutes",
        ));
    }
    let mut envs = Vec::new();
    for id in modesuite_tasks::all_ids() {
        let mut env = env_for_target(&id, None)?;
        let mut policy = make_policy(PolicyKind::Random, &env).map_err(CliError::runtime)?;
        env.reset(Some(args.seed));
        policy.reset(args.seed);
        let action = vec![0.0f32; env.spaces().action.flat_dim()];
        envs.push((id, env, policy, action, 0u64, 0u64));
    }
    let start = Instant::now();
    let mut next_sample = Duration::ZERO;
    let (mut steps, mut episodes, mut errors) = (0u64, 0u64, 0u64);
    let mut after_warmup: Option<f64> = None;
    let mut peak = 0.0f64;
    while start.elapsed() < total {
        // One episode-sized slice per task in turn: 50 steps each.
        for (id, env, policy, action, eps, errs) in envs.iter_mut() {
            for _ in 0..50 {
                policy.act(env, action).map_err(CliError::runtime)?;
                let o = env.step(action);
                steps += 1;
                if o.observation.iter().any(|x| !x.is_finite()) || !o.reward.is_finite() {
                    return Err(CliError::runtime(format!(
                        "{id}: a non-finite observation or reward after {steps} steps"
                    )));
                }
                if o.info.error.is_some() {
                    *errs += 1;
                }
                if o.terminated || o.truncated {
                    *eps += 1;
                    // The env reset itself (same-step autoreset); the policy follows its seed.
                    policy.reset(args.seed.wrapping_add(*eps));
                }
            }
        }
        let t = start.elapsed();
        if t >= next_sample {
            let rss = resident_mib();
            peak = peak.max(rss);
            if after_warmup.is_none() && t >= warmup {
                after_warmup = Some(rss);
            }
            episodes = envs.iter().map(|e| e.4).sum();
            errors = envs.iter().map(|e| e.5).sum();
            let line = json!({"t_s": t.as_secs_f64(), "rss_mib": rss, "steps": steps,
                              "episodes": episodes, "episode_errors": errors});
            writeln!(out, "{line}").map_err(io)?;
            next_sample = t + every;
        }
    }
    let end_rss = resident_mib();
    let base = after_warmup.unwrap_or(end_rss);
    let growth = end_rss - base;
    let hours = (start.elapsed() - warmup.min(start.elapsed())).as_secs_f64() / 3600.0;
    let per_task: Vec<_> = envs
        .iter()
        .map(|e| json!({"task": e.0, "episodes": e.4, "episode_errors": e.5}))
        .collect();
    let summary = json!({"summary": true, "minutes": start.elapsed().as_secs_f64() / 60.0,
        "steps": steps, "episodes": episodes, "episode_errors": errors,
        "rss_after_warmup_mib": base, "rss_end_mib": end_rss, "rss_peak_mib": peak.max(end_rss),
        "growth_mib": growth, "growth_mib_per_hour": if hours > 0.0 { growth / hours } else { 0.0 },
        "max_growth_mib": args.max_growth_mib, "tasks": per_task});
    writeln!(out, "{summary}").map_err(io)?;
    if growth > args.max_growth_mib {
        return Err(CliError::runtime(format!(
            "soak: resident memory grew {growth:.1} MiB after the warm-up (allowed {} MiB)",
            args.max_growth_mib
        )));
    }
    Ok(())
}
