//! # modesuite-robots
//!
//! Robots for modesuite: URDF loading into rapier multibodies (reduced coordinates), the
//! project's Franka-on-Ridgeback and Spot-with-arm models, joint PD control with gravity
//! compensation, holonomic base velocity control and damped-least-squares inverse kinematics.
//!
//! - [`urdf`]: asset search path (`package://` without ROS, refusing paths that escape the asset
//!   roots), parsing (urdf-rs, guarded against panics) and validation into a [`UrdfModel`].
//! - [`robot`]: [`spawn_robot`] builds a model into a `RigidContext`; [`Robot`] reads and sets
//!   joint positions and frame poses.
//! - [`control`]: [`JointController`] (position/velocity motors + gravity feed-forward),
//!   [`HolonomicBase`].
//! - [`ik`]: [`solve_ik`], [`forward_kinematics`].
//! - [`description`]: robot description files (`*.robot.ron`, [`RobotFile`]) and the robots
//!   built into the binary (`franka`, `spot`).
//! - [`models`]: [`RobotSpec`], a robot model built from its description file (URDF text, joint
//!   groups, home pose, gains, action modes).
//!
//! - [`actions`]: action modes (base, arm, gripper, 14 discrete keys).
//! - [`plugin`]: [`RobotsPlugin`]: the `robots` scene section, per-env controllers ([`Robots`]),
//!   action processing, joint states for observations and `--dump-state`.

#![deny(missing_docs)]

pub mod actions;
pub mod control;
pub mod description;
pub mod error;
pub mod gait;
pub mod ik;
pub mod locomotion;
pub mod models;
pub mod plugin;
pub mod robot;
pub mod urdf;

pub use actions::{ActionConfig, ActionModes, ArmMode, BaseMode, DiscreteKey, GripperMode};
pub use control::{BaseVelocity, HolonomicBase, JointCommand, JointController, JointGains};
pub use description::RobotFile;
pub use error::RobotError;
pub use ik::{forward_kinematics, solve_ik, IkOptions, IkSolution};
pub use locomotion::{FootState, LegKinematics, LegTargets, TrotController, TrotParams};
pub use models::RobotSpec;
pub use plugin::{RobotObservation, RobotRuntime, Robots, RobotsPlugin};
pub use robot::{spawn_robot, Robot, RobotBody, RobotFrame, RobotJoint, RootMount, SpawnOptions};
pub use urdf::{read_urdf, AssetPaths, UrdfModel};
