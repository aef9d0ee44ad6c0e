//! `SimApp` and `Plugin`: the Bevy-shaped application layer over one `bevy_ecs::World`.
//!
//! A [`SimApp`] is one simulated environment: a `World` plus its three schedules
//! ([`EnvStep`], [`PhysicsStep`], [`Substep`]). Plugins add systems to the public sets below and
//! register named capabilities (shapes, body kinds, terms, robots, sensors) in the
//! [`Registry`](crate::registry::Registry).
//! A vectorised environment builds one `SimApp` per env from the same plugin list (see
//! [`crate::env::VecEnv`]); compiled scene data is shared between them through `Arc`.
//!
//! ```text
//! EnvStep:     ProcessActions -> Simulate(decimation x PhysicsStep) -> Reset -> Sense -> Evaluate -> Observe
//! PhysicsStep: ApplyActions -> Prepare -> StepSimulation(substeps x Substep) -> Writeback
//! Substep:     Predict -> Collide -> Solve -> Couple -> Finalize
//! ```
//! `EnvStep` runs in one of two [`Phase`]s. In [`Phase::Step`] every set runs except `Reset`; in
//! [`Phase::Reset`] (after a snapshot restore) only `Reset`, `Sense` and `Observe` run, so the
//! observation of a fresh episode comes from the same systems as every other observation.

use std::sync::Arc;

use bevy_ecs::prelude::*;
use bevy_ecs::schedule::{LogLevel, ScheduleLabel, SingleThreadedExecutor};

use crate::settings::EpisodeLimit;
pub use crate::settings::{Phase, SimClock, SimErrors, SimSettings, DEFAULT_MAX_BODY_SPEED};
use crate::signals::{ActionBuffer, ObservationBuffer, StepSignals};
use crate::state::{StateRegistry, Stateful};

/// The top-level schedule: one environment step (one agent decision).
#[derive(ScheduleLabel, Debug, Clone, PartialEq, Eq, Hash)]
pub struct EnvStep;

/// One physics step of `SimSettings::dt` seconds; run `decimation` times per env step.
#[derive(ScheduleLabel, Debug, Clone, PartialEq, Eq, Hash)]
pub struct PhysicsStep;

/// One substep of `dt / substeps` seconds; run `substeps` times per physics step.
#[derive(ScheduleLabel, Debug, Clone, PartialEq, Eq, Hash)]
pub struct Substep;

/// Public sets of [`EnvStep`], chained in this order.
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub enum EnvSystems {
    /// Action terms parse the raw action buffer (clip, scale, discrete -> continuous).
    ProcessActions,
    /// Runs [`PhysicsStep`] `decimation` times (the engine's own system lives here).
    Simulate,
    /// Reset events (randomisation) after a snapshot restore; runs only in [`Phase::Reset`].
    Reset,
    /// Sensors (state, cameras when asked).
    Sense,
    /// Terminations, rewards, success; runs only in [`Phase::Step`].
    Evaluate,
    /// Observation groups write the flat observation buffer.
    Observe,
}

/// Public sets of [`PhysicsStep`], chained in this order.
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub enum PhysicsSystems {
    /// Once per physics step, before the substeps: controllers turn processed actions into
    /// joint targets, torques or base velocities, and components are pushed into the solver
    /// contexts.
    ApplyActions,
    /// Runs [`Substep`] `substeps` times (the engine's own system lives here).
    StepSimulation,
    /// Contexts -> components: poses, deformable vertices, contact caches.
    Writeback,
}

/// Public sets of [`Substep`], chained in this order.
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub enum SubstepSystems {
    /// Per-substep controllers before any solver runs (the robots' joint motors and walking
    /// controller).
    Predict,
    /// The solvers: every deformable solver's set ([`crate::DeformableSystems`], in
    /// registration order), then the rigid step (`RigidSystems::Step`), which applies the
    /// reactions the deformables pushed.
    Solve,
}

/// The engine's own systems inside the public sets, for plugins to order against.
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub enum EngineSystems {
    /// The time-limit truncation, inside [`EnvSystems::Evaluate`]; termination and reward
    /// systems that write `StepSignals` order themselves `.before(EngineSystems::TimeLimit)`.
    /// The scene's reward and termination terms ([`crate::terms`]) run first in this set.
    TimeLimit,
    /// The scene's observation terms ([`crate::terms`]), after [`EnvSystems::Evaluate`] and just
    /// before [`EnvSystems::Observe`] (in both phases): when the scene has any, they fill the
    /// `ObservationBuffer` from scratch; systems in `Observe` may then append to it or replace it.
    Observations,
}

