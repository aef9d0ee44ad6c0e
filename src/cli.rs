//! The `modesuite` command-line tool.
//!
//! Public contracts (outside scripts rely on them; extend, never rename):
//! - `modesuite run SCENE_OR_TASK [--steps N] [--seed S] [--episodes E] [--dump-state FILE.json] [--json]`
//!   `--dump-state` writes the `modesuite.state.v1` JSON of [`modesuite_engine::dump`] after the
//!   last step; `--json` prints one JSON object per episode (`episode`, `seed`, `return`, `length`,
//!   `success`, `error`, `wall_s`, `steps_per_s`) and a final summary object (`summary: true`,
//!   `episodes`, `success_rate`, `mean_return`, `mean_length`, `errors`, `env_steps_per_s`).
//!   `--video FILE.gif|FILE.mp4` records the episodes (MP4 needs ffmpeg) and `--frames DIR` writes
//!   PNG frames, from `--camera NAME` (a camera of the scene's render section) or a default orbit
//!   camera framing the scene; recording never changes the simulation.
//! - `modesuite bench NAME [--json]`: with `--json`, one JSON object per line per case with at
//!   least `case`, `steps_per_s`, `threads`, `envs` (for `bench render`, images per second).
//! - `modesuite view SCENE_OR_TASK [--seed S] [--record FILE.json]`: the interactive viewer.
//! - `--plugin PATH` (repeatable) on `run`, `validate` and `list` loads a compiled plugin (C ABI,
//!   see `modesuite_engine::dynamic`); nothing is ever loaded because a scene names it.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use clap::{Parser, Subcommand};
use serde_json::json;

use modesuite_engine::bench::{BenchOptions, BenchRecord};
use modesuite_engine::prelude::*;
use modesuite_engine::scene::{self, SceneModel};
use modesuite_engine::{DynamicPlugin, PluginLoadError};
use modesuite_render::video::{write_frame_png, VideoWriter};
use modesuite_render::{CameraDesc, EnvRenderer, Orbit, RenderConfig, RenderError};

/// Command-line arguments.
#[derive(Parser, Debug)]
#[command(
    name = "modesuite",
    version,
    about = "Mobile manipulation of deformable objects: simulator and benchmark",
    long_about = "Mobile manipulation of deformable objects: simulator and benchmark.\n\nWithout a command, runs the embedded default scene and prints its metrics."
)]
pub struct Cli {
    /// What to do (default: run the embedded default).
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// Subcommands.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// List tasks, robots, shapes, body kinds, terms, sensors and plugins.
    List {
        /// Only this category: tasks, robots, shapes, body-kinds, terms, forces, sensors, plugins.
        what: Option<String>,
        /// Load a compiled plugin (C ABI) first; repeatable.
        #[arg(long)]
        plugin: Vec<PathBuf>,
    },
    /// Parse, validate and compile scene files; exit 2 on the first error.
    Validate {
        /// Scene files (`*.scene.ron`).
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Load a compiled plugin (C ABI) first; repeatable.
        #[arg(long)]
        plugin: Vec<PathBuf>,
    },
    /// Run a scene file or a task id and report per-episode metrics.
    Run(RunArgs),
    /// Open the interactive viewer (orbit camera, pause/step/reset, keyboard teleoperation).
    View(ViewArgs),
    /// Run a benchmark suite: engine, fem, pbd, robots, render, tasks.
    Bench {
        /// Suite name.
        name: String,
        /// One JSON object per line per case.
        #[arg(long)]
        json: bool,
        /// Scale the number of steps (e.g. 0.1 for a quick run).
        #[arg(long, default_value_t = 1.0)]
        scale: f64,
        /// Threads for the all-core cases (0 = all cores).
        #[arg(long, default_value_t = 0)]
        threads: usize,
    },
}

