//! The coupling API between deformables (FEM, PBD) and the rigid world.
//!
//! Deformable solvers ask for the colliders near a point ([`ContactQuery`]) and hand back the
//! impulses they applied ([`Reaction`]); the rigid plugin turns those into forces on the bodies
//! (forces, because rapier ignores impulses on multibody links). The types are plain data so the
//! solvers stay independent of rapier.

use nalgebra::Vector3;

/// Closest point of a rigid collider near a query point (world frame, SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointContact {
    /// Closest point on the collider's surface, m.
    pub point: Vector3<f64>,
    /// Unit normal, outward from the collider.
    pub normal: Vector3<f64>,
    /// Signed distance of the query point along `normal`, m (negative inside).
    pub distance: f64,
    /// Coulomb friction coefficient of the collider's material.
    pub friction: f64,
    /// Id of the rigid body the collider belongs to (for reactions); `u32::MAX` for colliders
    /// without a body.
    pub body: u32,
    /// Velocity of the collider surface at `point`, m/s.
    pub velocity: Vector3<f64>,
}

/// Rigid-world queries a deformable solver needs.
pub trait ContactQuery {
    /// Appends one [`PointContact`] per collider within `max_distance` of `p` to `out`.
    fn contacts_near(&self, p: &Vector3<f64>, max_distance: f64, out: &mut Vec<PointContact>);

    /// The same queries restricted to the colliders that may come near the box `[lo, hi]`, for a
    /// solver about to make many queries inside it (a cloth's particles): every
    /// `contacts_near(p, d)` whose cube `p +- d` lies inside the box returns the same contacts,
    /// in the same order, as on `self`. `None` (the default) means "query `self`".
    fn region(&self, _lo: &Vector3<f64>, _hi: &Vector3<f64>) -> Option<Box<dyn ContactQuery + '_>> {
        None
    }
}

/// An impulse a deformable applied to rigid body `body` at `point` during a substep, N s.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Reaction {
    /// Body id as given in [`PointContact::body`].
    pub body: u32,
    /// Application point, world frame, m.
    pub point: Vector3<f64>,
    /// Impulse on the rigid body, world frame, N s.
    pub impulse: Vector3<f64>,
}

/// A world without colliders (for solvers used standalone).
#[derive(Debug, Clone, Copy, Default)]
pub struct NoColliders;

impl ContactQuery for NoColliders {
    fn contacts_near(&self, _p: &Vector3<f64>, _max_distance: f64, _out: &mut Vec<PointContact>) {}
}

/// One gripper as the deformable plugins see it: the rigid body that holds, the finger volume
/// (an oriented box in that body's frame), whether it is closed and the force it holds before
/// the grasped material slips. Robots write it; deformables react to it (level-triggered: a
/// closed gripper with no grasp grasps what is inside its volume, an open one releases), so
/// snapshots and resets need no event bookkeeping.
#[derive(Debug, Clone, PartialEq)]
pub struct GripperState {
    /// Unique name, e.g. `robot/gripper`.
    pub name: String,
    /// Body id of the holding body (as in [`PointContact::body`]).
    pub body: u32,
    /// Pose of the finger volume's centre in the body frame.
    pub volume_pose: nalgebra::Isometry3<f64>,
    /// Half extents of the finger volume, m.
    pub half_extents: Vector3<f64>,
    /// Closed (grasping) or open.
    pub closed: bool,
    /// Total force the grasp transmits before it slips, N.
    pub force_limit: f64,
}

/// Every gripper of an env (a resource written by the robots plugin in `ApplyActions`).
#[derive(bevy_ecs::prelude::Resource, Debug, Clone, PartialEq, Default)]
pub struct Grippers(pub Vec<GripperState>);
