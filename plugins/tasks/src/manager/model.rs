//! The task managers' types: the compiled [`TaskModel`], the per-env [`Task`] and
//! [`TaskState`], and the resources the systems publish.

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use bevy_ecs::prelude::*;
use modesuite_engine::state::{StateHasher, Stateful};
use nalgebra::Vector3;

use crate::desc::{EventDesc, PointRef, TaskDesc};
use crate::terms::{Dims, PointId, TaskTerm};

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
    /// The registered events (`Event(...)` entries) configured, by their key in `events`.
    pub custom_events: BTreeMap<String, Arc<dyn crate::events::TaskEvent>>,
    /// Named points and targets with their ids (published in [`TaskPoints`]).
    pub named: Vec<(String, PointId)>,
    /// The surface triangles of every deformable object, by name, as its body kind gives them
    /// (what the region terms measure).
    pub surfaces: BTreeMap<String, Arc<Vec<[u32; 3]>>>,
}

impl TaskModel {
    /// Index of a target.
    pub fn target_index(&self, name: &str) -> Option<usize> {
        self.targets.iter().position(|(n, _)| n == name)
    }
}

/// A point resolved in one env.
#[derive(Debug, Clone)]
pub(super) enum Resolved {
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

/// A deformable object with a surface: name, entity, triangles over its nodes.
pub(super) type SurfaceObject = (String, Entity, Arc<Vec<[u32; 3]>>);

/// The task of one env: the model and the points resolved at spawn (immutable).
#[derive(Resource, Clone)]
pub struct Task {
    /// The compiled task.
    pub model: Arc<TaskModel>,
    pub(super) points: Vec<Resolved>,
    /// Robot dimensions.
    pub dims: Dims,
    /// Arm joints (gripper last) and leg joints, indices into the robot's joints.
    pub arm_joints: Vec<usize>,
    /// Leg joint indices.
    pub leg_joints: Vec<usize>,
    /// Base height at spawn.
    pub base_height: f64,
    /// Deformable objects with a surface.
    pub(super) surfaces: Vec<SurfaceObject>,
    /// Per observation group: the lengths of a frame's items, in buffer order: the items of
    /// [`spaces::frame_items`] for a group with images, the whole frame otherwise. A group's
    /// buffer is item by item, each item's `history` frames oldest first (for one item or one
    /// frame, simply frame after frame).
    pub(super) frame_item_lens: Arc<Vec<Vec<usize>>>,
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
        modesuite_engine::state::restore_clone(self, state)
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
