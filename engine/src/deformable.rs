//! Shared plumbing of deformable body kinds (FEM solids, cloth, third-party solvers).
//!
//! A solver implements [`DeformableSolver`]; its plugin keeps every body of an env in a
//! [`DeformableContext`] (a stateful resource: snapshots, resets and hashes cover it) and adds the
//! generic step and writeback systems with [`add_deformable_systems`]. The step runs once per
//! engine substep inside the given [`DeformableSystems`] set (before the rigid step), queries the
//! rigid world through the coupling API and pushes the solver's reactions to the rigid bodies;
//! the writeback copies positions into each body's [`DeformableNodes`].

use std::any::Any;

use bevy_ecs::component::Mutable;
use bevy_ecs::prelude::*;
use nalgebra::{Isometry3, UnitQuaternion, Vector3};

use crate::app::SimErrors;
use crate::checkpoint::{Decoder, Encoder, Persist, StateError};
use crate::components::{DeformableNodes, Object};
use crate::contact::{deliver, ContactImpulses, ContactRefresh, DeformableContacts};
use crate::coupling::{ContactQuery, GripperState, Grippers, NoColliders, Reaction};
use crate::rigid::{DeformableSystems, RigidContext};
use crate::state::{mismatch, HashState, PluginStates, StateHasher, Stateful};
use crate::terms::{passive_forces_for, ForceContext, SceneTerms};
use crate::{SimApp, SimClock, SimSettings};

