//! Deformable-rigid coupling interface.
//!
//! The FEM solver does not know about rigid-body engines: it asks a [`ContactQuery`] for the
//! closest points of rigid colliders near its surface nodes and reports the impulses it applied
//! to rigid bodies as [`Reaction`]s. The engine implements the query (over parry/rapier) and
//! applies the reactions. The three interface types are the engine's, re-exported here; [`NoContacts`] and
//! [`HalfSpace`] are small implementations for standalone use and tests.

use nalgebra::Vector3;

pub use modesuite_engine::coupling::{ContactQuery, PointContact, Reaction};

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
