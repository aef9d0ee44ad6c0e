//! The solver-neutral interface of deformable bodies ([`DeformableSolver`]) and how to reach a
//! body of any solver from the world ([`deformable_mut`], [`deformable_ref`]). Below both the
//! generic deformable plumbing ([`crate::deformable`]) and contact between deformables
//! ([`crate::contact`]), which use it.

use bevy_ecs::prelude::*;
use nalgebra::{Isometry3, UnitQuaternion, Vector3};

use crate::coupling::{ContactQuery, Reaction};

use crate::rigid::DeformableSystems;

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
    /// The modulus, Pa, with which the body's material resists being compressed (a solid's
    /// Young's modulus): what decides whether a rigid body heavier than the deformable, pressing
    /// it onto a support, resolves the contact itself ([`crate::contact::support`]). Default:
    /// none (such a body never does).
    fn compression_modulus(&self) -> Option<f64> {
        None
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

pub(super) type RefFn = for<'a> fn(&'a World, Entity) -> Option<&'a dyn DeformableSolver>;
pub(super) type GetFn = for<'a> fn(&'a mut World, Entity) -> Option<&'a mut dyn DeformableSolver>;

/// How to reach the body of an entity in every solver's context, whatever its type (filled by
/// [`add_deformable_systems`](super::add_deformable_systems)); see [`deformable_mut`].
#[derive(Resource, Default, Clone)]
pub struct DeformableAccess {
    pub(super) solvers: Vec<(RefFn, GetFn)>,
    /// The solvers' system sets, in registration order (chained in that order).
    pub(super) sets: Vec<DeformableSystems>,
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
