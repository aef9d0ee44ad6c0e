//! Scene terms: a small, general runtime for observation, reward and termination terms, and for
//! passive forces on deformables.
//!
//! A term is registered by name ([`crate::registry::TermEntry::new`] with a [`Term`]); a scene
//! refers to it in its `rewards`, `terminations` or `observations` sections:
//!
//! ```ron
//! rewards: [(term: "acme.centroid_height", weight: -1.0, params: (object: "tube"))],
//! terminations: [(term: "acme.below", params: (object: "tube", z: 0.05))],
//! observations: [(term: "acme.centroid", params: (object: "tube"))],
//! passive_forces: [(force: "acme.wind", objects: ["tube"], params: (force: (0.5, 0.0, 0.0)))],
//! ```
//! When the scene is compiled, every term is [configured](Term::configure) with its parameters
//! (errors point at `rewards[i].params`); the configured terms are immutable and shared by every
//! env. Each step, in [`EngineSystems::TimeLimit`](crate::EngineSystems::TimeLimit) before the time
//! limit, rewards add `weight x value` to `StepSignals::reward` (and `reward/<term>` to its values)
//! and a non-zero termination value sets `terminated`; in
//! [`EngineSystems::Observations`](crate::EngineSystems::Observations) (just before
//! `EnvSystems::Observe`) the observation terms fill the `ObservationBuffer` from scratch, in
//! order (the observation space is set when the scene is spawned). Passive forces run inside the deformable step of every substep ([`crate::deformable`]).
//!
//! Terms read a [`WorldView`] (object poses and velocities, deformable nodes, joint state) and may
//! keep state in [`PluginStates`] (part of the env snapshot). A term error ends the episode with
//! that error (through `SimErrors`); the process goes on. The tasks plugin reuses the same
//! [`Term`] values in its managers.

use std::sync::Arc;

use bevy_ecs::prelude::*;
use nalgebra::{Isometry3, Vector3};

use crate::components::{DeformableNodes, JointState, Object, Pose, Velocity};
use crate::signals::{ObservationBuffer, StepSignals};
use crate::state::PluginStates;
use crate::{SimClock, SimErrors, SimSettings};

/// One object as terms see it (read-only).
#[derive(Debug, Clone)]
pub struct ObjectView<'a> {
    /// Unique name.
    pub name: &'a str,
    /// Body kind (`static`, `dynamic`, `kinematic`, `fem.solid`, ...).
    pub kind: &'a str,
    /// `world_from_body`.
    pub pose: Isometry3<f64>,
    /// Linear velocity, m/s (zero for bodies without one).
    pub linear_velocity: Vector3<f64>,
    /// Angular velocity, rad/s (zero for bodies without one).
    pub angular_velocity: Vector3<f64>,
    /// Deformable node positions, m, world frame (empty for rigid bodies).
    pub nodes: &'a [Vector3<f64>],
    /// Joint state of articulated objects.
    pub joints: Option<&'a JointState>,
}

/// The read-only world of one env at evaluation time.
#[derive(Debug, Clone, Default)]
pub struct WorldView<'a> {
    /// Simulated time since the episode started, s.
    pub time: f64,
    /// Length of one env step, s (dt x decimation).
    pub step_dt: f64,
    /// Env steps since the episode started.
    pub episode_steps: u64,
    /// Objects in scene order.
    pub objects: Vec<ObjectView<'a>>,
}

impl<'a> WorldView<'a> {
    /// The object of this name.
    pub fn object(&self, name: &str) -> Option<&ObjectView<'a>> {
        self.objects.iter().find(|o| o.name == name)
    }
}

/// What a term gets when it is evaluated.
pub struct TermContext<'a, 'w> {
    /// The world.
    pub world: &'a WorldView<'w>,
    /// State slots of plugins (C ABI plugins keep their state here).
    pub states: &'a mut PluginStates,
}

/// A named term as registered: turns scene parameters into a configured term.
pub trait Term: Send + Sync + 'static {
    /// Validates the RON parameters (once, when a scene is compiled); errors are messages for
    /// the scene author.
    fn configure(&self, params_ron: &str) -> Result<Arc<dyn ConfiguredTerm>, String>;
}

