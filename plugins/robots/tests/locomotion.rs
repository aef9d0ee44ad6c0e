//! Spot walking on its legs with the trot controller: leg kinematics against the simulated
//! robot, forward walking speed, turning in place, sideways walking, stopping, 60 s of random
//! commands with the arm moving and a 20 N pull on the gripper, determinism, and (ignored,
//! release) the simulation speed of walking Spot.

mod common;

use modesuite_engine::deps::nalgebra::{Isometry3, Vector3};
use modesuite_engine::deps::rapier3d::prelude::{ColliderBuilder, RigidBodyBuilder};
use modesuite_engine::math::vec_to_rapier;
use modesuite_engine::rng::EnvRng;
use modesuite_engine::RigidContext;
use modesuite_robots::{
    BaseVelocity, JointController, Robot, RobotSpec, TrotController, TrotParams,
};

/// Control period: 60 Hz.
const CONTROL_DT: f64 = 1.0 / 60.0;

/// Rapier settings a walking Spot runs with: substeps per 1/60 s step and Gauss-Seidel sweeps
/// per substep (`physics.substeps`, `physics.rigid_pgs_iterations`).
#[derive(Debug, Clone, Copy)]
struct Rapier {
    substeps: usize,
    pgs: u32,
}

impl Rapier {
    /// Spot alone (`RobotSpec::substeps`, `RobotSpec::pgs_iterations`: 1 substep of 1/60 s, 24
    /// sweeps): robot-only scenes and `bench robots`.
    fn alone() -> Self {
        let spec = common::spec("spot");
        Self {
            substeps: spec.substeps as usize,
            pgs: spec.pgs_iterations,
        }
    }

    /// Spot stepping with a deformable at 1/120 s (`substeps: 2`). No shipped task scene uses it
    /// since their deformables take their own finer steps (`deformable_substeps`), but a scene
    /// may, so it stays validated.
    const MEDIUM: Self = Self {
        substeps: 2,
        pgs: 8,
    };

    /// Spot stepping with a deformable at 1/240 s (`substeps: 4`), as MEDIUM.
    const FINE: Self = Self {
        substeps: 4,
        pgs: 4,
    };

    /// Every setting validated for a walking Spot, for the validation rows.
    fn all() -> [Self; 3] {
        [Self::alone(), Self::MEDIUM, Self::FINE]
    }

    fn dt(&self) -> f64 {
        CONTROL_DT / self.substeps as f64
    }
}

impl std::fmt::Display for Rapier {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "[{} substeps, {} sweeps]", self.substeps, self.pgs)
    }
}

/// Spot on a flat floor (a fixed box with friction 0.8 whose top is z = 0), with a joint
/// controller holding the home pose and a trot controller.
struct Walker {
    ctx: RigidContext,
    spec: RobotSpec,
    robot: Robot,
    ctl: JointController,
    trot: TrotController,
    rapier: Rapier,
    /// Control steps done.
    steps: usize,
}

/// Base state sampled for the measurements.
#[derive(Debug, Clone, Copy)]
struct BaseSample {
    pos: Vector3<f64>,
    roll: f64,
    pitch: f64,
    yaw: f64,
}

fn euler(pose: &Isometry3<f64>) -> (f64, f64, f64) {
    pose.rotation.euler_angles()
}

impl Walker {
    fn new(params: TrotParams, rapier: Rapier) -> Self {
        let (spec, model) = common::model("spot");
        let mut ctx = common::rapier_context(rapier.pgs);
        let robot = spec
            .spawn(&mut ctx, &model, Isometry3::identity())
            .expect("spot spawns");
        let floor = ctx.bodies.insert(
            RigidBodyBuilder::fixed().translation(vec_to_rapier(&Vector3::new(0.0, 0.0, -0.5))),
        );
        ctx.colliders.insert_with_parent(
            ColliderBuilder::cuboid(50.0, 50.0, 0.5)
                .friction(0.8)
                .build(),
            floor,
            &mut ctx.bodies,
        );
        let mut ctl = JointController::hold_current(&robot, &ctx).unwrap();
        ctl.gains = spec.default_gains(&robot);
        let trot = TrotController::new(&robot, &model, &spec, params).expect("trot controller");
        Self {
            ctx,
            spec,
            robot,
            ctl,
            trot,
            rapier,
            steps: 0,
        }
    }

