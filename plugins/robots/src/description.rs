//! Robot description files (`*.robot.ron`): a robot as data. One file names the URDF and says
//! how the robot is mounted, which joints form its base, legs, arm and gripper, which action
//! modes it takes, its gains, its home pose and its walking controller. The format is
//! documented with the Franka's file as the example in `docs/robots.md`.
//!
//! [`RobotFile`] is the file as written (serde, unknown fields refused); [`RobotFile::parse`]
//! reads and checks it on its own (errors name `file:line:col`, or the field, its value and what
//! is valid). The checks against the URDF (every named joint and frame exists) run when the
//! URDF is loaded ([`crate::RobotSpec::load`]).
//!
//! The project's robots are built into the binary ([`BUILTIN`]: the files and their URDFs as
//! text), so a moved binary still has them; a scene may also name a file by path.

use std::collections::BTreeMap;
use std::path::{Component, Path, PathBuf};

use serde::Deserialize;

use crate::actions::{ArmMode, BaseMode, GripperMode};
use crate::control::JointGains;
use crate::error::RobotError;
use crate::gait::TrotParams;

/// How the robot's base moves.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum BaseDesc {
    /// The URDF's root is fixed in the world at the spawn pose and the base moves through three
    /// virtual joints (prismatic x, prismatic y, revolute yaw) of the URDF: a holonomic wheeled
    /// base driven by velocity (`Velocity` base actions).
    Holonomic {
        /// The x joint.
        x: String,
        /// The y joint.
        y: String,
        /// The yaw joint.
        yaw: String,
    },
    /// The URDF's root is free (6 DoF), e.g. a legged robot's body.
    Floating,
    /// The URDF's root is fixed in the world at the spawn pose and nothing moves it: an arm on a
    /// pedestal or a table.
    Fixed,
}

/// The gripper: its joints, positions, where it grasps and how hard.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GripperDesc {
    /// Gripper joints; the first is the one commanded (the others may `<mimic>` it).
    pub joints: Vec<String>,
    /// Position of the first joint when open (rad or m).
    pub open: f64,
    /// Position of the first joint when closed.
    pub closed: f64,
    /// Half extents of the finger volume (what a closed gripper grasps), a box centred on the
    /// end-effector frame and aligned with it, m.
    pub finger_volume: (f64, f64, f64),
    /// Default grasp force limit (what a grasp transmits before it slips), N; a scene robot's
    /// `grasp_force_limit` replaces it.
    pub grasp_force_limit: f64,
}

/// The action modes a robot accepts, per part of its action; the first of each list is the
/// default when a scene leaves the part out.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActionModeLists {
    /// Base modes (`Velocity` needs a `Holonomic` base, `Locomotion` a walking controller,
    /// `LegJoints` legs; `Off` always works).
    pub base: Vec<BaseMode>,
    /// Arm modes (any of them drives the `arm` joints).
    pub arm: Vec<ArmMode>,
    /// Gripper modes.
    pub gripper: Vec<GripperMode>,
}

/// PD gains of the joint controller per joint group; joints of a group without an entry (and
/// joints in no group) take `default`.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GainsDesc {
    /// Gains of every joint without a group entry (default: inertia-scaled, 25 rad/s,
    /// critically damped).
    #[serde(default)]
    pub default: JointGains,
    /// Gains of the base joints.
    #[serde(default)]
    pub base: Option<JointGains>,
    /// Gains of the leg joints.
    #[serde(default)]
    pub legs: Option<JointGains>,
    /// Gains of the arm joints.
    #[serde(default)]
    pub arm: Option<JointGains>,
    /// Gains of the gripper joints.
    #[serde(default)]
    pub gripper: Option<JointGains>,
}

/// The rapier settings the robot's controllers are validated at when it is alone (its
/// robot-only scenes, `modesuite bench robots`, the robot tests).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicsDesc {
    /// Gauss-Seidel sweeps per rapier substep (`physics.rigid_pgs_iterations`).
    pub pgs_iterations: u32,
    /// Physics substeps per 1/60 s step (`physics.substeps`).
    pub substeps: u32,
}

/// A walking controller.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub enum WalkingDesc {
    /// The trot of [`crate::locomotion`] with these default parameters (a scene robot's `gait`
    /// replaces any of them); needs 12 leg joints.
    Trot(TrotParams),
}

