//! The fuzz targets: one per parser or loader that takes user input, each with its seed corpus
//! from the shipped files. A target returns `Ok` when the input was accepted (and, for inputs
//! that build an env, stepped), `Err` with the message when it was refused; panicking, hanging
//! or returning a non-finite observation or reward to the caller is a defect.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use modesuite_engine::scene::{self, SceneSource};
use modesuite_engine::shapes::{load_surface_bytes, load_volume_bytes};
use modesuite_engine::Env;
use modesuite_robots::urdf::{parse_urdf, AssetPaths};
use modesuite_tasks::expert::{make_policy, PolicyKind};

use crate::make::{default_app, env_for_target, override_actions, scenes_dir};

/// One fuzz target.
pub struct Target {
    /// Name (`modesuite fuzz NAME`).
    pub name: &'static str,
    /// What it feeds the input to.
    pub about: &'static str,
    /// The seed corpus (shipped files and small meshes written for it).
    pub seeds: fn() -> Vec<Vec<u8>>,
    /// Runs one input.
    pub run: fn(&[u8]) -> Result<(), String>,
}

/// Every target, in the order `modesuite fuzz all` runs them.
pub const TARGETS: &[Target] = &[
    Target {
        name: "scene",
        about: "scene files (RON): parse, compile, spawn with every default plugin, 4 random-action steps",
        seeds: scene_seeds,
        run: run_scene,
    },
    Target {
        name: "task",
        about: "task sections (RON) in the Franka Place scene: compile, spawn, 4 random-action steps",
        seeds: task_seeds,
        run: run_task,
    },
    Target {
        name: "robot",
        about: "robot description files (RON) used by a scene: load with their URDF, spawn, 4 steps",
        seeds: robot_seeds,
        run: run_robot,
    },
    Target {
        name: "urdf",
        about: "URDF text: parse and check",
        seeds: urdf_seeds,
        run: run_urdf,
    },
    Target {
        name: "actions",
        about: "action modes (`run --actions` RON) on the Franka Place scene: compile, spawn, 4 steps",
        seeds: action_seeds,
        run: run_actions,
    },
    Target {
        name: "obj",
        about: "Wavefront OBJ surfaces",
        seeds: || vec![OBJ.as_bytes().to_vec()],
        run: |b| surface("fuzz.obj", b),
    },
    Target {
        name: "stl",
        about: "STL surfaces, ASCII and binary",
        seeds: || vec![STL_ASCII.as_bytes().to_vec(), stl_binary()],
        run: |b| surface("fuzz.stl", b),
    },
    Target {
        name: "msh",
        about: "gmsh MSH 4.1 ASCII tetrahedral volumes",
        seeds: || vec![MSH.as_bytes().to_vec()],
        run: |b| volume("fuzz.msh", b),
    },
    Target {
        name: "medit",
        about: "medit .mesh tetrahedral volumes",
        seeds: || vec![MEDIT.as_bytes().to_vec()],
        run: |b| volume("fuzz.mesh", b),
    },
    Target {
        name: "state",
        about: "binary state files (`run --save-state`) of Franka Place, Bend and Uncover, loaded and stepped 4 times",
        seeds: state_seeds,
        run: run_state,
    },
    Target {
        name: "state_body",
        about: "state file bodies re-sealed with a valid checksum (a careless tool's edits), loaded and stepped 4 times",
        seeds: state_body_seeds,
        run: run_state_body,
    },
    Target {
        name: "checkpoint",
        about: "training checkpoints (checkpoint.bin of a small PPO run) resumed for one more iteration",
        seeds: checkpoint_seeds,
        run: run_checkpoint,
    },
    Target {
        name: "checkpoint_body",
        about: "training checkpoints with their hash re-sealed after the edit (a careless tool's), resumed",
        seeds: checkpoint_seeds,
        run: |b| run_checkpoint(&resealed_checkpoint(b)),
    },
    Target {
        name: "policy",
        about: "policy folders (policy.json, a NUL line, weights.bpk) loaded with Policy::load and asked for an action",
        seeds: policy_seeds,
        run: run_policy,
    },
    Target {
        name: "generated",
        about: "random valid scenes (every shape generator; rigid, FEM and cloth bodies) from the input's seed, 20 steps",
        seeds: || (0u64..8).map(|k| k.to_le_bytes().to_vec()).collect(),
        run: run_generated,
    },
    Target {
        name: "tasks",
        about: "the 16 tasks under random and bang-bang actions from the input's seed, 30 steps each way",
        seeds: || (0u64..2).map(|k| k.to_le_bytes().to_vec()).collect(),
        run: run_tasks,
    },
];

