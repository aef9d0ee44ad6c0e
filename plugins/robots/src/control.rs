//! Joint-space control: per-joint position (PD) or velocity commands realised by rapier's
//! implicit joint motors, plus gravity compensation applied as internal joint torques.
//!
//! Gravity compensation: for every actuated joint j the controller computes the generalised
//! gravity force `tau_g,j = a_j . sum_{i in subtree(j)} (c_i - p_j) x m_i g` (revolute; for a
//! prismatic joint `a_j . sum m_i g`) from the current link poses, and applies `-tau_g,j` as an
//! equal and opposite pair on the joint's child and parent bodies (a torque pair about the axis,
//! or a force pair through the child's centre of mass). The pair is internal: it changes no
//! ancestor joint and does not lift a floating base, so a legged robot still carries its arm's
//! weight. The motor then only has to remove the remaining error, and a PD motor reaches zero
//! steady-state error under gravity. The feed-forward is limited to the joint's effort and the
//! motor gets the rest of the effort budget.

use modesuite_engine::deps::nalgebra::{Isometry3, Vector3};
use modesuite_engine::deps::rapier3d::prelude::{MotorModel, RigidBodyHandle};
use modesuite_engine::math::{vec_from_rapier, vec_to_rapier};
use modesuite_engine::RigidContext;

use crate::error::RobotError;
use crate::robot::Robot;
use crate::urdf::JointKind;

/// What one joint is asked to do.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum JointCommand {
    /// Track a position (rad or m) with the joint's PD gains.
    Position(f64),
    /// Track a velocity (rad/s or m/s), clamped to the joint's velocity limit.
    Velocity(f64),
    /// No motor (the joint only feels its damping and the gravity feed-forward, if enabled).
    Passive,
}

/// PD gains of one joint's motor (rapier's implicit force-based motor, limited to the joint's
/// effort minus the gravity feed-forward).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub enum JointGains {
    /// Gains scaled by the joint-space inertia `M_kk` of the joint at the current configuration
    /// (the inertia it moves with every other joint held): `kp = omega^2 M_kk`,
    /// `kd = 2 zeta omega M_kk`, for a closed-loop natural frequency `omega` (rad/s) and damping
    /// ratio `zeta`. Suits arms, whose load is their own links.
    Inertial {
        /// Natural frequency, rad/s.
        omega: f64,
        /// Damping ratio.
        zeta: f64,
    },
    /// Absolute gains (N m/rad and N m s/rad, or N/m and N s/m). Suits legs, whose load (the
    /// body's weight through the feet) is not in their own inertia.
    Absolute {
        /// Position gain.
        kp: f64,
        /// Velocity gain.
        kd: f64,
    },
}

impl Default for JointGains {
    /// 25 rad/s natural frequency, critically damped: settles in about 0.25 s.
    fn default() -> Self {
        JointGains::Inertial {
            omega: 25.0,
            zeta: 1.0,
        }
    }
}

impl JointGains {
    /// (kp, kd) for a joint-space inertia `m_kk`.
    pub fn resolve(&self, m_kk: f64) -> (f64, f64) {
        match *self {
            JointGains::Inertial { omega, zeta } => {
                (omega * omega * m_kk, 2.0 * zeta * omega * m_kk)
            }
            JointGains::Absolute { kp, kd } => (kp, kd),
        }
    }
}