/// What the engine needs from a deformable solver.
pub trait DeformableSolver: Send + Sync + 'static {
    /// Advances by `dt` seconds under `gravity` (m/s^2, world frame), colliding with the rigid
    /// world; appends the impulses it applied on rigid bodies. On failure the solver keeps a
    /// finite state (rolled back) and returns the reason.
    fn step_coupled(
        &mut self,
        dt: f64,
        gravity: &Vector3<f64>,
        query: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
    ) -> Result<(), String>;
    /// [`DeformableSolver::step_coupled`] for a step that starts `t0` seconds after the rigid
    /// state `query` describes (several deformable steps per rigid substep,
    /// `physics.deformable_substeps`): a solver that extrapolates moving colliders over its
    /// step should extrapolate them over `t0 + dt`. Default: `step_coupled`, colliders seen
    /// from the rigid state.
    fn step_coupled_at(
        &mut self,
        t0: f64,
        dt: f64,
        gravity: &Vector3<f64>,
        query: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
    ) -> Result<(), String> {
        let _ = t0;
        self.step_coupled(dt, gravity, query, reactions)
    }
    /// Current node or particle positions, m, world frame.
    fn node_positions(&self) -> &[Vector3<f64>];
    /// The complete state (bit-exact round trip with `load`).
    fn save(&self) -> Vec<f64>;
    /// Restores a state made by `save` of this same body.
    fn load(&mut self, state: &[f64]) -> Result<(), String>;
    /// Current node velocities, m/s, world frame, when the solver keeps them (handed to passive
    /// forces; default: none).
    fn node_velocities(&self) -> Option<&[Vector3<f64>]> {
        None
    }
    /// Sets the passive (external) force on every node for the coming step(s), N, world frame,
    /// one per node (the scene's `passive_forces`, see [`crate::terms`]). It is part of the
    /// solver's state. Default: the solver takes no external forces (an error).
    fn set_passive_forces(&mut self, forces: &[Vector3<f64>]) -> Result<(), String> {
        let _ = forces;
        Err("this solver does not accept passive forces".to_string())
    }
    /// Moves the solver's body-attached frames (attachments, grasps) to the current poses of
    /// their bodies; `pose_of` gives the pose of any body id. Default: no rigid frames.
    fn follow_bodies(
        &mut self,
        pose_of: &dyn Fn(u32) -> Option<Isometry3<f64>>,
    ) -> Result<(), String> {
        let _ = pose_of;
        Ok(())
    }
    /// Whether rigid body `body` holds a grasp of this body. Default: never.
    fn grasped_by(&self, body: u32) -> bool {
        let _ = body;
        false
    }
    /// Grasps what lies inside `volume` (world frame) with rigid body `body`, currently at
    /// `pose`, up to `force_limit` N; nothing when nothing is inside. Default: not graspable.
    fn grasp_volume(
        &mut self,
        body: u32,
        pose: &Isometry3<f64>,
        volume: &FingerVolume,
        force_limit: f64,
    ) -> Result<(), String> {
        let _ = (body, pose, volume, force_limit);
        Ok(())
    }
    /// Releases every grasp held by rigid body `body`. Default: nothing to release.
    fn release_body(&mut self, body: u32) -> Result<(), String> {
        let _ = body;
        Ok(())
    }
    /// Appends the nodes held by grasps of any body (any order; repeats allowed). Default: none.
    fn grasped_nodes(&self, out: &mut Vec<u32>) {
        let _ = out;
    }
    /// Appends the nodes in contact with rigid colliders at the end of the last step (any
    /// order; repeats allowed). Default: none.
    fn contact_nodes(&self, out: &mut Vec<u32>) {
        let _ = out;
    }
    /// Moves the body rigidly: its nodes are now at `positions` (the old ones moved by a rigid
    /// transform whose rotation is `rotation`); velocities turn with it where the solver keeps
    /// them. Tasks' randomisation events use it. Default: not supported (an error).
    fn move_rigidly(
        &mut self,
        positions: &[Vector3<f64>],
        rotation: &UnitQuaternion<f64>,
    ) -> Result<(), String> {
        let _ = (positions, rotation);
        Err("this solver cannot move its bodies".to_string())
    }
    /// Adds `dv` (m/s) to the velocity of every node (tasks' `Push` event). Default: not
    /// supported (an error).
    fn add_velocity(&mut self, dv: &Vector3<f64>) -> Result<(), String> {
        let _ = dv;
        Err("this solver cannot push its bodies".to_string())
    }
    /// Sets the material's Young's modulus, Pa (tasks' `Material` event). Default: the body has
    /// none (an error).
    fn set_youngs_modulus(&mut self, youngs_modulus: f64) -> Result<(), String> {
        let _ = youngs_modulus;
        Err("this body has no Young's modulus to set".to_string())
    }
    /// Holds `nodes` with rigid body `body`, currently at `pose`: a grasp limited to
    /// `grasp_force_limit` N (released when that gripper opens) or, with `None`, a fixed
    /// attachment (a task's `held` object). Default: not supported (an error).
    fn hold_nodes(
        &mut self,
        body: u32,
        pose: &Isometry3<f64>,
        nodes: &[u32],
        grasp_force_limit: Option<f64>,
    ) -> Result<(), String> {
        let _ = (body, pose, nodes, grasp_force_limit);
        Err("this solver cannot hold nodes with a rigid body".to_string())
    }
    /// Node masses, kg, one per node. Contact with other deformables ([`crate::contact`]) uses
    /// them to pick which body of a touching pair resolves the contact, and only a body with
    /// masses is pushed back by the other ([`DeformableSolver::add_node_impulses`]). Default:
    /// none (the body is a moving collider for other deformables and is not pushed by them).
    fn node_masses(&self) -> Option<&[f64]> {
        None
    }
    /// Adds `impulses` (N s, world frame, one per node) to the node velocities, each divided by
    /// its node's mass; nodes the solver holds fixed keep theirs. Other deformables' contacts
    /// push the body this way. Default: not supported (an error; a solver reporting
    /// [`DeformableSolver::node_masses`] must implement it).
    fn add_node_impulses(&mut self, impulses: &[Vector3<f64>]) -> Result<(), String> {
        let _ = impulses;
        Err("this solver cannot take impulses on its nodes".to_string())
    }
}

type RefFn = for<'a> fn(&'a World, Entity) -> Option<&'a dyn DeformableSolver>;
type GetFn = for<'a> fn(&'a mut World, Entity) -> Option<&'a mut dyn DeformableSolver>;

