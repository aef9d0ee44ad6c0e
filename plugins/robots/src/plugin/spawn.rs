//! Spawning a compiled robot in an env: its rapier multibody, its entities and its
//! [`RobotRuntime`].

use std::sync::Arc;

use bevy_ecs::prelude::*;
use nalgebra::Isometry3;

use modesuite_engine::components::{JointState, Object, Pose, Velocity};
use modesuite_engine::rigid::RigidRef;
use modesuite_engine::{RigidContext, SimApp};

use super::model::CompiledRobot;
use super::runtime::{RobotFixed, RobotRuntime};
use crate::actions::BaseMode;
use crate::control::{BaseVelocity, HolonomicBase, JointController};
use crate::error::RobotError;
use crate::locomotion::TrotController;

pub(super) fn spawn_one(
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
    let base = match &c.spec.base_joints {
        Some([x, y, yaw]) => Some(HolonomicBase::new(&robot, x, y, yaw)?),
        None => None,
    };
    let arm = c.spec.indices(&robot, &c.spec.arm_joints)?;
    let legs = c.spec.indices(&robot, &c.spec.leg_joints)?;
    let leader = c
        .spec
        .gripper_joints
        .first()
        .ok_or_else(|| RobotError::InvalidInput {
            robot: c.desc.name.clone(),
            message: format!("robot `{}` has no gripper joint", c.spec.id),
        })?;
    let gripper = robot.joint_index(leader)?;
    let ee_frame = robot.frame_index(&c.spec.ee_frame)?;
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
        let params = c.gait.ok_or_else(|| RobotError::InvalidInput {
            robot: c.desc.name.clone(),
            message: format!("robot `{}` has no walking controller", c.spec.id),
        })?;
        Some(TrotController::new(&robot, &c.model, &c.spec, params)?)
    } else {
        None
    };
    Ok(RobotRuntime {
        gait,
        fixed: Arc::new(RobotFixed {
            name: c.desc.name.clone(),
            model: c.spec.id.clone(),
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
            finger_volume: c.spec.finger_volume,
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
