//! The task managers in ECS form: the `task` scene section compiles into an immutable
//! [`TaskModel`]; every env gets a [`Task`] (resolved points) and a [`TaskState`] (stateful:
//! targets, previous action, observation history, success), and five systems:
//! - `task_reset` (`EnvSystems::Reset`): startup events (once per env, from a stream derived at
//!   its first reset and replayed after every restore) and reset events (targets, robot start
//!   pose, object offsets, friction, material, push), drawn from the env's RNG; it also draws the
//!   first time of every interval event;
//! - `task_interval_events` (between `EnvSystems::ProcessActions` and `Simulate`): interval
//!   events that are due;
//! - `task_evaluate` (`EnvSystems::Evaluate`, before the time limit): rewards (weighted terms,
//!   optional dt scaling), success (all success terms non-zero: terminated, `success = true`,
//!   bonus), failure terminations;
//! - `task_observe` (`EnvSystems::Observe`): observation groups (terms concatenated, scaled,
//!   clipped, noise, history); the env's observation is the `policy` group, every group is in
//!   [`TaskObservations`].

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::Path;
use std::sync::Arc;

use bevy_ecs::prelude::*;
use modesuite_engine::components::{DeformableNodes, Object, Pose};
use modesuite_engine::env::{ActionBuffer, ObservationBuffer, StepSignals};
use modesuite_engine::math::{pose_from_rapier, pose_to_rapier, vec_from_rapier, vec_to_rapier};
use modesuite_engine::registry::{CompiledSection, SceneSection, SectionCompileContext};
use modesuite_engine::rigid::RigidRef;
use modesuite_engine::rng::EnvRng;
use modesuite_engine::scene::{NamedFrames, SceneError};
use modesuite_engine::state::{StateHasher, Stateful};
use modesuite_engine::terms::{check_finite, world_view, ViewQuery};
use modesuite_engine::{
    EngineSystems, EnvSystems, Phase, RigidContext, SimApp, SimClock, SimErrors, SimSettings,
    Space, Spaces,
};
use modesuite_fem::{FemContext, GraspParams};
use modesuite_pbd::{Cloth, PbdContext};
use modesuite_render::{CameraImages, CameraRequests};
use modesuite_robots::{RobotObservation, Robots};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::desc::{EventDesc, PointRef, TaskDesc};
use crate::terms::{tracked_nodes, Configure, Dims, PointId, TaskCtx, TaskTerm, TaskTermEntry};

/// A configured term with its name.
#[derive(Clone)]
pub struct NamedTerm {
    /// Name in the section.
    pub name: String,
    /// The term.
    pub term: Arc<dyn TaskTerm>,
}

/// A reward term.
#[derive(Clone)]
pub struct RewardTerm {
    /// Name and term.
    pub term: NamedTerm,
    /// Weight.
    pub weight: f64,
    /// Multiplied by the env step length.
    pub dt_scaled: bool,
    /// Counted only on steps where this term is non-zero.
    pub when: Option<NamedTerm>,
}

/// An observation term with post-processing.
#[derive(Clone)]
pub struct ObsTerm {
    /// Name (`term` of the entry) and term.
    pub term: NamedTerm,
    /// Scale.
    pub scale: f64,
    /// Clip range.
    pub clip: Option<(f64, f64)>,
}

/// An observation group.
#[derive(Clone)]
pub struct Group {
    /// Name.
    pub name: String,
    /// Terms in order.
    pub terms: Vec<ObsTerm>,
    /// Uniform noise half-width.
    pub noise: f64,
    /// Frames stacked.
    pub history: usize,
}

/// A target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// Nominal position.
    pub pos: Vector3<f64>,
    /// Randomisation half-widths.
    pub range: Vector3<f64>,
}

/// A compiled task (immutable, shared by every env).
pub struct TaskModel {
    /// The section after `extends` was applied.
    pub desc: TaskDesc,
    /// Robot name.
    pub robot: String,
    /// Points the terms use.
    pub points: Vec<PointRef>,
    /// Target names and values, in index order.
    pub targets: Vec<(String, Target)>,
    /// Rewards.
    pub rewards: Vec<RewardTerm>,
    /// Success terms.
    pub success: Vec<NamedTerm>,
    /// Success bonus.
    pub success_bonus: f64,
    /// Failure terminations.
    pub terminations: Vec<NamedTerm>,
    /// Observation groups.
    pub groups: Vec<Group>,
    /// Reset events in order.
    pub events: Vec<(String, EventDesc)>,
    /// Named points and targets with their ids (published in [`TaskPoints`]).
    pub named: Vec<(String, PointId)>,
}

impl TaskModel {
    /// Index of a target.
    pub fn target_index(&self, name: &str) -> Option<usize> {
        self.targets.iter().position(|(n, _)| n == name)
    }
}

/// A point resolved in one env.
#[derive(Debug, Clone)]
enum Resolved {
    Target(usize),
    Base,
    Ee,
    Object(String),
    Nodes {
        object: Entity,
        nodes: Vec<u32>,
    },
    Const(Vector3<f64>),
    /// Indices of the stage points and of the follower (earlier in the list), the reach, and
    /// the slot of the progress in [`TaskState::stages`].
    Stages {
        stages: Vec<usize>,
        by: usize,
        reach: f64,
        slot: usize,
    },
}

/// The task of one env: the model and the points resolved at spawn (immutable).
#[derive(Resource, Clone)]
pub struct Task {
    /// The compiled task.
    pub model: Arc<TaskModel>,
    points: Vec<Resolved>,
    /// Robot dimensions.
    pub dims: Dims,
    /// Arm joints (gripper last) and leg joints, indices into the robot's joints.
    pub arm_joints: Vec<usize>,
    /// Leg joint indices.
    pub leg_joints: Vec<usize>,
    /// Base height at spawn.
    pub base_height: f64,
    /// Cloth objects (name, entity).
    cloths: Vec<(String, Entity)>,
    /// Per observation group: the lengths of a frame's items, in buffer order: the items of
    /// [`frame_items`] for a group with images, the whole frame otherwise. A group's buffer is
    /// item by item, each item's `history` frames oldest first (for one item or one frame,
    /// simply frame after frame).
    frame_item_lens: Arc<Vec<Vec<usize>>>,
}

