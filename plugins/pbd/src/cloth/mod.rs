//! The cloth: particle state, constraints and the XPBD step.
//!
//! # Algorithm
//! One call of [`Cloth::step`] advances `dt` in `substeps` substeps of `h = dt / substeps`
//! ("Small steps in physics simulation", Macklin, Storey, Lu, Terdiman, Chentanez, Kim, Müller,
//! SCA 2019). Each substep: damp and integrate gravity, predict `x += h v`, move pinned particles to
//! their (interpolated) targets, then `iterations` Gauss-Seidel sweeps of XPBD projections
//! ("XPBD: position-based simulation of compliant constrained dynamics", Macklin, Müller,
//! Chentanez, MIG 2016): `dlambda = (-C - alpha~ lambda) / (sum_i w_i |grad_i C|^2 + alpha~)`,
//! `alpha~ = alpha / h^2`, over distance (stretch/shear) constraints in colour order, isometric
//! bending hinges, long-range tethers, frame/grasp attachments (force-limited), self-collision and
//! rigid contacts; then Coulomb friction on the contacts (positional, as in Macklin et al.,
//! "Unified particle physics for real-time applications", 2014) and `v = (x - x_prev) / h`.
//!
//! Rigid colliders are queried once per step: each particle's closest points within
//! `thickness/2 + (|v| + |g| dt) dt + margin` become plane constraints `n . (x - p(t)) >= thickness/2`
//! whose plane moves with the collider surface velocity. For convex colliders the tangent plane
//! at the closest point separates the particle from the collider, so a particle that obeys it
//! cannot enter the collider however fast it moves (no tunnelling within the query radius).
//! Colliders are kinematic during the step; the impulses the cloth applied are reported as
//! [`Reaction`]s (two-way coupling, staggered).
//!
//! # Files
//!
//! The types and the cloth's fields are here; its methods are split by responsibility:
//! `build` (construction), `access` (accessors, groups, measures), `attach` (frames and
//! attachments), `caches` (solver caches, tethers), `step` (the step: contacts and substeps),
//! `solve` (the constraint projections) and `state` (snapshots).
//!
//! [`Reaction`]: crate::coupling::Reaction

mod access;
mod attach;
mod build;
mod caches;
mod solve;
mod state;
mod step;

use crate::coupling::PointContact;
use crate::error::PbdError;
use crate::lanes::{RowCache, SolverRows, P4};
use crate::material::{ClothMaterial, SolverSettings};
use crate::selfcollide::SelfCollision;
use nalgebra::{Isometry3, Vector3};
use std::collections::BTreeMap;
use std::sync::Arc;

/// An explicit distance constraint for [`Cloth::from_distance_constraints`] (ropes, chains).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DistanceConstraint {
    /// The two particles.
    pub particles: [u32; 2],
    /// Rest length, m.
    pub rest_length: f64,
    /// XPBD compliance `alpha`, m/N (inverse spring stiffness).
    pub compliance: f64,
}

/// Handle of a frame (a rigid pose the caller sets every step, e.g. a gripper link).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct FrameId(pub u32);

/// Handle of an attachment (pin, frame attachment or grasp).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct AttachmentId(pub u32);

/// An oriented box in the world frame (a gripper's finger volume): the engine's
/// [`FingerVolume`](modesuite_engine::deformable::FingerVolume).
pub use modesuite_engine::deformable::FingerVolume as OrientedBox;

/// Per-step diagnostics returned by [`Cloth::step`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepStats {
    /// Rigid contacts (particle, collider) gathered this step.
    pub contacts: usize,
    /// Self-collision candidate pairs (point-triangle plus point-point) gathered this step.
    pub self_collision_pairs: usize,
    /// Largest particle speed at the end of the step, m/s.
    pub max_speed: f64,
    /// Attachments that slipped (hit their force limit) during the step.
    pub slipping_attachments: usize,
}

/// Mean and maximum edge strain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StretchStats {
    /// Mean of `L / L0 - 1` over the edges (signed, as the peer benchmark reports it).
    pub mean: f64,
    /// Mean of `|L / L0 - 1|`.
    pub mean_abs: f64,
    /// Maximum of `L / L0 - 1`.
    pub max: f64,
}

/// An axis-aligned rectangle in the world xy plane (a target region's footprint), m.
pub use modesuite_engine::surface::Region;

/// A frame whose pose the caller sets each step; attachments follow it.
#[derive(Debug, Clone, PartialEq)]
struct Frame {
    /// Rigid body that feels the attachment reactions (`u32::MAX`: none).
    body: u32,
    /// Pose at the start of the next step.
    prev: Isometry3<f64>,
    /// Pose at the end of the next step (set by the caller).
    target: Isometry3<f64>,
}