    fn base(&self) -> BaseSample {
        let pose = self.robot.body_pose(&self.ctx, 0).unwrap();
        let (roll, pitch, yaw) = euler(&pose);
        BaseSample {
            pos: pose.translation.vector,
            roll,
            pitch,
            yaw,
        }
    }

    /// One control step: substeps of the trot controller, joint control and physics, as the
    /// engine runs them (`robot_control` every substep). `each_substep` runs after the joint
    /// controller (which clears the robot's forces) and before the physics step, to add
    /// external forces; `worst` tracks the lowest body height and the largest |roll| and
    /// |pitch| over the substeps.
    fn control_step(
        &mut self,
        cmd: BaseVelocity,
        mut each_substep: impl FnMut(&Robot, &mut RigidContext),
        worst: &mut Worst,
    ) {
        let dt = self.rapier.dt();
        for _ in 0..self.rapier.substeps {
            self.trot
                .step(&self.robot, &self.ctx, cmd, dt, &mut self.ctl)
                .unwrap();
            self.ctl.apply(&self.robot, &mut self.ctx).unwrap();
            each_substep(&self.robot, &mut self.ctx);
            self.ctx.step(dt).unwrap();
            worst.add(&self.base());
        }
        self.steps += 1;
    }

    fn run(&mut self, cmd: BaseVelocity, seconds: f64, worst: &mut Worst) {
        let n = (seconds / CONTROL_DT).round() as usize;
        for _ in 0..n {
            self.control_step(cmd, |_, _| {}, worst);
        }
    }
}

/// Extremes of the base state.
#[derive(Debug, Clone, Copy)]
struct Worst {
    min_z: f64,
    max_z: f64,
    max_roll: f64,
    max_pitch: f64,
}

impl Worst {
    fn new() -> Self {
        Self {
            min_z: f64::INFINITY,
            max_z: f64::NEG_INFINITY,
            max_roll: 0.0,
            max_pitch: 0.0,
        }
    }

    fn add(&mut self, b: &BaseSample) {
        self.min_z = self.min_z.min(b.pos.z);
        self.max_z = self.max_z.max(b.pos.z);
        self.max_roll = self.max_roll.max(b.roll.abs());
        self.max_pitch = self.max_pitch.max(b.pitch.abs());
    }
}

fn unwrap_angle(prev: f64, now: f64) -> f64 {
    let mut d = now - prev;
    while d > std::f64::consts::PI {
        d -= std::f64::consts::TAU;
    }
    while d < -std::f64::consts::PI {
        d += std::f64::consts::TAU;
    }
    d
}

/// Walks with a constant command: `ramp` seconds to get going, then a measurement window of
/// `window` seconds. Returns the mean velocity over the window in the frame of the heading at
/// the window's start (forward, left, yaw rate), the xy displacement over the window, and the
/// extremes of the base state over the window.
fn walk_constant(
    rapier: Rapier,
    cmd: BaseVelocity,
    ramp: f64,
    window: f64,
) -> ([f64; 3], f64, Worst) {
    let mut w = Walker::new(TrotParams::default(), rapier);
    let mut worst_ramp = Worst::new();
    w.run(cmd, ramp, &mut worst_ramp);
    let start = w.base();
    let mut worst = Worst::new();
    let n = (window / CONTROL_DT).round() as usize;
    let mut yaw = start.yaw;
    let mut yaw_total = 0.0;
    for _ in 0..n {
        w.control_step(cmd, |_, _| {}, &mut worst);
        let b = w.base();
        yaw_total += unwrap_angle(yaw, b.yaw);
        yaw = b.yaw;
    }
    let end = w.base();
    let d = end.pos - start.pos;
    let (s, c) = start.yaw.sin_cos();
    // Displacement in the starting heading frame; for a turning robot the chord is not the
    // path, but the turning test only looks at the yaw rate and the drift.
    let fwd = c * d.x + s * d.y;
    let left = -s * d.x + c * d.y;
    (
        [fwd / window, left / window, yaw_total / window],
        d.xy().norm(),
        worst,
    )
}

