//! The elastic solid: state, constraints, grasps, contact and the implicit time step.
//!
//! # Time integration
//!
//! Backward (implicit) Euler in its variational form (Kharevych et al. 2006; Gast et al. 2015,
//! "Optimization integrator for large time steps"): each step minimises the incremental potential
//!
//! ```text
//! Pi(x) = sum_i m_i / (2 dt^2) |x_i - x^_i|^2 + Psi(x) + D(x) + E_grasp(x) - f_ext . x,
//! x^    = x_n + dt v_n + dt^2 g,      v_{n+1} = (x_{n+1} - x_n) / dt
//! ```
//!
//! The minimisation is Newton-type with a backtracking (Armijo) line search on `Pi`:
//!
//! - default (`FemConfig::quasi_newton`): chord iterations whose matrix is a profile-Cholesky
//!   factor of `M/dt^2 + K` at a reference shape (the rest shape at first), reused across steps
//!   and refactored at the current shape when the contraction rate drops; one triangular solve
//!   per iteration, no tangent assembly. For the small-strain, moderate-rotation motion of the
//!   task scenes this converges in 1-2 iterations per step;
//! - fallback (or `quasi_newton = false`): exact Newton with the analytic tangent, solved by PCG
//!   preconditioned with the same factor (truncated at negative curvature), and per-quadrature-
//!   point PSD projection of `dP/dF` only if a direction fails to decrease `Pi`.
//!
//! Why this scheme: explicit and semi-implicit schemes are bound by the stiffest element
//! (`dt < h / c`, about 1e-5 s for a coarse rod at E = 1e9); backward Euler is unconditionally
//! stable for any E and nu < 0.5 (tested at dt = 1/60 for E = 1e4..1e9, nu up to 0.49), the line
//! search on `Pi` makes each step robust to large deformation and inversion, and its numerical
//! damping is what a task simulator wants. Its cost: energy is not conserved (it decays, never
//! grows in the tests); frequencies are kept (first bending mode within 0.7 %).
//!
//! Rayleigh damping `C = a M + b K` enters as dissipation potentials so that `Pi` stays a
//! potential and the line search stays valid: `a/(2 dt) |x - x_n|_M^2` for the mass part, and for
//! the stiffness part `b/(2 dt) sum_q w_q dE : C_L : dE` with `dE` the Green-strain increment of
//! the step and `C_L` the small-strain elasticity tensor. The latter equals `b K` for small
//! strain but is exactly invariant to rigid rotation; a literal `b K(x_n)` damps the second-order
//! chord of every rotation (measured: 55 % of a free spin's energy in 30 steps at b = 2e-3 s).
//!
//! # Constraints
//!
//! Dirichlet-type constraints (nodes fixed to the world, rollers, nodes attached to kinematic rigid
//! frames, active contacts in their normal direction) are imposed exactly by filtering the Newton
//! system (Baraff & Witkin 1998): constrained components are set to their targets before the solve
//! and projected out of every search direction. Constraint forces are read off the gradient.
//! Grasps are springs to a rigid frame whose total force saturates at a limit (a Huber potential on
//! the mean offset), past which the anchors slide: a convex, force-limited, slipping attachment.
//! Contact is an active-set method: candidates are the closest collider points from the
//! [`ContactQuery`] within the distance a node and a collider can travel in the step (so nothing
//! tunnels), penetrating candidates become constraints, adhesive ones are released and the step
//! re-solved. Coulomb friction is part of the same active set: a contact starts sticking (full
//! constraint moving with the collider surface) unless it was already sliding; when the sticking
//! force leaves the friction cone it slides, constrained along the normal only, with the kinetic
//! friction force `mu * normal force` as a load opposing the sliding; a slide that reverses
//! sticks again. Reactions on rigid bodies are the constraint forces times `dt`.

// Numeric kernels below index several parallel node arrays with one loop variable.
#![allow(clippy::needless_range_loop)]

use crate::coupling::{ContactQuery, PointContact, Reaction};
use crate::element::{shape_values, NQ};
use crate::error::FemError;
use crate::material::Material;
use crate::model::{KernelStats, SolidModel};
use crate::precond::{ContactFactor, Penalty, Solved};
use crate::sparse::{dot, pcg, ProfileCholesky};
use crate::warp::Warp;
use nalgebra::{Isometry3, Matrix3, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};
use std::sync::Arc;

/// Solver settings. Defaults suit the task scenes (dt = 1/60 s, or substeps of it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FemConfig {
    /// Newton matrix: `false` assembles the exact tangent each iteration and solves with PCG;
    /// `true` (chord / quasi-Newton) uses the cached Cholesky factor of the system matrix at a
    /// reference shape directly, refactoring at the current shape when convergence slows. The
    /// chord variant needs no tangent assembly per iteration, which makes it several times faster
    /// for the small-strain, moderate-rotation motion of task scenes.
    pub quasi_newton: bool,
    /// Maximum Newton iterations per solve.
    pub newton_max_iterations: usize,
    /// Newton stops when the largest node displacement update is below this fraction of the rest
    /// bounding-box diagonal.
    pub newton_tolerance: f64,
    /// PCG stops at this residual norm relative to the right-hand side.
    pub linear_tolerance: f64,
    /// Maximum PCG iterations per Newton iteration.
    pub linear_max_iterations: usize,
    /// PCG iterations above which the preconditioner is refactored at the current shape.
    pub refactor_iterations: usize,
    /// Rayleigh mass-proportional damping coefficient `a` (1/s).
    pub rayleigh_mass: f64,
    /// Rayleigh stiffness-proportional damping coefficient `b` (s), applied to the strain rate
    /// (rotation invariant, equal to `b K` at small strain).
    pub rayleigh_stiffness: f64,
    /// Extra contact query distance (m) beyond the node's motion in the step.
    pub contact_margin: f64,
    /// Bound on collider surface speeds (m/s) used to size the contact query distance.
    pub collider_speed_bound: f64,
    /// Node speed (m/s) above which a step is reported as exploded and rolled back (and, inside
    /// [`FemSolid::step`], retried as two half steps). The default, 100 m/s, is two orders of
    /// magnitude above the task scenes' motion: a belt springing back onto the Franka after its
    /// release once "converged" to nodes at 600 m/s with inverted elements, whose reactions then
    /// blew up the robot (1,000 m/s let it through; at 100 m/s the step is halved and succeeds).
    pub max_speed: f64,
    /// Chord matrix warped by per-node rotations from its reference shape to the current shape
    /// (`R A R^T`, see [`crate::warp`]): a bending or swinging belt keeps the chord's contraction
    /// without refactoring as often. The solution is the same to the Newton tolerance; only the
    /// iteration and refactor counts change (`false`: the plain factored matrix).
    pub warped_chord: bool,
}

impl Default for FemConfig {
    fn default() -> Self {
        FemConfig {
            quasi_newton: true,
            newton_max_iterations: 20,
            newton_tolerance: 1e-5,
            linear_tolerance: 1e-6,
            linear_max_iterations: 300,
            refactor_iterations: 40,
            rayleigh_mass: 0.0,
            rayleigh_stiffness: 0.0,
            contact_margin: 1e-3,
            collider_speed_bound: 2.0,
            max_speed: 100.0,
            warped_chord: true,
        }
    }
}

impl FemConfig {
    /// Checks every field is finite and in range.
    pub fn validate(&self) -> Result<(), FemError> {
        let checks: [(&'static str, f64, bool, &'static str); 7] = [
            (
                "config.newton_tolerance",
                self.newton_tolerance,
                self.newton_tolerance > 0.0,
                "> 0",
            ),
            (
                "config.linear_tolerance",
                self.linear_tolerance,
                self.linear_tolerance > 0.0,
                "> 0",
            ),
            (
                "config.rayleigh_mass",
                self.rayleigh_mass,
                self.rayleigh_mass >= 0.0,
                ">= 0 (1/s)",
            ),
            (
                "config.rayleigh_stiffness",
                self.rayleigh_stiffness,
                self.rayleigh_stiffness >= 0.0,
                ">= 0 (s)",
            ),
            (
                "config.contact_margin",
                self.contact_margin,
                self.contact_margin >= 0.0,
                ">= 0 (m)",
            ),
            (
                "config.collider_speed_bound",
                self.collider_speed_bound,
                self.collider_speed_bound >= 0.0,
                ">= 0 (m/s)",
            ),
            (
                "config.max_speed",
                self.max_speed,
                self.max_speed > 0.0,
                "> 0 (m/s)",
            ),
        ];
        for (name, value, ok, expected) in checks {
            if !(ok && value.is_finite()) {
                return Err(FemError::InvalidParameter {
                    name,
                    value,
                    expected,
                });
            }
        }
        if self.newton_max_iterations == 0 || self.linear_max_iterations == 0 {
            return Err(FemError::InvalidParameter {
                name: "config.newton_max_iterations / linear_max_iterations",
                value: 0.0,
                expected: ">= 1",
            });
        }
        Ok(())
    }
}

/// Parameters of a grasp attachment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GraspParams {
    /// Spring stiffness per grasped node (N/m).
    pub stiffness: f64,
    /// Total force (N) the grasp transmits before it slips.
    pub force_limit: f64,
}

impl GraspParams {
    /// A robot gripper's grasp of `nodes` nodes with force limit `force_limit` (N): stiff enough
    /// that the grasp, not the spring, limits what the gripper transmits (the whole grasp holds
    /// its force limit at 2 mm of stretch), at least 1e3 N/m per node.
    pub fn for_gripper(force_limit: f64, nodes: usize) -> Self {
        let stiffness = (force_limit.min(1e4) / (0.002 * nodes.max(1) as f64)).max(1e3);
        Self {
            stiffness,
            force_limit,
        }
    }
}

/// What happened in a step or static solve. With `FemConfig::quasi_newton` a chord iteration
/// counts as one Newton iteration and one linear iteration (one triangular solve pair).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepStats {
    /// Active-set rounds (Newton solves with one contact set) of the step.
    pub active_set_rounds: usize,
    /// Newton iterations summed over the active-set rounds.
    pub newton_iterations: usize,
    /// PCG iterations summed over all Newton iterations.
    pub linear_iterations: usize,
    /// Whether the last Newton solve met its tolerance.
    pub converged: bool,
    /// Active contact constraints at the end of the step.
    pub contacts: usize,
    /// Grasps that slipped during the step.
    pub slipping_grasps: usize,
    /// Quadrature points with `det F <= 0` at the end of the step.
    pub inverted: usize,
    /// Times the preconditioner was (re)factored during the step.
    pub factorizations: usize,
    /// Times the step (or a part of it) was split into two halves because its solve failed.
    pub halvings: usize,
}

/// Where a rest-frame point sits in the mesh: element and shape-function weights, so its current
/// position is `sum_a weights[a] x[element node a]` (exact for the quadratic interpolation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointEmbedding {
    /// Element index.
    pub element: u32,
    /// Values of the 10 shape functions at the point.
    pub weights: [f64; 10],
}

/// Report on a grasp after the last step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GraspInfo {
    /// Rigid body holding the grasp.
    pub body: u32,
    /// Total force the grasp applied on the solid during the last step (world frame, N).
    pub force: Vector3<f64>,
    /// Whether it slipped during the last step.
    pub slipping: bool,
    /// Total slip distance since creation (m).
    pub slip_distance: f64,
}

#[derive(Clone, Debug, PartialEq)]
struct WorldConstraint {
    node: u32,
    /// Projector on the constrained subspace (world frame).
    proj: Matrix3<f64>,
    /// Target position (m); only its constrained components matter.
    target: Vector3<f64>,
}

#[derive(Clone, Debug, PartialEq)]
struct Attachment {
    id: u32,
    body: u32,
    nodes: Vec<u32>,
    /// Node positions in the body frame (m).
    local: Vec<Vector3<f64>>,
}

#[derive(Clone, Debug, PartialEq)]
struct Grasp {
    id: u32,
    body: u32,
    params: GraspParams,
    nodes: Vec<u32>,
    /// Anchor positions in the body frame (m).
    local: Vec<Vector3<f64>>,
    /// World anchors for the current step (m).
    anchor: Vec<Vector3<f64>>,
    force: Vector3<f64>,
    slipping: bool,
    slip_distance: f64,
}

#[derive(Clone, Copy, Debug)]
enum ConKind {
    World,
    Attachment(u32),
    Contact,
}

#[derive(Clone, Copy, Debug)]
struct ActiveCon {
    node: u32,
    /// Projector on the constrained subspace.
    proj: Matrix3<f64>,
    target: Vector3<f64>,
    /// Contact normal (zero for other kinds).
    normal: Vector3<f64>,
    kind: ConKind,
}

#[derive(Clone, Copy, Debug)]
struct Candidate {
    node: u32,
    contact: PointContact,
    active: bool,
    /// Sticking (full constraint at `stick_target`) or sliding (normal constraint + friction force).
    stick: bool,
    stick_target: Vector3<f64>,
    normal_force: f64,
    /// Kinetic friction force on the node while sliding (N).
    friction_force: Vector3<f64>,
    /// Unit direction of the kinetic friction force while sliding.
    slip_dir: Vector3<f64>,
    /// The previous active-set round's (friction magnitude used, `mu * normal force` it gave),
    /// for the secant update of a sliding contact's friction.
    secant: Option<(f64, f64)>,
}