/// A frame the cloth moves itself: at constant velocity from its initial pose during a time
/// window (a scripted handle, e.g. a group of particles dragged along the ground).
#[derive(Debug, Clone, PartialEq)]
struct Drive {
    frame: u32,
    /// Pose of the frame before the window, world frame.
    origin: Isometry3<f64>,
    /// Velocity during the window, m/s.
    velocity: Vector3<f64>,
    /// Window `[start, stop]` of simulated time, s.
    start: f64,
    stop: f64,
}

/// Particles held by a frame or the world.
#[derive(Debug, Clone, PartialEq)]
struct Attachment {
    id: u32,
    /// Frame index, or `None` for the world.
    frame: Option<u32>,
    /// Kinematic (pinned: infinite mass, exact) or force-limited.
    kinematic: bool,
    /// Force limit of the whole attachment, N (`INFINITY`: unlimited).
    max_force: f64,
    /// Attached particles.
    particles: Vec<u32>,
    /// Particle positions in frame coordinates (world coordinates when `frame` is `None`), m.
    local: Vec<Vector3<f64>>,
    /// Whether the attachment hit its force limit during the last step.
    slipped: bool,
    /// Impulse the attachment applied on the cloth during the last step, world frame, N s.
    impulse: Vector3<f64>,
    /// Per-particle accumulated multipliers of the current substep (scratch), kg m.
    lambda: Vec<Vector3<f64>>,
    /// Scratch for candidate multipliers.
    cand: Vec<Vector3<f64>>,
}

/// An XPBD cloth (or rope) with all solver state in flat arrays.
///
/// Array conventions (MuJoCo header style): `(n, 3)` means one `Vector3<f64>` per particle.
#[derive(Debug, Clone)]
pub struct Cloth {
    material: ClothMaterial,
    settings: SolverSettings,
    /// Simulated time, s.
    time: f64,
    /// Steps taken.
    steps: u64,

    // ---- particles
    /// `(n, 3)` positions, world frame, m.
    pos: Vec<Vector3<f64>>,
    /// `(n, 3)` velocities, world frame, m/s.
    vel: Vec<Vector3<f64>>,
    /// `(n, 3)` rest positions, m (mesh rest shape; measures and tethers).
    rest: Vec<Vector3<f64>>,
    /// `(n)` masses, kg.
    mass: Vec<f64>,
    /// `(n)` inverse masses without pins, 1/kg.
    inv_mass_free: Vec<f64>,
    /// `(n)` inverse masses used by the solver (0 for pinned particles), 1/kg.
    inv_mass: Vec<f64>,
    /// `(n)` working copies of the positions and velocities during a step (the layout of the
    /// kernels in [`lanes`]), and the positions at the start of the substep, m and m/s.
    ///
    /// [`lanes`]: crate::lanes
    x: Vec<P4>,
    v: Vec<P4>,
    prev: Vec<P4>,
    /// Whether the AVX2 versions of the kernels run (same results, see [`lanes`]).
    ///
    /// [`lanes`]: crate::lanes
    avx2: crate::lanes::Simd,
    /// `(n, 3)` scratch: positions / velocities at the start of the step (rollback).
    save_pos: Vec<Vector3<f64>>,
    save_vel: Vec<Vector3<f64>>,

    // ---- triangles
    /// `(t, 3)` triangle vertex indices.
    triangles: Vec<[u32; 3]>,
    /// `(e, 2)` mesh edges (measures), and `(e)` their rest lengths, m.
    edge: Vec<[u32; 2]>,
    edge_rest: Vec<f64>,

    // ---- distance constraints, sorted by colour
    /// `(d, 2)` particles, `(d)` rest lengths m, compliances m/N, multipliers kg m.
    dist_idx: Vec<[u32; 2]>,
    dist_rest: Vec<f64>,
    dist_alpha: Vec<f64>,
    dist_lambda: Vec<f64>,
    /// Packed solver rows (distances, the same in batches of four per colour for the first
    /// iteration, bending) derived from these constraints for the substep length `cache_h`;
    /// shared through `row_cache` with the other cloths of the same compiled object.
    rows: Arc<SolverRows>,
    row_cache: Arc<RowCache>,
    /// End index of each colour in the distance arrays (constraints of one colour share no
    /// particle, so they are processed four at a time).
    dist_colour_end: Vec<usize>,

