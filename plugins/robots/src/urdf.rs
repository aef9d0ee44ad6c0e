//! URDF reading: asset search path (`package://` resolution without ROS), parsing with urdf-rs
//! (guarded against panics), and validation into a [`UrdfModel`] whose numbers are all finite and
//! whose links form one tree.

use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};

use modesuite_engine::deps::nalgebra::{Isometry3, Matrix3, Translation3, Unit, Vector3};
use modesuite_engine::math::rpy;

use crate::error::RobotError;

/// Largest URDF file accepted, bytes.
pub const MAX_URDF_BYTES: u64 = 16 * 1024 * 1024;

/// Where robot files may be read from: asset roots (every file must lie inside one) and the
/// `package://NAME/` prefixes, each mapped to a folder.
#[derive(Debug, Clone, Default)]
pub struct AssetPaths {
    roots: Vec<PathBuf>,
    packages: Vec<(String, PathBuf)>,
}

impl AssetPaths {
    /// An asset search path with one root folder. Files outside every root are refused.
    pub fn new(root: impl Into<PathBuf>) -> Self {
        Self {
            roots: vec![root.into()],
            packages: Vec::new(),
        }
    }

    /// The asset folder of this repository (`assets/` at the workspace root), with the
    /// `package://modesuite_robots/` prefix mapped to `assets/robots/`.
    pub fn workspace_default() -> Self {
        let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets");
        Self::new(assets.clone()).with_package("modesuite_robots", assets.join("robots"))
    }

    /// Adds another root folder.
    pub fn with_root(mut self, root: impl Into<PathBuf>) -> Self {
        self.roots.push(root.into());
        self
    }

    /// Maps `package://NAME/` to `dir` (which must itself lie inside a root to be usable).
    pub fn with_package(mut self, name: impl Into<String>, dir: impl Into<PathBuf>) -> Self {
        self.packages.push((name.into(), dir.into()));
        self
    }

    /// The root folders.
    pub fn roots(&self) -> &[PathBuf] {
        &self.roots
    }

