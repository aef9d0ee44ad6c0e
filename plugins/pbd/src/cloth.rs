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

use crate::coupling::{ContactQuery, PointContact, Reaction};
use crate::error::PbdError;
use crate::lanes::{self, BendRow, DistRow, OnceRows, RowCache, SolverRows, P4};
use crate::material::{ClothMaterial, SolverSettings, TetherMetric};
use crate::mesh;
use crate::selfcollide::SelfCollision;
use modesuite_engine::math::interpolate_pose;
use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};
use std::collections::{BTreeMap, BinaryHeap};
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
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Region {
    /// Smallest x and y, m.
    pub min: [f64; 2],
    /// Largest x and y, m.
    pub max: [f64; 2],
}

impl Region {
    /// Area of the rectangle, m^2.
    pub fn area(&self) -> f64 {
        (self.max[0] - self.min[0]).max(0.0) * (self.max[1] - self.min[1]).max(0.0)
    }
    /// Whether the xy projection of `p` lies inside.
    pub fn contains_xy(&self, p: &Vector3<f64>) -> bool {
        p.x >= self.min[0] && p.x <= self.max[0] && p.y >= self.min[1] && p.y <= self.max[1]
    }
}

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
    x: Vec<P4>,
    v: Vec<P4>,
    prev: Vec<P4>,
    /// Whether the AVX2 versions of the kernels run (same results, see [`lanes`]).
    avx2: lanes::Simd,
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

impl Cloth {
    /// Builds a cloth from a triangle surface: masses from the areal density, a distance
    /// constraint per edge (stretch or shear compliance, see [`ClothMaterial`]) and an isometric
    /// bending hinge per interior edge. The rest shape is the given positions; the bending model
    /// assumes a flat rest shape (curved input is pulled towards flat).
    pub fn new(
        positions: &[Vector3<f64>],
        triangles: &[[u32; 3]],
        material: ClothMaterial,
        settings: SolverSettings,
    ) -> Result<Self, PbdError> {
        material.validate()?;
        settings.validate()?;
        check_positions(positions)?;
        if triangles.is_empty() {
            return Err(PbdError::InvalidMesh("no triangles".into()));
        }
        mesh::validate_triangles(positions, triangles)?;
        let n = positions.len();
        let mut mass = vec![0.0; n];
        for t in triangles {
            let m = material.areal_density * mesh::triangle_area(positions, *t) / 3.0;
            for &v in t {
                mass[v as usize] += m;
            }
        }
        if let Some(i) = mass.iter().position(|&m| m <= 0.0) {
            return Err(PbdError::InvalidMesh(format!(
                "particle {i} belongs to no triangle (it would have no mass)"
            )));
        }
        let edges = mesh::mesh_edges(positions, triangles);
        let shear_angle = 80f64.to_radians();
        let mut dists = Vec::with_capacity(edges.len());
        let mut bends = Vec::new();
        for e in &edges {
            let l0 = (positions[e.v[0] as usize] - positions[e.v[1] as usize]).norm();
            let c = if e.max_opposite_angle > shear_angle {
                material.shear_compliance
            } else {
                material.stretch_compliance
            };
            dists.push(DistanceConstraint {
                particles: e.v,
                rest_length: l0,
                compliance: c * l0 * l0 / e.area,
            });
            if e.opp[1] != u32::MAX {
                let ids = [e.v[0], e.v[1], e.opp[0], e.opp[1]];
                let x = ids.map(|i| positions[i as usize]);
                let k = mesh::isometric_bending_coefficients(x);
                if k.iter().all(|v| v.is_finite()) {
                    bends.push((ids, k, e.area * material.bending_compliance / 3.0));
                }
            }
        }
        let mut cloth = Self::build(
            positions, &mass, triangles, &dists, bends, material, settings,
        )?;
        cloth.edge = edges.iter().map(|e| e.v).collect();
        cloth.edge_rest = edges
            .iter()
            .map(|e| (positions[e.v[0] as usize] - positions[e.v[1] as usize]).norm())
            .collect();
        Ok(cloth)
    }

    /// Builds a particle system held together by explicit distance constraints only (a rope or a
    /// hanging chain); `masses` in kg. No triangles: no bending, no self-collision, no area
    /// measures. `material` supplies damping, friction and thickness.
    pub fn from_distance_constraints(
        positions: &[Vector3<f64>],
        masses: &[f64],
        constraints: &[DistanceConstraint],
        material: ClothMaterial,
        settings: SolverSettings,
    ) -> Result<Self, PbdError> {
        material.validate()?;
        settings.validate()?;
        check_positions(positions)?;
        if masses.len() != positions.len() {
            return Err(PbdError::InvalidParameter {
                field: "masses",
                value: format!("{} entries", masses.len()),
                expected: "one mass per particle",
            });
        }
        for &m in masses {
            crate::error::check_param("masses[i]", m, 0.0, true, "a finite mass > 0 kg")?;
        }
        for c in constraints {
            for &p in &c.particles {
                if p as usize >= positions.len() || c.particles[0] == c.particles[1] {
                    return Err(PbdError::InvalidMesh(format!(
                        "distance constraint {:?} refers to a missing or repeated particle",
                        c.particles
                    )));
                }
            }
            crate::error::check_param(
                "constraint.rest_length",
                c.rest_length,
                0.0,
                false,
                "a finite length >= 0 m",
            )?;
            crate::error::check_param(
                "constraint.compliance",
                c.compliance,
                0.0,
                false,
                "a finite compliance >= 0 m/N",
            )?;
        }
        let mut cloth = Self::build(
            positions,
            masses,
            &[],
            constraints,
            Vec::new(),
            material,
            settings,
        )?;
        cloth.edge = constraints.iter().map(|c| c.particles).collect();
        cloth.edge_rest = constraints.iter().map(|c| c.rest_length).collect();
        Ok(cloth)
    }

    fn build(
        positions: &[Vector3<f64>],
        masses: &[f64],
        triangles: &[[u32; 3]],
        dists: &[DistanceConstraint],
        bends: Vec<([u32; 4], [f64; 4], f64)>,
        material: ClothMaterial,
        settings: SolverSettings,
    ) -> Result<Self, PbdError> {
        let n = positions.len();
        // colour-sorted distance constraints
        let lists: Vec<&[u32]> = dists.iter().map(|d| &d.particles[..]).collect();
        let col = mesh::greedy_colouring(n, &lists);
        let mut order: Vec<usize> = (0..dists.len()).collect();
        order.sort_by_key(|&k| (col[k], k));
        let dist_idx: Vec<[u32; 2]> = order.iter().map(|&k| dists[k].particles).collect();
        let dist_rest: Vec<f64> = order.iter().map(|&k| dists[k].rest_length).collect();
        let dist_alpha: Vec<f64> = order.iter().map(|&k| dists[k].compliance).collect();
        let dist_colour_end = colour_ends(&order.iter().map(|&k| col[k]).collect::<Vec<_>>());
        // colour-sorted bending hinges
        let blists: Vec<&[u32]> = bends.iter().map(|b| &b.0[..]).collect();
        let bcol = mesh::greedy_colouring(n, &blists);
        let mut border: Vec<usize> = (0..bends.len()).collect();
        border.sort_by_key(|&k| (bcol[k], k));
        // adjacency for tethers
        let mut deg = vec![0u32; n + 1];
        for d in dists {
            deg[d.particles[0] as usize] += 1;
            deg[d.particles[1] as usize] += 1;
        }
        let mut adj_start = vec![0u32; n + 1];
        for i in 0..n {
            adj_start[i + 1] = adj_start[i] + deg[i];
        }
        let mut fill = adj_start.clone();
        let mut adj = vec![(0u32, 0.0f64); adj_start[n] as usize];
        for d in dists {
            let [a, b] = d.particles;
            adj[fill[a as usize] as usize] = (b, d.rest_length);
            fill[a as usize] += 1;
            adj[fill[b as usize] as usize] = (a, d.rest_length);
            fill[b as usize] += 1;
        }
        let inv: Vec<f64> = masses.iter().map(|m| 1.0 / m).collect();
        Ok(Cloth {
            material,
            settings,
            time: 0.0,
            steps: 0,
            pos: positions.to_vec(),
            vel: vec![Vector3::zeros(); n],
            rest: positions.to_vec(),
            mass: masses.to_vec(),
            inv_mass_free: inv.clone(),
            inv_mass: inv,
            x: positions.iter().map(P4::from_v).collect(),
            v: vec![P4::ZERO; n],
            prev: positions.iter().map(P4::from_v).collect(),
            avx2: lanes::Simd::detect(),
            save_pos: positions.to_vec(),
            save_vel: vec![Vector3::zeros(); n],
            triangles: triangles.to_vec(),
            edge: Vec::new(),
            edge_rest: Vec::new(),
            dist_lambda: vec![0.0; dist_idx.len()],
            rows: Arc::default(),
            row_cache: Arc::default(),
            dist_colour_end,
            dist_idx,
            dist_rest,
            dist_alpha,
            bend_idx: border.iter().map(|&k| bends[k].0).collect(),
            bend_k: border.iter().map(|&k| bends[k].1).collect(),
            bend_alpha: border.iter().map(|&k| bends[k].2).collect(),
            bend_lambda: vec![P4::ZERO; bends.len()],
            cache_h: f64::NAN,
            tether_rows: Vec::new(),
            grasp_tether_rows: Vec::new(),
            adj_start,
            adj,
            frames: Vec::new(),
            attachments: Vec::new(),
            next_attachment: 0,
            drives: Vec::new(),
            frame_now: Vec::new(),
            c_particle: Vec::new(),
            c_point: Vec::new(),
            c_normal: Vec::new(),
            c_vel: Vec::new(),
            c_mu: Vec::new(),
            c_body: Vec::new(),
            c_dn: Vec::new(),
            c_impulse: Vec::new(),
            query_buf: Vec::new(),
            e_edge: Vec::new(),
            e_point: Vec::new(),
            e_normal: Vec::new(),
            e_vel: Vec::new(),
            e_body: Vec::new(),
            e_impulse: Vec::new(),
            e_mu: Vec::new(),
            e_dn: Vec::new(),
            contact_start: vec![0; n + 1],
            guard_origin: positions.iter().map(P4::from_v).collect(),
            guard_radius: vec![0.0; n],
            selfc: SelfCollision::new(positions, triangles),
            groups: BTreeMap::new(),
        })
    }

