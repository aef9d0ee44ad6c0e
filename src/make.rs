//! The environment factory: the one entry point that the CLI, the Python binding and user
//! programs use to turn a task id or a scene file into environments.
//!
//! ```no_run
//! use modesuite::make::{make, make_vec, MakeOptions};
//! // one env of a task id (or a `*.scene.ron` path), default options
//! let mut env = make("MoDe-Franka-Place-v0", &MakeOptions::default())?;
//! let (obs, _) = env.reset(Some(0));
//! // 16 envs stepped on all cores, with the robot camera's RGB-D image in the observation
//! let opts = MakeOptions { rgbd: Some("robot".into()), ..MakeOptions::default() };
//! let mut envs = make_vec("MoDe-Franka-Place-v0", &opts, 16, 0)?;
//! # Ok::<(), modesuite::make::MakeError>(())
//! ```
//!
//! A target is a scene file (`*.scene.ron`, with or without a task section) or a task id
//! `MoDe-<Robot>-<Task>-v0`, resolved under [`scenes_dir`] and, when that folder lacks it, in the
//! copies of the task files embedded in the library. The scene is compiled once and every env
//! of a batch is spawned from the same compiled model (FEM models, robot models and meshes are
//! shared behind `Arc`).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use modesuite_engine::env::VecEnvError;
use modesuite_engine::prelude::*;
use modesuite_engine::scene::EpisodeLimit;
use modesuite_engine::scene::{self, SceneModel};
use modesuite_engine::{DynamicPlugin, PluginLoadError};
use modesuite_render::RenderError;

/// What went wrong making an environment: bad input (a scene error carrying `file:line:col`, an
/// unknown id, a bad option value) or a run-time failure (no render device, a thread pool).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MakeError {
    /// The user's input is wrong; the message says where and what would be valid.
    Input(String),
    /// Something failed at run time (rendering device, thread pool).
    Runtime(String),
}

impl MakeError {
    /// The message.
    pub fn message(&self) -> &str {
        match self {
            MakeError::Input(m) | MakeError::Runtime(m) => m,
        }
    }
}

impl std::fmt::Display for MakeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.message())
    }
}

impl std::error::Error for MakeError {}

impl From<SceneError> for MakeError {
    fn from(e: SceneError) -> Self {
        MakeError::Input(e.to_string())
    }
}

impl From<PluginLoadError> for MakeError {
    fn from(e: PluginLoadError) -> Self {
        MakeError::Input(format!("plugin: {e}"))
    }
}

impl From<RenderError> for MakeError {
    fn from(e: RenderError) -> Self {
        match e {
            RenderError::Scene(e) => MakeError::Input(e.to_string()),
            RenderError::UnknownCamera { .. } => MakeError::Input(e.to_string()),
            other => MakeError::Runtime(other.to_string()),
        }
    }
}

impl From<VecEnvError> for MakeError {
    fn from(e: VecEnvError) -> Self {
        MakeError::Runtime(e.to_string())
    }
}

/// Options of [`make`] and [`make_vec`]; the default is the scene as written.
#[derive(Clone, Default)]
pub struct MakeOptions {
    /// Action modes of the (first) robot, RON, replacing the scene's, e.g.
    /// `(base: Velocity, arm: JointDelta, gripper: Off)` or `(discrete: true)` (`run --actions`).
    pub actions: Option<String>,
    /// A camera of the scene's render section whose RGB-D image is appended to the task's
    /// `policy` observation (`run --rgbd`; the task environments' robot camera is `robot`).
    pub rgbd: Option<String>,
    /// Compiled plugins (C ABI) added to every env's app before the scene is read
    /// (`--plugin`; load them once with [`load_plugins`]).
    pub plugins: Vec<Arc<DynamicPlugin>>,
    /// Env steps per episode, replacing the scene's `episode_steps` (its time limit).
    pub episode_steps: Option<u64>,
}

impl std::fmt::Debug for MakeOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MakeOptions")
            .field("actions", &self.actions)
            .field("rgbd", &self.rgbd)
            .field("plugins", &self.plugins.len())
            .field("episode_steps", &self.episode_steps)
            .finish()
    }
}

/// Envs of one target that share one compiled scene, and that scene.
pub struct Made {
    /// The envs (spawned, not yet reset).
    pub envs: Vec<Env>,
    /// The compiled scene (settings, `episode_steps`, render section, objects).
    pub model: Arc<SceneModel>,
}