#[test]
fn leg_kinematics_match_the_simulated_robot() {
    let (spec, model) = common::model("spot");
    let mut ctx = RigidContext::new();
    let robot = spec.spawn(&mut ctx, &model, Isometry3::identity()).unwrap();
    let trot = TrotController::new(&robot, &model, &spec, TrotParams::default()).unwrap();
    let feet = ["fl_foot", "fr_foot", "hl_foot", "hr_foot"];
    let mut rng = EnvRng::from_seed(7);
    let mut worst_fk = 0.0f64;
    let mut worst_ik = 0.0f64;
    let mut worst_q = 0.0f64;
    let mut compared = 0;
    let trials = 200;
    for _ in 0..trials {
        let mut q = robot.joint_positions(&ctx).unwrap();
        let mut legs_q = [[0.0; 3]; 4];
        for (l, kin) in trot.legs().iter().enumerate() {
            for (k, slot) in legs_q[l].iter_mut().enumerate() {
                // Stay a little inside the limits.
                let (lo, hi) = (kin.lower[k] + 0.05, kin.upper[k] - 0.05);
                let v = rng.range(lo, hi);
                *slot = v;
                let name = spec.leg_joints[3 * l + k].as_str();
                q[robot.joint_index(name).unwrap()] = v;
            }
        }
        robot.set_joint_positions(&mut ctx, &q).unwrap();
        let base = robot.body_pose(&ctx, 0).unwrap();
        for (l, kin) in trot.legs().iter().enumerate() {
            // Forward kinematics against rapier's foot frame (f32 poses).
            let sim = base.inverse()
                * robot
                    .frame_pose(&ctx, robot.frame_index(feet[l]).unwrap())
                    .unwrap();
            let fk = kin.forward(legs_q[l]);
            worst_fk = worst_fk.max((sim.translation.vector - fk).norm());
            // Inverse kinematics round trip.
            let (qi, reachable) = kin.inverse(&fk);
            assert!(reachable);
            worst_ik = worst_ik.max((kin.forward(qi) - fk).norm());
            // Joint positions are unique when the foot is below the hip in the leg's plane
            // (the solver's branch; the knee's other branch is outside its limits).
            let d = fk - kin.hip;
            let (s, c) = legs_q[l][0].sin_cos();
            if -d.y * s + d.z * c < 0.0 {
                compared += 1;
                for k in 0..3 {
                    worst_q = worst_q.max((qi[k] - legs_q[l][k]).abs());
                }
            }
        }
    }
    println!(
        "{} random leg configurations x 4 legs: forward kinematics vs rapier foot frame {:.2e} m (tol 1e-5, f32 poses); IK round trip foot error {:.2e} m (tol 1e-9), joint error {:.2e} rad (tol 1e-7) over the {compared} with the foot below the hip",
        trials, worst_fk, worst_ik, worst_q
    );
    assert!(worst_fk < 1e-5);
    assert!(worst_ik < 1e-9);
    assert!(worst_q < 1e-7 && compared > trials);
    // The standing pose is the controller's nominal stance.
    let kin = trot.legs()[0];
    let (qs, _) = kin.inverse(&kin.nominal_foot(0.55));
    println!(
        "nominal stance at 0.55 m: hx {:.4}, hy {:.4}, kn {:.4} rad (model home hy 0.77, kn -1.43)",
        qs[0], qs[1], qs[2]
    );
    assert!((qs[1] - 0.77).abs() < 0.02 && (qs[2] + 1.43).abs() < 0.02);
}

#[test]
fn spot_walks_forward_at_half_a_metre_per_second() {
    let cmd = BaseVelocity {
        vx: 0.5,
        vy: 0.0,
        wz: 0.0,
    };
    for rapier in Rapier::all() {
        let (v, _, worst) = walk_constant(rapier, cmd, 2.0, 4.0);
        let err = (v[0] - 0.5).abs() / 0.5;
        println!(
            "{rapier} command vx 0.5 m/s; mean over 4 s after a 2 s ramp: forward {:.4} m/s (error {:.1} %, tol 20 %), lateral {:+.4} m/s (tol 0.1), yaw rate {:+.4} rad/s (tol 0.1)",
            v[0],
            err * 100.0,
            v[1],
            v[2]
        );
        println!(
            "{rapier} body height {:.4}..{:.4} m (tol 0.45..0.65), max |roll| {:.4}, max |pitch| {:.4} rad (tol 0.15)",
            worst.min_z, worst.max_z, worst.max_roll, worst.max_pitch
        );
        assert!(err <= 0.2, "{rapier} forward speed {} m/s", v[0]);
        assert!(v[1].abs() <= 0.1 && v[2].abs() <= 0.1);
        assert!(worst.min_z >= 0.45 && worst.max_z <= 0.65);
        assert!(worst.max_roll <= 0.15 && worst.max_pitch <= 0.15);
    }
}