/// What an active contact ended a step with: the next step's contact on the same node and body
/// starts from it (active, sticking or sliding the same way, friction from this normal force).
/// Part of the state, so that a restored snapshot steps exactly as the original.
#[derive(Clone, Copy, Debug, PartialEq)]
struct ContactMemory {
    node: u32,
    body: u32,
    stick: bool,
    slip_dir: Vector3<f64>,
    normal_force: f64,
}

/// Coefficients of one incremental-potential solve.
#[derive(Clone, Copy, Debug)]
struct Problem {
    /// Inertia coefficient `1/dt^2` (0 for statics).
    c_mass: f64,
    /// Mass damping coefficient `a/dt`.
    c_damp: f64,
    /// Stiffness damping coefficient `b/dt`.
    c_kdamp: f64,
    /// Gravity applied as a dead load (statics only; dynamics folds it into `x^`).
    gravity: Vector3<f64>,
}

/// Tangential speed (m/s) above which a contact starts a step sliding rather than sticking
/// (raised, per contact, to the speed its kinetic friction would take away within the step).
const SLIP_SPEED: f64 = 1e-3;

/// Relative change of a sliding contact's kinetic friction force below which the active-set
/// rounds accept it (besides the absolute force tolerance of the Newton solve).
const FRICTION_RTOL: f64 = 2e-2;

/// A node touches a collider only where its outward surface normal `s` faces the collider's
/// outward normal `n`: `s . n < -FACING_COS` (about 3 degrees past perpendicular). Without this,
/// a thin body (a 4 mm belt) pushed by a collider moving more than its thickness in a step had
/// its far-side nodes constrained onto the same surface as the near side: every element crushed
/// flat at the start of the Newton solve.
const FACING_COS: f64 = 0.05;

/// How often a step whose solve fails may be halved (at most `2^MAX_STEP_HALVINGS` parts).
const MAX_STEP_HALVINGS: u32 = 3;

const STATE_MAGIC_V1: f64 = 7.1e7 + 1.0; // format tag of get_state, version 1 (no contact memory)
const STATE_MAGIC: f64 = 7.1e7 + 2.0; // format tag of get_state (version 2)

/// A tetrahedral elastic solid with quadratic elements: model, state, constraints and solver.
///
/// State arrays (structure of arrays, world frame, SI units):
/// - `pos`: node positions, `n_nodes` x 3 (m); corners first (input order), then edge nodes.
/// - `vel`: node velocities, `n_nodes` x 3 (m/s).
/// - `ext_force`: external dead loads per node, `n_nodes` x 3 (N).
pub struct FemSolid {
    /// Immutable compiled model, shared between environment copies.
    model: Arc<SolidModel>,
    config: FemConfig,
    pos: Vec<Vector3<f64>>,
    vel: Vec<Vector3<f64>>,
    ext_force: Vec<Vector3<f64>>,
    /// Kinetic friction forces of sliding contacts during the current step (N); zero outside steps.
    fric: Vec<Vector3<f64>>,
    steps: u64,
    world: Vec<WorldConstraint>,
    attachments: Vec<Attachment>,
    grasps: Vec<Grasp>,
    poses: Vec<(u32, Isometry3<f64>)>,
    next_id: u32,
    /// Shape at which the preconditioner is factored (`None`: rest).
    precond_at: Option<Vec<Vector3<f64>>>,
    // caches (not state)
    precond: Option<([u64; 4], ContactFactor)>,
    /// Flops of a factorisation and of a solve in this model's profile.
    profile_costs: (f64, f64),
    /// Block values of the factored matrix without the contact penalties (for the chord solver's
    /// constrained PCG, and refactored with new penalties when only the contact set changes).
    precond_mat: Vec<Matrix3<f64>>,
    /// What `precond_mat` was built for: mass and stiffness coefficients, constraint version and
    /// `precond_gen`.
    precond_mat_key: Option<[u64; 4]>,
    /// Bumped whenever `precond_at` is assigned.
    precond_gen: u64,
    constraint_version: u64,
    /// Young's modulus of this solid over the model's (per-env material randomisation): the
    /// Stable Neo-Hookean energy is linear in E at a fixed Poisson ratio, so the elastic (and
    /// stiffness-damping) energy, gradient and Hessian are scaled by it. Part of the state.
    stiffness_scale: f64,
    hess: Vec<Matrix3<f64>>,
    grad: Vec<Vector3<f64>>,
    egrad: Vec<Vector3<f64>>,
    delta: Vec<Vector3<f64>>,
    trial: Vec<Vector3<f64>>,
    xhat: Vec<Vector3<f64>>,
    xprev: Vec<Vector3<f64>>,
    vprev: Vec<Vector3<f64>>,
    cg: [Vec<Vector3<f64>>; 3],
    active: Vec<ActiveCon>,
    candidates: Vec<Candidate>,
    /// Outward surface normals at the nodes at the start of the step.
    normals: Vec<Vector3<f64>>,
    con_forces: Vec<(u32, Vector3<f64>)>,
    /// Active contacts at the end of the last step, by node (part of the state).
    contact_memory: Vec<ContactMemory>,
    /// Elastic and full gradient at a line search's first trial point (swapped into `egrad` and
    /// `grad` when the trial is taken).
    trial_egrad: Vec<Vector3<f64>>,
    trial_grad: Vec<Vector3<f64>>,
    /// Set by the chord solver when it returns with `grad` already evaluated at `pos` (the
    /// inverted count of that evaluation); taken by the caller instead of a new evaluation.
    grad_at_pos: Option<usize>,
    last_linear_iterations: usize,
    /// Rotations of the warped chord matrix (a cache of the state, see [`crate::warp`]).
    warp: Warp,
}

/// The largest absolute component of a block vector.
fn max_component(v: &[Vector3<f64>]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.amax()))
}

fn finite3(v: &Vector3<f64>) -> bool {
    v.x.is_finite() && v.y.is_finite() && v.z.is_finite()
}

fn finite_pose(p: &Isometry3<f64>) -> bool {
    finite3(&p.translation.vector) && p.rotation.coords.iter().all(|c| c.is_finite())
}

impl FemSolid {
    /// Builds a solid from a positively oriented linear tet mesh (`nodes` in m, world frame); the
    /// 10-node elements are created here. Starts at rest with zero velocity and no constraints.
    pub fn new(
        nodes: &[Vector3<f64>],
        tets: &[[u32; 4]],
        material: Material,
        config: FemConfig,
    ) -> Result<Self, FemError> {
        config.validate()?;
        let model = SolidModel::new(nodes, tets, material)?;
        Ok(Self::from_model(Arc::new(model), config))
    }

    /// Builds a solid from an already compiled model, shared (e.g. by all environments of a
    /// vectorised env); the solid starts at the rest shape.
    pub fn from_model(model: Arc<SolidModel>, config: FemConfig) -> Self {
        let n = model.n_nodes();
        let nb = model.pattern.cols.len();
        let z = vec![Vector3::zeros(); n];
        FemSolid {
            pos: model.mesh.rest.clone(),
            vel: z.clone(),
            ext_force: z.clone(),
            fric: z.clone(),
            steps: 0,
            world: Vec::new(),
            attachments: Vec::new(),
            grasps: Vec::new(),
            poses: Vec::new(),
            next_id: 1,
            precond_at: None,
            precond: None,
            profile_costs: model.profile.costs(),
            precond_mat: Vec::new(),
            precond_mat_key: None,
            precond_gen: 0,
            constraint_version: 0,
            stiffness_scale: 1.0,
            hess: vec![Matrix3::zeros(); nb],
            grad: z.clone(),
            egrad: z.clone(),
            delta: z.clone(),
            trial: z.clone(),
            xhat: z.clone(),
            xprev: z.clone(),
            vprev: z,
            cg: [Vec::new(), Vec::new(), Vec::new()],
            active: Vec::new(),
            candidates: Vec::new(),
            normals: Vec::new(),
            con_forces: Vec::new(),
            contact_memory: Vec::new(),
            trial_egrad: vec![Vector3::zeros(); n],
            trial_grad: vec![Vector3::zeros(); n],
            grad_at_pos: None,
            last_linear_iterations: 0,
            warp: Warp::default(),
            model,
            config,
        }
    }

    // ----------------------------------------------------------------- accessors

    /// The compiled model (mesh, masses, quadrature data).
    pub fn model(&self) -> &SolidModel {
        &self.model
    }

    /// The shared handle of the compiled model (to build more solids from it).
    pub fn shared_model(&self) -> Arc<SolidModel> {
        Arc::clone(&self.model)
    }

    /// Solver settings.
    pub fn config(&self) -> &FemConfig {
        &self.config
    }

    /// Replaces the solver settings.
    pub fn set_config(&mut self, config: FemConfig) -> Result<(), FemError> {
        config.validate()?;
        self.config = config;
        Ok(())
    }

    /// Number of nodes (corners first, then edge nodes).
    pub fn n_nodes(&self) -> usize {
        self.pos.len()
    }

    /// Current node positions (world frame, m).
    pub fn positions(&self) -> &[Vector3<f64>] {
        &self.pos
    }

    /// Current node velocities (world frame, m/s).
    pub fn velocities(&self) -> &[Vector3<f64>] {
        &self.vel
    }

    /// Rest node positions (m).
    pub fn rest_positions(&self) -> &[Vector3<f64>] {
        &self.model.mesh.rest
    }

    /// Lumped node masses (kg).
    pub fn masses(&self) -> &[f64] {
        &self.model.mass
    }

    /// Number of completed steps.
    pub fn step_count(&self) -> u64 {
        self.steps
    }

    /// Sets all node positions (m) and velocities (m/s), e.g. for initial conditions.
    pub fn set_positions_velocities(
        &mut self,
        pos: &[Vector3<f64>],
        vel: &[Vector3<f64>],
    ) -> Result<(), FemError> {
        if pos.len() != self.n_nodes() || vel.len() != self.n_nodes() {
            return Err(FemError::InvalidState(format!(
                "expected {} positions and velocities",
                self.n_nodes()
            )));
        }
        if !pos.iter().chain(vel).all(finite3) {
            return Err(FemError::NonFiniteInput("positions or velocities"));
        }
        self.pos.copy_from_slice(pos);
        self.vel.copy_from_slice(vel);
        self.contact_memory.clear();
        Ok(())
    }

    /// Sets the external dead load on every node (N, world frame), kept until changed.
    pub fn set_external_forces(&mut self, forces: &[Vector3<f64>]) -> Result<(), FemError> {
        if forces.len() != self.n_nodes() {
            return Err(FemError::InvalidState(format!(
                "expected {} forces",
                self.n_nodes()
            )));
        }
        if !forces.iter().all(finite3) {
            return Err(FemError::NonFiniteInput("external forces"));
        }
        self.ext_force.copy_from_slice(forces);
        Ok(())
    }

    /// Indices of nodes whose current position satisfies `pred` (e.g. inside a finger volume).
    pub fn nodes_where(&self, pred: impl Fn(&Vector3<f64>) -> bool) -> Vec<u32> {
        (0..self.n_nodes() as u32)
            .filter(|&i| pred(&self.pos[i as usize]))
            .collect()
    }

    /// Indices of nodes whose rest position satisfies `pred` (e.g. the clamped end face).
    pub fn rest_nodes_where(&self, pred: impl Fn(&Vector3<f64>) -> bool) -> Vec<u32> {
        (0..self.n_nodes() as u32)
            .filter(|&i| pred(&self.model.mesh.rest[i as usize]))
            .collect()
    }

    fn check_nodes(&self, nodes: &[u32]) -> Result<(), FemError> {
        for &n in nodes {
            if n as usize >= self.n_nodes() {
                return Err(FemError::NodeOutOfRange {
                    node: n,
                    count: self.n_nodes(),
                });
            }
        }
        Ok(())
    }

    // ----------------------------------------------------------------- world constraints

    fn world_entry(&mut self, node: u32) -> &mut WorldConstraint {
        let k = match self.world.binary_search_by_key(&node, |w| w.node) {
            Ok(k) => k,
            Err(k) => {
                let target = self.pos[node as usize];
                self.world.insert(
                    k,
                    WorldConstraint {
                        node,
                        proj: Matrix3::zeros(),
                        target,
                    },
                );
                k
            }
        };
        &mut self.world[k]
    }

    /// Fixes nodes to the world at their current positions.
    pub fn fix_nodes(&mut self, nodes: &[u32]) -> Result<(), FemError> {
        self.check_nodes(nodes)?;
        for &n in nodes {
            let p = self.pos[n as usize];
            let w = self.world_entry(n);
            w.proj = Matrix3::identity();
            w.target = p;
        }
        self.constraint_version += 1;
        Ok(())
    }

