//! A robot model as the simulation uses it ([`RobotSpec`]): built from a description file
//! ([`crate::description`]), with its URDF text, joint groups, named poses and gains.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use modesuite_engine::deps::nalgebra::{Isometry3, Vector3};
use modesuite_engine::RigidContext;

use crate::actions::{ArmMode, BaseMode, GripperMode};
use crate::control::JointGains;
use crate::description::{
    join_lexically, BaseDesc, BuiltinRobot, GainsDesc, RobotFile, WalkingDesc, BUILTIN,
};
use crate::error::RobotError;
use crate::gait::TrotParams;
use crate::robot::{spawn_robot, Robot, RootMount, SpawnOptions};
use crate::urdf::{parse_urdf, AssetPaths, UrdfModel};

/// A robot model: what its description file says, resolved (mount, joint groups, named poses,
/// gains, action modes), with its URDF's text.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotSpec {
    /// Registry id (`franka`, `spot`, or a file's `id`).
    pub id: String,
    /// One line for `modesuite list robots`.
    pub description: String,
    /// The description file (for messages; for a built-in robot, where it was when the binary
    /// was built).
    pub file: PathBuf,
    /// The URDF file (for messages; relative mesh paths start from its folder).
    pub urdf: PathBuf,
    /// The URDF's text (built into the binary for the built-in robots, so a build or a
    /// checkout moved after building still loads its models).
    pub urdf_text: Arc<str>,
    /// Folders the URDF's files may come from besides the build's `assets/` (the description
    /// file's folder and the scene's folders, for a robot read from a file).
    pub asset_roots: Vec<PathBuf>,
    /// Root mount.
    pub root: RootMount,
    /// Height of the root frame above the floor in the home pose, m.
    pub root_height: f64,
    /// Virtual base joints (x, y, yaw) of a holonomic base.
    pub base_joints: Option<[String; 3]>,
    /// Leg joints (empty without legs).
    pub leg_joints: Vec<String>,
    /// Arm joints, shoulder to wrist.
    pub arm_joints: Vec<String>,
    /// Gripper joints (mimic joints included); the first is commanded.
    pub gripper_joints: Vec<String>,
    /// Gripper open and closed positions of the first gripper joint.
    pub gripper_open_closed: (f64, f64),
    /// Half extents of the finger volume in the end-effector frame, m.
    pub finger_volume: Vector3<f64>,
    /// Default grasp force limit, N.
    pub grasp_force_limit: f64,
    /// End-effector frame (tool centre point).
    pub ee_frame: String,
    /// Cameras mounted on its links.
    pub cameras: Vec<crate::description::CameraMountDesc>,
    /// Home pose: (joint, position) for every joint not at zero.
    pub home: Vec<(String, f64)>,
    /// Base modes it accepts, the default first.
    pub base_modes: Vec<BaseMode>,
    /// Arm modes it accepts, the default first.
    pub arm_modes: Vec<ArmMode>,
    /// Gripper modes it accepts, the default first.
    pub gripper_modes: Vec<GripperMode>,
    /// PD gains per joint group.
    pub gains: GainsDesc,
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
    /// Default parameters of the walking controller (legged robots).
    pub walking: Option<TrotParams>,
}

/// The built-in robots' folder where this binary was built (`assets/robots/`).
fn builtin_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../assets/robots")
}

impl RobotSpec {
    /// The ids of the robots built into the binary.
    pub fn builtin_ids() -> Vec<String> {
        BUILTIN
            .iter()
            .filter_map(|b| RobotFile::parse(b.text, b.file).ok())
            .map(|f| f.id)
            .collect()
    }

    /// A robot built into the binary, by id (`franka`, `spot`).
    pub fn builtin(id: &str) -> Result<Self, RobotError> {
        for b in &BUILTIN {
            let spec = Self::from_builtin(b)?;
            if spec.id == id {
                return Ok(spec);
            }
        }
        Err(RobotError::UnknownName {
            robot: id.to_string(),
            what: "built-in robot",
            name: format!("{id} (built in: {})", Self::builtin_ids().join(", ")),
        })
    }

