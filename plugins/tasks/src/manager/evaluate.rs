//! The per-step systems: resolving the task's points, the term context ([`TaskWorld`]),
//! `task_evaluate` (rewards, success, terminations) and `task_observe` (observation groups).

use bevy_ecs::prelude::*;
use modesuite_engine::components::{DeformableNodes, Object};
use modesuite_engine::env::{ActionBuffer, ObservationBuffer, StepSignals};
use modesuite_engine::rng::EnvRng;
use modesuite_engine::state::PluginStates;
use modesuite_engine::surface::Surface;
use modesuite_engine::terms::{check_finite, world_view, ViewQuery};
use modesuite_engine::{RigidContext, SimClock, SimErrors, SimSettings};
use modesuite_render::CameraImages;
use modesuite_robots::{RobotObservation, Robots};
use nalgebra::Vector3;

use super::model::{NamedTerm, Resolved, Task, TaskObservations, TaskPoints, TaskState};
use crate::terms::{Dims, TaskCtx};

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
pub(super) struct TaskWorld<'w, 's> {
    task: Option<Res<'w, Task>>,
    state: Option<ResMut<'w, TaskState>>,
    robots: Option<Res<'w, Robots>>,
    rigid: Option<Res<'w, RigidContext>>,
    view: ViewQuery<'w, 's>,
    nodes: Query<'w, 's, &'static DeformableNodes>,
    clock: Res<'w, SimClock>,
    settings: Res<'w, SimSettings>,
    action: Res<'w, ActionBuffer>,
    names: Query<'w, 's, &'static Object>,
    images: Option<Res<'w, CameraImages>>,
    states: Option<ResMut<'w, PluginStates>>,
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
        // Engine terms in the task may write plugin state slots: lent for the evaluation.
        let states = std::cell::RefCell::new(
            self.states
                .as_deref_mut()
                .map(std::mem::take)
                .unwrap_or_default(),
        );
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
            let surfaces: Vec<(&str, Surface)> = task
                .surfaces
                .iter()
                .filter_map(|(n, e, triangles)| {
                    let nodes = &self.nodes.get(*e).ok()?.0;
                    Some((n.as_str(), Surface { nodes, triangles }))
                })
                .collect();
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
                surfaces: &surfaces,
                base_height: task.base_height,
                touching: &touching,
                images: self.images.as_deref(),
                states: &states,
            };
            Ok(f(task, &ctx))
        })();
        if let Some(s) = self.states.as_deref_mut() {
            *s = states.into_inner();
        }
        Some(r.map(|v| (v, state)))
    }
}

pub(super) fn task_evaluate(
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

pub(super) fn task_observe(
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
                        let y = x as f32;
                        if !y.is_finite() {
                            return Err(format!(
                                "task observation term \"{}\" = {x}: outside the f32 range of observations (|x| <= {:e}); give it a smaller scale or a clip",
                                t.term.name,
                                f32::MAX
                            ));
                        }
                        frame.push(y);
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