/// Per-env task state (part of the snapshot).
#[derive(Resource, Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TaskState {
    /// Current target positions.
    pub targets: Vec<Vector3<f64>>,
    /// Action of the previous step.
    pub prev_action: Vec<f32>,
    /// Per group: the last `history` frames.
    pub history: Vec<VecDeque<Vec<f32>>>,
    /// Whether the current episode has succeeded.
    pub success: bool,
    /// Progress of every `Stages` point: the index of its current stage.
    pub stages: Vec<usize>,
    /// Episode time (s) of the next run of every `Interval` event, in event order.
    pub next_event: Vec<f64>,
}

modesuite_engine::persist_by_serde!(TaskState);

impl Stateful for TaskState {
    fn save_state(&self) -> Box<dyn std::any::Any + Send + Sync> {
        Box::new(self.clone())
    }
    fn load_state(
        &mut self,
        state: &(dyn std::any::Any + Send + Sync),
    ) -> Result<(), modesuite_engine::checkpoint::StateError> {
        self.clone_from(
            state
                .downcast_ref::<TaskState>()
                .ok_or_else(modesuite_engine::state::mismatch::<Self>)?,
        );
        Ok(())
    }
    fn hash_state(&self, h: &mut StateHasher) {
        for t in &self.targets {
            for x in t.iter() {
                h.write_f64(*x);
            }
        }
        for a in &self.prev_action {
            h.write_f64(f64::from(*a));
        }
        for g in &self.history {
            for f in g {
                for x in f {
                    h.write_f64(f64::from(*x));
                }
            }
        }
        h.write_u64(u64::from(self.success));
        for s in &self.stages {
            h.write_u64(*s as u64);
        }
        for t in &self.next_event {
            h.write_f64(*t);
        }
    }
}

/// The task's named points and targets after the last step or reset (world, m), for experts,
/// tests and viewers.
#[derive(Resource, Debug, Clone, Default)]
pub struct TaskPoints(pub BTreeMap<String, Vector3<f64>>);

/// Every observation group of the last observation, flat, by group name.
#[derive(Resource, Debug, Clone, Default)]
pub struct TaskObservations(pub BTreeMap<String, Vec<f32>>);

/// The `task` scene section.
pub struct TaskSection;

/// The cameras of the scene's render section: name -> (width, height).
fn scene_cameras(ctx: &SectionCompileContext) -> Result<BTreeMap<String, (u32, u32)>, SceneError> {
    let Some(text) = ctx.extension(modesuite_render::config::EXTENSION_KEY) else {
        return Ok(BTreeMap::new());
    };
    // The render section reports its own errors with their place; an unreadable one leaves
    // no cameras here.
    let cfg: Option<modesuite_render::RenderConfig> =
        modesuite_engine::scene::ron_options().from_str(text).ok();
    Ok(cfg
        .map(|c| {
            c.cameras
                .iter()
                .map(|c| (c.name.clone(), (c.width, c.height)))
                .collect()
        })
        .unwrap_or_default())
}

/// Checks that an event's `object` is in the scene; a robot link (`robot/link`, spawned by the
/// robots section after the task compiles) is checked when the event runs.
fn check_object(epath: &str, object: &str, cfg: &Configure) -> Result<(), SceneError> {
    if object.contains('/') {
        return Ok(());
    }
    cfg.object(object)
        .map_err(|m| serr(&format!("{epath}.object"), object, m))
}

/// Checks a `(lo, hi)` range: finite, `lo <= hi`, `lo >= 0` (`lo > 0` when `positive`).
fn check_range(
    path: &str,
    (lo, hi): (f64, f64),
    positive: bool,
    (low, high): (&str, &str),
    unit: &str,
) -> Result<(), SceneError> {
    let low_ok = if positive { lo > 0.0 } else { lo >= 0.0 };
    if lo.is_finite() && hi.is_finite() && low_ok && lo <= hi {
        return Ok(());
    }
    let op = if positive { "<" } else { "<=" };
    Err(serr(
        path,
        format!("({lo}, {hi})"),
        format!("finite ({low}, {high}) with 0 {op} {low} <= {high}{unit}"),
    ))
}

/// Checks an event of the task section (`wrapper`: the `Startup`/`Interval` it is inside).
fn check_event(
    epath: &str,
    e: &EventDesc,
    cfg: &Configure,
    wrapper: Option<&str>,
) -> Result<(), SceneError> {
    match e {
        EventDesc::RobotPose { xy, yaw, carry } => {
            if !(xy.is_finite() && *xy >= 0.0 && yaw.is_finite() && *yaw >= 0.0) {
                return Err(serr(epath, format!("{e:?}"), "finite xy >= 0 and yaw >= 0"));
            }
            for c in carry {
                cfg.object(c)
                    .map_err(|m| serr(&format!("{epath}.carry"), c.clone(), m))?;
            }
        }
        EventDesc::Friction { object, range } => {
            check_object(epath, object, cfg)?;
            check_range(
                &format!("{epath}.range"),
                *range,
                false,
                ("lowest", "highest"),
                "",
            )?;
        }
        EventDesc::ObjectOffset { object, xy } => {
            check_object(epath, object, cfg)?;
            if !(xy.is_finite() && *xy >= 0.0) {
                return Err(serr(
                    &format!("{epath}.xy"),
                    xy.to_string(),
                    "a finite xy >= 0",
                ));
            }
        }
        EventDesc::Material {
            object,
            youngs_modulus: (lo, hi),
        } => {
            check_object(epath, object, cfg)?;
            check_range(
                &format!("{epath}.youngs_modulus"),
                (*lo, *hi),
                true,
                ("lowest", "highest"),
                ", Pa",
            )?;
        }
        EventDesc::Push { object, velocity } => {
            check_object(epath, object, cfg)?;
            let (x, y, z) = *velocity;
            if ![x, y, z].iter().all(|v| v.is_finite() && *v >= 0.0) {
                return Err(serr(
                    &format!("{epath}.velocity"),
                    format!("{velocity:?}"),
                    "finite half-widths >= 0, m/s",
                ));
            }
        }
        EventDesc::Startup(inner) | EventDesc::Interval { event: inner, .. } => {
            let kind = if matches!(e, EventDesc::Startup(_)) {
                "Startup"
            } else {
                "Interval"
            };
            if let Some(outer) = wrapper {
                return Err(serr(
                    epath,
                    kind,
                    format!("an event inside {outer}(...) (Startup and Interval do not nest)"),
                ));
            }
            if let EventDesc::Interval {
                every: (lo, hi), ..
            } = e
            {
                check_range(
                    &format!("{epath}.every"),
                    (*lo, *hi),
                    true,
                    ("shortest", "longest"),
                    ", s",
                )?;
                if matches!(
                    **inner,
                    EventDesc::RobotPose { .. } | EventDesc::ObjectOffset { .. }
                ) {
                    return Err(serr(
                        &format!("{epath}.event"),
                        format!("{inner:?}"),
                        "Friction, Material or Push (RobotPose and ObjectOffset teleport objects: reset or Startup only)",
                    ));
                }
            }
            let ipath = if kind == "Startup" {
                format!("{epath}.0")
            } else {
                format!("{epath}.event")
            };
            check_event(&ipath, inner, cfg, Some(kind))?;
        }
    }
    Ok(())
}

