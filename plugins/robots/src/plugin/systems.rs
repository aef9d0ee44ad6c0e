//! The robot systems of every step: actions or scripts into commands and targets
//! (`robot_actions`), joint and walking control every substep (`robot_control`), and the joint
//! states written back to the root entities (`robot_writeback`).

use bevy_ecs::prelude::*;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use modesuite_engine::components::{JointState, Pose};
use modesuite_engine::coupling::{GripperState, Grippers};
use modesuite_engine::env::ActionBuffer;
use modesuite_engine::{RigidContext, SimClock, SimErrors, SimSettings};

use super::model::Script;
use super::runtime::{RobotFixed, RobotRuntime, Robots};
use crate::actions::{ArmMode, BaseMode, DiscreteKey};
use crate::control::{BaseVelocity, JointCommand};
use crate::error::RobotError;
use crate::ik::{solve_ik, IkOptions};
use crate::robot::Robot;

/// Base speed limits (vx m/s, vy m/s, wz rad/s) at a = 1 (SPEC: 0.5, 0.5, 1.0).
pub const BASE_LIMITS: [f64; 3] = [0.5, 0.5, 1.0];

/// What one robot is asked to do this control step, in [-1, 1] units where it applies.
#[derive(Debug, Clone, Default)]
struct Command {
    base: Option<[f64; 3]>,
    legs: Option<Vec<f64>>,
    arm_delta: Option<Vec<f64>>,
    arm_position: Option<Vec<f64>>,
    ee_velocity: Option<[f64; 6]>,
    ee_pose: Option<Isometry3<f64>>,
    gripper: Option<bool>,
}

fn lerp_script(s: &Script, t: f64) -> Command {
    let t = match s.period {
        Some(p) => t.rem_euclid(p),
        None => t,
    };
    let mut cmd = Command::default();
    if !s.base.is_empty() {
        let v = s
            .base
            .iter()
            .rev()
            .find(|b| b.t <= t)
            .map(|b| b.v)
            .unwrap_or([0.0; 3]);
        cmd.base = Some(v);
    }
    if !s.gripper.is_empty() {
        cmd.gripper = Some(
            s.gripper
                .iter()
                .rev()
                .find(|g| g.t <= t)
                .is_some_and(|g| g.closed),
        );
    }
    if let (Some(first), Some(last)) = (s.ee.first(), s.ee.last()) {
        let pos = if t <= first.t {
            first.pos
        } else if t >= last.t {
            last.pos
        } else {
            let k = s.ee.windows(2).find(|w| w[1].t >= t).map(|w| (w[0], w[1]));
            match k {
                Some((a, b)) if b.t > a.t => {
                    let f = (t - a.t) / (b.t - a.t);
                    [0, 1, 2].map(|i| a.pos[i] + f * (b.pos[i] - a.pos[i]))
                }
                Some((_, b)) => b.pos,
                None => last.pos,
            }
        };
        cmd.ee_pose = Some(Isometry3::from_parts(
            Translation3::new(pos[0], pos[1], pos[2]),
            UnitQuaternion::identity(),
        ));
    }
    cmd
}

fn parse_action(f: &RobotFixed, a: &[f32]) -> Command {
    let m = &f.modes;
    let mut cmd = Command::default();
    if m.discrete {
        if let Some(key) = DiscreteKey::from_index(a[0] as usize) {
            let (base, hand, grip) = key.continuous();
            if m.base != BaseMode::Off && m.base != BaseMode::LegJoints {
                cmd.base = Some(base);
            }
            cmd.ee_velocity = Some([hand[0], hand[1], hand[2], 0.0, 0.0, 0.0]);
            cmd.gripper = grip;
        }
        return cmd;
    }
    let (nb, na, ng) = m.dims(f.arm.len(), f.legs.len());
    let v: Vec<f64> = a.iter().map(|x| f64::from(*x)).collect();
    let clip = |x: &[f64]| x.iter().map(|v| v.clamp(-1.0, 1.0)).collect::<Vec<_>>();
    let (b, rest) = v.split_at(nb);
    let (ar, g) = rest.split_at(na);
    match m.base {
        BaseMode::Velocity | BaseMode::Locomotion => {
            let c = clip(b);
            cmd.base = Some([c[0], c[1], c[2]]);
        }
        BaseMode::LegJoints => cmd.legs = Some(clip(b)),
        BaseMode::Off => {}
    }
    match m.arm {
        ArmMode::JointDelta => cmd.arm_delta = Some(clip(ar)),
        ArmMode::JointPosition => cmd.arm_position = Some(clip(ar)),
        ArmMode::EePoseDelta => {
            let c = clip(ar);
            cmd.ee_velocity = Some([c[0], c[1], c[2], c[3], c[4], c[5]]);
        }
        ArmMode::EePoseAbsolute => {
            let rv = Vector3::new(ar[3], ar[4], ar[5]);
            cmd.ee_pose = Some(Isometry3::from_parts(
                Translation3::new(ar[0], ar[1], ar[2]),
                UnitQuaternion::from_scaled_axis(rv),
            ));
        }
        ArmMode::Off => {}
    }
    if ng > 0 {
        cmd.gripper = Some(g[0] > 0.0);
    }
    cmd
}