/// The target of this name.
pub fn target(name: &str) -> Option<&'static Target> {
    TARGETS.iter().find(|t| t.name == name)
}

fn text(b: &[u8]) -> Result<&str, String> {
    std::str::from_utf8(b).map_err(|e| format!("not UTF-8: {e}"))
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_default()
}

/// Files under `dir` (recursively) whose names end in `suffix`, sorted.
fn files(dir: &Path, suffix: &str) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.to_string_lossy().ends_with(suffix) {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

fn assets_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets")
}

/// A private folder holding every shipped task file (so any scene's `extends` resolves) and
/// the robot URDFs (for robot description inputs), made once per process.
fn workdir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("modesuite-fuzz-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&dir);
        let _ = std::fs::write(dir.join(super::generated::SURFACE_MESH), CLOSED_TETRA_OBJ);
        // An open, non-manifold surface (the `obj` seed), for scenes that name it.
        let _ = std::fs::write(dir.join("fuzz-open.obj"), OBJ);
        let _ = std::fs::write(dir.join(super::generated::VOLUME_MESH), MSH);
        for f in files(&scenes_dir(), ".task.ron")
            .into_iter()
            .chain(files(&assets_dir().join("robots"), ".urdf"))
        {
            if let Some(name) = f.file_name() {
                let _ = std::fs::copy(&f, dir.join(name));
            }
        }
        dir
    })
}

/// Steps an env 4 times with uniform random actions; a non-finite observation or reward
/// returned to the caller is a defect (reported as a panic so the campaign counts it).
fn exercise(mut env: Env) -> Result<(), String> {
    let mut policy = make_policy(PolicyKind::Random, &env)?;
    let (obs, _) = env.reset(Some(3));
    assert_finite("reset observation", &obs);
    policy.reset(3);
    let mut action = vec![0.0f32; env.spaces().action.flat_dim()];
    for _ in 0..4 {
        policy.act(&env, &mut action)?;
        let out = env.step(&action);
        assert_finite("observation", &out.observation);
        assert!(out.reward.is_finite(), "non-finite reward {}", out.reward);
    }
    Ok(())
}

fn assert_finite(what: &str, v: &[f32]) {
    if let Some((i, x)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
        panic!("{what}[{i}] = {x} returned to the caller");
    }
}

/// Compiles and spawns a scene with every default plugin, then steps it ([`exercise`]).
fn spawn_and_exercise(desc: &scene::SceneDesc, source: &SceneSource) -> Result<(), String> {
    let mut app = default_app();
    let model = app.compile_scene(desc, source).map_err(|e| e.to_string())?;
    app.spawn_scene(model).map_err(|e| e.to_string())?;
    exercise(Env::new(app))
}

/// Compiles and spawns scene text read from `file` (a name in the work folder), then steps it.
fn scene_env(text: &str, file: &Path) -> Result<(), String> {
    let desc = scene::parse_str(text, &file.display().to_string()).map_err(|e| e.to_string())?;
    let source = SceneSource {
        file: Some(file.to_path_buf()),
        base_dir: file.parent().map(Path::to_path_buf).unwrap_or_default(),
        asset_roots: scene::default_asset_roots(),
        text: Some(text.to_string()),
    };
    spawn_and_exercise(&desc, &source)
}

/// A path in the work folder private to this thread (parallel tests do not share it).
fn thread_path(prefix: &str, suffix: &str) -> PathBuf {
    let id = format!("{:?}", std::thread::current().id()).replace(['(', ')'], "");
    workdir().join(format!("{prefix}-{id}{suffix}"))
}