/// Arguments of `run`.
#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// A `*.scene.ron` file or a task id (`MoDe-<Robot>-<Task>-v0`).
    pub target: String,
    /// Env steps per episode (default: the scene's `episode_steps`, else 600).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Seed of the first episode (episode i uses seed + i).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Number of episodes.
    #[arg(long, default_value_t = 1)]
    pub episodes: u64,
    /// Write the final state (modesuite.state.v1 JSON) to this file.
    #[arg(long)]
    pub dump_state: Option<PathBuf>,
    /// Print one JSON object per episode and a summary object.
    #[arg(long)]
    pub json: bool,
    /// Load a compiled plugin (C ABI) before reading the scene; repeatable.
    #[arg(long)]
    pub plugin: Vec<PathBuf>,
    /// Record a video of the run: `.gif` (built in) or `.mp4` (needs ffmpeg).
    #[arg(long)]
    pub video: Option<PathBuf>,
    /// Write every recorded frame as a PNG into this folder.
    #[arg(long)]
    pub frames: Option<PathBuf>,
    /// Record from this camera of the scene's render section (default: an orbit camera).
    #[arg(long)]
    pub camera: Option<String>,
    /// Size of the default orbit camera, WIDTHxHEIGHT.
    #[arg(long, default_value = "480x320")]
    pub video_size: String,
    /// Draw contact (red) and grasp (yellow) markers and a line of text (episode, step,
    /// reward, return, success) into the recorded frames.
    #[arg(long)]
    pub overlays: bool,
    /// Who acts: `zero` (all-zero action), `random` (uniform over the action space, seeded by
    /// the episode seed) or `scripted` (the task's expert).
    #[arg(long, default_value = "zero")]
    pub policy: String,
    /// Action modes of the (first) robot for this run, RON, replacing the scene's, e.g.
    /// `(base: Velocity, arm: JointDelta, gripper: Off)`.
    #[arg(long)]
    pub actions: Option<String>,
    /// Appends an RGB-D image of this camera of the scene's render section to the task's
    /// `policy` observation (the task environments' robot camera is `robot`, 128 x 128).
    #[arg(long, value_name = "CAMERA")]
    pub rgbd: Option<String>,
}

/// Arguments of `view`.
#[derive(clap::Args, Debug)]
pub struct ViewArgs {
    /// A `*.scene.ron` file or a task id.
    pub target: String,
    /// Seed of the first episode (each reset uses the next).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Write the teleoperation recording (seed + actions, JSON) here on exit.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Folder for screenshots (key `p`).
    #[arg(long, default_value = ".")]
    pub screenshot_dir: PathBuf,
    /// Window size, WIDTHxHEIGHT.
    #[arg(long, default_value = "960x640")]
    pub size: String,
    /// Start paused.
    #[arg(long)]
    pub paused: bool,
    /// Action modes of the (first) robot, RON, replacing the scene's; `(discrete: true)` gives
    /// the 14 teleoperation keys to any robot scene or task.
    #[arg(long)]
    pub actions: Option<String>,
    /// Write the state when the viewer closes (modesuite.state.v1 JSON, as `run --dump-state`).
    #[arg(long)]
    pub dump_state: Option<PathBuf>,
}

/// A CLI failure: the message and the exit code (2 = bad input, 1 = runtime failure).
#[derive(Debug)]
pub struct CliError {
    /// What went wrong, for stderr.
    pub message: String,
    /// Process exit code.
    pub code: i32,
}

impl std::fmt::Display for CliError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl CliError {
    fn input(message: impl Into<String>) -> Self {
        Self {
            message: message.into(),
            code: 2,
        }
    }
    fn runtime(message: impl Into<String>) -> Self {
        Self {
            message: message.into(),
            code: 1,
        }
    }
}

impl From<SceneError> for CliError {
    fn from(e: SceneError) -> Self {
        Self::input(e.to_string())
    }
}

impl From<PluginLoadError> for CliError {
    fn from(e: PluginLoadError) -> Self {
        Self::input(format!("--plugin: {e}"))
    }
}

/// A fresh app with every default plugin.
pub fn default_app() -> SimApp {
    let mut app = SimApp::new();
    app.add_group(crate::DefaultPlugins);
    app
}

/// Spawns `model` into `app` and, when the task observes camera images, attaches a renderer
/// (the shared device) so the cameras are rendered in each env's `Sense` pass.
pub fn spawn_with_cameras(
    app: &mut SimApp,
    model: Arc<modesuite_engine::SceneModel>,
) -> Result<(), CliError> {
    app.spawn_scene(model)?;
    let wants = app
        .world
        .get_resource::<modesuite_render::CameraRequests>()
        .is_some_and(|r| !r.0.is_empty());
    if wants {
        modesuite_render::prepare(app).map_err(render_err)?;
    }
    Ok(())
}

