//! Policies for `modesuite run --policy`: `zero`, `random` (uniform over the action space, its
//! own seeded RNG) and `scripted` (the task's expert, named by the task section's `expert`).
//!
//! Experts read the task's state the way a privileged teacher would: [`TaskPoints`] (named
//! points and targets), the robot's [`RobotObservation`]
//! and controller targets, and write actions in the robot's configured action modes.

use std::collections::BTreeMap;
use std::sync::Arc;

use bevy_ecs::prelude::Resource;
use modesuite_engine::registry::insert_unique;
use modesuite_engine::rng::EnvRng;
use modesuite_engine::{Env, RigidContext, SimApp, SimSettings, Space};
use modesuite_robots::{
    ActionModes, ArmMode, BaseMode, GripperMode, RobotObservation, RobotRuntime, Robots,
};
use nalgebra::{UnitQuaternion, Vector2, Vector3};

use crate::desc::{RouteStep, TaskDesc};
use crate::manager::{Task, TaskPoints};

/// Which policy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PolicyKind {
    /// All-zero action.
    Zero,
    /// Uniform random action.
    Random,
    /// The task's scripted expert.
    Scripted,
}

impl std::str::FromStr for PolicyKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "zero" => Ok(Self::Zero),
            "random" => Ok(Self::Random),
            "scripted" => Ok(Self::Scripted),
            _ => Err(format!("--policy {s}: zero, random or scripted")),
        }
    }
}

/// Chooses an action for the env's current state.
pub trait Policy: Send {
    /// Called after every reset with the episode's seed.
    fn reset(&mut self, seed: u64) {
        let _ = seed;
    }
    /// Writes the action (length: the action space's flat size).
    fn act(&mut self, env: &Env, action: &mut [f32]) -> Result<(), String>;
}

struct Zero;

impl Policy for Zero {
    fn act(&mut self, _: &Env, action: &mut [f32]) -> Result<(), String> {
        action.fill(0.0);
        Ok(())
    }
}

struct Random {
    space: Space,
    rng: EnvRng,
}

fn sample(space: &Space, rng: &mut EnvRng, out: &mut [f32], k: &mut usize) {
    match space {
        Space::Box { low, high, .. } => {
            for (lo, hi) in low.iter().zip(high) {
                // Unbounded boxes sample [-1, 1].
                let (lo, hi) = (lo.max(-1.0), hi.min(1.0));
                out[*k] = rng.range(f64::from(lo), f64::from(hi)) as f32;
                *k += 1;
            }
        }
        Space::Discrete { n } => {
            out[*k] = rng.below(*n) as f32;
            *k += 1;
        }
        Space::Dict(items) => {
            for (_, s) in items {
                sample(s, rng, out, k);
            }
        }
    }
}

impl Policy for Random {
    fn reset(&mut self, seed: u64) {
        self.rng = EnvRng::from_seed(seed ^ 0x005e_ed0f_7a5c);
    }
    fn act(&mut self, _: &Env, action: &mut [f32]) -> Result<(), String> {
        let mut k = 0;
        sample(&self.space, &mut self.rng, action, &mut k);
        Ok(())
    }
}

