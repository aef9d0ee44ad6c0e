//! Action modes of a robot: how a slice of the env's flat action becomes controller commands.
//!
//! A robot's action is the concatenation of its parts, in this order (dims in brackets):
//! - base: `Velocity` \[3\] = (vx, vy, wz) in [-1, 1], scaled by the base's limits (a holonomic
//!   base); `Locomotion` \[3\] the same command for a legged base's walking controller;
//!   `LegJoints` \[12\] leg targets `q_stand + leg_scale * a`; `Off` \[0\].
//! - arm: `JointDelta` \[n\] `q_target += joint_delta_scale * dt * a` (the precursor's mode);
//!   `JointPosition` \[n\] `a` in [-1, 1] mapped linearly onto the joint limits; `EePoseDelta` \[6\]
//!   (linear and angular velocity of the end-effector target in the base frame, in [-1, 1], scaled
//!   by `ee_speed` and `ee_angular_speed`); `EePoseAbsolute` \[6\] (target position in the base
//!   frame, m, and rotation vector, rad); `Off` \[0\]. End-effector targets are solved by IK over
//!   the arm joints. Whatever the mode, an arm joint's target moves at most at the joint's
//!   URDF velocity limit, so the PD motors never track a reference faster than the limit.
//! - gripper: `Binary` \[1\] (a > 0 closes); `Off` \[0\].
//!
//! With `discrete: true` the robot's whole action is one `Discrete(14)` value, the 14 keys of
//! [`DiscreteKey`], each mapped onto the continuous modes at full speed for one control step.

use serde::{Deserialize, Serialize};

use modesuite_engine::Space;

/// Base part of a robot's action.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
pub enum BaseMode {
    /// No base action (the base holds still).
    Off,
    /// Holonomic base velocity (vx, vy, wz), a wheeled base.
    Velocity,
    /// Body velocity (vx, vy, wz) for the walking controller of a legged base.
    Locomotion,
    /// Direct targets of the 12 leg joints around the standing pose.
    LegJoints,
}

/// Arm part of a robot's action.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
pub enum ArmMode {
    /// No arm action (the arm holds its pose).
    Off,
    /// Joint targets integrate `scale * dt * a`.
    JointDelta,
    /// Joint targets from `a` in [-1, 1] over the joint limits.
    JointPosition,
    /// End-effector target velocity in the base frame (6-D), solved by IK.
    EePoseDelta,
    /// End-effector target pose in the base frame (position, rotation vector), solved by IK.
    EePoseAbsolute,
}

/// Gripper part of a robot's action.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
pub enum GripperMode {
    /// No gripper action (it stays as it starts: open).
    Off,
    /// One value: > 0 closes (and grasps), <= 0 opens (and releases).
    Binary,
}

/// The 14 discrete actions (keys) of both robots, in action-index order (serialised by their
/// snake-case names, as in teleoperation recordings).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DiscreteKey {
    /// Base forward (+x of the base).
    BodyForward,
    /// Base left (+y).
    BodyLeft,
    /// Base right (-y).
    BodyRight,
    /// Base back (-x).
    BodyBack,
    /// Base turns left (+yaw).
    TurnLeft,
    /// Base turns right (-yaw).
    TurnRight,
    /// Hand forward (+x of the base frame).
    HandForward,
    /// Hand back (-x).
    HandBack,
    /// Hand left (+y).
    HandLeft,
    /// Hand right (-y).
    HandRight,
    /// Hand up (+z).
    HandUp,
    /// Hand down (-z).
    HandDown,
    /// Close the gripper.
    Grasp,
    /// Open the gripper.
    Release,
}

impl DiscreteKey {
    /// All keys, index order.
    pub const ALL: [DiscreteKey; 14] = [
        DiscreteKey::BodyForward,
        DiscreteKey::BodyLeft,
        DiscreteKey::BodyRight,
        DiscreteKey::BodyBack,
        DiscreteKey::TurnLeft,
        DiscreteKey::TurnRight,
        DiscreteKey::HandForward,
        DiscreteKey::HandBack,
        DiscreteKey::HandLeft,
        DiscreteKey::HandRight,
        DiscreteKey::HandUp,
        DiscreteKey::HandDown,
        DiscreteKey::Grasp,
        DiscreteKey::Release,
    ];