    fn roots_text(&self) -> String {
        self.roots
            .iter()
            .map(|r| r.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Checks that `path` exists and lies inside one of the roots (after resolving `..` and
    /// symbolic links) and returns its canonical form.
    pub fn check_inside(&self, path: &Path) -> Result<PathBuf, RobotError> {
        let canonical = path.canonicalize().map_err(|e| RobotError::Io {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        for root in &self.roots {
            if let Ok(r) = root.canonicalize() {
                if canonical.starts_with(&r) {
                    return Ok(canonical);
                }
            }
        }
        Err(RobotError::OutsideAssetRoots {
            path: path.display().to_string(),
            roots: self.roots_text(),
        })
    }

    /// Resolves a file name written in a URDF (`package://NAME/rest`, `file://path`, an absolute
    /// path or a path relative to the URDF's folder `base_dir`) to a checked path inside the roots.
    pub fn resolve(&self, uri: &str, file: &str, base_dir: &Path) -> Result<PathBuf, RobotError> {
        let candidate = if let Some(rest) = uri.strip_prefix("package://") {
            let (package, tail) = rest.split_once('/').unwrap_or((rest, ""));
            let dir = self
                .packages
                .iter()
                .find(|(n, _)| n == package)
                .map(|(_, d)| d.clone())
                .ok_or_else(|| RobotError::UnknownPackage {
                    file: file.to_string(),
                    package: package.to_string(),
                    uri: uri.to_string(),
                    known: self
                        .packages
                        .iter()
                        .map(|(n, _)| n.as_str())
                        .collect::<Vec<_>>()
                        .join(", "),
                })?;
            dir.join(relative_only(tail, uri, self)?)
        } else if let Some(rest) = uri.strip_prefix("file://") {
            let p = PathBuf::from(rest);
            if p.is_absolute() {
                p
            } else {
                base_dir.join(p)
            }
        } else if uri.contains("://") {
            return Err(RobotError::Parse {
                file: file.to_string(),
                message: format!("unsupported URI scheme in `{uri}`"),
            });
        } else {
            let p = PathBuf::from(uri);
            if p.is_absolute() {
                p
            } else {
                base_dir.join(p)
            }
        };
        self.check_inside(&candidate)
    }
}

/// A package-relative path must not be absolute (it would escape the package folder).
fn relative_only(tail: &str, uri: &str, paths: &AssetPaths) -> Result<PathBuf, RobotError> {
    let p = PathBuf::from(tail);
    if p.components()
        .any(|c| matches!(c, Component::RootDir | Component::Prefix(_)))
    {
        return Err(RobotError::OutsideAssetRoots {
            path: uri.to_string(),
            roots: paths.roots_text(),
        });
    }
    Ok(p)
}

/// Joint types supported in a robot tree.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    /// Rotation about the axis, with limits.
    Revolute,
    /// Rotation about the axis without limits.
    Continuous,
    /// Translation along the axis, with limits.
    Prismatic,
    /// Rigid connection (the child is merged into the parent's body).
    Fixed,
}

impl JointKind {
    /// Whether the joint has a degree of freedom.
    pub fn is_actuated(self) -> bool {
        self != JointKind::Fixed
    }
}

/// Collision or visual geometry of a link.
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// Box with the given full sizes, m.
    Box {
        /// Full sizes along x, y, z.
        size: Vector3<f64>,
    },
    /// Cylinder along z.
    Cylinder {
        /// Radius, m.
        radius: f64,
        /// Length, m.
        length: f64,
    },
    /// Capsule along z; `length` is the distance between the two cap centres.
    Capsule {
        /// Radius, m.
        radius: f64,
        /// Length between the cap centres, m.
        length: f64,
    },
    /// Sphere.
    Sphere {
        /// Radius, m.
        radius: f64,
    },
    /// Triangle mesh file (visuals only; collision meshes are refused by the builder).
    Mesh {
        /// Resolved path inside the asset roots.
        path: PathBuf,
        /// Scale per axis.
        scale: Vector3<f64>,
    },
}

/// Geometry placed in a link frame.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacedGeometry {
    /// Pose in the link frame.
    pub origin: Isometry3<f64>,
    /// The shape.
    pub geometry: Geometry,
    /// RGBA colour of a visual (None for collisions or when the URDF gives none).
    pub rgba: Option<[f64; 4]>,
}

/// Mass properties of a link.
#[derive(Debug, Clone, PartialEq)]
pub struct Inertial {
    /// Centre of mass and inertia frame in the link frame.
    pub origin: Isometry3<f64>,
    /// Mass, kg.
    pub mass: f64,
    /// Inertia tensor about the centre of mass, in the inertial frame, kg m^2.
    pub inertia: Matrix3<f64>,
}

/// A validated link.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkDesc {
    /// Link name.
    pub name: String,
    /// Mass properties (None: massless frame).
    pub inertial: Option<Inertial>,
    /// Collision shapes.
    pub collisions: Vec<PlacedGeometry>,
    /// Visual shapes.
    pub visuals: Vec<PlacedGeometry>,
}

/// `<mimic>`: this joint follows `multiplier * q(joint) + offset`.
#[derive(Debug, Clone, PartialEq)]
pub struct MimicDesc {
    /// The leading joint's name.
    pub joint: String,
    /// Multiplier.
    pub multiplier: f64,
    /// Offset (rad or m).
    pub offset: f64,
}

/// A validated joint.
#[derive(Debug, Clone, PartialEq)]
pub struct JointDesc {
    /// Joint name.
    pub name: String,
    /// Type.
    pub kind: JointKind,
    /// Parent link index in [`UrdfModel::links`].
    pub parent: usize,
    /// Child link index.
    pub child: usize,
    /// Child frame in the parent frame at zero position.
    pub origin: Isometry3<f64>,
    /// Unit axis in the child (joint) frame.
    pub axis: Unit<Vector3<f64>>,
    /// Lower position limit (rad or m; -inf when unlimited).
    pub lower: f64,
    /// Upper position limit (+inf when unlimited).
    pub upper: f64,
    /// Effort limit (N m or N).
    pub effort: f64,
    /// Velocity limit (rad/s or m/s).
    pub velocity: f64,
    /// Viscous damping (N m s/rad or N s/m).
    pub damping: f64,
    /// Dry friction (N m or N).
    pub friction: f64,
    /// Mimic relation, if any.
    pub mimic: Option<MimicDesc>,
}

/// A validated URDF robot: links form one tree, every number is finite, every referenced file
/// resolved inside the asset roots.
#[derive(Debug, Clone, PartialEq)]
pub struct UrdfModel {
    /// Robot name.
    pub name: String,
    /// The file it came from (for messages).
    pub file: String,
    /// Links; [`UrdfModel::root`] is the root.
    pub links: Vec<LinkDesc>,
    /// Joints in breadth-first order from the root (a parent's joint comes before its children's).
    pub joints: Vec<JointDesc>,
    /// Root link index.
    pub root: usize,
}

impl UrdfModel {
    /// Index of a link by name.
    pub fn link_index(&self, name: &str) -> Option<usize> {
        self.links.iter().position(|l| l.name == name)
    }

