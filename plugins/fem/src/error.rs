//! Error values of the FEM plugin. Nothing in the crate panics on bad input or on a blow-up;
//! every failure is one of these.

use std::fmt;

/// Everything that can go wrong when building or stepping an elastic solid.
#[derive(Clone, Debug, PartialEq)]
pub enum FemError {
    /// A material or solver parameter is out of range; says which and what is valid.
    InvalidParameter {
        /// Parameter name, e.g. `"material.poisson_ratio"`.
        name: &'static str,
        /// The offending value.
        value: f64,
        /// What would be valid, e.g. `"in (-1, 0.5)"`.
        expected: &'static str,
    },
    /// The input mesh is malformed (empty, index out of range, non-finite coordinate).
    InvalidMesh(String),
    /// Tetrahedron `tet` has non-positive or degenerate rest volume (m^3).
    DegenerateElement {
        /// Index of the input tetrahedron.
        tet: usize,
        /// Its signed rest volume (m^3).
        volume: f64,
    },
    /// A node index passed to an API call does not exist.
    NodeOutOfRange {
        /// The index.
        node: u32,
        /// Number of nodes of the solid.
        count: usize,
    },
    /// An attachment or grasp identifier is unknown (already released, or never created).
    UnknownAttachment(u32),
    /// An input of a step (time step, gravity, frame pose, contact) is NaN or infinite.
    NonFiniteInput(&'static str),
    /// The state became non-finite or exceeded the configured speed limit during step `step`;
    /// the solver state was rolled back to the beginning of that step.
    Exploded {
        /// Index of the failed step (number of successful steps before it).
        step: u64,
        /// Largest node speed seen (m/s), `f64::INFINITY` for NaN.
        max_speed: f64,
    },
    /// A matrix that should be positive definite was not (bad constraints or parameters).
    NotPositiveDefinite(String),
    /// `set_state` received a vector that does not describe a state of this solid.
    InvalidState(String),
    /// A rest point to embed lies outside every element.
    PointOutsideMesh {
        /// The rest-frame point (m).
        point: [f64; 3],
    },
}

impl fmt::Display for FemError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FemError::InvalidParameter { name, value, expected } => {
                write!(f, "invalid {name} = {value}: expected {expected}")
            }
            FemError::InvalidMesh(m) => write!(f, "invalid mesh: {m}"),
            FemError::DegenerateElement { tet, volume } => write!(
                f,
                "tetrahedron {tet} has rest volume {volume:e} m^3: tets must be positively oriented and non-degenerate"
            ),
            FemError::NodeOutOfRange { node, count } => {
                write!(f, "node {node} out of range: the solid has {count} nodes")
            }
            FemError::UnknownAttachment(id) => write!(f, "unknown attachment or grasp id {id}"),
            FemError::NonFiniteInput(what) => write!(f, "non-finite input: {what}"),
            FemError::Exploded { step, max_speed } => write!(
                f,
                "simulation exploded at step {step} (max node speed {max_speed:e} m/s); state rolled back. Reduce the time step, add substeps or damping, or check the constraints"
            ),
            FemError::NotPositiveDefinite(m) => write!(f, "matrix not positive definite: {m}"),
            FemError::InvalidState(m) => write!(f, "invalid state vector: {m}"),
            FemError::PointOutsideMesh { point } => write!(
                f,
                "rest point ({}, {}, {}) lies outside the mesh",
                point[0], point[1], point[2]
            ),
        }
    }
}

impl std::error::Error for FemError {}
