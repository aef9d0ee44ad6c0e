//! Deformable-rigid coupling interface.
//!
//! The FEM solver does not know about rigid-body engines: it asks a [`ContactQuery`] for the
//! closest points of rigid colliders near its surface nodes and reports the impulses it applied
//! to rigid bodies as [`Reaction`]s. The engine implements the query (over parry/rapier) and
//! applies the reactions. These types will move to the engine crate and be re-exported here.

use nalgebra::Vector3;

/// Closest point of a rigid collider near a query point (world frame, SI units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointContact {
    /// Closest point on the collider surface (world frame, m).
    pub point: Vector3<f64>,
    /// Unit normal at `point`, pointing outward from the collider (world frame).
    pub normal: Vector3<f64>,
    /// Signed distance from the query point to the collider surface (m), negative inside.
    pub distance: f64,
    /// Coulomb friction coefficient of the contact pair (dimensionless).
    pub friction: f64,
    /// Identifier of the rigid body that owns the collider (the engine's handle).
    pub body: u32,
    /// Velocity of the collider surface at `point` (world frame, m/s).
    pub velocity: Vector3<f64>,
}

/// Source of rigid contacts for the deformable solver.
pub trait ContactQuery {
    /// Appends to `out` the closest collider points within `max_distance` (m) of `p` (world
    /// frame). At most one entry per collider is expected; `out` is not cleared by the callee's
    /// contract, the caller clears it before the call.
    fn contacts_near(&self, p: &Vector3<f64>, max_distance: f64, out: &mut Vec<PointContact>);
}

/// Impulse the deformable applied on rigid body `body` at `point` during a step (N s); the caller
/// applies it (as a force J/dt for multibody links).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reaction {
    /// Identifier of the rigid body that receives the impulse.
    pub body: u32,
    /// Application point (world frame, m).
    pub point: Vector3<f64>,
    /// Impulse on the rigid body (world frame, N s).
    pub impulse: Vector3<f64>,
}

/// A [`ContactQuery`] with no colliders (free space).
#[derive(Clone, Copy, Debug, Default)]
pub struct NoContacts;

impl ContactQuery for NoContacts {
    fn contacts_near(&self, _p: &Vector3<f64>, _max_distance: f64, _out: &mut Vec<PointContact>) {}
}

/// A static or moving half-space `{ y : (y - origin) . normal <= 0 }` as a collider, useful for
/// floors and slopes in tests and simple scenes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HalfSpace {
    /// A point on the boundary plane (world frame, m).
    pub origin: Vector3<f64>,
    /// Unit outward normal of the boundary plane (world frame).
    pub normal: Vector3<f64>,
    /// Coulomb friction coefficient.
    pub friction: f64,
    /// Body identifier reported in contacts.
    pub body: u32,
    /// Velocity of the half-space (world frame, m/s).
    pub velocity: Vector3<f64>,
}

impl ContactQuery for HalfSpace {
    fn contacts_near(&self, p: &Vector3<f64>, max_distance: f64, out: &mut Vec<PointContact>) {
        let distance = (p - self.origin).dot(&self.normal);
        if distance <= max_distance {
            out.push(PointContact {
                point: p - distance * self.normal,
                normal: self.normal,
                distance,
                friction: self.friction,
                body: self.body,
                velocity: self.velocity,
            });
        }
    }
}