/// The contents of the files under `dir` ending in `suffix`.
fn contents(dir: &Path, suffix: &str) -> Vec<Vec<u8>> {
    files(dir, suffix).iter().map(|p| read(p)).collect()
}

fn scene_seeds() -> Vec<Vec<u8>> {
    contents(&scenes_dir(), ".scene.ron")
}

fn run_scene(b: &[u8]) -> Result<(), String> {
    scene_env(text(b)?, &workdir().join("fuzz.scene.ron"))
}

/// The Franka Place scene, parsed once.
fn place_desc() -> Result<&'static scene::SceneDesc, String> {
    static DESC: OnceLock<Result<scene::SceneDesc, String>> = OnceLock::new();
    DESC.get_or_init(|| {
        scene::load_file(&scenes_dir().join("place/franka.scene.ron"))
            .map(|(d, _)| d)
            .map_err(|e| e.to_string())
    })
    .as_ref()
    .map_err(Clone::clone)
}

fn task_seeds() -> Vec<Vec<u8>> {
    let own = place_desc()
        .ok()
        .and_then(|d| d.extensions.get("task"))
        .map(|t| t.get_ron().as_bytes().to_vec());
    own.into_iter()
        .chain(contents(&scenes_dir(), ".task.ron"))
        .collect()
}

/// The Franka Place scene with its `task` section replaced by the input.
fn run_task(b: &[u8]) -> Result<(), String> {
    let mut desc = place_desc()?.clone();
    let section = ron::value::RawValue::from_boxed_ron(text(b)?.into())
        .map_err(|e| format!("task section: {e}"))?;
    desc.extensions.insert("task".into(), section);
    let mut source = SceneSource::in_memory(workdir());
    source.asset_roots = scene::default_asset_roots();
    spawn_and_exercise(&desc, &source)
}

fn robot_seeds() -> Vec<Vec<u8>> {
    contents(&assets_dir().join("robots"), ".robot.ron")
}

/// The pedestal example scene with its robot model pointing at `model`.
fn run_robot(b: &[u8]) -> Result<(), String> {
    let dir = workdir();
    let file = thread_path("fuzz", ".robot.ron");
    std::fs::write(&file, b).map_err(|e| format!("work file: {e}"))?;
    let scene_text = String::from_utf8(read(
        &scenes_dir().join("examples/franka_pedestal.scene.ron"),
    ))
    .unwrap_or_default()
    .replace(
        "\"../../assets/robots/franka_pedestal/franka_pedestal.robot.ron\"",
        &format!("{:?}", file.display().to_string()),
    );
    let desc = scene::parse_str(&scene_text, "fuzz.scene.ron").map_err(|e| e.to_string())?;
    let mut source = SceneSource::in_memory(dir);
    source.asset_roots = scene::default_asset_roots();
    source.asset_roots.push(dir.to_path_buf());
    spawn_and_exercise(&desc, &source)
}

fn urdf_seeds() -> Vec<Vec<u8>> {
    contents(&assets_dir().join("robots"), ".urdf")
}

fn run_urdf(b: &[u8]) -> Result<(), String> {
    let dir = workdir();
    parse_urdf(text(b)?, "fuzz.urdf", dir, &AssetPaths::new(dir))
        .map(|_| ())
        .map_err(|e| e.to_string())
}

