//! Helpers of the task tests (`tests/tasks.rs`, `tests/task_randomisation.rs`): the task
//! environments made from their ids, task points, the robot base, and scene files of a task
//! folder edited and compiled.
#![allow(dead_code)]

use modesuite::engine::scene::{SceneDesc, SceneSource};
use modesuite::engine::{Env, RigidContext};
use modesuite::robots::Robots;
use modesuite::tasks::TaskPoints;
use nalgebra::Vector3;

pub const PLACE: &str = "MoDe-Franka-Place-v0";

pub fn load(id: &str, actions: Option<&str>) -> (SceneDesc, SceneSource) {
    let (mut desc, source) = modesuite::make::load_target(id).unwrap_or_else(|e| panic!("{e}"));
    if let Some(a) = actions {
        modesuite::make::override_actions(&mut desc, a).unwrap_or_else(|e| panic!("{e}"));
    }
    (desc, source)
}

pub fn make(id: &str, actions: Option<&str>) -> Env {
    let (desc, source) = load(id, actions);
    let mut app = modesuite::make::default_app();
    let model = app
        .compile_scene(&desc, &source)
        .unwrap_or_else(|e| panic!("{e}"));
    app.spawn_scene(model).unwrap_or_else(|e| panic!("{e}"));
    let mut env = Env::new(app);
    env.reset(Some(0));
    env
}

pub fn point(env: &Env, name: &str) -> Vector3<f64> {
    env.app.world.resource::<TaskPoints>().0[name]
}

pub fn base(env: &Env) -> nalgebra::Isometry3<f64> {
    let r = &env.app.world.resource::<Robots>().robots[0];
    r.observe(env.app.world.resource::<RigidContext>())
        .unwrap()
        .base
}

pub fn scene_error(text: &str) -> String {
    scene_error_in("place", text)
}

/// The error of compiling and spawning `text`, a scene in scenes/`task`.
pub fn scene_error_in(task: &str, text: &str) -> String {
    let desc = modesuite::engine::scene::parse_str(text, "<test>").unwrap();
    let mut app = modesuite::make::default_app();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(task);
    match app
        .compile_scene(&desc, &SceneSource::in_memory(dir))
        .and_then(|m| app.spawn_scene(m))
    {
        Ok(_) => panic!("the scene compiled and spawned: {text}"),
        Err(e) => e.to_string(),
    }
}

/// The Franka scene file of `task` (its folder under scenes/) with `from` replaced by `to`.
pub fn task_text(task: &str, from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("scenes")
            .join(task)
            .join("franka.scene.ron"),
    )
    .unwrap();
    assert!(text.contains(from), "{from}");
    text.replace(from, to)
}

/// An app with `text` (a scene in scenes/`task`) compiled and spawned.
pub fn task_app(task: &str, text: &str) -> modesuite::engine::SimApp {
    let desc = modesuite::engine::scene::parse_str(text, "<test>").unwrap();
    let mut app = modesuite::make::default_app();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(task);
    let model = app
        .compile_scene(&desc, &SceneSource::in_memory(dir))
        .unwrap_or_else(|e| panic!("{e}"));
    app.spawn_scene(model).unwrap_or_else(|e| panic!("{e}"));
    app
}

/// The Franka Place scene file with `from` replaced by `to`.
pub fn place_text(from: &str, to: &str) -> String {
    task_text("place", from, to)
}

/// An app with `text` (a scene in scenes/place) compiled and spawned.
pub fn place_app(text: &str) -> modesuite::engine::SimApp {
    task_app("place", text)
}