/// Appends an RGB-D image of `camera` to the task's `policy` observation group (`run --rgbd`):
/// sets the task section's `camera_observation`.
pub fn override_rgbd(desc: &mut SceneDesc, camera: &str) -> Result<(), CliError> {
    let bad = |m: &str| CliError::input(format!("--rgbd {camera}: {m}"));
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

/// An env of a scene given as RON text (in-memory source, paths relative to the working
/// directory), with every default plugin.
pub fn env_from_text(text: &str) -> Result<Env, SceneError> {
    let desc = modesuite_engine::scene::parse_str(text, "<memory>")?;
    let mut app = default_app();
    let model = app.compile_scene(&desc, &SceneSource::in_memory("."))?;
    app.spawn_scene(model)?;
    Ok(Env::new(app))
}

/// An env (default plugins, not yet reset) of a scene file or task id, with optional action
/// modes replacing the first robot's (see `run --actions`).
pub fn env_for_target(target: &str, actions: Option<&str>) -> Result<Env, CliError> {
    let mut envs = envs_for_target(target, actions, 1)?;
    Ok(envs.remove(0))
}

/// `n` (at least 1) envs of a scene file or task id, as [`env_for_target`] makes one, that
/// share one compiled scene (FEM models, robot models, meshes behind `Arc`): the scene is
/// compiled once, and 16 envs of Franka Place hold about 270 KB less each than 16 compiled
/// apart (for a `VecEnv`).
pub fn envs_for_target(
    target: &str,
    actions: Option<&str>,
    n: usize,
) -> Result<Vec<Env>, CliError> {
    let (mut desc, source) = load_target(target)?;
    if let Some(a) = actions {
        override_actions(&mut desc, a)?;
    }
    let first = default_app();
    let model = first.compile_scene(&desc, &source)?;
    std::iter::once(first)
        .chain((1..n.max(1)).map(|_| default_app()))
        .map(|mut app| {
            spawn_with_cameras(&mut app, model.clone())?;
            Ok(Env::new(app))
        })
        .collect()
}

/// Loads the compiled plugins named by `--plugin` (once; every env shares them).
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

/// Runs the CLI; returns the process exit code's error on failure.
pub fn run_cli(cli: Cli, out: &mut dyn Write) -> Result<(), CliError> {
    match cli.command {
        None => run_default(out),
        Some(Command::List { what, plugin }) => list(what.as_deref(), &load_plugins(&plugin)?, out),
        Some(Command::Validate { files, plugin }) => validate(&files, &load_plugins(&plugin)?, out),
        Some(Command::Run(args)) => run(&args, out),
        Some(Command::View(args)) => view(&args, out),
        Some(Command::Bench {
            name,
            json,
            scale,
            threads,
        }) => bench(&name, json, scale, threads, out),
    }
}

fn io(e: std::io::Error) -> CliError {
    CliError::runtime(format!("output: {e}"))
}

fn run_default(out: &mut dyn Write) -> Result<(), CliError> {
    let video = PathBuf::from(crate::DEFAULT_VIDEO);
    writeln!(
        out,
        "modesuite: the embedded default: {} with its scripted expert, one episode, video {}\n(the same as `modesuite run {} --policy scripted --video {}`)",
        crate::DEFAULT_TASK,
        video.display(),
        crate::DEFAULT_TASK,
        video.display()
    )
    .map_err(io)?;
    if let Some(dir) = video.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .map_err(|e| CliError::runtime(format!("{}: {e}", dir.display())))?;
    }
    let args = RunArgs {
        target: crate::DEFAULT_TASK.to_string(),
        steps: None,
        seed: 0,
        episodes: 1,
        dump_state: None,
        json: false,
        plugin: Vec::new(),
        video: Some(video),
        frames: None,
        camera: None,
        video_size: "480x320".into(),
        overlays: false,
        policy: "scripted".into(),
        rgbd: None,
        actions: None,
    };
    run(&args, out)
}

