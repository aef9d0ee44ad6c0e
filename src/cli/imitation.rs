//! Imitation learning from recorded datasets: `train TARGET --algo bc|retrieval --dataset DIR
//! --out DIR` (behaviour cloning on the state observations, [`modesuite_learn::bc`], or
//! nearest-neighbour retrieval, [`crate::retrieval`]); the policy folder it writes is evaluated
//! by `eval` and `run --policy` like PPO's and SAC's.

use std::io::{IsTerminal, Write};
use std::path::Path;

use serde_json::json;

use modesuite_dataset::{Column, Dataset};
use modesuite_learn::bc::{train_bc, BcConfig, Demos};

use super::learn::TrainArgs;
use super::{io, CliError};
use crate::gym::layout::ActLayout;
use crate::inputs::{ImageFeatures, InputSpec};
use crate::make::{self, MakeOptions};

/// The demonstrations of every episode of `ds`: the inputs `spec` asks for (image features
/// first, then `observation.state`) and `action`.
fn demos(
    ds: &Dataset,
    spec: &InputSpec,
    successful_only: bool,
    low: Vec<f32>,
    high: Vec<f32>,
) -> Result<(Demos, Used), CliError> {
    let mut d = Demos {
        low,
        high,
        ..Demos::default()
    };
    let feature_col = spec.feature_column();
    let mut used = 0;
    let mut ends = Vec::new();
    for (i, meta) in ds.episodes.iter().enumerate() {
        if successful_only && meta.success != Some(true) {
            continue;
        }
        used += 1;
        let cols = ds
            .read_episode(i)
            .map_err(|e| CliError::input(e.to_string()))?;
        let get = |n: &str| match cols.iter().find(|(c, _)| c == n).map(|(_, c)| c) {
            Some(Column::F32 { dim, values }) => Ok((*dim, values.as_slice())),
            _ => Err(CliError::input(format!(
                "{}: episode {i} has no float column {n}",
                ds.dir.display()
            ))),
        };
        let (ad, a) = get("action")?;
        let mut parts = Vec::new();
        if let Some(c) = &feature_col {
            parts.push(get(c)?);
        }
        if spec.state {
            parts.push(get("observation.state")?);
        }
        let frames = a.len() / ad.max(1);
        d.obs_dim = parts.iter().map(|(dim, _)| dim).sum();
        d.act_dim = ad;
        for f in 0..frames {
            for (dim, v) in &parts {
                d.obs.extend_from_slice(&v[f * dim..(f + 1) * dim]);
            }
        }
        d.act.extend_from_slice(a);
        ends.push(d.act.len() / ad.max(1));
    }
    d.episode_ends.clone_from(&ends);
    if used == 0 {
        return Err(CliError::input(format!(
            "{}: no {}episode to learn from",
            ds.dir.display(),
            if successful_only { "successful " } else { "" }
        )));
    }
    Ok((
        d,
        Used {
            episodes: used,
            ends,
        },
    ))
}

/// The demonstrations a policy learns from: how many, and one past each one's last frame.
struct Used {
    episodes: usize,
    ends: Vec<usize>,
}

/// The behaviour-cloning settings: defaults, `--config FILE` (RON `BcConfig`), each `--set
/// key=value` (JSON value), then `--seed`.
fn config(args: &TrainArgs) -> Result<BcConfig, CliError> {
    let mut cfg = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| CliError::input(format!("--config {}: {e}", path.display())))?;
            ron::from_str::<BcConfig>(&text).map_err(|e| {
                CliError::input(format!(
                    "--config {}:{}: {}",
                    path.display(),
                    e.span.start,
                    e.code
                ))
            })?
        }
        None => BcConfig::default(),
    };
    let mut v = serde_json::to_value(&cfg).map_err(|e| CliError::runtime(e.to_string()))?;
    if let Some(fields) = v.as_object_mut() {
        for kv in &args.set {
            crate::learning::set_json_field(fields, kv).map_err(CliError::input)?;
        }
    }
    cfg = serde_json::from_value(v).map_err(|e| CliError::input(format!("--set: {e}")))?;
    if let Some(s) = args.seed {
        cfg.seed = s;
    }
    cfg.validate().map_err(|e| CliError::input(e.to_string()))?;
    Ok(cfg)
}

