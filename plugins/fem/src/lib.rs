//! # modesuite-fem: tetrahedral elastic solids
//!
//! The numerical core of the `fem.solid` body kind: rods, belts and tori as quadratic (10-node)
//! tetrahedra with the Stable Neo-Hookean material, stepped by implicit backward Euler, with
//! world constraints, kinematic attachments to rigid frames, force-limited grasps and frictional
//! contact with rigid colliders. Engine independent: nalgebra only.
//!
//! ## Architecture
//!
//! | module | role |
//! |---|---|
//! | [`material`] | Stable Neo-Hookean energy, stress, tangent, corrected Lamé mapping |
//! | [`element`] | 10-node tetrahedra from a linear tet mesh (edge nodes, shape functions, quadrature) |
//! | [`model`] | immutable compiled solid (masses, quadrature data, sparsity), element kernel |
//! | [`sparse`] | block-CSR matrix, RCM ordering, profile Cholesky, filtered PCG |
//! | [`solid`] | [`FemSolid`]: state arrays, constraints, grasps, contact, time step, snapshots |
//! | [`coupling`] | [`ContactQuery`], [`PointContact`], [`Reaction`]: the rigid-coupling interface |
//! | [`bench`](mod@bench) | the reference-rod benchmark helpers |
//! | [`testing`] | tiny Kuhn box mesher for tests and benchmarks |
//! | [`warp`] | per-node rotations that warp the chord matrix to the current shape |
//!
//! Why 10-node elements: linear tetrahedra lock in bending (a coarse rod is 5-10x too stiff);
//! quadratic ones reach a few percent of beam theory with one element through the thickness
//! (reference rod, linear static: 0.974 / 0.987 / 0.995 of Euler-Bernoulli on Kuhn 10x1x1 /
//! 20x1x1 / 40x2x2 grids, `tests/validation.rs`).
//!
//! ## API in one screen
//!
//! - Build: [`FemSolid::new`]`(nodes, tets, Material, FemConfig)` from a positively oriented
//!   linear tet mesh; the edge nodes are added (corners keep their indices, edge nodes follow).
//! - Step: [`FemSolid::step`]`(dt, gravity, &dyn ContactQuery, &mut Vec<Reaction>)
//!   -> Result<StepStats, FemError>`; statics: [`FemSolid::solve_static`],
//!   [`FemSolid::solve_linear_static`].
//! - Constraints: [`FemSolid::fix_nodes`], [`FemSolid::constrain_nodes_along`] (rollers),
//!   [`FemSolid::set_constraint_target`], [`FemSolid::release_nodes`]; kinematic attachment to a
//!   rigid frame [`FemSolid::attach_to_body`] / [`FemSolid::detach`], frames moved with
//!   [`FemSolid::set_body_pose`] before each step; grasps [`FemSolid::grasp`] (stiffness, force
//!   limit past which it slips) / [`FemSolid::release_grasp`] / [`FemSolid::grasp_info`].
//! - Coupling out: reactions (impulses on rigid bodies) from attachments, grasps and contacts;
//!   [`FemSolid::constraint_forces`] per constrained node.
//! - Derived quantities: [`FemSolid::positions`], [`FemSolid::velocities`], tracked points
//!   ([`FemSolid::embed_point`], [`FemSolid::embed_line`], [`FemSolid::embedded_position`]),
//!   [`FemSolid::green_strains`], [`FemSolid::max_strain`], [`FemSolid::elastic_energy`],
//!   [`FemSolid::kinetic_energy`], [`FemSolid::volume`], [`FemSolid::inverted_count`].
//! - Snapshots: [`FemSolid::get_state`] / [`FemSolid::set_state`] (bit-exact, including
//!   velocities, constraints, attachments, grasps and the preconditioner reference shape).
//! - Errors: every failure is a [`FemError`]; a step that produces non-finite values or exceeds
//!   `FemConfig::max_speed` is rolled back and reported as [`FemError::Exploded`].
//!
//! ## Use
//!
//! ```
//! use modesuite_fem::{FemSolid, FemConfig, Material, NoContacts, testing::box_mesh};
//! use nalgebra::Vector3;
//! let (nodes, tets) = box_mesh(Vector3::zeros(), Vector3::new(1.0, 0.04, 0.04), [10, 1, 1]);
//! let mut rod = FemSolid::new(&nodes, &tets, Material::new(1e6, 0.35, 60.0).unwrap(), FemConfig::default()).unwrap();
//! let clamp = rod.rest_nodes_where(|p| p.x == 0.0);
//! rod.fix_nodes(&clamp).unwrap();
//! let mut reactions = Vec::new();
//! let stats = rod.step(1.0 / 60.0, Vector3::new(0.0, 0.0, -9.81), &NoContacts, &mut reactions).unwrap();
//! assert!(stats.converged);
//! ```
//!
//! Determinism: every loop runs in a fixed order (sorted edges and constraints, no hash maps, no
//! threads), so the same inputs give bit-identical results; `get_state`/`set_state` round-trip
//! bit-exactly.

#![warn(missing_docs)]

pub mod bench;
pub mod coupling;
pub mod element;
pub mod error;
pub mod material;
pub mod model;
pub mod plugin;
mod precond;
pub mod solid;
pub mod sparse;
pub mod testing;
pub mod warp;

pub use coupling::{ContactQuery, HalfSpace, NoContacts, PointContact, Reaction};
pub use error::FemError;
pub use material::{Material, StableNeoHookean};
pub use model::SolidModel;
pub use plugin::{FemContext, FemPlugin, SolidKind, SolidParams};
pub use solid::{FemConfig, FemSolid, GraspInfo, GraspParams, PointEmbedding, StepStats};