#[test]
fn spot_turns_in_place() {
    let wz = 0.8;
    let cmd = BaseVelocity {
        vx: 0.0,
        vy: 0.0,
        wz,
    };
    for rapier in Rapier::all() {
        let (v, drift, worst) = walk_constant(rapier, cmd, 2.0, 4.0);
        let err = (v[2] - wz).abs() / wz;
        println!(
            "{rapier} command wz {wz} rad/s; mean over 4 s after a 2 s ramp: yaw rate {:.4} rad/s (error {:.1} %, tol 20 %), xy drift {:.4} m in 4 s (tol 0.3)",
            v[2],
            err * 100.0,
            drift
        );
        println!(
            "{rapier} body height {:.4}..{:.4} m, max |roll| {:.4}, max |pitch| {:.4} rad (tol 0.15)",
            worst.min_z, worst.max_z, worst.max_roll, worst.max_pitch
        );
        assert!(err <= 0.2, "{rapier} yaw rate {} rad/s", v[2]);
        assert!(drift <= 0.3);
        assert!(worst.max_roll <= 0.15 && worst.max_pitch <= 0.15);
    }
}

#[test]
fn spot_walks_sideways_and_stops() {
    for rapier in Rapier::all() {
        let cmd = BaseVelocity {
            vx: 0.0,
            vy: 0.3,
            wz: 0.0,
        };
        let (v, _, worst) = walk_constant(rapier, cmd, 2.0, 4.0);
        let err = (v[1] - 0.3).abs() / 0.3;
        println!(
            "{rapier} command vy 0.3 m/s; mean over 4 s after a 2 s ramp: lateral {:.4} m/s (error {:.1} %, tol 25 %), forward {:+.4} m/s (tol 0.1), yaw rate {:+.4} rad/s (tol 0.1); max |roll| {:.4}, max |pitch| {:.4} rad",
            v[1],
            err * 100.0,
            v[0],
            v[2],
            worst.max_roll,
            worst.max_pitch
        );
        assert!(err <= 0.25, "{rapier} lateral speed {} m/s", v[1]);
        assert!(v[0].abs() <= 0.1 && v[2].abs() <= 0.1);

        // Walk forward, then a zero command: the legs stop stepping and the body comes to rest.
        // rapier's default solves friction only in the unbiased pass of a substep; planted
        // multibody feet then creep about 1.5 cm/s even with the joints simply held (no trot
        // controller). With friction in the bias pass as well they do not, so the creep of a
        // standing robot is measured with that setting.
        let mut w = Walker::new(TrotParams::default(), rapier);
        w.ctx.params.friction_in_bias_pass = true;
        let mut worst = Worst::new();
        w.run(
            BaseVelocity {
                vx: 0.4,
                vy: 0.0,
                wz: 0.3,
            },
            2.0,
            &mut worst,
        );
        assert!(w.trot.stepping());
        let zero = BaseVelocity::default();
        let mut stopped_after = None;
        for k in 0..(3.0 / CONTROL_DT) as usize {
            w.control_step(zero, |_, _| {}, &mut worst);
            if stopped_after.is_none() && !w.trot.stepping() {
                stopped_after = Some((k + 1) as f64 * CONTROL_DT);
            }
        }
        let before = w.base();
        w.run(zero, 1.0, &mut worst);
        let after = w.base();
        let creep = (after.pos - before.pos).xy().norm();
        println!(
            "{rapier} zero command after walking: stepping stopped after {:?} s (tol 2 s); body moved {creep:.5} m in the following 1 s (tol 0.01); still standing: {}",
            stopped_after,
            !w.trot.stepping()
        );
        assert!(stopped_after.is_some_and(|t| t <= 2.0));
        assert!(!w.trot.stepping());
        assert!(creep <= 0.01);
    }
}

/// Sinusoidal arm motion around a raised pose, blended in from the stowed pose over 2 s.
fn arm_targets(home: &[f64; 6], t: f64) -> [f64; 6] {
    let centre = [0.0, -1.2, 2.0, 0.0, -0.4, 0.0];
    let amp = [0.6, 0.4, 0.5, 0.8, 0.6, 1.0];
    let freq = [0.21, 0.33, 0.27, 0.41, 0.37, 0.5];
    let blend = (t / 2.0).min(1.0);
    let mut out = [0.0; 6];
    for k in 0..6 {
        let moving = centre[k] + amp[k] * (std::f64::consts::TAU * freq[k] * t + k as f64).sin();
        out[k] = home[k] + (moving - home[k]) * blend;
    }
    out
}

