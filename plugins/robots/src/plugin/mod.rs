//! The robots plugin: robots in scene files, their per-env controllers and action modes.
//!
//! A scene names its robots in the `robots` section:
//! ```ron
//! extensions: {
//!     "robots": [
//!         (name: "robot", model: "franka", pose: (pos: (0, 0, 0), rpy: (0, 0, 0)),
//!          actions: (arm: EePoseDelta)),
//!     ],
//! }
//! ```
//! `model` is a registered robot (`franka`, `spot`, or one a plugin registers). Each env spawns
//! the robot as a rapier multibody, one entity per rapier body (`"robot/panda_link3"`, kind
//! `robot.link`, so `--dump-state` lists link poses and deformables can touch the links), and a
//! root entity (`"robot"`, kind `robot`) with the [`JointState`]. Per env, the [`Robots`]
//! resource holds every robot's controller state (targets, commands, gripper); it is part of the
//! env state, so resets and snapshots restore it.
//!
//! Systems: in `EnvSystems::ProcessActions` each robot reads its slice of the action (see
//! [`crate::actions`]) or follows its `script`; in `SubstepSystems::Predict` the walking
//! controllers plan and the joint controllers write motor targets and gravity compensation before every rapier substep; in
//! `PhysicsSystems::Writeback` the joint states are copied to the root entities.

use std::sync::Arc;

use bevy_ecs::prelude::*;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;

use modesuite_engine::components::{JointState, Object, Pose, Velocity};
use modesuite_engine::coupling::{GripperState, Grippers};
use modesuite_engine::env::ActionBuffer;
use modesuite_engine::registry::{
    CompiledSection, RobotEntry, SceneSection, SectionCompileContext,
};
use modesuite_engine::rigid::RigidRef;
use modesuite_engine::scene::PoseDesc;
use modesuite_engine::state::{StateHasher, Stateful};
use modesuite_engine::{
    EnvSystems, PhysicsSystems, Plugin, RigidContext, RigidSystems, SceneError, SimApp, SimClock,
    SimErrors, SimSettings, Space, Spaces, Substep, SubstepSystems,
};

use crate::actions::{ActionConfig, ActionModes, ArmMode, BaseMode, DiscreteKey, GripperMode};
use crate::control::{BaseVelocity, HolonomicBase, JointCommand, JointController};
use crate::error::RobotError;
use crate::ik::{solve_ik, IkOptions};
use crate::locomotion::{TrotController, TrotParams};
use crate::models::{RobotKind, RobotSpec};
use crate::robot::Robot;
use crate::urdf::{AssetPaths, UrdfModel};

/// Registers the robots (`franka`, `spot`), the `robots` scene section and the controller
/// systems.
pub struct RobotsPlugin;

impl Plugin for RobotsPlugin {
    fn name(&self) -> &str {
        "modesuite.robots"
    }

    fn build(&self, app: &mut SimApp) {
        for kind in [RobotKind::Franka, RobotKind::Spot] {
            let spec = RobotSpec::of(kind);
            app.register_robot(RobotEntry {
                name: spec.id.to_string(),
                description: match kind {
                    RobotKind::Franka => {
                        "Franka Panda with hand on a Clearpath Ridgeback (holonomic)"
                    }
                    RobotKind::Spot => "Spot with Spot Arm (legged, floating base)",
                }
                .to_string(),
                payload: Arc::new(spec),
            });
        }
        app.register_section(RobotsSection);
        app.register_stateful::<Robots>();
        app.register_stateful_component::<JointState>();
        app.world.init_resource::<Robots>();
        app.world.init_resource::<Grippers>();
        app.add_systems(
            modesuite_engine::EnvStep,
            robot_actions.in_set(EnvSystems::ProcessActions),
        );
        app.add_systems(Substep, robot_control.in_set(SubstepSystems::Predict));
        app.add_systems(
            modesuite_engine::PhysicsStep,
            robot_writeback
                .in_set(PhysicsSystems::Writeback)
                .after(RigidSystems::Writeback),
        );
    }
}

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

