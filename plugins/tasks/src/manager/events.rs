//! Task events: the `Startup` stream ([`TaskStartup`]), applying an event to the world
//! ([`EventWorld`]), and the `task_reset` and `task_interval_events` systems.

use bevy_ecs::prelude::*;
use modesuite_engine::components::{DeformableNodes, Object};
use modesuite_engine::deformable::{deformable_mut, DeformableSolver};
use modesuite_engine::math::{pose_from_rapier, pose_to_rapier, vec_from_rapier, vec_to_rapier};
use modesuite_engine::rigid::RigidRef;
use modesuite_engine::rng::EnvRng;
use modesuite_engine::scene::NamedFrames;
use modesuite_engine::{Phase, RigidContext, SimClock, SimErrors};
use modesuite_robots::Robots;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use std::sync::Arc;

use super::model::{Task, TaskState};
use crate::desc::EventDesc;
use crate::events::{EventCtx, EventOps, TaskEvent};

/// Rotation about z by `yaw` around `centre`, then translation by `d`.
fn planar_move(centre: Vector3<f64>, d: Vector3<f64>, yaw: f64) -> Isometry3<f64> {
    let r = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
    Isometry3::from_parts(Translation3::from(centre + d), r) * Translation3::from(-centre)
}

/// The stream of `Startup` events of one env: derived from the RNG of its first reset and kept
/// for its life (outside the snapshot, so a reset's restore does not undo it).
#[derive(Resource, Debug, Clone, Default)]
pub struct TaskStartup {
    rng: Option<EnvRng>,
}

/// Mixed into the first reset's RNG state to derive the `Startup` stream (so startup values are
/// not the reset events' first draws).
const STARTUP_SALT: u64 = 0x5eed_57a7_0000_0001;

/// What events change: the rigid world, the deformables, the env's RNG.
#[derive(bevy_ecs::system::SystemParam)]
pub(super) struct EventWorld<'w, 's> {
    robots: Option<Res<'w, Robots>>,
    rigid: Option<ResMut<'w, RigidContext>>,
    rng: ResMut<'w, EnvRng>,
    nodes: Query<'w, 's, (Entity, &'static Object, &'static mut DeformableNodes)>,
    bodies: Query<'w, 's, (&'static Object, &'static RigidRef)>,
    errors: ResMut<'w, SimErrors>,
    /// Changes to deformable bodies, made through the solver-neutral interface
    /// ([`deformable_mut`]) in event order right after the system (an `ApplyDeferred` follows
    /// both event systems), before anything steps or reads the solvers.
    commands: Commands<'w, 's>,
}

/// Queues `f` on the solver of deformable entity `e`; its failure becomes the env's error,
/// named like a failed event.
fn on_solver(
    commands: &mut Commands,
    event: &str,
    e: Entity,
    f: impl FnOnce(&mut dyn DeformableSolver) -> Result<(), String> + Send + 'static,
) {
    let event = event.to_string();
    commands.queue(move |world: &mut World| {
        let r = match deformable_mut(world, e) {
            Some(solver) => f(solver),
            None => Err(format!("entity {e} has no deformable solver body")),
        };
        if let Err(msg) = r {
            world
                .resource_mut::<SimErrors>()
                .raise(format!("task event \"{event}\": {msg}"));
        }
    });
}

impl EventWorld<'_, '_> {
    /// Moves a deformable rigidly (its nodes component now, its solver right after the system).
    fn move_object(&mut self, event: &str, name: &str, iso: &Isometry3<f64>) -> Result<(), String> {
        let Some((e, _, mut n)) = self.nodes.iter_mut().find(|(_, o, _)| o.name == name) else {
            return Err(format!(
                "object \"{name}\" is not a deformable (fem.solid, pbd.cloth) a task can move"
            ));
        };
        let moved: Vec<Vector3<f64>> =
            n.0.iter()
                .map(|p| (iso * Point3::from(*p)).coords)
                .collect();
        let (positions, rotation) = (moved.clone(), iso.rotation);
        on_solver(&mut self.commands, event, e, move |s| {
            s.move_rigidly(&positions, &rotation)
        });
        n.0 = moved;
        Ok(())
    }

    /// Adds `dv` to the velocity of a deformable's nodes or of a free rigid body.
    fn push(&mut self, event: &str, name: &str, dv: Vector3<f64>) -> Result<(), String> {
        if let Some((e, _, _)) = self.nodes.iter().find(|(_, o, _)| o.name == name) {
            on_solver(&mut self.commands, event, e, move |s| s.add_velocity(&dv));
            return Ok(());
        }
        let rigid = self.rigid.as_deref_mut().ok_or("no rigid world")?;
        let (_, body) = self
            .bodies
            .iter()
            .find(|(o, _)| o.name == name)
            .ok_or_else(|| format!("object \"{name}\" is neither a deformable nor a rigid body"))?;
        let b = rigid
            .bodies
            .get_mut(body.0)
            .ok_or_else(|| format!("object \"{name}\": its body is gone"))?;
        if !b.is_dynamic() || rigid.multibody_joints.rigid_body_link(body.0).is_some() {
            return Err(format!(
                "object \"{name}\" is not a free dynamic body (Push moves deformables and free rigid bodies; robot links and fixed or kinematic bodies are not implemented)"
            ));
        }
        let v = vec_to_rapier(&(vec_from_rapier(b.linvel()) + dv));
        b.set_linvel(v, true);
        Ok(())
    }