/// How to reach the body of an entity in every solver's context, whatever its type (filled by
/// [`add_deformable_systems`]); see [`deformable_mut`].
#[derive(Resource, Default, Clone)]
pub struct DeformableAccess {
    solvers: Vec<(RefFn, GetFn)>,
    /// The solvers' system sets, in registration order (chained in that order).
    sets: Vec<DeformableSystems>,
}

fn ref_body<S: DeformableSolver>(world: &World, entity: Entity) -> Option<&dyn DeformableSolver> {
    let ctx = world.get_resource::<DeformableContext<S>>()?;
    ctx.get(entity).map(|s| s as &dyn DeformableSolver)
}

fn get_body<S: DeformableSolver>(
    world: &mut World,
    entity: Entity,
) -> Option<&mut dyn DeformableSolver>
where
    DeformableContext<S>: Component<Mutability = Mutable>,
{
    let ctx = world
        .get_resource_mut::<DeformableContext<S>>()?
        .into_inner();
    ctx.get_mut(entity).map(|s| s as &mut dyn DeformableSolver)
}

/// The solver body of a deformable entity, through the solver-neutral [`DeformableSolver`]
/// interface (tasks and other plugins move, push, hold and re-parameterise bodies this way
/// without depending on the solver's crate); `None` when the entity is no deformable body.
pub fn deformable_mut(world: &mut World, entity: Entity) -> Option<&mut dyn DeformableSolver> {
    let solvers = world.get_resource::<DeformableAccess>()?.solvers.clone();
    let (_, get) = solvers
        .into_iter()
        .find(|(view, _)| view(world, entity).is_some())?;
    get(world, entity)
}

/// [`deformable_mut`], read-only.
pub fn deformable_ref(world: &World, entity: Entity) -> Option<&dyn DeformableSolver> {
    let access = world.get_resource::<DeformableAccess>()?;
    access
        .solvers
        .iter()
        .find_map(|(view, _)| view(world, entity))
}

/// A gripper's finger volume in the world frame: an oriented box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FingerVolume {
    /// Pose of the box centre, world frame.
    pub pose: Isometry3<f64>,
    /// Half extents along the box axes, m.
    pub half_extents: Vector3<f64>,
}

impl FingerVolume {
    /// Whether `p` (world frame) is inside or on the box.
    pub fn contains(&self, p: &Vector3<f64>) -> bool {
        let l = self
            .pose
            .inverse_transform_point(&nalgebra::Point3::from(*p));
        let h = self.half_extents;
        l.x.abs() <= h.x && l.y.abs() <= h.y && l.z.abs() <= h.z
    }
}

/// Brings a solver's rigid frames and grasps up to date before a step. Grippers are
/// level-triggered ([`Grippers`]): a closed gripper whose body holds nothing of this body grasps
/// what lies inside its finger volume; an open one releases what its body holds. Grasps belong
/// to the solver's state, so snapshots and resets carry them.
fn sync_grippers<S: DeformableSolver>(
    solver: &mut S,
    grippers: &[GripperState],
    pose_of: &dyn Fn(u32) -> Option<Isometry3<f64>>,
) -> Result<(), String> {
    solver.follow_bodies(pose_of)?;
    for g in grippers {
        let Some(pose) = pose_of(g.body) else {
            continue;
        };
        if !g.closed {
            solver.release_body(g.body)?;
        } else if !solver.grasped_by(g.body) {
            let volume = FingerVolume {
                pose: pose * g.volume_pose,
                half_extents: g.half_extents,
            };
            solver.grasp_volume(g.body, &pose, &volume, g.force_limit)?;
        }
    }
    Ok(())
}

/// One deformable body of an env.
pub struct DeformableBody<S> {
    /// The scene object.
    pub entity: Entity,
    /// The solver.
    pub solver: S,
}

/// Every body of one solver type in one env (a resource, part of the env state).
#[derive(Resource)]
pub struct DeformableContext<S: DeformableSolver> {
    /// Bodies in spawn order.
    pub bodies: Vec<DeformableBody<S>>,
}

