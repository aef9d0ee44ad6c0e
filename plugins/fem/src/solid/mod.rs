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
//!
//! # Files
//!
//! The types and the solid's fields are here; its methods are split by responsibility:
//! `access` (construction, accessors, derived quantities), `attach` (world constraints, rigid
//! frames, attachments, grasps), `active` (the active constraint set), `factor` (the factored
//! system matrix), `newton` (the incremental potential and the Newton solve), `chord` (the
//! chord solver), `step` (the time step and the static solves) and `state` (snapshots);
//! `config` holds the public settings and reports.
//!
//! [`ContactQuery`]: crate::coupling::ContactQuery

// Numeric kernels below index several parallel node arrays with one loop variable.
#![allow(clippy::needless_range_loop)]

mod access;
mod active;
mod attach;
mod chord;
mod config;
mod factor;
mod newton;
mod penalty;
mod state;
mod step;
#[cfg(test)]
mod tests;

use crate::coupling::PointContact;
use crate::model::SolidModel;
use crate::precond::{ContactFactor, Entry};
use crate::warp::Warp;
use nalgebra::{Isometry3, Matrix3, Vector3};
use std::sync::Arc;

pub use config::{FemConfig, GraspInfo, GraspParams, PointEmbedding, StepStats};

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

/// A contact of [`FemConfig::penalty_contacts`]: the node's energy in the incremental potential
/// is `k/2 min(0, gap)^2` for `gap = (x - point) . normal`, plus the smoothed Coulomb friction
/// potential `mu_lambda f0(|u_t|)` of its tangential displacement relative to the collider over
/// the step, `u_t = T (x - x_prev - v_c dt)`, with the normal force `lambda` lagged (fixed for
/// the solve, from the last step's contact or the predicted penetration) and
/// `f0(y) = y^2/eps - y^3/(3 eps^2) + eps/3` below `eps` (sticking region), `y` above
/// (Li et al. 2020, "Incremental Potential Contact", sec. 5).
#[derive(Clone, Copy, Debug)]
struct PenaltyContact {
    node: u32,
    point: Vector3<f64>,
    normal: Vector3<f64>,
    /// Penalty stiffness, N/m.
    stiffness: f64,
    /// Friction coefficient times the lagged normal force, N.
    mu_lambda: f64,
    /// Where the collider's surface point that started under the node is at the step's end,
    /// less the node's start position: `u_t` is the tangential part of `x - x_prev - shift`.
    shift: Vector3<f64>,
    /// Tangential displacement below which friction is in its sticking (smoothed) region, m.
    eps: f64,
}

impl PenaltyContact {
    fn gap(&self, x: &Vector3<f64>) -> f64 {
        (x - self.point).dot(&self.normal)
    }

    /// Tangential displacement over the step relative to the collider.
    fn slip(&self, x: &Vector3<f64>, xprev: &Vector3<f64>) -> Vector3<f64> {
        let u = x - xprev - self.shift;
        u - self.normal * u.dot(&self.normal)
    }

    /// Energy of the contact at `x`.
    fn energy(&self, x: &Vector3<f64>, xprev: &Vector3<f64>) -> f64 {
        let g = self.gap(x).min(0.0);
        let y = self.slip(x, xprev).norm();
        let f0 = if y < self.eps {
            y * y / self.eps - y * y * y / (3.0 * self.eps * self.eps) + self.eps / 3.0
        } else {
            y
        };
        0.5 * self.stiffness * g * g + self.mu_lambda * f0
    }

    /// `f1(y) / y` of the friction potential (its gradient is `mu_lambda f1(y)/y u_t`).
    fn friction_factor(&self, y: f64) -> f64 {
        if y < self.eps {
            2.0 / self.eps - y / (self.eps * self.eps)
        } else {
            1.0 / y
        }
    }

    /// Gradient of the contact's energy at `x` (normal penalty and friction).
    fn gradient(&self, x: &Vector3<f64>, xprev: &Vector3<f64>) -> Vector3<f64> {
        let g = self.gap(x).min(0.0);
        let u = self.slip(x, xprev);
        self.normal * (self.stiffness * g) + u * (self.mu_lambda * self.friction_factor(u.norm()))
    }

    /// The stiffnesses of the energy's Hessian at `x`: along the normal the penalty's `k` while
    /// penetrating (else 0), in the tangent plane the friction's `mu_lambda f1(y)/y`.
    fn stiffnesses(&self, x: &Vector3<f64>, xprev: &Vector3<f64>) -> (f64, f64) {
        let normal = if self.gap(x) < 0.0 {
            self.stiffness
        } else {
            0.0
        };
        let tangent = self.mu_lambda * self.friction_factor(self.slip(x, xprev).norm());
        (normal, tangent)
    }

