//! `SimApp` and `Plugin`: the Bevy-shaped application layer over one `bevy_ecs::World`.
//!
//! A [`SimApp`] is one simulated environment: a `World` plus its three schedules
//! ([`EnvStep`], [`PhysicsStep`], [`Substep`]). Plugins add systems to the public sets below and
//! register named capabilities (shapes, body kinds, terms, robots, sensors) in the [`Registry`].
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

use crate::registry::Registry;
use crate::scene::{SceneError, SceneModel};
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

/// Which pass of [`EnvStep`] is running.
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
        }
    }
}

impl SimSettings {
    /// Substep length in seconds.
    pub fn substep_dt(&self) -> f64 {
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
    ) -> Result<(), crate::checkpoint::StateError> {
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
    scene: Option<Arc<SceneModel>>,
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

/// Runs [`Substep`] `substeps` times; the engine's system in [`PhysicsSystems::StepSimulation`].
fn run_substeps(world: &mut World) {
    let n = world.resource::<SimSettings>().substeps;
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

impl SimApp {
    /// An app with the engine's schedules, sets and core resources, and no plugins.
    pub fn new() -> Self {
        let mut world = World::new();
        world.insert_resource(SimSettings::default());
        world.insert_resource(SimClock::default());
        world.insert_resource(SimErrors::default());
        world.insert_resource(Phase::Step);
        world.insert_resource(Registry::default());
        world.insert_resource(StateRegistry::default());
        world.insert_resource(crate::rng::EnvRng::from_seed(0));
        world.insert_resource(crate::env::ActionBuffer::default());
        world.insert_resource(crate::env::ObservationBuffer::default());
        world.insert_resource(crate::env::StepSignals::default());
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
            (crate::terms::evaluate_scene_terms, crate::scene::time_limit)
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
            scene: None,
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
            + crate::checkpoint::Persist,
    >(
        &mut self,
    ) -> &mut Self {
        self.world
            .resource_mut::<StateRegistry>()
            .add_component::<C>();
        self
    }

    /// The registry of named capabilities.
    pub fn registry(&self) -> &Registry {
        self.world.resource::<Registry>()
    }

    /// Mutable access to the registry (the `register_*` verbs below are shorthands).
    pub fn registry_mut(&mut self) -> Mut<'_, Registry> {
        self.world.resource_mut::<Registry>()
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

    /// Inserts `value` under `name` into one of the registry's maps unless the name is taken
    /// there; a second registration is refused (the first stays) and reported.
    fn register_unique<T>(
        &mut self,
        what: &str,
        name: String,
        value: T,
        map: fn(&mut Registry) -> &mut std::collections::BTreeMap<String, T>,
    ) -> &mut Self {
        if !crate::registry::insert_unique(map(&mut self.registry_mut()), name.clone(), value) {
            self.report_duplicate(what, &name);
        }
        self
    }

    /// Registers a shape generator under its name (RON: `Gen(name: "...", params: ...)`).
    pub fn register_shape(
        &mut self,
        generator: Arc<dyn crate::registry::ShapeGenerator>,
    ) -> &mut Self {
        let name = generator.name().to_string();
        self.register_unique("shape generator", name, generator, |r| &mut r.shapes)
    }

    /// Registers a body kind (RON: `body: Kind(kind: "fem.solid", params: ...)`).
    pub fn register_body_kind(&mut self, kind: Arc<dyn crate::registry::BodyKind>) -> &mut Self {
        let name = kind.name().to_string();
        self.register_unique("body kind", name, kind, |r| &mut r.body_kinds)
    }

    /// Registers a task term (observation, reward, termination, event) under its name.
    pub fn register_term(&mut self, term: crate::registry::TermEntry) -> &mut Self {
        let name = term.name.clone();
        self.register_unique("term", name, term, |r| &mut r.terms)
    }

    /// Registers a passive force on deformables (RON: `passive_forces: [(force: "...", ...)]`).
    pub fn register_passive_force(
        &mut self,
        force: Arc<dyn crate::terms::PassiveForce>,
    ) -> &mut Self {
        let name = force.name().to_string();
        self.register_unique("passive force", name, force, |r| &mut r.forces)
    }

    /// Declares `len` f64 state slots for `owner` in [`crate::state::PluginStates`] (part of the
    /// env state: saved in snapshots, restored on reset, hashed).
    pub fn declare_plugin_state(&mut self, owner: &str, len: usize) -> &mut Self {
        self.world
            .get_resource_or_insert_with(crate::state::PluginStates::default)
            .declare(owner, len);
        self.register_stateful::<crate::state::PluginStates>()
    }

    /// Registers a robot under its name.
    pub fn register_robot(&mut self, robot: crate::registry::RobotEntry) -> &mut Self {
        let name = robot.name.clone();
        self.register_unique("robot", name, robot, |r| &mut r.robots)
    }

    /// Registers the handler of a plugin-owned scene section (`extensions: { "key": ... }`).
    pub fn register_section(&mut self, section: impl crate::registry::SceneSection) -> &mut Self {
        let section: Arc<dyn crate::registry::SceneSection> = Arc::new(section);
        let name = section.name().to_string();
        self.register_unique("scene section", name, section, |r| &mut r.sections)
    }

    /// Registers a sensor type under its name.
    pub fn register_sensor(&mut self, sensor: crate::registry::SensorEntry) -> &mut Self {
        let name = sensor.name.clone();
        self.register_unique("sensor", name, sensor, |r| &mut r.sensors)
    }

    /// Compiles a scene description with this app's registries (body kinds, shapes).
    pub fn compile_scene(
        &self,
        desc: &crate::scene::SceneDesc,
        source: &crate::scene::SceneSource,
    ) -> Result<Arc<SceneModel>, SceneError> {
        if !self.setup_errors.is_empty() {
            return Err(SceneError::semantic(
                "plugins",
                self.setup_errors.join("; "),
                "plugins whose names do not clash",
            ));
        }
        crate::scene::compile(desc, source, self.registry()).map(Arc::new)
    }

    /// Spawns a compiled scene into this app's world and sets the simulation settings.
    pub fn spawn_scene(&mut self, model: Arc<SceneModel>) -> Result<(), SceneError> {
        if self.scene.is_some() {
            return Err(SceneError::semantic(
                "scene",
                "already spawned",
                "one scene per app; build a new SimApp",
            ));
        }
        crate::scene::spawn(&model, self)?;
        self.scene = Some(model);
        Ok(())
    }

    /// The compiled scene of this app, if one was spawned.
    pub fn scene(&self) -> Option<&Arc<SceneModel>> {
        self.scene.as_ref()
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