/// Finger volume of a gripper in its tool frame: half extents, m.
fn finger_volume(kind: RobotKind) -> Vector3<f64> {
    match kind {
        // Between the Panda's fingers: 8 cm opening, 2 cm deep finger pads.
        RobotKind::Franka => Vector3::new(0.015, 0.04, 0.02),
        // Inside Spot's jaw.
        RobotKind::Spot => Vector3::new(0.03, 0.03, 0.02),
    }
}

fn spawn_one(
    app: &mut SimApp,
    c: &CompiledRobot,
    next_index: &mut u32,
) -> Result<RobotRuntime, RobotError> {
    let pose = c.desc.pose.isometry();
    let mut ctx =
        app.world
            .remove_resource::<RigidContext>()
            .ok_or_else(|| RobotError::InvalidInput {
                robot: c.desc.name.clone(),
                message: "robots need the rigid plugin (RigidPlugin)".into(),
            })?;
    let built = build_runtime(app, &mut ctx, c, pose, next_index);
    app.world.insert_resource(ctx);
    built
}

fn build_runtime(
    app: &mut SimApp,
    ctx: &mut RigidContext,
    c: &CompiledRobot,
    pose: Isometry3<f64>,
    next_index: &mut u32,
) -> Result<RobotRuntime, RobotError> {
    let mut robot = c.spec.spawn(ctx, &c.model, pose)?;
    robot.name = c.desc.name.clone();
    let mut controller = JointController::hold_current(&robot, ctx)?;
    controller.gains = c.spec.default_gains(&robot);
    let base = match c.spec.base_joints {
        Some([x, y, yaw]) => Some(HolonomicBase::new(&robot, x, y, yaw)?),
        None => None,
    };
    let arm = c.spec.indices(&robot, c.spec.arm_joints)?;
    let legs = c.spec.indices(&robot, c.spec.leg_joints)?;
    let gripper = robot.joint_index(c.spec.gripper_joints[0])?;
    let ee_frame = robot.frame_index(c.spec.ee_frame)?;
    let base_body = match base {
        Some(b) => robot.joints[b.yaw].body,
        None => 0,
    };
    let q = robot.joint_positions(ctx)?;
    let leg_stand: Vec<f64> = legs.iter().map(|&j| q[j]).collect();
    // Entities: the root (joint state) and one per rapier body (link poses, contact ids).
    let root_pose = robot.body_pose(ctx, base_body)?;
    let root = app
        .world
        .spawn((
            Object {
                name: c.desc.name.clone(),
                index: *next_index,
                kind: "robot".into(),
            },
            Pose(root_pose),
            JointState {
                names: robot.joints.iter().map(|j| j.name.clone()).collect(),
                positions: q.clone(),
                velocities: vec![0.0; q.len()],
            },
        ))
        .id();
    *next_index += 1;
    let mut body_ids = Vec::with_capacity(robot.bodies.len());
    for b in &robot.bodies {
        let p = ctx
            .bodies
            .get(b.handle)
            .map(|rb| modesuite_engine::math::pose_from_rapier(rb.position()))
            .ok_or_else(|| robot.stale("body removed"))?;
        let e = app
            .world
            .spawn((
                Object {
                    name: format!("{}/{}", c.desc.name, b.name),
                    index: *next_index,
                    kind: "robot.link".into(),
                },
                Pose(p),
                Velocity::default(),
                RigidRef(b.handle),
            ))
            .id();
        *next_index += 1;
        body_ids.push(ctx.register_body(b.handle, e));
    }
    let ee_start = robot.body_pose(ctx, base_body)?.inverse() * robot.frame_pose(ctx, ee_frame)?;
    let gripper_body = robot.frames[ee_frame].body;
    let gait = if c.modes.base == BaseMode::Locomotion {
        Some(TrotController::new(
            &robot,
            &c.model,
            &c.spec,
            c.desc.gait.unwrap_or_default(),
        )?)
    } else {
        None
    };
    Ok(RobotRuntime {
        gait,
        fixed: Arc::new(RobotFixed {
            name: c.desc.name.clone(),
            kind: c.spec.kind,
            robot,
            modes: c.modes,
            script: c.desc.script.clone(),
            base,
            base_body,
            arm,
            legs,
            leg_stand,
            gripper,
            gripper_open_closed: c.spec.gripper_open_closed,
            ee_frame,
            gripper_body_id: body_ids[gripper_body],
            grasp_force_limit: c.grasp_force_limit,
            root,
        }),
        controller,
        base_command: BaseVelocity::default(),
        ee_target: ee_start,
        gripper_closed: c.desc.start_closed,
    })
}

