//! The learning commands: `train`, `eval` and `plot` (see [`crate::learning`] and
//! [`crate::plot`]).

use std::io::{IsTerminal, Write};
use std::path::PathBuf;

use super::{io, CliError, RunArgs};
use crate::learning::{self, TrainRequest, EVAL_SEED};

/// Arguments of `train`.
#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    /// A task id (`MoDe-<Robot>-<Task>-v0`) or a scene file with a task section.
    pub target: String,
    /// `ppo`, `sac`, or on `--dataset`'s demonstrations `bc` (behaviour cloning) or
    /// `retrieval` (nearest neighbours).
    #[arg(long, default_value = "ppo")]
    pub algo: String,
    /// The demonstrations for `--algo bc|retrieval`: a dataset folder of `modesuite record`.
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    /// What `--algo bc|retrieval` policies observe: `state` (the task's observation),
    /// `features` (the dataset's cached image features, `record --encoder`) or
    /// `features+state`; the policy renders and encodes its camera when it acts.
    #[arg(long, default_value = "state")]
    pub inputs: String,
    /// `--algo bc|retrieval`: learn from the dataset's successful episodes only (a noisy
    /// recording also holds failures).
    #[arg(long)]
    pub successful_only: bool,
    /// Seed of the learner and of the env resets (default: the configuration's, 0).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Env steps to train for, all envs together (default 5,000,000 for PPO, 1,000,000 for SAC).
    #[arg(long)]
    pub env_steps: Option<u64>,
    /// Envs stepped together.
    #[arg(long, default_value_t = 16)]
    pub envs: usize,
    /// Threads stepping the envs, or training a BC ensemble's members side by side (0: all
    /// cores; results do not depend on it).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// The run folder (config, metrics, checkpoint, policy); an existing run there resumes.
    #[arg(long)]
    pub out: PathBuf,
    /// Hyper-parameters as RON (`Ppo((...))` or `Sac((...))`), over the task's defaults.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// One hyper-parameter, `key=value` (JSON value), e.g. `--set learning_rate=3e-4`; repeatable.
    #[arg(long)]
    pub set: Vec<String>,
    /// Write a checkpoint every this many iterations.
    #[arg(long, default_value_t = 10)]
    pub checkpoint_every: u64,
    /// Action modes of the robot, RON, replacing the scene's.
    #[arg(long)]
    pub actions: Option<String>,
}

/// Arguments of `eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// A run folder (`train --out`) or a policy folder (holding `policy.json`).
    pub dir: PathBuf,
    /// Episodes.
    #[arg(long, default_value_t = 20)]
    pub episodes: u64,
    /// Seed of the first episode (episode i uses seed + i); the default is far from training's.
    #[arg(long, default_value_t = EVAL_SEED)]
    pub seed: u64,
    /// Record a video of the episodes (`.gif` or `.mp4`).
    #[arg(long)]
    pub video: Option<PathBuf>,
    /// Print one JSON object per episode and a summary (the keys of `run --json`).
    #[arg(long)]
    pub json: bool,
    /// Threads running episodes side by side (`0`: all cores; `run --threads`): the results
    /// are the same for any number.
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
}

/// Arguments of `plot`.
#[derive(clap::Args, Debug)]
pub struct PlotArgs {
    /// Run folders (one per seed); their mean and standard deviation are drawn.
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// The PNG to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Title (default: the first run's target and algorithm).
    #[arg(long)]
    pub title: Option<String>,
}