/// Checks the `route` legs of a task section: `Err((field path under the section, value,
/// what is valid))`. Run when the scene compiles, so `modesuite validate` reports them.
pub fn check_route(desc: &TaskDesc) -> Result<(), (String, String, String)> {
    for (i, l) in desc.route.iter().enumerate() {
        if let Some((r, p, y)) = l.hand_rpy {
            if !(r.is_finite() && p.is_finite() && y.is_finite()) {
                return Err((
                    format!("route[{i}].hand_rpy"),
                    format!("({r}, {p}, {y})"),
                    "finite roll, pitch, yaw in degrees".into(),
                ));
            }
        }
        for (field, v) in [
            ("speed", l.speed),
            ("hand_speed", l.hand_speed),
            ("tolerance", l.tolerance),
            ("hand_tolerance", l.hand_tolerance),
        ] {
            if let Some(v) = v.filter(|v| !(v.is_finite() && *v > 0.0)) {
                return Err((
                    format!("route[{i}].{field}"),
                    v.to_string(),
                    "a positive number (m/s or m)".into(),
                ));
            }
        }
        if let Some(n) = &l.hand_at {
            if !desc.points.contains_key(n) && !desc.targets.contains_key(n) {
                return Err((
                    format!("route[{i}].hand_at"),
                    format!("\"{n}\""),
                    format!(
                        "a point or target of the task (points {:?}, targets {:?})",
                        desc.points.keys().collect::<Vec<_>>(),
                        desc.targets.keys().collect::<Vec<_>>()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Makes a policy for `env`. `scripted` needs a task with an expert that supports the
/// robot's action modes; errors say which modes it supports.
pub fn make_policy(kind: PolicyKind, env: &Env) -> Result<Box<dyn Policy>, String> {
    match kind {
        PolicyKind::Zero => Ok(Box::new(Zero)),
        PolicyKind::Random => Ok(Box::new(Random {
            space: env.spaces().action,
            rng: EnvRng::from_seed(0),
        })),
        PolicyKind::Scripted => {
            let task = env
                .app
                .world
                .get_resource::<Task>()
                .ok_or("--policy scripted: this scene has no task section (no expert)")?;
            let name = task
                .model
                .desc
                .expert
                .clone()
                .ok_or("--policy scripted: the task names no expert")?;
            let robot = task.model.robot.clone();
            let rt = robot_of(env, &robot)?;
            let modes = rt.fixed.modes;
            if modes.discrete {
                return Err(format!(
                    "the {name} expert needs continuous actions (the robot has discrete keys)"
                ));
            }
            let experts = env.app.world.get_resource::<Experts>();
            let expert = experts.and_then(|x| x.0.get(&name)).ok_or_else(|| {
                format!(
                    "no scripted expert named \"{name}\"; registered: [{}]",
                    experts.map_or(String::new(), |x| x
                        .0
                        .keys()
                        .cloned()
                        .collect::<Vec<_>>()
                        .join(", "))
                )
            })?;
            expert.make(&ExpertContext {
                env,
                task,
                robot,
                modes,
            })
        }
    }
}

/// A scripted expert, registered by name with [`register_expert`]; a task section names the
/// one that solves it (`expert: "place"`). Plugins add their own the same way.
pub trait Expert: Send + Sync + 'static {
    /// Registry name.
    fn name(&self) -> &str;
    /// One line for listings.
    fn description(&self) -> &str;
    /// The expert's policy for this env's task, or why it cannot drive it (action modes,
    /// missing task data).
    fn make(&self, ctx: &ExpertContext) -> Result<Box<dyn Policy>, String>;
}

/// What an [`Expert`] is made for: the env, its task, the task's robot and its action modes.
pub struct ExpertContext<'a> {
    /// The env (after its reset).
    pub env: &'a Env,
    /// The env's task.
    pub task: &'a Task,
    /// The task's robot.
    pub robot: String,
    /// The robot's action modes in this run.
    pub modes: ActionModes,
}

impl ExpertContext<'_> {
    /// Every built-in expert drives the base by velocity and the hand by end-effector poses;
    /// `arm_off`: it can also do without an arm action. The error names what it supports.
    pub fn check_modes(&self, name: &str, arm_off: bool) -> Result<(), String> {
        let modes = self.modes;
        let arm_ok = matches!(modes.arm, ArmMode::EePoseDelta | ArmMode::EePoseAbsolute)
            || (arm_off && modes.arm == ArmMode::Off);
        if matches!(modes.base, BaseMode::Velocity | BaseMode::Locomotion) && arm_ok {
            return Ok(());
        }
        Err(format!(
            "the {name} expert drives base: Velocity or Locomotion and arm: EePoseDelta or EePoseAbsolute{}; this run has base {:?}, arm {:?}",
            if arm_off { " or Off" } else { "" },
            modes.base,
            modes.arm
        ))
    }
}

/// The experts of an app by name (a resource; [`register_expert`] adds to it).
#[derive(Resource, Clone, Default)]
pub struct Experts(pub BTreeMap<String, Arc<dyn Expert>>);

/// Registers an expert under its name; a second expert of the same name is refused (reported
/// with [`SimApp::report_setup_error`], so the app compiles no scene).
pub fn register_expert(app: &mut SimApp, expert: Arc<dyn Expert>) {
    let name = expert.name().to_string();
    let mut experts = app.world.get_resource_or_insert_with(Experts::default);
    if !insert_unique(&mut experts.0, name.clone(), expert) {
        app.report_duplicate("expert", &name);
    }
}

/// A built-in expert: name, description, and how it is made.
struct BuiltIn {
    name: &'static str,
    description: &'static str,
    make: fn(&ExpertContext) -> Result<Box<dyn Policy>, String>,
}

impl Expert for BuiltIn {
    fn name(&self) -> &str {
        self.name
    }
    fn description(&self) -> &str {
        self.description
    }
    fn make(&self, ctx: &ExpertContext) -> Result<Box<dyn Policy>, String> {
        (self.make)(ctx)
    }
}

/// Registers the built-in experts: `place`, `curtain` and `route`.
pub fn register_builtin_experts(app: &mut SimApp) {
    let builtins = [
        BuiltIn {
            name: "place",
            description: "drives the base so the held rod's free end hangs over the table target (Place)",
            make: |c| {
                c.check_modes("place", false)?;
                Ok(Box::new(PlaceExpert {
                    robot: c.robot.clone(),
                    start: None,
                }))
            },
        },
        BuiltIn {
            name: "curtain",
            description: "lines the base up with the curtain's frame and drives through it (Curtain)",
            make: |c| {
                c.check_modes("curtain", true)?;
                Ok(Box::new(CurtainExpert {
                    robot: c.robot.clone(),
                }))
            },
        },
        BuiltIn {
            name: "route",
            description: "follows the task's `route` legs: base goal poses, hand targets, gripper (Bend, Transport, Drag, Lift, Uncover, Cover)",
            make: |c| {
                let route = c.task.model.desc.route.clone();
                if route.is_empty() {
                    return Err("the route expert needs the task's `route` legs".into());
                }
                c.check_modes(
                    "route",
                    route
                        .iter()
                        .all(|l| l.hand.is_none() && l.hand_at.is_none() && l.hand_rpy.is_none()),
                )?;
                Ok(Box::new(RouteExpert {
                    robot: c.robot.clone(),
                    route,
                    leg: 0,
                    bias: Vector3::zeros(),
                }))
            },
        },
    ];
    for b in builtins {
        register_expert(app, Arc::new(b));
    }
}

fn robot_of<'a>(env: &'a Env, name: &str) -> Result<&'a RobotRuntime, String> {
    env.app
        .world
        .get_resource::<Robots>()
        .and_then(|r| r.get(name))
        .ok_or_else(|| format!("no robot named \"{name}\""))
}

fn point(env: &Env, name: &str) -> Result<Vector3<f64>, String> {
    env.app
        .world
        .get_resource::<TaskPoints>()
        .and_then(|p| p.0.get(name).copied())
        .ok_or_else(|| format!("the task has no point or target named \"{name}\""))
}

/// The robot's state and its base heading (yaw, rad).
fn observe(env: &Env, rt: &RobotRuntime) -> Result<(RobotObservation, f64), String> {
    let obs = rt
        .observe(env.app.world.resource::<RigidContext>())
        .map_err(|e| e.to_string())?;
    let (_, _, yaw) = obs.base.rotation.euler_angles();
    Ok((obs, yaw))
}

/// Whether the env is at the first step of an episode (experts drop their memory then).
fn episode_start(env: &Env) -> bool {
    env.app
        .world
        .resource::<modesuite_engine::SimClock>()
        .episode_steps
        == 0
}

/// Length of one env step, s.
fn step_dt(env: &Env) -> f64 {
    let s = env.app.world.resource::<SimSettings>();
    s.dt * f64::from(s.decimation)
}

/// Writes the base, arm and gripper parts: a world-frame base velocity (m/s, rad/s) for a base
/// heading `yaw`, an end-effector position target in the base frame, an optional hand
/// orientation goal in the base frame (approached at up to the arm's angular speed; `None`
/// holds the orientation) and the gripper.
#[allow(clippy::too_many_arguments)]
fn write_action(
    env: &Env,
    rt: &RobotRuntime,
    yaw: f64,
    base_world: (Vector2<f64>, f64),
    ee_base: Vector3<f64>,
    rot: Option<UnitQuaternion<f64>>,
    closed: bool,
    action: &mut [f32],
) -> Result<(), String> {
    let dt = step_dt(env);
    let m = rt.fixed.modes;
    let mut k = 0;
    if matches!(m.base, BaseMode::Velocity | BaseMode::Locomotion) {
        let v = nalgebra::Rotation2::new(-yaw) * base_world.0;
        // The base command limits: 0.5 m/s, 0.5 m/s, 1.0 rad/s (SPEC.md).
        for x in [v.x / 0.5, v.y / 0.5, base_world.1] {
            action[k] = x.clamp(-1.0, 1.0) as f32;
            k += 1;
        }
    }
    match m.arm {
        ArmMode::EePoseDelta => {
            let d = (ee_base - rt.ee_target.translation.vector) / (m.ee_speed * dt);
            for i in 0..3 {
                action[k + i] = d[i].clamp(-1.0, 1.0) as f32;
            }
            // rotation error in the base frame (targets turn by left multiplication)
            let w = rot.map_or(Vector3::zeros(), |g| {
                (g * rt.ee_target.rotation.inverse()).scaled_axis() / (m.ee_angular_speed * dt)
            });
            for i in 0..3 {
                action[k + 3 + i] = w[i].clamp(-1.0, 1.0) as f32;
            }
            k += 6;
        }
        ArmMode::EePoseAbsolute => {
            let cur: UnitQuaternion<f64> = rt.ee_target.rotation;
            let r = rot.map_or(cur, |g| {
                let max = m.ee_angular_speed * dt;
                let e = (g * cur.inverse()).scaled_axis();
                if e.norm() > max {
                    UnitQuaternion::from_scaled_axis(e * (max / e.norm())) * cur
                } else {
                    g
                }
            });
            let rv = r.scaled_axis();
            for i in 0..3 {
                action[k + i] = ee_base[i] as f32;
                action[k + 3 + i] = rv[i] as f32;
            }
            k += 6;
        }
        ArmMode::Off => {}
        other => return Err(format!("arm mode {other:?} is not driven by this expert")),
    }
    if m.gripper == GripperMode::Binary {
        action[k] = if closed { 1.0 } else { -1.0 };
    }
    Ok(())
}

/// Place: the rod is in the hand from the start. Drive the base (heading held at 0) so that the
/// rod's free end moves over the table target, while the hand's height is servoed so the end
/// hangs 8 cm above the table top.
struct PlaceExpert {
    robot: String,
    /// Hand target at the start of the episode (base frame).
    start: Option<Vector3<f64>>,
}

impl Policy for PlaceExpert {
    fn reset(&mut self, _seed: u64) {
        self.start = None;
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) -> Result<(), String> {
        let rt = robot_of(env, &self.robot)?;
        let end = point(env, "rod_end")?;
        let table = point(env, "table")?;
        let (_, yaw) = observe(env, rt)?;
        let err = Vector2::new(table.x - end.x, table.y - end.y);
        let mut v = 1.5 * err;
        if v.norm() > 0.5 {
            v *= 0.5 / v.norm();
        }
        // Hand: 5 cm ahead of where it started in the base frame (x), centred (y); its height
        // follows the end's height error at up to 0.25 m/s (an integrator on the target,
        // rate-limited so it cannot wind up ahead of the arm in the absolute mode), within
        // -0.4 .. +0.7 m of the start.
        let dt = step_dt(env);
        let cur = rt.ee_target.translation.vector;
        if episode_start(env) {
            self.start = None;
        }
        let dz = (3.0 * (table.z + 0.08 - end.z)).clamp(-0.25, 0.25) * dt;
        let step = |from: f64, to: f64| from + (to - from).clamp(-0.25 * dt, 0.25 * dt);
        let start = *self.start.get_or_insert(cur);
        let ee = Vector3::new(
            step(cur.x, start.x + 0.05),
            step(cur.y, 0.0),
            (cur.z + dz).clamp(start.z - 0.4, start.z + 0.7),
        );
        // The rod is attached to the hand; the fingers stay open around it (closing them would
        // squeeze the 7 cm rod).
        write_action(env, rt, yaw, (v, -2.0 * yaw), ee, None, false, action)
    }
}

/// Curtain: line the base up with the middle of the frame (y = 0, heading 0) while approaching
/// slowly, then drive straight through at 0.4 m/s (Spot 0.5) with the arm held where it is
/// (Spot: the hand lowered to the body's middle); the body pushes the curtain aside.
struct CurtainExpert {
    robot: String,
}

impl Policy for CurtainExpert {
    fn act(&mut self, env: &Env, action: &mut [f32]) -> Result<(), String> {
        let rt = robot_of(env, &self.robot)?;
        let (obs, yaw) = observe(env, rt)?;
        let b = obs.base.translation.vector;
        let aligned = b.y.abs() < 0.06 && yaw.abs() < 0.06;
        let spot = !rt.fixed.legs.is_empty();
        // Through the curtain at 0.4 m/s; Spot at its top walking speed, 0.5 m/s: at 0.4 (and
        // 1/120 s substeps) the curtain, wrapped round its front legs, held 5 to 8 of 20 seeds
        // short of the line (0.3 m/s: 11 of 20); 0.5: 38 of 40.
        let fast = if spot { 0.5 } else { 0.4 };
        let vx = if aligned || b.x > 1.0 { fast } else { 0.2 };
        let v = Vector2::new(vx, -2.0 * b.y);
        let mut hand = rt.ee_target.translation.vector;
        if spot {
            // Spot lowers its hand from above the body's top (0.31 m in the body frame at the
            // start) to the body's middle: a hand above the body caught the curtain, which then
            // held Spot back just past the frame (3 of 20 seeds got through)
            hand.z = 0.0;
        }
        write_action(env, rt, yaw, (v, -2.0 * yaw), hand, None, false, action)
    }
}

/// Route: the task's `route` legs in order. On each leg the base is driven to its goal pose (a
/// proportional controller on position and heading, speed-limited), the hand target moves to
/// its goal (base frame) at up to the leg's hand speed (0.25 m/s by default), and the gripper is set; the leg ends when all are
/// within tolerance. The last leg is held.
struct RouteExpert {
    robot: String,
    route: Vec<RouteStep>,
    leg: usize,
    /// Correction added to the hand target on a leg with `hand_tolerance` (base frame, m): an
    /// integral of the measured hand's error, so the hand itself reaches the goal although the
    /// arm's tracking sags.
    bias: Vector3<f64>,
}

impl Policy for RouteExpert {
    fn reset(&mut self, _seed: u64) {
        self.leg = 0;
        self.bias = Vector3::zeros();
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) -> Result<(), String> {
        if episode_start(env) {
            self.leg = 0;
            self.bias = Vector3::zeros();
        }
        let rt = robot_of(env, &self.robot)?;
        let (obs, yaw) = observe(env, rt)?;
        let dt = step_dt(env);
        let b = obs.base.translation.vector.xy();
        let cur = rt.ee_target.translation.vector;
        let closed = self.route[..=self.leg]
            .iter()
            .rev()
            .find_map(|l| l.closed)
            .unwrap_or(false);
        let rot = self.route[..=self.leg]
            .iter()
            .rev()
            .find_map(|l| l.hand_rpy)
            .map(|(r, p, y)| {
                UnitQuaternion::from_euler_angles(r.to_radians(), p.to_radians(), y.to_radians())
            });
        let leg = &self.route[self.leg];
        let goal = Vector2::new(leg.base.0, leg.base.1);
        let heading = leg.base.2.to_radians();
        let err = goal - b;
        let dyaw = (heading - yaw + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        let offset = leg.hand.map(|h| Vector3::new(h.0, h.1, h.2));
        let hand_goal = match &leg.hand_at {
            Some(name) => {
                let p = point(env, name)?;
                let local = obs.base.inverse_transform_point(&p.into()).coords;
                Some(local + offset.unwrap_or_else(Vector3::zeros))
            }
            None => offset,
        };
        let tcp = obs
            .base
            .inverse_transform_point(&obs.ee.translation.vector.into())
            .coords;
        let hand_reached = match (leg.hand_tolerance, hand_goal) {
            (Some(t), Some(h)) => (h - tcp).norm() < t,
            _ => hand_goal.is_none_or(|h| (h - cur).norm() < 0.02),
        };
        let hand_goal = match (leg.hand_tolerance, hand_goal) {
            (Some(_), Some(h)) => {
                // integrate the measured error once the target has arrived
                if (h + self.bias - cur).norm() < 0.02 {
                    self.bias += 0.2 * (h - tcp);
                    let n = self.bias.norm();
                    if n > 0.15 {
                        self.bias *= 0.15 / n;
                    }
                }
                Some(h + self.bias)
            }
            (_, h) => h,
        };
        let rot_reached = rot.is_none_or(|g| g.angle_to(&rt.ee_target.rotation) < 0.05);
        let tol = leg.tolerance.unwrap_or(0.05);
        if err.norm() < tol
            && dyaw.abs() < 3f64.to_radians()
            && hand_reached
            && rot_reached
            && self.leg + 1 < self.route.len()
        {
            self.leg += 1;
            self.bias = Vector3::zeros();
        }
        let speed = leg.speed.unwrap_or(0.4);
        let mut v = 1.5 * err;
        if v.norm() > speed {
            v *= speed / v.norm();
        }
        let wz = (2.0 * dyaw).clamp(-0.6, 0.6);
        let ee = match hand_goal {
            Some(h) => {
                let d = h - cur;
                let max = leg.hand_speed.unwrap_or(0.25) * dt;
                if d.norm() > max {
                    cur + d * (max / d.norm())
                } else {
                    h
                }
            }
            None => cur,
        };
        write_action(env, rt, yaw, (v, wz), ee, rot, closed, action)
    }
}