/// `modesuite train TARGET --algo bc --dataset DIR --out DIR`.
pub fn train(args: &TrainArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let dir = args.dataset.as_deref().ok_or_else(|| {
        CliError::input("--algo bc needs --dataset DIR (a dataset of `modesuite record`)")
    })?;
    let ds = Dataset::open(dir).map_err(|e| CliError::input(e.to_string()))?;
    let recorded = ds.extra["target"].as_str().unwrap_or_default();
    if recorded != args.target {
        return Err(CliError::input(format!(
            "--dataset {}: recorded on {recorded:?}, not {}",
            dir.display(),
            args.target
        )));
    }
    let actions = ds.extra["actions"].as_str().map(str::to_string);
    if args.actions.is_some() && args.actions != actions {
        return Err(CliError::input(format!(
            "--actions {:?}: the dataset was recorded with {actions:?}",
            args.actions
        )));
    }
    let env = make::make(
        &args.target,
        &MakeOptions {
            actions: actions.clone(),
            ..Default::default()
        },
    )?;
    let spaces = env.spaces();
    let act = ActLayout::of(&spaces.action).map_err(CliError::input)?;
    let features: Option<ImageFeatures> =
        serde_json::from_value(ds.extra["features"].clone()).unwrap_or(None);
    let inputs = InputSpec::parse(&args.inputs, features).map_err(CliError::input)?;
    let (mut demos, used) = demos(
        &ds,
        &inputs,
        args.successful_only,
        act.low.clone(),
        act.high.clone(),
    )?;
    // discrete keys (keyboard demonstrations): BC's classification head
    demos.discrete = act.discrete.map(|n| n as usize);
    if (inputs.features.is_none() && demos.obs_dim != spaces.observation.flat_dim())
        || demos.act_dim != act.dim
    {
        return Err(CliError::input(format!(
            "--dataset {}: {} observation and {} action values, the env has {} and {}",
            dir.display(),
            demos.obs_dim,
            demos.act_dim,
            spaces.observation.flat_dim(),
            act.dim
        )));
    }
    let note = json!({"target": args.target, "actions": actions, "algo": args.algo,
                      "dataset": dir.display().to_string(), "inputs": inputs,
                      "episodes": used.episodes, "successful_only": args.successful_only,
                      "command": std::env::args().collect::<Vec<_>>().join(" ")})
    .to_string();
    let policy_dir = args.out.join("policy");
    if args.algo == "retrieval" {
        let what = inputs.describe();
        return retrieval(args, &demos, &what, &note, &policy_dir, &used, out);
    }
    let cfg = config(args)?;
    let identity = format!(
        "{} actions {} obs {} act {}",
        args.target,
        actions.as_deref().unwrap_or("(scene)"),
        demos.obs_dim,
        demos.act_dim
    );
    writeln!(
        out,
        "train bc {} seed {} on {} samples ({}) of {} episodes from {} into {}",
        args.target,
        cfg.seed,
        demos.len(),
        inputs.describe(),
        used.episodes,
        dir.display(),
        args.out.display()
    )
    .map_err(io)?;
    let tty = std::io::stderr().is_terminal();
    // an ensemble's members train side by side on `--threads`: all their epochs are counted
    let total = cfg.epochs * cfg.members;
    let every = (cfg.epochs / 20).max(1);
    let summary = train_bc(
        &demos,
        &cfg,
        args.threads,
        &identity,
        &note,
        &policy_dir,
        |epoch, loss| {
            if epoch % every == 0 || epoch + 1 == total {
                let line = format!("epoch {:>6}/{total}  loss {loss:.6}", epoch + 1);
                if tty {
                    eprint!("\r{line:<60}");
                } else {
                    eprintln!("{line}");
                }
            }
        },
    )
    .map_err(|e| CliError::runtime(e.to_string()))?;
    if tty {
        eprintln!();
    }
    writeln!(
        out,
        "bc: {} gradient steps, final loss {:.6}; policy {}",
        summary.steps,
        summary.final_loss,
        policy_dir.display()
    )
    .map_err(io)
}

/// `train --algo retrieval`: every demonstration frame kept; `--set k=N` neighbours (default
/// 1), `--set horizon=H` actions of the matched demonstration replayed per look (default 1),
/// `--set ensemble=M` those segments retrieved at every step and ensembled (horizon >= 2).
fn retrieval(
    args: &TrainArgs,
    demos: &Demos,
    inputs: &str,
    note: &str,
    policy_dir: &Path,
    used: &Used,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    if args.config.is_some() {
        return Err(CliError::input(
            "--config: retrieval's settings are --set k=N, horizon=H and ensemble=M",
        ));
    }
    let (mut k, mut horizon, mut ensemble) = (1usize, 1usize, None);
    for kv in &args.set {
        let (key, v) = kv.split_once('=').unwrap_or((kv, ""));
        let slot = match key {
            "k" => &mut k,
            "horizon" => &mut horizon,
            "ensemble" => {
                let m: f64 = v.trim().parse().map_err(|_| {
                    CliError::input(format!("--set {kv}: ensemble is a number (ACT's 0.01)"))
                })?;
                ensemble = Some(m);
                continue;
            }
            _ => {
                return Err(CliError::input(format!(
                    "--set {kv}: retrieval's settings are k=N, horizon=H and ensemble=M"
                )))
            }
        };
        *slot =
            v.trim().parse().ok().filter(|n| *n >= 1).ok_or_else(|| {
                CliError::input(format!("--set {kv}: {key} is a whole number >= 1"))
            })?;
    }
    if demos.discrete.is_some() && k > 1 {
        return Err(CliError::input(format!(
            "--set k={k}: discrete keys are not averaged; k = 1 replays the nearest frame's key"
        )));
    }
    let r =
        crate::retrieval::Retrieval::new(&demos.obs, &demos.act, demos.obs_dim, demos.act_dim, k)
            .with_replay(horizon, used.ends.clone())
            .and_then(|r| r.with_ensemble(ensemble))
            .map_err(|e| CliError::input(format!("--set: {e}")))?;
    r.save(policy_dir, note).map_err(CliError::runtime)?;
    writeln!(
        out,
        "retrieval {} ({}): {} frames of {} episodes, k = {k}, horizon {horizon}{}; policy {}",
        args.target,
        inputs,
        r.len(),
        used.episodes,
        ensemble.map_or(String::new(), |m| format!(", ensembled ({m})")),
        policy_dir.display()
    )
    .map_err(io)
}
