//! Damped-least-squares inverse kinematics over a robot's kinematic branch, with joint limits.
//!
//! Each iteration runs forward kinematics of the branch (rapier's `forward_kinematics_single_branch`
//! through `Multibody::inverse_kinematics` with one iteration), takes one damped-least-squares
//! step `dq = J^T (J J^T + lambda^2 I)^-1 e` on the pose error e (position and rotation vector),
//! and clamps the result to the joint limits. An attempt is `iterations` (100) such steps; when it
//! ends above the tolerances (a local minimum, often against a limit) up to `restarts` further
//! attempts start from deterministic offsets of the seed and the best attempt is returned.
//! Nothing in the physics state changes: the solution is returned as joint positions.

use modesuite_engine::deps::nalgebra::{Isometry3, UnitQuaternion};
use modesuite_engine::deps::rapier3d::math::DVector;
use modesuite_engine::deps::rapier3d::prelude::{InverseKinematicsOption, JointAxesMask};
use modesuite_engine::math::{pose_from_rapier, pose_to_rapier};
use modesuite_engine::RigidContext;

use crate::error::RobotError;
use crate::robot::Robot;

/// Largest IK target coordinate accepted, m (world frame).
pub const MAX_IK_COORDINATE: f64 = 1e5;

/// Options of [`solve_ik`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkOptions {
    /// Iterations (rapier's default of 10 is too few; 100 converges to < 1 mm).
    pub iterations: usize,
    /// Damping lambda of the least-squares step (m or rad).
    pub damping: f64,
    /// Stop once the position error is below this, m (and the angle error below `tol_angle`).
    pub tol_position: f64,
    /// Stop once the angle error is below this, rad.
    pub tol_angle: f64,
    /// Further attempts when an attempt ends above the tolerances, each from the start
    /// configuration shifted by a fixed (deterministic) offset of up to +-`restart_spread` per
    /// joint; the best attempt is returned.
    pub restarts: usize,
    /// Largest seed offset of a restart, rad or m.
    pub restart_spread: f64,
}

impl Default for IkOptions {
    fn default() -> Self {
        Self {
            iterations: 100,
            damping: 0.05,
            tol_position: 1e-4,
            tol_angle: 1e-4,
            restarts: 4,
            restart_spread: 0.6,
        }
    }
}

/// Result of [`solve_ik`].
#[derive(Debug, Clone, PartialEq)]
pub struct IkSolution {
    /// Joint positions of every joint ([`Robot::joints`] order); joints outside the solved set
    /// keep their current positions.
    pub q: Vec<f64>,
    /// Remaining position error of the frame, m.
    pub position_error: f64,
    /// Remaining rotation error of the frame, rad.
    pub angle_error: f64,
    /// Attempts made (1 + restarts used).
    pub attempts: usize,
}

/// Fractional parts of square roots of primes: a fixed low-discrepancy sequence of restart
/// offsets (Weyl sequence), so a solve is reproducible.
const WEYL: [f64; 12] = [
    0.414_213_562,
    0.732_050_808,
    0.236_067_977,
    0.645_751_311,
    0.316_624_790,
    0.605_551_275,
    0.123_105_626,
    0.358_898_944,
    0.795_831_523,
    0.385_164_807,
    0.567_764_363,
    0.082_762_530,
];

