//! Keyboard demonstrations into datasets: `dataset import-teleop RECORDING --out DIR` and `view
//! --record-dataset DIR` (each episode appended when it ends).
//!
//! The viewer drives a robot with the 14 keys when its action space is `Discrete(14)`
//! (`--actions "(discrete: true)"`), one env step per key press. A recorded episode (seed and
//! keys) is re-simulated headless from its seed with its keys, which the deterministic
//! simulation turns into exactly the states the viewer showed, and recorded like `record` does
//! (state, action = key index, reward, success, camera videos and features).

use std::io::Write;
use std::path::PathBuf;

use clap::Args;
use modesuite_engine::prelude::*;
use modesuite_render::teleop::{RecordedEpisode, Recording};

use super::dataset::{print_episode, CaptureArgs, RecordArgs, Session};
use super::CliError;

/// Arguments of `dataset import-teleop`.
#[derive(Args, Debug)]
pub struct ImportArgs {
    /// The recording (`view --record FILE`, modesuite.teleop.v1 JSON).
    pub recording: PathBuf,
    /// The dataset folder (created, or appended to).
    #[arg(long)]
    pub out: PathBuf,
    /// The action modes the viewer ran with (`view --actions`); they must give the discrete keys.
    #[arg(long)]
    pub actions: Option<String>,
    /// Cameras and image features to record.
    #[command(flatten)]
    pub capture: CaptureArgs,
    /// One JSON object per episode.
    #[arg(long)]
    pub json: bool,
}

/// Plays an episode's keys back, one per env step.
struct Keys(Vec<f32>);

impl modesuite_tasks::expert::Policy for Keys {
    fn act(&mut self, env: &Env, action: &mut [f32]) -> Result<(), String> {
        let step = env.app.world.resource::<SimClock>().episode_steps as usize;
        let key = self
            .0
            .get(step)
            .ok_or_else(|| format!("the recording has no key for step {step}"))?;
        action[0] = *key;
        Ok(())
    }
}

/// The keys of an episode, one per step; an episode whose keys were not one per env step (a
/// recording of a continuous-action viewer) is refused.
fn keys_of(ep: &RecordedEpisode) -> Result<Keys, String> {
    let mut keys = Vec::with_capacity(ep.actions.len());
    for (j, a) in ep.actions.iter().enumerate() {
        if a.step != j as u64 || a.action >= 14 {
            return Err(format!(
                "episode of seed {}: key {j} is {:?} at step {} (a discrete-key recording has key j at step j, each in 0..14)",
                ep.seed, a.name, a.step
            ));
        }
        keys.push(a.action as f32);
    }
    Ok(Keys(keys))
}

/// A recording session into `out`: the env must take the discrete keys.
pub(super) fn session(
    target: &str,
    out: PathBuf,
    actions: Option<String>,
    capture: &CaptureArgs,
) -> Result<Session, CliError> {
    let args = RecordArgs {
        target: target.to_string(),
        policy: "teleop".into(),
        episodes: 0,
        seed: 0,
        noise: 0.0,
        capture: capture.clone(),
        out,
        actions,
        steps: None,
        json: false,
    };
    let session = Session::open(&args)?;
    if !matches!(session.env().spaces().action, Space::Discrete { .. }) {
        return Err(CliError::input(format!(
            "{target}: the keys of a teleoperation are env actions only with the discrete keys; \
             give the viewer's --actions (e.g. \"(discrete: true)\")"
        )));
    }
    Ok(session)
}

/// Appends one teleoperated episode (if it has keys) and returns its line.
pub(super) fn append(
    session: &mut Session,
    ep: &RecordedEpisode,
) -> Result<Option<serde_json::Value>, CliError> {
    if ep.actions.is_empty() {
        return Ok(None);
    }
    let mut keys = keys_of(ep).map_err(CliError::input)?;
    let n = keys.0.len() as u64;
    session.episode(&mut keys, ep.seed, 0.0, n).map(Some)
}

/// `modesuite dataset import-teleop`.
pub fn import(args: &ImportArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let rec = Recording::load(&args.recording).map_err(|e| CliError::input(e.to_string()))?;
    let mut s = session(
        &rec.scene,
        args.out.clone(),
        args.actions.clone(),
        &args.capture,
    )?;
    for ep in &rec.episodes {
        if let Some(line) = append(&mut s, ep)? {
            print_episode(&line, args.json, out)?;
        }
    }
    Ok(())
}

/// `view --record-dataset DIR`: a hook appending each ended episode to the dataset (checked,
/// and the dataset opened, before the window opens).
pub(super) fn dataset_hook(
    target: &str,
    out: PathBuf,
    actions: Option<String>,
    capture: &CaptureArgs,
) -> Result<modesuite_render::viewer::EpisodeHook, CliError> {
    let mut s = session(target, out.clone(), actions, capture)?;
    Ok(Box::new(move |ep: &RecordedEpisode| {
        if let Some(line) = append(&mut s, ep).map_err(|e| e.message)? {
            eprintln!("{}: appended {line}", out.display());
        }
        Ok(())
    }))
}
