//! The compiled form of rigid objects ([`RigidModel`]), what the rigid world spawns.

use std::sync::Arc;

use nalgebra::Vector3;

use crate::shapes::SurfaceMesh;

/// How a rigid object moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RigidKind {
    /// Never moves.
    Static,
    /// Simulated.
    Dynamic,
    /// Moved by the program.
    Kinematic,
}

/// Collision geometry of a rigid object, in its body frame.
#[derive(Debug, Clone)]
pub enum RigidShape {
    /// Box with half extents, m.
    Cuboid(Vector3<f64>),
    /// Sphere of radius, m.
    Ball(f64),
    /// Cylinder along z.
    CylinderZ {
        /// Radius, m.
        radius: f64,
        /// Half the height, m.
        half_height: f64,
    },
    /// Capsule along z.
    CapsuleZ {
        /// Radius, m.
        radius: f64,
        /// Half the length of the cylindrical part, m.
        half_height: f64,
    },
    /// The half space z <= 0 of the body frame (static planes).
    HalfSpace,
    /// A triangle mesh (static bodies).
    TriMesh(Arc<SurfaceMesh>),
    /// A convex decomposition of a triangle mesh (dynamic and kinematic bodies).
    ConvexDecomposition {
        /// The mesh (what renderers draw).
        mesh: Arc<SurfaceMesh>,
        /// Its convex parts, computed once when the scene compiles (every env's collider
        /// shares them).
        parts: rapier3d::prelude::SharedShape,
    },
}

/// A compiled rigid object.
#[derive(Debug, Clone)]
pub struct RigidModel {
    /// How it moves.
    pub kind: RigidKind,
    /// Collision geometry.
    pub shape: RigidShape,
    /// Mass override, kg (else density x volume).
    pub mass: Option<f64>,
    /// Initial linear velocity, m/s.
    pub linear_velocity: Vector3<f64>,
    /// Initial angular velocity, rad/s.
    pub angular_velocity: Vector3<f64>,
}
