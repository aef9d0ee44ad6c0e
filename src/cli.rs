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
//! - `run --save-state FILE` writes the complete state after the last step (a versioned binary
//!   file, [`modesuite_engine::checkpoint`]); `run --load-state FILE` starts the first episode
//!   from it, so `--steps 100 --save-state F` then `--load-state F --steps 100` ends in the
//!   state of `--steps 200` bit for bit (with a stateless policy: zero or trained).
//! - `modesuite bench NAME [--json]`: with `--json`, one JSON object per line per case with at
//!   least `case`, `steps_per_s`, `threads`, `envs` (for `bench render`, images per second).
//! - `modesuite view SCENE_OR_TASK [--seed S] [--record FILE.json]`: the interactive viewer.
//! - `modesuite record TARGET --out DIR [--policy P] [--episodes N] [--seed S] [--noise X]
//!   [--cameras C,...]`: a LeRobot v3.0 dataset (docs/datasets.md; episode i from seed S + i;
//!   `--episodes` counts the dataset's total, so the same command resumes); `dataset info DIR`
//!   and `dataset replay DIR [--episode I] [--json]` (exit 1 unless every state is reproduced).
//! - `--plugin PATH` (repeatable) on `run`, `validate` and `list` loads a compiled plugin (C ABI,
//!   see `modesuite_engine::dynamic`); nothing is ever loaded because a scene names it.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use clap::{Parser, Subcommand};
use serde_json::json;

use modesuite_engine::bench::{BenchOptions, BenchRecord};
use modesuite_engine::prelude::*;
use modesuite_engine::scene::{self, SceneModel};
use modesuite_engine::{DynamicPlugin, PluginLoadError};

pub mod dataset;
pub mod encode;
mod fuzz;
mod imitation;
pub mod learn;
mod record;
mod run;
mod soak;
mod teleop;

use crate::make::{self, load_plugins, MakeError};
use modesuite_render::RenderConfig;
use record::{parse_size, render_err};

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
    /// Train a policy with PPO or SAC (resumable: the same command continues a run).
    Train(learn::TrainArgs),
    /// Evaluate a trained policy (a run or policy folder) on its task: `run --json`'s keys.
    Eval(learn::EvalArgs),
    /// Plot training curves (mean and standard deviation over run folders) into a PNG.
    Plot(learn::PlotArgs),
    /// Record episodes of the scripted expert or a trained policy into a LeRobot v3.0 dataset
    /// (resumable: the same command continues a killed recording).
    Record(dataset::RecordArgs),
    /// Inspect or re-simulate a recorded dataset.
    Dataset {
        /// `info` or `replay`.
        #[command(subcommand)]
        command: dataset::DatasetCommand,
    },
    /// Image features of PNG files with an image encoder (`pooled`, or `dinov2` with its
    /// weights file): what `record --encoder` caches and image policies compute.
    Encode(encode::EncodeArgs),
    /// Fuzz the input parsers and loaders (scene, task, robot, URDF, actions, meshes, state
    /// files) with mutated inputs; exit 1 if any input panicked, 3 if one hung.
    Fuzz(fuzz::FuzzArgs),
    /// Step the 16 tasks with random actions for a long time, sampling resident memory (a
    /// leak check); exit 1 if memory grew beyond the limit after the warm-up.
    Soak(soak::SoakArgs),
    /// Run a benchmark suite: engine, fem, pbd, contact, robots, render, tasks, learn.
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
    /// Write the complete state after the last step to this binary state file (written
    /// atomically), to continue the episode later with `--load-state`.
    #[arg(long, value_name = "FILE")]
    pub save_state: Option<PathBuf>,
    /// Start the first episode from this state file (`--save-state` of the same target,
    /// plugins and build) instead of resetting it; `--steps` more steps follow. Later episodes
    /// reset as usual. The policy starts afresh: zero and trained policies continue exactly,
    /// `random` and `scripted` keep their own state outside the env.
    #[arg(long, value_name = "FILE")]
    pub load_state: Option<PathBuf>,
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
    /// the episode seed), `scripted` (the task's expert) or a trained policy's folder
    /// (`train --out DIR`, or its `policy/`).
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
    /// Threads running episodes side by side, each in its own env (`0`: all cores). Every
    /// episode resets with its own seed, so the episodes and their results are the same for
    /// any number (wall times aside); with `--video`, `--frames`, `--dump-state`,
    /// `--save-state` or `--load-state` the episodes run one after another.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
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
    /// Append each teleoperated episode to this LeRobot dataset when it ends (by the task, a
    /// reset `r`, or closing the viewer), marked successful or not; needs the discrete keys
    /// (`--actions "(discrete: true)"`). See `dataset import-teleop`.
    #[arg(long)]
    pub record_dataset: Option<PathBuf>,
    /// With --record-dataset: cameras and image features to record.
    #[command(flatten)]
    pub capture: dataset::CaptureArgs,
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