    /// Constrains the motion of nodes along `direction` (world frame) to their current
    /// coordinate; they stay free in the plane normal to it (a roller). Repeated calls with other
    /// directions add constrained directions.
    pub fn constrain_nodes_along(
        &mut self,
        nodes: &[u32],
        direction: Vector3<f64>,
    ) -> Result<(), FemError> {
        self.check_nodes(nodes)?;
        let d = direction
            .try_normalize(1e-12)
            .ok_or(FemError::NonFiniteInput("roller direction"))?;
        for &n in nodes {
            let p = self.pos[n as usize];
            let w = self.world_entry(n);
            // component of d outside the already constrained subspace
            let r = d - w.proj * d;
            if let Some(r) = r.try_normalize(1e-9) {
                w.proj += r * r.transpose();
            }
            // keep the constrained components of the current position as target
            w.target = p;
        }
        self.constraint_version += 1;
        Ok(())
    }

    /// Moves the target of a world-constrained node (m); only its constrained components apply.
    pub fn set_constraint_target(
        &mut self,
        node: u32,
        target: Vector3<f64>,
    ) -> Result<(), FemError> {
        if !finite3(&target) {
            return Err(FemError::NonFiniteInput("constraint target"));
        }
        match self.world.binary_search_by_key(&node, |w| w.node) {
            Ok(k) => {
                self.world[k].target = target;
                Ok(())
            }
            Err(_) => Err(FemError::NodeOutOfRange {
                node,
                count: self.n_nodes(),
            }),
        }
    }

    /// Removes the world constraints of the given nodes.
    pub fn release_nodes(&mut self, nodes: &[u32]) {
        self.world.retain(|w| !nodes.contains(&w.node));
        self.constraint_version += 1;
    }

    /// Force each constrained node received from its constraint during the last solve (N, world
    /// frame), for world constraints, attachments and contacts (normal part), in node order of
    /// the active constraint list.
    pub fn constraint_forces(&self) -> &[(u32, Vector3<f64>)] {
        &self.con_forces
    }

    // ----------------------------------------------------------------- rigid frames

    /// Sets the pose of rigid body `body` used by attachments and grasps from the next step.
    pub fn set_body_pose(
        &mut self,
        body: u32,
        world_from_body: Isometry3<f64>,
    ) -> Result<(), FemError> {
        if !finite_pose(&world_from_body) {
            return Err(FemError::NonFiniteInput("body pose"));
        }
        match self.poses.binary_search_by_key(&body, |p| p.0) {
            Ok(k) => self.poses[k].1 = world_from_body,
            Err(k) => self.poses.insert(k, (body, world_from_body)),
        }
        Ok(())
    }

    fn pose(&self, body: u32) -> Isometry3<f64> {
        match self.poses.binary_search_by_key(&body, |p| p.0) {
            Ok(k) => self.poses[k].1,
            Err(_) => Isometry3::identity(),
        }
    }

    /// Attaches nodes kinematically to rigid body `body` (currently at `world_from_body`): they
    /// follow the body frame exactly; the reaction impulses are reported by [`FemSolid::step`].
    /// Returns the attachment id.
    pub fn attach_to_body(
        &mut self,
        body: u32,
        world_from_body: Isometry3<f64>,
        nodes: &[u32],
    ) -> Result<u32, FemError> {
        self.check_nodes(nodes)?;
        self.set_body_pose(body, world_from_body)?;
        let inv = world_from_body.inverse();
        let local = nodes
            .iter()
            .map(|&n| inv * Point3::from(self.pos[n as usize]))
            .map(|p| p.coords)
            .collect();
        let id = self.next_id;
        self.next_id += 1;
        self.attachments.push(Attachment {
            id,
            body,
            nodes: nodes.to_vec(),
            local,
        });
        self.constraint_version += 1;
        Ok(id)
    }

    /// Removes a kinematic attachment.
    pub fn detach(&mut self, id: u32) -> Result<(), FemError> {
        let k = self
            .attachments
            .iter()
            .position(|a| a.id == id)
            .ok_or(FemError::UnknownAttachment(id))?;
        self.attachments.remove(k);
        self.constraint_version += 1;
        Ok(())
    }

    /// Grasps nodes with rigid body `body` (currently at `world_from_body`): each node is held by
    /// a spring of `params.stiffness` to its current position in the body frame; the total force
    /// saturates at `params.force_limit`, past which the grasp slips. Returns the grasp id.
    pub fn grasp(
        &mut self,
        body: u32,
        world_from_body: Isometry3<f64>,
        nodes: &[u32],
        params: GraspParams,
    ) -> Result<u32, FemError> {
        self.check_nodes(nodes)?;
        if nodes.is_empty() {
            return Err(FemError::InvalidMesh(
                "a grasp needs at least one node".into(),
            ));
        }
        if !(params.stiffness.is_finite() && params.stiffness > 0.0) {
            return Err(FemError::InvalidParameter {
                name: "grasp.stiffness",
                value: params.stiffness,
                expected: "finite and > 0 (N/m)",
            });
        }
        if params.force_limit.is_nan() || params.force_limit <= 0.0 {
            return Err(FemError::InvalidParameter {
                name: "grasp.force_limit",
                value: params.force_limit,
                expected: "> 0 (N), may be infinite",
            });
        }
        self.set_body_pose(body, world_from_body)?;
        let inv = world_from_body.inverse();
        let local: Vec<Vector3<f64>> = nodes
            .iter()
            .map(|&n| (inv * Point3::from(self.pos[n as usize])).coords)
            .collect();
        let id = self.next_id;
        self.next_id += 1;
        self.grasps.push(Grasp {
            id,
            body,
            params,
            nodes: nodes.to_vec(),
            anchor: nodes.iter().map(|&n| self.pos[n as usize]).collect(),
            local,
            force: Vector3::zeros(),
            slipping: false,
            slip_distance: 0.0,
        });
        self.constraint_version += 1;
        Ok(id)
    }

    /// Releases a grasp.
    pub fn release_grasp(&mut self, id: u32) -> Result<(), FemError> {
        let k = self
            .grasps
            .iter()
            .position(|g| g.id == id)
            .ok_or(FemError::UnknownAttachment(id))?;
        self.grasps.remove(k);
        self.constraint_version += 1;
        Ok(())
    }

    /// Ids of the rigid bodies that attachments or grasps follow (sorted, unique).
    pub fn attached_bodies(&self) -> Vec<u32> {
        let mut b: Vec<u32> = self
            .attachments
            .iter()
            .map(|a| a.body)
            .chain(self.grasps.iter().map(|g| g.body))
            .collect();
        b.sort_unstable();
        b.dedup();
        b
    }

    /// Ids of the grasps held by rigid body `body`, in creation order.
    pub fn grasps_of(&self, body: u32) -> Vec<u32> {
        self.grasps
            .iter()
            .filter(|g| g.body == body)
            .map(|g| g.id)
            .collect()
    }

    /// Appends the nodes held by grasps (grasp order).
    pub fn grasped_nodes(&self, out: &mut Vec<u32>) {
        out.extend(self.grasps.iter().flat_map(|g| g.nodes.iter().copied()));
    }

    /// Appends the nodes whose contact constraint was active at the end of the last step
    /// (ascending).
    pub fn contact_nodes(&self, out: &mut Vec<u32>) {
        out.extend(
            self.active
                .iter()
                .filter(|c| matches!(c.kind, ConKind::Contact))
                .map(|c| c.node),
        );
    }

    /// State of a grasp after the last step.
    pub fn grasp_info(&self, id: u32) -> Result<GraspInfo, FemError> {
        let g = self
            .grasps
            .iter()
            .find(|g| g.id == id)
            .ok_or(FemError::UnknownAttachment(id))?;
        Ok(GraspInfo {
            body: g.body,
            force: g.force,
            slipping: g.slipping,
            slip_distance: g.slip_distance,
        })
    }

    // ----------------------------------------------------------------- derived quantities

    /// Elastic energy (J).
    pub fn elastic_energy(&self) -> f64 {
        self.model.energy_only(&self.pos, None).energy * self.stiffness_scale
    }

    /// This solid's Young's modulus (Pa): the model's times [`FemSolid::set_youngs_modulus`]'s
    /// scale.
    pub fn youngs_modulus(&self) -> f64 {
        self.model.material.youngs_modulus * self.stiffness_scale
    }

    /// Sets this solid's Young's modulus (Pa, finite and > 0; the Poisson ratio and density stay
    /// the model's): a per-env material randomisation. Takes effect from the next step.
    pub fn set_youngs_modulus(&mut self, youngs_modulus: f64) -> Result<(), FemError> {
        if !(youngs_modulus.is_finite() && youngs_modulus > 0.0) {
            return Err(FemError::InvalidParameter {
                name: "youngs_modulus",
                value: youngs_modulus,
                expected: "finite and > 0 Pa",
            });
        }
        self.stiffness_scale = youngs_modulus / self.model.material.youngs_modulus;
        self.precond = None;
        self.constraint_version += 1;
        Ok(())
    }

    /// Kinetic energy (J) with the lumped masses.
    pub fn kinetic_energy(&self) -> f64 {
        0.5 * self
            .vel
            .iter()
            .zip(&self.model.mass)
            .map(|(v, m)| m * v.norm_squared())
            .sum::<f64>()
    }

    /// Gravitational potential energy `-sum m g . x` (J).
    pub fn gravity_energy(&self, gravity: &Vector3<f64>) -> f64 {
        -self
            .pos
            .iter()
            .zip(&self.model.mass)
            .map(|(x, m)| m * gravity.dot(x))
            .sum::<f64>()
    }

    /// Linear momentum (kg m/s).
    pub fn momentum(&self) -> Vector3<f64> {
        self.vel
            .iter()
            .zip(&self.model.mass)
            .map(|(v, m)| v * *m)
            .sum()
    }

    /// Number of quadrature points with `det F <= 0`.
    pub fn inverted_count(&self) -> usize {
        self.model.energy_only(&self.pos, None).inverted
    }

    /// Current volume (m^3) as the sum of signed volumes of the corner tetrahedra.
    pub fn volume(&self) -> f64 {
        self.model
            .mesh
            .elements
            .iter()
            .map(|e| {
                let x = [0, 1, 2, 3].map(|k| self.pos[e[k] as usize]);
                (x[1] - x[0]).cross(&(x[2] - x[0])).dot(&(x[3] - x[0])) / 6.0
            })
            .sum()
    }

    /// Green strain `E = (F^T F - I) / 2` at every quadrature point, `[element * 4 + q]`.
    pub fn green_strains(&self) -> Vec<Matrix3<f64>> {
        let mut out = Vec::with_capacity(self.model.n_elements() * NQ);
        for e in 0..self.model.n_elements() {
            for q in 0..NQ {
                let f = self.model.deformation_gradient(e, q, &self.pos);
                out.push((f.transpose() * f - Matrix3::identity()) * 0.5);
            }
        }
        out
    }

    /// Largest absolute principal Green strain over all quadrature points.
    pub fn max_strain(&self) -> f64 {
        self.green_strains()
            .iter()
            .map(|e| {
                e.symmetric_eigenvalues()
                    .iter()
                    .fold(0.0f64, |m, v| m.max(v.abs()))
            })
            .fold(0.0, f64::max)
    }

    /// Embeds a rest-frame point (m) in the element that contains it (the most interior one when
    /// on a shared face).
    pub fn embed_point(&self, rest_point: &Vector3<f64>) -> Result<PointEmbedding, FemError> {
        let mut best: Option<(f64, usize, [f64; 4])> = None;
        for (e, el) in self.model.mesh.elements.iter().enumerate() {
            let x = [0, 1, 2, 3].map(|k| self.model.mesh.rest[el[k] as usize]);
            let dm = Matrix3::from_columns(&[x[1] - x[0], x[2] - x[0], x[3] - x[0]]);
            let Some(inv) = dm.try_inverse() else {
                continue;
            };
            let b = inv * (rest_point - x[0]);
            let l = [1.0 - b.x - b.y - b.z, b.x, b.y, b.z];
            let worst = l.iter().cloned().fold(f64::INFINITY, f64::min);
            if best.is_none_or(|(w, _, _)| worst > w) {
                best = Some((worst, e, l));
            }
        }
        match best {
            Some((w, e, l)) if w >= -1e-9 => Ok(PointEmbedding {
                element: e as u32,
                weights: shape_values(&l),
            }),
            _ => Err(FemError::PointOutsideMesh {
                point: [rest_point.x, rest_point.y, rest_point.z],
            }),
        }
    }

    /// Embeds `k >= 2` equally spaced rest points from `a` to `b` (e.g. a rod's centre line).
    pub fn embed_line(
        &self,
        a: &Vector3<f64>,
        b: &Vector3<f64>,
        k: usize,
    ) -> Result<Vec<PointEmbedding>, FemError> {
        let k = k.max(2);
        (0..k)
            .map(|i| self.embed_point(&(a + (b - a) * (i as f64 / (k - 1) as f64))))
            .collect()
    }

    /// Current position (m) of an embedded point.
    pub fn embedded_position(&self, p: &PointEmbedding) -> Vector3<f64> {
        let el = &self.model.mesh.elements[p.element as usize];
        (0..10)
            .map(|a| self.pos[el[a] as usize] * p.weights[a])
            .sum()
    }