/// Result of a random-command run.
struct RandomRun {
    worst: Worst,
    segments: usize,
    distance: f64,
    q: Vec<f64>,
    base: Isometry3<f64>,
}

/// `seconds` of random piecewise-constant commands (held 1 to 3 s; one in six is zero) from a
/// seeded generator, optionally with the arm moving, and a `pull` N force in a random direction
/// (per segment) on the gripper.
fn random_commands(
    rapier: Rapier,
    seed: u64,
    seconds: f64,
    pull: f64,
    arm_moving: bool,
) -> RandomRun {
    let mut w = Walker::new(TrotParams::default(), rapier);
    let mut rng = EnvRng::from_seed(seed);
    let arm = w.spec.indices(&w.robot, &w.spec.arm_joints).unwrap();
    let q0 = w.robot.joint_positions(&w.ctx).unwrap();
    let home: [f64; 6] = std::array::from_fn(|k| q0[arm[k]]);
    let tool = w.robot.frame_index(&w.spec.ee_frame).unwrap();
    let gripper = w.robot.bodies[w.robot.frames[tool].body].handle;
    let mut worst = Worst::new();
    let n = (seconds / CONTROL_DT).round() as usize;
    let mut next_change = 0usize;
    let mut cmd = BaseVelocity::default();
    let mut force = Vector3::zeros();
    let mut segments = 0;
    let mut distance = 0.0;
    let mut last = w.base().pos;
    for s in 0..n {
        if s == next_change {
            segments += 1;
            next_change = s + (rng.range(1.0, 3.0) / CONTROL_DT).round() as usize;
            cmd = if rng.below(6) == 0 {
                BaseVelocity::default()
            } else {
                BaseVelocity {
                    vx: rng.range(-0.5, 0.5),
                    vy: rng.range(-0.5, 0.5),
                    wz: rng.range(-1.0, 1.0),
                }
            };
            // A random direction, not pointing steeply up.
            let dir = loop {
                let d = Vector3::new(rng.normal(), rng.normal(), rng.normal());
                let d = d / d.norm();
                if d.z < 0.5 {
                    break d;
                }
            };
            force = dir * pull;
        }
        let t = s as f64 * CONTROL_DT;
        let qa = if arm_moving {
            arm_targets(&home, t)
        } else {
            home
        };
        for k in 0..6 {
            w.ctl.set_position(&w.robot, arm[k], qa[k]).unwrap();
        }
        w.control_step(
            cmd,
            |robot, ctx| {
                let at = robot.frame_pose(ctx, tool).unwrap().translation.vector;
                ctx.bodies[gripper].add_force_at_point(
                    vec_to_rapier(&force),
                    vec_to_rapier(&at),
                    true,
                );
            },
            &mut worst,
        );
        let p = w.base().pos;
        distance += (p - last).xy().norm();
        last = p;
    }
    RandomRun {
        worst,
        segments,
        distance,
        q: w.robot.joint_positions(&w.ctx).unwrap(),
        base: w.robot.body_pose(&w.ctx, 0).unwrap(),
    }
}

/// The full demand of VALIDATION.md: 60 s of random commands (held 1 to 3 s) with the arm
/// sweeping and a 20 N pull in a random direction on the gripper; the body never falls (lowest
/// 0.3 m, |roll| and |pitch| below 0.6 rad). Three seeds; two more were checked by hand (seed
/// 11: |roll| 0.29 rad, seed 99: 0.24; seed 42's 0.42 is the largest of the five). The level
/// stance of the trot controller is what holds roll (see the locomotion module's notes).
#[test]
fn spot_does_not_fall_in_60_s_of_random_commands_with_arm_moving_and_a_pull() {
    for (rapier, seed) in Rapier::all()
        .into_iter()
        .flat_map(|r| [2026, 7, 42].map(|seed| (r, seed)))
    {
        let r = random_commands(rapier, seed, 60.0, 20.0, true);
        println!(
            "{rapier} seed {seed}: 60 s, {} random commands, arm moving, 20 N pull on the gripper: walked {:.2} m; lowest body {:.4} m (tol > 0.3), max |roll| {:.4} rad, max |pitch| {:.4} rad (tol < 0.6)",
            r.segments, r.distance, r.worst.min_z, r.worst.max_roll, r.worst.max_pitch
        );
        assert!(r.worst.min_z > 0.3, "seed {seed}: the body came down");
        assert!(
            r.worst.max_roll < 0.6 && r.worst.max_pitch < 0.6,
            "seed {seed}: tipped over"
        );
        assert!(r.distance > 5.0, "seed {seed}: the robot hardly moved");
    }
}

