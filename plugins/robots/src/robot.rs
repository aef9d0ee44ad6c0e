//! Building a [`UrdfModel`] into a rapier multibody (reduced coordinates) inside a
//! [`RigidContext`], and the [`Robot`] handle that reads and sets its joints afterwards.
//!
//! Links joined by fixed joints are merged into one rapier body (their shapes and mass
//! properties are combined; their frames stay addressable by name). Each revolute, continuous or
//! prismatic joint becomes a multibody joint with its limits, a motor limited to the joint's
//! effort, and its viscous damping. Contacts between links of the same robot are disabled.

use std::collections::HashMap;

use modesuite_engine::deps::nalgebra::{Isometry3, Matrix3, UnitQuaternion, Vector3};
use modesuite_engine::deps::rapier3d::prelude::{
    ColliderBuilder, GenericJointBuilder, JointAxesMask, JointAxis, MassProperties, MotorModel,
    Multibody, MultibodyJointSet, RigidBodyBuilder, RigidBodyHandle, SoftBodySet,
};
use modesuite_engine::math::{pose_from_rapier, pose_to_rapier, vec_to_rapier};
use modesuite_engine::RigidContext;

use crate::error::RobotError;
use crate::urdf::{Geometry, JointKind, UrdfModel};

/// How the root link is attached to the world.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RootMount {
    /// The root link is fixed in the world at the spawn pose (mobile bases move through virtual
    /// joints).
    Fixed,
    /// The root link is free (6 DoF): a floating base such as a legged robot's body.
    Floating,
}

/// Options for [`spawn_robot`].
#[derive(Debug, Clone)]
pub struct SpawnOptions {
    /// World pose of the root link.
    pub pose: Isometry3<f64>,
    /// How the root is attached.
    pub root: RootMount,
    /// Initial joint positions by name; joints not named start at 0, or at the middle of their
    /// limits when 0 is outside them.
    pub initial: Vec<(String, f64)>,
    /// Friction coefficient of every collider of the robot.
    pub friction: f64,
}

impl Default for SpawnOptions {
    fn default() -> Self {
        Self {
            pose: Isometry3::identity(),
            root: RootMount::Fixed,
            initial: Vec::new(),
            friction: 0.8,
        }
    }
}

/// One rapier body of a robot (a link plus every link fixed to it).
#[derive(Debug, Clone)]
pub struct RobotBody {
    /// Name of the link that owns the body.
    pub name: String,
    /// The rapier body.
    pub handle: RigidBodyHandle,
    /// Parent body index (None for the root).
    pub parent: Option<usize>,
    /// Mass of the body, kg.
    pub mass: f64,
}

/// An actuated joint of a robot.
#[derive(Debug, Clone)]
pub struct RobotJoint {
    /// URDF joint name.
    pub name: String,
    /// Revolute, continuous or prismatic.
    pub kind: JointKind,
    /// Index of the child body in [`Robot::bodies`].
    pub body: usize,
    /// Index of the parent body.
    pub parent_body: usize,
    /// Unit axis in the child body frame.
    pub axis: Vector3<f64>,
    /// Joint origin (a point on the axis) in the child body frame.
    pub anchor: Vector3<f64>,
    /// Lower limit (rad or m; -inf when unlimited).
    pub lower: f64,
    /// Upper limit (+inf when unlimited).
    pub upper: f64,
    /// Effort limit, N m or N.
    pub effort: f64,
    /// Velocity limit, rad/s or m/s.
    pub velocity: f64,
    /// Viscous damping, N m s/rad or N s/m.
    pub damping: f64,
    /// Mimic relation: (leader joint index, multiplier, offset).
    pub mimic: Option<(usize, f64, f64)>,
}

impl RobotJoint {
    /// The rapier joint axis of this joint's single degree of freedom.
    pub fn rapier_axis(&self) -> JointAxis {
        match self.kind {
            JointKind::Prismatic => JointAxis::LinX,
            _ => JointAxis::AngX,
        }
    }

    /// Index of the degree of freedom in the joint's spatial coordinates.
    fn coord_index(&self) -> usize {
        match self.kind {
            JointKind::Prismatic => 0,
            _ => 3,
        }
    }