fn action_seeds() -> Vec<Vec<u8>> {
    [
        "(base: Velocity, arm: EePoseDelta, gripper: Binary)",
        "(base: Velocity, arm: JointDelta, gripper: Off)",
        "(base: Discrete, arm: EePoseDelta, gripper: Binary)",
        "(arm: JointPosition, gripper: Off)",
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .collect()
}

fn run_actions(b: &[u8]) -> Result<(), String> {
    let file = scenes_dir().join("place/franka.scene.ron");
    let (mut desc, source) = scene::load_file(&file).map_err(|e| e.to_string())?;
    override_actions(&mut desc, text(b)?).map_err(|e| e.to_string())?;
    spawn_and_exercise(&desc, &source)
}

fn surface(label: &str, b: &[u8]) -> Result<(), String> {
    load_surface_bytes(Path::new(label), b)
        .map(|_| ())
        .map_err(|e| e.to_string())
}

fn volume(label: &str, b: &[u8]) -> Result<(), String> {
    let v = load_volume_bytes(Path::new(label), b).map_err(|e| e.to_string())?;
    let _ = v.mesh.boundary_surface_compact();
    Ok(())
}

/// The tasks state inputs are loaded into: a rigid-and-FEM task, an FEM rod task and a cloth
/// task, so every solver's part of a state file is decoded.
const STATE_TASKS: &[&str] = &[
    "MoDe-Franka-Place-v0",
    "MoDe-Franka-Bend-v0",
    "MoDe-Franka-Uncover-v0",
];

fn task_env(id: &str) -> Result<Env, String> {
    env_for_target(id, None).map_err(|e| e.to_string())
}

/// The fingerprint of each of [`STATE_TASKS`]' envs (computed once).
fn state_fingerprints() -> &'static [(u64, &'static str)] {
    static F: OnceLock<Vec<(u64, &'static str)>> = OnceLock::new();
    F.get_or_init(|| {
        STATE_TASKS
            .iter()
            .filter_map(|id| task_env(id).ok().map(|e| (e.fingerprint(), *id)))
            .collect()
    })
}

fn state_seeds() -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    for id in STATE_TASKS {
        let Ok(mut env) = task_env(id) else {
            continue;
        };
        env.reset(Some(5));
        out.extend(env.save_state().ok());
        let action = vec![0.1f32; env.spaces().action.flat_dim()];
        for _ in 0..10 {
            env.step(&action);
        }
        out.extend(env.save_state().ok());
    }
    out
}

/// Loads a state file into a fresh env of the task whose fingerprint its header names (Franka
/// Place when none does: the load must then refuse it) and steps it 4 times.
fn run_state(b: &[u8]) -> Result<(), String> {
    let id = modesuite_engine::checkpoint::read_header(b)
        .ok()
        .and_then(|h| {
            state_fingerprints()
                .iter()
                .find(|(f, _)| *f == h.fingerprint)
                .map(|(_, id)| *id)
        })
        .unwrap_or(STATE_TASKS[0]);
    let mut env = task_env(id)?;
    env.load_state(b).map_err(|e| e.to_string())?;
    let action = vec![0.0f32; env.spaces().action.flat_dim()];
    for _ in 0..4 {
        let out = env.step(&action);
        assert_finite("observation", &out.observation);
        assert!(out.reward.is_finite(), "non-finite reward {}", out.reward);
    }
    Ok(())
}

/// The seed an input stands for (its first 8 bytes, little-endian, zero-padded).
fn seed_of(b: &[u8]) -> u64 {
    let mut w = [0u8; 8];
    for (d, s) in w.iter_mut().zip(b) {
        *d = *s;
    }
    u64::from_le_bytes(w)
}

/// An episode error must say which object or body failed (a quoted name).
fn check_error_names_object(info: &modesuite_engine::EnvInfo) {
    if let Some(e) = &info.error {
        assert!(e.contains('"'), "an episode error names no object: {e}");
    }
}

/// Steps of each generated scene.
const GENERATED_STEPS: usize = 20;

fn run_generated(b: &[u8]) -> Result<(), String> {
    let text = super::generated::random_scene(seed_of(b));
    let desc = scene::parse_str(&text, "generated.scene.ron").map_err(|e| e.to_string())?;
    let mut app = default_app();
    let model = app
        .compile_scene(&desc, &SceneSource::in_memory(workdir()))
        .map_err(|e| e.to_string())?;
    app.spawn_scene(model).map_err(|e| e.to_string())?;
    let mut env = Env::new(app);
    let (obs, _) = env.reset(Some(seed_of(b)));
    assert_finite("reset observation", &obs);
    let action = vec![0.0f32; env.spaces().action.flat_dim()];
    for _ in 0..GENERATED_STEPS {
        let out = env.step(&action);
        assert_finite("observation", &out.observation);
        assert!(out.reward.is_finite(), "non-finite reward {}", out.reward);
        check_error_names_object(&out.info);
    }
    Ok(())
}

