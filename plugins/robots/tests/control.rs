//! Joint PD tracking with gravity compensation on the Franka arm, holonomic base velocity
//! tracking, and Spot standing on its legs under its own weight.

mod common;

use modesuite_engine::deps::nalgebra::{Isometry3, Vector3};
use modesuite_engine::deps::rapier3d::prelude::{ColliderBuilder, RigidBodyBuilder};
use modesuite_engine::math::vec_to_rapier;
use modesuite_robots::{BaseVelocity, HolonomicBase, JointController};

/// Steps the Franka arm from home to home + `delta` on every arm joint and returns, per joint,
/// (error at 1 s, overshoot fraction, settling time into 0.01 rad in s).
fn franka_step_response(
    dt: f64,
    gravity_compensation: bool,
    delta: f64,
    substeps_per_apply: usize,
) -> Vec<(String, f64, f64, f64)> {
    let (mut ctx, spec, robot) = common::spawn("franka");
    let arm = spec.indices(&robot, &spec.arm_joints).unwrap();
    let mut ctl = JointController::hold_current(&robot, &ctx).unwrap();
    ctl.gravity_compensation = gravity_compensation;
    // Settle for 0.5 s at home.
    for _ in 0..(0.5 / dt).round() as usize {
        ctl.apply(&robot, &mut ctx).unwrap();
        ctx.step(dt).unwrap();
    }
    let q0 = robot.joint_positions(&ctx).unwrap();
    let mut target = Vec::new();
    for &i in &arm {
        let j = &robot.joints[i];
        // Step towards the side with room.
        let d = if q0[i] + delta <= j.upper {
            delta
        } else {
            -delta
        };
        target.push(q0[i] + d);
        ctl.set_position(&robot, i, q0[i] + d).unwrap();
    }
    let mut peak = vec![0.0f64; arm.len()];
    let mut settle = vec![0.0f64; arm.len()];
    let steps = (1.0 / dt).round() as usize;
    for s in 0..steps {
        if s % substeps_per_apply == 0 {
            ctl.apply(&robot, &mut ctx).unwrap();
        }
        ctx.step(dt).unwrap();
        let q = robot.joint_positions(&ctx).unwrap();
        for (k, &i) in arm.iter().enumerate() {
            let dir = (target[k] - q0[i]).signum();
            peak[k] = peak[k].max((q[i] - target[k]) * dir);
            if (q[i] - target[k]).abs() > 0.01 {
                settle[k] = (s + 1) as f64 * dt;
            }
        }
    }
    let q = robot.joint_positions(&ctx).unwrap();
    arm.iter()
        .enumerate()
        .map(|(k, &i)| {
            (
                robot.joints[i].name.clone(),
                (q[i] - target[k]).abs(),
                peak[k] / (target[k] - q0[i]).abs(),
                settle[k],
            )
        })
        .collect()
}

/// Worst (error, overshoot, settling time) over the arm's joints.
fn worst(rows: &[(String, f64, f64, f64)]) -> (f64, f64, f64) {
    rows.iter().fold((0.0, 0.0, 0.0), |w, r| {
        (w.0.max(r.1), w.1.max(r.2), w.2.max(r.3))
    })
}

#[test]
fn franka_pd_tracking_with_gravity_compensation() {
    let delta = 0.3;
    let dt = common::dt("franka");
    let with = franka_step_response(dt, true, delta, 1);
    let without = franka_step_response(dt, false, delta, 1);
    println!(
        "step of {delta} rad on every arm joint at dt {dt:.5} s, measured 1 s after the step:"
    );
    println!("joint          | error (tol 0.01 rad) | overshoot (tol 10 %) | settled to 0.01 rad after (tol 1 s) | error without gravity comp.");
    for ((name, e, o, ts), (_, e0, _, _)) in with.iter().zip(&without) {
        println!(
            "{name:14} | {e:20.5} | {:19.2} % | {ts:33.3} s | {e0:.5}",
            o * 100.0
        );
    }
    // The same step at the finer substeps of the Franka's task scenes (1/120 s with FEM rods
    // and cloth, 1/240 s in Lift), and with the controller applied once per 60 Hz control step
    // (every 4th substep of 1/240 s) instead of every substep.
    let mut cases = vec![("controller every substep", dt, with)];
    for (label, h, per) in [
        ("controller every substep", 1.0 / 120.0, 1),
        ("controller every substep", 1.0 / 240.0, 1),
        ("controller every 4th substep", 1.0 / 240.0, 4),
    ] {
        cases.push((label, h, franka_step_response(h, true, delta, per)));
    }
    for (label, h, rows) in &cases {
        let (e, o, t) = worst(rows);
        println!(
            "dt {h:.5} s, {label}: worst error {e:.5} rad (tol 0.01), overshoot {:.2} % (tol 10 %), settling {t:.3} s (tol 1 s)",
            o * 100.0
        );
        assert!(t < 1.0, "dt {h}, {label}: not settled within 1 s");
        assert!(
            e <= 0.01,
            "dt {h}, {label}: steady-state error {e} rad > 0.01"
        );
        assert!(o <= 0.10, "dt {h}, {label}: overshoot {o} > 10 %");
    }
}