/// A term with its parameters, ready to evaluate (immutable, shared by every env).
pub trait ConfiguredTerm: Send + Sync + 'static {
    /// Number of values it writes (1 for rewards and terminations).
    fn dim(&self) -> usize;
    /// Writes `dim` values into `out` (zeroed by the caller).
    fn evaluate(&self, ctx: &mut TermContext, out: &mut [f64]) -> Result<(), String>;
}

/// What a passive force gets for one deformable object and one substep.
pub struct ForceContext<'a> {
    /// The object's name.
    pub object: &'a str,
    /// Time at the start of the substep, s.
    pub time: f64,
    /// Substep length, s.
    pub dt: f64,
    /// Current node positions, m, world frame.
    pub nodes: &'a [Vector3<f64>],
    /// Current node velocities, m/s, when the solver exposes them.
    pub velocities: Option<&'a [Vector3<f64>]>,
    /// State slots of plugins.
    pub states: &'a mut PluginStates,
}

/// A named passive force on deformable nodes as registered.
pub trait PassiveForce: Send + Sync + 'static {
    /// Registry name, e.g. `acme.wind`.
    fn name(&self) -> &str;
    /// One line for `modesuite list`.
    fn description(&self) -> &str;
    /// Validates the RON parameters (once, when a scene is compiled).
    fn configure(&self, params_ron: &str) -> Result<Arc<dyn ConfiguredForce>, String>;
}

/// A passive force with its parameters (immutable, shared by every env).
pub trait ConfiguredForce: Send + Sync + 'static {
    /// Adds forces (N, world frame), one per node, into `forces`.
    fn add_forces(&self, ctx: &mut ForceContext, forces: &mut [Vector3<f64>])
        -> Result<(), String>;
}

/// A configured reward term of a scene.
#[derive(Clone)]
pub struct RewardModel {
    /// Term name.
    pub name: String,
    /// Weight: the step reward adds `weight x value`.
    pub weight: f64,
    /// The term.
    pub term: Arc<dyn ConfiguredTerm>,
}

/// A configured observation or termination term of a scene.
#[derive(Clone)]
pub struct TermModel {
    /// Term name.
    pub name: String,
    /// The term.
    pub term: Arc<dyn ConfiguredTerm>,
}

/// A configured passive force of a scene.
#[derive(Clone)]
pub struct ForceModel {
    /// Force name.
    pub name: String,
    /// Indices (in the scene's object list) of the deformable objects it acts on.
    pub objects: Vec<u32>,
    /// The force.
    pub force: Arc<dyn ConfiguredForce>,
}

/// The compiled term sections of a scene (part of `SceneModel`, a resource once spawned).
#[derive(Resource, Clone, Default)]
pub struct SceneTerms {
    /// Reward terms.
    pub rewards: Vec<RewardModel>,
    /// Termination terms.
    pub terminations: Vec<TermModel>,
    /// Observation terms, in buffer order.
    pub observations: Vec<TermModel>,
    /// Passive forces.
    pub forces: Vec<ForceModel>,
}

impl SceneTerms {
    /// Total number of observation values.
    pub fn observation_dim(&self) -> usize {
        self.observations.iter().map(|o| o.term.dim()).sum()
    }

    /// True when the scene has no term or force sections.
    pub fn is_empty(&self) -> bool {
        self.rewards.is_empty()
            && self.terminations.is_empty()
            && self.observations.is_empty()
            && self.forces.is_empty()
    }
}

/// The components a world view is built from.
pub type ViewQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static Object,
        &'static Pose,
        Option<&'static Velocity>,
        Option<&'static DeformableNodes>,
        Option<&'static JointState>,
    ),
>;

