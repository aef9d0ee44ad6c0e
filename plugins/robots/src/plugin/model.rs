//! The robots section's data: a robot as a scene writes it ([`RobotDesc`]), its scripted
//! commands ([`Script`]) and its compiled form ([`CompiledRobot`]).

use modesuite_engine::deps::ron;
use modesuite_engine::scene::PoseDesc;
use serde::Deserialize;

use crate::actions::{ActionConfig, ActionModes};
use crate::gait::TrotParams;
use crate::models::RobotSpec;
use crate::urdf::UrdfModel;

/// One piece of a scripted base command: from time `t` (s since the episode start) on, drive
/// with `v` = (vx, vy, wz) in [-1, 1] of the base's limits.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptBase {
    /// Start time, s.
    pub t: f64,
    /// Command (vx, vy, wz), each in [-1, 1].
    pub v: [f64; 3],
}

/// One waypoint of a scripted end-effector path: at time `t` the tool centre point is at `pos`
/// (base frame, m); positions are interpolated linearly, the orientation is held.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptEe {
    /// Time, s.
    pub t: f64,
    /// Position in the base frame, m.
    pub pos: [f64; 3],
}

/// One gripper command of a script: from time `t` the gripper is closed or open.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptGripper {
    /// Start time, s.
    pub t: f64,
    /// Closed (grasps what is between the fingers) or open (releases).
    pub closed: bool,
}

/// A robot that drives itself (demo scenes): base commands, an end-effector path and gripper
/// commands, repeated every `period` seconds when given. A scripted robot takes no part of the
/// env's action.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Script {
    /// Piecewise-constant base commands, sorted by time.
    #[serde(default)]
    pub base: Vec<ScriptBase>,
    /// Piecewise-linear end-effector waypoints, sorted by time.
    #[serde(default)]
    pub ee: Vec<ScriptEe>,
    /// Piecewise-constant gripper commands, sorted by time (open before the first).
    #[serde(default)]
    pub gripper: Vec<ScriptGripper>,
    /// Repeat period, s.
    #[serde(default)]
    pub period: Option<f64>,
}

/// One robot of the `robots` section.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotDesc {
    /// Unique name (entities are `name` and `name/link`).
    pub name: String,
    /// Registered robot model (`franka`, `spot`) or a robot description file
    /// (`*.robot.ron`), relative to the scene's folder (or to an asset root).
    pub model: String,
    /// Pose of the robot on the floor (z of the floor point under the base).
    #[serde(default)]
    pub pose: PoseDesc,
    /// Action modes.
    #[serde(default)]
    pub actions: ActionConfig,
    /// Grasp force limit, N (default: the robot file's `gripper.grasp_force_limit`).
    #[serde(default)]
    pub grasp_force_limit: Option<f64>,
    /// Self-driving script (demo scenes); the robot then takes no action.
    #[serde(default)]
    pub script: Option<Script>,
    /// The gripper starts closed (the elastic tasks start with the rod or belt in the hand;
    /// with the gripper action `Off` it stays closed).
    #[serde(default)]
    pub start_closed: bool,
    /// Parameters of the walking controller (`base: Locomotion`), any subset of
    /// [`TrotParams`]' fields; the others keep the robot file's `walking` values. Kept as
    /// written; [`CompiledRobot::gait`] holds the result.
    #[serde(default)]
    pub gait: Option<Box<ron::value::RawValue>>,
}

/// A compiled robot: model, spec, modes.
#[derive(Debug)]
pub struct CompiledRobot {
    /// As written.
    pub desc: RobotDesc,
    /// Model facts.
    pub spec: RobotSpec,
    /// The parsed URDF.
    pub model: UrdfModel,
    /// Resolved action modes.
    pub modes: ActionModes,
    /// Grasp force limit, N.
    pub grasp_force_limit: f64,
    /// Parameters of the walking controller: the robot file's `walking` with the scene's
    /// `gait` fields in their place (legged robots with a walking controller).
    pub gait: Option<TrotParams>,
}

/// The payload of a registered robot whose built-in description file does not load: the
/// message a scene naming it reports.
#[derive(Debug, Clone)]
pub struct BrokenRobot(pub String);