    /// Sets the friction coefficient of every collider of a rigid object.
    fn set_friction(&mut self, object: &str, f: f64) -> Result<(), String> {
        let rigid = self.rigid.as_deref_mut().ok_or("no rigid world")?;
        let (_, body) = self
            .bodies
            .iter()
            .find(|(o, _)| o.name == *object)
            .ok_or_else(|| format!("object \"{object}\" is not a rigid body"))?;
        let colliders: Vec<_> = rigid
            .bodies
            .get(body.0)
            .ok_or_else(|| format!("object \"{object}\": its body is gone"))?
            .colliders()
            .to_vec();
        for c in colliders {
            if let Some(c) = rigid.colliders.get_mut(c) {
                c.set_friction(f as f32);
            }
        }
        Ok(())
    }

    /// Draws and applies one event (`Startup`/`Interval` wrappers run their event now);
    /// `custom` is the configured event of an `Event` leaf.
    fn apply(
        &mut self,
        robot_name: &str,
        event: &str,
        e: &EventDesc,
        custom: Option<&Arc<dyn TaskEvent>>,
    ) -> Result<(), String> {
        match e {
            EventDesc::Startup(inner) | EventDesc::Interval { event: inner, .. } => {
                self.apply(robot_name, event, inner, custom)
            }
            EventDesc::Event { event: name, .. } => {
                let configured = custom
                    .ok_or_else(|| format!("registered event \"{name}\" was not configured"))?;
                let mut ctx = EventCtx {
                    ops: self,
                    event,
                    robot: robot_name,
                };
                configured.apply(&mut ctx)
            }
            EventDesc::RobotPose { xy, yaw, carry } => {
                let dx = self.rng.range(-xy, *xy);
                let dy = self.rng.range(-xy, *xy);
                let dyaw = self.rng.range(-yaw, *yaw);
                let (Some(robots), Some(rigid)) =
                    (self.robots.as_deref(), self.rigid.as_deref_mut())
                else {
                    return Err("the scene has no robots".to_string());
                };
                let rt = robots
                    .get(robot_name)
                    .ok_or_else(|| format!("robot \"{robot_name}\" is gone"))?;
                let centre = rt
                    .observe(rigid)
                    .map_err(|e| e.to_string())?
                    .base
                    .translation
                    .vector;
                let iso = planar_move(centre, Vector3::new(dx, dy, 0.0), dyaw);
                let robot = &rt.fixed.robot;
                let mut q = robot.joint_positions(rigid).map_err(|e| e.to_string())?;
                match rt.fixed.base {
                    // A holonomic base: its virtual joints.
                    Some(base) => {
                        q[base.x] += dx;
                        q[base.y] += dy;
                        q[base.yaw] += dyaw;
                    }
                    // A floating base: move the root body; the links follow by forward
                    // kinematics from it.
                    None => {
                        let root = rigid
                            .bodies
                            .get_mut(robot.root())
                            .ok_or("the robot's root body is gone")?;
                        let pose = iso * pose_from_rapier(root.position());
                        root.set_position(pose_to_rapier(&pose), true);
                    }
                }
                robot
                    .set_joint_positions(rigid, &q)
                    .map_err(|e| e.to_string())?;
                for c in carry {
                    self.move_object(event, c, &iso)?;
                }
                Ok(())
            }
            EventDesc::Friction { object, range } => {
                let f = self.rng.range(range.0, range.1);
                self.set_friction(object, f)
            }
            EventDesc::ObjectOffset { object, xy } => {
                let d = Vector3::new(self.rng.range(-xy, *xy), self.rng.range(-xy, *xy), 0.0);
                self.move_object(
                    event,
                    object,
                    &Isometry3::from_parts(Translation3::from(d), UnitQuaternion::identity()),
                )
            }
            EventDesc::Material {
                object,
                youngs_modulus,
            } => {
                let value = self.rng.range(youngs_modulus.0, youngs_modulus.1);
                let (e, _, _) = self
                    .nodes
                    .iter()
                    .find(|(_, o, _)| o.name == *object)
                    .ok_or_else(|| {
                        format!("object \"{object}\" is not a deformable body (Material sets the Young's modulus of a solid, e.g. a fem.solid)")
                    })?;
                let object = object.clone();
                on_solver(&mut self.commands, event, e, move |s| {
                    s.set_youngs_modulus(value)
                        .map_err(|er| format!("object \"{object}\": {er}"))
                });
                Ok(())
            }
            EventDesc::Push { object, velocity } => {
                let (x, y, z) = *velocity;
                let dv = Vector3::new(
                    self.rng.range(-x, x),
                    self.rng.range(-y, y),
                    self.rng.range(-z, z),
                );
                self.push(event, object, dv)
            }
        }
    }