    // ------------------------------------------------------------------ accessors

    /// Number of particles.
    pub fn num_particles(&self) -> usize {
        self.pos.len()
    }
    /// Triangles, `(t, 3)` particle indices.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }
    /// Particle positions, `(n, 3)`, world frame, m.
    pub fn positions(&self) -> &[Vector3<f64>] {
        &self.pos
    }
    /// Particle velocities, `(n, 3)`, world frame, m/s.
    pub fn velocities(&self) -> &[Vector3<f64>] {
        &self.vel
    }
    /// Rest positions, `(n, 3)`, m.
    pub fn rest_positions(&self) -> &[Vector3<f64>] {
        &self.rest
    }
    /// Particle masses, `(n)`, kg.
    pub fn masses(&self) -> &[f64] {
        &self.mass
    }
    /// Total mass, kg.
    pub fn total_mass(&self) -> f64 {
        self.mass.iter().sum()
    }
    /// Material parameters.
    pub fn material(&self) -> &ClothMaterial {
        &self.material
    }
    /// Solver settings.
    pub fn settings(&self) -> &SolverSettings {
        &self.settings
    }
    /// Replaces the solver settings (validated first).
    pub fn set_settings(&mut self, settings: SolverSettings) -> Result<(), PbdError> {
        settings.validate()?;
        self.settings = settings;
        self.rebuild_tethers();
        Ok(())
    }
    /// Simulated time, s.
    pub fn time(&self) -> f64 {
        self.time
    }
    /// Steps taken since construction (restored by [`Cloth::set_state`]).
    pub fn step_count(&self) -> u64 {
        self.steps
    }
    /// Positions of the given particles, world frame, m (tracked points).
    pub fn particle_positions(&self, particles: &[u32]) -> Result<Vec<Vector3<f64>>, PbdError> {
        particles
            .iter()
            .map(|&p| {
                self.pos
                    .get(p as usize)
                    .copied()
                    .ok_or_else(|| PbdError::Unknown(format!("particle {p}")))
            })
            .collect()
    }
    /// Kinetic energy, J.
    pub fn kinetic_energy(&self) -> f64 {
        self.vel
            .iter()
            .zip(&self.mass)
            .map(|(v, m)| 0.5 * m * v.norm_squared())
            .sum()
    }

    /// Sets all positions (m) and zeroes the velocities (e.g. to start from a folded shape).
    pub fn set_positions(&mut self, positions: &[Vector3<f64>]) -> Result<(), PbdError> {
        if positions.len() != self.pos.len() {
            return Err(PbdError::InvalidParameter {
                field: "positions",
                value: format!("{} entries", positions.len()),
                expected: "one position per particle",
            });
        }
        check_positions(positions)?;
        self.pos.copy_from_slice(positions);
        self.vel.iter_mut().for_each(|v| *v = Vector3::zeros());
        Ok(())
    }

    /// Sets all velocities (m/s), e.g. a push; pinned and attached particles (zero inverse mass)
    /// keep following their anchors, so their entries are ignored.
    pub fn set_velocities(&mut self, velocities: &[Vector3<f64>]) -> Result<(), PbdError> {
        if velocities.len() != self.vel.len() {
            return Err(PbdError::InvalidParameter {
                field: "velocities",
                value: format!("{} entries", velocities.len()),
                expected: "one velocity per particle",
            });
        }
        if !velocities.iter().all(|v| v.iter().all(|x| x.is_finite())) {
            return Err(PbdError::InvalidParameter {
                field: "velocities",
                value: "a non-finite entry".to_string(),
                expected: "finite velocities, m/s",
            });
        }
        for ((v, new), w) in self.vel.iter_mut().zip(velocities).zip(&self.inv_mass) {
            if *w > 0.0 {
                *v = *new;
            }
        }
        Ok(())
    }

    // ------------------------------------------------------------------ groups

    /// Names a particle group (a handle or a tracked set). Replaces an existing group.
    pub fn add_group(&mut self, name: &str, particles: &[u32]) -> Result<(), PbdError> {
        if let Some(&p) = particles.iter().find(|&&p| p as usize >= self.pos.len()) {
            return Err(PbdError::Unknown(format!("particle {p} in group '{name}'")));
        }
        self.groups.insert(name.to_string(), particles.to_vec());
        Ok(())
    }
    /// The particles of a named group.
    pub fn group(&self, name: &str) -> Result<&[u32], PbdError> {
        self.groups
            .get(name)
            .map(|v| v.as_slice())
            .ok_or_else(|| PbdError::Unknown(format!("particle group '{name}'")))
    }
    /// Positions of a named group's particles, world frame, m.
    pub fn group_positions(&self, name: &str) -> Result<Vec<Vector3<f64>>, PbdError> {
        let g = self.group(name)?;
        self.particle_positions(g)
    }
    /// Names of all groups, sorted.
    pub fn group_names(&self) -> Vec<String> {
        self.groups.keys().cloned().collect()
    }

    // ------------------------------------------------------------------ frames and attachments

    /// Adds a frame (e.g. a gripper link) at `pose`; `body` is the rigid body that receives the
    /// attachment reactions (`u32::MAX` for none).
    pub fn add_frame(&mut self, pose: Isometry3<f64>, body: u32) -> Result<FrameId, PbdError> {
        if !iso_finite(&pose) {
            return Err(PbdError::InvalidParameter {
                field: "frame pose",
                value: format!("{pose:?}"),
                expected: "a finite pose",
            });
        }
        self.frames.push(Frame {
            body,
            prev: pose,
            target: pose,
        });
        Ok(FrameId(self.frames.len() as u32 - 1))
    }

    /// Sets the pose the frame will have at the end of the next step; attachments follow the
    /// pose interpolated over the substeps (translation linear, rotation slerp).
    pub fn set_frame_pose(&mut self, frame: FrameId, pose: Isometry3<f64>) -> Result<(), PbdError> {
        if !iso_finite(&pose) {
            return Err(PbdError::InvalidParameter {
                field: "frame pose",
                value: format!("{pose:?}"),
                expected: "a finite pose",
            });
        }
        let f = self
            .frames
            .get_mut(frame.0 as usize)
            .ok_or_else(|| PbdError::Unknown(format!("frame {}", frame.0)))?;
        f.target = pose;
        Ok(())
    }

    /// Current (end of last step) pose of a frame.
    pub fn frame_pose(&self, frame: FrameId) -> Result<Isometry3<f64>, PbdError> {
        self.frames
            .get(frame.0 as usize)
            .map(|f| f.prev)
            .ok_or_else(|| PbdError::Unknown(format!("frame {}", frame.0)))
    }

    fn check_particles(&self, particles: &[u32]) -> Result<(), PbdError> {
        if particles.is_empty() {
            return Err(PbdError::InvalidParameter {
                field: "particles",
                value: "[]".into(),
                expected: "at least one particle",
            });
        }
        if let Some(&p) = particles.iter().find(|&&p| p as usize >= self.pos.len()) {
            return Err(PbdError::Unknown(format!("particle {p}")));
        }
        Ok(())
    }

