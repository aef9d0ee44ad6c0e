//! `modesuite._core`: the extension module behind the `modesuite` Python package.
//!
//! One class, [`Core`], holds N environments of one target in a [`VecEnv`] and steps them on
//! the Rust thread pool with the GIL released. The Python package wraps it twice: a
//! `gymnasium.Env` (N = 1, no autoreset) and a `gymnasium.vector.VectorEnv` (same-step or
//! disabled autoreset). Observations, rewards and infos come back as fresh numpy arrays on every
//! call, laid out by [`modesuite::gym`] (shared with `cargo test`).
//!
//! Errors: bad input raises `modesuite.SceneError` (a `ValueError`; scene errors carry
//! `file:line:col`), run-time failures `RuntimeError`; a panic inside Rust is caught and raised
//! as `RuntimeError`, and the object then refuses further calls instead of running on a state
//! it cannot trust.

mod convert;
mod encoder;

use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard};

use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::{PyNotImplementedError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use modesuite::engine::{SceneModel, VecEnv};
use modesuite::gym::info::{reset_info, Batch, EpisodeTracker, InfoValue};
use modesuite::gym::layout::{ActLayout, ObsLayout};
use modesuite::make::{self, MakeError, MakeOptions};
use modesuite::render::{CameraDesc, EnvRenderer, Orbit};
use modesuite::tasks::expert::{make_policy, Policy as ExpertPolicy, PolicyKind};

pyo3::create_exception!(
    _core,
    SceneError,
    PyValueError,
    "Bad input: a scene or task file (the message carries file:line:col), an unknown task id, \
     a bad option value."
);

fn make_err(e: MakeError) -> PyErr {
    match e {
        MakeError::Input(m) => SceneError::new_err(m),
        MakeError::Runtime(m) => PyRuntimeError::new_err(m),
    }
}

/// Runs `f`, turning a panic into an error message.
fn guarded<R>(f: impl FnOnce() -> R) -> Result<R, String> {
    modesuite::engine::catch_panic(f).map_err(|what| {
        let what = if what.is_empty() {
            "unknown panic".to_string()
        } else {
            what
        };
        format!("internal error in modesuite (please report): {what}")
    })
}

/// `(observations, rewards, terminated, truncated, infos)` of a vector step.
type VecStepResult<'py> = (
    Py<PyAny>,
    Py<PyAny>,
    Py<PyAny>,
    Py<PyAny>,
    Bound<'py, PyDict>,
);

/// `(observation, reward, terminated, truncated, info)` of one env's step.
type StepResult<'py> = (Py<PyAny>, f64, bool, bool, Bound<'py, PyDict>);

/// The envs and what the binding keeps beside them.
struct Inner {
    vec: VecEnv,
    model: Arc<SceneModel>,
    obs: ObsLayout,
    act: ActLayout,
    trackers: Vec<EpisodeTracker>,
    autoreset: bool,
    /// Envs whose episode ended (autoreset disabled) and that wait for a reset.
    waiting: Vec<bool>,
    /// Whether `reset` has been called.
    started: bool,
    /// The observation of each env after the last call (`n x dim`).
    last_obs: Vec<f32>,
    /// The scripted expert of each env (made on first use) and whether its env was reset since.
    experts: Vec<Option<Box<dyn ExpertPolicy>>>,
    expert_reset: Vec<Option<u64>>,
    renderer: Option<EnvRenderer>,
    cameras: Vec<Option<CameraDesc>>,
    /// Set after a panic: the envs' state is not trusted any more.
    poisoned: Option<String>,
}

/// N environments of one target (a task id or a scene file) stepped together.
#[pyclass(module = "modesuite._core")]
pub struct Core {
    // boxed: Python allocates objects 16-byte aligned, whatever the envs' alignment is
    inner: Mutex<Box<Inner>>,
    n: usize,
    threads: usize,
    episode_steps: Option<u64>,
    target: String,
}

impl Core {
    fn lock(&self) -> PyResult<MutexGuard<'_, Box<Inner>>> {
        let g = self
            .inner
            .lock()
            .map_err(|_| PyRuntimeError::new_err("modesuite: env state lost after a panic"))?;
        if let Some(p) = &g.poisoned {
            return Err(PyRuntimeError::new_err(format!(
                "this env is unusable after an earlier internal error: {p}"
            )));
        }
        Ok(g)
    }
}