    /// Clamps a position to the limits.
    pub fn clamp(&self, q: f64) -> f64 {
        q.clamp(self.lower, self.upper)
    }
}

/// A named frame (every URDF link): the body it belongs to and its pose in that body.
#[derive(Debug, Clone)]
pub struct RobotFrame {
    /// Link name.
    pub name: String,
    /// Body index in [`Robot::bodies`].
    pub body: usize,
    /// Pose of the link frame in the body frame.
    pub offset: Isometry3<f64>,
}

/// A robot built into a [`RigidContext`]: the handles of its bodies and the description of its
/// joints. It owns no physics state itself (that lives in the context, so snapshots include it).
#[derive(Debug, Clone)]
pub struct Robot {
    /// Robot name (from the URDF).
    pub name: String,
    /// How the root is attached.
    pub root_mount: RootMount,
    /// Bodies; index 0 is the root.
    pub bodies: Vec<RobotBody>,
    /// Actuated joints, parents before children.
    pub joints: Vec<RobotJoint>,
    /// Every URDF link as a frame.
    pub frames: Vec<RobotFrame>,
}

fn rotation_x_to(axis: &Vector3<f64>) -> UnitQuaternion<f64> {
    let x = Vector3::x();
    UnitQuaternion::rotation_between(&x, axis).unwrap_or_else(|| {
        // Antiparallel: half a turn about z.
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI)
    })
}

/// Accumulated mass properties of a body in f64 (mass, first moment, inertia about the body
/// origin).
#[derive(Default, Clone, Copy)]
struct MassSum {
    mass: f64,
    moment: Vector3<f64>,
    inertia_origin: Matrix3<f64>,
}

impl MassSum {
    fn add(&mut self, mass: f64, com: Vector3<f64>, inertia_com: Matrix3<f64>) {
        self.mass += mass;
        self.moment += com * mass;
        let d = com;
        let shift = (Matrix3::identity() * d.dot(&d) - d * d.transpose()) * mass;
        self.inertia_origin += inertia_com + shift;
    }

    fn to_rapier(self) -> (f64, MassProperties) {
        if self.mass <= 0.0 {
            return (0.0, MassProperties::default());
        }
        let com = self.moment / self.mass;
        let shift = (Matrix3::identity() * com.dot(&com) - com * com.transpose()) * self.mass;
        let ic = self.inertia_origin - shift;
        let cols: [f32; 9] = [
            ic[(0, 0)] as f32,
            ic[(1, 0)] as f32,
            ic[(2, 0)] as f32,
            ic[(0, 1)] as f32,
            ic[(1, 1)] as f32,
            ic[(2, 1)] as f32,
            ic[(0, 2)] as f32,
            ic[(1, 2)] as f32,
            ic[(2, 2)] as f32,
        ];
        use modesuite_engine::deps::rapier3d::math::Matrix;
        (
            self.mass,
            MassProperties::with_inertia_matrix(
                vec_to_rapier(&com),
                self.mass as f32,
                Matrix::from_cols_array(&cols),
            ),
        )
    }
}