/// Builds the world view of an env (objects in scene order).
pub fn world_view<'a>(
    query: &'a ViewQuery,
    clock: &SimClock,
    settings: &SimSettings,
) -> WorldView<'a> {
    let mut objects: Vec<(u32, ObjectView<'a>)> = query
        .iter()
        .map(|(o, p, v, n, j)| {
            (
                o.index,
                ObjectView {
                    name: &o.name,
                    kind: &o.kind,
                    pose: p.0,
                    linear_velocity: v.map_or_else(Vector3::zeros, |v| v.linear),
                    angular_velocity: v.map_or_else(Vector3::zeros, |v| v.angular),
                    nodes: n.map_or(&[][..], |n| &n.0),
                    joints: j,
                },
            )
        })
        .collect();
    objects.sort_by_key(|(i, _)| *i);
    WorldView {
        time: clock.time,
        step_dt: settings.dt * f64::from(settings.decimation),
        episode_steps: clock.episode_steps,
        objects: objects.into_iter().map(|(_, o)| o).collect(),
    }
}

/// Evaluates one term into `out` (resized to its dimension); errors name the section and term.
fn evaluate_into(
    section: &str,
    name: &str,
    term: &dyn ConfiguredTerm,
    ctx: &mut TermContext,
    out: &mut Vec<f64>,
) -> Result<(), String> {
    out.clear();
    out.resize(term.dim(), 0.0);
    term.evaluate(ctx, out)
        .map_err(|e| format!("{section} term \"{name}\": {e}"))?;
    check_finite(section, name, out)
}

/// The error for the first non-finite value a term returned: terms must return finite values.
pub fn check_finite(section: &str, name: &str, out: &[f64]) -> Result<(), String> {
    match out.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        Some((i, v)) => Err(format!(
            "{section} term \"{name}\": value [{i}] = {v}: terms must return finite values"
        )),
        None => Ok(()),
    }
}

/// The scene's reward and termination terms (in `EngineSystems::TimeLimit`, before the limit).
pub(crate) fn evaluate_scene_terms(
    terms: Option<Res<SceneTerms>>,
    query: ViewQuery,
    clock: Res<SimClock>,
    settings: Res<SimSettings>,
    mut states: Option<ResMut<PluginStates>>,
    mut signals: ResMut<StepSignals>,
    mut errors: ResMut<SimErrors>,
) {
    let Some(terms) = terms else { return };
    if terms.rewards.is_empty() && terms.terminations.is_empty() {
        return;
    }
    let world = world_view(&query, &clock, &settings);
    let mut empty = PluginStates::default();
    let mut ctx = TermContext {
        world: &world,
        states: states.as_deref_mut().unwrap_or(&mut empty),
    };
    let mut out = Vec::new();
    for r in &terms.rewards {
        match evaluate_into("reward", &r.name, r.term.as_ref(), &mut ctx, &mut out) {
            Ok(()) => signals.add_reward(&r.name, r.weight * out[0]),
            Err(e) => errors.raise(e),
        }
    }
    for t in &terms.terminations {
        match evaluate_into("termination", &t.name, t.term.as_ref(), &mut ctx, &mut out) {
            Ok(()) => {
                if out[0] != 0.0 {
                    signals.terminated = true;
                }
                signals
                    .values
                    .insert(format!("termination/{}", t.name), out[0]);
            }
            Err(e) => errors.raise(e),
        }
    }
}

/// The scene's observation terms (`EngineSystems::Observations`): fill the buffer from scratch.
pub(crate) fn observe_scene_terms(
    terms: Option<Res<SceneTerms>>,
    query: ViewQuery,
    clock: Res<SimClock>,
    settings: Res<SimSettings>,
    mut states: Option<ResMut<PluginStates>>,
    mut buffer: ResMut<ObservationBuffer>,
    mut errors: ResMut<SimErrors>,
) {
    let Some(terms) = terms else { return };
    if terms.observations.is_empty() {
        return;
    }
    let world = world_view(&query, &clock, &settings);
    let mut empty = PluginStates::default();
    let mut ctx = TermContext {
        world: &world,
        states: states.as_deref_mut().unwrap_or(&mut empty),
    };
    buffer.0.clear();
    let mut out = Vec::new();
    for o in &terms.observations {
        let r = evaluate_into("observation", &o.name, o.term.as_ref(), &mut ctx, &mut out)
            .and_then(|()| match out.iter().find(|x| !(**x as f32).is_finite()) {
                Some(x) => Err(format!(
                    "observation term \"{}\" = {x}: outside the f32 range of observations (|x| <= {:e})",
                    o.name,
                    f32::MAX
                )),
                None => Ok(()),
            });
        match r {
            Ok(()) => buffer.0.extend(out.iter().map(|&x| x as f32)),
            Err(e) => {
                errors.raise(e);
                buffer.0.extend(std::iter::repeat_n(0.0f32, o.term.dim()));
            }
        }
    }
}