    /// The key of an action index.
    pub fn from_index(i: usize) -> Option<Self> {
        Self::ALL.get(i).copied()
    }

    /// The action index (0..14).
    pub fn index(self) -> usize {
        self as usize
    }

    /// Snake-case name (`body_forward`, ..., `release`).
    pub fn name(self) -> &'static str {
        match self {
            DiscreteKey::BodyForward => "body_forward",
            DiscreteKey::BodyLeft => "body_left",
            DiscreteKey::BodyRight => "body_right",
            DiscreteKey::BodyBack => "body_back",
            DiscreteKey::TurnLeft => "turn_left",
            DiscreteKey::TurnRight => "turn_right",
            DiscreteKey::HandForward => "hand_forward",
            DiscreteKey::HandBack => "hand_back",
            DiscreteKey::HandLeft => "hand_left",
            DiscreteKey::HandRight => "hand_right",
            DiscreteKey::HandUp => "hand_up",
            DiscreteKey::HandDown => "hand_down",
            DiscreteKey::Grasp => "grasp",
            DiscreteKey::Release => "release",
        }
    }

    /// What the key means in continuous terms: a base command in [-1, 1]^3, a hand velocity
    /// direction in [-1, 1]^3 (base frame) and a gripper command (Some(true) closes).
    pub fn continuous(self) -> ([f64; 3], [f64; 3], Option<bool>) {
        let mut base = [0.0; 3];
        let mut hand = [0.0; 3];
        let mut grip = None;
        match self {
            DiscreteKey::BodyForward => base[0] = 1.0,
            DiscreteKey::BodyBack => base[0] = -1.0,
            DiscreteKey::BodyLeft => base[1] = 1.0,
            DiscreteKey::BodyRight => base[1] = -1.0,
            DiscreteKey::TurnLeft => base[2] = 1.0,
            DiscreteKey::TurnRight => base[2] = -1.0,
            DiscreteKey::HandForward => hand[0] = 1.0,
            DiscreteKey::HandBack => hand[0] = -1.0,
            DiscreteKey::HandLeft => hand[1] = 1.0,
            DiscreteKey::HandRight => hand[1] = -1.0,
            DiscreteKey::HandUp => hand[2] = 1.0,
            DiscreteKey::HandDown => hand[2] = -1.0,
            DiscreteKey::Grasp => grip = Some(true),
            DiscreteKey::Release => grip = Some(false),
        }
        (base, hand, grip)
    }
}

fn default_joint_delta_scale() -> f64 {
    1.0
}
fn default_ee_speed() -> f64 {
    0.25
}
fn default_ee_angular_speed() -> f64 {
    0.5
}
fn default_leg_scale() -> f64 {
    0.5
}

/// How a robot reads its action (the `actions:` field of a robot in the `robots` section).
/// Fields left out take the robot's defaults: `franka` (Velocity, JointDelta, Binary), `spot`
/// (Locomotion, JointDelta, Binary).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActionConfig {
    /// Base part.
    #[serde(default)]
    pub base: Option<BaseMode>,
    /// Arm part.
    #[serde(default)]
    pub arm: Option<ArmMode>,
    /// Gripper part.
    #[serde(default)]
    pub gripper: Option<GripperMode>,
    /// One `Discrete(14)` action instead of the continuous parts.
    #[serde(default)]
    pub discrete: bool,
    /// `JointDelta` scale, rad/s at a = 1 (the precursor's `scale`).
    #[serde(default = "default_joint_delta_scale")]
    pub joint_delta_scale: f64,
    /// `EePoseDelta` and hand-key speed, m/s at a = 1.
    #[serde(default = "default_ee_speed")]
    pub ee_speed: f64,
    /// `EePoseDelta` angular speed, rad/s at a = 1.
    #[serde(default = "default_ee_angular_speed")]
    pub ee_angular_speed: f64,
    /// `LegJoints` range around the standing pose, rad at a = 1.
    #[serde(default = "default_leg_scale")]
    pub leg_scale: f64,
}