/// One env (not yet reset) of a scene file or task id.
pub fn make(target: &str, opts: &MakeOptions) -> Result<Env, MakeError> {
    let mut made = make_envs(target, opts, 1)?;
    Ok(made.envs.remove(0))
}

/// `n` envs (at least 1) of a scene file or task id stepped by a [`VecEnv`] on `threads`
/// threads (0: all cores; 1: the calling thread).
pub fn make_vec(
    target: &str,
    opts: &MakeOptions,
    n: usize,
    threads: usize,
) -> Result<VecEnv, MakeError> {
    let made = make_envs(target, opts, n)?;
    Ok(VecEnv::new(made.envs, threads)?)
}

/// `n` envs (at least 1) of a scene file or task id, spawned from one compiled scene (16 envs
/// of Franka Place hold about 270 KB less each than 16 compiled apart), with that scene.
pub fn make_envs(target: &str, opts: &MakeOptions, n: usize) -> Result<Made, MakeError> {
    let (mut desc, source) = load_target(target)?;
    if let Some(a) = &opts.actions {
        override_actions(&mut desc, a)?;
    }
    if let Some(c) = &opts.rgbd {
        override_rgbd(&mut desc, c)?;
    }
    if opts.episode_steps == Some(0) {
        return Err(MakeError::Input(
            "episode_steps = 0: at least 1 env step per episode".into(),
        ));
    }
    let first = app_with_plugins(&opts.plugins)?;
    let model = first.compile_scene(&desc, &source)?;
    let mut apps = vec![first];
    for _ in 1..n.max(1) {
        apps.push(app_with_plugins(&opts.plugins)?);
    }
    let envs = apps
        .into_iter()
        .map(|mut app| {
            spawn_with_cameras(&mut app, model.clone())?;
            if let Some(n) = opts.episode_steps {
                app.world.insert_resource(EpisodeLimit(Some(n)));
            }
            Ok(Env::new(app))
        })
        .collect::<Result<Vec<_>, MakeError>>()?;
    Ok(Made { envs, model })
}

/// An env (default plugins, not yet reset) of a scene file or task id, with optional action
/// modes replacing the first robot's (see `run --actions`).
pub fn env_for_target(target: &str, actions: Option<&str>) -> Result<Env, MakeError> {
    let mut envs = envs_for_target(target, actions, 1)?;
    Ok(envs.remove(0))
}

/// `n` (at least 1) envs of a scene file or task id, as [`env_for_target`] makes one, that
/// share one compiled scene (see [`make_envs`]).
pub fn envs_for_target(
    target: &str,
    actions: Option<&str>,
    n: usize,
) -> Result<Vec<Env>, MakeError> {
    let opts = MakeOptions {
        actions: actions.map(str::to_string),
        ..MakeOptions::default()
    };
    Ok(make_envs(target, &opts, n)?.envs)
}

/// A fresh app with every default plugin.
pub fn default_app() -> SimApp {
    let mut app = SimApp::new();
    app.add_group(crate::DefaultPlugins);
    app
}

/// Loads compiled plugins (once; every env shares them).
pub fn load_plugins(paths: &[PathBuf]) -> Result<Vec<Arc<DynamicPlugin>>, PluginLoadError> {
    paths.iter().map(DynamicPlugin::load).collect()
}

/// A fresh app with every default plugin and the given compiled plugins.
pub fn app_with_plugins(plugins: &[Arc<DynamicPlugin>]) -> Result<SimApp, PluginLoadError> {
    let mut app = default_app();
    for p in plugins {
        app.add_dynamic_plugin(p.clone())?;
    }
    Ok(app)
}

/// Spawns `model` into `app` and, when the task observes camera images, attaches a renderer
/// (the shared device) so the cameras are rendered in each env's `Sense` pass.
pub fn spawn_with_cameras(app: &mut SimApp, model: Arc<SceneModel>) -> Result<(), MakeError> {
    app.spawn_scene(model)?;
    let wants = app
        .world
        .get_resource::<modesuite_render::CameraRequests>()
        .is_some_and(|r| !r.0.is_empty());
    if wants {
        modesuite_render::prepare(app)?;
    }
    Ok(())
}

/// An env of a scene given as RON text (in-memory source, paths relative to the working
/// directory), with every default plugin.
pub fn env_from_text(text: &str) -> Result<Env, SceneError> {
    let desc = scene::parse_str(text, "<memory>")?;
    let mut app = default_app();
    let model = app.compile_scene(&desc, &SceneSource::in_memory("."))?;
    app.spawn_scene(model)?;
    Ok(Env::new(app))
}