    /// Index of a joint by name.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Sum of all link masses, kg.
    pub fn total_mass(&self) -> f64 {
        self.links
            .iter()
            .filter_map(|l| l.inertial.as_ref())
            .map(|i| i.mass)
            .sum()
    }
}

/// Reads and validates a URDF file. The file must lie inside the asset roots; `package://` and
/// relative mesh paths are resolved through `assets` and refused when they escape the roots.
pub fn read_urdf(path: &Path, assets: &AssetPaths) -> Result<UrdfModel, RobotError> {
    let canonical = assets.check_inside(path)?;
    let meta = std::fs::metadata(&canonical).map_err(|e| RobotError::Io {
        path: canonical.clone(),
        message: e.to_string(),
    })?;
    if meta.len() > MAX_URDF_BYTES {
        return Err(RobotError::Io {
            path: canonical,
            message: format!(
                "file is {} bytes, more than the {MAX_URDF_BYTES} accepted",
                meta.len()
            ),
        });
    }
    let text = std::fs::read_to_string(&canonical).map_err(|e| RobotError::Io {
        path: canonical.clone(),
        message: e.to_string(),
    })?;
    let base = canonical
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default();
    parse_urdf(&text, &path.display().to_string(), &base, assets)
}

/// Parses and validates URDF text. `file` names it in messages; `base_dir` is where relative mesh
/// paths start.
pub fn parse_urdf(
    text: &str,
    file: &str,
    base_dir: &Path,
    assets: &AssetPaths,
) -> Result<UrdfModel, RobotError> {
    // urdf-rs does not resolve package:// in read_from_string, but a parser panic must never
    // reach the caller: catch it as a defence.
    let parsed = modesuite_engine::catch_panic(|| urdf_rs::read_from_string(text));
    let robot = match parsed {
        Ok(Ok(r)) => r,
        Ok(Err(e)) => {
            return Err(RobotError::Parse {
                file: file.to_string(),
                message: e.to_string(),
            })
        }
        Err(_) => {
            return Err(RobotError::Parse {
                file: file.to_string(),
                message: "the URDF parser panicked on this input".to_string(),
            })
        }
    };
    validate(robot, file, base_dir, assets)
}

fn finite_all(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}

fn pose_of(p: &urdf_rs::Pose) -> Option<Isometry3<f64>> {
    let (x, r) = (p.xyz.0, p.rpy.0);
    if !finite_all(&x) || !finite_all(&r) {
        return None;
    }
    Some(Isometry3::from_parts(
        Translation3::new(x[0], x[1], x[2]),
        rpy(r[0], r[1], r[2]),
    ))
}

fn geometry_of(
    g: &urdf_rs::Geometry,
    file: &str,
    link: &str,
    base_dir: &Path,
    assets: &AssetPaths,
) -> Result<Geometry, RobotError> {
    let bad = |m: String| RobotError::Link {
        file: file.to_string(),
        link: link.to_string(),
        message: m,
    };
    let positive = |name: &str, v: f64| -> Result<f64, RobotError> {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(bad(format!("{name} must be finite and > 0, got {v}")))
        }
    };
    Ok(match g {
        urdf_rs::Geometry::Box { size } => {
            for (i, s) in size.0.iter().enumerate() {
                positive(["box size x", "box size y", "box size z"][i], *s)?;
            }
            Geometry::Box {
                size: Vector3::new(size.0[0], size.0[1], size.0[2]),
            }
        }
        urdf_rs::Geometry::Cylinder { radius, length } => Geometry::Cylinder {
            radius: positive("cylinder radius", *radius)?,
            length: positive("cylinder length", *length)?,
        },
        urdf_rs::Geometry::Capsule { radius, length } => {
            if !(length.is_finite() && *length >= 0.0) {
                return Err(bad(format!(
                    "capsule length must be finite and >= 0, got {length}"
                )));
            }
            Geometry::Capsule {
                radius: positive("capsule radius", *radius)?,
                length: *length,
            }
        }
        urdf_rs::Geometry::Sphere { radius } => Geometry::Sphere {
            radius: positive("sphere radius", *radius)?,
        },
        urdf_rs::Geometry::Mesh { filename, scale } => {
            let s = scale.map(|s| s.0).unwrap_or([1.0; 3]);
            if !finite_all(&s) {
                return Err(bad(format!("mesh scale not finite: {s:?}")));
            }
            Geometry::Mesh {
                path: assets.resolve(filename, file, base_dir)?,
                scale: Vector3::new(s[0], s[1], s[2]),
            }
        }
    })
}

