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
use nalgebra::{Isometry3, Vector3};

use crate::app::SimErrors;
use crate::codec::{Decoder, Encoder, Persist, StateError};
use crate::components::{DeformableNodes, Object};
use crate::contact::rigid_side::{RigidSurfaces, SurfaceSync, WithoutRigidSide};
use crate::contact::{
    deliver, ContactImpulses, ContactRefresh, ContactSurface, DeformableContacts,
};
use crate::coupling::{ContactQuery, GripperState, Grippers, NoColliders, Reaction};
use crate::rigid::{DeformableSystems, RigidContext};
use crate::state::{mismatch, HashState, PluginStates, StateHasher, Stateful};
use crate::terms::{passive_forces_for, ForceContext, SceneTerms};
use crate::{SimApp, SimClock, SimSettings};

pub mod solver;

pub use solver::{
    deformable_mut, deformable_ref, DeformableAccess, DeformableSolver, FingerVolume,
};

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
    rigid_surfaces: Option<Res<RigidSurfaces>>,
    names: Query<&Object>,
    contact_surfaces: Query<&ContactSurface>,
) {
    // Substep index within the physics step; deformables step at the first of every stride.
    let index = clock.substeps % u64::from(settings.step_substeps());
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
            // impulses owed by other deformables' contacts or by rigid bodies' (rigid_side)
            let object = names.get(entity).ok().map(|o| o.index);
            if let (Some(object), Some(j)) = (object, impulses.as_deref_mut()) {
                if let Err(e) = deliver(j, object, &mut body.solver) {
                    errors.raise(format!("object \"{}\": contact impulses: {e}", name()));
                    continue;
                }
            }
            let without;
            let rigid_query: &dyn ContactQuery = match rigid.as_deref() {
                Some(r) => match rigid_surfaces.as_deref().and_then(|s| s.of(entity)) {
                    // bodies lighter than this one resolve their contact with it themselves; the
                    // dynamic scene bodies it resolves are seen moving with the nodes they touch
                    Some(s) => {
                        let thickness = contact_surfaces.get(entity).map_or(0.0, |c| c.thickness);
                        without = WithoutRigidSide::with_touching(r, s, &body.solver, thickness);
                        &without
                    }
                    None => r,
                },
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
        .before(SurfaceSync)
        .before(crate::rigid::RigidSystems::Step);
    let writeback = set.clone().in_set(crate::app::PhysicsSystems::Writeback);
    match previous {
        Some(p) => {
            app.configure_sets(crate::Substep, solve.after(p.clone()));
            app.configure_sets(crate::PhysicsStep, writeback.after(p));
        }
        None => {
            crate::contact::add_contact_systems(app);
            crate::contact::rigid_side::add_rigid_side_systems(app);
            crate::contact::support::add_coupling_plan(app);
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
