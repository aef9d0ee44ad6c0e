//! Legged locomotion: a model-based trot that turns a body velocity command (vx, vy, wz) into
//! position targets of a quadruped's 12 leg joints (Spot: legs `fl`, `fr`, `hl`, `hr`, joints
//! hip roll `hx`, hip pitch `hy`, knee `kn`).
//!
//! # Design
//!
//! Everything is planned in the **level frame** H: origin at the base origin, z up (against
//! gravity), x along the body's heading (yaw of the base), no roll or pitch.
//!
//! - **Gait clock.** A phase in [0, 1) advances by `dt / period`. Diagonal pairs (fl, hr) and
//!   (fr, hl) are half a period apart; a leg swings for the first `swing_fraction` of its own
//!   phase and stands for the rest, so with `swing_fraction < 0.5` there is a short four-foot
//!   support between the pairs. With a zero command (and the body at rest, every foot back at its
//!   nominal place) the clock stops in a four-foot window and the robot stands; a non-zero command
//!   starts it again.
//! - **Command shaping.** The command is clamped to `max_command` and the tracked command moves
//!   towards it at most at `max_acceleration`.
//! - **Stance feet** move backwards in H as the ground moves under a body that travels at the
//!   commanded velocity: `p <- p - (v + wz x p) dt`. Stance legs therefore push the body at the
//!   command; nothing integrates the world position.
//! - **Velocity loop.** The stance feet's velocity is the command plus a bounded integral of
//!   the body velocity error (forward, lateral, yaw rate), so slip and leg compliance do not
//!   leave a steady tracking error.
//!   A stance starts where the foot really landed (forward kinematics at touchdown), and
//!   standing starts where the feet are, so the legs never push against each other.
//! - **Swing feet** lift off where their stance ended and follow a smooth curve (minimum-jerk in
//!   xy, `(1 - cos 2 pi s) / 2` in height) to a Raibert foot placement, recomputed every update:
//!   `nominal (rotated by wz t) + v t + k (v_measured - v)`, where `t` is the rest of the swing
//!   plus half a stance, so the foot lands ahead of the hip by half the stance travel.
//! - **Body stabilisation.** Stance foot heights get a correction from each hip's height error
//!   in H (its height change due to roll and pitch, with a damping term from the measured angular
//!   velocity) and an integral of the body height error (height measured from the stance feet by
//!   forward kinematics, so no floor is assumed). Stance legs lengthen under a low hip and shorten
//!   under a high one.
//! - **Level stance.** While stepping, stance foot targets are turned from H into the base frame
//!   as if the body were level (`stance_level` 1), so the leg joints pull a tilted body back to
//!   level; a robot standing on four feet uses the measured tilt (levelling there made the legs
//!   push against the planted feet). Solving stance legs with the measured roll made the legs
//!   follow the tilt: Spot's hips sit 5.5 cm either side of the roll axis, so the hip height
//!   term above hardly resists roll, and the body drifted to 0.8 rad of roll when turning fast
//!   with the arm moving (and rolled over under a 20 N pull). Measured over 60 s of random
//!   commands with the arm sweeping and a 20 N pull (seeds 2026, 7, 11, 42, 99): largest |roll|
//!   0.42 rad with a level stance, period 0.3 s and Raibert gain 0.25 s; falls on two seeds
//!   with the old (0.4 s, 0.15 s). kd 25 lowered that to 0.26 rad, but Spot then yielded
//!   sideways to the belt it holds in Lift.
//! - **Inverse kinematics.** Swing foot targets are turned from H into the base frame with the
//!   measured roll and pitch; all are solved by the analytic 3-DoF leg inverse kinematics of
//!   [`LegKinematics`] (hip roll, then a planar two-link hip pitch / knee chain). Joint target
//!   velocities come from the foot target velocities through the same inverse kinematics
//!   (finite difference).
//! - **Joint commands.** [`TrotController::write`] sets the leg gains and a position command
//!   `q + (kd / kp) qd` for each leg joint: a PD motor `kp (q_c - q) - kd q'` with that command is
//!   exactly `kp (q - q_meas) + kd (qd - q'_meas)`, PD with velocity feed-forward.
//!
//! The controller is meant to be updated at the control rate (60 Hz in the tests, every 4th
//! substep of 1/240 s) with the [`crate::JointController`] applied every substep; updating it
//! every substep works too (it only integrates with the `dt` it is given).
//!
//! State ([`TrotController`]) is plain data: clock, tracked command, foot targets, integrator. It
//! is `Clone + PartialEq` and deterministic (no randomness, no hashing, f64 only), so it goes into
//! snapshots as is.