/// A unit of functionality: adds systems, resources and registry entries to a [`SimApp`].
///
/// Plugins are built once per environment (each env has its own `World`), so `build` must be
/// cheap and deterministic; share heavy immutable data through `Arc`.
pub trait Plugin: Send + Sync + 'static {
    /// Adds the plugin's systems, resources and registry entries.
    fn build(&self, app: &mut SimApp);
    /// Unique name, used to refuse adding the same plugin twice and in `modesuite list`.
    fn name(&self) -> &str;
}

/// A list of plugins added together (for example the default plugins of the `modesuite` crate).
pub trait PluginGroup {
    /// The plugins, in build order.
    fn plugins(self) -> Vec<Arc<dyn Plugin>>;
}

/// Anything [`SimApp::add_plugins`] accepts: one plugin or a group.
pub trait Plugins {
    /// The plugins to add, in order.
    fn into_plugin_list(self) -> Vec<Arc<dyn Plugin>>;
}

impl<P: Plugin> Plugins for P {
    fn into_plugin_list(self) -> Vec<Arc<dyn Plugin>> {
        vec![Arc::new(self)]
    }
}

impl Plugins for Vec<Arc<dyn Plugin>> {
    fn into_plugin_list(self) -> Vec<Arc<dyn Plugin>> {
        self
    }
}

/// One environment: a `World`, its schedules and the plugins that built it.
pub struct SimApp {
    /// The ECS world of this environment.
    pub world: World,
    plugins: Vec<Arc<dyn Plugin>>,
    /// The plugin whose `build` is running (named in setup errors).
    building: Option<String>,
    /// What went wrong while plugins were built (a name registered twice): the app compiles no
    /// scene until it is fixed.
    setup_errors: Vec<String>,
}

impl Default for SimApp {
    fn default() -> Self {
        Self::new()
    }
}

fn new_schedule(label: impl ScheduleLabel) -> Schedule {
    let mut s = Schedule::new(label);
    s.set_executor(SingleThreadedExecutor::new());
    s
}

/// Runs [`PhysicsStep`] `decimation` times; the engine's system in [`EnvSystems::Simulate`].
fn run_physics_steps(world: &mut World) {
    let n = world.resource::<SimSettings>().decimation;
    for _ in 0..n {
        world.run_schedule(PhysicsStep);
        let dt = world.resource::<SimSettings>().dt;
        let mut clock = world.resource_mut::<SimClock>();
        clock.physics_steps += 1;
        clock.time += dt;
    }
}

/// Runs [`Substep`] `substeps` times, each split into [`SimSettings::coupling_substeps`] (set in
/// [`PhysicsSystems::ApplyActions`] by the contact module); the engine's system in
/// [`PhysicsSystems::StepSimulation`].
fn run_substeps(world: &mut World) {
    let n = world.resource::<SimSettings>().step_substeps();
    for _ in 0..n {
        world.run_schedule(Substep);
        world.resource_mut::<SimClock>().substeps += 1;
    }
}

fn in_step_phase(phase: Res<Phase>) -> bool {
    *phase == Phase::Step
}

fn in_reset_phase(phase: Res<Phase>) -> bool {
    *phase == Phase::Reset
}

fn count_env_step(mut clock: ResMut<SimClock>) {
    clock.episode_steps += 1;
}

/// The engine's own time-limit termination (in `Evaluate`): truncates at `EpisodeLimit`.
fn time_limit(
    limit: Option<Res<EpisodeLimit>>,
    clock: Res<SimClock>,
    mut signals: ResMut<StepSignals>,
) {
    if let Some(EpisodeLimit(Some(n))) = limit.as_deref() {
        if clock.episode_steps >= *n {
            signals.truncated = true;
        }
    }
}