/// `modesuite train`.
pub fn train(args: &TrainArgs, out: &mut dyn Write) -> Result<(), CliError> {
    if args.algo == "bc" || args.algo == "retrieval" {
        return super::imitation::train(args, out);
    }
    if args.dataset.is_some() {
        return Err(CliError::input(
            "--dataset: only used with --algo bc or retrieval",
        ));
    }
    if args.successful_only {
        return Err(CliError::input(
            "--successful-only: only used with --algo bc or retrieval",
        ));
    }
    if args.inputs != "state" {
        return Err(CliError::input(
            "--inputs: only used with --algo bc or retrieval (PPO and SAC observe the state)",
        ));
    }
    if args.envs == 0 {
        return Err(CliError::input("--envs = 0: at least 1"));
    }
    std::fs::create_dir_all(&args.out).map_err(|e| {
        CliError::runtime(format!("--out {}: cannot create: {e}", args.out.display()))
    })?;
    let req = TrainRequest {
        target: args.target.clone(),
        algo: args.algo.clone(),
        seed: args.seed,
        env_steps: args.env_steps,
        envs: args.envs,
        threads: args.threads,
        out: args.out.clone(),
        config: args.config.clone(),
        set: args.set.clone(),
        checkpoint_every: args.checkpoint_every,
        actions: args.actions.clone(),
        command: std::env::args().collect::<Vec<_>>().join(" "),
        log_env_calls: false,
    };
    let (cfg, files) = learning::resolve_config(&req).map_err(CliError::input)?;
    let total = args
        .env_steps
        .unwrap_or_else(|| learning::default_env_steps(&args.algo));
    writeln!(
        out,
        "train {} {} seed {} on {} envs for {total} env steps into {} (hyper-parameters: defaults{})",
        args.algo,
        args.target,
        cfg.seed(),
        args.envs,
        args.out.display(),
        files
            .iter()
            .map(|f| format!(" + {}", f.display()))
            .collect::<String>()
    )
    .map_err(io)?;
    let tty = std::io::stderr().is_terminal();
    let outcome = learning::train(&req, |m| {
        let line = m.progress_line(total);
        if tty {
            eprint!("\r{line:<150}");
        } else if m.iteration % 10 == 0 {
            eprintln!("{line}");
        }
    })?;
    if tty {
        eprintln!();
    }
    let summary = outcome.summary;
    writeln!(
        out,
        "done: {} iterations, {} env steps{}; last: {}",
        summary.iterations,
        summary.env_steps,
        if summary.resumed { " (resumed)" } else { "" },
        summary
            .last
            .as_ref()
            .map_or("-".to_string(), |m| m.progress_line(total))
    )
    .map_err(io)?;
    if let Some(why) = &summary.envs_reset {
        writeln!(
            out,
            "note: the envs saved in the checkpoint could not be restored ({why}); they were reset on resume, so this run no longer matches an uninterrupted one bit for bit"
        )
        .map_err(io)?;
    }
    let learner = outcome.wall_seconds - outcome.env_seconds;
    if summary.last.is_none() {
        // a finished run resumed: a share of a few milliseconds says nothing
        writeln!(out, "time: nothing left to train").map_err(io)?;
    } else {
        writeln!(
            out,
            "time: {:.1} s, of which envs {:.1} s and learner {:.1} s ({:.1} %)",
            outcome.wall_seconds,
            outcome.env_seconds,
            learner,
            100.0 * learner / outcome.wall_seconds.max(1e-9)
        )
        .map_err(io)?;
    }
    Ok(())
}

/// `modesuite eval`: `run` of the policy's target with the policy acting.
pub fn eval(args: &EvalArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let origin = learning::policy_origin(&args.dir).map_err(CliError::input)?;
    let run_args = RunArgs {
        target: origin.target,
        steps: None,
        seed: args.seed,
        episodes: args.episodes,
        dump_state: None,
        save_state: None,
        load_state: None,
        json: args.json,
        plugin: Vec::new(),
        video: args.video.clone(),
        frames: None,
        camera: None,
        video_size: "480x320".into(),
        overlays: false,
        policy: args.dir.display().to_string(),
        actions: origin.actions,
        rgbd: None,
        threads: args.threads,
    };
    super::run::run(&run_args, out)
}

/// `modesuite plot`.
pub fn plot(args: &PlotArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let title = match &args.title {
        Some(t) => t.clone(),
        None => learning::load_policy(&args.dirs[0])
            .map(|(p, o)| format!("{} {}", p.meta().algo.to_uppercase(), o.target))
            .unwrap_or_else(|_| args.dirs[0].display().to_string()),
    };
    crate::plot::plot(&args.dirs, &args.out, &title)?;
    writeln!(out, "wrote {}", args.out.display()).map_err(io)
}