use std::f64::consts::PI;

use modesuite_engine::deps::nalgebra::{UnitQuaternion, Vector2, Vector3};
use modesuite_engine::math::vec_from_rapier;
use modesuite_engine::RigidContext;

use crate::control::{BaseVelocity, JointController, JointGains};
use crate::error::RobotError;
pub use crate::gait::TrotParams;
use crate::models::RobotSpec;
use crate::robot::Robot;
use crate::urdf::{Geometry, JointDesc, UrdfModel};

/// Number of legs.
pub const NUM_LEGS: usize = 4;

/// Kinematics of one leg with a hip roll joint (axis x), a hip pitch joint (axis y) and a knee
/// (axis y), in the base frame. Read from the URDF by [`LegKinematics::from_model`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LegKinematics {
    /// Hip roll joint origin in the base frame, m.
    pub hip: Vector3<f64>,
    /// Hip pitch joint origin in the hip roll joint's child frame, m.
    pub hy_origin: Vector3<f64>,
    /// Knee origin (x, z) in the upper-leg frame (hip pitch child), m.
    pub knee: Vector2<f64>,
    /// Foot sphere centre (x, z) in the lower-leg frame (knee child), m.
    pub foot: Vector2<f64>,
    /// Foot sphere radius, m.
    pub foot_radius: f64,
    /// Lower joint limits (hx, hy, kn), rad.
    pub lower: [f64; 3],
    /// Upper joint limits (hx, hy, kn), rad.
    pub upper: [f64; 3],
}

/// Rotation about y of a point given as (x, z).
fn rot_y(angle: f64, x: f64, z: f64) -> (f64, f64) {
    let (s, c) = angle.sin_cos();
    (x * c + z * s, -x * s + z * c)
}

/// Wraps an angle into (-pi, pi].
fn wrap(a: f64) -> f64 {
    let w = (a + PI).rem_euclid(2.0 * PI) - PI;
    if w <= -PI {
        w + 2.0 * PI
    } else {
        w
    }
}

fn is_axis(axis: &Vector3<f64>, want: Vector3<f64>) -> bool {
    (axis - want).norm() < 1e-9
}

impl LegKinematics {
    /// Reads the leg whose joints are `joints = [hx, hy, kn]` from a URDF model: the hip roll
    /// joint must hang from the root link with axis +x, hip pitch and knee follow it with axes +y,
    /// joint frames unrotated, the knee and the foot in the leg's sagittal plane; the foot is the
    /// lowest sphere collision of the knee's child link.
    pub fn from_model(model: &UrdfModel, joints: [&str; 3]) -> Result<Self, RobotError> {
        let find = |name: &str| -> Result<&JointDesc, RobotError> {
            model
                .joints
                .iter()
                .find(|j| j.name == name)
                .ok_or_else(|| RobotError::Structure {
                    file: model.file.clone(),
                    message: format!("locomotion: leg joint `{name}` not in the model"),
                })
        };
        let [hx, hy, kn] = [find(joints[0])?, find(joints[1])?, find(joints[2])?];
        let bad = |j: &JointDesc, message: &str| RobotError::Joint {
            file: model.file.clone(),
            joint: j.name.clone(),
            message: format!("locomotion: {message}"),
        };
        if hx.parent != model.root {
            return Err(bad(hx, "the hip roll joint must hang from the root link"));
        }
        if hy.parent != hx.child || kn.parent != hy.child {
            return Err(bad(
                kn,
                "the leg joints must form a chain hip roll -> hip pitch -> knee",
            ));
        }
        for (j, want) in [(hx, Vector3::x()), (hy, Vector3::y()), (kn, Vector3::y())] {
            if !is_axis(&j.axis, want) {
                return Err(bad(j, &format!("axis must be {want:?}, got {:?}", j.axis)));
            }
            if j.origin.rotation.angle() > 1e-9 {
                return Err(bad(j, "joint origin must not be rotated"));
            }
        }
        let k = kn.origin.translation.vector;
        if k.y.abs() > 1e-9 {
            return Err(bad(kn, "knee origin must lie in the leg plane (y = 0)"));
        }
        let lleg = &model.links[kn.child];
        let (centre, radius) = lleg
            .collisions
            .iter()
            .filter_map(|c| match c.geometry {
                Geometry::Sphere { radius } => Some((c.origin.translation.vector, radius)),
                _ => None,
            })
            .min_by(|a, b| a.0.z.total_cmp(&b.0.z))
            .ok_or_else(|| bad(kn, "the lower leg has no sphere collision (foot)"))?;
        if centre.y.abs() > 1e-9 {
            return Err(bad(kn, "foot sphere must lie in the leg plane (y = 0)"));
        }
        Ok(Self {
            hip: hx.origin.translation.vector,
            hy_origin: hy.origin.translation.vector,
            knee: Vector2::new(k.x, k.z),
            foot: Vector2::new(centre.x, centre.z),
            foot_radius: radius,
            lower: [hx.lower, hy.lower, kn.lower],
            upper: [hx.upper, hy.upper, kn.upper],
        })
    }

