//! Components every scene object carries.

use bevy_ecs::prelude::*;
use nalgebra::{Isometry3, Vector3};

use crate::state::{HashState, StateHasher};

/// A scene object: its unique name and its index in the scene's object list.
#[derive(Component, Debug, Clone, PartialEq, Eq)]
pub struct Object {
    /// Unique name from the scene file.
    pub name: String,
    /// Index in `SceneModel::objects`.
    pub index: u32,
    /// Body kind: `static`, `dynamic`, `kinematic`, or a plugin kind such as `fem.solid`.
    pub kind: String,
}

/// Pose of an object, `world_from_body` (for deformables: the pose they were spawned at).
#[derive(Component, Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pose(pub Isometry3<f64>);

impl HashState for Pose {
    fn hash_state(&self, h: &mut StateHasher) {
        let t = self.0.translation.vector;
        let q = self.0.rotation.quaternion();
        for x in [t.x, t.y, t.z, q.i, q.j, q.k, q.w] {
            h.write_f64(x);
        }
    }
}

/// Linear (m/s) and angular (rad/s) velocity of a rigid object, world frame.
#[derive(
    Component, Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize,
)]
pub struct Velocity {
    /// Linear velocity of the centre of mass, m/s.
    pub linear: Vector3<f64>,
    /// Angular velocity, rad/s.
    pub angular: Vector3<f64>,
}

impl HashState for Velocity {
    fn hash_state(&self, h: &mut StateHasher) {
        for x in self.linear.iter().chain(self.angular.iter()) {
            h.write_f64(*x);
        }
    }
}

/// World positions of a deformable's nodes or particles (m), written by its plugin in
/// `Writeback`; what `--dump-state` reports and observation terms read.
#[derive(Component, Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct DeformableNodes(pub Vec<Vector3<f64>>);

crate::persist_by_serde!(Pose, Velocity, DeformableNodes);

impl HashState for DeformableNodes {
    fn hash_state(&self, h: &mut StateHasher) {
        for p in &self.0 {
            for x in p.iter() {
                h.write_f64(*x);
            }
        }
    }
}

/// Joint state of an articulated object (a robot), on its root entity: names, positions (rad
/// or m) and velocities, written by the plugin that owns it in `Writeback`; what `--dump-state`
/// reports under `joints` and observation terms read.
#[derive(Component, Debug, Clone, PartialEq, Default)]
pub struct JointState {
    /// Joint names, in the owner's joint order.
    pub names: std::sync::Arc<[String]>,
    /// Positions, rad or m.
    pub positions: Vec<f64>,
    /// Velocities, rad/s or m/s.
    pub velocities: Vec<f64>,
}

/// The names are fixed at spawn; positions and velocities are the state.
impl crate::codec::Persist for JointState {
    fn encode(&self, e: &mut crate::codec::Encoder) {
        e.put(&self.positions);
        e.put(&self.velocities);
    }
    fn decode(
        &mut self,
        d: &mut crate::codec::Decoder<'_>,
    ) -> Result<(), crate::codec::StateError> {
        let positions: Vec<f64> = d.take()?;
        let velocities: Vec<f64> = d.take()?;
        if positions.len() != self.names.len() || velocities.len() != self.names.len() {
            return Err(crate::codec::StateError::part(
                d.part(),
                format!(
                    "{} positions and {} velocities for {} joints",
                    positions.len(),
                    velocities.len(),
                    self.names.len()
                ),
            ));
        }
        self.positions = positions;
        self.velocities = velocities;
        Ok(())
    }
}

impl HashState for JointState {
    fn hash_state(&self, h: &mut StateHasher) {
        for x in self.positions.iter().chain(&self.velocities) {
            h.write_f64(*x);
        }
    }
}
