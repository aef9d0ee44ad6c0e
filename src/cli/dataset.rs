//! Demonstration datasets: `record` (episodes of the scripted expert or a trained policy, with
//! optional action noise and camera videos, into a LeRobot v3.0 dataset) and `dataset
//! info|replay` (see [`modesuite_dataset`]).

use std::io::Write;
use std::path::{Path, PathBuf};

use serde_json::json;

use modesuite_dataset::{
    Column, Dataset, DatasetWriter, EpisodeInput, Feature, FeatureStats, Features, Info,
};
use modesuite_engine::prelude::*;
use modesuite_engine::rng::EnvRng;
use modesuite_render::video::VideoWriter;
use modesuite_render::{CameraDesc, EnvRenderer};

use super::record::render_err;
use super::{io, make_run_policy, CliError};
use crate::episode::final_success;
use crate::gym::layout::ActLayout;
use crate::inputs::{encode_frame, ImageFeatures};
use crate::make::{self, MakeOptions};
use modesuite_learn::encoder::ImageEncoder;

/// Arguments of `record`.
#[derive(clap::Args, Debug)]
pub struct RecordArgs {
    /// A task id (`MoDe-<Robot>-<Task>-v0`) or a scene file with a task section.
    pub target: String,
    /// Who acts: `scripted` (the task's expert), `random`, `zero`, or a trained policy's folder.
    #[arg(long, default_value = "scripted")]
    pub policy: String,
    /// Episodes the dataset should hold: a folder that has some already gets the rest (so a
    /// killed recording continues with the same command).
    #[arg(long, default_value_t = 30)]
    pub episodes: u64,
    /// Seed of episode 0 (episode i is recorded from seed + i).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Action noise: each action component gets Gaussian noise of this standard deviation times
    /// half its range (clipped to the range); discrete actions are replaced by a random key
    /// with this probability. Seeded by the episode's seed. The recorded action is the one
    /// executed, so the expert's recoveries are in the data.
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
    /// Cameras and image features to record.
    #[command(flatten)]
    pub capture: CaptureArgs,
    /// The dataset folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Action modes of the robot, RON, replacing the scene's (default: the policy's, for a
    /// trained policy).
    #[arg(long)]
    pub actions: Option<String>,
    /// Env steps per episode at most (default: the scene's episode length).
    #[arg(long)]
    pub steps: Option<u64>,
    /// One JSON object per recorded episode.
    #[arg(long)]
    pub json: bool,
}

/// What a recording captures besides state and actions (`record`, `view --record-dataset`,
/// `dataset import-teleop`).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct CaptureArgs {
    /// Cameras of the scene's render section to record as videos (`robot`: the robot camera),
    /// comma-separated; MP4 through ffmpeg.
    #[arg(long, value_delimiter = ',')]
    pub cameras: Vec<String>,
    /// Caches image features of the first of `--cameras` per frame as
    /// `observation.features.<ENCODER>` (for `train --inputs features`): `pooled` (weights-free)
    /// or `dinov2` (needs --weights).
    #[arg(long)]
    pub encoder: Option<String>,
    /// The encoder's weights file (`dinov2`: DINOv2 ViT-S/14 as safetensors).
    #[arg(long)]
    pub weights: Option<PathBuf>,
}

impl CaptureArgs {
    /// Whether any capture option is given.
    pub fn any(&self) -> bool {
        !self.cameras.is_empty() || self.encoder.is_some() || self.weights.is_some()
    }
}