/// Adds the scene's passive forces on one deformable body into `forces` (zeroed here). Returns
/// `Ok(false)` when no force acts on the object (the solver's loads are left alone).
pub fn passive_forces_for(
    terms: &SceneTerms,
    object: &Object,
    ctx: &mut ForceContext,
    forces: &mut Vec<Vector3<f64>>,
) -> Result<bool, String> {
    let mut any = false;
    for f in terms
        .forces
        .iter()
        .filter(|f| f.objects.contains(&object.index))
    {
        if !any {
            forces.clear();
            forces.resize(ctx.nodes.len(), Vector3::zeros());
            any = true;
        }
        f.force
            .add_forces(ctx, forces)
            .map_err(|e| format!("passive force \"{}\": {e}", f.name))?;
        if let Some(i) = forces.iter().position(|v| !v.iter().all(|x| x.is_finite())) {
            return Err(format!(
                "passive force \"{}\": node {i} force is not finite",
                f.name
            ));
        }
    }
    Ok(any)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registry::{TermEntry, TermKind};
    use crate::{Env, RigidPlugin, SimApp};

    /// A static Rust term: the height of the object named in its parameters, counted in a
    /// plugin state slot.
    struct Height;
    struct HeightOf(String);

    impl Term for Height {
        fn configure(&self, params_ron: &str) -> Result<Arc<dyn ConfiguredTerm>, String> {
            let name: String = ron::from_str(params_ron).map_err(|e| e.to_string())?;
            Ok(Arc::new(HeightOf(name)))
        }
    }

    impl ConfiguredTerm for HeightOf {
        fn dim(&self) -> usize {
            1
        }
        fn evaluate(&self, ctx: &mut TermContext, out: &mut [f64]) -> Result<(), String> {
            ctx.states.get_mut("test")[0] += 1.0;
            let o = ctx.world.object(&self.0).ok_or("no such object")?;
            out[0] = o.pose.translation.z;
            Ok(())
        }
    }

    #[test]
    fn static_reward_terms_are_weighted_and_their_state_resets() {
        let mut app = SimApp::new();
        app.add_plugins(RigidPlugin);
        app.declare_plugin_state("test", 1);
        app.register_term(TermEntry::new(
            "test.height",
            TermKind::Reward,
            "height",
            Arc::new(Height),
        ));
        let desc = crate::scene::parse_str(
            r#"Scene(objects: [(name: "box", shape: Box(size: (0.1, 0.1, 0.1)), pose: (pos: (0.0, 0.0, 1.0)), body: Kinematic)],
                     rewards: [(term: "test.height", weight: 2.0, params: "box")])"#,
            "<test>",
        )
        .unwrap();
        let model = app
            .compile_scene(&desc, &crate::SceneSource::in_memory("."))
            .unwrap();
        app.spawn_scene(model).unwrap();
        let mut env = Env::new(app);
        env.reset(Some(0));
        for _ in 0..3 {
            let o = env.step(&[]);
            assert_eq!(o.reward, 2.0);
            assert_eq!(o.info.values["reward/test.height"], 2.0);
        }
        let states = env.app.world.resource::<PluginStates>();
        assert_eq!(states.get("test"), &[3.0]);
        env.reset(None);
        assert_eq!(env.app.world.resource::<PluginStates>().get("test"), &[0.0]);
    }
}