    fn push_attachment(
        &mut self,
        frame: Option<u32>,
        kinematic: bool,
        max_force: f64,
        particles: &[u32],
    ) -> AttachmentId {
        let local: Vec<Vector3<f64>> = particles
            .iter()
            .map(|&p| {
                let x = self.pos[p as usize];
                match frame {
                    None => x,
                    Some(f) => {
                        self.frames[f as usize]
                            .prev
                            .inverse_transform_point(&Point3::from(x))
                            .coords
                    }
                }
            })
            .collect();
        let id = self.next_attachment;
        self.next_attachment += 1;
        let k = particles.len();
        self.attachments.push(Attachment {
            id,
            frame,
            kinematic,
            max_force,
            particles: particles.to_vec(),
            local,
            slipped: false,
            impulse: Vector3::zeros(),
            lambda: vec![Vector3::zeros(); k],
            cand: vec![Vector3::zeros(); k],
        });
        self.refresh_inv_mass();
        self.rebuild_tethers();
        AttachmentId(id)
    }

    /// Pins particles to their current world positions (kinematic: they never move).
    pub fn pin_to_world(&mut self, particles: &[u32]) -> Result<AttachmentId, PbdError> {
        self.check_particles(particles)?;
        Ok(self.push_attachment(None, true, f64::INFINITY, particles))
    }

    /// Pins particles rigidly (kinematically) to a frame at their current offsets; they follow
    /// the frame exactly, and no reaction is reported (use [`Cloth::attach_to_frame`] with an
    /// infinite limit for a measured force).
    pub fn pin_to_frame(
        &mut self,
        frame: FrameId,
        particles: &[u32],
    ) -> Result<AttachmentId, PbdError> {
        self.check_particles(particles)?;
        if frame.0 as usize >= self.frames.len() {
            return Err(PbdError::Unknown(format!("frame {}", frame.0)));
        }
        Ok(self.push_attachment(Some(frame.0), true, f64::INFINITY, particles))
    }

    /// Pins particles kinematically to a new frame that the cloth itself moves at constant
    /// `velocity` (m/s, world frame) during the simulated-time window `[start, stop]` (s) and holds
    /// still before and after (a scripted handle: a group dragged along the ground, a corner
    /// lifted). The frame's pose follows from the cloth's time, so snapshots need nothing extra;
    /// [`Cloth::set_frame_pose`] on this frame is overridden at every step.
    pub fn drive_particles(
        &mut self,
        particles: &[u32],
        velocity: Vector3<f64>,
        start: f64,
        stop: f64,
    ) -> Result<(FrameId, AttachmentId), PbdError> {
        self.check_particles(particles)?;
        if !finite3(&velocity) {
            return Err(PbdError::InvalidParameter {
                field: "drive velocity",
                value: format!("{velocity:?}"),
                expected: "a finite vector (m/s)",
            });
        }
        if !(start.is_finite() && stop.is_finite() && start >= 0.0 && stop >= start) {
            return Err(PbdError::InvalidParameter {
                field: "drive window",
                value: format!("[{start}, {stop}]"),
                expected: "finite times with 0 <= start <= stop (s)",
            });
        }
        let frame = self.add_frame(Isometry3::identity(), u32::MAX)?;
        let id = self.pin_to_frame(frame, particles)?;
        self.drives.push(Drive {
            frame: frame.0,
            origin: Isometry3::identity(),
            velocity,
            start,
            stop,
        });
        Ok((frame, id))
    }

    /// Attaches particles to a frame at their current offsets with a total force limit `max_force`
    /// (N, may be `f64::INFINITY`). Above the limit the particles slip (they are re-anchored
    /// where the limited force leaves them, like kinetic friction). Reactions go to the frame's
    /// body.
    pub fn attach_to_frame(
        &mut self,
        frame: FrameId,
        particles: &[u32],
        max_force: f64,
    ) -> Result<AttachmentId, PbdError> {
        self.check_particles(particles)?;
        if frame.0 as usize >= self.frames.len() {
            return Err(PbdError::Unknown(format!("frame {}", frame.0)));
        }
        if max_force.is_nan() || max_force <= 0.0 {
            return Err(PbdError::InvalidParameter {
                field: "max_force",
                value: format!("{max_force}"),
                expected: "a force > 0 N (or infinity)",
            });
        }
        Ok(self.push_attachment(Some(frame.0), false, max_force, particles))
    }

    /// A gripper closes: attaches every particle inside the finger volume `volume` (world frame,
    /// current positions) to `frame` with force limit `max_force` (N). Returns `None` when no
    /// particle is inside.
    pub fn grasp(
        &mut self,
        frame: FrameId,
        volume: &OrientedBox,
        max_force: f64,
    ) -> Result<Option<AttachmentId>, PbdError> {
        if !iso_finite(&volume.pose) || !finite3(&volume.half_extents) {
            return Err(PbdError::InvalidParameter {
                field: "grasp volume",
                value: format!("{volume:?}"),
                expected: "a finite pose and half extents",
            });
        }
        let inside: Vec<u32> = (0..self.pos.len() as u32)
            .filter(|&p| volume.contains(&self.pos[p as usize]))
            .collect();
        if inside.is_empty() {
            return Ok(None);
        }
        self.attach_to_frame(frame, &inside, max_force).map(Some)
    }

    /// Removes an attachment (opening the gripper releases the grasp).
    pub fn release(&mut self, id: AttachmentId) -> Result<(), PbdError> {
        let k = self
            .attachments
            .iter()
            .position(|a| a.id == id.0)
            .ok_or_else(|| PbdError::Unknown(format!("attachment {}", id.0)))?;
        self.attachments.remove(k);
        self.refresh_inv_mass();
        self.rebuild_tethers();
        Ok(())
    }

    /// Particles held by an attachment.
    pub fn attachment_particles(&self, id: AttachmentId) -> Result<&[u32], PbdError> {
        self.attachment(id).map(|a| a.particles.as_slice())
    }

    /// Mean force the attachment exerted on the cloth during the last step, world frame, N.
    pub fn attachment_force(&self, id: AttachmentId, dt: f64) -> Result<Vector3<f64>, PbdError> {
        self.attachment(id).map(|a| a.impulse / dt)
    }

    /// Changes the force limit of a frame attachment or grasp (N, > 0, may be infinite).
    pub fn set_attachment_force_limit(
        &mut self,
        id: AttachmentId,
        max_force: f64,
    ) -> Result<(), PbdError> {
        if max_force.is_nan() || max_force <= 0.0 {
            return Err(PbdError::InvalidParameter {
                field: "max_force",
                value: format!("{max_force}"),
                expected: "a force > 0 N (or infinity)",
            });
        }
        let a = self
            .attachments
            .iter_mut()
            .find(|a| a.id == id.0)
            .ok_or_else(|| PbdError::Unknown(format!("attachment {}", id.0)))?;
        if a.kinematic {
            return Err(PbdError::InvalidParameter {
                field: "attachment",
                value: format!("{}", id.0),
                expected: "a force-limited attachment (pins are kinematic)",
            });
        }
        a.max_force = max_force;
        Ok(())
    }

    /// Whether the attachment hit its force limit (slipped) during the last step.
    pub fn attachment_slipped(&self, id: AttachmentId) -> Result<bool, PbdError> {
        self.attachment(id).map(|a| a.slipped)
    }

    /// The first frame that follows rigid body `body`, if any.
    pub fn frame_of_body(&self, body: u32) -> Option<FrameId> {
        self.frames
            .iter()
            .position(|f| f.body == body)
            .map(|i| FrameId(i as u32))
    }

    /// Frames that follow a rigid body (body id other than `u32::MAX`), with their body ids.
    pub fn body_frames(&self) -> Vec<(FrameId, u32)> {
        self.frames
            .iter()
            .enumerate()
            .filter(|(_, f)| f.body != u32::MAX)
            .map(|(i, f)| (FrameId(i as u32), f.body))
            .collect()
    }

    /// The force-limited (grasp) attachments on `frame`, in creation order.
    pub fn grasps_on(&self, frame: FrameId) -> Vec<AttachmentId> {
        self.attachments
            .iter()
            .filter(|a| a.frame == Some(frame.0) && !a.kinematic)
            .map(|a| AttachmentId(a.id))
            .collect()
    }

    /// Appends the particles held by grasps (force-limited attachments on body frames).
    pub fn grasped_particles(&self, out: &mut Vec<u32>) {
        out.extend(
            self.attachments
                .iter()
                .filter(|a| a.frame.is_some() && !a.kinematic)
                .flat_map(|a| a.particles.iter().copied()),
        );
    }