fn serr(path: &str, value: impl Into<String>, msg: impl Into<String>) -> SceneError {
    SceneError::semantic(path.to_string(), value.into(), msg.into())
}

/// Reads `file` (a `*.task.ron` holding one task section) and the files it extends.
fn load_extends(
    base_dir: &Path,
    file: &str,
    depth: usize,
    path: &str,
) -> Result<TaskDesc, SceneError> {
    if depth > 8 {
        return Err(serr(path, file, "at most 8 levels of `extends`"));
    }
    // a scene names task files beside it or in its subfolders, never elsewhere on the machine
    let inside = Path::new(file)
        .components()
        .all(|c| matches!(c, std::path::Component::Normal(_)));
    if !inside || !file.ends_with(".task.ron") {
        return Err(serr(
            path,
            file,
            "a `*.task.ron` file in the scene's folder or below it (a relative path without `..`)",
        ));
    }
    let full = base_dir.join(file);
    let text = match full
        .to_str()
        .and_then(|f| f.strip_prefix(crate::EMBEDDED_DIR))
        .map(|f| f.trim_start_matches('/'))
    {
        Some(rel) => crate::embedded(rel)
            .ok_or_else(|| serr(path, file, format!("no embedded file {rel}")))?
            .to_string(),
        None => std::fs::read_to_string(&full)
            .map_err(|e| serr(path, file, format!("cannot read {}: {e}", full.display())))?,
    };
    let desc: TaskDesc = crate::ron_options()
        .from_str(&text)
        .map_err(|e| serr(path, file, format!("{}:{}", full.display(), e)))?;
    resolve_extends(desc, full.parent().unwrap_or(base_dir), depth + 1, path)
}

fn resolve_extends(
    desc: TaskDesc,
    base_dir: &Path,
    depth: usize,
    path: &str,
) -> Result<TaskDesc, SceneError> {
    match desc.extends.clone() {
        None => Ok(desc),
        Some(f) => {
            let parent = load_extends(base_dir, &f, depth, &format!("{path}.extends"))?;
            Ok(desc.over(parent))
        }
    }
}

