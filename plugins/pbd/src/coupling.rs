//! The coupling API between the cloth and the rigid world.
//!
//! The cloth asks for the colliders near a particle ([`ContactQuery`]) once per step and hands back
//! the impulses it applied ([`Reaction`]); the caller (the engine's rigid plugin) applies them to the
//! bodies. The types are plain data so the solver stays independent of rapier. They mirror the
//! engine's `coupling` module field for field so that the engine can re-export one set later.

use nalgebra::Vector3;

/// Closest point of a rigid collider near a query point (world frame, SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointContact {
    /// Closest point on the collider's surface, world frame, m.
    pub point: Vector3<f64>,
    /// Unit normal, outward from the collider, world frame.
    pub normal: Vector3<f64>,
    /// Signed distance of the query point along `normal`, m (negative inside).
    pub distance: f64,
    /// Coulomb friction coefficient of the collider's material.
    pub friction: f64,
    /// Id of the rigid body the collider belongs to (for reactions); `u32::MAX` for colliders
    /// without a body (no reaction is reported for those).
    pub body: u32,
    /// Velocity of the collider surface at `point`, world frame, m/s.
    pub velocity: Vector3<f64>,
}

/// Rigid-world queries the cloth needs.
pub trait ContactQuery {
    /// Appends one [`PointContact`] per collider within `max_distance` of `p` to `out`.
    fn contacts_near(&self, p: &Vector3<f64>, max_distance: f64, out: &mut Vec<PointContact>);
}

/// Impulse the cloth applied on rigid body `body` at `point` during a step (N s); the caller
/// applies it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reaction {
    /// Body id as given in [`PointContact::body`] (or the frame's body for attachments).
    pub body: u32,
    /// Application point, world frame, m.
    pub point: Vector3<f64>,
    /// Impulse on the rigid body, world frame, N s.
    pub impulse: Vector3<f64>,
}

/// A world without colliders (for a cloth used standalone).
#[derive(Debug, Clone, Copy, Default)]
pub struct NoColliders;

impl ContactQuery for NoColliders {
    fn contacts_near(&self, _p: &Vector3<f64>, _max_distance: f64, _out: &mut Vec<PointContact>) {}
}