    /// Appends the particles that a rigid contact pushed in the last substep of the last step
    /// (particle order).
    pub fn contact_particles(&self, out: &mut Vec<u32>) {
        out.extend(
            self.c_particle
                .iter()
                .zip(&self.c_dn)
                .filter(|(_, dn)| **dn > 0.0)
                .map(|(p, _)| *p),
        );
    }

    /// Ids of all attachments, in creation order.
    pub fn attachment_ids(&self) -> Vec<AttachmentId> {
        self.attachments
            .iter()
            .map(|a| AttachmentId(a.id))
            .collect()
    }

    fn attachment(&self, id: AttachmentId) -> Result<&Attachment, PbdError> {
        self.attachments
            .iter()
            .find(|a| a.id == id.0)
            .ok_or_else(|| PbdError::Unknown(format!("attachment {}", id.0)))
    }

    /// Chooses the AVX2 or the baseline kernels (tests: both give the same bits); AVX2 only
    /// where the machine has it. Returns whether AVX2 is used.
    #[cfg(test)]
    pub(crate) fn use_avx2(&mut self, on: bool) -> bool {
        self.avx2 = if on {
            lanes::Simd::detect()
        } else {
            lanes::Simd::baseline()
        };
        self.avx2.avx2()
    }

    /// Shares this cloth's solver rows with the other cloths that use `cache` (the envs of one
    /// compiled object): where their rows are bitwise equal they read one copy. Results do not
    /// change (the rows are a pure function of the cloth's data).
    pub(crate) fn share_rows(&mut self, cache: Arc<RowCache>) {
        self.row_cache = cache;
        self.cache_h = f64::NAN;
    }

    /// Whether this cloth reads the same solver rows as `other` (tests).
    #[cfg(test)]
    pub(crate) fn shares_rows_with(&self, other: &Cloth) -> bool {
        Arc::ptr_eq(&self.rows, &other.rows)
    }

    /// Recomputes the packed per-constraint rows for substep length `h` if stale.
    fn refresh_caches(&mut self, h: f64) {
        if self.cache_h == h {
            return;
        }
        let inv_h2 = 1.0 / (h * h);
        let w = &self.inv_mass;
        let mut dist = Vec::with_capacity(self.dist_idx.len());
        for k in 0..self.dist_idx.len() {
            let [a, b] = self.dist_idx[k];
            let at = self.dist_alpha[k] * inv_h2;
            let (wa, wb) = (w[a as usize], w[b as usize]);
            let den = wa + wb + at;
            let inv_denom = if den > 0.0 { 1.0 / den } else { 0.0 };
            dist.push(DistRow {
                a,
                b,
                rest: self.dist_rest[k],
                at,
                inv_denom,
                ka: wa * inv_denom,
                kb: wb * inv_denom,
            });
        }
        let mut bend = Vec::with_capacity(self.bend_idx.len());
        for b in 0..self.bend_idx.len() {
            let ids = self.bend_idx[b];
            let k = self.bend_k[b];
            let at = self.bend_alpha[b] * inv_h2;
            let mut den = at;
            for j in 0..4 {
                den += w[ids[j] as usize] * k[j] * k[j];
            }
            let inv_denom = if den > 0.0 { 1.0 / den } else { 0.0 };
            let wk = [0, 1, 2, 3].map(|j| w[ids[j] as usize] * k[j] * inv_denom);
            bend.push(BendRow {
                ids,
                k,
                wk,
                at,
                inv_denom,
            });
        }
        let once = OnceRows::build(&dist, &self.dist_colour_end);
        self.rows = self.row_cache.share(SolverRows { dist, once, bend });
        self.cache_h = h;
    }

    fn refresh_inv_mass(&mut self) {
        self.cache_h = f64::NAN;
        self.inv_mass.copy_from_slice(&self.inv_mass_free);
        for a in &self.attachments {
            if a.kinematic {
                for &p in &a.particles {
                    self.inv_mass[p as usize] = 0.0;
                }
            }
        }
    }