fn list(
    what: Option<&str>,
    plugins: &[Arc<DynamicPlugin>],
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let app = app_with_plugins(plugins)?;
    let reg = app.registry();
    let all = what.is_none();
    let want = |k: &str| all || what == Some(k);
    let valid = [
        "tasks",
        "robots",
        "shapes",
        "body-kinds",
        "terms",
        "forces",
        "sensors",
        "plugins",
    ];
    if let Some(w) = what {
        if !valid.contains(&w) {
            return Err(CliError::input(format!(
                "list {w}: unknown category; valid: {}",
                valid.join(", ")
            )));
        }
    }
    let mut section = |title: &str, items: Vec<(String, String)>| -> Result<(), CliError> {
        writeln!(out, "{title}:").map_err(io)?;
        if items.is_empty() {
            writeln!(out, "  (none in this build)").map_err(io)?;
        }
        for (n, d) in items {
            writeln!(out, "  {n:<28} {d}").map_err(io)?;
        }
        Ok(())
    };
    if want("tasks") {
        section(
            "tasks",
            modesuite_tasks::all_ids()
                .into_iter()
                .map(|id| {
                    let d = if modesuite_tasks::IMPLEMENTED.contains(&id.as_str()) {
                        "implemented, with a scripted expert"
                    } else {
                        "not implemented yet"
                    };
                    (id, d.to_string())
                })
                .collect(),
        )?;
    }
    if want("robots") {
        section(
            "robots",
            reg.robots
                .values()
                .map(|r| (r.name.clone(), r.description.clone()))
                .collect(),
        )?;
    }
    if want("shapes") {
        let mut items: Vec<(String, String)> = [
            ("Box", "box; volume mesh: hex grid, 6 tets per hex"),
            ("Sphere", "sphere (surface)"),
            ("Cylinder", "cylinder along z; volume mesh: swept disk"),
            ("Capsule", "capsule along z (surface)"),
            ("Plane", "static half space z <= 0 (surface: a quad)"),
            ("Grid", "cloth sheet in the xy plane"),
            ("Polyline", "a path (used by Sweep)"),
            (
                "Revolve",
                "profile revolved about z: torus, ring; volume mesh",
            ),
            (
                "Sweep",
                "profile swept along a path: belt, tube; volume mesh",
            ),
            ("Extrude", "polygon extruded along z; volume mesh"),
            ("Mesh", "OBJ/STL surface, gmsh .msh v4 / medit .mesh volume"),
        ]
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
        items.extend(reg.shapes.values().map(|g| {
            (
                format!("Gen(\"{}\")", g.name()),
                g.description().to_string(),
            )
        }));
        section("shapes", items)?;
    }
    if want("body-kinds") {
        let mut items: Vec<(String, String)> = vec![
            ("Static".into(), "rigid, never moves".into()),
            ("Dynamic".into(), "rigid, simulated (rapier)".into()),
            ("Kinematic".into(), "rigid, moved by the program".into()),
        ];
        items.extend(
            reg.body_kinds
                .values()
                .map(|k| (k.name().to_string(), k.description().to_string())),
        );
        section("body kinds", items)?;
    }
    if want("terms") {
        section(
            "terms",
            reg.terms
                .values()
                .map(|t| (t.name.clone(), format!("{:?}: {}", t.kind, t.description)))
                .collect(),
        )?;
    }
    if want("forces") {
        section(
            "passive forces",
            reg.forces
                .values()
                .map(|f| (f.name().to_string(), f.description().to_string()))
                .collect(),
        )?;
    }
    if want("sensors") {
        section(
            "sensors",
            reg.sensors
                .values()
                .map(|s| (s.name.clone(), s.description.clone()))
                .collect(),
        )?;
    }
    if want("plugins") {
        section(
            "plugins",
            app.plugin_names()
                .into_iter()
                .map(|n| {
                    let loaded = plugins.iter().find(|p| p.plugin_name() == n);
                    let d = loaded.map_or_else(String::new, |p| {
                        format!("{} (compiled, {})", p.description(), p.path().display())
                    });
                    (n, d)
                })
                .collect(),
        )?;
    }
    Ok(())
}

fn compile_file(
    path: &Path,
    plugins: &[Arc<DynamicPlugin>],
) -> Result<(Arc<SceneModel>, SimApp), CliError> {
    let (desc, source) = scene::load_file(path)?;
    let app = app_with_plugins(plugins)?;
    let model = app.compile_scene(&desc, &source)?;
    Ok((model, app))
}

fn validate(
    files: &[PathBuf],
    plugins: &[Arc<DynamicPlugin>],
    out: &mut dyn Write,
) -> Result<(), CliError> {
    for f in files {
        let (model, _) = compile_file(f, plugins)?;
        RenderConfig::from_scene(&model)?;
        writeln!(
            out,
            "{}: ok ({} objects, dt {} s x {} substeps, decimation {})",
            f.display(),
            model.objects.len(),
            model.settings.dt,
            model.settings.substeps,
            model.settings.decimation
        )
        .map_err(io)?;
    }
    Ok(())
}

/// The scenes folder task ids resolve in: `$MODESUITE_SCENES`, else the repository's `scenes/`
/// (the binary falls back to its embedded copies of the task files).
pub fn scenes_dir() -> PathBuf {
    std::env::var_os("MODESUITE_SCENES")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes"))
}

/// Loads a scene file or a task id (`MoDe-<Robot>-<Task>-v0`) named on the command line.
pub fn load_target(target: &str) -> Result<(SceneDesc, SceneSource), CliError> {
    let path = Path::new(target);
    if path.is_file() {
        return Ok(scene::load_file(path)?);
    }
    if target.starts_with("MoDe-") {
        let dir = scenes_dir();
        let file = modesuite_tasks::task_scene_path(&dir, target).map_err(CliError::input)?;
        if file.is_file() {
            return Ok(scene::load_file(&file)?);
        }
        let rel = file
            .strip_prefix(&dir)
            .map(|r| r.to_string_lossy().replace('\\', "/"))
            .unwrap_or_default();
        let text = modesuite_tasks::embedded(&rel)
            .ok_or_else(|| CliError::input(format!("{target}: {} is missing", file.display())))?;
        let label = format!("{}/{rel}", modesuite_tasks::EMBEDDED_DIR);
        let desc = scene::parse_str(text, &label)?;
        let folder = Path::new(&label)
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default();
        return Ok((desc, SceneSource::in_memory(folder)));
    }
    Err(CliError::input(format!(
        "{target}: no such scene file, and not a task id (MoDe-<Robot>-<Task>-v0)"
    )))
}