/// What does not change after a robot is spawned.
#[derive(Debug)]
pub struct RobotFixed {
    /// Robot name in the scene.
    pub name: String,
    /// Which model.
    pub kind: RobotKind,
    /// Bodies and joints.
    pub robot: Robot,
    /// Action modes.
    pub modes: ActionModes,
    /// Self-driving script.
    pub script: Option<Script>,
    /// Holonomic base joints.
    pub base: Option<HolonomicBase>,
    /// Body index of the base frame (end-effector targets are in its frame).
    pub base_body: usize,
    /// Arm joint indices.
    pub arm: Vec<usize>,
    /// Leg joint indices.
    pub legs: Vec<usize>,
    /// Standing leg pose.
    pub leg_stand: Vec<f64>,
    /// Gripper (leader) joint index.
    pub gripper: usize,
    /// Gripper open and closed positions.
    pub gripper_open_closed: (f64, f64),
    /// End-effector frame index.
    pub ee_frame: usize,
    /// Body id (rigid context) of the body carrying the end-effector.
    pub gripper_body_id: u32,
    /// Grasp force limit, N.
    pub grasp_force_limit: f64,
    /// The robot's root entity.
    pub root: Entity,
}

/// One robot in one env: the fixed part and the controller state.
#[derive(Debug, Clone)]
pub struct RobotRuntime {
    /// Spawn-time facts.
    pub fixed: Arc<RobotFixed>,
    /// Joint commands and gains.
    pub controller: JointController,
    /// Current base command (m/s, m/s, rad/s).
    pub base_command: BaseVelocity,
    /// End-effector target in the base frame (end-effector modes and hand keys).
    pub ee_target: Isometry3<f64>,
    /// Gripper closed.
    pub gripper_closed: bool,
    /// Walking controller (legged base in `Locomotion` mode).
    pub gait: Option<TrotController>,
}

/// Every robot of an env, part of the env state.
#[derive(Resource, Debug, Clone, Default)]
pub struct Robots {
    /// In scene order.
    pub robots: Vec<RobotRuntime>,
}

impl Robots {
    /// A robot by name.
    pub fn get(&self, name: &str) -> Option<&RobotRuntime> {
        self.robots.iter().find(|r| r.fixed.name == name)
    }
}

#[derive(Clone)]
struct RobotsState(Vec<RobotRuntime>);

impl Stateful for Robots {
    fn save_state(&self) -> Box<dyn std::any::Any + Send + Sync> {
        Box::new(RobotsState(self.robots.clone()))
    }

    fn load_state(&mut self, state: &(dyn std::any::Any + Send + Sync)) {
        if let Some(s) = state.downcast_ref::<RobotsState>() {
            self.robots.clone_from(&s.0);
        }
    }

