//! # modesuite-tasks
//!
//! The MoDeSuite tasks: managers (observation groups, rewards, success, terminations, reset
//! events) in ECS form, a term library registered by name, the environments
//! `MoDe-<Robot>-<Task>-v0` as scene files with a `task` section, and policies (`zero`,
//! `random`, `scripted` experts).
//!
//! A task is a scene file (`scenes/<task>/<robot>.scene.ron`) whose `extensions` hold the robot
//! and a `task` section ([`desc::TaskDesc`]); a section may `extends` a shared `*.task.ron` and
//! override its entries by name. [`TasksPlugin`] registers the section, the term library
//! ([`terms`]) and the systems ([`manager`]). Task ids resolve to scene files with
//! [`task_scene_path`].
//!
//! Status: the managers, the term library, policies, and [`IMPLEMENTED`] environments with
//! their scripted experts. The other ids are known and answer with a clear "not implemented
//! yet".

pub mod desc;
pub mod events;
pub mod expert;
pub mod manager;
pub mod terms;

use std::path::{Path, PathBuf};

use modesuite_engine::{Plugin, SimApp};

pub use desc::{EventDesc, PointRef, TaskDesc};
pub use events::{register_task_event, EventCtx, TaskEvent, TaskEventFactory};
pub use expert::{
    make_policy, register_expert, Expert, ExpertContext, Experts, Policy, PolicyKind,
};
pub use manager::{
    Task, TaskModel, TaskObservations, TaskPoints, TaskSection, TaskState, TaskSystems,
};
pub use terms::{register_task_term, Configure, Dims, TaskCtx, TaskTerm, TaskTermFactory};

/// The two robots, as written in ids.
pub const ROBOTS: [&str; 2] = ["Franka", "Spot"];
/// The eight tasks, as written in ids.
pub const TASKS: [&str; 8] = [
    "Place",
    "Bend",
    "Transport",
    "Drag",
    "Lift",
    "Uncover",
    "Cover",
    "Curtain",
];
/// The environments implemented so far (the others answer "not implemented yet").
pub const IMPLEMENTED: [&str; 16] = [
    "MoDe-Franka-Place-v0",
    "MoDe-Spot-Place-v0",
    "MoDe-Franka-Curtain-v0",
    "MoDe-Spot-Curtain-v0",
    "MoDe-Franka-Bend-v0",
    "MoDe-Spot-Bend-v0",
    "MoDe-Franka-Transport-v0",
    "MoDe-Spot-Transport-v0",
    "MoDe-Franka-Drag-v0",
    "MoDe-Spot-Drag-v0",
    "MoDe-Franka-Lift-v0",
    "MoDe-Spot-Lift-v0",
    "MoDe-Franka-Uncover-v0",
    "MoDe-Spot-Uncover-v0",
    "MoDe-Franka-Cover-v0",
    "MoDe-Spot-Cover-v0",
];

/// All 16 environment ids, robot-major.
pub fn all_ids() -> Vec<String> {
    ROBOTS
        .iter()
        .flat_map(|r| TASKS.iter().map(move |t| format!("MoDe-{r}-{t}-v0")))
        .collect()
}

/// Splits `MoDe-<Robot>-<Task>-v0` into (robot, task); errors say what is valid.
pub fn parse_id(id: &str) -> Result<(&'static str, &'static str), String> {
    let bad = || {
        format!(
            "{id}: not a task id; ids are MoDe-<Robot>-<Task>-v0 with Robot in {ROBOTS:?} and Task in {TASKS:?}"
        )
    };
    let rest = id.strip_prefix("MoDe-").ok_or_else(bad)?;
    let rest = rest.strip_suffix("-v0").ok_or_else(bad)?;
    let (r, t) = rest.split_once('-').ok_or_else(bad)?;
    let r = ROBOTS.iter().find(|x| **x == r).ok_or_else(bad)?;
    let t = TASKS.iter().find(|x| **x == t).ok_or_else(bad)?;
    Ok((r, t))
}

/// The scene file of a task id under `scenes_dir`: `<task>/<robot>.scene.ron`, lower case.
/// Ids not implemented yet are an error saying so.
pub fn task_scene_path(scenes_dir: &Path, id: &str) -> Result<PathBuf, String> {
    let (robot, task) = parse_id(id)?;
    if !IMPLEMENTED.contains(&id) {
        return Err(format!(
            "{id}: this environment is not implemented yet; implemented: {}",
            IMPLEMENTED.join(", ")
        ));
    }
    Ok(scenes_dir
        .join(task.to_lowercase())
        .join(format!("{}.scene.ron", robot.to_lowercase())))
}

