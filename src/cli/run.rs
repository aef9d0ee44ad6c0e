//! `modesuite run` (and `eval`, which runs a trained policy through it): episodes of a policy
//! on a target, one after another in one env, or side by side in one env per thread
//! (`--threads`). Each episode resets its env with its own seed (the run's seed plus its index)
//! and its policy with the same seed, so its steps do not depend on which env or thread runs
//! it, nor on the episodes before it: the per-episode lines and the summary are the same for
//! any number of threads, except the wall times.

use std::io::{IsTerminal, Write};
use std::time::Instant;

use serde_json::json;

use modesuite_engine::checkpoint::StateError;
use modesuite_engine::prelude::*;
use modesuite_render::RenderConfig;

use super::record::Recorder;
use super::{dump_final, io, load_plugins, make_run_policy, CliError, RunArgs};
use crate::episode::{final_success, EpisodeEnd};
use crate::make::{self, MakeOptions};

/// `modesuite run`.
pub(super) fn run(args: &RunArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let opts = MakeOptions {
        actions: args.actions.clone(),
        rgbd: args.rgbd.clone(),
        plugins: load_plugins(&args.plugin)?,
        episode_steps: None,
    };
    let threads = match args.threads {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        t => t,
    };
    // what must happen in one env, in order: recording, the final state, a loaded start
    let sequential = args.video.is_some()
        || args.frames.is_some()
        || args.dump_state.is_some()
        || args.save_state.is_some()
        || args.load_state.is_some();
    let workers = if sequential {
        1
    } else {
        threads.min(args.episodes.max(1) as usize).max(1)
    };
    let made = make::make_envs(&args.target, &opts, workers)?;
    run_scene(made, args, out)
}

/// A one-line progress bar on stderr when it is a terminal.
struct Progress {
    total: u64,
    enabled: bool,
    last_pct: u64,
}

impl Progress {
    fn new(total: u64) -> Self {
        Self {
            total,
            enabled: total >= 2000 && std::io::stderr().is_terminal(),
            last_pct: u64::MAX,
        }
    }
    fn update(&mut self, done: u64) {
        if !self.enabled {
            return;
        }
        let pct = done * 100 / self.total.max(1);
        if pct != self.last_pct {
            self.last_pct = pct;
            let filled = (pct / 4) as usize;
            eprint!(
                "\r[{}{}] {pct:3}% ({done}/{})",
                "#".repeat(filled),
                " ".repeat(25 - filled),
                self.total
            );
        }
    }
    fn finish(&self) {
        if self.enabled {
            eprintln!();
        }
    }
}

/// One finished episode of a run.
struct Episode {
    index: u64,
    seed: u64,
    ret: f64,
    length: u64,
    success: Option<bool>,
    error: Option<String>,
    end: EpisodeEnd,
    wall: f64,
}

/// Runs episode `index` (seed `seed`) of at most `steps` steps in `env`, already reset (or
/// loaded) for it; `step_done` is called after every step with the step count.
fn run_episode(
    env: &mut Env,
    policy: &mut dyn modesuite_tasks::expert::Policy,
    index: u64,
    seed: u64,
    steps: u64,
    recorder: &mut Option<Recorder>,
    mut step_done: impl FnMut(u64),
) -> Result<Episode, CliError> {
    let mut action = vec![0.0f32; env.spaces().action.flat_dim()];
    policy.reset(seed);
    if let Some(r) = recorder.as_mut() {
        r.capture(&env.app.world, 0, || {
            format!("episode {index}  seed {seed}  step 0")
        })?;
    }
    let t = Instant::now();
    let mut ret = 0.0;
    let mut length = 0;
    let mut success = None;
    let mut error = None;
    // the run's --steps ends it unless the episode ends first
    let mut end = EpisodeEnd::Steps;
    for i in 0..steps {
        if let Err(e) = policy.act(env, &mut action) {
            error = Some(format!("policy: {e}"));
            end = EpisodeEnd::Error;
            break;
        }
        let o = env.step(&action);
        ret += o.reward;
        length = i + 1;
        if let Some(r) = recorder.as_mut() {
            r.capture(&env.app.world, length, || {
                format!(
                    "episode {index}  step {length}  reward {:.3}  return {ret:.3}  success {}",
                    o.reward,
                    o.info.success.map_or("-".to_string(), |s| s.to_string())
                )
            })?;
        }
        step_done(i + 1);
        if o.terminated || o.truncated {
            success = final_success(success, o.info.success, o.info.error.is_some());
            error = o.info.error.clone();
            end = EpisodeEnd::of(&o);
            break;
        }
        success = o.info.success;
    }
    Ok(Episode {
        index,
        seed,
        ret,
        length,
        success,
        error,
        end,
        wall: t.elapsed().as_secs_f64(),
    })
}

