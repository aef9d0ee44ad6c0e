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
//!
//! Files: `model` (the types), `section` (compile and spawn of the section), `compile` (its checks,
//! `extends` files, term configuration), `spaces` (observation spaces), `evaluate` (points,
//! rewards, observations) and `events` (reset, startup and interval events).

mod compile;
mod evaluate;
mod events;
mod model;
mod section;
mod spaces;

use bevy_ecs::prelude::*;
use modesuite_engine::{EngineSystems, EnvSystems, SimApp};

use evaluate::{task_evaluate, task_observe};
use events::{task_interval_events, task_reset};

pub use events::TaskStartup;
pub use model::{
    Group, NamedTerm, ObsTerm, RewardTerm, Target, Task, TaskModel, TaskObservations, TaskPoints,
    TaskState,
};
pub use section::TaskSection;

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
    // The events' changes to deformable solvers are commands: applied right after each system.
    app.add_systems(
        modesuite_engine::EnvStep,
        (task_reset, ApplyDeferred)
            .chain()
            .in_set(TaskSystems::Reset),
    );
    app.add_systems(
        modesuite_engine::EnvStep,
        (task_interval_events, ApplyDeferred)
            .chain()
            .in_set(TaskSystems::Interval),
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