impl SimApp {
    /// An app with the engine's schedules, sets and core resources, and no plugins.
    pub fn new() -> Self {
        let mut world = World::new();
        world.insert_resource(SimSettings::default());
        world.insert_resource(SimClock::default());
        world.insert_resource(SimErrors::default());
        world.insert_resource(Phase::Step);
        world.insert_resource(StateRegistry::default());
        world.insert_resource(crate::rng::EnvRng::from_seed(0));
        world.insert_resource(ActionBuffer::default());
        world.insert_resource(ObservationBuffer::default());
        world.insert_resource(StepSignals::default());
        // Registered up front so queries with optional components work before any is spawned.
        world.register_component::<crate::components::Object>();
        world.register_component::<crate::components::Pose>();
        world.register_component::<crate::components::Velocity>();
        world.register_component::<crate::components::DeformableNodes>();
        world.register_component::<crate::components::JointState>();

        let mut env_step = new_schedule(EnvStep);
        env_step.configure_sets(
            (
                EnvSystems::ProcessActions.run_if(in_step_phase),
                EnvSystems::Simulate.run_if(in_step_phase),
                EnvSystems::Reset.run_if(in_reset_phase),
                EnvSystems::Sense,
                EnvSystems::Evaluate.run_if(in_step_phase),
                EnvSystems::Observe,
            )
                .chain(),
        );
        env_step.add_systems(
            (run_physics_steps, count_env_step)
                .chain()
                .in_set(EnvSystems::Simulate),
        );
        env_step.configure_sets(EngineSystems::TimeLimit.in_set(EnvSystems::Evaluate));
        env_step.add_systems(
            (crate::terms::evaluate_scene_terms, time_limit)
                .chain()
                .in_set(EngineSystems::TimeLimit),
        );
        env_step.configure_sets(
            EngineSystems::Observations
                .after(EnvSystems::Evaluate)
                .before(EnvSystems::Observe),
        );
        env_step.add_systems(crate::terms::observe_scene_terms.in_set(EngineSystems::Observations));
        let mut physics = new_schedule(PhysicsStep);
        physics.configure_sets(
            (
                PhysicsSystems::ApplyActions,
                PhysicsSystems::StepSimulation,
                PhysicsSystems::Writeback,
            )
                .chain(),
        );
        physics.add_systems(run_substeps.in_set(PhysicsSystems::StepSimulation));
        let mut substep = new_schedule(Substep);
        substep.configure_sets((SubstepSystems::Predict, SubstepSystems::Solve).chain());
        world.add_schedule(env_step);
        world.add_schedule(physics);
        world.add_schedule(substep);

        let mut app = Self {
            world,
            plugins: Vec::new(),
            building: None,
            setup_errors: Vec::new(),
        };
        app.register_stateful::<SimClock>();
        app.register_stateful::<crate::rng::EnvRng>();
        app
    }

    /// Adds one plugin or a plugin group and builds them now. A plugin whose name is already
    /// present is skipped (plugins are unique by name).
    pub fn add_plugins(&mut self, plugins: impl Plugins) -> &mut Self {
        for p in plugins.into_plugin_list() {
            if self.plugins.iter().any(|q| q.name() == p.name()) {
                continue;
            }
            self.plugins.push(p.clone());
            let outer = self.building.replace(p.name().to_string());
            p.build(self);
            self.building = outer;
        }
        self
    }

    /// Adds every plugin of a group (see [`SimApp::add_plugins`]).
    pub fn add_group(&mut self, group: impl PluginGroup) -> &mut Self {
        self.add_plugins(group.plugins())
    }

    /// Whether a plugin of this name has been added.
    pub fn has_plugin(&self, name: &str) -> bool {
        self.plugins.iter().any(|p| p.name() == name)
    }

    /// Names of the plugins added so far, in build order.
    pub fn plugin_names(&self) -> Vec<String> {
        self.plugins.iter().map(|p| p.name().to_string()).collect()
    }

    /// The plugin list (to build another env with the same plugins).
    pub fn plugin_list(&self) -> Vec<Arc<dyn Plugin>> {
        self.plugins.clone()
    }

    /// Adds systems to a schedule (Bevy's verb).
    pub fn add_systems<M>(
        &mut self,
        schedule: impl ScheduleLabel,
        systems: impl IntoScheduleConfigs<bevy_ecs::system::ScheduleSystem, M>,
    ) -> &mut Self {
        self.world
            .resource_mut::<Schedules>()
            .add_systems(schedule, systems);
        self
    }

    /// Configures system sets in a schedule (Bevy's verb).
    pub fn configure_sets<M>(
        &mut self,
        schedule: impl ScheduleLabel,
        sets: impl IntoScheduleConfigs<bevy_ecs::schedule::InternedSystemSet, M>,
    ) -> &mut Self {
        self.world
            .resource_mut::<Schedules>()
            .configure_sets(schedule, sets);
        self
    }

    /// Inserts (or replaces) a resource.
    pub fn insert_resource<R: Resource>(&mut self, resource: R) -> &mut Self {
        self.world.insert_resource(resource);
        self
    }