/// `dataset` subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum DatasetCommand {
    /// What a dataset holds: episodes, frames, features, success rate, what recorded it.
    Info {
        /// The dataset folder.
        dir: PathBuf,
        /// As one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Appends the episodes of a teleoperation recording (`view --record FILE` with the discrete
    /// keys) to a dataset, re-simulated from their seeds with their keys (the simulation is
    /// deterministic, so the dataset holds what the viewer showed).
    ImportTeleop(super::teleop::ImportArgs),
    /// Re-simulates recorded episodes from their seeds with their actions and checks that every
    /// state, reward and end is reproduced bit for bit; exit 1 otherwise.
    Replay {
        /// The dataset folder.
        dir: PathBuf,
        /// Only this episode (default: all).
        #[arg(long)]
        episode: Option<usize>,
        /// One JSON object per episode.
        #[arg(long)]
        json: bool,
    },
}

/// The natural-language task of a task id (LeRobot's `task`), else the target itself.
pub fn instruction(target: &str) -> String {
    let task = target.split('-').nth(2).unwrap_or("");
    let text = match task {
        "Place" => "Place the free end of the foam rod on the table.",
        "Bend" => "Carry the rod around the corner of the corridor to the target.",
        "Transport" => "Transport the rod along the corridor past the pillar to the target.",
        "Drag" => "Drag the belt around the post to the target.",
        "Lift" => "Lift the belt and pass under it to the end of the corridor.",
        "Uncover" => "Pull the cover off the table by its handle.",
        "Cover" => "Cover the gap between the two cubes with the fabric.",
        "Curtain" => "Pass through the curtain without touching its frame.",
        _ => return format!("Run {target}."),
    };
    text.to_string()
}

fn dataset_err(e: modesuite_dataset::DatasetError) -> CliError {
    CliError::runtime(e.to_string())
}

/// The env with its cameras and encoder.
struct Setup {
    env: Env,
    renderer: Option<EnvRenderer>,
    cameras: Vec<CameraDesc>,
    encoder: Option<Box<dyn ImageEncoder>>,
    steps: u64,
}

/// The env and what a dataset of it looks like (its info and `modesuite.json`).
fn setup(args: &RecordArgs) -> Result<(Setup, Info, serde_json::Value), CliError> {
    let mut actions = args.actions.clone();
    if actions.is_none() && crate::learning::policy_dir(Path::new(&args.policy)).is_some() {
        let origin =
            crate::learning::policy_origin(Path::new(&args.policy)).map_err(CliError::input)?;
        actions = origin.actions;
    }
    let opts = MakeOptions {
        actions: actions.clone(),
        ..Default::default()
    };
    let made = make::make_envs(&args.target, &opts, 1)?;
    let model = made.model;
    let Some(env) = made.envs.into_iter().next() else {
        return Err(CliError::runtime("no env was made"));
    };
    let spaces = env.spaces();
    let act = ActLayout::of(&spaces.action).map_err(CliError::input)?;
    let step_dt = model.settings.dt * model.settings.decimation as f64;
    let fps = (1.0 / step_dt).round().max(1.0) as u32;
    let mut act_names = Vec::new();
    for (name, _, len) in &act.parts {
        for k in 0..*len {
            act_names.push(if *len == 1 {
                name.clone()
            } else {
                format!("{name}.{k}")
            });
        }
    }
    let obs_dim = spaces.observation.flat_dim();
    let mut state = Feature::f32(&[]);
    state.shape = vec![obs_dim.max(1)];
    state.names = serde_json::Value::Null;
    let mut features = vec![
        ("observation.state".to_string(), state),
        ("action".to_string(), Feature::f32(&act_names)),
        ("next.reward".to_string(), Feature::scalar("float32")),
        ("next.done".to_string(), Feature::scalar("bool")),
        ("next.success".to_string(), Feature::scalar("bool")),
    ];
    let renderer = if args.capture.cameras.is_empty() {
        None
    } else {
        Some(EnvRenderer::for_scene(model.clone()).map_err(render_err)?)
    };
    let mut cameras = Vec::new();
    if let Some(r) = &renderer {
        for name in &args.capture.cameras {
            let cam = r.scene_camera(name).map_err(render_err)?.clone();
            features.push((
                format!("observation.images.{name}"),
                Feature::video(cam.width, cam.height, fps, "h264"),
            ));
            cameras.push(cam);
        }
    }
    let mut image_features = None;
    let encoder = match &args.capture.encoder {
        Some(name) => {
            let camera = args.capture.cameras.first().ok_or_else(|| {
                CliError::input("--encoder: needs a camera to encode (--cameras robot)")
            })?;
            let enc = super::encode::make_encoder(name, args.capture.weights.as_deref())?;
            let mut f = Feature::f32(&[]);
            f.shape = vec![enc.dim()];
            f.names = serde_json::Value::Null;
            features.push((format!("observation.features.{name}"), f));
            image_features = Some(ImageFeatures {
                encoder: name.clone(),
                camera: camera.clone(),
                weights: args
                    .capture
                    .weights
                    .as_ref()
                    .map(|w| w.canonicalize().unwrap_or(w.clone())),
            });
            Some(enc)
        }
        None if args.capture.weights.is_some() => {
            return Err(CliError::input("--weights: only with --encoder"))
        }
        None => None,
    };
    let robot = args.target.split('-').nth(1).map(|r| match r {
        "Franka" => "franka_ridgeback".to_string(),
        other => other.to_lowercase(),
    });
    let info = Info::new(fps, robot, Features::with_defaults(features));
    let extra = json!({
        "format": "modesuite.dataset.v1",
        "target": args.target,
        "actions": actions,
        "policy": args.policy,
        "noise": args.noise,
        "seed": args.seed,
        "cameras": args.capture.cameras,
        "features": image_features,
        "step_dt": step_dt,
        "modesuite_version": env!("CARGO_PKG_VERSION"),
    });
    let steps = args.steps.or(model.episode_steps).unwrap_or(600);
    let setup = Setup {
        env,
        renderer,
        cameras,
        encoder,
        steps,
    };
    Ok((setup, info, extra))
}