/// Solves for joint positions of `joints` that put `frame` at `target` (world frame), starting
/// from `seed` (all joints; None: the current positions).
pub fn solve_ik(
    robot: &Robot,
    ctx: &RigidContext,
    frame: usize,
    target: &Isometry3<f64>,
    joints: &[usize],
    seed: Option<&[f64]>,
    options: &IkOptions,
) -> Result<IkSolution, RobotError> {
    let invalid = |m: String| RobotError::InvalidInput {
        robot: robot.name.clone(),
        message: m,
    };
    let f = robot
        .frames
        .get(frame)
        .ok_or_else(|| invalid(format!("no frame {frame}")))?;
    if !(target.translation.vector.iter().all(|v| v.is_finite())
        && target.rotation.coords.iter().all(|v| v.is_finite()))
    {
        return Err(invalid("IK target not finite".into()));
    }
    // rapier's IK runs in f32 and its SVD does not return on non-finite entries: a target far
    // beyond any workspace (1e308 is finite in f64, infinite in f32) would never come back.
    if let Some(x) = target
        .translation
        .vector
        .iter()
        .find(|v| v.abs() > MAX_IK_COORDINATE)
    {
        return Err(invalid(format!(
            "IK target coordinate {x} m is beyond +-{MAX_IK_COORDINATE:e} m (a robot's reach is a few metres)"
        )));
    }
    if !(options.damping.is_finite() && options.damping >= 0.0) {
        return Err(invalid(format!("IK damping {} invalid", options.damping)));
    }
    for &j in joints {
        if j >= robot.num_joints() {
            return Err(invalid(format!("no joint {j}")));
        }
    }
    let current = robot.joint_positions(ctx)?;
    if current.iter().any(|q| !q.is_finite()) {
        return Err(invalid(
            "the robot's joint positions are not finite (the physics blew up)".into(),
        ));
    }
    let start = match seed {
        Some(s) if s.len() == current.len() && s.iter().all(|v| v.is_finite()) => s.to_vec(),
        Some(s) => {
            return Err(invalid(format!(
                "IK seed has {} finite values, expected {}",
                s.len(),
                current.len()
            )))
        }
        None => current.clone(),
    };
    let (mb, ids) = robot.multibody(ctx)?;
    let link_of_body = |b: usize| -> Result<usize, RobotError> {
        ctx.multibody_joints
            .rigid_body_link(robot.bodies[b].handle)
            .map(|l| l.id)
            .ok_or_else(|| robot.stale("body not in the multibody"))
    };
    let target_link = link_of_body(f.body)?;
    let dof = |i: usize| -> Result<usize, RobotError> {
        mb.link(ids[i])
            .map(|l| l.assembly_id())
            .ok_or_else(|| robot.stale("joint link missing"))
    };
    let movable: Vec<_> = joints
        .iter()
        .map(|&j| robot.bodies[robot.joints[j].body].handle)
        .collect();
    // Target pose of the body that carries the frame, its quaternion on the same hemisphere as
    // the body's current one: q and -q are the same rotation, but rapier's IK error takes the
    // angle of `target * current^-1` as is, so an opposite sign reads as a turn of nearly 2 pi
    // (a target built from a rotation vector, w >= 0, sent the arm away from a pose with w < 0).
    let mut body_target_iso = target * f.offset.inverse();
    let now = robot.body_pose(ctx, f.body)?;
    if now.rotation.coords.dot(&body_target_iso.rotation.coords) < 0.0 {
        body_target_iso.rotation =
            UnitQuaternion::new_unchecked(-body_target_iso.rotation.into_inner());
    }
    let body_target = pose_to_rapier(&body_target_iso);
    let step = InverseKinematicsOption {
        damping: options.damping as f32,
        max_iters: 1,
        constrained_axes: JointAxesMask::all(),
        epsilon_linear: 0.0,
        epsilon_angular: 0.0,
    };
    let branch = mb.kinematic_branch(target_link);
    let error_of = |disp: &DVector| -> (f64, f64) {
        let pose =
            mb.forward_kinematics_single_branch(&ctx.bodies, &branch, Some(disp.as_slice()), None);
        let got = pose_from_rapier(&pose) * f.offset;
        (
            (got.translation.vector - target.translation.vector).norm(),
            got.rotation.angle_to(&target.rotation),
        )
    };
    let converged = |(ep, ea): (f64, f64)| ep <= options.tol_position && ea <= options.tol_angle;
    // Position error plus angle error at 0.1 m per rad.
    let score = |(ep, ea): (f64, f64)| ep + 0.1 * ea;
    let mut best: Option<(DVector, (f64, f64))> = None;
    let mut attempts = 0;
    for attempt in 0..=options.restarts {
        attempts = attempt + 1;
        let mut disp = DVector::zeros(mb.ndofs());
        for i in 0..robot.num_joints() {
            disp[dof(i)?] = (start[i] - current[i]) as f32;
        }
        if attempt > 0 {
            for (m, &j) in joints.iter().enumerate() {
                let w = (WEYL[m % WEYL.len()] * attempt as f64).fract() * 2.0 - 1.0;
                let q = (start[j] + w * options.restart_spread)
                    .clamp(robot.joints[j].lower, robot.joints[j].upper);
                disp[dof(j)?] = (q - current[j]) as f32;
            }
        }
        for it in 0..options.iterations {
            mb.inverse_kinematics(
                &ctx.bodies,
                target_link,
                &step,
                &body_target,
                |link| movable.contains(&link.rigid_body_handle()),
                &mut disp,
            );
            for &j in joints {
                let d = dof(j)?;
                let q = (current[j] + f64::from(disp[d]))
                    .clamp(robot.joints[j].lower, robot.joints[j].upper);
                disp[d] = (q - current[j]) as f32;
            }
            if it % 10 == 9 && converged(error_of(&disp)) {
                break;
            }
        }
        let err = error_of(&disp);
        if best.as_ref().is_none_or(|(_, e)| score(err) < score(*e)) {
            best = Some((disp, err));
        }
        if converged(err) {
            break;
        }
    }
    let Some((disp, (position_error, angle_error))) = best else {
        return Err(invalid("IK made no attempt".into()));
    };
    let mut q = current.clone();
    for (i, qi) in q.iter_mut().enumerate() {
        *qi = current[i] + f64::from(disp[dof(i)?]);
    }
    Ok(IkSolution {
        q,
        position_error,
        angle_error,
        attempts,
    })
}

/// World pose of `frame` if the joints were at `q` (all joints), without changing the state.
pub fn forward_kinematics(
    robot: &Robot,
    ctx: &RigidContext,
    frame: usize,
    q: &[f64],
) -> Result<Isometry3<f64>, RobotError> {
    let f = robot
        .frames
        .get(frame)
        .ok_or_else(|| RobotError::InvalidInput {
            robot: robot.name.clone(),
            message: format!("no frame {frame}"),
        })?;
    let current = robot.joint_positions(ctx)?;
    if q.len() != current.len() || !q.iter().all(|v| v.is_finite()) {
        return Err(RobotError::InvalidInput {
            robot: robot.name.clone(),
            message: format!(
                "expected {} finite joint positions, got {}",
                current.len(),
                q.len()
            ),
        });
    }
    let (mb, ids) = robot.multibody(ctx)?;
    let mut disp = DVector::zeros(mb.ndofs());
    for i in 0..current.len() {
        let d = mb
            .link(ids[i])
            .map(|l| l.assembly_id())
            .ok_or_else(|| robot.stale("joint link missing"))?;
        disp[d] = (q[i] - current[i]) as f32;
    }
    let link = ctx
        .multibody_joints
        .rigid_body_link(robot.bodies[f.body].handle)
        .map(|l| l.id)
        .ok_or_else(|| robot.stale("body not in the multibody"))?;
    let pose = mb.forward_kinematics_single_link(&ctx.bodies, link, Some(disp.as_slice()), None);
    Ok(pose_from_rapier(&pose) * f.offset)
}