fn run_tasks(b: &[u8]) -> Result<(), String> {
    let seed = seed_of(b);
    for id in modesuite_tasks::all_ids() {
        let mut env = task_env(&id)?;
        let mut policy = make_policy(PolicyKind::Random, &env)?;
        let (obs, _) = env.reset(Some(seed));
        assert_finite("reset observation", &obs);
        policy.reset(seed);
        let space = env.spaces().action;
        let dim = space.flat_dim();
        let mut action = vec![0.0f32; dim];
        for k in 0..60 {
            if k < 30 {
                policy.act(&env, &mut action)?;
            } else if let modesuite_engine::Space::Box { low, high, .. } = &space {
                // bang-bang: every value at a bound, switching every few steps
                for (i, a) in action.iter_mut().enumerate() {
                    let up = (k / 3 + i) % 2 == 0;
                    *a = if up {
                        high[i].min(1.0)
                    } else {
                        low[i].max(-1.0)
                    };
                }
            }
            let out = env.step(&action);
            assert_finite(&format!("{id} observation"), &out.observation);
            assert!(
                out.reward.is_finite(),
                "{id}: non-finite reward {}",
                out.reward
            );
            check_error_names_object(&out.info);
        }
    }
    Ok(())
}

/// A small PPO run on Franka Place (2 envs, 64-step rollouts, a 16-unit network) in `dir`.
fn small_run(dir: &Path, env_steps: u64) -> Result<(), String> {
    let req = crate::learning::TrainRequest {
        target: "MoDe-Franka-Place-v0".into(),
        algo: "ppo".into(),
        seed: Some(0),
        env_steps: Some(env_steps),
        envs: 2,
        threads: 1,
        out: dir.to_path_buf(),
        config: None,
        set: vec!["horizon=64".into(), "hidden=[16]".into()],
        checkpoint_every: 1,
        actions: None,
        command: "fuzz".into(),
        log_env_calls: false,
    };
    crate::learning::train(&req, |_| {})
        .map(|_| ())
        .map_err(|e| e.to_string())
}

/// The folder of the seed run (made once per process).
fn seed_run() -> Option<&'static Path> {
    static RUN: OnceLock<Option<PathBuf>> = OnceLock::new();
    RUN.get_or_init(|| {
        let dir = workdir().join("seed-run");
        let _ = std::fs::remove_dir_all(&dir);
        small_run(&dir, 128).ok().map(|()| dir)
    })
    .as_deref()
}

fn checkpoint_seeds() -> Vec<Vec<u8>> {
    seed_run()
        .map(|d| read(&d.join("checkpoint.bin")))
        .into_iter()
        .filter(|b| !b.is_empty())
        .collect()
}

/// Resumes the seed run from `b` as its checkpoint, for one more iteration (128 env steps).
fn run_checkpoint(b: &[u8]) -> Result<(), String> {
    let seed = seed_run().ok_or("the seed run could not be made")?;
    let dir = thread_path("ckpt", "");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    for f in ["config.ron", "metrics.jsonl"] {
        std::fs::copy(seed.join(f), dir.join(f)).map_err(|e| e.to_string())?;
    }
    std::fs::write(dir.join("checkpoint.bin"), b).map_err(|e| e.to_string())?;
    small_run(&dir, 256)
}

/// `b` with its last 8 bytes replaced by the FNV-1a hash of the rest, as checkpoints end.
fn resealed_checkpoint(b: &[u8]) -> Vec<u8> {
    let n = b.len().saturating_sub(8);
    let mut out = b[..n].to_vec();
    out.extend(modesuite_learn::checkpoint::fnv1a(&out).to_le_bytes());
    out
}

/// The separator of a `policy` input's two files.
const POLICY_SEPARATOR: &[u8] = b"\n\0\n";

fn policy_seeds() -> Vec<Vec<u8>> {
    let Some(d) = seed_run() else {
        return Vec::new();
    };
    let mut b = read(&d.join("policy/policy.json"));
    b.extend_from_slice(POLICY_SEPARATOR);
    b.extend(read(&d.join("policy/weights.bpk")));
    vec![b]
}