fn configure(
    ctx: &SectionCompileContext,
    cfg: &mut Configure,
    path: String,
    name: &str,
    params: Option<&ron::value::RawValue>,
) -> Result<Arc<dyn TaskTerm>, SceneError> {
    let entry = ctx.registry.terms.get(name).ok_or_else(|| {
        serr(
            &path,
            format!("term: \"{name}\""),
            format!(
                "a registered task term: [{}]",
                ctx.registry
                    .terms
                    .iter()
                    .filter(|(_, e)| e.payload.downcast_ref::<TaskTermEntry>().is_some())
                    .map(|(n, _)| n.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )
    })?;
    let f = entry
        .payload
        .downcast_ref::<TaskTermEntry>()
        .ok_or_else(|| {
            serr(
            &path,
            format!("term: \"{name}\""),
            "a task term (this one is a scene term: use it in the scene's rewards/observations)",
        )
        })?;
    let ron = params.map_or("()", |p| p.get_ron());
    f.0.configure(ron, cfg)
        .map_err(|e| serr(&format!("{path}.params"), ron.trim(), e))
}

impl SceneSection for TaskSection {
    fn name(&self) -> &str {
        "task"
    }

    fn description(&self) -> &str {
        "a MoDeSuite task: points, targets, rewards, success, terminations, observation groups, reset events"
    }

    fn compile(&self, ctx: &SectionCompileContext) -> Result<CompiledSection, SceneError> {
        let path = ctx.path();
        let desc: TaskDesc = ctx.parse()?;
        let desc = resolve_extends(desc, &ctx.source.base_dir, 0, &path)?;
        if let Some(id) = &desc.id {
            crate::parse_id(id).map_err(|e| serr(&format!("{path}.id"), id.clone(), e))?;
        }
        let objects: Vec<String> = ctx.objects.iter().map(|o| o.name.clone()).collect();
        let mut targets = Vec::new();
        for (n, t) in &desc.targets {
            let v = |x: (f64, f64, f64)| Vector3::new(x.0, x.1, x.2);
            let (pos, range) = (v(t.pos), v(t.range));
            if !pos.iter().chain(range.iter()).all(|x| x.is_finite()) || range.min() < 0.0 {
                return Err(serr(
                    &format!("{path}.targets[\"{n}\"]"),
                    format!("{t:?}"),
                    "finite pos and range >= 0",
                ));
            }
            targets.push((n.clone(), Target { pos, range }));
        }
        let target_names: Vec<String> = targets.iter().map(|(n, _)| n.clone()).collect();
        let cameras = scene_cameras(ctx)?;
        let mut cfg = Configure {
            named: &desc.points,
            targets: &target_names,
            objects: &objects,
            table: Vec::new(),
            cameras: &cameras,
        };
        let mut named_ids = Vec::new();
        for (n, p) in &desc.points {
            let id = cfg
                .point(p)
                .map_err(|e| serr(&format!("{path}.points[\"{n}\"]"), format!("{p:?}"), e))?;
            named_ids.push((n.clone(), id));
        }
        for (n, _) in &targets {
            named_ids.push((
                n.clone(),
                cfg.point(&PointRef::Target(n.clone()))
                    .map_err(|e| serr(&path, n.clone(), e))?,
            ));
        }
        let mut rewards = Vec::new();
        for (n, r) in &desc.rewards {
            if !r.weight.is_finite() {
                return Err(serr(
                    &format!("{path}.rewards[\"{n}\"].weight"),
                    r.weight.to_string(),
                    "a finite weight",
                ));
            }
            let term = configure(
                ctx,
                &mut cfg,
                format!("{path}.rewards[\"{n}\"]"),
                &r.term,
                r.params.as_deref(),
            )?;
            let when = match &r.when {
                Some(t) => Some(NamedTerm {
                    name: format!("{n}.when"),
                    term: configure(
                        ctx,
                        &mut cfg,
                        format!("{path}.rewards[\"{n}\"].when"),
                        &t.term,
                        t.params.as_deref(),
                    )?,
                }),
                None => None,
            };
            rewards.push(RewardTerm {
                term: NamedTerm {
                    name: n.clone(),
                    term,
                },
                weight: r.weight,
                dt_scaled: r.dt_scaled,
                when,
            });
        }
        let named = |section: &str,
                     m: &BTreeMap<String, crate::desc::TermDesc>,
                     cfg: &mut Configure|
         -> Result<Vec<NamedTerm>, SceneError> {
            m.iter()
                .map(|(n, t)| {
                    Ok(NamedTerm {
                        name: n.clone(),
                        term: configure(
                            ctx,
                            cfg,
                            format!("{path}.{section}[\"{n}\"]"),
                            &t.term,
                            t.params.as_deref(),
                        )?,
                    })
                })
                .collect()
        };
        let success = named("success", &desc.success, &mut cfg)?;
        let terminations = named("terminations", &desc.terminations, &mut cfg)?;
        let mut groups = Vec::new();
        for (g, gd) in &desc.observations {
            let gpath = format!("{path}.observations[\"{g}\"]");
            if gd.history == 0 || gd.history > 64 {
                return Err(serr(
                    &format!("{gpath}.history"),
                    gd.history.to_string(),
                    "1..=64 frames",
                ));
            }
            if !(gd.noise.is_finite() && gd.noise >= 0.0) {
                return Err(serr(
                    &format!("{gpath}.noise"),
                    gd.noise.to_string(),
                    "a finite noise >= 0",
                ));
            }
            let mut terms = Vec::new();
            for (i, t) in gd.terms.iter().enumerate() {
                let tpath = format!("{gpath}.terms[{i}]");
                if let Some((lo, hi)) = t.clip {
                    if lo
                        .partial_cmp(&hi)
                        .is_none_or(|o| o == std::cmp::Ordering::Greater)
                    {
                        return Err(serr(
                            &format!("{tpath}.clip"),
                            format!("({lo}, {hi})"),
                            "lo <= hi",
                        ));
                    }
                }
                if t.scale.is_some_and(|s| !s.is_finite()) {
                    return Err(serr(
                        &format!("{tpath}.scale"),
                        format!("{:?}", t.scale),
                        "a finite scale",
                    ));
                }
                terms.push(ObsTerm {
                    term: NamedTerm {
                        name: t.term.clone(),
                        term: configure(ctx, &mut cfg, tpath, &t.term, t.params.as_deref())?,
                    },
                    scale: t.scale.unwrap_or(1.0),
                    clip: t.clip,
                });
            }
            if g == "policy" {
                if let Some(c) = &desc.camera_observation {
                    terms.push(ObsTerm {
                        term: NamedTerm {
                            name: "camera".to_string(),
                            term: crate::terms::camera_term(c.clone(), &cfg).map_err(|e| {
                                serr(&format!("{path}.camera_observation"), format!("{c:?}"), e)
                            })?,
                        },
                        scale: 1.0,
                        clip: None,
                    });
                }
            }
            groups.push(Group {
                name: g.clone(),
                terms,
                noise: gd.noise,
                history: gd.history,
            });
        }
        if desc.camera_observation.is_some() && !desc.observations.contains_key("policy") {
            return Err(serr(
                &format!("{path}.camera_observation"),
                format!("{:?}", desc.camera_observation),
                "a task with a \"policy\" observation group to append the image to",
            ));
        }
        if !desc.observations.is_empty() && !desc.observations.contains_key("policy") {
            return Err(serr(
                &format!("{path}.observations"),
                format!("{:?}", desc.observations.keys().collect::<Vec<_>>()),
                "a group named \"policy\" (the env's observation)",
            ));
        }
        crate::expert::check_route(&desc)
            .map_err(|(field, value, msg)| serr(&format!("{path}.{field}"), value, msg))?;
        for (n, e) in &desc.events {
            check_event(&format!("{path}.events[\"{n}\"]"), e, &cfg, None)?;
        }
        let points = cfg.table;
        let success_bonus = desc.success_bonus.unwrap_or(0.0);
        Ok(Arc::new(TaskModel {
            named: named_ids,
            robot: desc.robot.clone().unwrap_or_else(|| "robot".to_string()),
            events: desc.events.clone().into_iter().collect(),
            desc,
            points,
            targets,
            rewards,
            success,
            success_bonus,
            terminations,
            groups,
        }))
    }

    fn spawn(&self, app: &mut SimApp, compiled: &CompiledSection) -> Result<(), SceneError> {
        let model = compiled.clone().downcast::<TaskModel>().map_err(|_| {
            serr(
                "extensions[\"task\"]",
                "(compiled)",
                "a section compiled by the tasks plugin",
            )
        })?;
        let path = "extensions[\"task\"]";
        let (dims, arm_joints, leg_joints, base_height) = {
            let robots = app.world.get_resource::<Robots>();
            let ctx = app.world.get_resource::<RigidContext>();
            let (Some(robots), Some(ctx)) = (robots, ctx) else {
                return Err(serr(
                    path,
                    model.robot.clone(),
                    "a task needs the robots section with its robot",
                ));
            };
            let r = robots.get(&model.robot).ok_or_else(|| {
                serr(
                    &format!("{path}.robot"),
                    model.robot.clone(),
                    "the name of a robot of the robots section",
                )
            })?;
            let mut arm = r.fixed.arm.clone();
            arm.push(r.fixed.gripper);
            let obs = r
                .observe(ctx)
                .map_err(|e| serr(path, model.robot.clone(), e.to_string()))?;
            (
                Dims {
                    arm: arm.len(),
                    legs: r.fixed.legs.len(),
                },
                arm,
                r.fixed.legs.clone(),
                obs.base.translation.z,
            )
        };
        type Spawned = (Entity, Vec<Vector3<f64>>, Isometry3<f64>);
        let mut by_name: BTreeMap<String, Spawned> = BTreeMap::new();
        let mut q = app
            .world
            .query::<(Entity, &Object, Option<&DeformableNodes>, Option<&Pose>)>();
        for (e, o, n, p) in q.iter(&app.world) {
            by_name.insert(
                o.name.clone(),
                (
                    e,
                    n.map(|n| n.0.clone()).unwrap_or_default(),
                    p.map_or(Isometry3::identity(), |p| p.0),
                ),
            );
        }
        let local = |name: &str| -> Result<(Entity, Vec<Vector3<f64>>), SceneError> {
            let (e, nodes, pose) = by_name
                .get(name)
                .ok_or_else(|| serr(path, name, "a scene object"))?;
            if nodes.is_empty() {
                return Err(serr(
                    path,
                    name,
                    "a deformable object (fem.solid, pbd.cloth)",
                ));
            }
            let inv = pose.inverse();
            Ok((
                *e,
                nodes
                    .iter()
                    .map(|p| (inv * Point3::from(*p)).coords)
                    .collect(),
            ))
        };
        let mut points: Vec<Resolved> = Vec::new();
        let n_stages = |points: &[Resolved]| {
            points
                .iter()
                .filter(|r| matches!(r, Resolved::Stages { .. }))
                .count()
        };
        for p in &model.points {
            points.push(match p {
                PointRef::Target(t) => Resolved::Target(model.target_index(t).unwrap_or(0)),
                PointRef::Base => Resolved::Base,
                PointRef::Ee => Resolved::Ee,
                PointRef::Object(o) => Resolved::Object(o.clone()),
                PointRef::Centroid(o) => {
                    let (e, l) = local(o)?;
                    Resolved::Nodes {
                        object: e,
                        nodes: (0..l.len() as u32).collect(),
                    }
                }
                PointRef::Nodes { object, select } => {
                    let (e, l) = local(object)?;
                    let nodes =
                        select.select(&format!("{path}.points (object \"{object}\")"), &l)?;
                    Resolved::Nodes { object: e, nodes }
                }
                PointRef::Tracked { object, i, k } => {
                    let (e, l) = local(object)?;
                    let n = tracked_nodes(&l, *k);
                    Resolved::Nodes {
                        object: e,
                        nodes: vec![n[*i]],
                    }
                }
                PointRef::Const(c) => Resolved::Const(Vector3::new(c.0, c.1, c.2)),
                PointRef::Stages { stages, by, reach } => {
                    let index = |q: &PointRef| {
                        model.points.iter().position(|x| x == q).ok_or_else(|| {
                            serr(path, format!("{q:?}"), "an interned point (internal)")
                        })
                    };
                    Resolved::Stages {
                        stages: stages.iter().map(index).collect::<Result<_, _>>()?,
                        by: index(by)?,
                        reach: *reach,
                        slot: n_stages(&points),
                    }
                }
                PointRef::Point(_) => return Err(serr(path, format!("{p:?}"), "a resolved point")),
            });
        }
        let cloths: Vec<(String, Entity)> = app
            .world
            .get_resource::<PbdContext>()
            .map(|c| {
                c.bodies
                    .iter()
                    .filter_map(|b| {
                        by_name
                            .iter()
                            .find(|(_, (e, _, _))| *e == b.entity)
                            .map(|(n, _)| (n.clone(), b.entity))
                    })
                    .collect()
            })
            .unwrap_or_default();
        if let Some(h) = &model.desc.held {
            let hpath = format!("{path}.held");
            let (e, l) = local(&h.object)?;
            let nodes = h.select.select(&hpath, &l)?;
            let robots = app.world.resource::<Robots>();
            let rt = robots
                .get(&model.robot)
                .ok_or_else(|| serr(&hpath, model.robot.clone(), "a robot"))?;
            let body = rt.fixed.gripper_body_id;
            let force_limit = rt.fixed.grasp_force_limit;
            if h.grasp && !rt.gripper_closed {
                return Err(serr(
                    &format!("{hpath}.grasp"),
                    "true",
                    format!(
                        "a robot whose gripper starts closed (robot \"{}\": start_closed: true); an open gripper releases the grasp at the first step",
                        model.robot
                    ),
                ));
            }
            let pose = app
                .world
                .resource::<RigidContext>()
                .body_pose(body)
                .ok_or_else(|| serr(&hpath, model.robot.clone(), "a robot with a gripper body"))?;
            let mut fem = app
                .world
                .get_resource_mut::<FemContext>()
                .ok_or_else(|| serr(&hpath, h.object.clone(), "the FEM plugin"))?;
            let solid = fem.get_mut(e).ok_or_else(|| {
                serr(
                    &format!("{hpath}.object"),
                    h.object.clone(),
                    "a fem.solid object",
                )
            })?;
            let held = if h.grasp {
                let params = GraspParams::for_gripper(force_limit, nodes.len());
                solid.grasp(body, pose, &nodes, params)
            } else {
                solid.attach_to_body(body, pose, &nodes)
            };
            held.map_err(|er| serr(&hpath, format!("{} nodes", nodes.len()), er.to_string()))?;
        }
        let stage_slots = n_stages(&points);
        let frame_item_lens = model
            .groups
            .iter()
            .map(|g| {
                if has_images(g) {
                    frame_items(g, &dims)
                        .iter()
                        .map(|(_, s)| s.flat_dim())
                        .collect()
                } else {
                    vec![g.terms.iter().map(|t| t.term.term.dim(&dims)).sum()]
                }
            })
            .collect::<Vec<_>>()
            .into();
        let task = Task {
            model: model.clone(),
            points,
            dims,
            arm_joints,
            leg_joints,
            base_height,
            cloths,
            frame_item_lens,
        };
        let observation = model
            .groups
            .iter()
            .find(|g| g.name == "policy")
            .map_or(Space::unbounded(0), |g| policy_space(g, &dims));
        let cameras: BTreeSet<String> = model
            .groups
            .iter()
            .flat_map(|g| &g.terms)
            .filter_map(|t| t.term.term.image().map(|(c, _, _)| c.to_string()))
            .collect();
        if !cameras.is_empty() {
            let mut requests = app
                .world
                .get_resource_mut::<CameraRequests>()
                .ok_or_else(|| {
                    serr(
                        &format!("{path}.observations"),
                        format!("cameras {cameras:?}"),
                        "the render plugin (modesuite.render) for image observations",
                    )
                })?;
            requests.0.extend(cameras);
        }
        let state = TaskState {
            targets: model.targets.iter().map(|(_, t)| t.pos).collect(),
            prev_action: Vec::new(),
            history: vec![VecDeque::new(); model.groups.len()],
            success: false,
            stages: vec![0; stage_slots],
            next_event: Vec::new(),
        };
        app.world.insert_resource(task);
        app.world.insert_resource(state);
        app.world.insert_resource(TaskObservations::default());
        app.world.insert_resource(TaskPoints::default());
        app.world.insert_resource(TaskStartup::default());
        app.register_stateful::<TaskState>();
        let mut s = app.world.get_resource_or_insert_with(Spaces::default);
        if !model.groups.is_empty() {
            s.observation = observation;
        }
        Ok(())
    }
}

/// The space of the `policy` group: one unbounded box of every run of state terms (its
/// `history` frames one after another) or, with camera terms, a `Dict` of the items of
/// [`frame_items`], each with a leading axis of `history` frames (oldest first) when the group
/// stacks more than one: `state` of shape (history, n), an image of shape (history, height,
/// width, channels), the layout of Gymnasium's frame stacking.
fn policy_space(g: &Group, dims: &Dims) -> Space {
    if !has_images(g) {
        let dim: usize = g.terms.iter().map(|t| t.term.term.dim(dims)).sum();
        return Space::unbounded(g.history * dim);
    }
    let items = frame_items(g, dims);
    if g.history == 1 {
        return Space::Dict(items);
    }
    let stack = |s: Space| match s {
        Space::Box { low, high, shape } => Space::Box {
            low: low.repeat(g.history),
            high: high.repeat(g.history),
            shape: [&[g.history][..], &shape].concat(),
        },
        other => other,
    };
    Space::Dict(items.into_iter().map(|(n, s)| (n, stack(s))).collect())
}

/// Whether a group has camera images (its observation is then a `Dict`).
fn has_images(g: &Group) -> bool {
    g.terms.iter().any(|t| t.term.term.image().is_some())
}

/// The items of one frame of a group with camera images, in buffer order: each run of state
/// terms (`state`, `state_1`, ...; an unbounded box) and each image (`<camera>_<channels>`, a box
/// of shape (height, width, channels)).
fn frame_items(g: &Group, dims: &Dims) -> Vec<(String, Space)> {
    let mut items: Vec<(String, Space)> = Vec::new();
    let mut run = 0usize;
    let mut states = 0usize;
    let mut flush = |run: &mut usize, items: &mut Vec<(String, Space)>| {
        if *run > 0 {
            let name = if states == 0 {
                "state".to_string()
            } else {
                format!("state_{states}")
            };
            states += 1;
            items.push((name, Space::unbounded(*run)));
            *run = 0;
        }
    };
    for t in &g.terms {
        match t.term.term.image() {
            None => run += t.term.term.dim(dims),
            Some((camera, channels, shape)) => {
                flush(&mut run, &mut items);
                let n: usize = shape.iter().product();
                items.push((
                    format!("{camera}_{}", channels.name()),
                    Space::Box {
                        low: vec![0.0; n],
                        high: vec![f32::INFINITY; n],
                        shape: shape.to_vec(),
                    },
                ));
            }
        }
    }
    flush(&mut run, &mut items);
    items
}

/// The task managers' sets. Other plugins that write `StepSignals` or the observation buffer
/// order themselves `.after(TaskSystems::Evaluate)` / `.after(TaskSystems::Observe)` (the
/// managers run first; later systems may add to the reward or the observation).
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub enum TaskSystems {
    /// Reset and startup events (in `EnvSystems::Reset`).
    Reset,
    /// Interval events (after `EnvSystems::ProcessActions`, before `EnvSystems::Simulate`).
    Interval,
    /// Rewards, success, terminations (in `EnvSystems::Evaluate`, before the time limit).
    Evaluate,
    /// Observation groups (in `EnvSystems::Observe`).
    Observe,
}

/// Adds the task systems (the section spawns the resources they need).
pub fn add_task_systems(app: &mut SimApp) {
    app.configure_sets(
        modesuite_engine::EnvStep,
        (
            TaskSystems::Reset.in_set(EnvSystems::Reset),
            TaskSystems::Interval
                .after(EnvSystems::ProcessActions)
                .before(EnvSystems::Simulate),
            TaskSystems::Evaluate
                .in_set(EnvSystems::Evaluate)
                .before(EngineSystems::TimeLimit),
            TaskSystems::Observe.in_set(EnvSystems::Observe),
        ),
    );
    app.add_systems(
        modesuite_engine::EnvStep,
        task_reset.in_set(TaskSystems::Reset),
    );
    app.add_systems(
        modesuite_engine::EnvStep,
        task_interval_events.in_set(TaskSystems::Interval),
    );
    app.add_systems(
        modesuite_engine::EnvStep,
        task_evaluate.in_set(TaskSystems::Evaluate),
    );
    app.add_systems(
        modesuite_engine::EnvStep,
        task_observe.in_set(TaskSystems::Observe),
    );
}

/// The task's points now, in point order; a `Stages` point moves on to its next stage when
/// its follower is within reach of the current one (progress kept in `state.stages`).
fn resolve_points(
    task: &Task,
    state: &mut TaskState,
    robot: &RobotObservation,
    world: &modesuite_engine::terms::WorldView,
    nodes: &Query<&DeformableNodes>,
) -> Result<Vec<Vector3<f64>>, String> {
    let mut out: Vec<Vector3<f64>> = Vec::with_capacity(task.points.len());
    for p in &task.points {
        let v = match p {
            Resolved::Target(i) => state.targets.get(*i).copied().unwrap_or_default(),
            Resolved::Base => robot.base.translation.vector,
            Resolved::Ee => robot.ee.translation.vector,
            Resolved::Object(o) => world
                .object(o)
                .map(|v| v.pose.translation.vector)
                .ok_or_else(|| format!("object \"{o}\" is gone"))?,
            Resolved::Nodes { object, nodes: idx } => {
                let n = nodes
                    .get(*object)
                    .map_err(|_| "a deformable object lost its nodes".to_string())?;
                let mut c = Vector3::zeros();
                for &i in idx {
                    c += n.0[i as usize];
                }
                c / idx.len().max(1) as f64
            }
            Resolved::Const(c) => *c,
            Resolved::Stages {
                stages,
                by,
                reach,
                slot,
            } => {
                let k = &mut state.stages[*slot];
                while *k + 1 < stages.len() && (out[*by] - out[stages[*k]]).xy().norm() < *reach {
                    *k += 1;
                }
                out[stages[*k]]
            }
        };
        out.push(v);
    }
    Ok(out)
}

/// Evaluates one term into a fresh buffer, checking its values.
fn eval(t: &NamedTerm, ctx: &TaskCtx, dims: &Dims, what: &str) -> Result<Vec<f64>, String> {
    let mut out = vec![0.0; t.term.dim(dims)];
    let what = format!("task {what}");
    t.term
        .evaluate(ctx, &mut out)
        .map_err(|e| format!("{what} term \"{}\": {e}", t.name))?;
    check_finite(&what, &t.name, &out)?;
    Ok(out)
}

/// What the evaluate and observe systems read to build a term context.
#[derive(bevy_ecs::system::SystemParam)]
struct TaskWorld<'w, 's> {
    task: Option<Res<'w, Task>>,
    state: Option<ResMut<'w, TaskState>>,
    robots: Option<Res<'w, Robots>>,
    rigid: Option<Res<'w, RigidContext>>,
    view: ViewQuery<'w, 's>,
    nodes: Query<'w, 's, &'static DeformableNodes>,
    clock: Res<'w, SimClock>,
    settings: Res<'w, SimSettings>,
    pbd: Option<Res<'w, PbdContext>>,
    action: Res<'w, ActionBuffer>,
    names: Query<'w, 's, &'static Object>,
    images: Option<Res<'w, CameraImages>>,
}

impl TaskWorld<'_, '_> {
    /// Runs `f` with the term context and the task state (`None`: this env has no task).
    fn with_ctx<R>(
        &mut self,
        f: impl FnOnce(&Task, &TaskCtx) -> R,
    ) -> Option<Result<(R, &mut TaskState), String>> {
        let (Some(task), Some(state), Some(robots), Some(rigid)) = (
            self.task.as_deref(),
            self.state.as_deref_mut(),
            self.robots.as_deref(),
            self.rigid.as_deref(),
        ) else {
            return None;
        };
        let action = &self.action.0[..];
        let world = world_view(&self.view, &self.clock, &self.settings);
        let r = (|| {
            let robot = robots
                .get(&task.model.robot)
                .ok_or_else(|| format!("robot \"{}\" is gone", task.model.robot))?
                .observe(rigid)
                .map_err(|e| e.to_string())?;
            let points = resolve_points(task, state, &robot, &world, &self.nodes)?;
            let touching: Vec<&str> = robot
                .touching
                .iter()
                .filter_map(|id| rigid.body_of_id(*id))
                .filter_map(|(_, e)| self.names.get(e).ok())
                .map(|o| o.name.as_str())
                .collect();
            let cloths: Vec<(&str, &Cloth)> = match self.pbd.as_deref() {
                Some(p) => task
                    .cloths
                    .iter()
                    .filter_map(|(n, e)| p.get(*e).map(|c| (n.as_str(), c)))
                    .collect(),
                None => Vec::new(),
            };
            let zeros = vec![0.0f32; action.len()];
            let prev = if state.prev_action.len() == action.len() {
                &state.prev_action[..]
            } else {
                &zeros[..]
            };
            let ctx = TaskCtx {
                world: &world,
                robot: &robot,
                arm_joints: &task.arm_joints,
                leg_joints: &task.leg_joints,
                points: &points,
                action,
                prev_action: prev,
                cloths: &cloths,
                base_height: task.base_height,
                touching: &touching,
                images: self.images.as_deref(),
            };
            Ok(f(task, &ctx))
        })();
        Some(r.map(|v| (v, state)))
    }
}

fn task_evaluate(
    mut tw: TaskWorld,
    mut signals: ResMut<StepSignals>,
    mut errors: ResMut<SimErrors>,
) {
    let step_dt = tw.settings.dt * f64::from(tw.settings.decimation);
    let action = tw.action.0.clone();
    let result = tw.with_ctx(|task, ctx| -> Result<(), String> {
        let (m, dims) = (&task.model, task.dims);
        for r in &m.rewards {
            if let Some(w) = &r.when {
                if eval(w, ctx, &dims, "reward")?[0] == 0.0 {
                    signals.add_reward(&r.term.name, 0.0);
                    continue;
                }
            }
            let v = eval(&r.term, ctx, &dims, "reward")?[0];
            let w = r.weight * if r.dt_scaled { step_dt } else { 1.0 };
            signals.add_reward(&r.term.name, w * v);
        }
        let mut ok = !m.success.is_empty();
        for s in &m.success {
            let v = eval(s, ctx, &dims, "success")?[0];
            signals.values.insert(format!("success/{}", s.name), v);
            ok &= v != 0.0;
        }
        for t in &m.terminations {
            let v = eval(t, ctx, &dims, "termination")?[0];
            signals.values.insert(format!("termination/{}", t.name), v);
            if v != 0.0 {
                signals.terminated = true;
            }
        }
        if !m.success.is_empty() {
            signals.success = Some(ok);
            if ok {
                signals.terminated = true;
                signals.add_reward("success_bonus", m.success_bonus);
            }
        }
        Ok(())
    });
    match result {
        None => {}
        Some(Ok((Ok(()), state))) => {
            state.success = signals.success == Some(true);
            state.prev_action = action;
        }
        Some(Ok((Err(e), _)) | Err(e)) => errors.raise(e),
    }
}

fn task_observe(
    mut tw: TaskWorld,
    mut rng: ResMut<EnvRng>,
    mut buffer: ResMut<ObservationBuffer>,
    mut all: ResMut<TaskObservations>,
    mut named: ResMut<TaskPoints>,
    mut errors: ResMut<SimErrors>,
) {
    let first = tw.clock.episode_steps == 0;
    let Some((model, item_lens)) = tw
        .task
        .as_deref()
        .map(|t| (t.model.clone(), t.frame_item_lens.clone()))
    else {
        return;
    };
    let result = tw.with_ctx(|task, ctx| -> Result<Vec<Vec<f32>>, String> {
        let (m, dims) = (&task.model, task.dims);
        named.0.clear();
        for (n, id) in &m.named {
            named.0.insert(n.clone(), ctx.point(*id));
        }
        m.groups
            .iter()
            .map(|g| {
                let mut frame = Vec::new();
                for t in &g.terms {
                    for v in eval(&t.term, ctx, &dims, "observation")? {
                        let mut x = v * t.scale;
                        if let Some((lo, hi)) = t.clip {
                            x = x.clamp(lo, hi);
                        }
                        frame.push(x as f32);
                    }
                }
                Ok(frame)
            })
            .collect()
    });
    let (frames, state) = match result {
        None => return,
        Some(Ok((Ok(f), state))) => (f, state),
        Some(Ok((Err(e), _)) | Err(e)) => {
            errors.raise(e);
            return;
        }
    };
    for (k, (g, mut frame)) in model.groups.iter().zip(frames).enumerate() {
        if g.noise > 0.0 {
            for x in frame.iter_mut() {
                *x += rng.range(-g.noise, g.noise) as f32;
            }
        }
        let h = &mut state.history[k];
        if first {
            // A new episode starts with its first frame repeated.
            h.clear();
            for _ in 1..g.history {
                h.push_back(frame.clone());
            }
        }
        h.push_back(frame);
        while h.len() > g.history {
            h.pop_front();
        }
        // item by item (state, each image), each item's frames oldest first
        let mut flat = Vec::with_capacity(h.iter().map(Vec::len).sum());
        let mut at = 0;
        for &len in &item_lens[k] {
            for f in h.iter() {
                flat.extend_from_slice(&f[at..at + len]);
            }
            at += len;
        }
        if g.name == "policy" {
            buffer.0.clone_from(&flat);
        }
        all.0.insert(g.name.clone(), flat);
    }
}

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
struct EventWorld<'w, 's> {
    robots: Option<Res<'w, Robots>>,
    rigid: Option<ResMut<'w, RigidContext>>,
    rng: ResMut<'w, EnvRng>,
    fem: Option<ResMut<'w, FemContext>>,
    pbd: Option<ResMut<'w, PbdContext>>,
    nodes: Query<'w, 's, (Entity, &'static Object, &'static mut DeformableNodes)>,
    bodies: Query<'w, 's, (&'static Object, &'static RigidRef)>,
    errors: ResMut<'w, SimErrors>,
}

impl EventWorld<'_, '_> {
    /// Moves a deformable rigidly (its solver and its nodes component).
    fn move_object(&mut self, name: &str, iso: &Isometry3<f64>) -> Result<(), String> {
        let Some((e, _, mut n)) = self.nodes.iter_mut().find(|(_, o, _)| o.name == name) else {
            return Err(format!(
                "object \"{name}\" is not a deformable (fem.solid, pbd.cloth) a task can move"
            ));
        };
        let moved: Vec<Vector3<f64>> =
            n.0.iter()
                .map(|p| (iso * Point3::from(*p)).coords)
                .collect();
        if let Some(s) = self.fem.as_deref_mut().and_then(|f| f.get_mut(e)) {
            let vel: Vec<Vector3<f64>> = s.velocities().iter().map(|v| iso.rotation * v).collect();
            s.set_positions_velocities(&moved, &vel)
                .map_err(|e| e.to_string())?;
        } else if let Some(c) = self.pbd.as_deref_mut().and_then(|p| p.get_mut(e)) {
            c.set_positions(&moved).map_err(|e| e.to_string())?;
        } else {
            return Err(format!(
                "object \"{name}\" is not a deformable this task can move"
            ));
        }
        n.0 = moved;
        Ok(())
    }

    /// Adds `dv` to the velocity of a deformable's nodes or of a free rigid body.
    fn push(&mut self, name: &str, dv: Vector3<f64>) -> Result<(), String> {
        if let Some((e, _, _)) = self.nodes.iter().find(|(_, o, _)| o.name == name) {
            if let Some(s) = self.fem.as_deref_mut().and_then(|f| f.get_mut(e)) {
                let vel: Vec<Vector3<f64>> = s.velocities().iter().map(|v| v + dv).collect();
                let pos = s.positions().to_vec();
                return s
                    .set_positions_velocities(&pos, &vel)
                    .map_err(|e| e.to_string());
            }
            if let Some(c) = self.pbd.as_deref_mut().and_then(|p| p.get_mut(e)) {
                let vel: Vec<Vector3<f64>> = c.velocities().iter().map(|v| v + dv).collect();
                return c.set_velocities(&vel).map_err(|e| e.to_string());
            }
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

    /// Draws and applies one event (`Startup`/`Interval` wrappers run their event now).
    fn apply(&mut self, robot_name: &str, e: &EventDesc) -> Result<(), String> {
        match e {
            EventDesc::Startup(inner) | EventDesc::Interval { event: inner, .. } => {
                self.apply(robot_name, inner)
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
                    self.move_object(c, &iso)?;
                }
                Ok(())
            }
            EventDesc::Friction { object, range } => {
                let f = self.rng.range(range.0, range.1);
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
            EventDesc::ObjectOffset { object, xy } => {
                let d = Vector3::new(self.rng.range(-xy, *xy), self.rng.range(-xy, *xy), 0.0);
                self.move_object(
                    object,
                    &Isometry3::from_parts(Translation3::from(d), UnitQuaternion::identity()),
                )
            }
            EventDesc::Material {
                object,
                youngs_modulus,
            } => {
                let value = self.rng.range(youngs_modulus.0, youngs_modulus.1);
                let solid = self
                    .nodes
                    .iter()
                    .find(|(_, o, _)| o.name == *object)
                    .and_then(|(e, _, _)| self.fem.as_deref_mut()?.get_mut(e))
                    .ok_or_else(|| {
                        format!("object \"{object}\" is not a fem.solid (Material sets a solid's Young's modulus)")
                    })?;
                solid
                    .set_youngs_modulus(value)
                    .map_err(|er| format!("object \"{object}\": {er}"))
            }
            EventDesc::Push { object, velocity } => {
                let (x, y, z) = *velocity;
                let dv = Vector3::new(
                    self.rng.range(-x, x),
                    self.rng.range(-y, y),
                    self.rng.range(-z, z),
                );
                self.push(object, dv)
            }
        }
    }

    /// Applies `e` and reports a failure as the env's error.
    fn run(&mut self, robot_name: &str, name: &str, e: &EventDesc) {
        if let Err(msg) = self.apply(robot_name, e) {
            self.errors.raise(format!("task event \"{name}\": {msg}"));
        }
    }
}

fn task_reset(
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
            ew.run(&m.robot, name, e);
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
            ew.run(&m.robot, name, e);
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
fn task_interval_events(
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
        ew.run(&m.robot, name, e);
        let gap = ew.rng.range(every.0, every.1);
        *next += gap;
        if *next <= clock.time {
            *next = clock.time + gap;
        }
    }
}
