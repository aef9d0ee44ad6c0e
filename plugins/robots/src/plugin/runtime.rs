//! The per-env robot state: what is fixed at spawn ([`RobotFixed`]), the controller state
//! ([`RobotRuntime`]), every robot of an env ([`Robots`], stateful) and what observations read
//! ([`RobotObservation`]).

use std::sync::Arc;

use bevy_ecs::prelude::*;
use nalgebra::Isometry3;

use modesuite_engine::checkpoint::{Decoder, Encoder, Persist, StateError};
use modesuite_engine::state::{mismatch, StateHasher, Stateful};
use modesuite_engine::RigidContext;

use super::model::Script;
use crate::actions::ActionModes;
use crate::control::{BaseVelocity, HolonomicBase, JointCommand, JointController};
use crate::error::RobotError;
use crate::locomotion::TrotController;
use crate::robot::Robot;

/// What does not change after a robot is spawned.
#[derive(Debug)]
pub struct RobotFixed {
    /// Robot name in the scene.
    pub name: String,
    /// The model's id (its description file's `id`).
    pub model: String,
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
    /// Half extents of the finger volume in the end-effector frame (what a closed gripper
    /// grasps), m.
    pub finger_volume: nalgebra::Vector3<f64>,
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

/// The part of a [`RobotRuntime`] that changes during an episode (its `fixed` facts come from
/// the scene).
type RuntimeState = (
    JointController,
    BaseVelocity,
    Isometry3<f64>,
    bool,
    Option<TrotController>,
);

impl Persist for Robots {
    fn encode(&self, e: &mut Encoder) {
        e.put(&(self.robots.len() as u64));
        for r in &self.robots {
            e.put(&(
                &r.controller,
                &r.base_command,
                &r.ee_target,
                r.gripper_closed,
                &r.gait,
            ));
        }
    }

    fn decode(&mut self, d: &mut Decoder<'_>) -> Result<(), StateError> {
        d.take_len("robots", self.robots.len())?;
        let states = (0..self.robots.len())
            .map(|_| d.take::<RuntimeState>())
            .collect::<Result<Vec<_>, _>>()?;
        for (r, (controller, base, ee, closed, gait)) in self.robots.iter_mut().zip(states) {
            if controller.commands.len() != r.controller.commands.len()
                || gait.is_some() != r.gait.is_some()
            {
                return Err(StateError::part(
                    d.part(),
                    format!(
                        "robot {}: the file's controller does not fit its joints or gait",
                        r.fixed.name
                    ),
                ));
            }
            r.controller = controller;
            r.base_command = base;
            r.ee_target = ee;
            r.gripper_closed = closed;
            r.gait = gait;
        }
        Ok(())
    }
}

impl Stateful for Robots {
    fn save_state(&self) -> Box<dyn std::any::Any + Send + Sync> {
        Box::new(RobotsState(self.robots.clone()))
    }

    fn load_state(&mut self, state: &(dyn std::any::Any + Send + Sync)) -> Result<(), StateError> {
        let s = state
            .downcast_ref::<RobotsState>()
            .ok_or_else(mismatch::<Self>)?;
        self.robots.clone_from(&s.0);
        Ok(())
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