    /// Applies `e` and reports a failure as the env's error.
    fn run(
        &mut self,
        robot_name: &str,
        name: &str,
        e: &EventDesc,
        custom: Option<&Arc<dyn TaskEvent>>,
    ) {
        if let Err(msg) = self.apply(robot_name, name, e, custom) {
            self.errors.raise(format!("task event \"{name}\": {msg}"));
        }
    }
}

impl EventOps for EventWorld<'_, '_> {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.rng.range(lo, hi)
    }
    fn push(&mut self, event: &str, object: &str, dv: Vector3<f64>) -> Result<(), String> {
        EventWorld::push(self, event, object, dv)
    }
    fn move_object(
        &mut self,
        event: &str,
        object: &str,
        iso: &Isometry3<f64>,
    ) -> Result<(), String> {
        EventWorld::move_object(self, event, object, iso)
    }
    fn set_friction(&mut self, object: &str, friction: f64) -> Result<(), String> {
        EventWorld::set_friction(self, object, friction)
    }
}

pub(super) fn task_reset(
    task: Option<Res<Task>>,
    mut state: Option<ResMut<TaskState>>,
    mut startup: Option<ResMut<TaskStartup>>,
    mut frames: Option<ResMut<NamedFrames>>,
    mut ew: EventWorld,
) {
    let (Some(task), Some(state)) = (task, state.as_deref_mut()) else {
        return;
    };
    if ew.robots.is_none() || ew.rigid.is_none() {
        return;
    }
    let m = &task.model;
    state.success = false;
    state.stages.iter_mut().for_each(|k| *k = 0);
    state.prev_action.clear();
    for h in state.history.iter_mut() {
        h.clear();
    }
    // Startup events first, from their own stream: the same values after every reset.
    if let Some(startup) = startup.as_deref_mut() {
        let mut episode = *ew.rng;
        let stream = *startup
            .rng
            .get_or_insert_with(|| EnvRng::from_seed(episode.next_u64() ^ STARTUP_SALT));
        let saved = std::mem::replace(&mut *ew.rng, stream);
        for (name, e) in m
            .events
            .iter()
            .filter(|(_, e)| matches!(e, EventDesc::Startup(_)))
        {
            ew.run(&m.robot, name, e, m.custom_events.get(name));
        }
        *ew.rng = saved;
    }
    for (i, (_, t)) in m.targets.iter().enumerate() {
        let mut p = t.pos;
        for k in 0..3 {
            if t.range[k] > 0.0 {
                p[k] += ew.rng.range(-t.range[k], t.range[k]);
            }
        }
        state.targets[i] = p;
    }
    // The targets as named frames `target/<name>`: renderers draw them as markers.
    if let Some(frames) = frames.as_deref_mut() {
        for ((name, _), p) in m.targets.iter().zip(&state.targets) {
            frames.0.insert(
                format!("target/{name}"),
                Isometry3::translation(p.x, p.y, p.z),
            );
        }
    }
    for (name, e) in &m.events {
        if !matches!(e, EventDesc::Startup(_) | EventDesc::Interval { .. }) {
            ew.run(&m.robot, name, e, m.custom_events.get(name));
        }
    }
    // The first run of every interval event.
    state.next_event.clear();
    for (_, e) in &m.events {
        if let EventDesc::Interval { every, .. } = e {
            let gap = ew.rng.range(every.0, every.1);
            state.next_event.push(gap);
        }
    }
    if let Some(rigid) = ew.rigid.as_deref_mut() {
        rigid.bodies_moved();
    }
}

/// Runs the interval events that are due at the start of this env step (before its physics).
/// They move no body (friction, stiffness, velocities), so the rigid queries stay valid.
pub(super) fn task_interval_events(
    task: Option<Res<Task>>,
    mut state: Option<ResMut<TaskState>>,
    phase: Res<Phase>,
    clock: Res<SimClock>,
    mut ew: EventWorld,
) {
    let (Some(task), Some(state)) = (task, state.as_deref_mut()) else {
        return;
    };
    if *phase != Phase::Step || state.next_event.is_empty() {
        return;
    }
    let m = &task.model;
    let intervals = m.events.iter().filter_map(|(n, e)| match e {
        EventDesc::Interval { every, .. } => Some((n, e, every)),
        _ => None,
    });
    for ((name, e, every), next) in intervals.zip(state.next_event.iter_mut()) {
        // A little slack so an event due at t = k * dt is not pushed to the next step by
        // round-off in the clock.
        if clock.time + 1e-9 < *next {
            continue;
        }
        ew.run(&m.robot, name, e, m.custom_events.get(name.as_str()));
        let gap = ew.rng.range(every.0, every.1);
        *next += gap;
        if *next <= clock.time {
            *next = clock.time + gap;
        }
    }
}