fn add_noise(action: &mut [f32], act: &ActLayout, noise: f64, rng: &mut EnvRng) {
    if noise <= 0.0 {
        return;
    }
    if let Some(n) = act.discrete {
        if rng.uniform() < noise {
            action[0] = rng.below(n) as f32;
        }
        return;
    }
    for (i, a) in action.iter_mut().enumerate() {
        let (lo, hi) = (act.low[i], act.high[i]);
        let half = if lo.is_finite() && hi.is_finite() {
            0.5 * f64::from(hi - lo)
        } else {
            1.0
        };
        let v = f64::from(*a) + noise * half * rng.normal();
        *a = (v as f32).clamp(lo, hi);
    }
}

/// `modesuite record`.
pub fn record(args: &RecordArgs, out: &mut dyn Write) -> Result<(), CliError> {
    if !(0.0..=1.0).contains(&args.noise) {
        return Err(CliError::input(format!(
            "--noise = {}: in 0..=1",
            args.noise
        )));
    }
    let mut session = Session::open(args)?;
    let mut policy = make_run_policy(&args.policy, session.env())?;
    let start = session.writer.info().total_episodes as u64;
    if start >= args.episodes && !args.json {
        writeln!(
            out,
            "{}: {start} episodes already, nothing to record",
            args.out.display()
        )
        .map_err(io)?;
    }
    for e in start..args.episodes {
        let seed = args.seed.wrapping_add(e);
        let steps = session.setup.steps;
        let line = session.episode(policy.as_mut(), seed, args.noise, steps)?;
        print_episode(&line, args.json, out)?;
    }
    Ok(())
}

/// One line per recorded episode: JSON (`--json`) or text.
pub(super) fn print_episode(
    line: &serde_json::Value,
    as_json: bool,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    if as_json {
        return writeln!(out, "{line}").map_err(io);
    }
    writeln!(
        out,
        "episode {}: seed {}, {} frames, return {:.3}, success {}{}",
        line["episode"],
        line["seed"],
        line["length"],
        line["return"].as_f64().unwrap_or(f64::NAN),
        line["success"]
            .as_bool()
            .map_or("-".into(), |s| s.to_string()),
        line["error"]
            .as_str()
            .map_or(String::new(), |e| format!(", error: {e}"))
    )
    .map_err(io)
}