    /// Every robot built into the binary, each parsed from its embedded file.
    pub fn builtins() -> Vec<Result<Self, RobotError>> {
        BUILTIN.iter().map(Self::from_builtin).collect()
    }

    fn from_builtin(b: &BuiltinRobot) -> Result<Self, RobotError> {
        let file = builtin_dir().join(b.file);
        let label = file.display().to_string();
        let desc = RobotFile::parse(b.text, &label)?;
        let rel = join_lexically(
            Path::new(b.file).parent().unwrap_or(Path::new("")),
            &desc.urdf,
        );
        if rel != Path::new(b.urdf) {
            return Err(RobotError::Description {
                file: label,
                field: "urdf".into(),
                value: format!("{:?}", desc.urdf),
                expected: format!("the URDF built into the binary with this file ({})", b.urdf),
            });
        }
        Ok(Self::from_desc(
            desc,
            file,
            builtin_dir().join(b.urdf),
            b.urdf_text.into(),
            Vec::new(),
        ))
    }

    /// Reads a description file and its URDF. `roots` are the folders files may come from (the
    /// description file must lie in one of them or in the build's `assets/`; its URDF in one of
    /// them, in the build's `assets/` or in the description file's folder).
    pub fn from_file(path: &Path, roots: &[PathBuf]) -> Result<Self, RobotError> {
        let assets = roots
            .iter()
            .fold(AssetPaths::workspace_default(), |a, r| a.with_root(r));
        let file = assets.check_inside(path)?;
        let label = path.display().to_string();
        let text = read_text(&file)?;
        let desc = RobotFile::parse(&text, &label)?;
        let dir = file.parent().map(Path::to_path_buf).unwrap_or_default();
        let urdf = assets
            .clone()
            .with_root(&dir)
            .check_inside(&dir.join(&desc.urdf))
            .map_err(|e| RobotError::Description {
                file: label.clone(),
                field: "urdf".into(),
                value: format!("{:?}", desc.urdf),
                expected: format!("a URDF file relative to this file's folder ({e})"),
            })?;
        let urdf_text = read_text(&urdf)?;
        let mut roots = roots.to_vec();
        roots.push(dir);
        Ok(Self::from_desc(desc, file, urdf, urdf_text.into(), roots))
    }

    fn from_desc(
        d: RobotFile,
        file: PathBuf,
        urdf: PathBuf,
        urdf_text: Arc<str>,
        asset_roots: Vec<PathBuf>,
    ) -> Self {
        let (root, base_joints) = match d.base {
            BaseDesc::Holonomic { x, y, yaw } => (RootMount::Fixed, Some([x, y, yaw])),
            BaseDesc::Floating => (RootMount::Floating, None),
            BaseDesc::Fixed => (RootMount::Fixed, None),
        };
        let (hx, hy, hz) = d.gripper.finger_volume;
        Self {
            id: d.id,
            description: d.description,
            file,
            urdf,
            urdf_text,
            asset_roots,
            root,
            root_height: d.root_height,
            base_joints,
            leg_joints: d.legs,
            arm_joints: d.arm,
            gripper_joints: d.gripper.joints,
            gripper_open_closed: (d.gripper.open, d.gripper.closed),
            finger_volume: Vector3::new(hx, hy, hz),
            grasp_force_limit: d.gripper.grasp_force_limit,
            ee_frame: d.ee_frame,
            cameras: d.cameras,
            home: d.home.into_iter().collect(),
            base_modes: d.actions.base,
            arm_modes: d.actions.arm,
            gripper_modes: d.actions.gripper,
            gains: d.gains,
            pgs_iterations: d.physics.pgs_iterations,
            substeps: d.physics.substeps,
            walking: d.walking.map(|WalkingDesc::Trot(p)| p),
        }
    }

    /// Whether the robot has legs.
    pub fn legged(&self) -> bool {
        !self.leg_joints.is_empty()
    }

    /// Where the URDF's files may come from: the build's `assets/` (with
    /// `package://modesuite_robots/` mapped to `assets/robots/`) and [`RobotSpec::asset_roots`].
    pub fn asset_paths(&self) -> AssetPaths {
        self.asset_roots
            .iter()
            .fold(AssetPaths::workspace_default(), |a, r| a.with_root(r))
    }