impl<S: DeformableSolver> Default for DeformableContext<S> {
    fn default() -> Self {
        Self { bodies: Vec::new() }
    }
}

impl<S: DeformableSolver> DeformableContext<S> {
    /// The solver of an entity.
    pub fn get(&self, entity: Entity) -> Option<&S> {
        self.bodies
            .iter()
            .find(|b| b.entity == entity)
            .map(|b| &b.solver)
    }

    /// The solver of an entity, mutable (grasps, attachments).
    pub fn get_mut(&mut self, entity: Entity) -> Option<&mut S> {
        self.bodies
            .iter_mut()
            .find(|b| b.entity == entity)
            .map(|b| &mut b.solver)
    }

    /// Adds a spawned body and gives its entity [`DeformableNodes`] and [`DeformableMarkers`]
    /// components.
    pub fn spawn_into(app: &mut SimApp, entity: Entity, solver: S) {
        let mut markers = DeformableMarkers::default();
        markers.read(&solver);
        app.world
            .entity_mut(entity)
            .insert((DeformableNodes(solver.node_positions().to_vec()), markers));
        app.world
            .resource_mut::<Self>()
            .bodies
            .push(DeformableBody { entity, solver });
    }
}

impl<S: DeformableSolver> DeformableContext<S> {
    fn load_bodies(&mut self, states: &[Vec<f64>], part: &str) -> Result<(), StateError> {
        if states.len() != self.bodies.len() {
            return Err(StateError::part(
                part,
                format!(
                    "{} bodies saved, {} in this env",
                    states.len(),
                    self.bodies.len()
                ),
            ));
        }
        for (b, s) in self.bodies.iter_mut().zip(states) {
            b.solver
                .load(s)
                .map_err(|e| StateError::part(part, format!("body {}: {e}", b.entity)))?;
        }
        Ok(())
    }
}

/// Every body's [`DeformableSolver::save`] vector, in spawn order.
impl<S: DeformableSolver> Persist for DeformableContext<S> {
    fn encode(&self, e: &mut Encoder) {
        e.put(&(self.bodies.len() as u64));
        for b in &self.bodies {
            e.put(&b.solver.save());
        }
    }

    fn decode(&mut self, d: &mut Decoder<'_>) -> Result<(), StateError> {
        d.take_len("deformable bodies", self.bodies.len())?;
        let states = (0..self.bodies.len())
            .map(|_| d.take::<Vec<f64>>())
            .collect::<Result<Vec<_>, _>>()?;
        let part = d.part().to_string();
        self.load_bodies(&states, &part)
    }
}

impl<S: DeformableSolver> Stateful for DeformableContext<S> {
    fn save_state(&self) -> Box<dyn Any + Send + Sync> {
        Box::new(
            self.bodies
                .iter()
                .map(|b| b.solver.save())
                .collect::<Vec<_>>(),
        )
    }

    fn load_state(&mut self, state: &(dyn Any + Send + Sync)) -> Result<(), StateError> {
        let states = state
            .downcast_ref::<Vec<Vec<f64>>>()
            .ok_or_else(mismatch::<Self>)?;
        self.load_bodies(states, std::any::type_name::<Self>())
    }

    fn hash_state(&self, h: &mut StateHasher) {
        for b in &self.bodies {
            for x in b.solver.save() {
                h.write_f64(x);
            }
        }
    }
}