fn inertial_of(i: &urdf_rs::Inertial, file: &str, link: &str) -> Result<Inertial, RobotError> {
    let bad = |m: String| RobotError::Link {
        file: file.to_string(),
        link: link.to_string(),
        message: m,
    };
    let origin = pose_of(&i.origin).ok_or_else(|| bad("inertial origin not finite".into()))?;
    let m = i.mass.value;
    if !(m.is_finite() && m >= 0.0) {
        return Err(bad(format!("mass must be finite and >= 0, got {m}")));
    }
    let t = &i.inertia;
    let inertia = Matrix3::new(
        t.ixx, t.ixy, t.ixz, t.ixy, t.iyy, t.iyz, t.ixz, t.iyz, t.izz,
    );
    if !inertia.iter().all(|v| v.is_finite()) {
        return Err(bad("inertia tensor not finite".into()));
    }
    if m > 0.0 {
        let eig = inertia.symmetric_eigenvalues();
        let tol = 1e-9 * eig.amax().max(1e-12);
        if eig.iter().any(|e| *e < -tol) {
            return Err(bad(format!(
                "inertia tensor is not positive semi-definite (eigenvalues {:.3e}, {:.3e}, {:.3e})",
                eig[0], eig[1], eig[2]
            )));
        }
    }
    Ok(Inertial {
        origin,
        mass: m,
        inertia,
    })
}