/// A camera the robot carries on one of its links. Every scene with the robot gets it as if
/// its render section listed it (unless that section has a camera of the same name): a camera
/// without a name is the robot's own camera and takes the scene robot's name (`robot` in the
/// task scenes: their robot camera); a named one is `<robot name>/<name>` (`robot/wrist`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraMountDesc {
    /// Camera name within the robot (no '/'); none for the robot's own camera (at most one).
    #[serde(default)]
    pub name: Option<String>,
    /// The URDF link it moves with.
    pub link: String,
    /// `link_from_camera` (optical frame: x right, y down, z forward): position, m, and roll,
    /// pitch, yaw, rad.
    #[serde(default)]
    pub pose: modesuite_engine::scene::PoseDesc,
    /// Aim at this point of the link frame (up = link +z) instead of `pose`'s rotation.
    #[serde(default)]
    pub look_at: Option<[f64; 3]>,
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Vertical field of view, degrees (default 60).
    #[serde(default = "default_fov")]
    pub fov: f64,
}

fn default_fov() -> f64 {
    60.0
}

impl CameraMountDesc {
    /// The checks that need no URDF; `field` is `cameras[i]`.
    fn check(&self, file: &str, field: &str) -> Result<(), RobotError> {
        let bad = |f: &str, value: String, expected: &str| {
            invalid(file, format!("{field}.{f}"), value, expected)
        };
        if let Some(n) = self
            .name
            .as_ref()
            .filter(|n| n.is_empty() || n.contains('/'))
        {
            return Err(bad(
                "name",
                format!("{n:?}"),
                "a non-empty name without '/' (or none: the robot's own camera)",
            ));
        }
        if self.link.is_empty() {
            return Err(bad("link", "\"\"".into(), "a link of the URDF"));
        }
        let finite = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
        if !(finite(&self.pose.pos) && finite(&self.pose.rpy)) {
            return Err(bad(
                "pose",
                format!("{:?}", self.pose),
                "a finite position (m) and roll, pitch, yaw (rad)",
            ));
        }
        if let Some(t) = self.look_at.filter(|t| !finite(t) || *t == self.pose.pos) {
            return Err(bad(
                "look_at",
                format!("{t:?}"),
                "a finite point other than the camera's position",
            ));
        }
        for (f, v) in [("width", self.width), ("height", self.height)] {
            if !(1..=4096).contains(&v) {
                return Err(bad(f, v.to_string(), "1..=4096 px"));
            }
        }
        if !(self.fov.is_finite() && self.fov > 0.0 && self.fov < 180.0) {
            return Err(bad(
                "fov",
                self.fov.to_string(),
                "a field of view in (0, 180) degrees",
            ));
        }
        Ok(())
    }
}

/// A robot description file as written (`Robot(id: ..., ...)`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(rename = "Robot", deny_unknown_fields)]
pub struct RobotFile {
    /// Registry name (what a scene's `model:` names), e.g. `franka`.
    pub id: String,
    /// One line for `modesuite list robots`.
    pub description: String,
    /// The URDF file, relative to this file's folder.
    pub urdf: String,
    /// How the base moves (which also says how the URDF's root is mounted).
    pub base: BaseDesc,
    /// Height of the root frame above the floor in the home pose, m: added to a scene robot's
    /// pose, which places the floor point under the root (default 0).
    #[serde(default)]
    pub root_height: f64,
    /// Leg joints, three per leg (hip x, hip y, knee; legs front-left, front-right, hind-left,
    /// hind-right); empty for robots without legs.
    #[serde(default)]
    pub legs: Vec<String>,
    /// Arm joints, shoulder to wrist.
    pub arm: Vec<String>,
    /// The gripper.
    pub gripper: GripperDesc,
    /// End-effector (tool centre point) frame: a URDF link.
    pub ee_frame: String,
    /// Home pose: the position of every joint that does not start at zero (or mid-range when
    /// zero is outside its limits).
    #[serde(default)]
    pub home: BTreeMap<String, f64>,
    /// The action modes the robot accepts.
    pub actions: ActionModeLists,
    /// PD gains per joint group.
    #[serde(default)]
    pub gains: GainsDesc,
    /// The rapier settings the robot is validated at alone.
    pub physics: PhysicsDesc,
    /// The walking controller of a legged robot.
    #[serde(default)]
    pub walking: Option<WalkingDesc>,
    /// Cameras mounted on its links (default none); see [`CameraMountDesc`].
    #[serde(default)]
    pub cameras: Vec<CameraMountDesc>,
}

