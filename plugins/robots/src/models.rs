//! The project's two robots: where their URDFs are, how they are mounted, their named poses and
//! joint groups.

use std::path::{Path, PathBuf};

use modesuite_engine::deps::nalgebra::Isometry3;
use modesuite_engine::RigidContext;

use crate::control::JointGains;
use crate::error::RobotError;
use crate::robot::{spawn_robot, Robot, RootMount, SpawnOptions};
use crate::urdf::{parse_urdf, AssetPaths, UrdfModel};

/// Which robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RobotKind {
    /// Franka Panda on a Clearpath Ridgeback (holonomic base through 3 virtual joints).
    Franka,
    /// Boston Dynamics Spot with Spot Arm (floating base, 12 leg joints).
    Spot,
}

/// Static description of a robot model: file, mount, joint groups, named poses.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotSpec {
    /// Which robot.
    pub kind: RobotKind,
    /// Registry id (`franka`, `spot`).
    pub id: &'static str,
    /// URDF path relative to `assets/robots/`.
    pub urdf: &'static str,
    /// The URDF's text, built into the binary (a build or a checkout moved after building
    /// still loads its models).
    pub urdf_text: &'static str,
    /// Root mount.
    pub root: RootMount,
    /// Height of the root frame above the floor in the home pose, m.
    pub root_height: f64,
    /// Virtual base joints (x, y, yaw) for a holonomic base.
    pub base_joints: Option<[&'static str; 3]>,
    /// Leg joints (empty for wheeled bases).
    pub leg_joints: &'static [&'static str],
    /// Arm joints, shoulder to wrist.
    pub arm_joints: &'static [&'static str],
    /// Gripper joints (mimic joints included).
    pub gripper_joints: &'static [&'static str],
    /// Gripper open and closed positions of the first gripper joint.
    pub gripper_open_closed: (f64, f64),
    /// End-effector frame (tool centre point).
    pub ee_frame: &'static str,
    /// Home pose: (joint, position) for every joint not at zero.
    pub home: &'static [(&'static str, f64)],
    /// Gauss-Seidel sweeps per rapier substep of its robot-only scenes
    /// (`physics.rigid_pgs_iterations`; rapier's default is 1): 4 for the Franka, whose seven
    /// arm motors, solved one after another, overshoot a 0.3 rad step by 8.8 % at 1/240 s and
    /// 16.5 % at 1/120 s with 1 sweep, 2.5 % and 3.6 % with 4 (robot tests,
    /// `franka_pd_tracking_with_gravity_compensation`); 24 for Spot at 1/60 s, where the stance
    /// feet need converged friction: with 8 the trot walked 0.34 m/s for 0.5 and fell under the
    /// pulled arm, with 12 it drifted 0.11 m/s forward while side-stepping (tol 0.1), with 16
    /// 0.07, with 24 0.05 (locomotion tests). Sweeps are cheap beside the multibody's mass
    /// matrix: `bench robots` spot 3,052 steps/s with 16, 3,065 with 24, 2,947 with 32.
    pub pgs_iterations: u32,
    /// Physics substeps per 1/60 s step its controllers are validated at when it is alone
    /// (`physics.substeps` of its robot-only scenes and of `modesuite bench robots`): 1 for
    /// both (the robot and locomotion tests pass at 1/60 s).
    /// Scenes may take more: the locomotion tests also validate Spot at 2 substeps with 8
    /// sweeps and 4 with 4. Spot's task scenes keep 1 and give their FEM finer steps
    /// (`physics.deformable_substeps`) or their cloth more cloth substeps, except Cover (4
    /// substeps, 1 sweep).
    pub substeps: u32,
}

const FRANKA_ARM: &[&str] = &[
    "panda_joint1",
    "panda_joint2",
    "panda_joint3",
    "panda_joint4",
    "panda_joint5",
    "panda_joint6",
    "panda_joint7",
];

const SPOT_LEGS: &[&str] = &[
    "fl_hx", "fl_hy", "fl_kn", "fr_hx", "fr_hy", "fr_kn", "hl_hx", "hl_hy", "hl_kn", "hr_hx",
    "hr_hy", "hr_kn",
];

const SPOT_ARM: &[&str] = &[
    "arm_sh0", "arm_sh1", "arm_el0", "arm_el1", "arm_wr0", "arm_wr1",
];

/// Position gain of Spot's leg joints, N m/rad (the walking controller's gain): the knee's
/// standing load (about 20 N m) costs about 0.025 rad of error.
pub const LEG_KP: f64 = 800.0;
/// Velocity gain of Spot's leg joints, N m s/rad.
pub const LEG_KD: f64 = 15.0;

/// Spot standing pose: hip pitch 0.77 rad and knee -1.43 rad put each foot under its hip with
/// the body origin 0.55 m above the floor (foot sphere radius included).
pub const SPOT_STAND_HY: f64 = 0.77;
/// Knee angle of the standing pose, rad.
pub const SPOT_STAND_KN: f64 = -1.43;

