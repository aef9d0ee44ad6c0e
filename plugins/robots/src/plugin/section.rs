//! The `robots` scene section: the robot descriptions and scripts as written, and compiling
//! them (checks of scripts and action modes).

use std::sync::Arc;

use bevy_ecs::prelude::*;
use serde::Deserialize;

use modesuite_engine::components::Object;
use modesuite_engine::registry::{CompiledSection, SceneSection, SectionCompileContext};
use modesuite_engine::scene::PoseDesc;
use modesuite_engine::{SceneError, SimApp, Space, Spaces};

use super::spawn::spawn_one;
use super::Robots;
use crate::actions::{ActionConfig, ActionModes, ArmMode, BaseMode, GripperMode};
use crate::error::RobotError;
use crate::locomotion::TrotParams;
use crate::models::{RobotKind, RobotSpec};
use crate::urdf::{AssetPaths, UrdfModel};

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
    /// Registered robot model (`franka`, `spot`).
    pub model: String,
    /// Pose of the robot on the floor (z of the floor point under the base).
    #[serde(default)]
    pub pose: PoseDesc,
    /// Action modes.
    #[serde(default)]
    pub actions: ActionConfig,
    /// Grasp force limit, N (default: the robot's).
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
    /// [`TrotParams`]' fields (default: all at their defaults).
    #[serde(default)]
    pub gait: Option<TrotParams>,
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
}

/// The `robots` scene section.
pub struct RobotsSection;

fn robot_err(path: &str, e: RobotError) -> SceneError {
    SceneError::semantic(path, "(robot)", e.to_string())
}

impl SceneSection for RobotsSection {
    fn name(&self) -> &str {
        "robots"
    }

    fn description(&self) -> &str {
        "robots of the scene: [(name, model, pose, actions, grasp_force_limit, script, start_closed, gait)]"
    }

    fn compile(&self, ctx: &SectionCompileContext) -> Result<CompiledSection, SceneError> {
        let descs: Vec<RobotDesc> = ctx.parse()?;
        let mut out = Vec::with_capacity(descs.len());
        let mut discrete = false;
        for (i, d) in descs.into_iter().enumerate() {
            let path = format!("{}[{i}] \"{}\"", ctx.path(), d.name);
            if d.name.is_empty() || d.name.contains('/') {
                return Err(SceneError::semantic(
                    format!("{path}.name"),
                    format!("{:?}", d.name),
                    "a non-empty name without '/'",
                ));
            }
            if ctx.objects.iter().any(|o| o.name == d.name)
                || out.iter().any(|r: &CompiledRobot| r.desc.name == d.name)
            {
                return Err(SceneError::semantic(
                    format!("{path}.name"),
                    format!("{:?}", d.name),
                    "a name no object or other robot has",
                ));
            }
            let spec = match d.model.as_str() {
                "franka" => RobotSpec::of(RobotKind::Franka),
                "spot" => RobotSpec::of(RobotKind::Spot),
                other => {
                    return Err(SceneError::semantic(
                        format!("{path}.model"),
                        format!("{other:?}"),
                        "a registered robot: [franka, spot]",
                    ))
                }
            };
            if !(d.pose.pos.iter().chain(&d.pose.rpy).all(|x| x.is_finite())) {
                return Err(SceneError::semantic(
                    format!("{path}.pose"),
                    format!("{:?}", d.pose),
                    "finite position (m) and roll, pitch, yaw (rad)",
                ));
            }
            let modes = resolve_modes(&path, &spec, &d.actions)?;
            let limit = d.grasp_force_limit.unwrap_or(match spec.kind {
                // Franka Hand: 70 N continuous grasping force; Spot gripper: 130 N clamp force.
                RobotKind::Franka => 70.0,
                RobotKind::Spot => 130.0,
            });
            if !(limit.is_finite() && limit > 0.0) {
                return Err(SceneError::semantic(
                    format!("{path}.grasp_force_limit"),
                    limit.to_string(),
                    "a finite force > 0, N",
                ));
            }
            if let Some(g) = &d.gait {
                let bad = |expected: String| {
                    SceneError::semantic(format!("{path}.gait"), format!("{g:?}"), expected)
                };
                if spec.leg_joints.is_empty() {
                    return Err(bad("no gait field: only legged robots (spot) walk".into()));
                }
                g.check().map_err(bad)?;
            }
            if let Some(s) = &d.script {
                check_script(&path, s)?;
            } else if modes.discrete {
                discrete = true;
            }
            let model = spec
                .load(&AssetPaths::workspace_default())
                .map_err(|e| robot_err(&format!("{path}.model"), e))?;
            out.push(CompiledRobot {
                desc: d,
                spec,
                model,
                modes,
                grasp_force_limit: limit,
            });
        }
        let acting = out.iter().filter(|r| r.desc.script.is_none()).count();
        if discrete && acting > 1 {
            return Err(SceneError::semantic(
                ctx.path(),
                "(robots)",
                "discrete actions with one acting robot only (the env's action is one Discrete(14) value)",
            ));
        }
        Ok(Arc::new(out))
    }