    fn hash_state(&self, h: &mut StateHasher) {
        for r in &self.robots {
            for c in &r.controller.commands {
                match c {
                    JointCommand::Position(q) => {
                        h.write_u64(0);
                        h.write_f64(*q);
                    }
                    JointCommand::Velocity(v) => {
                        h.write_u64(1);
                        h.write_f64(*v);
                    }
                    JointCommand::Passive => h.write_u64(2),
                }
            }
            for x in [r.base_command.vx, r.base_command.vy, r.base_command.wz] {
                h.write_f64(x);
            }
            let t = r.ee_target.translation.vector;
            let q = r.ee_target.rotation.quaternion();
            for x in [t.x, t.y, t.z, q.i, q.j, q.k, q.w] {
                h.write_f64(x);
            }
            h.write_u64(u64::from(r.gripper_closed));
            if let Some(g) = &r.gait {
                h.write_f64(g.phase());
                for f in g.feet() {
                    for x in f.target.iter().chain(f.liftoff.iter()) {
                        h.write_f64(*x);
                    }
                    h.write_u64(u64::from(f.swing));
                }
            }
        }
    }
}

/// Base speed limits (vx m/s, vy m/s, wz rad/s) at a = 1 (SPEC: 0.5, 0.5, 1.0).
pub const BASE_LIMITS: [f64; 3] = [0.5, 0.5, 1.0];

/// What one robot is asked to do this control step, in [-1, 1] units where it applies.
#[derive(Debug, Clone, Default)]
struct Command {
    base: Option<[f64; 3]>,
    legs: Option<Vec<f64>>,
    arm_delta: Option<Vec<f64>>,
    arm_position: Option<Vec<f64>>,
    ee_velocity: Option<[f64; 6]>,
    ee_pose: Option<Isometry3<f64>>,
    gripper: Option<bool>,
}

fn lerp_script(s: &Script, t: f64) -> Command {
    let t = match s.period {
        Some(p) => t.rem_euclid(p),
        None => t,
    };
    let mut cmd = Command::default();
    if !s.base.is_empty() {
        let v = s
            .base
            .iter()
            .rev()
            .find(|b| b.t <= t)
            .map(|b| b.v)
            .unwrap_or([0.0; 3]);
        cmd.base = Some(v);
    }
    if !s.gripper.is_empty() {
        cmd.gripper = Some(
            s.gripper
                .iter()
                .rev()
                .find(|g| g.t <= t)
                .is_some_and(|g| g.closed),
        );
    }
    if let (Some(first), Some(last)) = (s.ee.first(), s.ee.last()) {
        let pos = if t <= first.t {
            first.pos
        } else if t >= last.t {
            last.pos
        } else {
            let k = s.ee.windows(2).find(|w| w[1].t >= t).map(|w| (w[0], w[1]));
            match k {
                Some((a, b)) if b.t > a.t => {
                    let f = (t - a.t) / (b.t - a.t);
                    [0, 1, 2].map(|i| a.pos[i] + f * (b.pos[i] - a.pos[i]))
                }
                Some((_, b)) => b.pos,
                None => last.pos,
            }
        };
        cmd.ee_pose = Some(Isometry3::from_parts(
            Translation3::new(pos[0], pos[1], pos[2]),
            UnitQuaternion::identity(),
        ));
    }
    cmd
}