/// The scene's passive forces on one body (see [`crate::terms`]): computed from its current
/// nodes and handed to the solver before it steps.
fn apply_passive_forces<S: DeformableSolver>(
    terms: &SceneTerms,
    object: &Object,
    solver: &mut S,
    time: f64,
    dt: f64,
    states: &mut PluginStates,
    buffer: &mut Vec<Vector3<f64>>,
) -> Result<(), String> {
    let mut ctx = ForceContext {
        object: &object.name,
        time,
        dt,
        nodes: solver.node_positions(),
        velocities: solver.node_velocities(),
        states,
    };
    if passive_forces_for(terms, object, &mut ctx, buffer)? {
        solver.set_passive_forces(buffer)?;
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn deformable_step<S: DeformableSolver>(
    mut ctx: ResMut<DeformableContext<S>>,
    mut rigid: Option<ResMut<RigidContext>>,
    settings: Res<SimSettings>,
    clock: Res<SimClock>,
    terms: Option<Res<SceneTerms>>,
    grippers: Option<Res<Grippers>>,
    mut states: Option<ResMut<PluginStates>>,
    mut errors: ResMut<SimErrors>,
    mut contacts: Option<ResMut<DeformableContacts>>,
    mut impulses: Option<ResMut<ContactImpulses>>,
    names: Query<&Object>,
) {
    // Substep index within the physics step; deformables step at the first of every stride.
    let index = clock.substeps % u64::from(settings.substeps.max(1));
    let stride = u64::from(settings.deformable_stride.max(1));
    if !index.is_multiple_of(stride) {
        return;
    }
    let h = settings.substep_dt();
    let inner = settings.deformable_inner.max(1);
    let dt = h * stride as f64 / f64::from(inner);
    let mut reactions: Vec<Reaction> = Vec::new();
    let mut empty = PluginStates::default();
    let mut buffer = Vec::new();
    if let Some(r) = rigid.as_deref_mut() {
        r.refresh_queries();
    }
    for k in 0..inner {
        // Seconds after the rigid state: the deformable step's start within the substep.
        let t0 = f64::from(k) * dt;
        // Where the bodies were at the end of this step: one rigid substep behind.
        let s = f64::from(k + 1) / f64::from(inner);
        // Time at the start of this step: the physics step's start plus the substeps done in it.
        let time = clock.time + index as f64 * h + t0;
        for body in &mut ctx.bodies {
            if let (Some(terms), Ok(object)) = (terms.as_deref(), names.get(body.entity)) {
                let states = states.as_deref_mut().unwrap_or(&mut empty);
                if let Err(e) = apply_passive_forces(
                    terms,
                    object,
                    &mut body.solver,
                    time,
                    dt,
                    states,
                    &mut buffer,
                ) {
                    errors.raise(format!("object \"{}\": {e}", object.name));
                    continue;
                }
            }
            if let Some(r) = rigid.as_deref() {
                let grippers = grippers.as_deref().map_or(&[][..], |g| &g.0);
                if let Err(e) =
                    sync_grippers(&mut body.solver, grippers, &|id| r.body_pose_between(id, s))
                {
                    let name = names.get(body.entity).map_or("?", |o| o.name.as_str());
                    errors.raise(format!("object \"{name}\": {e}"));
                    continue;
                }
            }
            let entity = body.entity;
            let name = || names.get(entity).map_or("?", |o| o.name.as_str());
            let object = contacts.as_deref().and_then(|c| c.object_of(entity));
            if let (Some(object), Some(j)) = (object, impulses.as_deref_mut()) {
                if let Err(e) = deliver(j, object, &mut body.solver) {
                    errors.raise(format!("object \"{}\": contact impulses: {e}", name()));
                    continue;
                }
            }
            let rigid_query: &dyn ContactQuery = match rigid.as_deref() {
                Some(r) => r,
                None => &NoColliders,
            };
            let surfaces = contacts
                .as_deref()
                .and_then(|c| c.query_for(entity, Some(rigid_query)));
            let query: &dyn ContactQuery = match &surfaces {
                Some(s) => s,
                None => rigid_query,
            };
            let before = reactions.len();
            let stepped =
                body.solver
                    .step_coupled_at(t0, dt, &settings.gravity, query, &mut reactions);
            drop(surfaces);
            if let Err(e) = stepped {
                // The solver rolled its state back: the impulses of the failed step never happened.
                reactions.truncate(before);
                errors.raise(format!("object \"{}\": {e}", name()));
            }
            if let (Some(c), Some(j)) = (contacts.as_deref_mut(), impulses.as_deref_mut()) {
                c.after_step(entity, &body.solver, &mut reactions, before, j);
            }
        }
    }
    if let Some(r) = rigid.as_deref_mut() {
        // (reactions on deformable surfaces were taken out by `after_step`)
        for re in reactions.into_iter().filter(|re| re.body != u32::MAX) {
            r.push_reaction(re);
        }
    }
}

/// Which nodes of a deformable are grasped and which touch rigid colliders (written with its
/// [`DeformableNodes`] after every physics step): what viewers draw as grasp and contact markers
/// and what tasks may read. Derived from the solver's state.
#[derive(Component, Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct DeformableMarkers {
    /// Nodes held by grasps, ascending.
    pub grasped: Vec<u32>,
    /// Nodes in contact with rigid colliders after the last step, ascending.
    pub contacts: Vec<u32>,
}

impl DeformableMarkers {
    fn read<S: DeformableSolver>(&mut self, solver: &S) {
        self.grasped.clear();
        self.contacts.clear();
        solver.grasped_nodes(&mut self.grasped);
        solver.contact_nodes(&mut self.contacts);
        for list in [&mut self.grasped, &mut self.contacts] {
            list.sort_unstable();
            list.dedup();
        }
    }
}

crate::persist_by_serde!(DeformableMarkers);

impl HashState for DeformableMarkers {
    fn hash_state(&self, h: &mut StateHasher) {
        for list in [&self.grasped, &self.contacts] {
            h.write_u64(list.len() as u64);
            for &i in list {
                h.write_u64(u64::from(i));
            }
        }
    }
}

fn deformable_writeback<S: DeformableSolver>(
    ctx: Res<DeformableContext<S>>,
    mut q: Query<(&mut DeformableNodes, Option<&mut DeformableMarkers>)>,
) {
    for body in &ctx.bodies {
        if let Ok((mut nodes, markers)) = q.get_mut(body.entity) {
            nodes.0.clear();
            nodes.0.extend_from_slice(body.solver.node_positions());
            if let Some(mut m) = markers {
                m.read(&body.solver);
            }
        }
    }
}

/// Inserts the context of solver type `S`, registers it (and [`DeformableNodes`]) as state, and
/// adds its step (in `Substep`) and writeback (in `PhysicsStep`) systems to `set`.
pub fn add_deformable_systems<S: DeformableSolver>(app: &mut SimApp, set: DeformableSystems)
where
    DeformableContext<S>: Component<Mutability = Mutable>,
{
    app.insert_resource(DeformableContext::<S>::default());
    let mut access = app
        .world
        .get_resource_or_insert_with(DeformableAccess::default);
    access.solvers.push((ref_body::<S>, get_body::<S>));
    let previous = access.sets.last().cloned();
    if access.sets.contains(&set) {
        app.report_duplicate("deformable solver set", set.0);
        return;
    }
    access.sets.push(set.clone());
    // One set per solver, after the previous solver's, between the contact refresh and flush,
    // before the rigid step.
    let solve = set
        .clone()
        .in_set(crate::app::SubstepSystems::Solve)
        .after(ContactRefresh)
        .before(crate::rigid::RigidSystems::Step);
    let writeback = set.clone().in_set(crate::app::PhysicsSystems::Writeback);
    match previous {
        Some(p) => {
            app.configure_sets(crate::Substep, solve.after(p.clone()));
            app.configure_sets(crate::PhysicsStep, writeback.after(p));
        }
        None => {
            crate::contact::add_contact_systems(app);
            app.configure_sets(crate::Substep, solve);
            app.configure_sets(crate::PhysicsStep, writeback);
        }
    }
    app.register_stateful::<DeformableContext<S>>();
    app.register_stateful_component::<DeformableNodes>();
    app.register_stateful_component::<DeformableMarkers>();
    app.add_systems(crate::Substep, deformable_step::<S>.in_set(set.clone()));
    app.add_systems(crate::PhysicsStep, deformable_writeback::<S>.in_set(set));
}