/// Marks `inner` poisoned when `r` is a caught panic and turns it into a `RuntimeError`.
fn poison<R>(inner: &mut Inner, r: Result<R, String>) -> PyResult<R> {
    r.map_err(|m| {
        inner.poisoned = Some(m.clone());
        PyRuntimeError::new_err(m)
    })
}

#[pymethods]
impl Core {
    /// Makes `num_envs` envs of `target` (a task id `MoDe-<Robot>-<Task>-v0` or a
    /// `*.scene.ron` path) on `threads` threads (0: all cores).
    #[new]
    #[pyo3(signature = (target, num_envs=1, threads=1, actions=None, rgbd=None, plugins=Vec::new(), episode_steps=None, autoreset=true))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        target: String,
        num_envs: usize,
        threads: usize,
        actions: Option<String>,
        rgbd: Option<String>,
        plugins: Vec<PathBuf>,
        episode_steps: Option<u64>,
        autoreset: bool,
    ) -> PyResult<Self> {
        if num_envs == 0 {
            return Err(SceneError::new_err("num_envs = 0: at least 1"));
        }
        let built = py.detach(|| {
            guarded(|| -> Result<_, MakeError> {
                let plugins = make::load_plugins(&plugins)
                    .map_err(|e| MakeError::Input(format!("plugins: {e}")))?;
                let opts = MakeOptions {
                    actions,
                    rgbd,
                    plugins,
                    episode_steps,
                };
                let made = make::make_envs(&target, &opts, num_envs)?;
                let mut vec = VecEnv::new(made.envs, threads)?;
                for e in vec.envs_mut() {
                    e.autoreset = autoreset;
                }
                let spaces = vec.spaces().clone();
                let obs = ObsLayout::of(&spaces.observation).map_err(MakeError::Input)?;
                let act = ActLayout::of(&spaces.action).map_err(MakeError::Input)?;
                Ok((vec, made.model, obs, act))
            })
        });
        let (vec, model, obs, act) = built.map_err(PyRuntimeError::new_err)?.map_err(make_err)?;
        let dim = obs.flat_dim();
        let threads = vec.threads();
        let episode_steps = episode_steps.or(model.episode_steps);
        Ok(Self {
            inner: Mutex::new(Box::new(Inner {
                vec,
                model,
                obs,
                act,
                trackers: vec![EpisodeTracker::default(); num_envs],
                autoreset,
                waiting: vec![false; num_envs],
                started: false,
                last_obs: vec![0.0; num_envs * dim],
                experts: (0..num_envs).map(|_| None).collect(),
                expert_reset: vec![Some(0); num_envs],
                renderer: None,
                cameras: vec![None; num_envs],
                poisoned: None,
            })),
            n: num_envs,
            threads,
            episode_steps,
            target,
        })
    }

    /// Number of envs.
    #[getter]
    fn num_envs(&self) -> usize {
        self.n
    }

    /// Threads stepping the envs.
    #[getter]
    fn threads(&self) -> usize {
        self.threads
    }

    /// Env steps per episode (the scene's time limit, or the override), or None.
    #[getter]
    fn episode_steps(&self) -> Option<u64> {
        self.episode_steps
    }

    /// The target the envs were made from.
    #[getter]
    fn target(&self) -> String {
        self.target.clone()
    }

    /// Seconds of simulated time per env step (`dt x decimation`).
    #[getter]
    fn step_dt(&self) -> PyResult<f64> {
        let g = self.lock()?;
        Ok(g.model.settings.dt * g.model.settings.decimation as f64)
    }

    /// The spaces: `{"obs": [(key, dtype, shape, low, high)], "obs_dict": bool,
    /// "act_discrete": n or None, "act_low": [..], "act_high": [..],
    /// "act_parts": [(name, offset, len)]}`.
    fn spaces<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let g = self.lock()?;
        let d = PyDict::new(py);
        let keys: Vec<_> = g
            .obs
            .out_keys()
            .into_iter()
            .map(|k| (k.key, k.dtype, k.shape, k.low, k.high))
            .collect();
        d.set_item("obs", keys)?;
        d.set_item("obs_dict", matches!(g.obs, ObsLayout::Dict(_)))?;
        d.set_item("act_discrete", g.act.discrete)?;
        d.set_item("act_low", g.act.low.clone())?;
        d.set_item("act_high", g.act.high.clone())?;
        d.set_item("act_parts", g.act.parts.clone())?;
        Ok(d)
    }

    /// Resets the envs whose `mask` entry is true (all without a mask), env i with `seeds[i]`
    /// (None: its RNG goes on). Returns the batched observations of every env and the batched
    /// reset infos.
    #[pyo3(signature = (seeds, mask=None))]
    fn reset<'py>(
        &self,
        py: Python<'py>,
        seeds: Vec<Option<u64>>,
        mask: Option<Vec<bool>>,
    ) -> PyResult<(Py<PyAny>, Bound<'py, PyDict>)> {
        let mut g = self.lock()?;
        if seeds.len() != self.n || mask.as_ref().is_some_and(|m| m.len() != self.n) {
            return Err(PyValueError::new_err(format!(
                "seeds and mask: one entry per env ({})",
                self.n
            )));
        }
        let inner = &mut *g;
        let r = py.detach(|| guarded(|| inner.vec.reset_each(&seeds, mask.as_deref())));
        let results = poison(inner, r)?;
        let dim = inner.obs.flat_dim();
        let mut batch = Batch::new(self.n);
        for (i, r) in results.into_iter().enumerate() {
            let Some((obs, info)) = r else { continue };
            inner.last_obs[i * dim..(i + 1) * dim].copy_from_slice(&obs);
            batch.add(reset_info::<Vec<f32>>(info.error.as_deref()), i);
            inner.trackers[i].reset();
            inner.waiting[i] = false;
            inner.expert_reset[i] = Some(seeds[i].unwrap_or(0));
        }
        inner.started = true;
        let obs = convert::obs(py, &inner.obs, &inner.last_obs, Some(self.n))?;
        Ok((obs, convert::batch(py, &inner.obs, batch)?))
    }

    /// Resets the only env (N = 1): `(observation, info)` unbatched.
    #[pyo3(signature = (seed=None))]
    fn reset_one<'py>(
        &self,
        py: Python<'py>,
        seed: Option<u64>,
    ) -> PyResult<(Py<PyAny>, Bound<'py, PyDict>)> {
        let mut g = self.lock()?;
        let inner = &mut *g;
        let r = py.detach(|| guarded(|| inner.vec.envs_mut()[0].reset(seed)));
        let (obs, info) = poison(inner, r)?;
        inner.last_obs.copy_from_slice(&obs);
        inner.trackers[0].reset();
        inner.waiting[0] = false;
        inner.started = true;
        inner.expert_reset[0] = Some(seed.unwrap_or(0));
        let o = convert::obs(py, &inner.obs, &obs, None)?;
        Ok((
            o,
            convert::info(py, &inner.obs, reset_info(info.error.as_deref()))?,
        ))
    }

    /// Steps every env with its row of `actions` (float32, `num_envs x act_dim`, C order).
    /// Returns `(observations, rewards, terminated, truncated, infos)`, batched.
    fn step<'py>(
        &self,
        py: Python<'py>,
        actions: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<VecStepResult<'py>> {
        let mut g = self.lock()?;
        let inner = &mut *g;
        self.check_can_step(inner)?;
        let actions = actions.as_slice()?;
        let r = py.detach(|| guarded(|| inner.vec.step(actions)));
        let out = poison(inner, r)?.map_err(|e| PyValueError::new_err(e.to_string()))?;
        let mut batch = Batch::new(self.n);
        let mut infos = out.infos;
        for (i, info) in infos.iter_mut().enumerate() {
            let (term, done) = (out.terminated[i], out.terminated[i] || out.truncated[i]);
            if done && inner.autoreset {
                let final_obs = info.final_observation.take().unwrap_or_default();
                let final_info = info.final_info.take().map(|b| *b).unwrap_or_default();
                let step_info = inner.trackers[i].step_info(&final_info, term, true);
                batch.add(
                    vec![
                        ("final_obs".to_string(), InfoValue::Obs(final_obs)),
                        ("final_info".to_string(), InfoValue::Dict(step_info)),
                    ],
                    i,
                );
                let err = inner.vec.envs()[i].pending_reset_error();
                batch.add(reset_info(err), i);
                inner.expert_reset[i] = Some(0);
            } else {
                batch.add(inner.trackers[i].step_info(info, term, done), i);
                inner.waiting[i] = done;
            }
        }
        inner.last_obs = out.observations;
        let obs = convert::obs(py, &inner.obs, &inner.last_obs, Some(self.n))?;
        Ok((
            obs,
            convert::array(py, out.rewards, &[self.n])?,
            convert::array(py, out.terminated, &[self.n])?,
            convert::array(py, out.truncated, &[self.n])?,
            convert::batch(py, &inner.obs, batch)?,
        ))
    }

    /// Steps the only env (N = 1, no autoreset) with `action` (float32, `act_dim`).
    /// Returns `(observation, reward, terminated, truncated, info)`.
    fn step_one<'py>(
        &self,
        py: Python<'py>,
        action: PyReadonlyArray1<'py, f32>,
    ) -> PyResult<StepResult<'py>> {
        let mut g = self.lock()?;
        let inner = &mut *g;
        self.check_can_step(inner)?;
        let action = action.as_slice()?;
        let r = py.detach(|| guarded(|| inner.vec.envs_mut()[0].step(action)));
        let o = poison(inner, r)?;
        let done = o.terminated || o.truncated;
        inner.waiting[0] = done;
        let info = inner.trackers[0].step_info(&o.info, o.terminated, done);
        inner.last_obs.copy_from_slice(&o.observation);
        let obs = convert::obs(py, &inner.obs, &o.observation, None)?;
        Ok((
            obs,
            o.reward,
            o.terminated,
            o.truncated,
            convert::info(py, &inner.obs, info)?,
        ))
    }

    /// The scripted expert's action for each env's current state (`num_envs x act_dim`,
    /// float32); `NotImplementedError` when the target has no expert.
    fn expert_actions(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let mut g = self.lock()?;
        let inner = &mut *g;
        let dim = inner.act.dim;
        let mut actions = vec![0.0f32; self.n * dim];
        for i in 0..self.n {
            let env = &inner.vec.envs()[i];
            if inner.experts[i].is_none() {
                let p = make_policy(PolicyKind::Scripted, env)
                    .map_err(|e| PyNotImplementedError::new_err(format!("expert: {e}")))?;
                inner.experts[i] = Some(p);
            }
            let Some(p) = inner.experts[i].as_mut() else {
                continue;
            };
            if let Some(seed) = inner.expert_reset[i].take() {
                p.reset(seed);
            }
            let row = &mut actions[i * dim..(i + 1) * dim];
            let r = guarded(|| p.act(env, row));
            poison(inner, r)?.map_err(|e| PyRuntimeError::new_err(format!("expert: {e}")))?;
        }
        convert::array(py, actions, &[self.n, dim])
    }

    /// An RGB frame (`height x width x 3`, uint8) of env `index` from an orbit camera framing
    /// the scene (fixed after the first frame), as `run --video` records.
    #[pyo3(signature = (index=0, width=480, height=320))]
    fn render(&self, py: Python<'_>, index: usize, width: u32, height: u32) -> PyResult<Py<PyAny>> {
        let mut g = self.lock()?;
        let inner = &mut *g;
        if index >= self.n {
            return Err(PyValueError::new_err(format!(
                "index = {index}: 0..{}",
                self.n
            )));
        }
        if !(1..=8192).contains(&width) || !(1..=8192).contains(&height) {
            return Err(PyValueError::new_err(format!(
                "width x height = {width} x {height}: each in 1..=8192"
            )));
        }
        let frame = py.detach(|| -> Result<_, MakeError> {
            if inner.renderer.is_none() {
                inner.renderer = Some(EnvRenderer::for_scene(inner.model.clone())?);
            }
            let Some(renderer) = inner.renderer.as_mut() else {
                return Err(MakeError::Runtime("no renderer".into()));
            };
            let world = &inner.vec.envs()[index].app.world;
            let cam = match &inner.cameras[index] {
                Some(c) if c.width == width && c.height == height => c.clone(),
                _ => {
                    let c = renderer.orbit_camera(world, "orbit", width, height, Orbit::default());
                    inner.cameras[index] = Some(c.clone());
                    c
                }
            };
            let frames = renderer.render_cameras(world, std::slice::from_ref(&cam))?;
            frames
                .into_iter()
                .next()
                .ok_or_else(|| MakeError::Runtime("the renderer returned no frame".into()))
        });
        let frame = frame.map_err(make_err)?;
        convert::array(
            py,
            frame.rgb,
            &[frame.height as usize, frame.width as usize, 3],
        )
    }

    /// Steps the envs through `actions` (`steps x num_envs x act_dim`, float32) in Rust with
    /// the GIL released and without converting observations: open-loop replays and the
    /// binding's overhead benchmark. Returns `(seconds, rewards)` (`steps x num_envs`). Envs
    /// reset themselves as in `step` (autoreset), but the Python-side episode bookkeeping (infos)
    /// is not kept: call `reset` before stepping from Python again.
    fn rollout<'py>(
        &self,
        py: Python<'py>,
        actions: PyReadonlyArray3<'py, f32>,
    ) -> PyResult<(f64, Py<PyAny>)> {
        let mut g = self.lock()?;
        let inner = &mut *g;
        self.check_can_step(inner)?;
        let shape = actions.shape().to_vec();
        if shape[1] != self.n || shape[2] != inner.act.dim {
            return Err(PyValueError::new_err(format!(
                "actions of shape {shape:?}: expected (steps, {}, {})",
                self.n, inner.act.dim
            )));
        }
        let actions = actions.as_slice()?;
        let per_step = self.n * inner.act.dim;
        let r = py.detach(|| {
            guarded(|| {
                let start = std::time::Instant::now();
                let mut rewards = Vec::with_capacity(shape[0] * self.n);
                for t in 0..shape[0] {
                    let out = inner.vec.step(&actions[t * per_step..(t + 1) * per_step])?;
                    rewards.extend(out.rewards);
                }
                Ok::<_, modesuite::engine::env::VecEnvError>((
                    start.elapsed().as_secs_f64(),
                    rewards,
                ))
            })
        });
        let (secs, rewards) =
            poison(inner, r)?.map_err(|e| PyValueError::new_err(e.to_string()))?;
        inner.started = false;
        Ok((secs, convert::array(py, rewards, &[shape[0], self.n])?))
    }

    /// A bit-exact hash of each env's state.
    fn state_hashes(&self) -> PyResult<Vec<u64>> {
        Ok(self.lock()?.vec.state_hashes())
    }

    /// The complete state of env `index` as the bytes of a state file (`run --save-state`).
    #[pyo3(signature = (index=0))]
    fn save_state<'py>(&self, py: Python<'py>, index: usize) -> PyResult<Bound<'py, PyBytes>> {
        let g = self.lock()?;
        let env = g
            .vec
            .envs()
            .get(index)
            .ok_or_else(|| PyValueError::new_err(format!("index = {index}: 0..{}", self.n)))?;
        let bytes = env
            .save_state()
            .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
        Ok(PyBytes::new(py, &bytes))
    }

    /// Replaces the state of env `index` with a state file's bytes (of the same target, plugins
    /// and build; anything else is a `ValueError` and changes nothing). Its episode continues
    /// from there; returns its observation. The scripted expert starts afresh.
    fn load_state<'py>(&self, py: Python<'py>, index: usize, data: &[u8]) -> PyResult<Py<PyAny>> {
        let mut g = self.lock()?;
        let inner = &mut *g;
        if index >= self.n {
            return Err(PyValueError::new_err(format!(
                "index = {index}: 0..{}",
                self.n
            )));
        }
        let r = py.detach(|| {
            guarded(|| {
                let env = &mut inner.vec.envs_mut()[index];
                env.load_state(data).map(|()| env.observation())
            })
        });
        let obs =
            poison(inner, r)?.map_err(|e| PyValueError::new_err(format!("load_state: {e}")))?;
        let dim = obs.len();
        inner.last_obs[index * dim..(index + 1) * dim].copy_from_slice(&obs);
        inner.trackers[index].reset();
        inner.waiting[index] = false;
        inner.started = true;
        inner.expert_reset[index] = Some(0);
        convert::obs(py, &inner.obs, &obs, None)
    }

    /// The state of env `index` as `modesuite.state.v1` JSON (as `run --dump-state` writes).
    #[pyo3(signature = (index=0))]
    fn dump_state(&self, index: usize) -> PyResult<String> {
        let g = self.lock()?;
        let env = g
            .vec
            .envs()
            .get(index)
            .ok_or_else(|| PyValueError::new_err(format!("index = {index}: 0..{}", self.n)))?;
        let v = modesuite::engine::dump::dump_state(&env.app.world);
        serde_json::to_string(&v).map_err(|e| PyRuntimeError::new_err(e.to_string()))
    }
}