    /// Current velocity (m/s) of an embedded point.
    pub fn embedded_velocity(&self, p: &PointEmbedding) -> Vector3<f64> {
        let el = &self.model.mesh.elements[p.element as usize];
        (0..10)
            .map(|a| self.vel[el[a] as usize] * p.weights[a])
            .sum()
    }

    // ----------------------------------------------------------------- solver internals

    fn build_active(&mut self) {
        self.active.clear();
        for w in &self.world {
            self.active.push(ActiveCon {
                node: w.node,
                proj: w.proj,
                target: w.target,
                normal: Vector3::zeros(),
                kind: ConKind::World,
            });
        }
        for (ai, a) in self.attachments.iter().enumerate() {
            let pose = match self.poses.binary_search_by_key(&a.body, |p| p.0) {
                Ok(k) => self.poses[k].1,
                Err(_) => Isometry3::identity(),
            };
            for (&n, l) in a.nodes.iter().zip(&a.local) {
                let target = (pose * Point3::from(*l)).coords;
                self.active.push(ActiveCon {
                    node: n,
                    proj: Matrix3::identity(),
                    target,
                    normal: Vector3::zeros(),
                    kind: ConKind::Attachment(ai as u32),
                });
            }
        }
        for c in self.candidates.iter() {
            if c.active {
                let n = c.contact.normal;
                let (proj, target) = if c.stick {
                    (Matrix3::identity(), c.stick_target)
                } else {
                    (n * n.transpose(), c.contact.point)
                };
                self.active.push(ActiveCon {
                    node: c.node,
                    proj,
                    target,
                    normal: n,
                    kind: ConKind::Contact,
                });
            }
        }
        // one constraint per node, by priority: attachment > world > contact (a contact on a
        // node that is already constrained is dropped)
        let rank = |k: &ConKind| match k {
            ConKind::Attachment(..) => 0u8,
            ConKind::World => 1,
            ConKind::Contact => 2,
        };
        self.active.sort_by_key(|c| (c.node, rank(&c.kind)));
        let mut merged: Vec<ActiveCon> = Vec::with_capacity(self.active.len());
        for c in self.active.drain(..) {
            if merged.last().is_some_and(|l| l.node == c.node) {
                continue;
            }
            merged.push(c);
        }
        self.active = merged;
    }

    fn apply_filter(active: &[ActiveCon], v: &mut [Vector3<f64>]) {
        for c in active {
            let x = &mut v[c.node as usize];
            *x -= c.proj * *x;
        }
    }

    fn full_constrained(&self) -> Vec<bool> {
        let mut full = vec![false; self.n_nodes()];
        for w in &self.world {
            if (w.proj - Matrix3::identity()).norm() < 1e-12 {
                full[w.node as usize] = true;
            }
        }
        for a in &self.attachments {
            for &n in &a.nodes {
                full[n as usize] = true;
            }
        }
        full
    }

    /// Factors `c_mass M + c_stiff K(x_ref) + grasp springs` with full constraints eliminated and
    /// partial ones penalised, if the cached factor does not match.
    fn ensure_precond(&mut self, c_mass: f64, c_stiff: f64) -> Result<usize, FemError> {
        let c_stiff = c_stiff * self.stiffness_scale;
        // active contacts enter the factor as stiff penalties along their normals, quantised to
        // 1e-2 so that a resting contact set reuses the factor; the factor is a pure function of
        // the key and the preconditioner shape (deterministic after snapshot restore)
        let contacts: Vec<(u32, Vector3<f64>, bool)> = self
            .active
            .iter()
            .filter(|c| matches!(c.kind, ConKind::Contact))
            .map(|c| {
                (
                    c.node,
                    (c.normal * 100.0).map(|x| x.round() / 100.0),
                    c.proj[(0, 0)] == 1.0 && c.proj[(1, 1)] == 1.0,
                )
            })
            .collect();
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for (node, n, stick) in &contacts {
            for w in [
                *node as u64,
                n.x.to_bits(),
                n.y.to_bits(),
                n.z.to_bits(),
                *stick as u64,
            ] {
                h = (h ^ w).wrapping_mul(0x0100_0000_01b3);
            }
        }
        let key = [
            c_mass.to_bits(),
            c_stiff.to_bits(),
            self.constraint_version,
            h,
        ];
        if let Some((k, _)) = &self.precond {
            if *k == key {
                return Ok(0);
            }
        }
        let mat_key = [
            c_mass.to_bits(),
            c_stiff.to_bits(),
            self.constraint_version,
            self.precond_gen,
        ];
        let previous = self.precond.take();
        if self.precond_mat_key == Some(mat_key) {
            // only the contacts changed: the matrix without them is the one built last time
            let base = previous.and_then(|(_, f)| f.into_base());
            if let Ok((f, k)) = self.contact_factor(base, true, &self.precond_mat, &contacts) {
                self.precond = Some((key, f));
                return Ok(k);
            }
        }
        self.precond_mat_key = None;
        let x_ref = self
            .precond_at
            .clone()
            .unwrap_or_else(|| self.model.mesh.rest.clone());
        // the last matrix's buffer (`eval` overwrites every block) instead of a fresh one
        let mut vals = std::mem::take(&mut self.precond_mat);
        vals.resize(self.model.pattern.cols.len(), Matrix3::zeros());
        let mut g = vec![Vector3::zeros(); self.n_nodes()];
        // at the rest shape unprojected (exact there); at a deformed reference shape projected
        // (ARCHITECTURE.md: an unprojected tangent in compression was nearly singular and gave
        // metre-long steps); projected if the unprojected one is not positive definite
        let mut out = Err(FemError::NotPositiveDefinite(String::new()));
        for project in [self.precond_at.is_some(), true] {
            self.model
                .eval(&x_ref, &mut g, Some(&mut vals), project, None);
            self.system_matrix(&mut vals, c_mass, c_stiff);
            out = self.contact_factor(None, false, &vals, &contacts);
            if out.is_ok() {
                break;
            }
        }
        let (f, k) = out?;
        self.precond = Some((key, f));
        self.precond_mat = vals;
        self.precond_mat_key = Some(mat_key);
        Ok(k)
    }

    /// Factors the system matrix `vals` with the contacts' stiff penalties (`1e6` times the norm
    /// of the node's diagonal block, along the normal; all three directions when sticking),
    /// reusing `base`, a factor of `vals` from an earlier contact set and the columns solved
    /// with it, when given;
    /// `contacts_changed`: `vals` was factored before with other contacts (see
    /// [`ContactFactor::new`]).
    fn contact_factor(
        &self,
        base: Option<(ProfileCholesky, Solved)>,
        contacts_changed: bool,
        vals: &[Matrix3<f64>],
        contacts: &[(u32, Vector3<f64>, bool)],
    ) -> Result<(ContactFactor, usize), FemError> {
        let pat = &self.model.pattern;
        let penalties: Vec<Penalty> = contacts
            .iter()
            .map(|&(node, n, stick)| {
                let scale = vals[pat.diag[node as usize] as usize].norm().max(1e-300);
                let n = n.try_normalize(1e-12).unwrap_or(Vector3::z());
                (node, n, stick, 1e6 * scale)
            })
            .collect();
        ContactFactor::new(
            base,
            contacts_changed,
            vals,
            &pat.diag,
            &penalties,
            self.profile_costs,
            |m, blocks| ProfileCholesky::factor(&self.model.profile, pat, m, blocks),
        )
    }

    /// Turns the scaled elastic Hessian in `vals` into the system matrix without contacts:
    /// stiffness scaled by `c_stiff`, masses by `c_mass`, grasp springs, full constraints
    /// eliminated and partial ones penalised, and a tiny regularisation.
    fn system_matrix(&self, vals: &mut [Matrix3<f64>], c_mass: f64, c_stiff: f64) {
        for v in vals.iter_mut() {
            *v *= c_stiff;
        }
        let pat = &self.model.pattern;
        for i in 0..self.n_nodes() {
            vals[pat.diag[i] as usize] += Matrix3::identity() * (c_mass * self.model.mass[i]);
        }
        for gr in &self.grasps {
            for &n in &gr.nodes {
                vals[pat.diag[n as usize] as usize] += Matrix3::identity() * gr.params.stiffness;
            }
        }
        let full = self.full_constrained();
        for i in 0..self.n_nodes() {
            for k in pat.row_ptr[i] as usize..pat.row_ptr[i + 1] as usize {
                let j = pat.cols[k] as usize;
                if full[i] || full[j] {
                    vals[k] = if i == j {
                        Matrix3::identity()
                    } else {
                        Matrix3::zeros()
                    };
                }
            }
        }
        for w in &self.world {
            if !full[w.node as usize] {
                let d = pat.diag[w.node as usize] as usize;
                let scale = vals[d].norm().max(1e-300);
                vals[d] += w.proj * (1e6 * scale);
            }
        }
        // tiny regularisation keeps statics with roller-only supports factorable
        let mean_diag = (0..self.n_nodes())
            .map(|i| vals[pat.diag[i] as usize].trace())
            .sum::<f64>()
            / (3 * self.n_nodes()) as f64;
        for i in 0..self.n_nodes() {
            vals[pat.diag[i] as usize] += Matrix3::identity() * (1e-10 * mean_diag);
        }
    }

    fn grasp_energy_grad(&self, x: &[Vector3<f64>], grad: Option<&mut [Vector3<f64>]>) -> f64 {
        let mut e = 0.0;
        let mut grad = grad;
        for g in &self.grasps {
            let n = g.nodes.len() as f64;
            let k = g.params.stiffness;
            let kk = n * k;
            let dbar: Vector3<f64> = g
                .nodes
                .iter()
                .zip(&g.anchor)
                .map(|(&i, a)| x[i as usize] - a)
                .sum::<Vector3<f64>>()
                / n;
            for (&i, a) in g.nodes.iter().zip(&g.anchor) {
                let d = x[i as usize] - a - dbar;
                e += 0.5 * k * d.norm_squared();
            }
            let r = dbar.norm();
            let flim = g.params.force_limit;
            let (eh, gh) = if kk * r <= flim {
                (0.5 * kk * r * r, dbar * kk)
            } else {
                (flim * r - 0.5 * flim * flim / kk, dbar * (flim / r))
            };
            e += eh;
            if let Some(gr) = grad.as_deref_mut() {
                for (&i, a) in g.nodes.iter().zip(&g.anchor) {
                    gr[i as usize] += (x[i as usize] - a - dbar) * k + gh / n;
                }
            }
        }
        e
    }

    /// Elastic (and stiffness-damping) gradient and Hessian at the current positions, scaled by
    /// this solid's Young's modulus over the model's; returns the number of inverted quadrature
    /// points.
    fn eval_elastic(
        &self,
        grad: &mut [Vector3<f64>],
        hess: &mut [Matrix3<f64>],
        project: bool,
        damping: Option<(&[Vector3<f64>], f64)>,
    ) -> usize {
        let inverted = self
            .model
            .eval(&self.pos, grad, Some(&mut *hess), project, damping)
            .inverted;
        let k = self.stiffness_scale;
        if k != 1.0 {
            grad.iter_mut().for_each(|g| *g *= k);
            hess.iter_mut().for_each(|b| *b *= k);
        }
        inverted
    }

    /// Total incremental potential at `x`.
    fn potential(&self, p: &Problem, x: &[Vector3<f64>]) -> f64 {
        let damping = (p.c_kdamp > 0.0).then_some((&self.xprev[..], p.c_kdamp));
        self.potential_with(p, x, self.model.energy_only(x, damping).energy)
    }

    /// The incremental potential at `x` given its (unscaled) elastic energy.
    fn potential_with(&self, p: &Problem, x: &[Vector3<f64>], elastic: f64) -> f64 {
        let mut e = elastic * self.stiffness_scale;
        for i in 0..self.n_nodes() {
            let m = self.model.mass[i];
            if p.c_mass > 0.0 {
                e += 0.5 * m * p.c_mass * (x[i] - self.xhat[i]).norm_squared();
            }
            if p.c_damp > 0.0 {
                e += 0.5 * m * p.c_damp * (x[i] - self.xprev[i]).norm_squared();
            }
            e -= (self.ext_force[i] + self.fric[i] + p.gravity * m).dot(&x[i]);
        }
        e + self.grasp_energy_grad(x, None)
    }