/// The scenes folder task ids resolve in: `$MODESUITE_SCENES`, else the repository's `scenes/`
/// (the library falls back to its embedded copies of the task files).
pub fn scenes_dir() -> PathBuf {
    std::env::var_os("MODESUITE_SCENES")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes"))
}

/// Loads a scene file or a task id (`MoDe-<Robot>-<Task>-v0`).
pub fn load_target(target: &str) -> Result<(SceneDesc, SceneSource), MakeError> {
    let path = Path::new(target);
    if path.is_file() {
        return Ok(scene::load_file(path)?);
    }
    if target.starts_with("MoDe-") {
        let dir = scenes_dir();
        let file = modesuite_tasks::task_scene_path(&dir, target).map_err(MakeError::Input)?;
        if file.is_file() {
            return Ok(scene::load_file(&file)?);
        }
        let rel = file
            .strip_prefix(&dir)
            .map(|r| r.to_string_lossy().replace('\\', "/"))
            .unwrap_or_default();
        let text = modesuite_tasks::embedded(&rel)
            .ok_or_else(|| MakeError::Input(format!("{target}: {} is missing", file.display())))?;
        let label = format!("{}/{rel}", modesuite_tasks::EMBEDDED_DIR);
        let desc = scene::parse_str(text, &label)?;
        let folder = Path::new(&label)
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default();
        return Ok((desc, SceneSource::in_memory(folder)));
    }
    Err(MakeError::Input(format!(
        "{target}: no such scene file, and not a task id (MoDe-<Robot>-<Task>-v0)"
    )))
}

/// Replaces the `actions` of the first robot of the scene's `robots` section with `ron_text`.
pub fn override_actions(desc: &mut SceneDesc, ron_text: &str) -> Result<(), MakeError> {
    let bad = |m: &str| MakeError::Input(format!("actions = {ron_text}: {m}"));
    modesuite_robots::ActionConfig::parse_ron(ron_text).map_err(|e| bad(&e))?;
    let raw = desc
        .extensions
        .get("robots")
        .ok_or_else(|| bad("the scene has no robots section"))?;
    let text = raw.get_ron().to_string();
    let new = match text.find("actions:") {
        Some(k) => {
            let open = k + text[k..]
                .find('(')
                .ok_or_else(|| bad("unreadable robots section"))?;
            let mut depth = 0usize;
            let mut end = None;
            for (i, c) in text[open..].char_indices() {
                match c {
                    '(' => depth += 1,
                    ')' => {
                        depth -= 1;
                        if depth == 0 {
                            end = Some(open + i + 1);
                            break;
                        }
                    }
                    _ => {}
                }
            }
            let end = end.ok_or_else(|| bad("unreadable robots section"))?;
            format!("{}actions: {ron_text}{}", &text[..k], &text[end..])
        }
        None => {
            let k = text
                .find("(name:")
                .ok_or_else(|| bad("the robots section lists no robot"))?;
            format!("{}(actions: {ron_text}, {}", &text[..k], &text[k + 1..])
        }
    };
    let value = ron::value::RawValue::from_boxed_ron(new.into_boxed_str())
        .map_err(|e| bad(&e.to_string()))?;
    desc.extensions.insert("robots".into(), value);
    Ok(())
}

/// Appends an RGB-D image of `camera` to the task's `policy` observation group (`run --rgbd`):
/// sets the task section's `camera_observation`.
pub fn override_rgbd(desc: &mut SceneDesc, camera: &str) -> Result<(), MakeError> {
    let bad = |m: &str| MakeError::Input(format!("rgbd camera {camera:?}: {m}"));
    if camera.is_empty() || camera.contains(['"', '\\']) {
        return Err(bad("a camera name of the scene's render section"));
    }
    let raw = desc
        .extensions
        .get("task")
        .ok_or_else(|| bad("the scene has no task section"))?;
    let text = raw.get_ron();
    let open = text
        .find('(')
        .ok_or_else(|| bad("unreadable task section"))?;
    let new = format!(
        "{}(camera_observation: Some((camera: \"{camera}\", channels: Rgbd)), {}",
        &text[..open],
        &text[open + 1..]
    );
    let value = ron::value::RawValue::from_boxed_ron(new.into_boxed_str())
        .map_err(|e| bad(&e.to_string()))?;
    desc.extensions.insert("task".into(), value);
    Ok(())
}