impl Core {
    /// Refuses a step before the first reset, and (autoreset disabled) on an env whose episode
    /// ended and that was not reset.
    fn check_can_step(&self, inner: &Inner) -> PyResult<()> {
        if !inner.started {
            return Err(PyRuntimeError::new_err(
                "step() before reset(): call reset() first",
            ));
        }
        let waiting: Vec<usize> = (0..self.n).filter(|i| inner.waiting[*i]).collect();
        if !waiting.is_empty() {
            return Err(PyRuntimeError::new_err(format!(
                "envs {waiting:?} ended their episode: reset them first (reset(), or \
                 reset(options={{\"reset_mask\": mask}}) for a vector env)"
            )));
        }
        Ok(())
    }
}

/// A trained policy (`modesuite train --out DIR`, or a folder of `policies/`): the deterministic
/// action (the mean) for observations of the task it was trained on.
#[pyclass(module = "modesuite._core")]
pub struct Policy {
    // boxed: burn's buffers are 64-byte aligned and Python allocates objects 16-byte aligned
    inner: Box<modesuite::learn::Policy>,
    origin: modesuite::learning::PolicyOrigin,
}

impl Policy {
    /// `obs` as C-ordered float32 of one `(obs_dim,)` observation (rows `None`) or a batch
    /// `(n, obs_dim)` (rows `Some(n)`).
    fn observations<'py>(
        &self,
        obs: &Bound<'py, PyAny>,
    ) -> PyResult<(Option<usize>, numpy::PyReadonlyArrayDyn<'py, f32>)> {
        let obs = convert::f32_array(obs)?;
        let shape = obs.shape().to_vec();
        let (rows, dim) = match shape.as_slice() {
            [d] => (None, *d),
            [n, d] => (Some(*n), *d),
            _ => (None, usize::MAX),
        };
        if dim != self.inner.obs_dim() {
            return Err(PyValueError::new_err(format!(
                "observations of shape {shape:?}: expected ({0},) or (n, {0})",
                self.inner.obs_dim()
            )));
        }
        Ok((rows, obs))
    }
}