    /// Newton solve of the incremental potential from `self.pos` with the active constraints.
    fn newton(
        &mut self,
        p: &Problem,
        max_iter: usize,
        line_search: bool,
        stats: &mut StepStats,
    ) -> Result<(), FemError> {
        let n = self.n_nodes();
        let tol_x = self.config.newton_tolerance * self.model.length_scale;
        stats.converged = false;
        // set only by a chord solve that ends with the gradient at `pos` evaluated
        self.grad_at_pos = None;
        let c_stiff_pre = 1.0 + p.c_kdamp;
        let c_mass_pre = p.c_mass + p.c_damp;
        // constrained components to targets
        self.predict_constrained(p, stats)?;
        if self.config.quasi_newton && line_search {
            // chord iterations first; exact Newton takes over when they stall (strong nonlinearity)
            if self.chord(p, 8, stats)? {
                return Ok(());
            }
        }
        // exact Hessian first; per-quadrature-point PSD projection once it proves indefinite
        let mut project = false;
        for _it in 0..max_iter {
            stats.factorizations += self.ensure_precond(c_mass_pre, c_stiff_pre)?;
            stats.newton_iterations += 1;
            let mut egrad = std::mem::take(&mut self.egrad);
            let mut hess = std::mem::take(&mut self.hess);
            let damping = (p.c_kdamp > 0.0).then_some((&self.xprev[..], p.c_kdamp));
            self.eval_elastic(&mut egrad, &mut hess, project, damping);
            // gradient
            let mut grad = std::mem::take(&mut self.grad);
            self.assemble_gradient(p, &self.pos, &egrad, &mut grad);
            let pat = &self.model.pattern;
            for i in 0..n {
                let m = self.model.mass[i];
                hess[pat.diag[i] as usize] += Matrix3::identity() * (m * (p.c_mass + p.c_damp));
            }
            for g in &self.grasps {
                for &i in &g.nodes {
                    hess[pat.diag[i as usize] as usize] += Matrix3::identity() * g.params.stiffness;
                }
            }
            // grasp low-rank corrections (saturated grasps), per grasp: (H_h - K I) / n^2 on the mean
            let mut lowrank: Vec<(usize, Matrix3<f64>)> = Vec::new();
            for (gi, g) in self.grasps.iter().enumerate() {
                let nn = g.nodes.len() as f64;
                let kk = nn * g.params.stiffness;
                let dbar: Vector3<f64> = g
                    .nodes
                    .iter()
                    .zip(&g.anchor)
                    .map(|(&i, a)| self.pos[i as usize] - a)
                    .sum::<Vector3<f64>>()
                    / nn;
                let r = dbar.norm();
                if kk * r > g.params.force_limit {
                    let u = dbar / r;
                    let hh = (Matrix3::identity() - u * u.transpose()) * (g.params.force_limit / r);
                    lowrank.push((gi, (hh - Matrix3::identity() * kk) / (nn * nn)));
                }
            }
            self.egrad = egrad;
            // solve H d = -g (filtered)
            for gi in grad.iter_mut() {
                *gi = -*gi;
            }
            Self::apply_filter(&self.active, &mut grad);
            let gnorm = max_component(&grad);
            if gnorm == 0.0 {
                self.grad = grad;
                self.hess = hess;
                stats.converged = true;
                break;
            }
            let mut delta = std::mem::take(&mut self.delta);
            let mut cg = std::mem::take(&mut self.cg);
            let (_, pre) = self.precond.as_mut().expect("factored above");
            let active = &self.active;
            let grasps = &self.grasps;
            let res = pcg(
                |v, y| {
                    pat.spmv(&hess, v, y);
                    for (gi, m) in &lowrank {
                        let g = &grasps[*gi];
                        let s: Vector3<f64> = g.nodes.iter().map(|&i| v[i as usize]).sum();
                        let add = m * s;
                        for &i in &g.nodes {
                            y[i as usize] += add;
                        }
                    }
                },
                |z| pre.solve_in_place(z),
                |v| Self::apply_filter(active, v),
                &grad,
                &mut delta,
                self.config.linear_tolerance,
                self.config.linear_max_iterations,
                &mut cg,
            );
            self.cg = cg;
            stats.linear_iterations += res.iterations;
            self.last_linear_iterations = res.iterations;
            if !project && dot(&grad, &delta) <= 0.0 {
                // not a descent direction: redo this iteration with the projected Hessian
                project = true;
                self.grad = grad;
                self.hess = hess;
                self.delta = delta;
                continue;
            }
            let step_max = max_component(&delta);
            if !step_max.is_finite() {
                self.grad = grad;
                self.hess = hess;
                self.delta = delta;
                return Err(FemError::Exploded {
                    step: self.steps,
                    max_speed: f64::INFINITY,
                });
            }
            let mut alpha = 1.0;
            if line_search && step_max > tol_x {
                let mut trial = std::mem::take(&mut self.trial);
                let e0 = self.potential(p, &self.pos);
                // grad holds -g; slope = g . d = -(grad . d)
                let slope = -dot(&grad, &delta);
                let mut accepted = false;
                for _ in 0..30 {
                    for i in 0..n {
                        trial[i] = self.pos[i] + delta[i] * alpha;
                    }
                    let e1 = self.potential(p, &trial);
                    if e1.is_finite() && e1 <= e0 + 1e-4 * alpha * slope + 1e-12 * e0.abs() {
                        accepted = true;
                        break;
                    }
                    alpha *= 0.5;
                }
                self.trial = trial;
                if !accepted {
                    alpha = 0.0;
                }
            }
            if alpha == 0.0 && !project {
                // no decrease along the exact-Hessian direction: retry with the projected Hessian
                project = true;
                self.grad = grad;
                self.hess = hess;
                self.delta = delta;
                continue;
            }
            for i in 0..n {
                self.pos[i] += delta[i] * alpha;
            }
            self.grad = grad;
            self.hess = hess;
            self.delta = delta;
            if step_max * alpha <= tol_x {
                // `gnorm`: the filtered residual at the start of this iteration
                stats.converged =
                    (alpha > 0.0 || step_max <= tol_x) && gnorm <= self.residual_bound(p);
                break;
            }
            if alpha == 0.0 {
                break;
            }
            if self.last_linear_iterations > self.config.refactor_iterations {
                // the rest-state preconditioner no longer fits the current shape: refactor here
                self.precond_at = Some(self.pos.clone());
                self.precond_gen += 1;
                self.precond = None;
            }
        }
        Ok(())
    }

    /// Moves the constrained components to their targets. World constraints and attachments are
    /// set directly; contact displacements `d` go through a linearised predictor, so that the free
    /// nodes follow: `x += d + u` with `A u = -(g + A d)` on the free components (`A` the factored
    /// matrix without contact penalties, `g` the gradient at `x`; filtered PCG, factor as
    /// preconditioner). Setting only the contact nodes would invert every element of a thin body
    /// whose contact side moves by more than its thickness in one step (a collider moving at 1 m/s
    /// against a 4 mm belt), and Newton then crawls out of the inverted state in tiny line-search
    /// steps.
    fn predict_constrained(&mut self, p: &Problem, stats: &mut StepStats) -> Result<(), FemError> {
        let n = self.n_nodes();
        let tol_x = self.config.newton_tolerance * self.model.length_scale;
        let has_contacts = self
            .active
            .iter()
            .any(|c| matches!(c.kind, ConKind::Contact));
        let mut d = if has_contacts {
            vec![Vector3::zeros(); n]
        } else {
            Vec::new()
        };
        let mut contact_moves = false;
        for c in &self.active {
            let i = c.node as usize;
            let di = c.proj * (c.target - self.pos[i]);
            if matches!(c.kind, ConKind::Contact) {
                d[i] = di;
                contact_moves |= di.amax() > tol_x;
            } else {
                self.pos[i] += di;
            }
        }
        if contact_moves {
            stats.factorizations += self.ensure_precond(p.c_mass + p.c_damp, 1.0 + p.c_kdamp)?;
            self.final_gradient(p);
            let mut r = vec![Vector3::zeros(); n];
            self.model.pattern.spmv(&self.precond_mat, &d, &mut r);
            for (ri, gi) in r.iter_mut().zip(&self.grad) {
                *ri = -(*ri + *gi);
            }
            Self::apply_filter(&self.active, &mut r);
            let mut u = std::mem::take(&mut self.delta);
            let mut cg = std::mem::take(&mut self.cg);
            let (_, pre) = self.precond.as_mut().expect("factored above");
            let pat = &self.model.pattern;
            let mat = &self.precond_mat;
            let active = &self.active;
            let res = pcg(
                |v, y| pat.spmv(mat, v, y),
                |z| pre.solve_in_place(z),
                |v| Self::apply_filter(active, v),
                &r,
                &mut u,
                1e-3,
                self.config.linear_max_iterations,
                &mut cg,
            );
            self.cg = cg;
            stats.linear_iterations += res.iterations;
            if u.iter().all(finite3) {
                for (di, ui) in d.iter_mut().zip(&u) {
                    *di += *ui;
                }
            }
            self.delta = u;
        }
        for (x, di) in self.pos.iter_mut().zip(&d) {
            *x += *di;
        }
        Ok(())
    }

    /// Largest residual force (N, any component) with which a dynamic step's small final step
    /// counts as convergence: a tenth of the force that would move the heaviest node by the
    /// solid's size within the step (`m l / dt^2`; no bound for statics). Converged steps of the
    /// task scenes end with residuals under 2 N where this bound is 60 to 600 N; a chord matrix
    /// gone bad (Spot Lift, held-out seed 37) took steps of 1e-19 m at residuals of 4e3 N and
    /// more, which the step-size test alone accepted, and the belt flew apart unreported.
    fn residual_bound(&self, p: &Problem) -> f64 {
        if p.c_mass > 0.0 {
            let m = self.model.mass.iter().fold(0.0f64, |a, &b| a.max(b));
            0.1 * m * self.model.length_scale * p.c_mass
        } else {
            f64::INFINITY
        }
    }

    /// Chord (quasi-Newton) iterations with the cached factor as the Newton matrix, Armijo line
    /// search on the potential, and a refactor at the current shape when the contraction rate
    /// exceeds 0.5 (the reference shape no longer represents the tangent).
    fn chord(
        &mut self,
        p: &Problem,
        max_iter: usize,
        stats: &mut StepStats,
    ) -> Result<bool, FemError> {
        let n = self.n_nodes();
        let tol_x = self.config.newton_tolerance * self.model.length_scale;
        let c_stiff_pre = 1.0 + p.c_kdamp;
        let c_mass_pre = p.c_mass + p.c_damp;
        let mut prev_step = f64::INFINITY;
        let mut refactored = false;
        // potential at `self.pos` once a line search has evaluated it there (the accepted trial is
        // bitwise the new position)
        let mut e_pos: Option<f64> = None;
        if self.config.warped_chord {
            let x_ref = self.precond_at.as_ref().unwrap_or(&self.model.mesh.rest);
            self.warp
                .update(&self.model.mesh.elements, x_ref, &self.pos);
            // contact penalties sit in the factor along world normals: those nodes stay unturned
            self.warp.unwarp(
                self.active
                    .iter()
                    .filter(|c| matches!(c.kind, ConKind::Contact))
                    .map(|c| c.node),
            );
        } else {
            self.warp.reset();
        }
        // `Some(inverted)`: `grad` holds the gradient at `pos` (evaluated with the line search's
        // first trial, which became `pos`)
        let mut grad_ready: Option<usize> = None;
        for _ in 0..max_iter {
            stats.factorizations += self.ensure_precond(c_mass_pre, c_stiff_pre)?;
            stats.newton_iterations += 1;
            if grad_ready.take().is_none() {
                self.final_gradient(p);
            }
            let mut delta = std::mem::take(&mut self.delta);
            for (d, g) in delta.iter_mut().zip(&self.grad) {
                *d = -*g;
            }
            Self::apply_filter(&self.active, &mut delta);
            let r = delta.clone();
            // constraints the factor does not contain (contacts) need a filtered PCG on the factored
            // matrix; otherwise one triangular solve is the exact chord step
            let needs_pcg = self
                .active
                .iter()
                .any(|c| matches!(c.kind, ConKind::Contact));
            let (_, pre) = self.precond.as_mut().expect("factored above");
            if needs_pcg {
                let mut cg = std::mem::take(&mut self.cg);
                let pat = &self.model.pattern;
                let mat = &self.precond_mat;
                let active = &self.active;
                let warp = &self.warp;
                // the line search's buffer is free until the line search
                let mut tmp = std::mem::take(&mut self.trial);
                let res = pcg(
                    |v, y| warp.apply(v, y, &mut tmp, |u, out| pat.spmv(mat, u, out)),
                    |z| {
                        warp.turn_back(z);
                        pre.solve_in_place(z);
                        warp.turn(z);
                    },
                    |v| Self::apply_filter(active, v),
                    &r,
                    &mut delta,
                    1e-3,
                    self.config.linear_max_iterations,
                    &mut cg,
                );
                self.trial = tmp;
                self.cg = cg;
                stats.linear_iterations += res.iterations;
            } else {
                self.warp.turn_back(&mut delta);
                pre.solve_in_place(&mut delta);
                self.warp.turn(&mut delta);
                Self::apply_filter(&self.active, &mut delta);
                stats.linear_iterations += 1;
            }
            let step_max = max_component(&delta);
            if !step_max.is_finite() {
                self.delta = delta;
                return Err(FemError::Exploded {
                    step: self.steps,
                    max_speed: f64::INFINITY,
                });
            }
            let mut alpha = 1.0;
            if step_max > tol_x {
                let mut trial = std::mem::take(&mut self.trial);
                let e0 = match e_pos {
                    Some(e) => e,
                    None => self.potential(p, &self.pos),
                };
                let slope = -dot(&r, &delta);
                let mut accepted = None;
                // a warped step is taken whole or not at all: one that needs damping means the
                // rotations do not fit this shape (a belt crushed by a fast box), and its damped
                // version would move the state in a poor direction; the refactor below follows
                let warped = self.warp.is_on();
                for k in 0..30 {
                    for i in 0..n {
                        trial[i] = self.pos[i] + delta[i] * alpha;
                    }
                    // the full step (usually taken) evaluates the gradient with the energy, in
                    // one pass: the next iteration's gradient if the step is accepted
                    let e1 = if k == 0 {
                        let mut egrad = std::mem::take(&mut self.trial_egrad);
                        let mut grad = std::mem::take(&mut self.trial_grad);
                        let st = self.gradient_at(p, &trial, &mut egrad, &mut grad, true);
                        self.trial_egrad = egrad;
                        self.trial_grad = grad;
                        grad_ready = Some(st.inverted);
                        self.potential_with(p, &trial, st.energy)
                    } else {
                        grad_ready = None;
                        self.potential(p, &trial)
                    };
                    if e1.is_finite() && e1 <= e0 + 1e-4 * alpha * slope + 1e-12 * e0.abs() {
                        accepted = Some(e1);
                        break;
                    }
                    if warped {
                        break;
                    }
                    alpha *= 0.5;
                }
                self.trial = trial;
                if accepted.is_none() {
                    alpha = 0.0;
                }
                // rejected: the position stays and so does its potential
                e_pos = accepted.or(Some(e0));
            } else {
                e_pos = None;
            }
            for i in 0..n {
                self.pos[i] += delta[i] * alpha;
            }
            self.delta = delta;
            if alpha == 1.0 && grad_ready.is_some() {
                // `pos` is bitwise the first trial point
                std::mem::swap(&mut self.egrad, &mut self.trial_egrad);
                std::mem::swap(&mut self.grad, &mut self.trial_grad);
            } else {
                grad_ready = None;
            }
            let moved = step_max * alpha;
            if alpha > 0.0 && moved <= tol_x || step_max <= tol_x {
                if max_component(&r) > self.residual_bound(p) {
                    // a tiny step at a large residual: the chord matrix no longer describes this
                    // shape (it is not convergence); exact Newton takes over
                    return Ok(false);
                }
                stats.converged = true;
                self.grad_at_pos = grad_ready;
                return Ok(true);
            }
            if (alpha < 1.0 || moved > 0.5 * prev_step) && !refactored {
                // slow or damped convergence: refactor the matrix at the current shape (once per solve)
                self.precond_at = Some(self.pos.clone());
                self.precond_gen += 1;
                self.precond = None;
                self.warp.reset();
                refactored = true;
            } else if alpha == 0.0 {
                return Ok(false);
            }
            prev_step = moved;
        }
        Ok(false)
    }