/// Scene and task files compiled into the binary, by path under `scenes/` (task ids resolve to
/// them when the scenes folder is not on disk; `extends` inside them resolves here too).
pub const EMBEDDED: &[(&str, &str)] = &[
    (
        "bend/bend.task.ron",
        include_str!("../../../scenes/bend/bend.task.ron"),
    ),
    (
        "bend/franka.scene.ron",
        include_str!("../../../scenes/bend/franka.scene.ron"),
    ),
    (
        "bend/spot.scene.ron",
        include_str!("../../../scenes/bend/spot.scene.ron"),
    ),
    (
        "transport/transport.task.ron",
        include_str!("../../../scenes/transport/transport.task.ron"),
    ),
    (
        "transport/franka.scene.ron",
        include_str!("../../../scenes/transport/franka.scene.ron"),
    ),
    (
        "transport/spot.scene.ron",
        include_str!("../../../scenes/transport/spot.scene.ron"),
    ),
    (
        "drag/drag.task.ron",
        include_str!("../../../scenes/drag/drag.task.ron"),
    ),
    (
        "drag/franka.scene.ron",
        include_str!("../../../scenes/drag/franka.scene.ron"),
    ),
    (
        "drag/spot.scene.ron",
        include_str!("../../../scenes/drag/spot.scene.ron"),
    ),
    (
        "lift/lift.task.ron",
        include_str!("../../../scenes/lift/lift.task.ron"),
    ),
    (
        "lift/franka.scene.ron",
        include_str!("../../../scenes/lift/franka.scene.ron"),
    ),
    (
        "lift/spot.scene.ron",
        include_str!("../../../scenes/lift/spot.scene.ron"),
    ),
    (
        "place/place.task.ron",
        include_str!("../../../scenes/place/place.task.ron"),
    ),
    (
        "place/franka.scene.ron",
        include_str!("../../../scenes/place/franka.scene.ron"),
    ),
    (
        "place/spot.scene.ron",
        include_str!("../../../scenes/place/spot.scene.ron"),
    ),
    (
        "curtain/curtain.task.ron",
        include_str!("../../../scenes/curtain/curtain.task.ron"),
    ),
    (
        "curtain/franka.scene.ron",
        include_str!("../../../scenes/curtain/franka.scene.ron"),
    ),
    (
        "curtain/spot.scene.ron",
        include_str!("../../../scenes/curtain/spot.scene.ron"),
    ),
    (
        "uncover/uncover.task.ron",
        include_str!("../../../scenes/uncover/uncover.task.ron"),
    ),
    (
        "uncover/franka.scene.ron",
        include_str!("../../../scenes/uncover/franka.scene.ron"),
    ),
    (
        "uncover/spot.scene.ron",
        include_str!("../../../scenes/uncover/spot.scene.ron"),
    ),
    (
        "cover/cover.task.ron",
        include_str!("../../../scenes/cover/cover.task.ron"),
    ),
    (
        "cover/franka.scene.ron",
        include_str!("../../../scenes/cover/franka.scene.ron"),
    ),
    (
        "cover/spot.scene.ron",
        include_str!("../../../scenes/cover/spot.scene.ron"),
    ),
];

/// The base folder name of embedded files (`SceneSource::in_memory("<embedded>/place")`).
pub const EMBEDDED_DIR: &str = "<embedded>";

/// An embedded file by its path under `scenes/`.
pub fn embedded(path: &str) -> Option<&'static str> {
    EMBEDDED.iter().find(|(p, _)| *p == path).map(|(_, t)| *t)
}

/// The RON options of scene files (implicit `Some`).
pub(crate) fn ron_options() -> ron::Options {
    modesuite_engine::scene::ron_options()
}

/// Registers the `task` scene section, the term library and the task systems.
pub struct TasksPlugin;

impl Plugin for TasksPlugin {
    fn name(&self) -> &str {
        "modesuite.tasks"
    }

    fn build(&self, app: &mut SimApp) {
        terms::register_library(app);
        expert::register_builtin_experts(app);
        app.register_section(TaskSection);
        app.insert_resource(TaskObservations::default());
        app.insert_resource(TaskPoints::default());
        manager::add_task_systems(app);
    }
}