/// An open recording: the env with its cameras and encoder, and the dataset it appends to.
pub(super) struct Session {
    setup: Setup,
    writer: DatasetWriter,
    act: ActLayout,
    staging: PathBuf,
    task: String,
}

impl Session {
    pub(super) fn open(args: &RecordArgs) -> Result<Self, CliError> {
        let (mut setup, info, extra) = setup(args)?;
        setup.env.autoreset = false;
        let writer = DatasetWriter::open_or_create(&args.out, info, &extra).map_err(dataset_err)?;
        let act = ActLayout::of(&setup.env.spaces().action).map_err(CliError::input)?;
        Ok(Self {
            setup,
            writer,
            act,
            staging: args.out.join(".recording"),
            task: instruction(&args.target),
        })
    }

    /// Records one episode of `policy` from `seed` (at most `steps` env steps, actions
    /// perturbed by `noise`) and appends it; returns its line (`episode`, `seed`, `length`,
    /// `return`, `success`, `error`).
    pub(super) fn episode(
        &mut self,
        policy: &mut dyn modesuite_tasks::expert::Policy,
        seed: u64,
        noise: f64,
        steps: u64,
    ) -> Result<serde_json::Value, CliError> {
        let (s, act) = (&mut self.setup, &self.act);
        let env = &mut s.env;
        let e = self.writer.info().total_episodes;
        let fps = self.writer.info().fps;
        let mut obs = env.reset(Some(seed)).0;
        policy.reset(seed);
        let mut rng = EnvRng::from_seed(seed ^ 0x6e6f_6973_655f_7365);
        let mut action = vec![0.0f32; act.dim];
        let (mut states, mut actions, mut rewards, mut dones, mut succ) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut feats: Vec<f32> = Vec::new();
        std::fs::create_dir_all(&self.staging)
            .map_err(|err| CliError::runtime(format!("{}: {err}", self.staging.display())))?;
        let mut videos: Vec<(PathBuf, VideoWriter, Vec<Vec<u8>>)> = Vec::new();
        for (k, cam) in s.cameras.iter().enumerate() {
            let path = self.staging.join(format!("episode-{e}-{k}.mp4"));
            let w = VideoWriter::create(&path, cam.width, cam.height, f64::from(fps))
                .map_err(render_err)?;
            videos.push((path, w, Vec::new()));
        }
        let (mut success, mut error, mut ret) = (None, None, 0.0);
        for t in 0..steps {
            if let Some(r) = s.renderer.as_mut() {
                let frames = r
                    .render_cameras(&env.app.world, &s.cameras)
                    .map_err(render_err)?;
                if let (Some(enc), Some(frame)) = (&s.encoder, frames.first()) {
                    feats.extend(encode_frame(enc.as_ref(), frame).map_err(CliError::runtime)?);
                }
                for (frame, (_, w, sampled)) in frames.iter().zip(videos.iter_mut()) {
                    w.push(frame).map_err(render_err)?;
                    if t % 4 == 0 {
                        sampled.push(frame.rgb.clone());
                    }
                }
            }
            if let Err(err) = policy.act(env, &mut action) {
                error = Some(format!("policy: {err}"));
                break;
            }
            add_noise(&mut action, act, noise, &mut rng);
            let o = env.step(&action);
            states.extend_from_slice(&obs);
            actions.extend_from_slice(&action);
            rewards.push(o.reward as f32);
            ret += o.reward;
            let done = o.terminated || o.truncated;
            dones.push(done);
            if done {
                success = final_success(success, o.info.success, o.info.error.is_some());
                error = o.info.error.clone();
            } else {
                success = o.info.success;
            }
            succ.push(success.unwrap_or(false));
            obs = o.observation;
            if done {
                break;
            }
        }
        if states.is_empty() {
            return Err(CliError::runtime(format!(
                "episode {e} (seed {seed}) recorded no frame: {}",
                error.unwrap_or_default()
            )));
        }
        let mut video_inputs = Vec::new();
        for (path, w, sampled) in videos {
            w.finish().map_err(render_err)?;
            let refs: Vec<&[u8]> = sampled.iter().map(|f| f.as_slice()).collect();
            video_inputs.push((path, FeatureStats::of_rgb(&refs)));
        }
        let len = rewards.len();
        // a step cut short by a policy error rendered a frame it did not record
        feats.truncate(len * s.encoder.as_ref().map_or(0, |e| e.dim()));
        let mut columns = vec![
            (
                "observation.state".into(),
                Column::F32 {
                    dim: states.len() / len,
                    values: states,
                },
            ),
            (
                "action".into(),
                Column::F32 {
                    dim: act.dim,
                    values: actions,
                },
            ),
            (
                "next.reward".into(),
                Column::F32 {
                    dim: 1,
                    values: rewards,
                },
            ),
            ("next.done".into(), Column::Bool(dones)),
            ("next.success".into(), Column::Bool(succ)),
        ];
        if let Some(enc) = &s.encoder {
            columns.push((
                format!("observation.features.{}", enc.name()),
                Column::F32 {
                    dim: enc.dim(),
                    values: feats,
                },
            ));
        }
        let input = EpisodeInput {
            task: self.task.clone(),
            columns,
            videos: video_inputs,
            seed,
            success,
        };
        let index = self.writer.append(input).map_err(dataset_err)?;
        Ok(
            json!({"episode": index, "seed": seed, "length": len, "return": ret,
                  "success": success, "error": error}),
        )
    }