/// Sets a position target of an arm joint, moved from the previous target by at most the
/// joint's velocity limit times `dt`: the reference the PD motor tracks never runs faster than
/// the URDF's velocity limit, whatever the action mode asks (IK jumps, absolute targets).
fn set_rate_limited(
    r: &mut RobotRuntime,
    robot: &Robot,
    ctx: &RigidContext,
    j: usize,
    q: f64,
    dt: f64,
) -> Result<(), RobotError> {
    let prev = match r.controller.commands[j] {
        JointCommand::Position(p) => p,
        _ => robot.joint_positions(ctx)?[j],
    };
    let step = robot.joints[j].velocity * dt;
    r.controller
        .set_position(robot, j, prev + (q - prev).clamp(-step, step))
}

/// Applies one control step's command to a robot's targets.
fn apply_command(
    r: &mut RobotRuntime,
    ctx: &RigidContext,
    cmd: Command,
    dt: f64,
) -> Result<(), RobotError> {
    let f = r.fixed.clone();
    let robot = &f.robot;
    let m = &f.modes;
    if let Some(b) = cmd.base {
        r.base_command = BaseVelocity {
            vx: b[0] * BASE_LIMITS[0],
            vy: b[1] * BASE_LIMITS[1],
            wz: b[2] * BASE_LIMITS[2],
        };
    }
    if let Some(l) = cmd.legs {
        for ((&j, q0), a) in f.legs.iter().zip(&f.leg_stand).zip(l) {
            r.controller.set_position(robot, j, q0 + m.leg_scale * a)?;
        }
    }
    if let Some(d) = cmd.arm_delta {
        for (&j, a) in f.arm.iter().zip(d) {
            let q = match r.controller.commands[j] {
                JointCommand::Position(q) => q,
                _ => robot.joint_positions(ctx)?[j],
            };
            set_rate_limited(r, robot, ctx, j, q + m.joint_delta_scale * dt * a, dt)?;
        }
    }
    if let Some(p) = cmd.arm_position {
        for (&j, a) in f.arm.iter().zip(p) {
            let jt = &robot.joints[j];
            let (lo, hi) = if jt.lower.is_finite() && jt.upper.is_finite() {
                (jt.lower, jt.upper)
            } else {
                (-std::f64::consts::PI, std::f64::consts::PI)
            };
            set_rate_limited(r, robot, ctx, j, lo + 0.5 * (a + 1.0) * (hi - lo), dt)?;
        }
    }
    let mut solve = false;
    if let Some(v) = cmd.ee_velocity {
        if v.iter().any(|x| *x != 0.0) {
            let dp = Vector3::new(v[0], v[1], v[2]) * (m.ee_speed * dt);
            let dr = Vector3::new(v[3], v[4], v[5]) * (m.ee_angular_speed * dt);
            r.ee_target = Isometry3::from_parts(
                Translation3::from(r.ee_target.translation.vector + dp),
                UnitQuaternion::from_scaled_axis(dr) * r.ee_target.rotation,
            );
            solve = true;
        }
    }
    if let Some(p) = cmd.ee_pose {
        r.ee_target = if f.script.is_some() {
            // Scripts give positions only: keep the orientation.
            Isometry3::from_parts(p.translation, r.ee_target.rotation)
        } else {
            p
        };
        solve = true;
    }
    if solve {
        let world = robot.body_pose(ctx, f.base_body)? * r.ee_target;
        let seed: Vec<f64> = {
            let q = robot.joint_positions(ctx)?;
            q.iter()
                .enumerate()
                .map(|(j, qj)| match r.controller.commands[j] {
                    JointCommand::Position(t) if f.arm.contains(&j) => t,
                    _ => *qj,
                })
                .collect()
        };
        // Seeded from the previous targets, a moving target converges in a few iterations;
        // restarts only run when an attempt ends above the tolerances.
        let opts = IkOptions {
            tol_position: 1e-4,
            tol_angle: 1e-3,
            ..IkOptions::default()
        };
        let sol = solve_ik(robot, ctx, f.ee_frame, &world, &f.arm, Some(&seed), &opts)?;
        for &j in &f.arm {
            set_rate_limited(r, robot, ctx, j, sol.q[j], dt)?;
        }
    }
    if let Some(g) = cmd.gripper {
        r.gripper_closed = g;
    }
    let (open, closed) = f.gripper_open_closed;
    r.controller.set_position(
        robot,
        f.gripper,
        if r.gripper_closed { closed } else { open },
    )?;
    Ok(())
}