/// Diagonal of the joint-space mass matrix, `M_kk = sum_i J_i,k^T diag(m_i, I_i) J_i,k` over the
/// robot's bodies (rapier's body Jacobians, linear part at the centre of mass), one per joint.
pub fn joint_inertias(robot: &Robot, ctx: &RigidContext) -> Result<Vec<f64>, RobotError> {
    use modesuite_engine::deps::nalgebra::Matrix3;
    let (mb, ids) = robot.multibody(ctx)?;
    let dofs: Vec<usize> = ids
        .iter()
        .map(|id| {
            mb.link(*id)
                .map(|l| l.assembly_id())
                .ok_or_else(|| robot.stale("joint link missing"))
        })
        .collect::<Result<_, _>>()?;
    let mut out = vec![0.0; dofs.len()];
    for link in mb.links() {
        let Some(rb) = ctx.bodies.get(link.rigid_body_handle()) else {
            continue;
        };
        if !rb.is_dynamic() {
            continue;
        }
        let m = f64::from(rb.mass());
        let local = rb
            .mass_properties()
            .local_mprops
            .reconstruct_inertia_matrix();
        let cols = local.to_cols_array();
        let il = Matrix3::from_column_slice(&cols.map(f64::from));
        let r =
            modesuite_engine::math::rot_from_rapier(rb.position().rotation).to_rotation_matrix();
        let iw = r.matrix() * il * r.matrix().transpose();
        let jac = mb.body_jacobian(link.link_id());
        for (k, &d) in dofs.iter().enumerate() {
            if d >= jac.ncols() {
                continue;
            }
            let col = jac.column(d);
            let v = Vector3::new(f64::from(col[0]), f64::from(col[1]), f64::from(col[2]));
            let w = Vector3::new(f64::from(col[3]), f64::from(col[4]), f64::from(col[5]));
            out[k] += m * v.dot(&v) + w.dot(&(iw * w));
        }
    }
    Ok(out)
}

/// Damping factor of velocity motors (1/s): how fast a velocity command is reached.
pub const VELOCITY_MOTOR_FACTOR: f64 = 50.0;

/// Joint controller of one robot: a command and gains per joint, gravity compensation on or off.
/// Call [`JointController::apply`] before every rapier step (in `PhysicsSystems::ApplyActions`).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct JointController {
    /// Command per joint, [`Robot::joints`] order. Mimic joints ignore theirs and follow their
    /// leader's position command.
    pub commands: Vec<JointCommand>,
    /// Gains per joint.
    pub gains: Vec<JointGains>,
    /// Whether gravity compensation torques are applied.
    pub gravity_compensation: bool,
    /// The last gravity feed-forward per joint (N m or N), for inspection.
    pub last_feedforward: Vec<f64>,
}

impl JointController {
    /// A controller holding the robot's current joint positions, default gains, gravity
    /// compensation on.
    pub fn hold_current(robot: &Robot, ctx: &RigidContext) -> Result<Self, RobotError> {
        let q = robot.joint_positions(ctx)?;
        Ok(Self {
            commands: q.into_iter().map(JointCommand::Position).collect(),
            gains: vec![JointGains::default(); robot.num_joints()],
            gravity_compensation: true,
            last_feedforward: vec![0.0; robot.num_joints()],
        })
    }

    /// Sets a position command for a joint (clamped to its limits).
    pub fn set_position(&mut self, robot: &Robot, joint: usize, q: f64) -> Result<(), RobotError> {
        let j = robot
            .joints
            .get(joint)
            .ok_or_else(|| bad_joint(robot, joint))?;
        if !q.is_finite() {
            return Err(RobotError::InvalidInput {
                robot: robot.name.clone(),
                message: format!("joint `{}`: position command not finite", j.name),
            });
        }
        self.commands[joint] = JointCommand::Position(j.clamp(q));
        Ok(())
    }

    /// Sets a velocity command for a joint (clamped to its velocity limit).
    pub fn set_velocity(&mut self, robot: &Robot, joint: usize, v: f64) -> Result<(), RobotError> {
        let j = robot
            .joints
            .get(joint)
            .ok_or_else(|| bad_joint(robot, joint))?;
        if !v.is_finite() {
            return Err(RobotError::InvalidInput {
                robot: robot.name.clone(),
                message: format!("joint `{}`: velocity command not finite", j.name),
            });
        }
        self.commands[joint] = JointCommand::Velocity(v.clamp(-j.velocity, j.velocity));
        Ok(())
    }