    /// The env episodes are recorded in.
    pub(super) fn env(&self) -> &Env {
        &self.setup.env
    }
}

impl Drop for Session {
    /// Removes the staging folder of the videos (committed episodes' videos were moved out of
    /// it), also when the session ends with an error or with the viewer of `--record-dataset`.
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.staging);
    }
}

/// `modesuite dataset ...`.
pub fn dataset(cmd: &DatasetCommand, out: &mut dyn Write) -> Result<(), CliError> {
    match cmd {
        DatasetCommand::Info { dir, json } => info(dir, *json, out),
        DatasetCommand::Replay { dir, episode, json } => replay(dir, *episode, *json, out),
        DatasetCommand::ImportTeleop(args) => super::teleop::import(args, out),
    }
}

fn open(dir: &Path) -> Result<Dataset, CliError> {
    Dataset::open(dir).map_err(|e| CliError::input(e.to_string()))
}

fn info(dir: &Path, as_json: bool, out: &mut dyn Write) -> Result<(), CliError> {
    let ds = open(dir)?;
    let successes: Vec<bool> = ds.episodes.iter().filter_map(|e| e.success).collect();
    let rate = (!successes.is_empty())
        .then(|| successes.iter().filter(|s| **s).count() as f64 / successes.len() as f64);
    let features: Vec<_> = ds
        .info
        .features
        .0
        .iter()
        .map(|(n, f)| json!({"name": n, "dtype": f.dtype, "shape": f.shape}))
        .collect();
    let v = json!({
        "dir": dir.display().to_string(), "codebase_version": ds.info.codebase_version,
        "episodes": ds.info.total_episodes, "frames": ds.info.total_frames, "fps": ds.info.fps,
        "tasks": ds.tasks, "success_rate": rate, "features": features,
        "recorded_by": ds.extra,
        "orphans": ds.orphans.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
    });
    if as_json {
        writeln!(out, "{v}").map_err(io)?;
        return Ok(());
    }
    writeln!(
        out,
        "{}: LeRobot {} dataset, {} episodes, {} frames at {} fps, success rate {}",
        dir.display(),
        ds.info.codebase_version,
        ds.info.total_episodes,
        ds.info.total_frames,
        ds.info.fps,
        rate.map_or("n/a".into(), |r| format!("{:.1} %", 100.0 * r))
    )
    .map_err(io)?;
    writeln!(out, "tasks: {:?}", ds.tasks).map_err(io)?;
    for (n, f) in &ds.info.features.0 {
        writeln!(out, "  {n:<28} {:<8} {:?}", f.dtype, f.shape).map_err(io)?;
    }
    writeln!(out, "recorded by: {}", ds.extra).map_err(io)?;
    if !ds.orphans.is_empty() {
        writeln!(
            out,
            "{} file(s) of an interrupted recording, ignored (the next `record` into this folder deletes them)",
            ds.orphans.len()
        )
        .map_err(io)?;
    }
    Ok(())
}