/// A policy acting in one environment, one observation per step, as `modesuite eval` plays it:
/// a policy of action chunks plays each chunk open-loop before it observes again, or, trained
/// with `ensemble=M`, observes every step and plays ACT's temporal ensemble of its chunks.
/// `reset()` at each episode's start.
#[pyclass(module = "modesuite._core")]
pub struct PolicyPlayer {
    policy: Py<Policy>,
    player: modesuite::learn::policy::ChunkPlayer,
}

#[pymethods]
impl PolicyPlayer {
    /// A player of `policy` (a `modesuite.Policy`).
    #[new]
    fn new(py: Python<'_>, policy: Py<Policy>) -> Self {
        let player = {
            let m = policy.borrow(py);
            let m = m.inner.meta();
            modesuite::learn::policy::ChunkPlayer::new(m.act_dim, m.chunk, m.ensemble)
        };
        Self { policy, player }
    }

    /// Forgets the actions still pending (a new episode).
    fn reset(&mut self) {
        self.player.reset();
    }

    /// The action (float32, `(act_dim,)`) for this step's observation `(obs_dim,)`; between
    /// two looks of an open-loop chunk the observation is not used.
    fn act<'py>(&mut self, py: Python<'py>, obs: &Bound<'py, PyAny>) -> PyResult<Py<PyAny>> {
        let policy = self.policy.borrow(py);
        let (rows, obs) = policy.observations(obs)?;
        if rows.is_some() {
            return Err(PyValueError::new_err(
                "PolicyPlayer.act takes one observation (obs_dim,): it keeps one episode's chunks",
            ));
        }
        let ad = policy.inner.act_dim();
        let mut action = vec![0.0f32; ad];
        if self.player.needs_chunk() {
            let data = obs.as_slice()?;
            let inner: &modesuite::learn::Policy = &policy.inner;
            let chunk = py.detach(|| inner.act_chunk(data));
            self.player.play(Some(&chunk), &mut action);
        } else {
            self.player.play(None, &mut action);
        }
        convert::array(py, action, &[ad])
    }
}