    /// Foot sphere centre in the base frame for joint positions (hx, hy, kn).
    pub fn forward(&self, q: [f64; 3]) -> Vector3<f64> {
        let (ax, az) = rot_y(q[2], self.foot.x, self.foot.y);
        let (sx, sz) = rot_y(q[1], ax + self.knee.x, az + self.knee.y);
        let inner = self.hy_origin + Vector3::new(sx, 0.0, sz);
        let (s, c) = q[0].sin_cos();
        self.hip
            + Vector3::new(
                inner.x,
                inner.y * c - inner.z * s,
                inner.y * s + inner.z * c,
            )
    }

    /// Joint positions (hx, hy, kn) that put the foot sphere centre at `p` (base frame), knee
    /// on the branch inside the limits (or the nearer one). Targets out of reach are moved to the
    /// nearest reachable leg extension; the flag is false then. Results are not clamped to the
    /// joint limits.
    pub fn inverse(&self, p: &Vector3<f64>) -> ([f64; 3], bool) {
        let mut reachable = true;
        let d = p - self.hip;
        let o = self.hy_origin;
        // Hip roll: the point (o.y, zz) of the leg's plane rotates onto (d.y, d.z).
        let mut r2 = d.y * d.y + d.z * d.z - o.y * o.y;
        if r2 < 1e-6 {
            r2 = 1e-6;
            reachable = false;
        }
        let zz = -r2.sqrt();
        let hx = wrap(d.z.atan2(d.y) - zz.atan2(o.y));
        // Planar two-link chain in (x, z), written as complex numbers z + i x (a rotation about
        // y by a is a multiplication by e^{ia}).
        let sx = d.x - o.x;
        let sz = zz - o.z;
        let l1 = self.knee.norm();
        let l2 = self.foot.norm();
        let d2 = sx * sx + sz * sz;
        let mut c = (d2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
        if !(-1.0..=1.0).contains(&c) {
            c = c.clamp(-1.0, 1.0);
            reachable = false;
        }
        let gamma = self.foot.x.atan2(self.foot.y) - self.knee.x.atan2(self.knee.y);
        let violation = |q: f64| (self.lower[2] - q).max(q - self.upper[2]).max(0.0);
        let a = c.acos();
        let (k1, k2) = (wrap(-a - gamma), wrap(a - gamma));
        let kn = if violation(k2) < violation(k1) {
            k2
        } else {
            k1
        };
        // Leg vector with that knee, before the hip pitch rotation.
        let (ax, az) = rot_y(kn, self.foot.x, self.foot.y);
        let (ax, az) = (ax + self.knee.x, az + self.knee.y);
        let hy = wrap(sx.atan2(sz) - ax.atan2(az));
        ([hx, hy, kn], reachable)
    }

    /// Nominal foot centre in the base frame at a standing body height `height` (base origin
    /// above the ground): under the hip pitch joint, on the ground.
    pub fn nominal_foot(&self, height: f64) -> Vector3<f64> {
        Vector3::new(
            self.hip.x + self.hy_origin.x,
            self.hip.y + self.hy_origin.y,
            -(height - self.foot_radius),
        )
    }
}

/// Joint targets of the 12 leg joints, legs in the order of [`RobotSpec::leg_joints`]
/// (fl, fr, hl, hr; hx, hy, kn each).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LegTargets {
    /// Positions, rad.
    pub q: [f64; 12],
    /// Velocities, rad/s.
    pub qd: [f64; 12],
}