    /// Declares a resource as part of the env state: it is saved in snapshots, restored on
    /// reset and hashed for determinism checks.
    pub fn register_stateful<
        R: Resource + Component<Mutability = bevy_ecs::component::Mutable> + Stateful,
    >(
        &mut self,
    ) -> &mut Self {
        self.world
            .resource_mut::<StateRegistry>()
            .add_resource::<R>();
        self
    }

    /// Declares a component type as part of the env state (every entity's value is saved).
    pub fn register_stateful_component<
        C: Component<Mutability = bevy_ecs::component::Mutable>
            + Clone
            + crate::state::HashState
            + crate::codec::Persist,
    >(
        &mut self,
    ) -> &mut Self {
        self.world
            .resource_mut::<StateRegistry>()
            .add_component::<C>();
        self
    }

    /// Records a setup error (a plugin's conflicting registration): the app then refuses to
    /// compile scenes, with every recorded message. Plugins with registries of their own (the
    /// tasks' experts) report their conflicts here too.
    pub fn report_setup_error(&mut self, message: impl Into<String>) {
        let by = self
            .building
            .as_deref()
            .map_or(String::new(), |p| format!("plugin \"{p}\": "));
        self.setup_errors.push(format!("{by}{}", message.into()));
    }

    /// The setup errors recorded so far (empty when every registration was accepted).
    pub fn setup_errors(&self) -> &[String] {
        &self.setup_errors
    }

    /// Reports a second registration of `name` as a `what` (refused: the first one stays).
    pub fn report_duplicate(&mut self, what: &str, name: &str) {
        self.report_setup_error(format!(
            "{what} \"{name}\" is already registered; a second registration is refused (each name once per registry)"
        ));
    }

    /// Declares `len` f64 state slots for `owner` in [`crate::state::PluginStates`] (part of the
    /// env state: saved in snapshots, restored on reset, hashed).
    pub fn declare_plugin_state(&mut self, owner: &str, len: usize) -> &mut Self {
        self.world
            .get_resource_or_insert_with(crate::state::PluginStates::default)
            .declare(owner, len);
        self.register_stateful::<crate::state::PluginStates>()
    }

    /// Runs one env step (one pass of [`EnvStep`] in [`Phase::Step`]).
    pub fn step(&mut self) {
        *self.world.resource_mut::<Phase>() = Phase::Step;
        self.world.resource_mut::<SimErrors>().current.clear();
        self.run_env_step();
    }

    /// One pass of [`EnvStep`] with subnormals flushed (`simd::flush_denormals`).
    fn run_env_step(&mut self) {
        crate::simd::flush_denormals(|| self.world.run_schedule(EnvStep));
    }

    /// Runs the reset pass of [`EnvStep`] (reset events, sensing, observation).
    pub fn run_reset_pass(&mut self) {
        *self.world.resource_mut::<Phase>() = Phase::Reset;
        self.run_env_step();
        *self.world.resource_mut::<Phase>() = Phase::Step;
    }

    /// Number of pairs of systems with conflicting data access and no order between them, over
    /// all three schedules (must be zero: such pairs make results depend on executor order).
    pub fn ambiguity_count(&mut self) -> usize {
        self.ambiguities().len()
    }

    /// The conflicting system pairs, by name, over all three schedules.
    pub fn ambiguities(&mut self) -> Vec<String> {
        let mut out = Vec::new();
        let labels: [bevy_ecs::schedule::InternedScheduleLabel; 3] =
            [EnvStep.intern(), PhysicsStep.intern(), Substep.intern()];
        for label in labels {
            self.world.schedule_scope(label, |world, schedule| {
                // With ambiguity detection at Error, a build that finds conflicts fails with a
                // message naming the systems; a schedule built earlier keeps its conflict list.
                let mut settings = schedule.get_build_settings();
                let old = settings.ambiguity_detection;
                settings.ambiguity_detection = LogLevel::Error;
                schedule.set_build_settings(settings.clone());
                match schedule.initialize(world) {
                    Err(e) => out.push(format!(
                        "{label:?}: {}",
                        e.to_string(schedule.graph(), world)
                    )),
                    Ok(_) => {
                        for i in 0..schedule.graph().conflicting_systems().len() {
                            out.push(format!(
                                "{label:?}: conflict {i} (found when the schedule was first built)"
                            ));
                        }
                    }
                }
                settings.ambiguity_detection = old;
                schedule.set_build_settings(settings);
            });
        }
        out
    }
}