/// A robot file built into the binary, with its URDF.
#[derive(Debug, Clone, Copy)]
pub struct BuiltinRobot {
    /// Path of the description file under `assets/robots/`.
    pub file: &'static str,
    /// Its text.
    pub text: &'static str,
    /// Path of the URDF under `assets/robots/` (the file's `urdf`, resolved).
    pub urdf: &'static str,
    /// The URDF's text.
    pub urdf_text: &'static str,
}

/// The project's robots, built into the binary: `franka` (Franka Panda on a Clearpath
/// Ridgeback) and `spot` (Spot with Spot Arm). The robots plugin registers each under its id.
pub const BUILTIN: [BuiltinRobot; 2] = [
    BuiltinRobot {
        file: "franka_ridgeback/franka.robot.ron",
        text: include_str!("../../../assets/robots/franka_ridgeback/franka.robot.ron"),
        urdf: "franka_ridgeback/franka_ridgeback.urdf",
        urdf_text: include_str!("../../../assets/robots/franka_ridgeback/franka_ridgeback.urdf"),
    },
    BuiltinRobot {
        file: "spot_arm/spot.robot.ron",
        text: include_str!("../../../assets/robots/spot_arm/spot.robot.ron"),
        urdf: "spot_arm/spot_arm.urdf",
        urdf_text: include_str!("../../../assets/robots/spot_arm/spot_arm.urdf"),
    },
];

/// A field's error: `field = value: expected`.
fn invalid(
    file: &str,
    field: impl Into<String>,
    value: impl Into<String>,
    expected: impl Into<String>,
) -> RobotError {
    RobotError::Description {
        file: file.to_string(),
        field: field.into(),
        value: value.into(),
        expected: expected.into(),
    }
}

fn names_text(names: &[String]) -> String {
    format!("{names:?}")
}

impl RobotFile {
    /// Parses and checks a description file's text on its own; `file` names it in errors.
    /// Syntax errors and unknown fields give `file:line:col`; a value out of range gives the
    /// field, the value and what is valid.
    pub fn parse(text: &str, file: &str) -> Result<Self, RobotError> {
        let desc: RobotFile = modesuite_engine::scene::ron_options()
            .from_str(text)
            .map_err(|e| RobotError::DescriptionSyntax {
                file: file.to_string(),
                line: e.span.start.line,
                col: e.span.start.col,
                message: e.code.to_string(),
            })?;
        desc.check(file)?;
        Ok(desc)
    }

    /// Every joint the file names, with the field that names it (`arm[2]`, `home`, ...).
    pub fn named_joints(&self) -> Vec<(String, &str)> {
        let mut out = Vec::new();
        if let BaseDesc::Holonomic { x, y, yaw } = &self.base {
            out.push(("base.x".to_string(), x.as_str()));
            out.push(("base.y".to_string(), y.as_str()));
            out.push(("base.yaw".to_string(), yaw.as_str()));
        }
        for (group, names) in [
            ("legs", &self.legs),
            ("arm", &self.arm),
            ("gripper.joints", &self.gripper.joints),
        ] {
            for (i, n) in names.iter().enumerate() {
                out.push((format!("{group}[{i}]"), n.as_str()));
            }
        }
        for n in self.home.keys() {
            out.push((format!("home[{n:?}]"), n.as_str()));
        }
        out
    }