pub(super) fn robot_actions(
    mut robots: ResMut<Robots>,
    action: Res<ActionBuffer>,
    ctx: Option<Res<RigidContext>>,
    settings: Res<SimSettings>,
    clock: Res<SimClock>,
    mut grippers: ResMut<Grippers>,
    mut errors: ResMut<SimErrors>,
) {
    let Some(ctx) = ctx else { return };
    if robots.robots.is_empty() {
        return;
    }
    let dt = settings.dt * f64::from(settings.decimation);
    let mut offset = 0;
    grippers.0.clear();
    for r in robots.robots.iter_mut() {
        let f = r.fixed.clone();
        let cmd = match &f.script {
            Some(s) => lerp_script(s, clock.time),
            None => {
                let n = f.modes.flat_dim(f.arm.len(), f.legs.len());
                let Some(a) = action.0.get(offset..offset + n) else {
                    errors.raise(format!(
                        "robot \"{}\": the action has {} values, the robots need at least {}",
                        f.name,
                        action.0.len(),
                        offset + n
                    ));
                    return;
                };
                offset += n;
                parse_action(&f, a)
            }
        };
        if let Err(e) = apply_command(r, &ctx, cmd, dt) {
            errors.raise(format!("robot \"{}\": {e}", f.name));
        }
        let offset_pose = f.robot.frames[f.ee_frame].offset;
        grippers.0.push(GripperState {
            name: format!("{}/gripper", f.name),
            body: f.gripper_body_id,
            volume_pose: offset_pose,
            half_extents: f.finger_volume,
            closed: r.gripper_closed,
            force_limit: f.grasp_force_limit,
        });
    }
}

pub(super) fn robot_control(
    mut robots: ResMut<Robots>,
    ctx: Option<ResMut<RigidContext>>,
    settings: Res<SimSettings>,
    mut errors: ResMut<SimErrors>,
) {
    let Some(mut ctx) = ctx else { return };
    for r in robots.robots.iter_mut() {
        let f = r.fixed.clone();
        let result = (|| {
            if let Some(gait) = r.gait.as_mut() {
                // The walking controller plans every substep and writes the leg targets.
                gait.step(
                    &f.robot,
                    &ctx,
                    r.base_command,
                    settings.substep_dt(),
                    &mut r.controller,
                )?;
            }
            if let Some(base) = &f.base {
                // The base command is turned into joint velocities at the current yaw every
                // substep; with no base action the base holds still.
                let v = if f.modes.base == BaseMode::Velocity || f.script.is_some() {
                    r.base_command
                } else {
                    BaseVelocity::default()
                };
                base.command(&f.robot, &ctx, &mut r.controller, v)?;
            }
            r.controller.apply(&f.robot, &mut ctx)
        })();
        if let Err(e) = result {
            errors.raise(format!("robot \"{}\": {e}", f.name));
        }
    }
}

pub(super) fn robot_writeback(
    robots: Res<Robots>,
    ctx: Option<Res<RigidContext>>,
    mut q: Query<(&mut JointState, &mut Pose)>,
) {
    let Some(ctx) = ctx else { return };
    for r in &robots.robots {
        let f = &r.fixed;
        if let Ok((mut js, mut pose)) = q.get_mut(f.root) {
            if let (Ok(p), Ok(v), Ok(b)) = (
                f.robot.joint_positions(&ctx),
                f.robot.joint_velocities(&ctx),
                f.robot.body_pose(&ctx, f.base_body),
            ) {
                js.positions = p;
                js.velocities = v;
                pose.0 = b;
            }
        }
    }
}