    /// Long-range attachments: each particle is tethered to its nearest anchor: a pinned
    /// (kinematic) particle, and with [`SolverSettings::grasp_tethers`] a grasped one too
    /// (multi-source Dijkstra over the edge graph, deterministic tie-breaking by index).
    fn rebuild_tethers(&mut self) {
        let n = self.pos.len();
        self.tether_rows.clear();
        self.grasp_tether_rows.clear();
        if !self.settings.tethers {
            return;
        }
        #[derive(PartialEq)]
        struct Item(f64, u32, u32);
        impl Eq for Item {}
        impl PartialOrd for Item {
            fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
                Some(self.cmp(o))
            }
        }
        impl Ord for Item {
            fn cmp(&self, o: &Self) -> std::cmp::Ordering {
                // min-heap on distance, then particle, then anchor
                o.0.total_cmp(&self.0)
                    .then(o.1.cmp(&self.1))
                    .then(o.2.cmp(&self.2))
            }
        }
        let mut dist = vec![f64::INFINITY; n];
        let mut anchor = vec![u32::MAX; n];
        // predecessor on the shortest path and the rest length of that edge
        let mut parent = vec![(u32::MAX, 0.0); n];
        // Anchors that are grasped particles (a particle both pinned and grasped is a pin).
        let mut grasped = vec![false; n];
        let mut is_source = vec![false; n];
        let mut heap = BinaryHeap::new();
        for a in self.attachments.iter().filter(|a| a.kinematic) {
            for &p in &a.particles {
                is_source[p as usize] = true;
            }
        }
        if self.settings.grasp_tethers {
            for a in &self.attachments {
                if a.kinematic || a.frame.is_none() {
                    continue;
                }
                for &p in &a.particles {
                    if !is_source[p as usize] {
                        is_source[p as usize] = true;
                        grasped[p as usize] = true;
                    }
                }
            }
        }
        for s in 0..n {
            if is_source[s] {
                dist[s] = 0.0;
                anchor[s] = s as u32;
                heap.push(Item(0.0, s as u32, s as u32));
            }
        }
        while let Some(Item(d, p, a)) = heap.pop() {
            if d > dist[p as usize] || (d == dist[p as usize] && a != anchor[p as usize]) {
                continue;
            }
            // grasp-anchored particles in the order they are settled (parents first)
            let (par, len) = parent[p as usize];
            if par != u32::MAX && grasped[a as usize] {
                self.grasp_tether_rows.push((
                    p,
                    par,
                    len * (1.0 + self.settings.grasp_tether_slack),
                ));
            }
            let (s, e) = (
                self.adj_start[p as usize] as usize,
                self.adj_start[p as usize + 1] as usize,
            );
            for &(q, l) in &self.adj[s..e] {
                let nd = d + l;
                let qi = q as usize;
                if nd < dist[qi] || (nd == dist[qi] && a < anchor[qi]) {
                    dist[qi] = nd;
                    anchor[qi] = a;
                    parent[qi] = (p, l);
                    heap.push(Item(nd, q, a));
                }
            }
        }
        for i in 0..n {
            if anchor[i] == u32::MAX || anchor[i] as usize == i {
                continue;
            }
            let a = anchor[i] as usize;
            let len = match self.settings.tether_metric {
                TetherMetric::Graph => dist[i],
                TetherMetric::RestEuclidean => (self.rest[i] - self.rest[a]).norm(),
            };
            if !grasped[a] {
                self.tether_rows.push((i as u32, a as u32, len));
            }
        }
    }

    // ------------------------------------------------------------------ stepping

    /// Advances the cloth by `dt` seconds under `gravity` (m/s^2, world frame), colliding with the
    /// colliders `query` reports; impulses applied on rigid bodies are appended to `reactions`.
    ///
    /// On a non-finite result the state is rolled back to the start of the step and an error is
    /// returned (nothing is appended to `reactions`).
    pub fn step(
        &mut self,
        dt: f64,
        gravity: &Vector3<f64>,
        query: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
    ) -> Result<StepStats, PbdError> {
        crate::error::check_param("dt", dt, 0.0, true, "a finite time step > 0 s")?;
        if !finite3(gravity) {
            return Err(PbdError::InvalidParameter {
                field: "gravity",
                value: format!("{gravity:?}"),
                expected: "a finite vector",
            });
        }
        self.save_pos.copy_from_slice(&self.pos);
        self.save_vel.copy_from_slice(&self.vel);
        let saved_att: Vec<(Vec<Vector3<f64>>, bool, Vector3<f64>)> = self
            .attachments
            .iter()
            .map(|a| (a.local.clone(), a.slipped, a.impulse))
            .collect();
        for d in &self.drives {
            let moved = (self.time + dt).clamp(d.start, d.stop) - d.start;
            self.frames[d.frame as usize].target =
                Translation3::from(d.velocity * moved) * d.origin;
        }
        let result = self.step_inner(dt, gravity, query);
        let result = result.and_then(|stats| {
            match self
                .pos
                .iter()
                .zip(&self.vel)
                .position(|(x, v)| !(finite3(x) && finite3(v)))
            {
                Some(p) => Err(PbdError::NonFinite {
                    particle: p,
                    step: self.steps,
                }),
                None => Ok(stats),
            }
        });
        match result {
            Ok(stats) => {
                for f in &mut self.frames {
                    f.prev = f.target;
                }
                self.time += dt;
                self.steps += 1;
                // reactions: rigid contacts
                for c in 0..self.c_particle.len() {
                    let imp = self.c_impulse[c].to_v();
                    if self.c_body[c] != u32::MAX && imp != Vector3::zeros() {
                        reactions.push(Reaction {
                            body: self.c_body[c],
                            point: self.c_point[c].to_v(),
                            impulse: -imp,
                        });
                    }
                }
                for c in 0..self.e_edge.len() {
                    let imp = self.e_impulse[c].to_v();
                    if self.e_body[c] != u32::MAX && imp != Vector3::zeros() {
                        reactions.push(Reaction {
                            body: self.e_body[c],
                            point: self.e_point[c].to_v(),
                            impulse: -imp,
                        });
                    }
                }
                // reactions: force-limited frame attachments
                for a in &self.attachments {
                    if a.kinematic {
                        continue;
                    }
                    if let Some(f) = a.frame {
                        let body = self.frames[f as usize].body;
                        if body != u32::MAX && a.impulse != Vector3::zeros() {
                            let c: Vector3<f64> = a
                                .particles
                                .iter()
                                .map(|&p| self.pos[p as usize])
                                .sum::<Vector3<f64>>()
                                / a.particles.len() as f64;
                            reactions.push(Reaction {
                                body,
                                point: c,
                                impulse: -a.impulse,
                            });
                        }
                    }
                }
                Ok(stats)
            }
            Err(e) => {
                self.pos.copy_from_slice(&self.save_pos);
                self.vel.copy_from_slice(&self.save_vel);
                for (a, (l, s, i)) in self.attachments.iter_mut().zip(saved_att) {
                    a.local = l;
                    a.slipped = s;
                    a.impulse = i;
                }
                Err(e)
            }
        }
    }

    /// Appends the contacts in `query_buf` (queried at time `t_query` into the step) for
    /// particle `i`, validated; stores the plane point at the start of the step.
    fn push_queried(&mut self, i: usize, t_query: f64) -> Result<(), PbdError> {
        for k in 0..self.query_buf.len() {
            let c = self.query_buf[k];
            let ok = finite3(&c.point)
                && finite3(&c.normal)
                && finite3(&c.velocity)
                && c.friction.is_finite()
                && c.friction >= 0.0
                && c.distance.is_finite();
            let nn = c.normal.norm();
            if !ok || nn.is_nan() || nn <= 0.5 {
                return Err(PbdError::NonFiniteContact { particle: i });
            }
            self.c_particle.push(i as u32);
            self.c_point
                .push(P4::from_v(&(c.point - c.velocity * t_query)));
            self.c_normal.push(P4::from_v(&(c.normal / nn)));
            self.c_vel.push(P4::from_v(&c.velocity));
            self.c_mu.push((self.material.friction * c.friction).sqrt());
            self.c_body.push(c.body);
            self.c_dn.push(0.0);
            self.c_impulse.push(P4::ZERO);
        }
        Ok(())
    }

    /// Conservative guard against tunnelling: a particle that constraint corrections moved
    /// farther from where its colliders were last queried than that query's radius is queried
    /// again from its position at the start of the substep (outside the colliders), and the new
    /// planes are enforced before the substep ends.
    fn requery_moved(&mut self, query: &dyn ContactQuery, t_start: f64) -> Result<(), PbdError> {
        let half = 0.5 * self.material.thickness;
        for i in 0..self.x.len() {
            let g = self.guard_radius[i];
            if self.inv_mass[i] == 0.0 || (self.x[i] - self.guard_origin[i]).norm_squared() <= g * g
            {
                continue;
            }
            let from = self.prev[i];
            let r = half + (self.x[i] - from).norm() + self.settings.contact_margin;
            self.query_buf.clear();
            query.contacts_near(&from.to_v(), r, &mut self.query_buf);
            self.push_queried(i, t_start)?;
            self.guard_origin[i] = from;
            self.guard_radius[i] = r - half;
        }
        Ok(())
    }

    fn gather_contacts(
        &mut self,
        dt: f64,
        gravity: &Vector3<f64>,
        query: &dyn ContactQuery,
    ) -> Result<(), PbdError> {
        self.c_particle.clear();
        self.c_point.clear();
        self.c_normal.clear();
        self.c_vel.clear();
        self.c_mu.clear();
        self.c_body.clear();
        self.c_dn.clear();
        self.c_impulse.clear();
        let half = 0.5 * self.material.thickness;
        let gdt = gravity.norm() * dt;
        let margin = self.settings.contact_margin;
        // query distance of a point moving at `speed`: half the thickness, the step's travel
        let radius = |speed: f64| half + (speed + gdt) * dt + margin;
        // every query below (particles, and edge midpoints with their endpoints' larger speed)
        // lies inside the particles' box padded by the largest query distance: the rigid world
        // narrows its colliders to that region once (same contacts, same order)
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        let mut reach: f64 = 0.0;
        for (x, v) in self.pos.iter().zip(&self.vel) {
            lo = lo.inf(x);
            hi = hi.sup(x);
            reach = reach.max(radius(v.norm()));
        }
        let pad = Vector3::repeat(reach * 1.01 + 1e-4);
        let region = if self.pos.is_empty() {
            None
        } else {
            query.region(&(lo - pad), &(hi + pad))
        };
        let query: &dyn ContactQuery = region.as_deref().unwrap_or(query);
        for i in 0..self.pos.len() {
            // pinned particles are queried too (their normals decide edge contacts) but never
            // moved by contacts
            let r = radius(self.vel[i].norm());
            self.query_buf.clear();
            query.contacts_near(&self.pos[i], r, &mut self.query_buf);
            self.push_queried(i, 0.0)?;
            self.guard_origin[i] = P4::from_v(&self.pos[i]);
            self.guard_radius[i] = r - half;
        }
        let m = self.c_particle.len();
        debug_assert_eq!(self.c_dn.len(), m);
        // midpoints of the mesh edges next to a touching particle
        self.e_edge.clear();
        self.e_point.clear();
        self.e_normal.clear();
        self.e_vel.clear();
        self.e_body.clear();
        self.e_mu.clear();
        // contacts are gathered in particle order: CSR starts
        self.contact_start.iter_mut().for_each(|c| *c = 0);
        for &p in &self.c_particle {
            self.contact_start[p as usize + 1] += 1;
        }
        for i in 0..self.pos.len() {
            self.contact_start[i + 1] += self.contact_start[i];
        }
        // An edge whose endpoints touch the same body through differently oriented surfaces
        // (e.g. the top and a side of a box) may cut the collider's corner between them.
        let wraps = |ca: std::ops::Range<usize>, cb: std::ops::Range<usize>| -> bool {
            ca.clone().any(|i| {
                cb.clone().any(|j| {
                    self.c_body[i] == self.c_body[j]
                        && self.c_normal[i].dot(self.c_normal[j]) < 0.985
                })
            })
        };
        for (k, &[a, b]) in self.edge.iter().enumerate() {
            let (a, b) = (a as usize, b as usize);
            let ca = self.contact_start[a] as usize..self.contact_start[a + 1] as usize;
            let cb = self.contact_start[b] as usize..self.contact_start[b + 1] as usize;
            if !self.settings.edge_contacts
                || self.inv_mass[a] + self.inv_mass[b] == 0.0
                || ca.is_empty()
                || cb.is_empty()
                || !wraps(ca, cb)
            {
                continue;
            }
            let mid = (self.pos[a] + self.pos[b]) * 0.5;
            let speed = self.vel[a].norm().max(self.vel[b].norm());
            let r = radius(speed);
            self.query_buf.clear();
            query.contacts_near(&mid, r, &mut self.query_buf);
            for c in &self.query_buf {
                let nn = c.normal.norm();
                let ok = finite3(&c.point) && finite3(&c.normal) && finite3(&c.velocity);
                if !ok || nn.is_nan() || nn <= 0.5 {
                    return Err(PbdError::NonFiniteContact { particle: a });
                }
                self.e_edge.push(k as u32);
                self.e_point.push(P4::from_v(&c.point));
                self.e_normal.push(P4::from_v(&(c.normal / nn)));
                self.e_vel.push(P4::from_v(&c.velocity));
                self.e_body.push(c.body);
                self.e_mu
                    .push((self.material.friction * c.friction.max(0.0)).sqrt());
            }
        }
        self.e_impulse.clear();
        self.e_impulse.resize(self.e_edge.len(), P4::ZERO);
        self.e_dn.clear();
        self.e_dn.resize(self.e_edge.len(), 0.0);
        Ok(())
    }

    fn step_inner(
        &mut self,
        dt: f64,
        gravity: &Vector3<f64>,
        query: &dyn ContactQuery,
    ) -> Result<StepStats, PbdError> {
        let ns = self.settings.substeps as usize;
        let h = dt / ns as f64;
        let inv_h2 = 1.0 / (h * h);
        self.refresh_caches(h);
        self.gather_contacts(dt, gravity, query)?;
        let mut self_pairs = 0;
        if self.settings.self_collision && !self.triangles.is_empty() {
            self_pairs = self.selfc.gather(
                &self.pos,
                &self.rest,
                &self.triangles,
                self.material.thickness,
                self.settings.self_collision_margin,
            );
        }
        for a in &mut self.attachments {
            a.slipped = false;
            a.impulse = Vector3::zeros();
        }
        let damp = 1.0 / (1.0 + self.material.damping * h);
        let half = 0.5 * self.material.thickness;
        let att_alpha = self.settings.attachment_compliance * inv_h2;
        for ((x, v), (p, u)) in self
            .x
            .iter_mut()
            .zip(&mut self.v)
            .zip(self.pos.iter().zip(&self.vel))
        {
            *x = P4::from_v(p);
            *v = P4::from_v(u);
        }
        let g4 = P4::from_v(gravity);
        for s in 0..ns {
            let t_end = (s + 1) as f64 * h;
            let frac = (s + 1) as f64 / ns as f64;
            self.frame_now.clear();
            for f in &self.frames {
                self.frame_now
                    .push(interpolate_pose(&f.prev, &f.target, frac));
            }
            // velocities of the substep before (if any), then predict, in one pass
            lanes::advance(
                self.avx2,
                &mut self.x,
                &mut self.v,
                &mut self.prev,
                &self.inv_mass,
                (s > 0).then_some(1.0 / h),
                damp,
                g4 * h,
                h,
            );
            // kinematic pins
            for a in &self.attachments {
                if a.kinematic {
                    for (k, &p) in a.particles.iter().enumerate() {
                        self.x[p as usize] = P4::from_v(&match a.frame {
                            None => a.local[k],
                            Some(f) => {
                                self.frame_now[f as usize]
                                    .transform_point(&Point3::from(a.local[k]))
                                    .coords
                            }
                        });
                    }
                }
            }
            self.e_dn.iter_mut().for_each(|d| *d = 0.0);
            if self.settings.iterations > 1 {
                self.dist_lambda.iter_mut().for_each(|l| *l = 0.0);
                self.bend_lambda.iter_mut().for_each(|l| *l = P4::ZERO);
            }
            self.c_dn.iter_mut().for_each(|d| *d = 0.0);
            for a in &mut self.attachments {
                a.lambda.iter_mut().for_each(|l| *l = Vector3::zeros());
            }
            for _ in 0..self.settings.iterations {
                if self.settings.iterations == 1 {
                    // multipliers start at zero and are not needed afterwards
                    lanes::distances_once(self.avx2, &mut self.x, &self.rows.once);
                    lanes::bending_once(self.avx2, &mut self.x, &self.rows.bend);
                } else {
                    solve_distances(&mut self.x, &self.rows.dist, &mut self.dist_lambda);
                    solve_bending(&mut self.x, &self.rows.bend, &mut self.bend_lambda);
                }
                self.solve_attachments(att_alpha, h);
                self.solve_tethers();
                if self_pairs > 0 {
                    self.selfc.solve(
                        &mut self.x,
                        &self.inv_mass,
                        &self.triangles,
                        self.material.thickness,
                    );
                }
                self.solve_edge_contacts(t_end, half, h);
                self.solve_contacts_normal(t_end, half);
            }
            self.requery_moved(query, s as f64 * h)?;
            self.apply_edge_friction(h);
            self.apply_friction(h);
            // friction of one contact may push a particle into another contact's plane
            self.reproject_contacts(t_end, half, h);
            if !self.grasp_tether_rows.is_empty() {
                // after friction, so that a tether pulling a particle into a collider (cloth
                // hanging over a table's far edge, pulled from the near one) does not make a
                // normal correction that friction then turns into a lock; the contacts are
                // projected once more (normal only)
                self.solve_grasp_tethers();
                self.reproject_contacts(t_end, half, h);
            }
            // slip: re-anchor attachments that hit their limit at the positions they reached
            for a in &mut self.attachments {
                if a.kinematic {
                    continue;
                }
                let total: Vector3<f64> = a.lambda.iter().sum();
                a.impulse += total / h;
                if total.norm() * inv_h2 >= a.max_force * (1.0 - 1e-12) {
                    a.slipped = true;
                    if let Some(f) = a.frame {
                        let pose = self.frame_now[f as usize];
                        for (k, &p) in a.particles.iter().enumerate() {
                            a.local[k] = pose
                                .inverse_transform_point(&Point3::from(self.x[p as usize].to_v()))
                                .coords;
                        }
                    }
                }
            }
        }
        // velocities of the last substep (the others are computed by `advance`)
        lanes::velocities(self.avx2, &self.x, &mut self.v, &self.prev, 1.0 / h);
        for ((x, v), (p, u)) in self
            .x
            .iter()
            .zip(&self.v)
            .zip(self.pos.iter_mut().zip(&mut self.vel))
        {
            *p = x.to_v();
            *u = v.to_v();
        }
        let max_speed = self.vel.iter().map(|v| v.norm()).fold(0.0, f64::max);
        Ok(StepStats {
            contacts: self.c_particle.len(),
            self_collision_pairs: self_pairs,
            max_speed,
            slipping_attachments: self.attachments.iter().filter(|a| a.slipped).count(),
        })
    }

    fn solve_attachments(&mut self, alpha_t: f64, h: f64) {
        let limit_scale = h * h;
        for a in &mut self.attachments {
            if a.kinematic {
                continue;
            }
            let Some(f) = a.frame else { continue };
            let pose = self.frame_now[f as usize];
            let mut total = Vector3::zeros();
            for (k, &p) in a.particles.iter().enumerate() {
                let w = self.inv_mass[p as usize];
                if w == 0.0 {
                    a.cand[k] = a.lambda[k];
                    continue;
                }
                let target = pose.transform_point(&Point3::from(a.local[k])).coords;
                let c = self.x[p as usize].to_v() - target;
                let dl = (-c - a.lambda[k] * alpha_t) / (w + alpha_t);
                a.cand[k] = a.lambda[k] + dl;
                total += a.cand[k];
            }
            let tn = total.norm();
            let lim = a.max_force * limit_scale;
            let scale = if tn > lim { lim / tn } else { 1.0 };
            for (k, &p) in a.particles.iter().enumerate() {
                let nl = a.cand[k] * scale;
                let w = self.inv_mass[p as usize];
                self.x[p as usize] += P4::from_v(&((nl - a.lambda[k]) * w));
                a.lambda[k] = nl;
            }
        }
    }

    /// Long-range attachments: a particle farther from its (kinematic, never moving) anchor than
    /// the tether length is moved back onto the sphere. Branch-free over the compact rows, four at
    /// a time ([`lanes::tethers`]; whether a tether is active is data dependent and mispredicted
    /// often); anchors have zero inverse mass, so rows touch only their own particle and their
    /// order does not matter.
    fn solve_tethers(&mut self) {
        lanes::tethers(self.avx2, &mut self.x, &self.tether_rows);
    }

    /// Tethers anchored at grasped particles ([`SolverSettings::grasp_tethers`]), "follow the
    /// leader" along the shortest-path tree from the grasp (Müller, Kim, Chentanez, "Fast
    /// simulation of inextensible hair and fur", 2012): in tree order (parents first) a particle
    /// farther from its parent than their edge's rest length times
    /// `1 + SolverSettings::grasp_tether_slack` is moved back onto that sphere; the parent is not
    /// moved (the slack keeps the sweep off in the cloth's ordinary slightly stretched state:
    /// with none, it pulled the whole sheet towards the grasp by the sum of the edges' small
    /// stretches at every substep, and the sheet flew off the table). One sweep carries a pull
    /// across the whole sheet, and, unlike straight-line tethers, along the cloth around a
    /// table's edge (a straight tether pressed the particles hanging over the far edge into the
    /// table's side, where friction held them).
    ///
    /// The sweep is a limit on stretch, not a load path: its corrections are neither reported
    /// to the gripper's body nor counted against the grasp's force limit (the grasp attachment
    /// itself still carries and reports the pull of its neighbours). Counting the impulse of
    /// the corrections overstated the load, because the contacts undo part of them at every
    /// substep: it reached the grasp's whole limit (130 N for Spot) while a cover slid off a
    /// table and dragged Spot back to the table (Spot Uncover: 5 of 8 seeds with it, 8 of 8
    /// without).
    fn solve_grasp_tethers(&mut self) {
        for &(i, par, len) in &self.grasp_tether_rows {
            let d = self.x[i as usize] - self.x[par as usize];
            let l = d.norm();
            if l > len {
                self.x[i as usize] -= d * ((l - len) / l);
            }
        }
    }

    /// Keeps mesh-edge midpoints outside the colliders (so that an edge does not cut a
    /// collider's corner between two particles). Friction is applied after the iterations.
    fn solve_edge_contacts(&mut self, t_end: f64, half: f64, h: f64) {
        for c in 0..self.e_edge.len() {
            let [a, b] = self.edge[self.e_edge[c] as usize];
            let (a, b) = (a as usize, b as usize);
            let (wa, wb) = (self.inv_mass[a], self.inv_mass[b]);
            let n = self.e_normal[c];
            let plane = self.e_point[c] + self.e_vel[c] * t_end;
            let mid = (self.x[a] + self.x[b]) * 0.5;
            let gap = n.dot(mid - plane) - half;
            if gap < 0.0 {
                let lam = -gap / (0.25 * (wa + wb));
                self.x[a] += n * (0.5 * wa * lam);
                self.x[b] += n * (0.5 * wb * lam);
                let moved = 0.5 * lam * (self.mass[a] * wa + self.mass[b] * wb);
                self.e_impulse[c] += n * (moved / h);
                self.e_dn[c] -= gap;
            }
        }
    }

    fn solve_contacts_normal(&mut self, t_end: f64, half: f64) {
        for c in 0..self.c_particle.len() {
            let p = self.c_particle[c] as usize;
            if self.inv_mass[p] == 0.0 {
                continue;
            }
            let n = self.c_normal[c];
            let plane = self.c_point[c] + self.c_vel[c] * t_end;
            let gap = n.dot(self.x[p] - plane) - half;
            if gap < 0.0 {
                self.x[p] -= n * gap;
                self.c_dn[c] -= gap;
            }
        }
    }

    /// Final normal projection after friction (positions and impulses, no friction).
    fn reproject_contacts(&mut self, t_end: f64, half: f64, h: f64) {
        for c in 0..self.c_particle.len() {
            let p = self.c_particle[c] as usize;
            if self.inv_mass[p] == 0.0 {
                continue;
            }
            let n = self.c_normal[c];
            let plane = self.c_point[c] + self.c_vel[c] * t_end;
            let gap = n.dot(self.x[p] - plane) - half;
            if gap < 0.0 {
                self.x[p] -= n * gap;
                self.c_impulse[c] -= n * (gap * self.mass[p] / h);
            }
        }
    }

    fn apply_edge_friction(&mut self, h: f64) {
        for c in 0..self.e_edge.len() {
            let dn = self.e_dn[c];
            if dn <= 0.0 {
                continue;
            }
            let [a, b] = self.edge[self.e_edge[c] as usize];
            let (a, b) = (a as usize, b as usize);
            let (wa, wb) = (self.inv_mass[a], self.inv_mass[b]);
            let n = self.e_normal[c];
            let mid = (self.x[a] + self.x[b]) * 0.5;
            let mid_prev = (self.prev[a] + self.prev[b]) * 0.5;
            let rel = (mid - mid_prev) - self.e_vel[c] * h;
            let tang = rel - n * n.dot(rel);
            let tl = tang.norm();
            let lim = self.e_mu[c] * dn;
            let target = if tl <= lim { -tang } else { -tang * (lim / tl) };
            // move the midpoint by `target`: dx_i = w_i / 2 * target / ((w_a + w_b) / 4)
            let s = 2.0 / (wa + wb);
            self.x[a] += target * (wa * s);
            self.x[b] += target * (wb * s);
            let moved = (self.mass[a] * wa + self.mass[b] * wb) * s;
            self.e_impulse[c] += target * (moved / h);
        }
    }

    fn apply_friction(&mut self, h: f64) {
        for c in 0..self.c_particle.len() {
            let dn = self.c_dn[c];
            if dn <= 0.0 {
                continue;
            }
            let p = self.c_particle[c] as usize;
            let n = self.c_normal[c];
            let rel = (self.x[p] - self.prev[p]) - self.c_vel[c] * h;
            let tang = rel - n * n.dot(rel);
            let tl = tang.norm();
            let lim = self.c_mu[c] * dn;
            let corr = if tl <= lim { -tang } else { -tang * (lim / tl) };
            self.x[p] += corr;
            self.c_impulse[c] += (n * dn + corr) * (self.mass[p] / h);
        }
    }

    // ------------------------------------------------------------------ measures

    /// Mean and maximum strain over the mesh edges (the distance constraints for ropes).
    pub fn stretch_stats(&self) -> StretchStats {
        let mut sum = 0.0;
        let mut sum_abs = 0.0;
        let mut max = f64::NEG_INFINITY;
        for (e, &l0) in self.edge.iter().zip(&self.edge_rest) {
            if l0 <= 0.0 {
                continue;
            }
            let l = (self.pos[e[0] as usize] - self.pos[e[1] as usize]).norm();
            let s = l / l0 - 1.0;
            sum += s;
            sum_abs += s.abs();
            max = max.max(s);
        }
        let m = self.edge.len().max(1) as f64;
        StretchStats {
            mean: sum / m,
            mean_abs: sum_abs / m,
            max,
        }
    }

    /// Fraction of particles whose xy projection lies inside `region` (Uncover: what is still
    /// covered).
    pub fn fraction_above(&self, region: &Region) -> f64 {
        let k = self.pos.iter().filter(|p| region.contains_xy(p)).count();
        k as f64 / self.pos.len() as f64
    }

    /// Area of `region` covered by the cloth's xy projection, m^2 (Cover), estimated on a
    /// `resolution` x `resolution` grid of sample points (cell centres); the error is at most the
    /// region's boundary cells.
    pub fn covered_area(&self, region: &Region, resolution: usize) -> f64 {
        self.covered_area_above(region, resolution, f64::NEG_INFINITY)
    }

    /// [`Cloth::covered_area`] counting only the triangles whose three particles are higher
    /// than `above` (m): Cover's gap is covered by cloth spanning it, not by cloth lying on the
    /// floor under it.
    pub fn covered_area_above(&self, region: &Region, resolution: usize, above: f64) -> f64 {
        let r = resolution.max(1);
        let (x0, y0) = (region.min[0], region.min[1]);
        let dx = (region.max[0] - x0) / r as f64;
        let dy = (region.max[1] - y0) / r as f64;
        if !(dx > 0.0 && dy > 0.0) {
            return 0.0;
        }
        let mut covered = vec![false; r * r];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.pos[i as usize]);
            if !(a.z > above && b.z > above && c.z > above) {
                continue;
            }
            let lo_x = a.x.min(b.x).min(c.x);
            let hi_x = a.x.max(b.x).max(c.x);
            let lo_y = a.y.min(b.y).min(c.y);
            let hi_y = a.y.max(b.y).max(c.y);
            let i0 = (((lo_x - x0) / dx - 0.5).ceil().max(0.0)) as usize;
            let i1 = (((hi_x - x0) / dx - 0.5).floor()).min(r as f64 - 1.0);
            let j0 = (((lo_y - y0) / dy - 0.5).ceil().max(0.0)) as usize;
            let j1 = (((hi_y - y0) / dy - 0.5).floor()).min(r as f64 - 1.0);
            if i1 < 0.0 || j1 < 0.0 {
                continue;
            }
            let det = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
            if det == 0.0 {
                continue;
            }
            for j in j0..=(j1 as usize) {
                let py = y0 + (j as f64 + 0.5) * dy;
                for i in i0..=(i1 as usize) {
                    let px = x0 + (i as f64 + 0.5) * dx;
                    let u = ((b.x - px) * (c.y - py) - (c.x - px) * (b.y - py)) / det;
                    let v = ((c.x - px) * (a.y - py) - (a.x - px) * (c.y - py)) / det;
                    let w = 1.0 - u - v;
                    if u >= 0.0 && v >= 0.0 && w >= 0.0 {
                        covered[j * r + i] = true;
                    }
                }
            }
        }
        covered.iter().filter(|&&c| c).count() as f64 * dx * dy
    }

    // ------------------------------------------------------------------ state

    /// The full dynamic state as a flat vector: time, step count, positions, velocities, frames
    /// (previous and target poses) and attachments (particles, offsets, limits). Multipliers are
    /// not kept between substeps, so they are not part of it. Bit-exact with
    /// [`Cloth::set_state`].
    pub fn get_state(&self) -> Vec<f64> {
        let n = self.pos.len();
        let mut s = Vec::with_capacity(6 * n + 16);
        s.push(STATE_MAGIC);
        s.push(n as f64);
        s.push(self.time);
        s.push(self.steps as f64);
        for v in self.pos.iter().chain(&self.vel) {
            s.extend_from_slice(&[v.x, v.y, v.z]);
        }
        s.push(self.frames.len() as f64);
        for f in &self.frames {
            s.push(f.body as f64);
            for p in [&f.prev, &f.target] {
                let t = p.translation.vector;
                let q = p.rotation.coords;
                s.extend_from_slice(&[t.x, t.y, t.z, q.x, q.y, q.z, q.w]);
            }
        }
        s.push(self.next_attachment as f64);
        s.push(self.attachments.len() as f64);
        for a in &self.attachments {
            s.push(a.id as f64);
            s.push(a.frame.map(|f| f as f64).unwrap_or(-1.0));
            s.push(if a.kinematic { 1.0 } else { 0.0 });
            s.push(a.max_force);
            s.push(if a.slipped { 1.0 } else { 0.0 });
            s.extend_from_slice(&[a.impulse.x, a.impulse.y, a.impulse.z]);
            s.push(a.particles.len() as f64);
            for (p, l) in a.particles.iter().zip(&a.local) {
                s.extend_from_slice(&[*p as f64, l.x, l.y, l.z]);
            }
        }
        s
    }

    /// Restores a state produced by [`Cloth::get_state`] of a cloth with the same mesh. The vector
    /// is validated completely before anything is changed.
    pub fn set_state(&mut self, state: &[f64]) -> Result<(), PbdError> {
        let mut r = Reader { s: state, k: 0 };
        let bad = |m: &str| PbdError::BadState(m.to_string());
        if r.next()? != STATE_MAGIC {
            return Err(bad("not a modesuite-pbd cloth state (wrong magic number)"));
        }
        let n = self.pos.len();
        if r.next()? != n as f64 {
            return Err(bad("particle count differs from this cloth"));
        }
        let time = r.next()?;
        let steps = r.next()?;
        let mut pos = Vec::with_capacity(n);
        let mut vel = Vec::with_capacity(n);
        for k in 0..2 * n {
            let v = r.vec3()?;
            if !finite3(&v) {
                return Err(bad("non-finite position or velocity"));
            }
            if k < n {
                pos.push(v)
            } else {
                vel.push(v)
            }
        }
        let nf = r.count()?;
        let mut frames = Vec::with_capacity(nf);
        for _ in 0..nf {
            let body = r.next()?;
            let prev = r.iso()?;
            let target = r.iso()?;
            frames.push(Frame {
                body: body as u32,
                prev,
                target,
            });
        }
        if self.drives.iter().any(|d| d.frame as usize >= nf) {
            return Err(bad("a driven frame of this cloth is missing"));
        }
        let next_attachment = r.count()? as u32;
        let na = r.count()?;
        let mut atts = Vec::with_capacity(na);
        for _ in 0..na {
            let id = r.count()? as u32;
            let frame = r.next()?;
            let frame = if frame < 0.0 {
                None
            } else {
                Some(frame as u32)
            };
            if let Some(f) = frame {
                if f as usize >= nf {
                    return Err(bad("attachment refers to a missing frame"));
                }
            }
            let kinematic = r.next()? != 0.0;
            let max_force = r.next()?;
            let slipped = r.next()? != 0.0;
            let impulse = r.vec3()?;
            let k = r.count()?;
            let mut particles = Vec::with_capacity(k);
            let mut local = Vec::with_capacity(k);
            for _ in 0..k {
                let p = r.count()?;
                if p >= n {
                    return Err(bad("attachment refers to a missing particle"));
                }
                particles.push(p as u32);
                local.push(r.vec3()?);
            }
            atts.push(Attachment {
                id,
                frame,
                kinematic,
                max_force,
                particles,
                local,
                slipped,
                impulse,
                lambda: vec![Vector3::zeros(); k],
                cand: vec![Vector3::zeros(); k],
            });
        }
        if r.k != state.len() {
            return Err(bad("trailing values"));
        }
        self.time = time;
        self.steps = steps as u64;
        self.pos = pos;
        self.vel = vel;
        self.frames = frames;
        self.next_attachment = next_attachment;
        self.attachments = atts;
        self.refresh_inv_mass();
        self.rebuild_tethers();
        Ok(())
    }
}