    /// The checks that need no URDF: names, numbers in range, the action modes against the base,
    /// legs and walking controller.
    fn check(&self, file: &str) -> Result<(), RobotError> {
        let bad =
            |field: &str, value: String, expected: &str| invalid(file, field, value, expected);
        let g = &self.gripper;
        let (hx, hy, hz) = g.finger_volume;
        let finite_positive = |v: f64| v.is_finite() && v > 0.0;
        let home = self.home.iter().find(|(_, v)| !v.is_finite());
        // (valid, field, value, what is valid), the first invalid one reported
        let fields: [(bool, String, String, &str); 10] = [
            (
                !(self.id.is_empty() || self.id.contains(['/', '\\']) || self.id.ends_with(".ron")),
                "id".into(),
                format!("{:?}", self.id),
                "a non-empty name without '/' or '\\' that does not end in .ron",
            ),
            (
                !self.urdf.is_empty(),
                "urdf".into(),
                "\"\"".into(),
                "a URDF file relative to this file's folder",
            ),
            (
                self.root_height.is_finite() && self.root_height >= 0.0,
                "root_height".into(),
                self.root_height.to_string(),
                "a finite height >= 0, m",
            ),
            (
                !self.arm.is_empty(),
                "arm".into(),
                "[]".into(),
                "at least one arm joint",
            ),
            (
                !g.joints.is_empty(),
                "gripper.joints".into(),
                "[]".into(),
                "at least one gripper joint",
            ),
            (
                g.open.is_finite() && g.closed.is_finite(),
                "gripper.open / gripper.closed".into(),
                format!("{} / {}", g.open, g.closed),
                "finite positions",
            ),
            (
                [hx, hy, hz].into_iter().all(finite_positive),
                "gripper.finger_volume".into(),
                format!("{:?}", g.finger_volume),
                "half extents > 0, m",
            ),
            (
                finite_positive(g.grasp_force_limit),
                "gripper.grasp_force_limit".into(),
                g.grasp_force_limit.to_string(),
                "a finite force > 0, N",
            ),
            (
                !self.ee_frame.is_empty(),
                "ee_frame".into(),
                "\"\"".into(),
                "a link of the URDF",
            ),
            (
                home.is_none(),
                format!("home[{:?}]", home.map_or("", |(n, _)| n.as_str())),
                home.map_or(String::new(), |(_, v)| v.to_string()),
                "a finite position",
            ),
        ];
        if let Some((_, field, value, expected)) = fields.into_iter().find(|f| !f.0) {
            return Err(bad(&field, value, expected));
        }
        // A joint in two groups would take two commands.
        let mut seen: BTreeMap<&str, String> = BTreeMap::new();
        for (field, name) in self.named_joints() {
            if field.starts_with("home") {
                continue;
            }
            if let Some(first) = seen.insert(name, field.clone()) {
                return Err(bad(
                    &field,
                    format!("{name:?}"),
                    &format!("a joint no other group names (already {first})"),
                ));
            }
        }
        self.check_gains(file)?;
        for (i, c) in self.cameras.iter().enumerate() {
            c.check(file, &format!("cameras[{i}]"))?;
            if self.cameras[..i].iter().any(|d| d.name == c.name) {
                return Err(bad(
                    &format!("cameras[{i}].name"),
                    format!("{:?}", c.name),
                    "a name no other camera of the robot has (one camera at most without)",
                ));
            }
        }
        if self.physics.pgs_iterations == 0 || self.physics.substeps == 0 {
            return Err(bad(
                "physics",
                format!("{:?}", self.physics),
                "pgs_iterations >= 1 and substeps >= 1",
            ));
        }
        if let Some(WalkingDesc::Trot(p)) = &self.walking {
            p.check()
                .map_err(|e| bad("walking", format!("Trot({p:?})"), &e))?;
            if self.legs.len() != 12 {
                return Err(bad(
                    "walking",
                    "Trot(..)".into(),
                    &format!(
                        "a trot needs 12 leg joints (3 per leg); legs has {}",
                        self.legs.len()
                    ),
                ));
            }
        }
        self.check_actions(file)
    }

    fn check_gains(&self, file: &str) -> Result<(), RobotError> {
        let gs = &self.gains;
        for (field, g) in [
            ("gains.default", Some(gs.default)),
            ("gains.base", gs.base),
            ("gains.legs", gs.legs),
            ("gains.arm", gs.arm),
            ("gains.gripper", gs.gripper),
        ] {
            let ok = match g {
                None => true,
                Some(JointGains::Inertial { omega, zeta }) => {
                    omega.is_finite() && omega > 0.0 && zeta.is_finite() && zeta >= 0.0
                }
                Some(JointGains::Absolute { kp, kd }) => {
                    kp.is_finite() && kp > 0.0 && kd.is_finite() && kd >= 0.0
                }
            };
            if !ok {
                return Err(invalid(
                    file,
                    field,
                    format!("{g:?}"),
                    "Inertial(omega > 0, zeta >= 0) or Absolute(kp > 0, kd >= 0), finite",
                ));
            }
        }
        Ok(())
    }