fn run_scene(made: make::Made, args: &RunArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let make::Made { mut envs, model } = made;
    let steps = args.steps.or(model.episode_steps).unwrap_or(600);
    if steps == 0 {
        return Err(CliError::input("--steps = 0: must be at least 1"));
    }
    if args.episodes == 0 {
        return Err(CliError::input("--episodes = 0: must be at least 1"));
    }
    RenderConfig::from_scene(&model)?;
    if envs.is_empty() {
        return Err(CliError::runtime("no env was made"));
    }
    // The CLI resets between episodes itself, so the final state stays for --dump-state.
    let mut policies = Vec::with_capacity(envs.len());
    for env in &mut envs {
        env.autoreset = false;
        policies.push(make_run_policy(&args.policy, env)?);
    }
    if !args.json {
        writeln!(
            out,
            "{:>7} {:>12} {:>8} {:>7} {:>9} {:>12}  end",
            "episode", "return", "success", "steps", "time_s", "steps/s"
        )
        .map_err(io)?;
    }
    let mut summary = Summary::default();
    if envs.len() == 1 {
        let (env, policy) = (&mut envs[0], &mut policies[0]);
        let mut recorder = Recorder::new(&model, args)?;
        let mut progress = Progress::new(steps * args.episodes);
        for ep in 0..args.episodes {
            let seed = args.seed.wrapping_add(ep);
            match (&args.load_state, ep) {
                (Some(path), 0) => env.load_state_file(path).map_err(|e| {
                    CliError::input(match e {
                        // names the file already
                        StateError::Io { .. } => format!("--load-state {e}"),
                        _ => format!("--load-state {}: {e}", path.display()),
                    })
                })?,
                _ => {
                    env.reset(Some(seed));
                }
            }
            let e = run_episode(env, policy.as_mut(), ep, seed, steps, &mut recorder, |i| {
                progress.update(ep * steps + i)
            })?;
            // The last dumped state is the state after the final step (before any autoreset).
            if ep + 1 == args.episodes {
                if let Some(path) = &args.dump_state {
                    dump_final(env, &args.target, seed, e.length, path)?;
                }
                if let Some(path) = &args.save_state {
                    env.save_state_file(path)
                        .map_err(|e| CliError::runtime(format!("--save-state {e}")))?;
                }
            }
            summary.print(&e, args.json, out)?;
        }
        progress.finish();
        if let Some(r) = recorder {
            r.finish(out, args.json)?;
        }
    } else {
        for e in run_side_by_side(&mut envs, &mut policies, args, steps)? {
            summary.print(&e, args.json, out)?;
        }
    }
    summary.finish(args, out)
}