    /// Gradient of the potential at the current positions (for constraint forces), into `self.grad`.
    fn final_gradient(&mut self, p: &Problem) -> usize {
        let mut egrad = std::mem::take(&mut self.egrad);
        let mut grad = std::mem::take(&mut self.grad);
        let inverted = self
            .gradient_at(p, &self.pos, &mut egrad, &mut grad, false)
            .inverted;
        self.egrad = egrad;
        self.grad = grad;
        inverted
    }

    /// [`FemSolid::final_gradient`] after a Newton solve: the chord's own evaluation at `pos`
    /// when it left one, else a new one.
    fn gradient_after_solve(&mut self, p: &Problem) -> usize {
        match self.grad_at_pos.take() {
            Some(inverted) => inverted,
            None => self.final_gradient(p),
        }
    }

    /// The incremental potential's gradient at `x` into `grad` (its elastic part, scaled, into
    /// `egrad`), with the unscaled elastic energy when `with_energy` (else 0).
    fn gradient_at(
        &self,
        p: &Problem,
        x: &[Vector3<f64>],
        egrad: &mut [Vector3<f64>],
        grad: &mut [Vector3<f64>],
        with_energy: bool,
    ) -> KernelStats {
        let damping = (p.c_kdamp > 0.0).then_some((&self.xprev[..], p.c_kdamp));
        let stats = self.model.kernel(x, Some(egrad), damping, with_energy);
        let k = self.stiffness_scale;
        if k != 1.0 {
            egrad.iter_mut().for_each(|g| *g *= k);
        }
        self.assemble_gradient(p, x, egrad, grad);
        stats
    }

    /// The incremental potential's gradient at `x` from the (scaled) elastic one.
    fn assemble_gradient(
        &self,
        p: &Problem,
        x: &[Vector3<f64>],
        egrad: &[Vector3<f64>],
        grad: &mut [Vector3<f64>],
    ) {
        for i in 0..self.n_nodes() {
            let m = self.model.mass[i];
            let mut g = egrad[i] - self.ext_force[i] - self.fric[i] - p.gravity * m;
            if p.c_mass > 0.0 {
                g += (x[i] - self.xhat[i]) * (m * p.c_mass);
            }
            if p.c_damp > 0.0 {
                g += (x[i] - self.xprev[i]) * (m * p.c_damp);
            }
            grad[i] = g;
        }
        self.grasp_energy_grad(x, Some(grad));
    }

    fn refresh_grasp_anchors(&mut self) {
        for gi in 0..self.grasps.len() {
            let pose = self.pose(self.grasps[gi].body);
            let g = &mut self.grasps[gi];
            for (a, l) in g.anchor.iter_mut().zip(&g.local) {
                *a = (pose * Point3::from(*l)).coords;
            }
        }
    }

    /// Updates grasp forces and slips saturated grasps; returns the number that slipped.
    fn finish_grasps(&mut self, dt: f64, reactions: Option<&mut Vec<Reaction>>) -> usize {
        let mut slipped = 0;
        let mut reactions = reactions;
        for gi in 0..self.grasps.len() {
            let pose = self.pose(self.grasps[gi].body);
            let inv = pose.inverse();
            let g = &mut self.grasps[gi];
            let n = g.nodes.len() as f64;
            let k = g.params.stiffness;
            let kk = n * k;
            let dbar: Vector3<f64> = g
                .nodes
                .iter()
                .zip(&g.anchor)
                .map(|(&i, a)| self.pos[i as usize] - a)
                .sum::<Vector3<f64>>()
                / n;
            let r = dbar.norm();
            let flim = g.params.force_limit;
            let gh = if kk * r <= flim {
                dbar * kk
            } else {
                dbar * (flim / r)
            };
            g.force = -gh;
            if let Some(re) = reactions.as_deref_mut() {
                for (&i, a) in g.nodes.iter().zip(&g.anchor) {
                    let f_on_node = -((self.pos[i as usize] - a - dbar) * k + gh / n);
                    re.push(Reaction {
                        body: g.body,
                        point: *a,
                        impulse: -f_on_node * dt,
                    });
                }
            }
            g.slipping = kk * r > flim;
            if g.slipping {
                slipped += 1;
                let s = dbar * (1.0 - flim / (kk * r));
                g.slip_distance += s.norm();
                for (a, l) in g.anchor.iter_mut().zip(g.local.iter_mut()) {
                    *a += s;
                    *l = (inv * Point3::from(*a)).coords;
                }
            }
        }
        slipped
    }

    fn record_constraint_forces(&mut self) {
        self.con_forces.clear();
        for c in &self.active {
            let f = c.proj * self.grad[c.node as usize];
            self.con_forces.push((c.node, f));
        }
    }

    // ----------------------------------------------------------------- stepping

    /// Advances the solid by one backward-Euler step of `dt` (s) under `gravity` (m/s^2, world
    /// frame), with rigid contacts from `contacts`; appends to `reactions` the impulses (N s) the
    /// solid applied on rigid bodies through attachments, grasps and contacts. Kinematic
    /// attachments reach their bodies' poses (set by [`FemSolid::set_body_pose`]) at the end of
    /// the step. On a blow-up the state is rolled back and an error returned.
    pub fn step(
        &mut self,
        dt: f64,
        gravity: Vector3<f64>,
        contacts: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
    ) -> Result<StepStats, FemError> {
        self.step_at(0.0, dt, gravity, contacts, reactions)
    }