/// Loads a policy folder made of the input's two parts and asks it for an action.
fn run_policy(b: &[u8]) -> Result<(), String> {
    let (json, weights) = match b
        .windows(POLICY_SEPARATOR.len())
        .position(|w| w == POLICY_SEPARATOR)
    {
        Some(k) => (&b[..k], &b[k + POLICY_SEPARATOR.len()..]),
        None => (b, &b[b.len()..]),
    };
    let dir = thread_path("policy", "");
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    std::fs::write(dir.join("policy.json"), json).map_err(|e| e.to_string())?;
    std::fs::write(dir.join("weights.bpk"), weights).map_err(|e| e.to_string())?;
    let p = modesuite_learn::Policy::load(&dir).map_err(|e| e.to_string())?;
    let a = p.act(&vec![0.5f32; p.obs_dim()]);
    assert_finite("policy action", &a);
    Ok(())
}

/// Length of a state file's magic and version.
const STATE_PREFIX: usize = modesuite_engine::checkpoint::MAGIC.len() + 4;

fn state_body_seeds() -> Vec<Vec<u8>> {
    state_seeds()
        .into_iter()
        .filter(|b| b.len() > STATE_PREFIX + 8)
        .map(|b| b[STATE_PREFIX..b.len() - 8].to_vec())
        .collect()
}

/// A state file around `body`: magic, version, body and the checksum the loader checks.
fn sealed(body: &[u8]) -> Vec<u8> {
    let mut out = modesuite_engine::checkpoint::MAGIC.to_vec();
    out.extend(modesuite_engine::checkpoint::FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(body);
    let mut h = modesuite_engine::state::StateHasher::default();
    h.write_bytes(&out);
    out.extend(h.finish().to_le_bytes());
    out
}

fn run_state_body(b: &[u8]) -> Result<(), String> {
    run_state(&sealed(b))
}

const OBJ: &str = "# a unit tetrahedron and a quad\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 1 1 0\n\
vt 0 0\nvn 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\nf 2/1 5/1 3/1\nf -1 -2 -3\n";

/// A closed tetrahedron, 10 cm legs (what generated scenes' rigid `Mesh` bodies load).
const CLOSED_TETRA_OBJ: &str =
    "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

const STL_ASCII: &str = "solid t\nfacet normal 0 0 -1\nouter loop\nvertex 0 0 0\nvertex 0 1 0\n\
vertex 1 0 0\nendloop\nendfacet\nfacet normal 0 -1 0\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n\
vertex 0 0 1\nendloop\nendfacet\nfacet normal -1 0 0\nouter loop\nvertex 0 0 0\nvertex 0 0 1\n\
vertex 0 1 0\nendloop\nendfacet\nfacet normal 1 1 1\nouter loop\nvertex 1 0 0\nvertex 0 1 0\n\
vertex 0 0 1\nendloop\nendfacet\nendsolid t\n";

/// The ASCII STL's four triangles in the binary layout.
fn stl_binary() -> Vec<u8> {
    let tris: [[[f32; 3]; 3]; 4] = [
        [[0., 0., 0.], [0., 1., 0.], [1., 0., 0.]],
        [[0., 0., 0.], [1., 0., 0.], [0., 0., 1.]],
        [[0., 0., 0.], [0., 0., 1.], [0., 1., 0.]],
        [[1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
    ];
    let mut b = vec![0u8; 80];
    b.extend((tris.len() as u32).to_le_bytes());
    for t in tris {
        b.extend([0u8; 12]);
        for v in t {
            for c in v {
                b.extend(c.to_le_bytes());
            }
        }
        b.extend([0u8; 2]);
    }
    b
}

const MSH: &str = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 5 1 5\n3 1 0 5\n1\n2\n3\n4\n5\n\
0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n$EndNodes\n$Elements\n2 3 1 3\n2 1 2 1\n6 1 2 3\n3 1 4 2\n\
1 1 2 3 4\n2 2 3 4 5\n$EndElements\n";

const MEDIT: &str = "MeshVersionFormatted 2\nDimension\n3\nVertices\n5\n0 0 0 1\n1 0 0 1\n\
0 1 0 1\n0 0 1 1\n1 1 1 1\nTriangles\n1\n1 2 3 1\nTetrahedra\n2\n1 2 3 4 1\n2 3 4 5 1\nEnd\n";