struct Reader<'a> {
    s: &'a [f64],
    k: usize,
}

impl Reader<'_> {
    fn next(&mut self) -> Result<f64, PbdError> {
        let v = self
            .s
            .get(self.k)
            .copied()
            .ok_or_else(|| PbdError::BadState("too short".into()))?;
        self.k += 1;
        Ok(v)
    }
    fn count(&mut self) -> Result<usize, PbdError> {
        let v = self.next()?;
        if v.is_finite() && v >= 0.0 && v.fract() == 0.0 && v < 4.0e9 {
            Ok(v as usize)
        } else {
            Err(PbdError::BadState(format!("expected a count, found {v}")))
        }
    }
    fn vec3(&mut self) -> Result<Vector3<f64>, PbdError> {
        Ok(Vector3::new(self.next()?, self.next()?, self.next()?))
    }
    fn iso(&mut self) -> Result<Isometry3<f64>, PbdError> {
        let t = self.vec3()?;
        let (i, j, k, w) = (self.next()?, self.next()?, self.next()?, self.next()?);
        let q = Quaternion::from(nalgebra::Vector4::new(i, j, k, w));
        let p = Isometry3::from_parts(Translation3::from(t), UnitQuaternion::new_unchecked(q));
        if !iso_finite(&p) {
            return Err(PbdError::BadState("non-finite frame pose".into()));
        }
        Ok(p)
    }
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