/// Builds `model` into `ctx` as one multibody and returns its [`Robot`] handle. On error nothing
/// is left half-built in `ctx` that could step: bodies created before the error are removed.
pub fn spawn_robot(
    ctx: &mut RigidContext,
    model: &UrdfModel,
    options: &SpawnOptions,
) -> Result<Robot, RobotError> {
    let file = model.file.clone();
    if !options.friction.is_finite() || options.friction < 0.0 {
        return Err(RobotError::InvalidInput {
            robot: model.name.clone(),
            message: format!("friction must be finite and >= 0, got {}", options.friction),
        });
    }
    let p = &options.pose;
    if !(p.translation.vector.iter().all(|v| v.is_finite())
        && p.rotation.coords.iter().all(|v| v.is_finite()))
    {
        return Err(RobotError::InvalidInput {
            robot: model.name.clone(),
            message: "spawn pose not finite".into(),
        });
    }
    // 1. Bodies: the root and every child of an actuated joint; fixed children merge.
    let n = model.links.len();
    // A UrdfModel can be built by hand: check its indices instead of trusting them.
    if model.root >= n || model.joints.iter().any(|j| j.parent >= n || j.child >= n) {
        return Err(RobotError::Structure {
            file,
            message: "link index out of range (root or joint parent/child)".into(),
        });
    }
    let mut body_of: Vec<Option<(usize, Isometry3<f64>)>> = vec![None; n];
    let mut body_links: Vec<usize> = vec![model.root];
    let mut body_parent: Vec<Option<usize>> = vec![None];
    body_of[model.root] = Some((0, Isometry3::identity()));
    for j in &model.joints {
        let (pb, poff) = body_of[j.parent].ok_or_else(|| RobotError::Structure {
            file: file.clone(),
            message: format!("joint `{}` reached before its parent link", j.name),
        })?;
        if j.kind == JointKind::Fixed {
            body_of[j.child] = Some((pb, poff * j.origin));
        } else {
            body_of[j.child] = Some((body_links.len(), Isometry3::identity()));
            body_links.push(j.child);
            body_parent.push(Some(pb));
        }
    }
    let body_of: Vec<(usize, Isometry3<f64>)> = body_of
        .into_iter()
        .enumerate()
        .map(|(li, b)| {
            b.ok_or_else(|| RobotError::Structure {
                file: file.clone(),
                message: format!(
                    "link `{}` is not reached from the root",
                    model.links[li].name
                ),
            })
        })
        .collect::<Result<_, _>>()?;
    let nb = body_links.len();
    if nb < 2 {
        return Err(RobotError::Structure {
            file,
            message: "the robot has no revolute, continuous or prismatic joint".into(),
        });
    }
    // 2. Mass properties per body.
    let mut sums = vec![MassSum::default(); nb];
    for (li, link) in model.links.iter().enumerate() {
        let (b, off) = body_of[li];
        if let Some(inr) = &link.inertial {
            let frame = off * inr.origin;
            let r = frame.rotation.to_rotation_matrix();
            let i_body = r.matrix() * inr.inertia * r.matrix().transpose();
            sums[b].add(inr.mass, frame.translation.vector, i_body);
        }
    }
    // 3. World poses at zero configuration.
    let mut world: Vec<Isometry3<f64>> = vec![options.pose; nb];
    for j in &model.joints {
        if j.kind.is_actuated() {
            let (pb, poff) = body_of[j.parent];
            let (cb, _) = body_of[j.child];
            world[cb] = world[pb] * poff * j.origin;
        }
    }
    // 4. Rapier bodies and colliders.
    let mut bodies = Vec::with_capacity(nb);
    let mut created: Vec<RigidBodyHandle> = Vec::with_capacity(nb);
    let cleanup = |ctx: &mut RigidContext, created: &[RigidBodyHandle]| {
        for h in created.iter().rev() {
            // The bodies were created by this call: no soft body can be attached to them, so an
            // empty soft-body set stands in for the context's own.
            ctx.bodies.remove(
                *h,
                &mut ctx.islands,
                &mut ctx.colliders,
                &mut ctx.impulse_joints,
                &mut ctx.multibody_joints,
                &mut SoftBodySet::new(),
                true,
            );
        }
    };
    for b in 0..nb {
        let (mass, mprops) = sums[b].to_rapier();
        let builder = if b == 0 && options.root == RootMount::Fixed {
            RigidBodyBuilder::fixed()
        } else {
            RigidBodyBuilder::dynamic()
                .additional_mass_properties(mprops)
                .can_sleep(false)
        };
        let handle = ctx
            .bodies
            .insert(builder.pose(pose_to_rapier(&world[b])).build());
        created.push(handle);
        bodies.push(RobotBody {
            name: model.links[body_links[b]].name.clone(),
            handle,
            parent: body_parent[b],
            mass,
        });
    }
    for (li, link) in model.links.iter().enumerate() {
        let (b, off) = body_of[li];
        for c in &link.collisions {
            let local = off * c.origin;
            let (builder, fix) = match &c.geometry {
                Geometry::Box { size } => (
                    ColliderBuilder::cuboid(
                        (size.x / 2.0) as f32,
                        (size.y / 2.0) as f32,
                        (size.z / 2.0) as f32,
                    ),
                    None,
                ),
                // rapier's cylinder runs along y, URDF's along z.
                Geometry::Cylinder { radius, length } => (
                    ColliderBuilder::cylinder((length / 2.0) as f32, *radius as f32),
                    Some(UnitQuaternion::from_axis_angle(
                        &Vector3::x_axis(),
                        std::f64::consts::FRAC_PI_2,
                    )),
                ),
                Geometry::Capsule { radius, length } => (
                    ColliderBuilder::capsule_z((length / 2.0) as f32, *radius as f32),
                    None,
                ),
                Geometry::Sphere { radius } => (ColliderBuilder::ball(*radius as f32), None),
                Geometry::Mesh { path, .. } => {
                    cleanup(ctx, &created);
                    return Err(RobotError::Link {
                        file,
                        link: link.name.clone(),
                        message: format!(
                            "collision mesh `{}` is not supported: use primitives (box, cylinder, capsule, sphere)",
                            path.display()
                        ),
                    });
                }
            };
            let local = match fix {
                Some(r) => local * r,
                None => local,
            };
            let collider = builder
                .position(pose_to_rapier(&local))
                .density(0.0)
                .friction(options.friction as f32)
                .build();
            ctx.colliders
                .insert_with_parent(collider, bodies[b].handle, &mut ctx.bodies);
        }
    }
    // 5. Multibody joints.
    let mut joints: Vec<RobotJoint> = Vec::new();
    for j in &model.joints {
        if !j.kind.is_actuated() {
            continue;
        }
        let (pb, poff) = body_of[j.parent];
        let (cb, _) = body_of[j.child];
        let r_axis = rotation_x_to(&j.axis);
        let frame1 = poff * j.origin * r_axis;
        let frame2 = Isometry3::from_parts(Default::default(), r_axis);
        let (mask, axis) = match j.kind {
            JointKind::Prismatic => (JointAxesMask::LOCKED_PRISMATIC_AXES, JointAxis::LinX),
            _ => (JointAxesMask::LOCKED_REVOLUTE_AXES, JointAxis::AngX),
        };
        let mut builder = GenericJointBuilder::new(mask)
            .local_frame1(pose_to_rapier(&frame1))
            .local_frame2(pose_to_rapier(&frame2))
            .contacts_enabled(false)
            .motor_model(axis, MotorModel::AccelerationBased)
            .motor_max_force(axis, j.effort as f32);
        if j.kind != JointKind::Continuous {
            builder = builder.limits(axis, [j.lower as f32, j.upper as f32]);
        }
        let inserted = ctx.multibody_joints.insert(
            bodies[pb].handle,
            bodies[cb].handle,
            builder.build(),
            true,
        );
        if inserted.is_none() {
            cleanup(ctx, &created);
            return Err(RobotError::Joint {
                file,
                joint: j.name.clone(),
                message: "rapier refused the multibody joint (would close a loop)".into(),
            });
        }
        joints.push(RobotJoint {
            name: j.name.clone(),
            kind: j.kind,
            body: cb,
            parent_body: pb,
            axis: j.axis.into_inner(),
            anchor: Vector3::zeros(),
            lower: j.lower,
            upper: j.upper,
            effort: j.effort,
            velocity: j.velocity,
            damping: j.damping,
            mimic: None,
        });
    }
    let names: HashMap<String, usize> = joints
        .iter()
        .enumerate()
        .map(|(i, j)| (j.name.clone(), i))
        .collect();
    for j in &model.joints {
        if let (Some(m), Some(&ji)) = (&j.mimic, names.get(&j.name)) {
            if let Some(&leader) = names.get(&m.joint) {
                joints[ji].mimic = Some((leader, m.multiplier, m.offset));
            }
        }
    }
    let frames = model
        .links
        .iter()
        .enumerate()
        .map(|(li, l)| {
            let (b, off) = body_of[li];
            RobotFrame {
                name: l.name.clone(),
                body: b,
                offset: off,
            }
        })
        .collect();
    let robot = Robot {
        name: model.name.clone(),
        root_mount: options.root,
        bodies,
        joints,
        frames,
    };
    // 6. Per-dof damping, self-contacts off, initial configuration.
    let result = (|| {
        let mut q = Vec::with_capacity(robot.joints.len());
        for j in &robot.joints {
            let zero_ok = j.lower <= 0.0 && 0.0 <= j.upper;
            q.push(if zero_ok {
                0.0
            } else {
                0.5 * (j.lower + j.upper)
            });
        }
        for (name, v) in &options.initial {
            let i = robot.joint_index(name)?;
            q[i] = *v;
        }
        for i in 0..robot.joints.len() {
            if let Some((leader, mult, off)) = robot.joints[i].mimic {
                q[i] = robot.joints[i].clamp(mult * q[leader] + off);
            }
        }
        {
            let (mb, ids) = robot.multibody_mut(&mut ctx.multibody_joints)?;
            mb.set_self_contacts_enabled(false);
            for (j, id) in robot.joints.iter().zip(ids) {
                let dof = mb
                    .link(id)
                    .map(|l| l.assembly_id())
                    .ok_or_else(|| robot.stale("joint link missing"))?;
                if let Some(d) = mb.damping_mut().get_mut(dof) {
                    *d = j.damping as f32;
                }
            }
        }
        robot.set_joint_positions(ctx, &q)
    })();
    if let Err(e) = result {
        let handles: Vec<_> = robot.bodies.iter().map(|b| b.handle).collect();
        cleanup(ctx, &handles);
        return Err(e);
    }
    Ok(robot)
}