#[pymethods]
impl Policy {
    /// Loads the policy of a run folder or policy folder.
    #[new]
    fn new(dir: PathBuf) -> PyResult<Self> {
        let (inner, origin) =
            modesuite::learning::load_policy(&dir).map_err(SceneError::new_err)?;
        Ok(Self {
            inner: Box::new(inner),
            origin,
        })
    }

    /// Actions (float32) for observations: one `(obs_dim,)` or a batch `(n, obs_dim)`, any
    /// numeric array (float64, a strided view: converted to C-ordered float32 first). A policy
    /// of action chunks gives each chunk's first action (see `act_chunk`).
    fn act<'py>(&self, py: Python<'py>, obs: &Bound<'py, PyAny>) -> PyResult<Py<PyAny>> {
        let (rows, obs) = self.observations(obs)?;
        let data = obs.as_slice()?;
        let actions = py.detach(|| self.inner.act(data));
        let act_dim = self.inner.act_dim();
        match rows {
            Some(n) => convert::array(py, actions, &[n, act_dim]),
            None => convert::array(py, actions, &[act_dim]),
        }
    }

    /// Every action of each chunk (`chunk x act_dim` per observation, to be taken one after
    /// another): `(chunk, act_dim)` for one observation, `(n, chunk, act_dim)` for a batch.
    fn act_chunk<'py>(&self, py: Python<'py>, obs: &Bound<'py, PyAny>) -> PyResult<Py<PyAny>> {
        let (rows, obs) = self.observations(obs)?;
        let data = obs.as_slice()?;
        let actions = py.detach(|| self.inner.act_chunk(data));
        let (k, ad) = (self.inner.meta().chunk, self.inner.act_dim());
        match rows {
            Some(n) => convert::array(py, actions, &[n, k, ad]),
            None => convert::array(py, actions, &[k, ad]),
        }
    }

    /// Actions per observation (1, or the action chunk of a `bc` policy trained with
    /// `chunk=K`).
    #[getter]
    fn chunk(&self) -> usize {
        self.inner.meta().chunk
    }

    /// The temporal-ensembling exponent of a chunked `bc` policy (`ensemble=M` at training),
    /// or None: how `modesuite eval` and `run` play its chunks (`act` and `act_chunk` are
    /// stateless and give the raw predictions).
    #[getter]
    fn ensemble(&self) -> Option<f64> {
        self.inner.meta().ensemble
    }

    /// Networks of a `bc` ensemble (`members=N` at training; 1 otherwise): `act` and
    /// `act_chunk` give the mean of their outputs.
    #[getter]
    fn members(&self) -> usize {
        self.inner.meta().members
    }

    /// The task id or scene file it was trained on.
    #[getter]
    fn target(&self) -> String {
        self.origin.target.clone()
    }

    /// The action modes it was trained with (RON), or None for the scene's.
    #[getter]
    fn actions(&self) -> Option<String> {
        self.origin.actions.clone()
    }

    /// `ppo`, `sac` or `bc`.
    #[getter]
    fn algo(&self) -> String {
        self.inner.meta().algo.clone()
    }

    /// Observation values it takes.
    #[getter]
    fn obs_dim(&self) -> usize {
        self.inner.obs_dim()
    }

    /// Action values it gives.
    #[getter]
    fn act_dim(&self) -> usize {
        self.inner.act_dim()
    }
}