/// Random commands over the whole command range, arm stowed, no pull: the body stays level
/// (this run reached 0.83 rad of roll before the trot controller's level stance).
#[test]
fn spot_does_not_fall_in_20_s_of_random_commands() {
    for rapier in Rapier::all() {
        let r = random_commands(rapier, 2026, 20.0, 0.0, false);
        println!(
            "{rapier} 20 s, {} random commands (|vx|, |vy| <= 0.5 m/s, |wz| <= 1 rad/s), arm stowed, no pull: walked {:.2} m; lowest body {:.4} m (tol > 0.3), max |roll| {:.4} rad, max |pitch| {:.4} rad (tol < 0.6)",
            r.segments, r.distance, r.worst.min_z, r.worst.max_roll, r.worst.max_pitch
        );
        assert!(r.worst.min_z > 0.3);
        assert!(r.worst.max_roll < 0.6 && r.worst.max_pitch < 0.6);
        assert!(r.distance > 2.0, "the robot hardly moved");
    }
}

#[test]
fn walking_is_deterministic() {
    let a = random_commands(Rapier::alone(), 5, 4.0, 20.0, true);
    let b = random_commands(Rapier::alone(), 5, 4.0, 20.0, true);
    let same_q =
        a.q.iter()
            .zip(&b.q)
            .all(|(x, y)| x.to_bits() == y.to_bits());
    let same_base = a
        .base
        .translation
        .vector
        .iter()
        .chain(a.base.rotation.coords.iter())
        .zip(
            b.base
                .translation
                .vector
                .iter()
                .chain(b.base.rotation.coords.iter()),
        )
        .all(|(x, y)| x.to_bits() == y.to_bits());
    println!(
        "two identical 4 s runs (random commands, arm, pull): joint positions bit-identical: {same_q}, base pose bit-identical: {same_base} (walked {:.3} m)",
        a.distance
    );
    assert!(same_q && same_base);
}

/// Simulation speed of walking Spot alone: control steps of 1/60 s (its substeps, the trot and
/// joint controllers every substep) per second of wall time. Run in
/// release: `cargo test --release -p modesuite-robots --test locomotion -- --ignored --nocapture`.
#[test]
#[ignore]
fn walking_spot_steps_per_second() {
    let rapier = Rapier::alone();
    let mut w = Walker::new(TrotParams::default(), rapier);
    let dt = rapier.dt();
    let mut worst = Worst::new();
    let cmd = BaseVelocity {
        vx: 0.5,
        vy: 0.0,
        wz: 0.3,
    };
    w.run(cmd, 1.0, &mut worst);
    let n = 1200;
    let (mut t_trot, mut t_joint, mut t_physics) = (0.0, 0.0, 0.0);
    let t0 = std::time::Instant::now();
    for _ in 0..n {
        for _ in 0..rapier.substeps {
            let a = std::time::Instant::now();
            w.trot.step(&w.robot, &w.ctx, cmd, dt, &mut w.ctl).unwrap();
            t_trot += a.elapsed().as_secs_f64();
            let b = std::time::Instant::now();
            w.ctl.apply(&w.robot, &mut w.ctx).unwrap();
            let c = std::time::Instant::now();
            w.ctx.step(dt).unwrap();
            t_joint += (c - b).as_secs_f64();
            t_physics += c.elapsed().as_secs_f64();
        }
    }
    let secs = t0.elapsed().as_secs_f64();
    println!(
        "time split: trot controller {:.1} %, joint controller (PD + gravity compensation, every substep) {:.1} %, rapier step {:.1} %",
        100.0 * t_trot / secs,
        100.0 * t_joint / secs,
        100.0 * t_physics / secs
    );
    println!(
        "walking spot {rapier}: {n} control steps (dt 1/60 s) in {secs:.3} s = {:.0} control steps/s ({:.0} substeps/s), target >= 2000",
        n as f64 / secs,
        (rapier.substeps * n) as f64 / secs
    );
}
