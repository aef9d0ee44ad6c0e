//! # modesuite-pbd: XPBD cloth
//!
//! The numerical core of the `pbd.cloth` body kind: a triangle-surface cloth simulated with
//! extended position-based dynamics and small steps, engine-independent (nalgebra only).
//!
//! ## Pieces
//! * [`Cloth`] owns all solver state in flat arrays (positions, velocities, masses, constraint
//!   rows sorted by graph colour, contact caches) and steps with [`Cloth::step`].
//!   [`Cloth::new`] builds a cloth from any triangle surface (`positions`, `triangles`);
//!   [`GridSheet`] makes rectangular sheets; [`Cloth::from_distance_constraints`] builds ropes
//!   and chains.
//! * Constraints: edge distance (stretch/shear; compliance given per unit of material and scaled
//!   per edge so that refining the mesh keeps the behaviour), isometric bending (Bergou et al.
//!   2006; the constraint `sum_i K_i x_i` is linear, so one projection is exact and cheap),
//!   long-range tethers to pinned particles (Kim, Chentanez, Müller 2012), frame attachments with
//!   a force limit (grasp and slip), kinematic pins, rigid contacts with Coulomb friction and
//!   thickness, optional edge-midpoint contacts, and self-collision (spatial hash, point-triangle
//!   with side memory, point-point).
//! * Coupling to rigid bodies goes through [`coupling::ContactQuery`] (closest points, queried
//!   once per step, turned into moving plane constraints, which for convex colliders cannot be
//!   tunnelled through) and [`coupling::Reaction`] (impulses the cloth applied, for the caller to
//!   apply to the rigid bodies).
//! * Derived quantities: positions, named groups (handles, tracked points), stretch statistics,
//!   covered area of a region (Cover), fraction of particles over a region (Uncover).
//! * [`Cloth::get_state`] / [`Cloth::set_state`]: bit-exact snapshots (positions, velocities,
//!   frames, attachments, time). Lagrange multipliers restart each substep, so they are not
//!   state. Stepping is deterministic: no hash-map iteration, fixed orders everywhere.
//! * [`testing`] has analytic colliders (plane, box, sphere, cylinder); [`bench`](mod@bench) the
//!   reference-sheet benchmark of the peer harness.
//!
//! ## Choices and their measured reasons
//! * **f64 particle arrays** (an f32 variant was not built or measured). The converged
//!   hanging-chain test reaches 1e-13 relative error in f64; profiles show the time going to
//!   gather/scatter and sqrt/division latency rather than memory bandwidth (a 1600-particle
//!   sheet's positions are 38 KB), which f32 would only partly help.
//! * **Padded particles and AVX2 copies of the hot loops** (`lanes.rs`): during a step each
//!   particle is `[x, y, z, 0]`, 32-byte aligned (one 256-bit load or store), and the distance,
//!   bending, tether, prediction and velocity loops are compiled a second time with AVX2
//!   enabled, chosen at run time. Same bits either way (no fused multiply-adds; tested), same
//!   bits as the earlier `Vector3<f64>` arrays (nalgebra's order of operations). Measured
//!   1.5x on the reference sheet (2026-11-25, docs/bench-history.md); an SoA layout with gathers was
//!   not needed: rows of one colour are gathered as whole particles.
//! * **Gauss-Seidel in colour order**, one iteration per substep by default (8 substeps per
//!   1/60 s step): constraints of one colour share no particle, so distance constraints are
//!   processed four at a time (one vector square root and one vector division for four rows). Under-iterated XPBD is always softer than converged, never
//!   stiffer (tested). Stiff bending needs many more substeps to converge (the drape test uses
//!   80 per frame).
//! * **Straight tethers only from kinematic pins**: a force-limited attachment must feel the
//!   cloth's load through the constraints; tethers to it made the grip force wrong (measured).
//!   Grasps may instead anchor *grasp tethers* (`SolverSettings::grasp_tethers`, off by
//!   default): a follow-the-leader sweep along the shortest-path tree from the grasp that limits
//!   stretch only (5 % slack per edge) and is not part of the grasp's reaction or force limit;
//!   it lets three grasped particles drag a 41 x 31 table cover off a table (see
//!   ARCHITECTURE.md, "Grasp tethers", for the measured alternatives).
//! * **Contacts are queried once per step** (one `contacts_near` call per particle), plus a
//!   guard: a particle that constraint corrections carry farther than its query radius is
//!   queried again within the step. Without the guard, one particle of the reference sheet
//!   ended 7 mm inside the cube when edge contacts yanked it around a corner.
//! * **Edge contacts off by default**: on, they stop mesh edges from cutting box corners, where
//!   friction otherwise locks a particle and leaves its edges stretched (max strain 25.8 % at 8
//!   substeps in the reference scene; 11 % with edge contacts), but they also change coarse
//!   drapes over the disc rim (Cusick 21 -> 31 particles per side: change 0.027, beyond the 0.02
//!   tolerance, versus 0.006 without).
//!
//! ## Errors
//! Non-finite results never propagate: a step that produces one is rolled back and returns
//! [`PbdError::NonFinite`]; non-finite inputs (parameters, poses, contacts) are rejected with an
//! error that names the field.

#![warn(missing_docs)]

pub mod bench;
mod cloth;
pub mod coupling;
mod error;
mod lanes;
mod material;
mod mesh;
pub mod plugin;
mod selfcollide;
pub mod testing;
#[cfg(test)]
mod tests;

pub use cloth::{
    AttachmentId, Cloth, DistanceConstraint, FrameId, OrientedBox, Region, StepStats, StretchStats,
};
pub use coupling::{ContactQuery, NoColliders, PointContact, Reaction};
pub use error::PbdError;
pub use material::{ClothMaterial, SolverSettings, TetherMetric};
pub use mesh::{fold_positions, GridSheet};
pub use plugin::{ClothKind, ClothParams, PbdContext, PbdPlugin};
