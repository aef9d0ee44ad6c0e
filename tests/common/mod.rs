//! Shared test fixtures: a small task-like plugin that exercises actions, randomness,
//! observations and rewards through the public sets, without the tasks plugin.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use modesuite::engine::env::{ActionBuffer, ObservationBuffer, StepSignals};
use modesuite::engine::math::vec_to_rapier;
use modesuite::engine::rigid::RigidRef;
use modesuite::engine::rng::EnvRng;
use modesuite::prelude::*;

/// Repository root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The `modesuite` binary, run in the repository root.
pub fn modesuite_cmd() -> std::process::Command {
    let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_modesuite"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"));
    c
}

/// Runs `cmd`, asserts that it succeeded (showing its stderr if not) and returns its stdout.
pub fn stdout_ok(cmd: &mut std::process::Command) -> String {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "exit {:?}: {}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// Pushes the object named `target` with the action (N s along x) plus a random kick from the
/// env's RNG; observes its height and the step count; rewards its height.
pub struct PokePlugin {
    pub target: &'static str,
    /// Set the target's velocity to NaN at this env step (blow-up test).
    pub poison_at: Option<u64>,
}

#[derive(Resource)]
struct PokeConfig {
    target: String,
    poison_at: Option<u64>,
}

impl Plugin for PokePlugin {
    fn name(&self) -> &str {
        "test.poke"
    }
    fn build(&self, app: &mut SimApp) {
        app.insert_resource(PokeConfig {
            target: self.target.to_string(),
            poison_at: self.poison_at,
        });
        app.insert_resource(Spaces {
            observation: Space::unbounded(2),
            action: Space::Box {
                low: vec![-1.0],
                high: vec![1.0],
                shape: vec![1],
            },
        });
        app.add_systems(PhysicsStep, poke.in_set(PhysicsSystems::ApplyActions));
        app.add_systems(
            EnvStep,
            (observe,)
                .in_set(EnvSystems::Observe)
                .after(modesuite::tasks::TaskSystems::Observe),
        );
        app.add_systems(
            EnvStep,
            reward
                .in_set(EnvSystems::Evaluate)
                .after(modesuite::tasks::TaskSystems::Evaluate)
                .before(EngineSystems::TimeLimit),
        );
    }
}

fn poke(
    cfg: Res<PokeConfig>,
    action: Res<ActionBuffer>,
    clock: Res<SimClock>,
    mut rng: ResMut<EnvRng>,
    mut rigid: ResMut<RigidContext>,
    q: Query<(&Object, &RigidRef)>,
) {
    let kick = 0.002 * rng.normal();
    let a = action.0.first().copied().unwrap_or(0.0) as f64;
    for (obj, r) in &q {
        if obj.name == cfg.target {
            if let Some(b) = rigid.bodies.get_mut(r.0) {
                let j = nalgebra::Vector3::new(0.01 * a + kick, 0.0, 0.0);
                b.apply_impulse(vec_to_rapier(&j), true);
                if cfg.poison_at == Some(clock.episode_steps) {
                    b.set_linvel(
                        vec_to_rapier(&nalgebra::Vector3::new(f64::NAN, 0.0, 0.0)),
                        true,
                    );
                }
            }
        }
    }
}

fn observe(
    cfg: Res<PokeConfig>,
    clock: Res<SimClock>,
    mut obs: ResMut<ObservationBuffer>,
    q: Query<(&Object, &Pose)>,
) {
    obs.0.clear();
    let z = q
        .iter()
        .find(|(o, _)| o.name == cfg.target)
        .map_or(0.0, |(_, p)| p.0.translation.z);
    obs.0.push(z as f32);
    obs.0.push(clock.episode_steps as f32);
}

fn reward(cfg: Res<PokeConfig>, mut s: ResMut<StepSignals>, q: Query<(&Object, &Pose)>) {
    if let Some((_, p)) = q.iter().find(|(o, _)| o.name == cfg.target) {
        s.reward += p.0.translation.z;
        s.values.insert("height".into(), p.0.translation.z);
    }
}

/// An app with the default plugins, the poke plugin and the scene file spawned.
pub fn poke_app(scene: &Path, poison_at: Option<u64>) -> SimApp {
    let (desc, source) = modesuite::engine::scene::load_file(scene).expect("scene loads");
    poke_app_desc(&desc, &source, poison_at)
}

/// Same, from a description.
pub fn poke_app_desc(desc: &SceneDesc, source: &SceneSource, poison_at: Option<u64>) -> SimApp {
    let mut app = modesuite::make::default_app();
    app.add_plugins(PokePlugin {
        target: "box",
        poison_at,
    });
    let model = app.compile_scene(desc, source).expect("scene compiles");
    app.spawn_scene(model).expect("scene spawns");
    app
}

/// The drop scene.
pub fn drop_scene() -> PathBuf {
    root().join("scenes/examples/drop.scene.ron")
}

/// Runs a scene file for `steps` env steps without autoreset, asserting no step fails.
pub fn run_scene(file: &str, steps: u64) -> Env {
    let path = root().join(file);
    let (desc, source) = modesuite::engine::scene::load_file(&path).unwrap();
    let mut app = modesuite::make::default_app();
    let model = app.compile_scene(&desc, &source).unwrap();
    app.spawn_scene(model).unwrap();
    let mut env = Env::new(app);
    env.autoreset = false;
    env.reset(Some(0));
    for i in 0..steps {
        let o = env.step(&[]);
        assert!(
            o.info.error.is_none(),
            "{file} step {i}: {:?}",
            o.info.error
        );
    }
    env
}

/// The node positions of a deformable object by name.
pub fn nodes(env: &mut Env, name: &str) -> Vec<nalgebra::Vector3<f64>> {
    let mut q = env.app.world.query::<(&Object, &DeformableNodes)>();
    q.iter(&env.app.world)
        .find(|(o, _)| o.name == name)
        .map(|(_, n)| n.0.clone())
        .unwrap()
}

/// An app with the default plugins and a scene given as RON text (paths resolve against `.`).
pub fn app_from_ron(text: &str) -> SimApp {
    let desc = modesuite::engine::scene::parse_str(text, "<test>").unwrap();
    let mut app = modesuite::make::default_app();
    let model = app
        .compile_scene(&desc, &SceneSource::in_memory("."))
        .unwrap();
    app.spawn_scene(model).unwrap();
    app
}
pub mod tasks;