    /// [`FemSolid::step`] for a step that starts `t0` seconds (>= 0) after the rigid state
    /// `contacts` describes: moving colliders are extrapolated at their surface velocity over
    /// `t0 + dt` (and searched for that much further), as the halves of a split step are.
    /// Several solid steps per rigid substep use it (`physics.deformable_substeps`).
    pub fn step_at(
        &mut self,
        t0: f64,
        dt: f64,
        gravity: Vector3<f64>,
        contacts: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
    ) -> Result<StepStats, FemError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(FemError::InvalidParameter {
                name: "dt",
                value: dt,
                expected: "finite and > 0 (s)",
            });
        }
        if !(t0.is_finite() && t0 >= 0.0) {
            return Err(FemError::InvalidParameter {
                name: "t0",
                value: t0,
                expected: "finite and >= 0 (s)",
            });
        }
        if !finite3(&gravity) {
            return Err(FemError::NonFiniteInput("gravity"));
        }
        let result = self.step_split(dt, t0, gravity, contacts, reactions, MAX_STEP_HALVINGS);
        if result.is_ok() {
            self.steps += 1;
        }
        result
    }

    /// One step of `dt`, starting `t0` seconds after the rigid world's state that `contacts`
    /// describes; if its solve fails (does not converge, explodes, or meets a matrix that is not
    /// positive definite) and `halvings > 0`, it is rolled back and done as two half steps.
    /// A collider moving more than a thin body's thickness in one step (a box at 3 m/s against a
    /// 4 mm belt) is the usual cause; the halves see the collider at its interpolated position.
    fn step_split(
        &mut self,
        dt: f64,
        t0: f64,
        gravity: Vector3<f64>,
        contacts: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
        halvings: u32,
    ) -> Result<StepStats, FemError> {
        let strict = halvings > 0;
        match self.step_once(dt, t0, gravity, contacts, reactions, strict) {
            Err(FemError::Exploded { .. } | FemError::NotPositiveDefinite(_)) if strict => {
                // rolled back to the start of this (part of the) step: keep it in case a half fails
                let start = self.get_state();
                let reactions_len = reactions.len();
                let h = 0.5 * dt;
                let halves = self
                    .step_split(h, t0, gravity, contacts, reactions, halvings - 1)
                    .and_then(|a| {
                        self.step_split(h, t0 + h, gravity, contacts, reactions, halvings - 1)
                            .map(|b| (a, b))
                    });
                let (a, b) = match halves {
                    Ok(ab) => ab,
                    Err(e) => {
                        self.set_state(&start)?;
                        reactions.truncate(reactions_len);
                        return Err(e);
                    }
                };
                Ok(StepStats {
                    active_set_rounds: a.active_set_rounds + b.active_set_rounds,
                    newton_iterations: a.newton_iterations + b.newton_iterations,
                    linear_iterations: a.linear_iterations + b.linear_iterations,
                    factorizations: a.factorizations + b.factorizations,
                    slipping_grasps: a.slipping_grasps.max(b.slipping_grasps),
                    halvings: 1 + a.halvings + b.halvings,
                    ..b
                })
            }
            r => r,
        }
    }

    /// One backward-Euler step; on failure (and, if `strict`, on a solve that did not converge)
    /// the state is rolled back and an error returned.
    fn step_once(
        &mut self,
        dt: f64,
        t0: f64,
        gravity: Vector3<f64>,
        contacts: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
        strict: bool,
    ) -> Result<StepStats, FemError> {
        let reactions_len = reactions.len();
        self.xprev.copy_from_slice(&self.pos);
        self.vprev.copy_from_slice(&self.vel);
        let grasp_backup: Vec<(Vec<Vector3<f64>>, f64)> = self
            .grasps
            .iter()
            .map(|g| (g.local.clone(), g.slip_distance))
            .collect();
        let precond_backup = self.precond_at.clone();
        let memory_backup = self.contact_memory.clone();
        let result = self.step_inner(dt, t0, gravity, contacts, reactions);
        let failed = match &result {
            Ok(stats) => {
                let mut max_speed: f64 = 0.0;
                let mut finite = true;
                for (x, v) in self.pos.iter().zip(&self.vel) {
                    finite &= finite3(x) && finite3(v);
                    max_speed = max_speed.max(v.norm());
                }
                if !finite {
                    Some(FemError::Exploded {
                        step: self.steps,
                        max_speed: f64::INFINITY,
                    })
                } else if max_speed > self.config.max_speed || (strict && !stats.converged) {
                    Some(FemError::Exploded {
                        step: self.steps,
                        max_speed,
                    })
                } else {
                    None
                }
            }
            Err(e) => Some(e.clone()),
        };
        if let Some(err) = failed {
            self.pos.copy_from_slice(&self.xprev);
            self.vel.copy_from_slice(&self.vprev);
            for (g, (l, s)) in self.grasps.iter_mut().zip(grasp_backup) {
                g.local = l;
                g.slip_distance = s;
            }
            self.precond_at = precond_backup;
            self.precond_gen += 1;
            self.contact_memory = memory_backup;
            reactions.truncate(reactions_len);
            return Err(err);
        }
        result
    }

    fn step_inner(
        &mut self,
        dt: f64,
        t0: f64,
        gravity: Vector3<f64>,
        contacts: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
    ) -> Result<StepStats, FemError> {
        let n = self.n_nodes();
        let mut stats = StepStats::default();
        let problem = Problem {
            c_mass: 1.0 / (dt * dt),
            c_damp: self.config.rayleigh_mass / dt,
            c_kdamp: self.config.rayleigh_stiffness / dt,
            gravity: Vector3::zeros(),
        };
        for i in 0..n {
            self.xhat[i] = self.pos[i] + self.vel[i] * dt + gravity * (dt * dt);
        }
        self.refresh_grasp_anchors();
        // contact candidates
        self.candidates.clear();
        // Fully constrained nodes need no contact; grasped nodes are pinched between the fingers,
        // whose contact the grasp spring stands for (a contact with the closing fingers would
        // fight the spring).
        let mut skip = self.full_constrained();
        for g in &self.grasps {
            for &n in &g.nodes {
                skip[n as usize] = true;
            }
        }
        let mut normals = std::mem::take(&mut self.normals);
        self.model.surface_normals(&self.pos, &mut normals);
        self.normals = normals;
        let mut out: Vec<PointContact> = Vec::new();
        let gdt2 = gravity.norm() * dt * dt;
        for &i in &self.model.surface_nodes {
            if skip[i as usize] {
                continue;
            }
            let x = self.pos[i as usize];
            let reach = self.vel[i as usize].norm() * dt
                + gdt2
                + self.config.collider_speed_bound * (t0 + dt)
                + self.config.contact_margin;
            out.clear();
            contacts.contacts_near(&x, reach, &mut out);
            // keep the closest contact on a collider the node's surface faces
            let ns = self.normals[i as usize];
            let mut best: Option<PointContact> = None;
            for c in &out {
                let valid = finite3(&c.point)
                    && finite3(&c.normal)
                    && finite3(&c.velocity)
                    && c.distance.is_finite()
                    && c.friction.is_finite();
                if !valid {
                    return Err(FemError::NonFiniteInput("contact query result"));
                }
                let faces = ns == Vector3::zeros() || ns.dot(&c.normal) < -FACING_COS;
                if faces && best.is_none_or(|b| c.distance < b.distance) {
                    best = Some(*c);
                }
            }
            if let Some(mut c) = best {
                c.normal = c.normal.try_normalize(1e-12).unwrap_or(Vector3::z());
                // collider surface position at the end of the step
                c.point += c.velocity * (t0 + dt);
                let gap = (self.xhat[i as usize] - c.point).dot(&c.normal);
                let t = x + c.velocity * dt;
                let stick_target = t - c.normal * (t - c.point).dot(&c.normal);
                let vrel = self.vel[i as usize] - c.velocity;
                let vt = vrel - c.normal * vrel.dot(&c.normal);
                let speed = vt.norm();
                let mass = self.model.mass[i as usize];
                // The last step's contact on this node and body (if any) is the first guess:
                // active, its normal force, and sliding if it ended sliding (in its direction of
                // motion, or the old one if it barely moves). A new contact's normal force is
                // the one stopping the node's predicted penetration within the step.
                let memory = self
                    .contact_memory
                    .binary_search_by_key(&i, |m| m.node)
                    .ok()
                    .map(|k| self.contact_memory[k])
                    .filter(|m| m.body == c.body);
                let normal_force = match memory {
                    Some(m) => m.normal_force.max(0.0),
                    None => mass * (-gap).max(0.0) * problem.c_mass,
                };
                // a node slower than its kinetic friction can stop within the step starts
                // sticking (sliding, the friction would reverse it: one more round)
                let stop_speed = c.friction * normal_force * dt / mass;
                let remembered_slip = memory.filter(|m| !m.stick).map(|m| m.slip_dir);
                let sliding = remembered_slip.is_some() || speed > SLIP_SPEED.max(stop_speed);
                let slip_dir = match remembered_slip {
                    Some(d) if speed <= SLIP_SPEED => d,
                    _ if sliding => -vt / speed,
                    _ => Vector3::zeros(),
                };
                // (a remembered frictionless slide has no direction: with friction now, stick)
                let sliding = sliding && slip_dir != Vector3::zeros();
                self.candidates.push(Candidate {
                    node: i,
                    contact: c,
                    // (a node that was touching and is predicted within the margin touches)
                    active: gap < 0.0 || (memory.is_some() && gap < self.config.contact_margin),
                    stick: c.friction > 0.0 && !sliding,
                    stick_target,
                    normal_force,
                    friction_force: slip_dir * (c.friction * normal_force),
                    slip_dir,
                    secant: None,
                });
            }
        }
        // active-set rounds: contacts start sticking; a stuck contact whose tangential force
        // exceeds mu * normal force slides with kinetic friction mu * normal force opposing the
        // tendency; pulling (adhesive) contacts are released; penetrating ones activated
        // Tolerances of the rounds match the Newton solve's: a penetration, an adhesive normal
        // force or a change of kinetic friction smaller than what the solve resolves (its step
        // tolerance, and that step's inertial force) starts no new round.
        let pen_tol = self.config.newton_tolerance * self.model.length_scale;
        let max_rounds = 6;
        for round in 0..max_rounds {
            let last = round + 1 == max_rounds;
            for i in 0..n {
                self.fric[i] = Vector3::zeros();
            }
            for c in &self.candidates {
                if c.active && !c.stick {
                    self.fric[c.node as usize] = c.friction_force;
                }
            }
            // initial guess x_n + dt v_n (exact for steady motion; gravity is left to Newton)
            for i in 0..n {
                self.pos[i] = self.xprev[i] + self.vprev[i] * dt;
            }
            self.build_active();
            stats.active_set_rounds += 1;
            self.newton(
                &problem,
                self.config.newton_max_iterations,
                true,
                &mut stats,
            )?;
            stats.inverted = self.gradient_after_solve(&problem);
            let mut changed = false;
            for ci in 0..self.candidates.len() {
                let c = self.candidates[ci];
                let i = c.node as usize;
                let nrm = c.contact.normal;
                let force_tol = self.model.mass[i] * problem.c_mass * pen_tol;
                if c.active {
                    let g = self.grad[i];
                    let lam = nrm.dot(&g);
                    self.candidates[ci].normal_force = lam;
                    if lam < -force_tol {
                        if !last {
                            self.candidates[ci].active = false;
                            changed = true;
                        }
                        continue;
                    }
                    let mu = c.contact.friction;
                    if c.stick {
                        let ft = g - nrm * lam;
                        if ft.norm() > mu * lam * (1.0 + 1e-9) && !last {
                            let cc = &mut self.candidates[ci];
                            cc.stick = false;
                            cc.slip_dir = ft / ft.norm();
                            cc.friction_force = cc.slip_dir * (mu * lam);
                            cc.secant = None;
                            changed = true;
                        }
                    } else {
                        let vt = {
                            let v = (self.pos[i] - self.xprev[i]) / dt - c.contact.velocity;
                            v - nrm * v.dot(&nrm)
                        };
                        let cc = &mut self.candidates[ci];
                        if vt.dot(&cc.slip_dir) > 0.0 && mu > 0.0 && !last {
                            // friction reversed the sliding: the node sticks
                            cc.stick = true;
                            changed = true;
                        } else {
                            // kinetic friction f must equal mu * normal force, itself a function
                            // of f: a secant step on f - mu * lam(f) once two rounds are known
                            let f = cc.friction_force.dot(&cc.slip_dir);
                            let target = mu * lam.max(0.0);
                            let off = (target - f).abs();
                            if off > (FRICTION_RTOL * target).max(force_tol) && !last {
                                let next = match cc.secant {
                                    Some((f0, t0)) if f != f0 => {
                                        let slope = ((target - t0) / (f - f0)).clamp(-10.0, 0.5);
                                        (f + (target - f) / (1.0 - slope)).max(0.0)
                                    }
                                    _ => target,
                                };
                                cc.secant = Some((f, target));
                                cc.friction_force = cc.slip_dir * next;
                                changed = true;
                            }
                        }
                    }
                } else {
                    let gap = (self.pos[i] - c.contact.point).dot(&nrm);
                    if gap < -pen_tol && !last {
                        let cc = &mut self.candidates[ci];
                        cc.active = true;
                        cc.stick = cc.contact.friction > 0.0;
                        cc.secant = None;
                        changed = true;
                    }
                }
            }
            if !changed {
                break;
            }
        }
        self.record_constraint_forces();
        self.contact_memory.clear();
        for c in &self.candidates {
            if c.active {
                self.contact_memory.push(ContactMemory {
                    node: c.node,
                    body: c.contact.body,
                    stick: c.stick,
                    slip_dir: c.slip_dir,
                    normal_force: c.normal_force,
                });
            }
        }
        self.contact_memory.sort_by_key(|m| m.node);
        // reactions of kinematic attachments
        for c in &self.active {
            if let ConKind::Attachment(ai) = c.kind {
                let f = c.proj * self.grad[c.node as usize];
                reactions.push(Reaction {
                    body: self.attachments[ai as usize].body,
                    point: self.pos[c.node as usize],
                    impulse: -f * dt,
                });
            }
        }
        // contact reactions (normal + friction); remaining penetration of inactive candidates
        // (only possible when the rounds ran out) is projected out
        for c in &self.candidates {
            let i = c.node as usize;
            let nrm = c.contact.normal;
            if !c.active {
                let gap = (self.pos[i] - c.contact.point).dot(&nrm);
                if gap < 0.0 {
                    self.pos[i] -= nrm * gap;
                }
                continue;
            }
            stats.contacts += 1;
            // only what a contact can transmit goes to the body: a compressive normal force and
            // friction inside the cone (the active-set rounds can end with a contact outside)
            let g = self.grad[i];
            let lam = nrm.dot(&g);
            if lam <= 0.0 {
                continue;
            }
            let ft = if c.stick {
                g - nrm * lam
            } else {
                c.friction_force
            };
            let ft_max = c.contact.friction * lam;
            let ft = if ft.norm() > ft_max {
                ft * (ft_max / ft.norm())
            } else {
                ft
            };
            let force_on_node = nrm * lam + ft;
            reactions.push(Reaction {
                body: c.contact.body,
                point: c.contact.point,
                impulse: -force_on_node * dt,
            });
        }
        for f in self.fric.iter_mut() {
            *f = Vector3::zeros();
        }
        for i in 0..n {
            self.vel[i] = (self.pos[i] - self.xprev[i]) / dt;
        }
        stats.slipping_grasps = self.finish_grasps(dt, Some(reactions));
        Ok(stats)
    }

    /// Static equilibrium under `gravity` and the external loads from the current shape
    /// (nonlinear, Newton with line search), respecting world constraints, attachments (at their
    /// bodies' poses) and grasps; contacts are ignored. Velocities are set to zero.
    pub fn solve_static(
        &mut self,
        gravity: Vector3<f64>,
        max_iterations: usize,
    ) -> Result<StepStats, FemError> {
        if !finite3(&gravity) {
            return Err(FemError::NonFiniteInput("gravity"));
        }
        let p = Problem {
            c_mass: 0.0,
            c_damp: 0.0,
            c_kdamp: 0.0,
            gravity,
        };
        self.xprev.copy_from_slice(&self.pos);
        self.refresh_grasp_anchors();
        self.candidates.clear();
        self.build_active();
        let mut stats = StepStats::default();
        let r = self.newton(&p, max_iterations, true, &mut stats);
        if let Err(e) = r {
            self.pos.copy_from_slice(&self.xprev);
            return Err(e);
        }
        if !self.pos.iter().all(finite3) {
            self.pos.copy_from_slice(&self.xprev);
            return Err(FemError::Exploded {
                step: self.steps,
                max_speed: f64::INFINITY,
            });
        }
        stats.inverted = self.gradient_after_solve(&p);
        self.record_constraint_forces();
        self.finish_grasps(1.0, None);
        self.vel.iter_mut().for_each(|v| *v = Vector3::zeros());
        Ok(stats)
    }

    /// Linear static displacement from the rest shape (m per node): one Newton step from rest,
    /// i.e. `K_rest u = f` with the current constraints, gravity and external loads. Leaves the
    /// state unchanged.
    pub fn solve_linear_static(
        &mut self,
        gravity: Vector3<f64>,
    ) -> Result<Vec<Vector3<f64>>, FemError> {
        if !finite3(&gravity) {
            return Err(FemError::NonFiniteInput("gravity"));
        }
        let saved = self.pos.clone();
        self.pos.copy_from_slice(&self.model.mesh.rest);
        self.xprev.copy_from_slice(&self.pos);
        let p = Problem {
            c_mass: 0.0,
            c_damp: 0.0,
            c_kdamp: 0.0,
            gravity,
        };
        self.refresh_grasp_anchors();
        self.candidates.clear();
        self.build_active();
        let mut stats = StepStats::default();
        let r = self.newton(&p, 1, false, &mut stats);
        let u: Vec<Vector3<f64>> = self
            .pos
            .iter()
            .zip(&self.model.mesh.rest)
            .map(|(x, r)| x - r)
            .collect();
        self.pos = saved;
        r?;
        Ok(u)
    }

    // ----------------------------------------------------------------- state

    /// Full dynamic state as a flat vector: positions, velocities, step count, external loads,
    /// world constraints, body poses, attachments, grasps (with slip state), the
    /// preconditioner's reference shape, the Young's modulus scale and the contacts the last step
    /// ended with (the next step's first guess). `set_state(get_state())` is a bit-exact round
    /// trip. [`FemSolid::set_state`] also reads the previous format (without the contacts).
    pub fn get_state(&self) -> Vec<f64> {
        let mut s = vec![
            STATE_MAGIC,
            self.n_nodes() as f64,
            self.steps as f64,
            self.next_id as f64,
        ];
        let push3 = |s: &mut Vec<f64>, v: &Vector3<f64>| s.extend_from_slice(&[v.x, v.y, v.z]);
        for v in self.pos.iter().chain(&self.vel).chain(&self.ext_force) {
            push3(&mut s, v);
        }
        s.push(self.world.len() as f64);
        for w in &self.world {
            s.push(w.node as f64);
            s.extend_from_slice(w.proj.as_slice());
            push3(&mut s, &w.target);
        }
        s.push(self.poses.len() as f64);
        for (b, p) in &self.poses {
            s.push(*b as f64);
            push3(&mut s, &p.translation.vector);
            s.extend_from_slice(p.rotation.coords.as_slice());
        }
        s.push(self.attachments.len() as f64);
        for a in &self.attachments {
            s.extend_from_slice(&[a.id as f64, a.body as f64, a.nodes.len() as f64]);
            for (n, l) in a.nodes.iter().zip(&a.local) {
                s.push(*n as f64);
                push3(&mut s, l);
            }
        }
        s.push(self.grasps.len() as f64);
        for g in &self.grasps {
            s.extend_from_slice(&[
                g.id as f64,
                g.body as f64,
                g.params.stiffness,
                g.params.force_limit,
                g.nodes.len() as f64,
            ]);
            for (n, l) in g.nodes.iter().zip(&g.local) {
                s.push(*n as f64);
                push3(&mut s, l);
            }
            push3(&mut s, &g.force);
            s.extend_from_slice(&[if g.slipping { 1.0 } else { 0.0 }, g.slip_distance]);
        }
        match &self.precond_at {
            None => s.push(0.0),
            Some(x) => {
                s.push(1.0);
                for v in x {
                    push3(&mut s, v);
                }
            }
        }
        s.push(self.stiffness_scale);
        s.push(self.contact_memory.len() as f64);
        for m in &self.contact_memory {
            s.extend_from_slice(&[
                m.node as f64,
                f64::from(m.body),
                f64::from(u8::from(m.stick)),
            ]);
            push3(&mut s, &m.slip_dir);
            s.push(m.normal_force);
        }
        s
    }

    /// Restores a state produced by [`FemSolid::get_state`] of a solid with the same model.
    pub fn set_state(&mut self, state: &[f64]) -> Result<(), FemError> {
        let mut r = Reader { s: state, i: 0 };
        let version = r.next()?;
        if version != STATE_MAGIC && version != STATE_MAGIC_V1 {
            return Err(FemError::InvalidState(
                "not a modesuite-fem state vector (bad tag)".into(),
            ));
        }
        let n = r.next()? as usize;
        if n != self.n_nodes() {
            return Err(FemError::InvalidState(format!(
                "state has {n} nodes, solid has {}",
                self.n_nodes()
            )));
        }
        let steps = r.next()? as u64;
        let next_id = r.next()? as u32;
        let mut pos = Vec::with_capacity(n);
        let mut vel = Vec::with_capacity(n);
        let mut ext = Vec::with_capacity(n);
        for _ in 0..n {
            pos.push(r.v3()?);
        }
        for _ in 0..n {
            vel.push(r.v3()?);
        }
        for _ in 0..n {
            ext.push(r.v3()?);
        }
        let nw = r.count()?;
        let mut world = Vec::with_capacity(nw);
        for _ in 0..nw {
            let node = r.node(n)?;
            let mut proj = Matrix3::zeros();
            for k in 0..9 {
                proj.as_mut_slice()[k] = r.next()?;
            }
            world.push(WorldConstraint {
                node,
                proj,
                target: r.v3()?,
            });
        }
        let np = r.count()?;
        let mut poses = Vec::with_capacity(np);
        for _ in 0..np {
            let b = r.next()? as u32;
            let t = r.v3()?;
            let (qi, qj, qk, qw) = (r.next()?, r.next()?, r.next()?, r.next()?);
            let q = Quaternion::new(qw, qi, qj, qk);
            poses.push((
                b,
                Isometry3::from_parts(Translation3::from(t), UnitQuaternion::new_unchecked(q)),
            ));
        }
        let na = r.count()?;
        let mut attachments = Vec::with_capacity(na);
        for _ in 0..na {
            let id = r.next()? as u32;
            let body = r.next()? as u32;
            let k = r.count()?;
            let mut nodes = Vec::with_capacity(k);
            let mut local = Vec::with_capacity(k);
            for _ in 0..k {
                nodes.push(r.node(n)?);
                local.push(r.v3()?);
            }
            attachments.push(Attachment {
                id,
                body,
                nodes,
                local,
            });
        }
        let ng = r.count()?;
        let mut grasps = Vec::with_capacity(ng);
        for _ in 0..ng {
            let id = r.next()? as u32;
            let body = r.next()? as u32;
            let params = GraspParams {
                stiffness: r.next()?,
                force_limit: r.next()?,
            };
            let k = r.count()?;
            let mut nodes = Vec::with_capacity(k);
            let mut local = Vec::with_capacity(k);
            for _ in 0..k {
                nodes.push(r.node(n)?);
                local.push(r.v3()?);
            }
            let force = r.v3()?;
            let slipping = r.next()? != 0.0;
            let slip_distance = r.next()?;
            grasps.push(Grasp {
                id,
                body,
                params,
                anchor: local.clone(),
                nodes,
                local,
                force,
                slipping,
                slip_distance,
            });
        }
        let precond_at = if r.next()? != 0.0 {
            let mut x = Vec::with_capacity(n);
            for _ in 0..n {
                x.push(r.v3()?);
            }
            Some(x)
        } else {
            None
        };
        let stiffness_scale = r.next()?;
        if !(stiffness_scale.is_finite() && stiffness_scale > 0.0) {
            return Err(FemError::InvalidState(format!(
                "stiffness scale {stiffness_scale}: finite and > 0"
            )));
        }
        let mut contact_memory = Vec::new();
        if version == STATE_MAGIC {
            let count = r.count()?;
            for _ in 0..count {
                let node = r.node(n)?;
                let body = r.next()?;
                if !(body >= 0.0 && body <= f64::from(u32::MAX) && body.fract() == 0.0) {
                    return Err(FemError::InvalidState(format!("contact body id {body}")));
                }
                let stick = r.next()? != 0.0;
                let slip_dir = r.v3()?;
                let normal_force = r.next()?;
                if !(finite3(&slip_dir) && normal_force.is_finite()) {
                    return Err(FemError::NonFiniteInput("contact memory"));
                }
                contact_memory.push(ContactMemory {
                    node,
                    body: body as u32,
                    stick,
                    slip_dir,
                    normal_force,
                });
            }
            if !contact_memory.windows(2).all(|w| w[0].node < w[1].node) {
                return Err(FemError::InvalidState(
                    "contact memory: nodes not in increasing order".into(),
                ));
            }
        }
        if r.i != state.len() {
            return Err(FemError::InvalidState(format!(
                "{} trailing values",
                state.len() - r.i
            )));
        }
        self.pos = pos;
        self.vel = vel;
        self.ext_force = ext;
        self.steps = steps;
        self.next_id = next_id;
        self.world = world;
        self.poses = poses;
        self.attachments = attachments;
        self.grasps = grasps;
        self.precond_at = precond_at;
        self.precond_gen += 1;
        self.stiffness_scale = stiffness_scale;
        self.contact_memory = contact_memory;
        self.precond = None;
        self.constraint_version += 1;
        self.refresh_grasp_anchors();
        Ok(())
    }
}