impl ActionConfig {
    /// Parses an `actions:` value written on its own (command-line overrides); errors are RON's.
    pub fn parse_ron(text: &str) -> Result<Self, String> {
        modesuite_engine::scene::ron_options()
            .from_str(text)
            .map_err(|e| e.to_string())
    }
}

impl Default for ActionConfig {
    fn default() -> Self {
        Self {
            base: None,
            arm: None,
            gripper: None,
            discrete: false,
            joint_delta_scale: default_joint_delta_scale(),
            ee_speed: default_ee_speed(),
            ee_angular_speed: default_ee_angular_speed(),
            leg_scale: default_leg_scale(),
        }
    }
}

/// The resolved modes of one robot (defaults filled in, checked against the robot).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActionModes {
    /// Base part.
    pub base: BaseMode,
    /// Arm part.
    pub arm: ArmMode,
    /// Gripper part.
    pub gripper: GripperMode,
    /// Discrete keys instead of the parts.
    pub discrete: bool,
    /// See [`ActionConfig::joint_delta_scale`].
    pub joint_delta_scale: f64,
    /// See [`ActionConfig::ee_speed`].
    pub ee_speed: f64,
    /// See [`ActionConfig::ee_angular_speed`].
    pub ee_angular_speed: f64,
    /// See [`ActionConfig::leg_scale`].
    pub leg_scale: f64,
}

impl ActionModes {
    /// Dims of the base, arm and gripper parts for an arm of `arm_joints` joints and
    /// `leg_joints` legs joints.
    pub fn dims(&self, arm_joints: usize, leg_joints: usize) -> (usize, usize, usize) {
        let base = match self.base {
            BaseMode::Off => 0,
            BaseMode::Velocity | BaseMode::Locomotion => 3,
            BaseMode::LegJoints => leg_joints,
        };
        let arm = match self.arm {
            ArmMode::Off => 0,
            ArmMode::JointDelta | ArmMode::JointPosition => arm_joints,
            ArmMode::EePoseDelta | ArmMode::EePoseAbsolute => 6,
        };
        let gripper = match self.gripper {
            GripperMode::Off => 0,
            GripperMode::Binary => 1,
        };
        (base, arm, gripper)
    }

    /// The action space of one robot named `name`: `Discrete(14)` as `name/discrete`, or boxes
    /// `name/base`, `name/arm`, `name/gripper` (absent parts left out).
    pub fn space(&self, name: &str, arm_joints: usize, leg_joints: usize) -> Vec<(String, Space)> {
        if self.discrete {
            return vec![(
                format!("{name}/discrete"),
                Space::Discrete {
                    n: DiscreteKey::ALL.len() as u64,
                },
            )];
        }
        let (b, a, g) = self.dims(arm_joints, leg_joints);
        let unit = |n: usize| Space::Box {
            low: vec![-1.0; n],
            high: vec![1.0; n],
            shape: vec![n],
        };
        let mut out = Vec::new();
        if b > 0 {
            out.push((format!("{name}/base"), unit(b)));
        }
        if a > 0 {
            let space = if self.arm == ArmMode::EePoseAbsolute {
                Space::unbounded(a)
            } else {
                unit(a)
            };
            out.push((format!("{name}/arm"), space));
        }
        if g > 0 {
            out.push((format!("{name}/gripper"), unit(g)));
        }
        out
    }

    /// Number of f32 values this robot reads from the flat action.
    pub fn flat_dim(&self, arm_joints: usize, leg_joints: usize) -> usize {
        if self.discrete {
            return 1;
        }
        let (b, a, g) = self.dims(arm_joints, leg_joints);
        b + a + g
    }
}
