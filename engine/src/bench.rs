//! Benchmark records and the engine's own cases (`modesuite bench engine`).
//!
//! Every case produces a [`BenchRecord`]; the CLI prints a table or, with `--json`, one JSON
//! object per line with at least `case`, `steps_per_s`, `threads` and `envs` (stable keys that
//! outside scripts parse) plus the case's own figures in `extra`.

use std::collections::BTreeMap;
use std::time::Instant;

use serde_json::{json, Value};

use crate::env::{Env, VecEnv};
use crate::{SceneSource, SimApp};

/// One measured benchmark case.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchRecord {
    /// Case name, e.g. `empty_x16`.
    pub case: String,
    /// Env steps per second (summed over envs).
    pub steps_per_s: f64,
    /// Threads used.
    pub threads: usize,
    /// Envs stepped.
    pub envs: usize,
    /// The case's own figures (keys documented per case).
    pub extra: BTreeMap<String, Value>,
}

impl BenchRecord {
    /// A record with the case's own figures.
    pub fn new(
        case: &str,
        steps_per_s: f64,
        threads: usize,
        envs: usize,
        extra: BTreeMap<String, Value>,
    ) -> Self {
        Self {
            case: case.to_string(),
            steps_per_s,
            threads,
            envs,
            extra,
        }
    }

    /// As one JSON object (the `--json` line).
    pub fn to_json(&self) -> Value {
        let mut m = serde_json::Map::new();
        m.insert("case".into(), json!(self.case));
        m.insert("steps_per_s".into(), json!(self.steps_per_s));
        m.insert("threads".into(), json!(self.threads));
        m.insert("envs".into(), json!(self.envs));
        for (k, v) in &self.extra {
            m.insert(k.clone(), v.clone());
        }
        Value::Object(m)
    }
}

/// Options shared by benchmark cases.
#[derive(Debug, Clone, Copy)]
pub struct BenchOptions {
    /// Scale of the number of steps (1.0 = default; smaller for quick runs).
    pub scale: f64,
    /// Threads for the "all cores" cases (0 = all).
    pub threads: usize,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            scale: 1.0,
            threads: 0,
        }
    }
}

fn empty_app() -> Result<SimApp, crate::SceneError> {
    let mut app = SimApp::new();
    app.add_group(crate::EnginePlugins);
    let model = app.compile_scene(&crate::SceneDesc::default(), &SceneSource::in_memory("."))?;
    app.spawn_scene(model)?;
    Ok(app)
}

fn time_vec(envs: usize, threads: usize, steps: usize) -> Result<(f64, usize), String> {
    let mut v = VecEnv::build(envs, threads, |_| empty_app()).map_err(|e| e.to_string())?;
    v.reset(Some(0));
    for _ in 0..steps / 10 {
        v.step(&[]).map_err(|e| e.to_string())?;
    }
    let t = Instant::now();
    for _ in 0..steps {
        v.step(&[]).map_err(|e| e.to_string())?;
    }
    let secs = t.elapsed().as_secs_f64();
    Ok(((steps * envs) as f64 / secs, v.threads()))
}

/// The engine cases: `schedule` (one `EnvStep` pass of an app without plugins: the schedule
/// overhead alone), `empty_env` (one env with the rigid plugin and an empty scene through
/// `Env::step`), `empty_x16` (16 such envs through `VecEnv`, one thread and all threads). Extra key: `us_per_env_step` (wall-clock microseconds per env step,
/// aggregate over envs).
pub fn engine_cases(opts: &BenchOptions) -> Result<Vec<BenchRecord>, String> {
    let mut out = Vec::new();
    let n = ((200_000.0 * opts.scale) as usize).max(100);

    // Pure schedule overhead: the three schedules with the engine's own systems, no plugins.
    let mut app = SimApp::new();
    let model = app
        .compile_scene(&crate::SceneDesc::default(), &SceneSource::in_memory("."))
        .map_err(|e| e.to_string())?;
    app.spawn_scene(model).map_err(|e| e.to_string())?;
    for _ in 0..n / 10 {
        app.step();
    }
    let t = Instant::now();
    for _ in 0..n {
        app.step();
    }
    let sps = n as f64 / t.elapsed().as_secs_f64();
    out.push(record("schedule", sps, 1, 1));

    let mut env = Env::new(empty_app().map_err(|e| e.to_string())?);
    env.reset(Some(0));
    let t = Instant::now();
    for _ in 0..n {
        env.step(&[]);
    }
    let sps = n as f64 / t.elapsed().as_secs_f64();
    out.push(record("empty_env", sps, 1, 1));

    let m = (n / 16).max(10);
    let (sps, threads) = time_vec(16, 1, m)?;
    out.push(record("empty_x16", sps, threads, 16));
    let (sps, threads) = time_vec(16, opts.threads, m)?;
    if threads != 1 {
        out.push(record("empty_x16", sps, threads, 16));
    }
    Ok(out)
}

fn record(case: &str, steps_per_s: f64, threads: usize, envs: usize) -> BenchRecord {
    let mut extra = BTreeMap::new();
    extra.insert("us_per_env_step".to_string(), json!(1e6 / steps_per_s));
    BenchRecord::new(case, steps_per_s, threads, envs, extra)
}