struct Reader<'a> {
    s: &'a [f64],
    i: usize,
}

impl Reader<'_> {
    fn next(&mut self) -> Result<f64, FemError> {
        let v = *self
            .s
            .get(self.i)
            .ok_or_else(|| FemError::InvalidState("truncated".into()))?;
        self.i += 1;
        Ok(v)
    }
    fn v3(&mut self) -> Result<Vector3<f64>, FemError> {
        Ok(Vector3::new(self.next()?, self.next()?, self.next()?))
    }
    fn count(&mut self) -> Result<usize, FemError> {
        let v = self.next()?;
        if !(v >= 0.0 && v.fract() == 0.0 && v < 1e9) {
            return Err(FemError::InvalidState(format!("bad count {v}")));
        }
        Ok(v as usize)
    }
    fn node(&mut self, n: usize) -> Result<u32, FemError> {
        let v = self.count()?;
        if v >= n {
            return Err(FemError::InvalidState(format!("node {v} out of range")));
        }
        Ok(v as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coupling::HalfSpace;
    use crate::testing::box_mesh;

    fn block_on_floor() -> FemSolid {
        let (nodes, tets) = box_mesh(Vector3::zeros(), Vector3::new(0.2, 0.04, 0.04), [4, 1, 1]);
        let material = Material::new(1e5, 0.35, 200.0).unwrap();
        FemSolid::new(&nodes, &tets, material, FemConfig::default()).unwrap()
    }

    #[test]
    fn the_state_keeps_the_contact_memory_and_reads_the_old_format() {
        let floor = HalfSpace {
            origin: Vector3::zeros(),
            normal: Vector3::z(),
            friction: 0.5,
            body: 3,
            velocity: Vector3::zeros(),
        };
        let mut a = block_on_floor();
        let vel = vec![Vector3::new(0.3, 0.0, 0.0); a.n_nodes()];
        let pos = a.positions().to_vec();
        a.set_positions_velocities(&pos, &vel).unwrap();
        let mut reactions = Vec::new();
        for _ in 0..5 {
            a.step(
                1.0 / 60.0,
                Vector3::new(0.0, 0.0, -9.81),
                &floor,
                &mut reactions,
            )
            .unwrap();
        }
        let k = a.contact_memory.len();
        assert!(k > 0, "the block rests on the floor");
        assert!(a.contact_memory.iter().any(|m| !m.stick), "and slides");
        let state = a.get_state();
        let mut b = block_on_floor();
        b.set_state(&state).unwrap();
        assert_eq!(b.contact_memory, a.contact_memory);
        // version 1: the same without the memory (a restored solid starts from scratch)
        let mut v1 = state[..state.len() - 1 - 7 * k].to_vec();
        v1[0] = STATE_MAGIC_V1;
        let mut c = block_on_floor();
        c.set_state(&v1).unwrap();
        assert!(c.contact_memory.is_empty());
        assert_eq!(c.positions(), a.positions());
        // a version-1 tag with the memory appended is trailing data
        let mut bad = state.clone();
        bad[0] = STATE_MAGIC_V1;
        assert!(matches!(b.set_state(&bad), Err(FemError::InvalidState(_))));
        // setting positions by hand forgets the contacts
        b.set_positions_velocities(&pos, &vel).unwrap();
        assert!(b.contact_memory.is_empty());
    }

    #[test]
    fn a_remembered_frictionless_slide_sticks_once_the_surface_has_friction() {
        let floor = |friction| HalfSpace {
            origin: Vector3::zeros(),
            normal: Vector3::z(),
            friction,
            body: 3,
            velocity: Vector3::zeros(),
        };
        let g = Vector3::new(0.0, 0.0, -9.81);
        let mut s = block_on_floor();
        let mut reactions = Vec::new();
        for _ in 0..10 {
            s.step(1.0 / 60.0, g, &floor(0.0), &mut reactions).unwrap();
        }
        // resting on a frictionless floor: sliding contacts, most without a direction
        let mem = &s.contact_memory;
        assert!(!mem.is_empty() && mem.iter().all(|m| !m.stick));
        assert!(mem.iter().any(|m| m.slip_dir == Vector3::zeros()));
        // friction 0.5 and a push of 0.2 times the weight: static friction holds the block
        let push: Vec<Vector3<f64>> = s
            .masses()
            .iter()
            .map(|m| Vector3::new(0.2 * 9.81 * m, 0.0, 0.0))
            .collect();
        s.set_external_forces(&push).unwrap();
        let x0 = s.positions()[0];
        for _ in 0..10 {
            s.step(1.0 / 60.0, g, &floor(0.5), &mut reactions).unwrap();
        }
        let moved = (s.positions()[0] - x0).x.abs();
        println!("slide along the push: {moved:e} m (< 1e-6)");
        assert!(moved < 1e-6);
    }
}