    // ---- isometric bending hinges, sorted by colour
    /// `(b, 4)` particles (edge x0 x1, opposite x2 x3), `(b, 4)` coefficients K, `(b)`
    /// compliances m/N, `(b, 3)` multipliers kg m.
    bend_idx: Vec<[u32; 4]>,
    bend_k: Vec<[f64; 4]>,
    bend_alpha: Vec<f64>,
    bend_lambda: Vec<P4>,
    /// Substep length the caches were computed for, s (NaN: stale).
    cache_h: f64,

    // ---- tethers (derived from attachments)
    /// Tethers as compact rows (particle, its nearest kinematic particle, maximal distance to
    /// it m), in particle order.
    tether_rows: Vec<(u32, u32, f64)>,
    /// Tethers anchored at grasped (force-limited) particles, along the shortest-path tree:
    /// (particle, its parent on the path to the grasp, maximal distance to it m (the edge's rest
    /// length with the slack)), parents before children.
    grasp_tether_rows: Vec<(u32, u32, f64)>,
    /// `(n)` particle adjacency (CSR over mesh edges / distance constraints) for tethers.
    adj_start: Vec<u32>,
    adj: Vec<(u32, f64)>,

    // ---- attachments
    /// `(f)` frames (poses set by the caller each step).
    frames: Vec<Frame>,
    /// Pins, frame attachments and grasps, in creation order.
    attachments: Vec<Attachment>,
    /// Id the next attachment gets.
    next_attachment: u32,
    /// Frames the cloth moves itself (configuration, not state: the poses follow from the time).
    drives: Vec<Drive>,
    /// `(f)` scratch: frame poses at the end of the current substep.
    frame_now: Vec<Isometry3<f64>>,

    // ---- rigid contacts of the current step (SoA, `(c)` entries, in particle order except for
    // the re-queried ones appended during the step)
    /// Particle of each contact.
    c_particle: Vec<u32>,
    /// `(c, 3)` plane point at the start of the step, world frame, m (it moves with `c_vel`).
    c_point: Vec<P4>,
    /// `(c, 3)` unit outward normal, world frame.
    c_normal: Vec<P4>,
    /// `(c, 3)` collider surface velocity, world frame, m/s.
    c_vel: Vec<P4>,
    /// `(c)` combined friction coefficient.
    c_mu: Vec<f64>,
    /// `(c)` rigid body id (`u32::MAX`: none).
    c_body: Vec<u32>,
    /// Normal correction accumulated in the current substep, m.
    c_dn: Vec<f64>,
    /// Impulse applied on the particle over the step, N s.
    c_impulse: Vec<P4>,
    query_buf: Vec<PointContact>,
    // ---- rigid contacts of mesh-edge midpoints (keep edges from cutting collider corners)
    /// Mesh edge index, contact point m, normal, surface velocity m/s, body, impulse N s.
    e_edge: Vec<u32>,
    e_point: Vec<P4>,
    e_normal: Vec<P4>,
    e_vel: Vec<P4>,
    e_body: Vec<u32>,
    e_impulse: Vec<P4>,
    /// Friction coefficient and normal correction of the current substep, m.
    e_mu: Vec<f64>,
    e_dn: Vec<f64>,
    /// `(n, 3)` position where each particle's colliders were last queried, m, and `(n)` how
    /// far it may move from there before they are queried again, m.
    guard_origin: Vec<P4>,
    guard_radius: Vec<f64>,
    /// `(n + 1)` scratch: start of each particle's contacts in the contact arrays.
    contact_start: Vec<u32>,

    selfc: SelfCollision,

    /// Named particle groups (handles, tracked points); BTreeMap for deterministic order.
    groups: BTreeMap<String, Vec<u32>>,
}

const STATE_MAGIC: f64 = 4_002.0;

fn finite3(v: &Vector3<f64>) -> bool {
    v.x.is_finite() && v.y.is_finite() && v.z.is_finite()
}

fn iso_finite(p: &Isometry3<f64>) -> bool {
    finite3(&p.translation.vector) && p.rotation.coords.iter().all(|c| c.is_finite())
}

fn check_positions(positions: &[Vector3<f64>]) -> Result<(), PbdError> {
    if positions.is_empty() || positions.len() > (u32::MAX / 2) as usize {
        return Err(PbdError::InvalidMesh(format!(
            "{} particles",
            positions.len()
        )));
    }
    if let Some(i) = positions.iter().position(|p| !finite3(p)) {
        return Err(PbdError::InvalidParameter {
            field: "positions",
            value: format!("particle {i} at {:?}", positions[i]),
            expected: "finite coordinates",
        });
    }
    Ok(())
}
