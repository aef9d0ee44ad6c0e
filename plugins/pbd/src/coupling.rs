//! The coupling API between the cloth and the rigid world: the engine's types, re-exported.
//!
//! The cloth asks for the colliders near a particle ([`ContactQuery`]) once per step and hands
//! back the impulses it applied ([`Reaction`]); the engine's rigid plugin applies them.

pub use modesuite_engine::coupling::{ContactQuery, NoColliders, PointContact, Reaction};