/// One Gauss-Seidel sweep over distance constraints (XPBD, Macklin et al. 2016, eq. 18):
/// `dlambda = (-C - alpha~ lambda) / (w_a + w_b + alpha~)`, `dx_a = w_a dlambda n`.
#[inline(never)]
fn solve_distances(pos: &mut [P4], rows: &[DistRow], lambda: &mut [f64]) {
    for (r, lam) in rows.iter().zip(lambda.iter_mut()) {
        let (a, b) = (r.a as usize, r.b as usize);
        let d = pos[a] - pos[b];
        let l = d.norm();
        if l < 1e-12 {
            continue;
        }
        let num = r.rest - l - r.at * *lam;
        *lam += num * r.inv_denom;
        let s = num / l;
        pos[a] += d * (s * r.ka);
        pos[b] -= d * (s * r.kb);
    }
}

/// End index of each run of equal colours in a colour-sorted list.
fn colour_ends(colours: &[u32]) -> Vec<usize> {
    let mut ends = Vec::new();
    for k in 1..=colours.len() {
        if k == colours.len() || colours[k] != colours[k - 1] {
            ends.push(k);
        }
    }
    ends
}

/// One sweep over isometric bending hinges. The constraint `C = sum_i K_i x_i` is linear, so its
/// XPBD update is exact in one projection: `dlambda = (-C - alpha~ lambda) / (sum_i w_i K_i^2 +
/// alpha~)` (a 3-vector), `dx_i = w_i K_i dlambda`.
#[inline(never)]
fn solve_bending(pos: &mut [P4], rows: &[BendRow], lambda: &mut [P4]) {
    for (r, lam) in rows.iter().zip(lambda.iter_mut()) {
        let [i0, i1, i2, i3] = r.ids.map(|i| i as usize);
        let k = r.k;
        let c = pos[i0] * k[0] + pos[i1] * k[1] + pos[i2] * k[2] + pos[i3] * k[3];
        let num = -c - *lam * r.at;
        *lam += num * r.inv_denom;
        pos[i0] += num * r.wk[0];
        pos[i1] += num * r.wk[1];
        pos[i2] += num * r.wk[2];
        pos[i3] += num * r.wk[3];
    }
}