    /// A positive semi-definite approximation of the energy's Hessian at `x`:
    /// `k_t (I - n n^T) + k_n n n^T` with the [`stiffnesses`](Self::stiffnesses).
    fn hessian(&self, x: &Vector3<f64>, xprev: &Vector3<f64>) -> Matrix3<f64> {
        let nnt = self.normal * self.normal.transpose();
        let (kn, kt) = self.stiffnesses(x, xprev);
        let mut h = (Matrix3::identity() - nnt) * kt;
        if kn > 0.0 {
            h += nnt * kn;
        }
        h
    }
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

/// A contact in the factored matrix: node, direction (rounded, see [`quantised_normal`]), all
/// three directions (a sticking contact), stiffness (`None`: an active-set contact's stiff
/// penalty, `1e6` times the node's diagonal block).
pub(super) type FactorContact = (u32, Vector3<f64>, bool, Option<f64>);

/// A contact normal rounded to 1e-2 per component, so that a resting contact set reuses the
/// factor.
pub(super) fn quantised_normal(n: &Vector3<f64>) -> Vector3<f64> {
    (n * 100.0).map(|x| x.round() / 100.0)
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

/// Active-set rounds after the last full one (which releases no contact and changes no
/// friction) that only activate the candidates still penetrating, so that the step ends with
/// the elastic solution of its contact set. Before, those nodes were projected out of the
/// collider one by one after the solve: a 1.9x-stretched belt swinging into a post at 2 m/s
/// ran out of rounds (contacts activated and released in turn) with four nodes 1.4-2 cm deep,
/// whose projection left the belt at 47 m/s and blew it up on the next step (PPO Spot Drag,
/// seed 1,000,000). Activation only is monotone: each such round adds contacts. A contact
/// joining from the last full round on takes its normal only (no round is left to let it slide).
const ACTIVATION_ROUNDS: usize = 8;

/// How often a step whose solve fails may be halved (at most `2^MAX_STEP_HALVINGS` parts).
const MAX_STEP_HALVINGS: u32 = 3;

const STATE_MAGIC_V1: f64 = 7.1e7 + 1.0; // format tag of get_state, version 1 (no contact memory)
const STATE_MAGIC_V2: f64 = 7.1e7 + 2.0; // format tag of get_state, version 2 (no factor anchor)
const STATE_MAGIC: f64 = 7.1e7 + 3.0; // format tag of get_state (version 3)

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
    /// Impulses other bodies' contacts left for the next step, N s per node (applied as a force
    /// over that step, then cleared): empty between steps, so not part of the state.
    impulse: Vec<Vector3<f64>>,
    /// Kinetic friction forces of sliding contacts during the current step (N); zero outside steps.
    fric: Vec<Vector3<f64>>,
    steps: u64,
    world: Vec<WorldConstraint>,
    attachments: Vec<Attachment>,
    grasps: Vec<Grasp>,
    poses: Vec<(u32, Isometry3<f64>)>,
    /// The bodies' poses at the start of the next step: where the last step left them (or where
    /// they were when attached or grasping). A split step moves attachments and grasps from
    /// these to `poses` in proportion (see `step_split`). Equal to `poses` between steps, so a
    /// restored state sets it from them.
    poses_start: Vec<(u32, Isometry3<f64>)>,
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
    /// The step's contacts as penalty energies (only with `FemConfig::penalty_contacts`; empty
    /// otherwise and outside a step's solve).
    penalties: Vec<PenaltyContact>,
    /// The penalty contacts' Hessian entries the factored matrix holds for this step (see
    /// `penalty_blocks`; empty with them and outside a step's solve).
    penalty_factor: Vec<FactorContact>,
    /// Outward surface normals at the nodes at the start of the step.
    normals: Vec<Vector3<f64>>,
    con_forces: Vec<(u32, Vector3<f64>)>,
    /// Active contacts at the end of the last step, by node (part of the state).
    contact_memory: Vec<ContactMemory>,
    /// The contact penalties the factor's base holds (see [`crate::precond`]): later contact
    /// sets correct that factor by their difference. Part of the state, so that a restored
    /// solid factors and solves as the uninterrupted one.
    factor_anchor: Vec<Entry>,
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