impl From<MakeError> for CliError {
    fn from(e: MakeError) -> Self {
        match e {
            MakeError::Input(m) => Self::input(m),
            MakeError::Runtime(m) => Self::runtime(m),
        }
    }
}

impl From<PluginLoadError> for CliError {
    fn from(e: PluginLoadError) -> Self {
        Self::input(format!("--plugin: {e}"))
    }
}

/// Runs the CLI; returns the process exit code's error on failure.
pub fn run_cli(cli: Cli, out: &mut dyn Write) -> Result<(), CliError> {
    match cli.command {
        None => run_default(out),
        Some(Command::List { what, plugin }) => list(what.as_deref(), &load_plugins(&plugin)?, out),
        Some(Command::Validate { files, plugin }) => validate(&files, &load_plugins(&plugin)?, out),
        Some(Command::Run(args)) => run::run(&args, out),
        Some(Command::View(args)) => view(&args, out),
        Some(Command::Train(args)) => learn::train(&args, out),
        Some(Command::Eval(args)) => learn::eval(&args, out),
        Some(Command::Plot(args)) => learn::plot(&args, out),
        Some(Command::Record(args)) => dataset::record(&args, out),
        Some(Command::Dataset { command }) => dataset::dataset(&command, out),
        Some(Command::Encode(args)) => encode::encode(&args, out),
        Some(Command::Fuzz(args)) => fuzz::fuzz(&args, out),
        Some(Command::Soak(args)) => soak::soak(&args, out),
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
        save_state: None,
        load_state: None,
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
        threads: 1,
    };
    run::run(&args, out)
}

fn list(
    what: Option<&str>,
    plugins: &[Arc<DynamicPlugin>],
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let app = make::app_with_plugins(plugins)?;
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
    let app = make::app_with_plugins(plugins)?;
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

fn view(args: &ViewArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let size = parse_size("--size", &args.size)?;
    let (mut desc, source) = make::load_target(&args.target)?;
    if let Some(a) = &args.actions {
        make::override_actions(&mut desc, a)?;
    }
    let mut app = make::default_app();
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
    let hook = match &args.record_dataset {
        Some(dir) => Some(teleop::dataset_hook(
            &args.target,
            dir.clone(),
            args.actions.clone(),
            &args.capture,
        )?),
        None if args.capture.any() => {
            return Err(CliError::input(
                "--cameras, --encoder, --weights: only with --record-dataset",
            ))
        }
        None => None,
    };
    let (summary, mut env) =
        modesuite_render::viewer::run_viewer_with(env, opts, hook).map_err(render_err)?;
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

/// The policy of `run --policy`: a built-in kind, or a trained policy's folder.
fn make_run_policy(
    policy: &str,
    env: &Env,
) -> Result<Box<dyn modesuite_tasks::expert::Policy>, CliError> {
    let path = Path::new(policy);
    if crate::learning::policy_dir(path).is_some() {
        let (p, _) = crate::learning::load_run_policy(path).map_err(CliError::input)?;
        return Ok(p);
    }
    let kind: modesuite_tasks::PolicyKind = policy
        .parse()
        .map_err(|e: String| CliError::input(format!("{e}, or a trained policy's folder")))?;
    modesuite_tasks::make_policy(kind, env).map_err(CliError::input)
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
    modesuite_engine::fsio::write_atomic(path, text.as_bytes())
        .map_err(|e| CliError::runtime(format!("{}: {e}", path.display())))
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
        "contact" => crate::bench_contact::contact_cases(&opts).map_err(CliError::runtime)?,
        "robots" => crate::benches::robots_cases(&opts).map_err(CliError::runtime)?,
        "render" => crate::benches::render_cases(&opts).map_err(CliError::runtime)?,
        "tasks" => crate::benches::tasks_cases(&opts).map_err(CliError::runtime)?,
        "learn" => crate::bench_learn::learn_cases(&opts).map_err(CliError::runtime)?,
        other => {
            return Err(CliError::input(format!(
                "bench {other}: unknown suite; available: engine, fem, pbd, contact, robots, render, tasks, learn"
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