    fn check_actions(&self, file: &str) -> Result<(), RobotError> {
        let a = &self.actions;
        let lists: [(&str, Vec<String>); 3] = [
            (
                "actions.base",
                a.base.iter().map(|m| format!("{m:?}")).collect(),
            ),
            (
                "actions.arm",
                a.arm.iter().map(|m| format!("{m:?}")).collect(),
            ),
            (
                "actions.gripper",
                a.gripper.iter().map(|m| format!("{m:?}")).collect(),
            ),
        ];
        for (field, modes) in &lists {
            let dup = modes
                .iter()
                .enumerate()
                .any(|(i, m)| modes[..i].contains(m));
            if modes.is_empty() || dup {
                return Err(invalid(
                    file,
                    *field,
                    names_text(modes),
                    "a non-empty list of modes without repeats (the first is the default)",
                ));
            }
        }
        for (i, m) in a.base.iter().enumerate() {
            let why = match m {
                BaseMode::Off => None,
                BaseMode::Velocity if !matches!(self.base, BaseDesc::Holonomic { .. }) => {
                    Some("a mode its base has: Velocity needs base: Holonomic(..)")
                }
                BaseMode::Locomotion if self.walking.is_none() => {
                    Some("a mode its base has: Locomotion needs a walking controller (walking: Trot(..))")
                }
                BaseMode::LegJoints if self.legs.is_empty() => Some("a mode its base has: LegJoints needs leg joints"),
                _ => None,
            };
            if let Some(why) = why {
                return Err(invalid(
                    file,
                    format!("actions.base[{i}]"),
                    format!("{m:?}"),
                    why,
                ));
            }
        }
        Ok(())
    }
}

/// Joins a relative path written in a file onto `dir` and removes `.` and `..` lexically (no
/// file system access: built-in files have none).
pub(crate) fn join_lexically(dir: &Path, rel: &str) -> PathBuf {
    let mut out = PathBuf::new();
    for c in dir.join(rel).components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    out.push("..");
                }
            }
            other => out.push(other),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_files_parse() {
        for b in BUILTIN {
            let f = RobotFile::parse(b.text, b.file).unwrap();
            let urdf = join_lexically(Path::new(b.file).parent().unwrap(), &f.urdf);
            assert_eq!(urdf, Path::new(b.urdf), "{}", b.file);
        }
    }

    #[test]
    fn errors_name_the_place() {
        let text = BUILTIN[0].text.replace("ee_frame:", "ee_frme:");
        let e = RobotFile::parse(&text, "f.robot.ron")
            .unwrap_err()
            .to_string();
        println!("{e}");
        assert!(e.starts_with("f.robot.ron:") && e.contains("ee_frme"));
        let line = text.lines().position(|l| l.contains("ee_frme")).unwrap() + 1;
        assert!(e.contains(&format!(":{line}:")), "{e}");
        let text = BUILTIN[0]
            .text
            .replace("grasp_force_limit: 70.0", "grasp_force_limit: -1.0");
        let e = RobotFile::parse(&text, "f.robot.ron")
            .unwrap_err()
            .to_string();
        println!("{e}");
        assert!(e.contains("gripper.grasp_force_limit = -1") && e.contains("> 0"));
        let text = BUILTIN[0]
            .text
            .replace("base: [Velocity, Off]", "base: [Locomotion, Off]");
        let e = RobotFile::parse(&text, "f.robot.ron")
            .unwrap_err()
            .to_string();
        println!("{e}");
        assert!(e.contains("actions.base[0] = Locomotion") && e.contains("walking"));
    }

    #[test]
    fn lexical_join() {
        assert_eq!(
            join_lexically(Path::new("a/b"), "../c/./d.urdf"),
            Path::new("a/c/d.urdf")
        );
        assert_eq!(join_lexically(Path::new(""), "../x"), Path::new("../x"));
    }
}