    /// Generalised gravity force on every joint at the current configuration (N m or N): what
    /// gravity does to each joint, the negative of the compensation torque.
    pub fn gravity_torques(robot: &Robot, ctx: &RigidContext) -> Result<Vec<f64>, RobotError> {
        let g = ctx.gravity();
        let nb = robot.bodies.len();
        // Subtree mass and first moment per body (children come after parents).
        let mut mass = vec![0.0; nb];
        let mut moment = vec![Vector3::zeros(); nb];
        for (i, b) in robot.bodies.iter().enumerate() {
            let rb = ctx
                .bodies
                .get(b.handle)
                .ok_or_else(|| robot.stale("body removed"))?;
            if rb.is_dynamic() {
                let m = f64::from(rb.mass());
                mass[i] = m;
                moment[i] = vec_from_rapier(rb.center_of_mass()) * m;
            }
        }
        for i in (1..nb).rev() {
            if let Some(p) = robot.bodies[i].parent {
                let (m, c) = (mass[i], moment[i]);
                mass[p] += m;
                moment[p] += c;
            }
        }
        let mut tau = Vec::with_capacity(robot.joints.len());
        for j in &robot.joints {
            let pose = robot.body_pose(ctx, j.body)?;
            let axis = pose.rotation * j.axis;
            let anchor = pose * modesuite_engine::deps::nalgebra::Point3::from(j.anchor);
            let m = mass[j.body];
            let t = match j.kind {
                JointKind::Prismatic => axis.dot(&(g * m)),
                _ => {
                    // sum (c_i - p) x m_i g = (moment - m p) x g
                    let r = moment[j.body] - anchor.coords * m;
                    axis.dot(&r.cross(&g))
                }
            };
            tau.push(t);
        }
        Ok(tau)
    }

    /// Writes the motor targets and the gravity feed-forward into the rapier state. Clears
    /// every user force and torque on the robot's bodies first (rapier keeps them between steps).
    pub fn apply(&mut self, robot: &Robot, ctx: &mut RigidContext) -> Result<(), RobotError> {
        let n = robot.num_joints();
        if self.commands.len() != n || self.gains.len() != n {
            return Err(RobotError::InvalidInput {
                robot: robot.name.clone(),
                message: format!(
                    "controller has {} commands and {} gains for {n} joints",
                    self.commands.len(),
                    self.gains.len()
                ),
            });
        }
        let ff: Vec<f64> = if self.gravity_compensation {
            Self::gravity_torques(robot, ctx)?
                .into_iter()
                .zip(&robot.joints)
                .map(|(t, j)| (-t).clamp(-j.effort, j.effort))
                .collect()
        } else {
            vec![0.0; n]
        };
        for b in &robot.bodies {
            if let Some(rb) = ctx.bodies.get_mut(b.handle) {
                rb.reset_forces(false);
                rb.reset_torques(false);
            }
        }
        // Internal feed-forward pairs.
        for (j, t) in robot.joints.iter().zip(&ff) {
            if *t == 0.0 {
                continue;
            }
            let pose: Isometry3<f64> = robot.body_pose(ctx, j.body)?;
            let axis = pose.rotation * j.axis;
            let child = robot.bodies[j.body].handle;
            let parent = robot.bodies[j.parent_body].handle;
            match j.kind {
                JointKind::Prismatic => {
                    let com = ctx
                        .bodies
                        .get(child)
                        .map(|b| b.center_of_mass())
                        .ok_or_else(|| robot.stale("body removed"))?;
                    let f = vec_to_rapier(&(axis * *t));
                    add_force_at(ctx, child, f, com);
                    add_force_at(ctx, parent, -f, com);
                }
                _ => {
                    let tq = vec_to_rapier(&(axis * *t));
                    if let Some(b) = ctx.bodies.get_mut(child) {
                        b.add_torque(tq, true);
                    }
                    if let Some(b) = ctx.bodies.get_mut(parent) {
                        if b.is_dynamic() {
                            b.add_torque(-tq, true);
                        }
                    }
                }
            }
        }
        // Motors.
        let inertia = joint_inertias(robot, ctx)?;
        let (mb, ids) = robot.multibody_mut(&mut ctx.multibody_joints)?;
        for (i, (j, id)) in robot.joints.iter().zip(&ids).enumerate() {
            let command = match j.mimic {
                Some((leader, mult, off)) => match self.commands[leader] {
                    JointCommand::Position(q) => JointCommand::Position(j.clamp(mult * q + off)),
                    JointCommand::Velocity(v) => JointCommand::Velocity(mult * v),
                    JointCommand::Passive => JointCommand::Passive,
                },
                None => self.commands[i],
            };
            let axis = j.rapier_axis();
            let budget = (j.effort - ff[i].abs()).max(0.0);
            let link = mb
                .link_mut(*id)
                .ok_or_else(|| robot.stale("joint link missing"))?;
            let data = &mut link.joint.data;
            match command {
                JointCommand::Position(q) => {
                    let (kp, kd) = self.gains[i].resolve(inertia[i]);
                    data.set_motor_model(axis, MotorModel::ForceBased);
                    data.set_motor(axis, q as f32, 0.0, kp as f32, kd as f32);
                    data.set_motor_max_force(axis, budget as f32);
                }
                JointCommand::Velocity(v) => {
                    data.set_motor_model(axis, MotorModel::AccelerationBased);
                    data.set_motor(axis, 0.0, v as f32, 0.0, VELOCITY_MOTOR_FACTOR as f32);
                    data.set_motor_max_force(axis, budget as f32);
                }
                JointCommand::Passive => {
                    data.set_motor(axis, 0.0, 0.0, 0.0, 0.0);
                    data.set_motor_max_force(axis, 0.0);
                }
            }
        }
        self.last_feedforward = ff;
        Ok(())
    }
}