fn parse_action(f: &RobotFixed, a: &[f32]) -> Command {
    let m = &f.modes;
    let mut cmd = Command::default();
    if m.discrete {
        if let Some(key) = DiscreteKey::from_index(a[0] as usize) {
            let (base, hand, grip) = key.continuous();
            if m.base != BaseMode::Off && m.base != BaseMode::LegJoints {
                cmd.base = Some(base);
            }
            cmd.ee_velocity = Some([hand[0], hand[1], hand[2], 0.0, 0.0, 0.0]);
            cmd.gripper = grip;
        }
        return cmd;
    }
    let (nb, na, ng) = m.dims(f.arm.len(), f.legs.len());
    let v: Vec<f64> = a.iter().map(|x| f64::from(*x)).collect();
    let clip = |x: &[f64]| x.iter().map(|v| v.clamp(-1.0, 1.0)).collect::<Vec<_>>();
    let (b, rest) = v.split_at(nb);
    let (ar, g) = rest.split_at(na);
    match m.base {
        BaseMode::Velocity | BaseMode::Locomotion => {
            let c = clip(b);
            cmd.base = Some([c[0], c[1], c[2]]);
        }
        BaseMode::LegJoints => cmd.legs = Some(clip(b)),
        BaseMode::Off => {}
    }
    match m.arm {
        ArmMode::JointDelta => cmd.arm_delta = Some(clip(ar)),
        ArmMode::JointPosition => cmd.arm_position = Some(clip(ar)),
        ArmMode::EePoseDelta => {
            let c = clip(ar);
            cmd.ee_velocity = Some([c[0], c[1], c[2], c[3], c[4], c[5]]);
        }
        ArmMode::EePoseAbsolute => {
            let rv = Vector3::new(ar[3], ar[4], ar[5]);
            cmd.ee_pose = Some(Isometry3::from_parts(
                Translation3::new(ar[0], ar[1], ar[2]),
                UnitQuaternion::from_scaled_axis(rv),
            ));
        }
        ArmMode::Off => {}
    }
    if ng > 0 {
        cmd.gripper = Some(g[0] > 0.0);
    }
    cmd
}

/// Sets a position target of an arm joint, moved from the previous target by at most the
/// joint's velocity limit times `dt`: the reference the PD motor tracks never runs faster than
/// the URDF's velocity limit, whatever the action mode asks (IK jumps, absolute targets).
fn set_rate_limited(
    r: &mut RobotRuntime,
    robot: &Robot,
    ctx: &RigidContext,
    j: usize,
    q: f64,
    dt: f64,
) -> Result<(), RobotError> {
    let prev = match r.controller.commands[j] {
        JointCommand::Position(p) => p,
        _ => robot.joint_positions(ctx)?[j],
    };
    let step = robot.joints[j].velocity * dt;
    r.controller
        .set_position(robot, j, prev + (q - prev).clamp(-step, step))
}

/// Applies one control step's command to a robot's targets.
fn apply_command(
    r: &mut RobotRuntime,
    ctx: &RigidContext,
    cmd: Command,
    dt: f64,
) -> Result<(), RobotError> {
    let f = r.fixed.clone();
    let robot = &f.robot;
    let m = &f.modes;
    if let Some(b) = cmd.base {
        r.base_command = BaseVelocity {
            vx: b[0] * BASE_LIMITS[0],
            vy: b[1] * BASE_LIMITS[1],
            wz: b[2] * BASE_LIMITS[2],
        };
    }
    if let Some(l) = cmd.legs {
        for ((&j, q0), a) in f.legs.iter().zip(&f.leg_stand).zip(l) {
            r.controller.set_position(robot, j, q0 + m.leg_scale * a)?;
        }
    }
    if let Some(d) = cmd.arm_delta {
        for (&j, a) in f.arm.iter().zip(d) {
            let q = match r.controller.commands[j] {
                JointCommand::Position(q) => q,
                _ => robot.joint_positions(ctx)?[j],
            };
            set_rate_limited(r, robot, ctx, j, q + m.joint_delta_scale * dt * a, dt)?;
        }
    }
    if let Some(p) = cmd.arm_position {
        for (&j, a) in f.arm.iter().zip(p) {
            let jt = &robot.joints[j];
            let (lo, hi) = if jt.lower.is_finite() && jt.upper.is_finite() {
                (jt.lower, jt.upper)
            } else {
                (-std::f64::consts::PI, std::f64::consts::PI)
            };
            set_rate_limited(r, robot, ctx, j, lo + 0.5 * (a + 1.0) * (hi - lo), dt)?;
        }
    }
    let mut solve = false;
    if let Some(v) = cmd.ee_velocity {
        if v.iter().any(|x| *x != 0.0) {
            let dp = Vector3::new(v[0], v[1], v[2]) * (m.ee_speed * dt);
            let dr = Vector3::new(v[3], v[4], v[5]) * (m.ee_angular_speed * dt);
            r.ee_target = Isometry3::from_parts(
                Translation3::from(r.ee_target.translation.vector + dp),
                UnitQuaternion::from_scaled_axis(dr) * r.ee_target.rotation,
            );
            solve = true;
        }
    }
    if let Some(p) = cmd.ee_pose {
        r.ee_target = if f.script.is_some() {
            // Scripts give positions only: keep the orientation.
            Isometry3::from_parts(p.translation, r.ee_target.rotation)
        } else {
            p
        };
        solve = true;
    }
    if solve {
        let world = robot.body_pose(ctx, f.base_body)? * r.ee_target;
        let seed: Vec<f64> = {
            let q = robot.joint_positions(ctx)?;
            q.iter()
                .enumerate()
                .map(|(j, qj)| match r.controller.commands[j] {
                    JointCommand::Position(t) if f.arm.contains(&j) => t,
                    _ => *qj,
                })
                .collect()
        };
        // Seeded from the previous targets, a moving target converges in a few iterations;
        // restarts only run when an attempt ends above the tolerances.
        let opts = IkOptions {
            tol_position: 1e-4,
            tol_angle: 1e-3,
            ..IkOptions::default()
        };
        let sol = solve_ik(robot, ctx, f.ee_frame, &world, &f.arm, Some(&seed), &opts)?;
        for &j in &f.arm {
            set_rate_limited(r, robot, ctx, j, sol.q[j], dt)?;
        }
    }
    if let Some(g) = cmd.gripper {
        r.gripper_closed = g;
    }
    let (open, closed) = f.gripper_open_closed;
    r.controller.set_position(
        robot,
        f.gripper,
        if r.gripper_closed { closed } else { open },
    )?;
    Ok(())
}