    /// Parses and validates the URDF text (named by [`RobotSpec::urdf`] in messages; relative
    /// mesh paths start from its folder) and checks that every joint and frame the description
    /// file names is in it.
    pub fn load(&self) -> Result<UrdfModel, RobotError> {
        let base = self
            .urdf
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default();
        let model = parse_urdf(
            &self.urdf_text,
            &self.urdf.display().to_string(),
            &base,
            &self.asset_paths(),
        )?;
        self.check_names(&model)?;
        Ok(model)
    }

    /// Every joint the description names must be a movable joint of the URDF, the end-effector
    /// frame and the cameras' links links of it.
    fn check_names(&self, model: &UrdfModel) -> Result<(), RobotError> {
        let movable: Vec<&str> = model
            .joints
            .iter()
            .filter(|j| j.kind.is_actuated())
            .map(|j| j.name.as_str())
            .collect();
        let bad = |field: String, value: &str, expected: String| RobotError::Description {
            file: self.file.display().to_string(),
            field,
            value: format!("{value:?}"),
            expected,
        };
        let groups = [
            (
                "base",
                self.base_joints.as_ref().map_or(&[][..], |b| &b[..]),
            ),
            ("legs", &self.leg_joints[..]),
            ("arm", &self.arm_joints[..]),
            ("gripper.joints", &self.gripper_joints[..]),
        ];
        let home = self.home.iter().map(|(n, _)| ("home", n));
        let named = groups
            .iter()
            .flat_map(|(g, names)| names.iter().map(move |n| (*g, n)))
            .chain(home);
        for (group, name) in named {
            if !movable.contains(&name.as_str()) {
                return Err(bad(
                    group.to_string(),
                    name,
                    format!("a movable joint of {}: {movable:?}", self.urdf.display()),
                ));
            }
        }
        let frames = std::iter::once(("ee_frame".to_string(), &self.ee_frame)).chain(
            self.cameras
                .iter()
                .enumerate()
                .map(|(i, c)| (format!("cameras[{i}].link"), &c.link)),
        );
        for (field, link) in frames {
            if model.link_index(link).is_none() {
                let links: Vec<&str> = model.links.iter().map(|l| l.name.as_str()).collect();
                return Err(bad(
                    field,
                    link,
                    format!("a link of {}: {links:?}", self.urdf.display()),
                ));
            }
        }
        Ok(())
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

    /// PD gains per joint of `robot`: the gains of the joint's group in the description file
    /// (base, legs, arm, gripper), else its default (inertia-scaled for arms; legs take absolute
    /// gains, because a standing leg's load is the body's weight, not its own inertia).
    pub fn default_gains(&self, robot: &Robot) -> Vec<JointGains> {
        let g = &self.gains;
        let base = self.base_joints.as_ref().map_or(&[][..], |b| &b[..]);
        let groups = [
            (base, g.base),
            (&self.leg_joints[..], g.legs),
            (&self.arm_joints[..], g.arm),
            (&self.gripper_joints[..], g.gripper),
        ];
        robot
            .joints
            .iter()
            .map(|j| {
                groups
                    .iter()
                    .find(|(names, _)| names.contains(&j.name))
                    .and_then(|(_, gains)| *gains)
                    .unwrap_or(g.default)
            })
            .collect()
    }

    /// Joint indices of a group of names.
    pub fn indices(&self, robot: &Robot, names: &[String]) -> Result<Vec<usize>, RobotError> {
        names.iter().map(|n| robot.joint_index(n)).collect()
    }
}

/// Reads a text file (a robot description or a URDF), refusing files over
/// [`crate::urdf::MAX_URDF_BYTES`].
fn read_text(path: &Path) -> Result<String, RobotError> {
    let io = |e: std::io::Error| RobotError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let len = std::fs::metadata(path).map_err(io)?.len();
    if len > crate::urdf::MAX_URDF_BYTES {
        return Err(RobotError::Io {
            path: path.to_path_buf(),
            message: format!(
                "{len} bytes, more than the {} a robot file may have",
                crate::urdf::MAX_URDF_BYTES
            ),
        });
    }
    std::fs::read_to_string(path).map_err(io)
}