/// The 16 task ids, `MoDe-<Robot>-<Task>-v0`.
#[pyfunction]
fn task_ids() -> Vec<String> {
    modesuite::tasks::all_ids()
}

/// The scene's `episode_steps` of a task id or scene file (parsed, not compiled), or None.
#[pyfunction]
fn scene_episode_steps(target: &str) -> PyResult<Option<u64>> {
    let (desc, _) = make::load_target(target).map_err(make_err)?;
    Ok(desc.episode_steps)
}

/// Panics inside the binding's panic guard with `message`: the test suite's way to check that
/// a panic in Rust reaches Python as a `RuntimeError` (not part of the public API).
#[pyfunction]
fn _panic_for_test(message: &str) -> PyResult<()> {
    guarded(|| panic!("{message}")).map_err(PyRuntimeError::new_err)
}

/// The extension module.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Core>()?;
    m.add_class::<Policy>()?;
    m.add_class::<PolicyPlayer>()?;
    m.add_class::<encoder::Encoder>()?;
    m.add("SceneError", m.py().get_type::<SceneError>())?;
    m.add_function(wrap_pyfunction!(task_ids, m)?)?;
    m.add_function(wrap_pyfunction!(scene_episode_steps, m)?)?;
    m.add_function(wrap_pyfunction!(_panic_for_test, m)?)?;
    Ok(())
}