fn robot_actions(
    mut robots: ResMut<Robots>,
    action: Res<ActionBuffer>,
    ctx: Option<Res<RigidContext>>,
    settings: Res<SimSettings>,
    clock: Res<SimClock>,
    mut grippers: ResMut<Grippers>,
    mut errors: ResMut<SimErrors>,
) {
    let Some(ctx) = ctx else { return };
    if robots.robots.is_empty() {
        return;
    }
    let dt = settings.dt * f64::from(settings.decimation);
    let mut offset = 0;
    grippers.0.clear();
    for r in robots.robots.iter_mut() {
        let f = r.fixed.clone();
        let cmd = match &f.script {
            Some(s) => lerp_script(s, clock.time),
            None => {
                let n = f.modes.flat_dim(f.arm.len(), f.legs.len());
                let Some(a) = action.0.get(offset..offset + n) else {
                    errors.raise(format!(
                        "robot \"{}\": the action has {} values, the robots need at least {}",
                        f.name,
                        action.0.len(),
                        offset + n
                    ));
                    return;
                };
                offset += n;
                parse_action(&f, a)
            }
        };
        if let Err(e) = apply_command(r, &ctx, cmd, dt) {
            errors.raise(format!("robot \"{}\": {e}", f.name));
        }
        let offset_pose = f.robot.frames[f.ee_frame].offset;
        grippers.0.push(GripperState {
            name: format!("{}/gripper", f.name),
            body: f.gripper_body_id,
            volume_pose: offset_pose,
            half_extents: finger_volume(f.kind),
            closed: r.gripper_closed,
            force_limit: f.grasp_force_limit,
        });
    }
}

