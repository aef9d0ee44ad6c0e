//! The `task` scene section: [`SceneSection`] for [`TaskSection`], compiling the section into
//! a [`TaskModel`] and spawning an env's [`Task`] and [`TaskState`].

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::Arc;

use bevy_ecs::prelude::*;
use modesuite_engine::components::{DeformableNodes, Object, Pose};
use modesuite_engine::deformable::deformable_mut;
use modesuite_engine::registry::{CompiledSection, SceneSection, SectionCompileContext};
use modesuite_engine::scene::BodyModel;
use modesuite_engine::scene::SceneError;
use modesuite_engine::{RigidContext, SimApp, Space, Spaces};
use modesuite_render::CameraRequests;
use modesuite_robots::Robots;
use nalgebra::{Isometry3, Point3, Vector3};

use super::compile::{check_event, configure, resolve_extends, scene_cameras, serr};
use super::events::TaskStartup;
use super::model::{
    Group, NamedTerm, ObsTerm, Resolved, RewardTerm, SurfaceObject, Target, Task, TaskModel,
    TaskObservations, TaskPoints, TaskState,
};
use super::spaces::{frame_items, has_images, policy_space};
use crate::desc::{PointRef, TaskDesc};
use crate::terms::{tracked_nodes, Configure, Dims};

/// The `task` scene section.
pub struct TaskSection;

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
        let mut custom_events = BTreeMap::new();
        for (n, e) in &desc.events {
            if let Some(c) = check_event(ctx, &format!("{path}.events[\"{n}\"]"), e, &cfg, None)? {
                custom_events.insert(n.clone(), c);
            }
        }
        let points = cfg.table;
        let success_bonus = desc.success_bonus.unwrap_or(0.0);
        let surfaces = ctx
            .objects
            .iter()
            .filter_map(|o| match &o.body {
                BodyModel::Plugin { kind, compiled } => kind
                    .surface_triangles(compiled)
                    .map(|t| (o.name.clone(), Arc::new(t))),
                _ => None,
            })
            .collect();
        Ok(Arc::new(TaskModel {
            surfaces,
            named: named_ids,
            robot: desc.robot.clone().unwrap_or_else(|| "robot".to_string()),
            events: desc.events.clone().into_iter().collect(),
            custom_events,
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
        let surfaces: Vec<SurfaceObject> = model
            .surfaces
            .iter()
            .filter_map(|(n, t)| by_name.get(n).map(|(e, _, _)| (n.clone(), *e, t.clone())))
            .collect();
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
            let solver = deformable_mut(&mut app.world, e).ok_or_else(|| {
                serr(
                    &format!("{hpath}.object"),
                    h.object.clone(),
                    "a deformable object whose solver can hold nodes (fem.solid)",
                )
            })?;
            solver
                .hold_nodes(body, &pose, &nodes, h.grasp.then_some(force_limit))
                .map_err(|er| serr(&hpath, format!("{} nodes", nodes.len()), er))?;
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
            surfaces,
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