#[test]
fn franka_holonomic_base_tracks_velocity() {
    let dt = common::dt("franka");
    let (mut ctx, spec, robot) = common::spawn("franka");
    let [x, y, yaw] = spec.base_joints.clone().unwrap();
    let base = HolonomicBase::new(&robot, &x, &y, &yaw).unwrap();
    let mut ctl = JointController::hold_current(&robot, &ctx).unwrap();
    let cmds = [
        BaseVelocity {
            vx: 0.5,
            vy: 0.0,
            wz: 0.0,
        },
        BaseVelocity {
            vx: 0.0,
            vy: -0.5,
            wz: 0.0,
        },
        BaseVelocity {
            vx: 0.3,
            vy: 0.2,
            wz: 1.0,
        },
        BaseVelocity {
            vx: -0.4,
            vy: 0.3,
            wz: -0.6,
        },
    ];
    let mut worst = 0.0f64;
    for cmd in cmds {
        // 1 s to accelerate, then the mean over 1 s.
        let mut sum = [0.0; 3];
        let n = (1.0 / dt).round() as usize;
        for k in 0..2 * n {
            base.command(&robot, &ctx, &mut ctl, cmd).unwrap();
            ctl.apply(&robot, &mut ctx).unwrap();
            ctx.step(dt).unwrap();
            if k >= n {
                let m = base.measured(&robot, &ctx).unwrap();
                sum[0] += m.vx;
                sum[1] += m.vy;
                sum[2] += m.wz;
            }
        }
        let mean = [sum[0] / n as f64, sum[1] / n as f64, sum[2] / n as f64];
        let want = [cmd.vx, cmd.vy, cmd.wz];
        let scale = want.iter().map(|v| v.abs()).fold(0.0, f64::max);
        let rel = (0..3)
            .map(|i| (mean[i] - want[i]).abs() / scale)
            .fold(0.0, f64::max);
        println!(
            "command (vx, vy, wz) = ({:+.2}, {:+.2}, {:+.2}) -> measured ({:+.4}, {:+.4}, {:+.4}); error {:.3} % of the command (tol 5 %)",
            want[0], want[1], want[2], mean[0], mean[1], mean[2], rel * 100.0
        );
        worst = worst.max(rel);
    }
    assert!(worst <= 0.05, "base velocity error {worst}");
    // The arm kept its pose while the base moved.
    let arm = spec.indices(&robot, &spec.arm_joints).unwrap();
    let q = robot.joint_positions(&ctx).unwrap();
    let mut arm_err = 0.0f64;
    for &i in &arm {
        if let modesuite_robots::JointCommand::Position(t) = ctl.commands[i] {
            arm_err = arm_err.max((q[i] - t).abs());
        }
    }
    println!("arm joint error while driving: {arm_err:.5} rad (tol 0.01)");
    assert!(arm_err <= 0.01);
}

#[test]
fn spot_stands_on_its_legs() {
    let dt = common::dt("spot");
    let (mut ctx, spec, robot) = common::spawn("spot");
    // Floor: a fixed box whose top is z = 0.
    let floor = ctx.bodies.insert(
        RigidBodyBuilder::fixed().translation(vec_to_rapier(&Vector3::new(0.0, 0.0, -0.5))),
    );
    ctx.colliders.insert_with_parent(
        ColliderBuilder::cuboid(10.0, 10.0, 0.5)
            .friction(0.8)
            .build(),
        floor,
        &mut ctx.bodies,
    );
    let mut ctl = JointController::hold_current(&robot, &ctx).unwrap();
    ctl.gains = spec.default_gains(&robot);
    let z0 = robot.body_pose(&ctx, 0).unwrap().translation.z;
    let steps = (3.0 / dt).round() as usize;
    for _ in 0..steps {
        ctl.apply(&robot, &mut ctx).unwrap();
        ctx.step(dt).unwrap();
    }
    let pose: Isometry3<f64> = robot.body_pose(&ctx, 0).unwrap();
    let (roll, pitch, _) = pose.rotation.euler_angles();
    let drift = (pose.translation.vector.xy()).norm();
    println!(
        "spot after 3 s standing: body z {:.4} m (spawned {z0:.4}, tol 0.55 +- 0.03), roll {roll:.4}, pitch {pitch:.4} rad (tol 0.05), xy drift {drift:.4} m (tol 0.05)",
        pose.translation.z
    );
    assert!((pose.translation.z - 0.55).abs() <= 0.03);
    assert!(roll.abs() <= 0.05 && pitch.abs() <= 0.05);
    assert!(drift <= 0.05);
}

#[test]
fn franka_gripper_mimic_fingers_close_together() {
    let dt = common::dt("franka");
    let (mut ctx, spec, robot) = common::spawn("franka");
    let f1 = robot.joint_index(&spec.gripper_joints[0]).unwrap();
    let f2 = robot.joint_index(&spec.gripper_joints[1]).unwrap();
    let mut ctl = JointController::hold_current(&robot, &ctx).unwrap();
    // Only the leading finger is commanded; the mimic finger follows it.
    ctl.set_position(&robot, f1, spec.gripper_open_closed.1)
        .unwrap();
    let mut worst_gap = 0.0f64;
    for _ in 0..(0.5 / dt).round() as usize {
        ctl.apply(&robot, &mut ctx).unwrap();
        ctx.step(dt).unwrap();
        let q = robot.joint_positions(&ctx).unwrap();
        worst_gap = worst_gap.max((q[f1] - q[f2]).abs());
    }
    let q = robot.joint_positions(&ctx).unwrap();
    println!(
        "gripper after 0.5 s closing from 0.04 m: fingers {:.5} / {:.5} m (tol 0.001 of 0), largest finger mismatch on the way {worst_gap:.5} m (tol 0.002)",
        q[f1], q[f2]
    );
    assert!(q[f1].abs() <= 1e-3 && q[f2].abs() <= 1e-3);
    assert!(worst_gap <= 2e-3);
}