fn robot_control(
    mut robots: ResMut<Robots>,
    ctx: Option<ResMut<RigidContext>>,
    settings: Res<SimSettings>,
    mut errors: ResMut<SimErrors>,
) {
    let Some(mut ctx) = ctx else { return };
    for r in robots.robots.iter_mut() {
        let f = r.fixed.clone();
        let result = (|| {
            if let Some(gait) = r.gait.as_mut() {
                // The walking controller plans every substep and writes the leg targets.
                gait.step(
                    &f.robot,
                    &ctx,
                    r.base_command,
                    settings.substep_dt(),
                    &mut r.controller,
                )?;
            }
            if let Some(base) = &f.base {
                // The base command is turned into joint velocities at the current yaw every
                // substep; with no base action the base holds still.
                let v = if f.modes.base == BaseMode::Velocity || f.script.is_some() {
                    r.base_command
                } else {
                    BaseVelocity::default()
                };
                base.command(&f.robot, &ctx, &mut r.controller, v)?;
            }
            r.controller.apply(&f.robot, &mut ctx)
        })();
        if let Err(e) = result {
            errors.raise(format!("robot \"{}\": {e}", f.name));
        }
    }
}

fn robot_writeback(
    robots: Res<Robots>,
    ctx: Option<Res<RigidContext>>,
    mut q: Query<(&mut JointState, &mut Pose)>,
) {
    let Some(ctx) = ctx else { return };
    for r in &robots.robots {
        let f = &r.fixed;
        if let Ok((mut js, mut pose)) = q.get_mut(f.root) {
            if let (Ok(p), Ok(v), Ok(b)) = (
                f.robot.joint_positions(&ctx),
                f.robot.joint_velocities(&ctx),
                f.robot.body_pose(&ctx, f.base_body),
            ) {
                js.positions = p;
                js.velocities = v;
                pose.0 = b;
            }
        }
    }
}

/// The state of a robot as observations read it (s_r of SPEC.md and more).
#[derive(Debug, Clone, PartialEq)]
pub struct RobotObservation {
    /// Base frame pose (world).
    pub base: Isometry3<f64>,
    /// Joint positions, [`Robot::joints`] order.
    pub q: Vec<f64>,
    /// Joint velocities.
    pub qd: Vec<f64>,
    /// End-effector (tool centre point) pose, world.
    pub ee: Isometry3<f64>,
    /// Per rapier body ([`Robot::bodies`] order): touching anything that is not the robot.
    pub link_contacts: Vec<bool>,
    /// Body ids ([`RigidContext::body_of_id`]) of the other bodies the robot touches, sorted.
    pub touching: Vec<u32>,
    /// Gripper closed.
    pub gripper_closed: bool,
}

impl RobotRuntime {
    /// Reads the robot's state from the rigid world.
    pub fn observe(&self, ctx: &RigidContext) -> Result<RobotObservation, RobotError> {
        let f = &self.fixed;
        let robot = &f.robot;
        let own: Vec<_> = robot.bodies.iter().map(|b| b.handle).collect();
        let mut link_contacts = vec![false; robot.bodies.len()];
        let mut touching = Vec::new();
        for (i, b) in robot.bodies.iter().enumerate() {
            let Some(rb) = ctx.bodies.get(b.handle) else {
                continue;
            };
            for &co in rb.colliders() {
                for pair in ctx.narrow_phase.contact_pairs_with(co) {
                    if !pair.has_any_active_contact() {
                        continue;
                    }
                    let other = if pair.collider1 == co {
                        pair.collider2
                    } else {
                        pair.collider1
                    };
                    let other_body = ctx.colliders.get(other).and_then(|c| c.parent());
                    if other_body.is_none_or(|h| !own.contains(&h)) {
                        link_contacts[i] = true;
                        if let Some(id) = other_body.and_then(|h| ctx.body_id(h)) {
                            touching.push(id);
                        }
                    }
                }
            }
        }
        Ok(RobotObservation {
            base: robot.body_pose(ctx, f.base_body)?,
            q: robot.joint_positions(ctx)?,
            qd: robot.joint_velocities(ctx)?,
            ee: robot.frame_pose(ctx, f.ee_frame)?,
            link_contacts,
            touching: {
                touching.sort_unstable();
                touching.dedup();
                touching
            },
            gripper_closed: self.gripper_closed,
        })
    }
}