fn validate(
    robot: urdf_rs::Robot,
    file: &str,
    base_dir: &Path,
    assets: &AssetPaths,
) -> Result<UrdfModel, RobotError> {
    let structure = |m: String| RobotError::Structure {
        file: file.to_string(),
        message: m,
    };
    if robot.links.is_empty() {
        return Err(structure("the robot has no links".into()));
    }
    let mut link_ids: HashMap<&str, usize> = HashMap::new();
    let mut links = Vec::with_capacity(robot.links.len());
    for (i, l) in robot.links.iter().enumerate() {
        if link_ids.insert(l.name.as_str(), i).is_some() {
            return Err(RobotError::Link {
                file: file.to_string(),
                link: l.name.clone(),
                message: "duplicated link name".into(),
            });
        }
        // urdf-rs fills a missing <inertial> with zeros: mass 0 means a massless frame.
        let inertial = inertial_of(&l.inertial, file, &l.name)?;
        let inertial = (inertial.mass > 0.0).then_some(inertial);
        let mut collisions = Vec::new();
        for c in &l.collision {
            collisions.push(PlacedGeometry {
                origin: pose_of(&c.origin).ok_or_else(|| RobotError::Link {
                    file: file.to_string(),
                    link: l.name.clone(),
                    message: "collision origin not finite".into(),
                })?,
                geometry: geometry_of(&c.geometry, file, &l.name, base_dir, assets)?,
                rgba: None,
            });
        }
        let mut visuals = Vec::new();
        for v in &l.visual {
            let rgba = v
                .material
                .as_ref()
                .and_then(|m| m.color.as_ref())
                .map(|c| c.rgba.0)
                .filter(|c| finite_all(c));
            visuals.push(PlacedGeometry {
                origin: pose_of(&v.origin).ok_or_else(|| RobotError::Link {
                    file: file.to_string(),
                    link: l.name.clone(),
                    message: "visual origin not finite".into(),
                })?,
                geometry: geometry_of(&v.geometry, file, &l.name, base_dir, assets)?,
                rgba,
            });
        }
        links.push(LinkDesc {
            name: l.name.clone(),
            inertial,
            collisions,
            visuals,
        });
    }

    let mut joints: Vec<JointDesc> = Vec::with_capacity(robot.joints.len());
    let mut parent_of: Vec<Option<usize>> = vec![None; links.len()];
    let mut joint_names: HashMap<&str, ()> = HashMap::new();
    for j in &robot.joints {
        let bad = |m: String| RobotError::Joint {
            file: file.to_string(),
            joint: j.name.clone(),
            message: m,
        };
        if joint_names.insert(j.name.as_str(), ()).is_some() {
            return Err(bad("duplicated joint name".into()));
        }
        let parent = *link_ids
            .get(j.parent.link.as_str())
            .ok_or_else(|| bad(format!("unknown parent link `{}`", j.parent.link)))?;
        let child = *link_ids
            .get(j.child.link.as_str())
            .ok_or_else(|| bad(format!("unknown child link `{}`", j.child.link)))?;
        if parent == child {
            return Err(bad("parent and child are the same link".into()));
        }
        if parent_of[child].is_some() {
            return Err(bad(format!(
                "link `{}` has more than one parent joint",
                j.child.link
            )));
        }
        parent_of[child] = Some(parent);
        let kind = match j.joint_type {
            urdf_rs::JointType::Revolute => JointKind::Revolute,
            urdf_rs::JointType::Continuous => JointKind::Continuous,
            urdf_rs::JointType::Prismatic => JointKind::Prismatic,
            urdf_rs::JointType::Fixed => JointKind::Fixed,
            ref other => {
                return Err(bad(format!(
                    "joint type {other:?} is not supported (revolute, continuous, prismatic, fixed)"
                )))
            }
        };
        let origin = pose_of(&j.origin).ok_or_else(|| bad("origin not finite".into()))?;
        let a = j.axis.xyz.0;
        let axis_v = Vector3::new(a[0], a[1], a[2]);
        if kind.is_actuated() && !(finite_all(&a) && axis_v.norm() > 1e-9) {
            return Err(bad(format!("axis must be finite and non-zero, got {a:?}")));
        }
        let axis = Unit::try_new(axis_v, 1e-9).unwrap_or(Vector3::x_axis());
        let lim = &j.limit;
        let (mut lower, mut upper) = (lim.lower, lim.upper);
        match kind {
            JointKind::Revolute | JointKind::Prismatic => {
                if !(lower.is_finite() && upper.is_finite()) {
                    return Err(bad(format!(
                        "{kind:?} joint needs finite lower/upper limits, got [{lower}, {upper}]"
                    )));
                }
                if lower > upper {
                    return Err(bad(format!("lower limit {lower} > upper limit {upper}")));
                }
            }
            JointKind::Continuous | JointKind::Fixed => {
                lower = f64::NEG_INFINITY;
                upper = f64::INFINITY;
            }
        }
        if kind.is_actuated() {
            if !(lim.effort.is_finite() && lim.effort > 0.0) {
                return Err(bad(format!(
                    "effort limit must be finite and > 0, got {}",
                    lim.effort
                )));
            }
            if !(lim.velocity.is_finite() && lim.velocity > 0.0) {
                return Err(bad(format!(
                    "velocity limit must be finite and > 0, got {}",
                    lim.velocity
                )));
            }
        }
        let (damping, friction) = j
            .dynamics
            .as_ref()
            .map(|d| (d.damping, d.friction))
            .unwrap_or((0.0, 0.0));
        if !(damping.is_finite() && damping >= 0.0 && friction.is_finite() && friction >= 0.0) {
            return Err(bad(format!(
                "damping {damping} and friction {friction} must be finite and >= 0"
            )));
        }
        let mimic = match &j.mimic {
            Some(m) => {
                let multiplier = m.multiplier.unwrap_or(1.0);
                let offset = m.offset.unwrap_or(0.0);
                if !(multiplier.is_finite() && offset.is_finite()) {
                    return Err(bad("mimic multiplier/offset not finite".into()));
                }
                Some(MimicDesc {
                    joint: m.joint.clone(),
                    multiplier,
                    offset,
                })
            }
            None => None,
        };
        joints.push(JointDesc {
            name: j.name.clone(),
            kind,
            parent,
            child,
            origin,
            axis,
            lower,
            upper,
            effort: if kind.is_actuated() { lim.effort } else { 0.0 },
            velocity: if kind.is_actuated() {
                lim.velocity
            } else {
                0.0
            },
            damping,
            friction,
            mimic,
        });
    }
    let roots: Vec<usize> = (0..links.len())
        .filter(|i| parent_of[*i].is_none())
        .collect();
    if roots.len() != 1 {
        let names: Vec<&str> = roots.iter().map(|i| links[*i].name.as_str()).collect();
        return Err(structure(format!(
            "expected exactly one root link, found {} ({})",
            roots.len(),
            names.join(", ")
        )));
    }
    let root = roots[0];
    // Breadth-first order from the root; links not reached sit on a cycle.
    let mut order = Vec::with_capacity(joints.len());
    let mut reached = vec![false; links.len()];
    reached[root] = true;
    let mut frontier = vec![root];
    while let Some(l) = frontier.pop() {
        for (ji, j) in joints.iter().enumerate() {
            if j.parent == l && !reached[j.child] {
                reached[j.child] = true;
                order.push(ji);
                frontier.insert(0, j.child);
            }
        }
    }
    if let Some(i) = reached.iter().position(|r| !r) {
        return Err(structure(format!(
            "link `{}` is not connected to the root `{}` (cycle in the joint graph)",
            links[i].name, links[root].name
        )));
    }
    let mut ordered: Vec<JointDesc> = order.iter().map(|i| joints[*i].clone()).collect();
    for j in &mut ordered {
        if let Some(m) = &j.mimic {
            if !robot.joints.iter().any(|o| o.name == m.joint) || m.joint == j.name {
                return Err(RobotError::Joint {
                    file: file.to_string(),
                    joint: j.name.clone(),
                    message: format!("mimics unknown joint `{}`", m.joint),
                });
            }
        }
    }
    // A mimic must follow an actuated joint that is itself no mimic.
    for j in &ordered {
        if let Some(m) = &j.mimic {
            let leader = ordered.iter().find(|o| o.name == m.joint);
            if !leader.is_some_and(|o| o.kind.is_actuated() && o.mimic.is_none()) {
                return Err(RobotError::Joint {
                    file: file.to_string(),
                    joint: j.name.clone(),
                    message: format!(
                        "mimics `{}`, which is fixed or itself a mimic joint",
                        m.joint
                    ),
                });
            }
        }
    }
    Ok(UrdfModel {
        name: robot.name,
        file: file.to_string(),
        links,
        joints: ordered,
        root,
    })
}