fn add_force_at(
    ctx: &mut RigidContext,
    body: RigidBodyHandle,
    f: modesuite_engine::deps::rapier3d::math::Vector,
    at: modesuite_engine::deps::rapier3d::math::Vector,
) {
    if let Some(b) = ctx.bodies.get_mut(body) {
        if b.is_dynamic() {
            b.add_force_at_point(f, at, true);
        }
    }
}

fn bad_joint(robot: &Robot, joint: usize) -> RobotError {
    RobotError::InvalidInput {
        robot: robot.name.clone(),
        message: format!("no joint {joint} (the robot has {})", robot.num_joints()),
    }
}

/// Holonomic base velocity command in the base frame: forward `vx` (m/s), left `vy` (m/s), yaw
/// rate `wz` (rad/s).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct BaseVelocity {
    /// Forward velocity, m/s.
    pub vx: f64,
    /// Lateral velocity, m/s.
    pub vy: f64,
    /// Yaw rate, rad/s.
    pub wz: f64,
}

/// The three virtual joints of a holonomic base (prismatic x, prismatic y, revolute yaw, in the
/// spawn frame).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HolonomicBase {
    /// Prismatic x joint index.
    pub x: usize,
    /// Prismatic y joint index.
    pub y: usize,
    /// Yaw joint index.
    pub yaw: usize,
}

impl HolonomicBase {
    /// Finds the three joints by name and checks their types.
    pub fn new(robot: &Robot, x: &str, y: &str, yaw: &str) -> Result<Self, RobotError> {
        let base = Self {
            x: robot.joint_index(x)?,
            y: robot.joint_index(y)?,
            yaw: robot.joint_index(yaw)?,
        };
        let kinds = [
            (base.x, JointKind::Prismatic),
            (base.y, JointKind::Prismatic),
            (base.yaw, JointKind::Continuous),
        ];
        for (i, k) in kinds {
            let j = &robot.joints[i];
            let ok = j.kind == k || (k == JointKind::Continuous && j.kind == JointKind::Revolute);
            if !ok {
                return Err(RobotError::InvalidInput {
                    robot: robot.name.clone(),
                    message: format!("base joint `{}` is {:?}, expected {k:?}", j.name, j.kind),
                });
            }
        }
        Ok(base)
    }

    /// Turns a base-frame velocity into velocity commands of the three joints, using the current
    /// yaw.
    pub fn command(
        &self,
        robot: &Robot,
        ctx: &RigidContext,
        controller: &mut JointController,
        v: BaseVelocity,
    ) -> Result<(), RobotError> {
        let yaw = robot.joint_positions(ctx)?[self.yaw];
        let (s, c) = yaw.sin_cos();
        controller.set_velocity(robot, self.x, c * v.vx - s * v.vy)?;
        controller.set_velocity(robot, self.y, s * v.vx + c * v.vy)?;
        controller.set_velocity(robot, self.yaw, v.wz)
    }

    /// Measured base-frame velocity from the joint velocities.
    pub fn measured(&self, robot: &Robot, ctx: &RigidContext) -> Result<BaseVelocity, RobotError> {
        let q = robot.joint_positions(ctx)?;
        let qd = robot.joint_velocities(ctx)?;
        let (s, c) = q[self.yaw].sin_cos();
        let (xd, yd) = (qd[self.x], qd[self.y]);
        Ok(BaseVelocity {
            vx: c * xd + s * yd,
            vy: -s * xd + c * yd,
            wz: qd[self.yaw],
        })
    }
}