impl Robot {
    pub(crate) fn stale(&self, message: &str) -> RobotError {
        RobotError::Stale {
            robot: self.name.clone(),
            message: message.to_string(),
        }
    }

    /// Handle of the root body.
    pub fn root(&self) -> RigidBodyHandle {
        self.bodies[0].handle
    }

    /// Number of actuated joints.
    pub fn num_joints(&self) -> usize {
        self.joints.len()
    }

    /// Index of an actuated joint by name.
    pub fn joint_index(&self, name: &str) -> Result<usize, RobotError> {
        self.joints
            .iter()
            .position(|j| j.name == name)
            .ok_or_else(|| RobotError::UnknownName {
                robot: self.name.clone(),
                what: "joint",
                name: name.to_string(),
            })
    }

    /// Index of a frame (URDF link) by name.
    pub fn frame_index(&self, name: &str) -> Result<usize, RobotError> {
        self.frames
            .iter()
            .position(|f| f.name == name)
            .ok_or_else(|| RobotError::UnknownName {
                robot: self.name.clone(),
                what: "frame",
                name: name.to_string(),
            })
    }

    /// Total mass of the robot, kg.
    pub fn total_mass(&self) -> f64 {
        self.bodies.iter().map(|b| b.mass).sum()
    }

    /// The multibody and the link id of every joint's child body.
    pub(crate) fn multibody<'a>(
        &self,
        ctx: &'a RigidContext,
    ) -> Result<(&'a Multibody, Vec<usize>), RobotError> {
        self.multibody_in(&ctx.multibody_joints)
    }

    fn link_ids(&self, set: &MultibodyJointSet) -> Result<Vec<usize>, RobotError> {
        let root = set
            .rigid_body_link(self.root())
            .ok_or_else(|| self.stale("root body is not in a multibody"))?;
        let mut ids = Vec::with_capacity(self.joints.len());
        for j in &self.joints {
            let l = set
                .rigid_body_link(self.bodies[j.body].handle)
                .ok_or_else(|| self.stale("joint body is not in a multibody"))?;
            if l.multibody != root.multibody {
                return Err(self.stale("joint body moved to another multibody"));
            }
            ids.push(l.id);
        }
        Ok(ids)
    }

    /// The multibody (in a multibody joint set) and the link id of every joint's child body.
    pub(crate) fn multibody_in<'a>(
        &self,
        set: &'a MultibodyJointSet,
    ) -> Result<(&'a Multibody, Vec<usize>), RobotError> {
        let ids = self.link_ids(set)?;
        let root = set
            .rigid_body_link(self.root())
            .ok_or_else(|| self.stale("root body is not in a multibody"))?;
        let mb = set
            .get_multibody(root.multibody)
            .ok_or_else(|| self.stale("multibody removed"))?;
        Ok((mb, ids))
    }

    /// Mutable multibody and the link id of every joint's child body.
    pub(crate) fn multibody_mut<'a>(
        &self,
        set: &'a mut MultibodyJointSet,
    ) -> Result<(&'a mut Multibody, Vec<usize>), RobotError> {
        let ids = self.link_ids(set)?;
        let root = *set
            .rigid_body_link(self.root())
            .ok_or_else(|| self.stale("root body is not in a multibody"))?;
        let mb = set
            .get_multibody_mut(root.multibody)
            .ok_or_else(|| self.stale("multibody removed"))?;
        Ok((mb, ids))
    }

    /// Current joint positions (rad or m), in [`Robot::joints`] order.
    pub fn joint_positions(&self, ctx: &RigidContext) -> Result<Vec<f64>, RobotError> {
        let (mb, ids) = self.multibody(ctx)?;
        self.joints
            .iter()
            .zip(ids)
            .map(|(j, id)| {
                mb.link(id)
                    .map(|l| f64::from(l.joint.coords()[j.coord_index()]))
                    .ok_or_else(|| self.stale("joint link missing"))
            })
            .collect()
    }

    /// Current joint velocities (rad/s or m/s).
    pub fn joint_velocities(&self, ctx: &RigidContext) -> Result<Vec<f64>, RobotError> {
        let (mb, ids) = self.multibody(ctx)?;
        self.joints
            .iter()
            .zip(ids)
            .map(|(_, id)| {
                mb.link(id)
                    .map(|l| f64::from(mb.generalized_velocity()[l.assembly_id()]))
                    .ok_or_else(|| self.stale("joint link missing"))
            })
            .collect()
    }

    /// Teleports the joints to `q` (all joints, [`Robot::joints`] order) with zero velocity and
    /// updates every body pose (forward kinematics from the root body's pose).
    pub fn set_joint_positions(&self, ctx: &mut RigidContext, q: &[f64]) -> Result<(), RobotError> {
        if q.len() != self.joints.len() {
            return Err(RobotError::InvalidInput {
                robot: self.name.clone(),
                message: format!(
                    "expected {} joint positions, got {}",
                    self.joints.len(),
                    q.len()
                ),
            });
        }
        for (j, v) in self.joints.iter().zip(q) {
            if !v.is_finite() || *v < j.lower - 1e-6 || *v > j.upper + 1e-6 {
                return Err(RobotError::InvalidInput {
                    robot: self.name.clone(),
                    message: format!(
                        "joint `{}`: position {v} outside its limits [{}, {}]",
                        j.name, j.lower, j.upper
                    ),
                });
            }
        }
        let (mb, ids) = self.multibody_mut(&mut ctx.multibody_joints)?;
        // The root joint type follows the root body (free or fixed) only after forward
        // kinematics: do it first, then displace each joint to its target.
        mb.forward_kinematics(&ctx.bodies, true);
        for ((j, id), v) in self.joints.iter().zip(&ids).zip(q) {
            let link = mb
                .link_mut(*id)
                .ok_or_else(|| self.stale("joint link missing"))?;
            let current = f64::from(link.joint.coords()[j.coord_index()]);
            link.joint.apply_displacement(&[(v - current) as f32]);
        }
        mb.generalized_velocity_mut().fill(0.0);
        mb.forward_kinematics(&ctx.bodies, true);
        mb.update_rigid_bodies(&mut ctx.bodies, true);
        for b in &self.bodies {
            if let Some(body) = ctx.bodies.get_mut(b.handle) {
                if body.is_dynamic() {
                    body.set_linvel(Default::default(), true);
                    body.set_angvel(Default::default(), true);
                }
            }
        }
        Ok(())
    }

    /// World pose of a body.
    pub fn body_pose(&self, ctx: &RigidContext, body: usize) -> Result<Isometry3<f64>, RobotError> {
        let b = self
            .bodies
            .get(body)
            .ok_or_else(|| RobotError::InvalidInput {
                robot: self.name.clone(),
                message: format!("no body {body}"),
            })?;
        ctx.bodies
            .get(b.handle)
            .map(|rb| pose_from_rapier(rb.position()))
            .ok_or_else(|| self.stale("body removed"))
    }

    /// World pose of a frame (URDF link).
    pub fn frame_pose(
        &self,
        ctx: &RigidContext,
        frame: usize,
    ) -> Result<Isometry3<f64>, RobotError> {
        let f = self
            .frames
            .get(frame)
            .ok_or_else(|| RobotError::InvalidInput {
                robot: self.name.clone(),
                message: format!("no frame {frame}"),
            })?;
        Ok(self.body_pose(ctx, f.body)? * f.offset)
    }
}
