//! The settings, clock and error list every system reads: plain resources with no dependency
//! on the application layer, so terms, solvers and scenes below [`crate::app`] can use them.
//! [`crate::app`] re-exports them (`modesuite_engine::app::SimSettings` and the crate root name
//! the same types).

use bevy_ecs::prelude::*;

use crate::state::Stateful;

/// Which pass of [`EnvStep`](crate::EnvStep) is running.
#[derive(Resource, Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Phase {
    /// A normal step: actions, simulation, evaluation.
    #[default]
    Step,
    /// The pass after a snapshot restore: reset events, sensing and observation only.
    Reset,
}

/// Timing of the simulation, fixed per scene.
#[derive(Resource, Debug, Clone, Copy, PartialEq)]
pub struct SimSettings {
    /// Physics step in seconds.
    pub dt: f64,
    /// Substeps per physics step (each `dt / substeps` seconds).
    pub substeps: u32,
    /// Physics steps per env step.
    pub decimation: u32,
    /// Gravity in the world frame, m/s^2 (z up).
    pub gravity: nalgebra::Vector3<f64>,
    /// Internal solver substeps of each rapier step.
    pub rigid_iterations: u32,
    /// Projected Gauss-Seidel sweeps per internal solver substep.
    pub rigid_pgs_iterations: u32,
    /// Friction also in rapier's position-correcting (bias) pass.
    pub rigid_friction_in_bias_pass: bool,
    /// Substeps per deformable step (1: every substep; the scene's `physics.substeps /
    /// physics.deformable_substeps`): deformable bodies step at the first substep of every
    /// `deformable_stride`, over that many substeps' time, before the rigid world's substep.
    pub deformable_stride: u32,
    /// Deformable steps per substep (1: one; the scene's `physics.deformable_substeps /
    /// physics.substeps` when that is larger): each substep's deformable step is split into
    /// this many, the `i`-th (from 0) following the rigid bodies to their poses
    /// `(i + 1) / deformable_inner` of the way through the last rigid substep
    /// (`RigidContext::body_pose_between`), while colliders are extrapolated from
    /// `i * substep / deformable_inner` after the rigid state.
    pub deformable_inner: u32,
    /// Linear speed (m/s) of a rigid body, by its velocity or by its displacement over a rapier
    /// step, above which the rigid physics is reported as blown up (the episode ends with an
    /// error naming the body).
    pub max_body_speed: f64,
    /// Substeps the engine adds to every scene substep in the current physics step (1: none):
    /// set at the start of each physics step from the stiffness of the deformables that
    /// dynamic scene bodies heavier than them press onto supports
    /// (`crate::contact::support`); never set by a scene.
    pub coupling_substeps: u32,
}

/// Default of [`SimSettings::max_body_speed`] and the scene's `physics.max_body_speed`, m/s.
pub const DEFAULT_MAX_BODY_SPEED: f64 = 100.0;

impl Default for SimSettings {
    fn default() -> Self {
        Self {
            dt: 1.0 / 60.0,
            substeps: 1,
            decimation: 1,
            gravity: nalgebra::Vector3::new(0.0, 0.0, -9.81),
            rigid_iterations: 4,
            rigid_pgs_iterations: 1,
            rigid_friction_in_bias_pass: false,
            deformable_stride: 1,
            deformable_inner: 1,
            max_body_speed: DEFAULT_MAX_BODY_SPEED,
            coupling_substeps: 1,
        }
    }
}

impl SimSettings {
    /// Substeps in the current physics step: the scene's times the engine's
    /// [`SimSettings::coupling_substeps`].
    pub fn step_substeps(&self) -> u32 {
        self.substeps.max(1) * self.coupling_substeps.max(1)
    }

    /// Substep length in seconds (in the current physics step).
    pub fn substep_dt(&self) -> f64 {
        self.dt / f64::from(self.step_substeps())
    }

    /// The scene's substep length in seconds, without the engine's coupling substeps.
    pub fn scene_substep_dt(&self) -> f64 {
        self.dt / f64::from(self.substeps.max(1))
    }
}

/// Counters of the simulation (part of the env state).
#[derive(
    Resource, Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize,
)]
pub struct SimClock {
    /// Env steps since the episode started.
    pub episode_steps: u64,
    /// Physics steps since the episode started.
    pub physics_steps: u64,
    /// Substeps since the episode started.
    pub substeps: u64,
    /// Simulated seconds since the episode started.
    pub time: f64,
}

crate::persist_by_serde!(SimClock);

impl Stateful for SimClock {
    fn save_state(&self) -> Box<dyn std::any::Any + Send + Sync> {
        Box::new(*self)
    }
    fn load_state(
        &mut self,
        state: &(dyn std::any::Any + Send + Sync),
    ) -> Result<(), crate::codec::StateError> {
        crate::state::restore_clone(self, state)
    }
    fn hash_state(&self, h: &mut crate::state::StateHasher) {
        h.write_u64(self.episode_steps);
        h.write_u64(self.physics_steps);
        h.write_u64(self.substeps);
        h.write_f64(self.time);
    }
}

/// Errors the simulation reports instead of panicking (physics blow-ups, plugin failures).
/// Systems push into this; the env ends the episode with the reason in `info["error"]`.
#[derive(Resource, Debug, Clone, Default)]
pub struct SimErrors {
    /// Errors raised during the current env step (cleared at the start of each step).
    pub current: Vec<String>,
    /// Total errors since the env was created (not reset by episodes).
    pub total: u64,
}

impl SimErrors {
    /// Record an error; the env ends the episode after this step.
    pub fn raise(&mut self, message: impl Into<String>) {
        self.current.push(message.into());
        self.total += 1;
    }
}

/// Episode length limit in env steps (the engine truncates at this count).
#[derive(Resource, Debug, Clone, Copy, PartialEq, Eq)]
pub struct EpisodeLimit(pub Option<u64>);