/// Replaces the `actions` of the first robot of the scene's `robots` section with `ron`.
pub fn override_actions(desc: &mut SceneDesc, ron_text: &str) -> Result<(), CliError> {
    let bad = |m: &str| CliError::input(format!("--actions {ron_text}: {m}"));
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

fn run(args: &RunArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let plugins = load_plugins(&args.plugin)?;
    let (mut desc, source) = load_target(&args.target)?;
    if let Some(a) = &args.actions {
        override_actions(&mut desc, a)?;
    }
    if let Some(c) = &args.rgbd {
        override_rgbd(&mut desc, c)?;
    }
    run_scene(&desc, &source, args, &plugins, out)
}

/// Parses `WIDTHxHEIGHT`.
fn parse_size(flag: &str, s: &str) -> Result<(u32, u32), CliError> {
    let bad = || {
        CliError::input(format!(
            "{flag} = {s:?}: WIDTHxHEIGHT in pixels, each in 1..=8192, e.g. 480x320"
        ))
    };
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let w: u32 = w.trim().parse().map_err(|_| bad())?;
    let h: u32 = h.trim().parse().map_err(|_| bad())?;
    if !(1..=8192).contains(&w) || !(1..=8192).contains(&h) {
        return Err(bad());
    }
    Ok((w, h))
}

fn render_err(e: RenderError) -> CliError {
    match e {
        RenderError::Scene(e) => CliError::input(e.to_string()),
        RenderError::UnknownCamera { .. } => CliError::input(e.to_string()),
        other => CliError::runtime(other.to_string()),
    }
}

/// Records frames of a run into a video and/or PNG files.
struct Recorder {
    renderer: EnvRenderer,
    camera: Option<CameraDesc>,
    camera_name: Option<String>,
    size: (u32, u32),
    video_path: Option<PathBuf>,
    video: Option<VideoWriter>,
    frames_dir: Option<PathBuf>,
    every: u64,
    fps: f64,
    written: u64,
    overlays: bool,
}

impl Recorder {
    fn new(model: &std::sync::Arc<SceneModel>, args: &RunArgs) -> Result<Option<Self>, CliError> {
        if args.video.is_none() && args.frames.is_none() {
            if args.camera.is_some() {
                return Err(CliError::input(
                    "--camera: only used with --video or --frames",
                ));
            }
            return Ok(None);
        }
        let size = parse_size("--video-size", &args.video_size)?;
        if let Some(dir) = &args.frames {
            std::fs::create_dir_all(dir).map_err(|e| {
                CliError::runtime(format!("--frames {}: cannot create: {e}", dir.display()))
            })?;
        }
        let renderer = EnvRenderer::for_scene(model.clone()).map_err(render_err)?;
        if let Some(name) = &args.camera {
            renderer.scene_camera(name).map_err(render_err)?;
        }
        // About 30 frames per second of simulated time.
        let step_dt = model.settings.dt * model.settings.decimation as f64;
        let every = ((1.0 / (30.0 * step_dt)).round() as u64).max(1);
        Ok(Some(Self {
            renderer,
            camera: None,
            camera_name: args.camera.clone(),
            size,
            video_path: args.video.clone(),
            video: None,
            frames_dir: args.frames.clone(),
            every,
            fps: 1.0 / (every as f64 * step_dt),
            written: 0,
            overlays: args.overlays,
        }))
    }

    /// Renders and writes the current frame when `step` is on the recording stride; with
    /// `--overlays` also the markers and the text `status` makes (only called then).
    fn capture(
        &mut self,
        world: &World,
        step: u64,
        status: impl FnOnce() -> String,
    ) -> Result<(), CliError> {
        if !step.is_multiple_of(self.every) {
            return Ok(());
        }
        let mut cam = match (&self.camera, &self.camera_name) {
            (Some(c), _) => c.clone(),
            (None, Some(name)) => self
                .renderer
                .scene_camera(name)
                .map_err(render_err)?
                .clone(),
            (None, None) => {
                let c = self.renderer.orbit_camera(
                    world,
                    "orbit",
                    self.size.0,
                    self.size.1,
                    Orbit::default(),
                );
                self.camera = Some(c.clone());
                c
            }
        };
        cam.overlays = self.overlays;
        let frames = self
            .renderer
            .render_cameras(world, std::slice::from_ref(&cam))
            .map_err(render_err)?;
        let Some(mut frame) = frames.into_iter().next() else {
            return Ok(());
        };
        if self.overlays {
            let (w, h) = (frame.width, frame.height);
            let lines = [status()];
            modesuite_render::hud::draw_text(&mut frame.rgb, w, h, 3, (4, 4), 1, &lines, [255; 3]);
        }
        let frame = &frame;
        if let Some(dir) = &self.frames_dir {
            let path = dir.join(format!("frame_{:05}.png", self.written));
            write_frame_png(&path, frame).map_err(render_err)?;
        }
        if let Some(path) = &self.video_path {
            if self.video.is_none() {
                self.video = Some(
                    VideoWriter::create(path, frame.width, frame.height, self.fps)
                        .map_err(render_err)?,
                );
            }
            if let Some(v) = self.video.as_mut() {
                v.push(frame).map_err(render_err)?;
            }
        }
        self.written += 1;
        Ok(())
    }

    fn finish(self, out: &mut dyn Write, quiet: bool) -> Result<(), CliError> {
        let frames = match self.video {
            Some(v) => v.finish().map_err(render_err)?,
            None => self.written as usize,
        };
        if !quiet {
            let mut what = Vec::new();
            if let Some(p) = &self.video_path {
                what.push(format!("video {}", p.display()));
            }
            if let Some(d) = &self.frames_dir {
                what.push(format!("PNG frames in {}", d.display()));
            }
            writeln!(
                out,
                "recorded {frames} frames at {:.1} fps ({}; {})",
                self.fps,
                what.join(", "),
                self.renderer.device().adapter_name()
            )
            .map_err(io)?;
        }
        Ok(())
    }
}

fn view(args: &ViewArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let size = parse_size("--size", &args.size)?;
    let (mut desc, source) = load_target(&args.target)?;
    if let Some(a) = &args.actions {
        override_actions(&mut desc, a)?;
    }
    let mut app = default_app();
    let model = app.compile_scene(&desc, &source)?;
    RenderConfig::from_scene(&model)?;
    app.spawn_scene(model)?;
    let env = Env::new(app);
    let opts = modesuite_render::viewer::ViewerOptions {
        label: args.target.clone(),
        seed: args.seed,
        record: args.record.clone(),
        screenshot_dir: args.screenshot_dir.clone(),
        size,
        paused: args.paused,
    };
    let (summary, mut env) = modesuite_render::viewer::run_viewer(env, opts).map_err(render_err)?;
    if let Some(path) = &args.dump_state {
        let length = env
            .app
            .world
            .resource::<modesuite_engine::SimClock>()
            .episode_steps;
        dump_final(&mut env, &args.target, args.seed, length, path)?;
    }
    writeln!(
        out,
        "viewer closed: {} env steps, {} frames, {} teleoperation actions, {} screenshots{}",
        summary.steps,
        summary.frames,
        summary.actions,
        summary.screenshots.len(),
        args.record
            .as_ref()
            .map_or(String::new(), |p| format!(", recording {}", p.display()))
    )
    .map_err(io)
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

fn run_scene(
    desc: &SceneDesc,
    source: &SceneSource,
    args: &RunArgs,
    plugins: &[Arc<DynamicPlugin>],
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let mut app = app_with_plugins(plugins)?;
    let model = app.compile_scene(desc, source)?;
    let steps = args.steps.or(model.episode_steps).unwrap_or(600);
    if steps == 0 {
        return Err(CliError::input("--steps = 0: must be at least 1"));
    }
    if args.episodes == 0 {
        return Err(CliError::input("--episodes = 0: must be at least 1"));
    }
    RenderConfig::from_scene(&model)?;
    let mut recorder = Recorder::new(&model, args)?;
    spawn_with_cameras(&mut app, model)?;
    let mut env = Env::new(app);
    // The CLI resets between episodes itself, so the final state stays for --dump-state.
    env.autoreset = false;
    let act_dim = env.spaces().action.flat_dim();
    let mut action = vec![0.0f32; act_dim];
    let kind: modesuite_tasks::PolicyKind = args.policy.parse().map_err(CliError::input)?;
    let mut policy = modesuite_tasks::make_policy(kind, &env).map_err(CliError::input)?;
    if !args.json {
        writeln!(
            out,
            "{:>7} {:>12} {:>8} {:>7} {:>9} {:>12}  end",
            "episode", "return", "success", "steps", "time_s", "steps/s"
        )
        .map_err(io)?;
    }
    let mut total_steps = 0u64;
    let mut total_time = 0.0;
    let mut returns = Vec::new();
    let mut lengths = Vec::new();
    let mut successes = Vec::new();
    let mut errors = 0u64;
    // episodes per way of ending (`ended` of the JSON summary)
    let mut ends: std::collections::BTreeMap<&'static str, u64> = Default::default();
    let mut progress = Progress::new(steps * args.episodes);
    for ep in 0..args.episodes {
        let seed = args.seed.wrapping_add(ep);
        env.reset(Some(seed));
        policy.reset(seed);
        if let Some(r) = recorder.as_mut() {
            r.capture(&env.app.world, 0, || {
                format!("episode {ep}  seed {seed}  step 0")
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
            if let Err(e) = policy.act(&env, &mut action) {
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
                        "episode {ep}  step {length}  reward {:.3}  return {ret:.3}  success {}",
                        o.reward,
                        o.info.success.map_or("-".to_string(), |s| s.to_string())
                    )
                })?;
            }
            progress.update(ep * steps + i + 1);
            if o.terminated || o.truncated {
                success = final_success(success, o.info.success, o.info.error.is_some());
                error = o.info.error.clone();
                end = EpisodeEnd::of(&o);
                break;
            }
            success = o.info.success;
        }
        // The last dumped state is the state after the final step (before any autoreset).
        if ep + 1 == args.episodes {
            if let Some(path) = &args.dump_state {
                dump_final(&mut env, &args.target, seed, length, path)?;
            }
        }
        let wall = t.elapsed().as_secs_f64();
        total_steps += length;
        total_time += wall;
        returns.push(ret);
        lengths.push(length);
        if let Some(s) = success {
            successes.push(s);
        }
        if error.is_some() {
            errors += 1;
        }
        *ends.entry(end.name()).or_default() += 1;
        let sps = length as f64 / wall.max(1e-12);
        if args.json {
            writeln!(
                out,
                "{}",
                json!({"episode": ep, "seed": seed, "return": ret, "length": length,
                       "success": success, "error": error, "ended": end.name(),
                       "terminations": end.terminations(), "wall_s": wall, "steps_per_s": sps})
            )
            .map_err(io)?;
        } else {
            writeln!(
                out,
                "{:>7} {:>12.4} {:>8} {:>7} {:>9.3} {:>12.0}  {}",
                ep,
                ret,
                success.map_or("-".to_string(), |s| s.to_string()),
                length,
                wall,
                sps,
                match &error {
                    Some(e) => format!("error: {e}"),
                    None => end.to_string(),
                }
            )
            .map_err(io)?;
        }
    }
    progress.finish();
    if let Some(r) = recorder {
        r.finish(out, args.json)?;
    }
    let n = args.episodes as f64;
    let mean_return = returns.iter().sum::<f64>() / n;
    let mean_length = lengths.iter().sum::<u64>() as f64 / n;
    let success_rate = if successes.is_empty() {
        None
    } else {
        Some(successes.iter().filter(|s| **s).count() as f64 / successes.len() as f64)
    };
    let sps = total_steps as f64 / total_time.max(1e-12);
    if args.json {
        writeln!(
            out,
            "{}",
            json!({"summary": true, "target": args.target, "episodes": args.episodes,
                   "success_rate": success_rate, "mean_return": mean_return,
                   "mean_length": mean_length, "errors": errors, "ended": ends,
                   "env_steps_per_s": sps})
        )
        .map_err(io)?;
    } else {
        writeln!(
            out,
            "summary: {} episodes, success rate {}, mean return {:.4}, mean length {:.1}, errors {}, {:.0} env steps/s",
            args.episodes,
            success_rate.map_or("n/a (no success criterion)".to_string(), |r| format!("{:.1} %", 100.0 * r)),
            mean_return,
            mean_length,
            errors,
            sps
        )
        .map_err(io)?;
    }
    Ok(())
}

/// How a run's episode ended (`run --json`'s `ended` and `terminations`).
#[derive(Debug, Clone, PartialEq)]
enum EpisodeEnd {
    /// Terminated with the task's success.
    Success,
    /// Terminated without success: a failure termination term fired (names of those that did,
    /// from the step's `termination/<name>` values; empty when another system ended it).
    Failure(Vec<String>),
    /// Truncated by the scene's time limit (`episode_steps`).
    TimeLimit,
    /// Ended by an error (physics blow-up, bad action, plugin or policy failure).
    Error,
    /// Still running when the run's `--steps` were done.
    Steps,
}

impl EpisodeEnd {
    /// The end of the step `o` that ended its episode (`terminated` or `truncated`).
    fn of(o: &StepOutcome) -> Self {
        if o.info.error.is_some() {
            EpisodeEnd::Error
        } else if o.terminated && o.info.success == Some(true) {
            EpisodeEnd::Success
        } else if o.terminated {
            EpisodeEnd::Failure(
                o.info
                    .values
                    .iter()
                    .filter(|(_, v)| **v != 0.0)
                    .filter_map(|(k, _)| k.strip_prefix("termination/").map(str::to_string))
                    .collect(),
            )
        } else {
            EpisodeEnd::TimeLimit
        }
    }

    /// `success`, `failure`, `time_limit`, `error` or `steps`.
    fn name(&self) -> &'static str {
        match self {
            EpisodeEnd::Success => "success",
            EpisodeEnd::Failure(_) => "failure",
            EpisodeEnd::TimeLimit => "time_limit",
            EpisodeEnd::Error => "error",
            EpisodeEnd::Steps => "steps",
        }
    }

    /// The failure termination terms that fired (empty for other ends).
    fn terminations(&self) -> &[String] {
        match self {
            EpisodeEnd::Failure(t) => t,
            _ => &[],
        }
    }
}