impl RobotSpec {
    /// The specification of a robot.
    pub fn of(kind: RobotKind) -> Self {
        match kind {
            RobotKind::Franka => Self {
                kind,
                id: "franka",
                urdf: "franka_ridgeback/franka_ridgeback.urdf",
                urdf_text: include_str!(
                    "../../../assets/robots/franka_ridgeback/franka_ridgeback.urdf"
                ),
                root: RootMount::Fixed,
                root_height: 0.0,
                base_joints: Some(["base_x", "base_y", "base_yaw"]),
                leg_joints: &[],
                arm_joints: FRANKA_ARM,
                gripper_joints: &["panda_finger_joint1", "panda_finger_joint2"],
                gripper_open_closed: (0.04, 0.0),
                ee_frame: "panda_hand_tcp",
                // Arm pose of Isaac Lab's RIDGEBACK_FRANKA_PANDA_CFG, fingers open.
                home: &[
                    ("panda_joint2", -0.569),
                    ("panda_joint4", -2.810),
                    ("panda_joint6", 2.0),
                    ("panda_joint7", 0.741),
                    ("panda_finger_joint1", 0.04),
                    ("panda_finger_joint2", 0.04),
                ],
                pgs_iterations: 4,
                substeps: 1,
            },
            RobotKind::Spot => Self {
                kind,
                id: "spot",
                urdf: "spot_arm/spot_arm.urdf",
                urdf_text: include_str!("../../../assets/robots/spot_arm/spot_arm.urdf"),
                root: RootMount::Floating,
                root_height: 0.55,
                base_joints: None,
                leg_joints: SPOT_LEGS,
                arm_joints: SPOT_ARM,
                gripper_joints: &["arm_f1x"],
                gripper_open_closed: (-std::f64::consts::FRAC_PI_2, 0.0),
                ee_frame: "arm_link_tool",
                // Standing legs; arm stowed (folded back over the body); gripper closed.
                home: &[
                    ("fl_hy", SPOT_STAND_HY),
                    ("fl_kn", SPOT_STAND_KN),
                    ("fr_hy", SPOT_STAND_HY),
                    ("fr_kn", SPOT_STAND_KN),
                    ("hl_hy", SPOT_STAND_HY),
                    ("hl_kn", SPOT_STAND_KN),
                    ("hr_hy", SPOT_STAND_HY),
                    ("hr_kn", SPOT_STAND_KN),
                    ("arm_sh1", -3.0),
                    ("arm_el0", 3.0),
                ],
                pgs_iterations: 24,
                substeps: 1,
            },
        }
    }

    /// Path of the URDF inside `assets` (the `package://modesuite_robots/` package) where this
    /// binary was built; [`RobotSpec::load`] reads the copy built into the binary.
    pub fn urdf_path(&self) -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../assets/robots")
            .join(self.urdf)
    }

    /// Parses and validates the built-in URDF text (named by [`RobotSpec::urdf_path`] in
    /// messages; relative mesh paths would start from its folder).
    pub fn load(&self, assets: &AssetPaths) -> Result<UrdfModel, RobotError> {
        let path = self.urdf_path();
        let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        parse_urdf(self.urdf_text, &path.display().to_string(), &base, assets)
    }

    /// Builds the robot in its home pose with its root at `pose` (the floor point under the root
    /// for Spot: the root height is added).
    pub fn spawn(
        &self,
        ctx: &mut RigidContext,
        model: &UrdfModel,
        pose: Isometry3<f64>,
    ) -> Result<Robot, RobotError> {
        let mut pose = pose;
        pose.translation.vector.z += self.root_height;
        spawn_robot(
            ctx,
            model,
            &SpawnOptions {
                pose,
                root: self.root,
                initial: self.home.iter().map(|(n, v)| (n.to_string(), *v)).collect(),
                friction: 0.8,
            },
        )
    }

    /// Default PD gains per joint: inertia-scaled (25 rad/s, critically damped) for arm, gripper
    /// and base joints; for legs absolute gains of [`LEG_KP`] N m/rad and [`LEG_KD`] N m s/rad,
    /// because a standing leg's load is the body's weight, not its own inertia.
    pub fn default_gains(&self, robot: &Robot) -> Vec<JointGains> {
        robot
            .joints
            .iter()
            .map(|j| {
                if self.leg_joints.contains(&j.name.as_str()) {
                    JointGains::Absolute {
                        kp: LEG_KP,
                        kd: LEG_KD,
                    }
                } else {
                    JointGains::default()
                }
            })
            .collect()
    }

    /// Joint indices of a group of names.
    pub fn indices(&self, robot: &Robot, names: &[&str]) -> Result<Vec<usize>, RobotError> {
        names.iter().map(|n| robot.joint_index(n)).collect()
    }
}