    fn spawn(&self, app: &mut SimApp, compiled: &CompiledSection) -> Result<(), SceneError> {
        let robots = compiled
            .downcast_ref::<Vec<CompiledRobot>>()
            .ok_or_else(|| {
                SceneError::semantic("extensions[\"robots\"]", "(compiled)", "robots")
            })?;
        let mut next_index = {
            let mut q = app.world.query::<&Object>();
            q.iter(&app.world).map(|o| o.index + 1).max().unwrap_or(0)
        };
        let mut runtime = Vec::with_capacity(robots.len());
        let mut spaces = Vec::new();
        for (i, c) in robots.iter().enumerate() {
            let path = format!("extensions[\"robots\"][{i}] \"{}\"", c.desc.name);
            let r = spawn_one(app, c, &mut next_index).map_err(|e| robot_err(&path, e))?;
            if c.desc.script.is_none() {
                spaces.extend(c.modes.space(
                    &c.desc.name,
                    c.spec.arm_joints.len(),
                    c.spec.leg_joints.len(),
                ));
            }
            runtime.push(r);
        }
        app.world.insert_resource(Robots { robots: runtime });
        let mut s = app.world.get_resource_or_insert_with(Spaces::default);
        s.action = match spaces.len() {
            0 => Space::unbounded(0),
            1 => spaces
                .pop()
                .map(|(_, sp)| sp)
                .unwrap_or(Space::unbounded(0)),
            _ => Space::Dict(spaces),
        };
        Ok(())
    }
}

fn check_script(path: &str, s: &Script) -> Result<(), SceneError> {
    let sorted =
        |ts: Vec<f64>| ts.windows(2).all(|w| w[0] <= w[1]) && ts.iter().all(|t| t.is_finite());
    if !sorted(s.base.iter().map(|b| b.t).collect())
        || s.base
            .iter()
            .any(|b| b.v.iter().any(|x| !x.is_finite() || x.abs() > 1.0))
    {
        return Err(SceneError::semantic(
            format!("{path}.script.base"),
            format!("{:?}", s.base),
            "entries sorted by finite t, each v in [-1, 1]^3",
        ));
    }
    if !sorted(s.ee.iter().map(|e| e.t).collect())
        || s.ee.iter().any(|e| e.pos.iter().any(|x| !x.is_finite()))
    {
        return Err(SceneError::semantic(
            format!("{path}.script.ee"),
            format!("{:?}", s.ee),
            "waypoints sorted by finite t with finite positions",
        ));
    }
    if !sorted(s.gripper.iter().map(|g| g.t).collect()) {
        return Err(SceneError::semantic(
            format!("{path}.script.gripper"),
            format!("{:?}", s.gripper),
            "entries sorted by finite t",
        ));
    }
    if let Some(p) = s.period {
        if !(p.is_finite() && p > 0.0) {
            return Err(SceneError::semantic(
                format!("{path}.script.period"),
                p.to_string(),
                "a finite period > 0, s",
            ));
        }
    }
    Ok(())
}

fn resolve_modes(
    path: &str,
    spec: &RobotSpec,
    c: &ActionConfig,
) -> Result<ActionModes, SceneError> {
    let legged = !spec.leg_joints.is_empty();
    let base = c.base.unwrap_or(if legged {
        BaseMode::Locomotion
    } else {
        BaseMode::Velocity
    });
    let ok = match base {
        BaseMode::Off => true,
        BaseMode::Velocity => spec.base_joints.is_some(),
        BaseMode::Locomotion | BaseMode::LegJoints => legged,
    };
    if !ok {
        let valid = if legged {
            "Locomotion, LegJoints or Off (a legged base)"
        } else {
            "Velocity or Off (a holonomic base)"
        };
        return Err(SceneError::semantic(
            format!("{path}.actions.base"),
            format!("{base:?}"),
            valid,
        ));
    }
    for (field, v) in [
        ("joint_delta_scale", c.joint_delta_scale),
        ("ee_speed", c.ee_speed),
        ("ee_angular_speed", c.ee_angular_speed),
        ("leg_scale", c.leg_scale),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(SceneError::semantic(
                format!("{path}.actions.{field}"),
                v.to_string(),
                "a finite number > 0",
            ));
        }
    }
    Ok(ActionModes {
        base,
        arm: c.arm.unwrap_or(ArmMode::JointDelta),
        gripper: c.gripper.unwrap_or(GripperMode::Binary),
        discrete: c.discrete,
        joint_delta_scale: c.joint_delta_scale,
        ee_speed: c.ee_speed,
        ee_angular_speed: c.ee_angular_speed,
        leg_scale: c.leg_scale,
    })
}