fn replay(
    dir: &Path,
    only: Option<usize>,
    as_json: bool,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let ds = open(dir)?;
    let target = ds.extra["target"].as_str().ok_or_else(|| {
        CliError::input(format!(
            "{}: meta/modesuite.json names no target: not recorded by modesuite",
            dir.display()
        ))
    })?;
    let opts = MakeOptions {
        actions: ds.extra["actions"].as_str().map(str::to_string),
        ..Default::default()
    };
    let mut env = make::make(target, &opts)?;
    env.autoreset = false;
    let episodes: Vec<usize> = match only {
        Some(i) => vec![i],
        None => (0..ds.episodes.len()).collect(),
    };
    let mut failed = 0;
    for i in episodes {
        let cols = ds.read_episode(i).map_err(dataset_err)?;
        let meta = &ds.episodes[i];
        let get = |name: &str| cols.iter().find(|(n, _)| n == name).map(|(_, c)| c);
        let (
            Some(Column::F32 {
                dim: sd,
                values: states,
            }),
            Some(Column::F32 {
                dim: ad,
                values: actions,
            }),
            Some(Column::F32 {
                values: rewards, ..
            }),
            Some(Column::Bool(dones)),
        ) = (
            get("observation.state"),
            get("action"),
            get("next.reward"),
            get("next.done"),
        )
        else {
            return Err(CliError::input(format!(
                "{}: episode {i} lacks observation.state, action, next.reward or next.done",
                dir.display()
            )));
        };
        let mut obs = env.reset(Some(meta.seed)).0;
        let mut mismatch = None;
        for t in 0..meta.length {
            if obs.len() != *sd
                || obs
                    .iter()
                    .zip(&states[t * sd..(t + 1) * sd])
                    .any(|(a, b)| a.to_bits() != b.to_bits())
            {
                mismatch = Some(format!("frame {t}: observation.state differs"));
                break;
            }
            let o = env.step(&actions[t * ad..(t + 1) * ad]);
            if (o.reward as f32).to_bits() != rewards[t].to_bits()
                || (o.terminated || o.truncated) != dones[t]
            {
                mismatch = Some(format!("frame {t}: reward or end differs"));
                break;
            }
            obs = o.observation;
        }
        if mismatch.is_some() {
            failed += 1;
        }
        if as_json {
            writeln!(out, "{}", json!({"episode": i, "seed": meta.seed, "frames": meta.length, "identical": mismatch.is_none(), "mismatch": mismatch})).map_err(io)?;
        } else {
            writeln!(
                out,
                "episode {i}: seed {}, {} frames: {}",
                meta.seed,
                meta.length,
                mismatch
                    .as_deref()
                    .unwrap_or("every state, reward and end identical")
            )
            .map_err(io)?;
        }
    }
    if failed > 0 {
        return Err(CliError::runtime(format!(
            "{failed} episode(s) did not replay bit for bit"
        )));
    }
    Ok(())
}