impl std::fmt::Display for EpisodeEnd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.terminations() {
            [] => f.write_str(self.name()),
            t => write!(f, "{}: {}", self.name(), t.join(", ")),
        }
    }
}

/// An episode's success from its last step: that step's value, except that an episode ended by
/// an error counts as a failure where the task has a success criterion (its earlier steps
/// reported one, `before`); the error step itself measures none.
fn final_success(before: Option<bool>, last: Option<bool>, error: bool) -> Option<bool> {
    match (error, last) {
        (true, None) => before.map(|_| false),
        (_, s) => s,
    }
}

fn dump_final(
    env: &mut Env,
    target: &str,
    seed: u64,
    length: u64,
    path: &Path,
) -> Result<(), CliError> {
    let mut v = modesuite_engine::dump::dump_state(&env.app.world);
    v["scene"] = json!(target);
    v["seed"] = json!(seed);
    v["episode_length"] = json!(length);
    let text =
        serde_json::to_string_pretty(&v).map_err(|e| CliError::runtime(format!("dump: {e}")))?;
    std::fs::write(path, text)
        .map_err(|e| CliError::runtime(format!("{}: cannot write: {e}", path.display())))
}

fn bench(
    name: &str,
    json_out: bool,
    scale: f64,
    threads: usize,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    if !(scale.is_finite() && scale > 0.0) {
        return Err(CliError::input(format!(
            "--scale = {scale}: a finite number > 0"
        )));
    }
    let opts = BenchOptions { scale, threads };
    let records: Vec<BenchRecord> = match name {
        "engine" => modesuite_engine::bench::engine_cases(&opts).map_err(CliError::runtime)?,
        "fem" => crate::benches::fem_cases(&opts).map_err(CliError::runtime)?,
        "pbd" => crate::benches::pbd_cases(&opts).map_err(CliError::runtime)?,
        "robots" => crate::benches::robots_cases(&opts).map_err(CliError::runtime)?,
        "render" => crate::benches::render_cases(&opts).map_err(CliError::runtime)?,
        "tasks" => crate::benches::tasks_cases(&opts).map_err(CliError::runtime)?,
        other => {
            return Err(CliError::input(format!(
                "bench {other}: unknown suite; available: engine, fem, pbd, robots, render, tasks"
            )))
        }
    };
    for r in &records {
        if json_out {
            writeln!(out, "{}", r.to_json()).map_err(io)?;
        }
    }
    if !json_out {
        writeln!(
            out,
            "{:<16} {:>5} {:>8} {:>14}  figures",
            "case", "envs", "threads", "steps/s"
        )
        .map_err(io)?;
        for r in &records {
            let extra: Vec<String> = r.extra.iter().map(|(k, v)| format!("{k}={v}")).collect();
            writeln!(
                out,
                "{:<16} {:>5} {:>8} {:>14.0}  {}",
                r.case,
                r.envs,
                r.threads,
                r.steps_per_s,
                extra.join(" ")
            )
            .map_err(io)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::final_success;

    #[test]
    fn an_errored_episode_of_a_task_with_success_is_a_failure() {
        // the error step measured nothing; earlier steps said "not yet": a failure
        assert_eq!(final_success(Some(false), None, true), Some(false));
        // no success criterion at all: still none
        assert_eq!(final_success(None, None, true), None);
        // a normal end keeps the last step's value
        assert_eq!(final_success(Some(false), Some(true), false), Some(true));
        assert_eq!(final_success(None, None, false), None);
    }
}