/// Runs the episodes in one env per thread, episode i in env i mod the number of envs, and
/// returns them in episode order.
fn run_side_by_side(
    envs: &mut [Env],
    policies: &mut [Box<dyn modesuite_tasks::expert::Policy>],
    args: &RunArgs,
    steps: u64,
) -> Result<Vec<Episode>, CliError> {
    let k = envs.len() as u64;
    let results: Vec<Result<Vec<Episode>, CliError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = envs
            .iter_mut()
            .zip(policies.iter_mut())
            .enumerate()
            .map(|(w, (env, policy))| {
                scope.spawn(move || {
                    let mut done = Vec::new();
                    let mut ep = w as u64;
                    while ep < args.episodes {
                        let seed = args.seed.wrapping_add(ep);
                        env.reset(Some(seed));
                        done.push(run_episode(
                            env,
                            policy.as_mut(),
                            ep,
                            seed,
                            steps,
                            &mut None,
                            |_| {},
                        )?);
                        ep += k;
                    }
                    Ok(done)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err(CliError::runtime("an episode's thread panicked")))
            })
            .collect()
    });
    let mut all = Vec::with_capacity(args.episodes as usize);
    for r in results {
        all.extend(r?);
    }
    all.sort_by_key(|e| e.index);
    Ok(all)
}

/// What the summary line counts, episode by episode.
#[derive(Default)]
struct Summary {
    total_steps: u64,
    total_time: f64,
    returns: Vec<f64>,
    lengths: Vec<u64>,
    successes: Vec<bool>,
    errors: u64,
    /// episodes per way of ending (`ended` of the JSON summary)
    ends: std::collections::BTreeMap<&'static str, u64>,
}

impl Summary {
    /// Counts episode `e` and prints its line.
    fn print(&mut self, e: &Episode, json: bool, out: &mut dyn Write) -> Result<(), CliError> {
        self.total_steps += e.length;
        self.total_time += e.wall;
        self.returns.push(e.ret);
        self.lengths.push(e.length);
        if let Some(s) = e.success {
            self.successes.push(s);
        }
        if e.error.is_some() {
            self.errors += 1;
        }
        *self.ends.entry(e.end.name()).or_default() += 1;
        let sps = e.length as f64 / e.wall.max(1e-12);
        if json {
            writeln!(
                out,
                "{}",
                json!({"episode": e.index, "seed": e.seed, "return": e.ret, "length": e.length,
                       "success": e.success, "error": e.error, "ended": e.end.name(),
                       "terminations": e.end.terminations(), "wall_s": e.wall, "steps_per_s": sps})
            )
            .map_err(io)
        } else {
            writeln!(
                out,
                "{:>7} {:>12.4} {:>8} {:>7} {:>9.3} {:>12.0}  {}",
                e.index,
                e.ret,
                e.success.map_or("-".to_string(), |s| s.to_string()),
                e.length,
                e.wall,
                sps,
                match &e.error {
                    Some(err) => format!("error: {err}"),
                    None => e.end.to_string(),
                }
            )
            .map_err(io)
        }
    }

    /// Prints the summary line (env steps/s: summed over the episodes' own wall times, so
    /// per env whatever the threads).
    fn finish(self, args: &RunArgs, out: &mut dyn Write) -> Result<(), CliError> {
        let n = args.episodes as f64;
        let mean_return = self.returns.iter().sum::<f64>() / n;
        let mean_length = self.lengths.iter().sum::<u64>() as f64 / n;
        let success_rate = if self.successes.is_empty() {
            None
        } else {
            Some(self.successes.iter().filter(|s| **s).count() as f64 / self.successes.len() as f64)
        };
        let sps = self.total_steps as f64 / self.total_time.max(1e-12);
        if args.json {
            writeln!(
                out,
                "{}",
                json!({"summary": true, "target": args.target, "episodes": args.episodes,
                       "success_rate": success_rate, "mean_return": mean_return,
                       "mean_length": mean_length, "errors": self.errors, "ended": self.ends,
                       "env_steps_per_s": sps})
            )
            .map_err(io)
        } else {
            writeln!(
                out,
                "summary: {} episodes, success rate {}, mean return {:.4}, mean length {:.1}, errors {}, {:.0} env steps/s",
                args.episodes,
                success_rate.map_or("n/a (no success criterion)".to_string(), |r| format!("{:.1} %", 100.0 * r)),
                mean_return,
                mean_length,
                self.errors,
                sps
            )
            .map_err(io)
        }
    }
}