/// Per-leg state of the trot.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FootState {
    /// Foot centre target in the level frame H (relative to the base origin), m.
    pub target: Vector3<f64>,
    /// Where the current swing started (H), m.
    pub liftoff: Vector3<f64>,
    /// Whether the foot is swinging.
    pub swing: bool,
}

/// The trot controller of one quadruped. See the [module documentation](self).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrotController {
    params: TrotParams,
    legs: [LegKinematics; NUM_LEGS],
    /// Joint index (in [`Robot::joints`]) of each leg's hx, hy, kn.
    joints: [[usize; 3]; NUM_LEGS],
    /// Phase offset of each leg in the cycle.
    offsets: [f64; NUM_LEGS],
    phase: f64,
    stepping: bool,
    command: BaseVelocity,
    feet: [FootState; NUM_LEGS],
    height_integral: f64,
    velocity_integral: [f64; 3],
    last: Option<LegTargets>,
}

/// A command is treated as zero below this magnitude (m/s or rad/s).
const ZERO_COMMAND: f64 = 1e-3;

impl TrotController {
    /// A controller for the robot described by `spec` (its 12 `leg_joints`, three per leg in
    /// the order hx, hy, kn, legs front-left, front-right, hind-left, hind-right), reading the
    /// leg geometry from `model`. The feet start at their nominal standing places.
    pub fn new(
        robot: &Robot,
        model: &UrdfModel,
        spec: &RobotSpec,
        params: TrotParams,
    ) -> Result<Self, RobotError> {
        params.check().map_err(|message| RobotError::InvalidInput {
            robot: robot.name.clone(),
            message: format!("locomotion: {message}"),
        })?;
        if spec.leg_joints.len() != 3 * NUM_LEGS {
            return Err(RobotError::InvalidInput {
                robot: robot.name.clone(),
                message: format!(
                    "locomotion needs 12 leg joints, `{}` has {}",
                    spec.id,
                    spec.leg_joints.len()
                ),
            });
        }
        let mut legs = [None; NUM_LEGS];
        let mut joints = [[0usize; 3]; NUM_LEGS];
        for l in 0..NUM_LEGS {
            let names = [
                spec.leg_joints[3 * l].as_str(),
                spec.leg_joints[3 * l + 1].as_str(),
                spec.leg_joints[3 * l + 2].as_str(),
            ];
            legs[l] = Some(LegKinematics::from_model(model, names)?);
            for k in 0..3 {
                joints[l][k] = robot.joint_index(names[k])?;
            }
        }
        let legs = legs.map(|l| l.expect("every leg was read"));
        // Diagonal pairs: a front leg steps with the hind leg on the other side.
        let mut offsets = [0.0; NUM_LEGS];
        for l in 0..NUM_LEGS {
            let front = legs[l].hip.x > 0.0;
            let left = legs[l].hip.y > 0.0;
            offsets[l] = if front == left { 0.0 } else { 0.5 };
        }
        let feet = legs.map(|k| {
            let p = k.nominal_foot(params.body_height);
            FootState {
                target: p,
                liftoff: p,
                swing: false,
            }
        });
        Ok(Self {
            params,
            legs,
            joints,
            offsets,
            phase: 0.0,
            stepping: false,
            command: BaseVelocity::default(),
            feet,
            height_integral: 0.0,
            velocity_integral: [0.0; 3],
            last: None,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &TrotParams {
        &self.params
    }

    /// Leg kinematics (fl, fr, hl, hr).
    pub fn legs(&self) -> &[LegKinematics; NUM_LEGS] {
        &self.legs
    }

    /// Gait phase in [0, 1).
    pub fn phase(&self) -> f64 {
        self.phase
    }

    /// Whether the legs are stepping (false: standing on four feet).
    pub fn stepping(&self) -> bool {
        self.stepping
    }

    /// The tracked (clamped, acceleration-limited) command.
    pub fn command(&self) -> BaseVelocity {
        self.command
    }

    /// Foot states (fl, fr, hl, hr).
    pub fn feet(&self) -> &[FootState; NUM_LEGS] {
        &self.feet
    }

    /// The targets of the last update.
    pub fn last_targets(&self) -> Option<&LegTargets> {
        self.last.as_ref()
    }

    /// Advances the controller by `dt` seconds with the body velocity command `cmd` (base frame:
    /// forward, left, yaw rate) and returns the leg joint targets for the next `dt`. Reads the
    /// base pose and velocity and the leg joint positions from `ctx`.
    pub fn update(
        &mut self,
        robot: &Robot,
        ctx: &RigidContext,
        cmd: BaseVelocity,
        dt: f64,
    ) -> Result<LegTargets, RobotError> {
        let invalid = |message: String| RobotError::InvalidInput {
            robot: robot.name.clone(),
            message,
        };
        if !(dt.is_finite() && dt > 0.0) {
            return Err(invalid(format!("locomotion: dt must be > 0, got {dt}")));
        }
        if !(cmd.vx.is_finite() && cmd.vy.is_finite() && cmd.wz.is_finite()) {
            return Err(invalid("locomotion: command not finite".into()));
        }
        let p = self.params;
        // Measured base state, split into yaw and the roll/pitch part.
        let base = robot.body_pose(ctx, 0)?;
        let rb = ctx
            .bodies
            .get(robot.root())
            .ok_or_else(|| robot.stale("root body removed"))?;
        let m = base.rotation.to_rotation_matrix();
        let yaw = m[(1, 0)].atan2(m[(0, 0)]);
        let r_yaw = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
        let r_rp = r_yaw.inverse() * base.rotation;
        let v_meas = r_yaw.inverse_transform_vector(&vec_from_rapier(rb.linvel()));
        let w_meas = r_yaw.inverse_transform_vector(&vec_from_rapier(rb.angvel()));

        // Command shaping.
        let want = [
            cmd.vx.clamp(-p.max_command[0], p.max_command[0]),
            cmd.vy.clamp(-p.max_command[1], p.max_command[1]),
            cmd.wz.clamp(-p.max_command[2], p.max_command[2]),
        ];
        let mut c = [self.command.vx, self.command.vy, self.command.wz];
        for k in 0..3 {
            let step = p.max_acceleration[k] * dt;
            c[k] += (want[k] - c[k]).clamp(-step, step);
        }
        self.command = BaseVelocity {
            vx: c[0],
            vy: c[1],
            wz: c[2],
        };
        let v = Vector2::new(c[0], c[1]);
        let wz = c[2];
        let asked = want.iter().chain(&c).any(|x| x.abs() > ZERO_COMMAND);

        // Measured stance feet (forward kinematics) give the body height over the ground.
        let q = robot.joint_positions(ctx)?;
        let measured: [Vector3<f64>; NUM_LEGS] = std::array::from_fn(|l| {
            let jl = self.joints[l];
            r_rp * self.legs[l].forward([q[jl[0]], q[jl[1]], q[jl[2]]])
        });
        let mut h_sum = 0.0;
        let mut h_n = 0usize;
        for ((foot, kin), m) in self.feet.iter().zip(&self.legs).zip(&measured) {
            if !foot.swing {
                h_sum += -m.z + kin.foot_radius;
                h_n += 1;
            }
        }
        if h_n > 0 {
            let err = p.body_height - h_sum / h_n as f64;
            self.height_integral = (self.height_integral + p.height_integral_gain * err * dt)
                .clamp(-p.height_integral_limit, p.height_integral_limit);
        }

        // Gait clock.
        let near_nominal = (0..NUM_LEGS).all(|l| {
            let n = self.legs[l].nominal_foot(p.body_height);
            (self.feet[l].target.xy() - n.xy()).norm() < 0.03
        });
        if !self.stepping && asked {
            self.stepping = true;
            // Start at the next pair's lift-off.
            self.phase = if self.phase < 0.5 { 0.5 } else { 0.0 };
        } else if self.stepping {
            let stop = !asked && near_nominal && v_meas.xy().norm() < 0.1;
            let next = self.phase + dt / p.period;
            // The four-foot windows [swing_fraction, 0.5) and [0.5 + swing_fraction, 1) may be
            // shorter than one update: a stop that would step over the end of one ends just
            // inside it instead.
            let end = if self.phase < 0.5 { 0.5 } else { 1.0 };
            self.phase = if stop && next >= end {
                end - 1e-9
            } else {
                next.rem_euclid(1.0)
            };
            let all_stance = (0..NUM_LEGS)
                .all(|l| (self.phase + self.offsets[l]).rem_euclid(1.0) >= p.swing_fraction);
            if stop && all_stance {
                self.stepping = false;
                // Stand where the feet are: targets that disagree with the planted feet would
                // make the legs push against each other (and the feet creep).
                for (foot, m) in self.feet.iter_mut().zip(&measured) {
                    foot.target.x = m.x;
                    foot.target.y = m.y;
                }
            }
        }

        // Velocity loop: the stance feet move at the command plus an integral of the tracking
        // error (slip, leg compliance and an off-centre mass make the body drift otherwise).
        if self.stepping {
            let e = [v.x - v_meas.x, v.y - v_meas.y, wz - w_meas.z];
            for (k, ek) in e.iter().enumerate() {
                let lim = p.velocity_integral_limit[k];
                self.velocity_integral[k] = (self.velocity_integral[k]
                    + p.velocity_integral_gain * ek * dt)
                    .clamp(-lim, lim);
            }
        } else {
            self.velocity_integral = [0.0; 3];
        }
        let v_cmd = v;
        let v = v + Vector2::new(self.velocity_integral[0], self.velocity_integral[1]);
        let wz = wz + self.velocity_integral[2];

        let t_swing = p.period * p.swing_fraction;
        let t_stance = p.period - t_swing;
        let ground = -(p.body_height - self.legs[0].foot_radius);
        let mut targets = LegTargets {
            q: [0.0; 12],
            qd: [0.0; 12],
        };
        #[allow(clippy::needless_range_loop)] // several per-leg arrays, one borrowed mutably
        for l in 0..NUM_LEGS {
            let kin = self.legs[l];
            let nominal = kin.nominal_foot(p.body_height);
            let psi = (self.phase + self.offsets[l]).rem_euclid(1.0);
            let swing = self.stepping && psi < p.swing_fraction;
            let foot = &mut self.feet[l];
            if swing && !foot.swing {
                foot.liftoff = foot.target;
            }
            if !swing && foot.swing {
                // Touchdown: the stance starts where the foot landed.
                foot.target.x = measured[l].x;
                foot.target.y = measured[l].y;
            }
            foot.swing = swing;
            let (pos, vel) = if swing {
                let s = psi / p.swing_fraction;
                let t_pred = (1.0 - s) * t_swing + 0.5 * t_stance;
                // Raibert placement with yaw: the nominal place rotated by the yaw to come.
                let (sn, cs) = (wz * t_pred).sin_cos();
                let n = Vector2::new(
                    cs * nominal.x - sn * nominal.y,
                    sn * nominal.x + cs * nominal.y,
                );
                let mut td = n + v * t_pred + p.raibert_gain * (v_meas.xy() - v_cmd);
                let off = td - nominal.xy();
                if off.norm() > p.max_foot_offset {
                    td = nominal.xy() + off * (p.max_foot_offset / off.norm());
                }
                let lo = foot.liftoff.xy();
                let blend = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
                let dblend = 30.0 * s * s * (1.0 - s) * (1.0 - s) / t_swing;
                let xy = lo + (td - lo) * blend;
                let lift = 0.5 * (1.0 - (2.0 * PI * s).cos());
                let dlift = PI * (2.0 * PI * s).sin() / t_swing;
                let pos = Vector3::new(xy.x, xy.y, ground + p.step_height * lift);
                let d = (td - lo) * dblend;
                (pos, Vector3::new(d.x, d.y, p.step_height * dlift))
            } else {
                let xy = foot.target.xy();
                let vel = -(v + wz * Vector2::new(-xy.y, xy.x));
                let xy = xy + vel * dt;
                (
                    Vector3::new(xy.x, xy.y, ground),
                    Vector3::new(vel.x, vel.y, 0.0),
                )
            };
            foot.target = pos;
            // Stabilisation of stance legs: hip height error from roll/pitch, its rate, and the
            // height integral.
            let mut aim = pos;
            if !swing {
                let hip_h = r_rp * kin.hip;
                let hip_rate = w_meas.cross(&hip_h).z;
                aim.z += p.attitude_gain * (hip_h.z - kin.hip.z) + p.attitude_damping * hip_rate
                    - self.height_integral;
            }
            // Into the base frame and through the inverse kinematics (stance legs with the
            // body levelled by `stance_level` while stepping; standing on four feet holds roll
            // by itself, and levelling there made the body creep 7 cm in 1 s after a stop).
            let level = if self.stepping { p.stance_level } else { 0.0 };
            let r_ik = if swing || level == 0.0 {
                r_rp
            } else {
                r_rp.powf(1.0 - level)
            };
            let aim_b = r_ik.inverse_transform_vector(&aim);
            let vel_b = r_ik.inverse_transform_vector(&vel);
            let (qa, _) = kin.inverse(&aim_b);
            let eps = 1e-3;
            let (qb, _) = kin.inverse(&(aim_b + vel_b * eps));
            for k in 0..3 {
                targets.q[3 * l + k] = qa[k].clamp(kin.lower[k], kin.upper[k]);
                targets.qd[3 * l + k] = wrap(qb[k] - qa[k]) / eps;
            }
        }
        self.last = Some(targets);
        Ok(targets)
    }

    /// Writes `targets` into a joint controller: leg gains `kp`, `kd` of the parameters and a
    /// position command `q + (kd / kp + h) qd` per leg joint, `h` = `motor_dt`, the rigid step
    /// the motors act over (`h` = 0 with `implicit_damping_lead: false`): PD with velocity
    /// feed-forward through a position-only motor.
    /// Rapier's spring motor is implicit: over a step `h` it applies `kp (q_c - q - h v') - kd v'`
    /// with the step's end velocity `v'`, i.e. damping `kd + kp h`; the lead `(kd + kp h) / kp`
    /// makes that `kp (q - q_meas) + (kd + kp h) (qd - v')`, which tracks a moving target
    /// without the lag of the extra damping (at 1/120 s, `kp h` is 6.7 N m s/rad beside kd 15).
    pub fn write(
        &self,
        targets: &LegTargets,
        robot: &Robot,
        controller: &mut JointController,
        motor_dt: f64,
    ) -> Result<(), RobotError> {
        let h = if self.params.implicit_damping_lead {
            motor_dt
        } else {
            0.0
        };
        let lead = self.params.kd / self.params.kp + h;
        for l in 0..NUM_LEGS {
            for k in 0..3 {
                let j = self.joints[l][k];
                let i = 3 * l + k;
                if let Some(g) = controller.gains.get_mut(j) {
                    *g = JointGains::Absolute {
                        kp: self.params.kp,
                        kd: self.params.kd,
                    };
                }
                controller.set_position(robot, j, targets.q[i] + lead * targets.qd[i])?;
            }
        }
        Ok(())
    }

    /// [`TrotController::update`] then [`TrotController::write`], with `dt` both the update's
    /// interval and the motors' step (the engine updates the controller every rigid substep).
    pub fn step(
        &mut self,
        robot: &Robot,
        ctx: &RigidContext,
        cmd: BaseVelocity,
        dt: f64,
        controller: &mut JointController,
    ) -> Result<LegTargets, RobotError> {
        let t = self.update(robot, ctx, cmd, dt)?;
        self.write(&t, robot, controller, dt)?;
        Ok(t)
    }
}
