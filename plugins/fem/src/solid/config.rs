//! The solid's public settings and reports: solver settings ([`FemConfig`]), grasp parameters,
//! step statistics, embedded points and grasp reports.

use crate::error::FemError;
use nalgebra::Vector3;

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
    ///
    /// [`FemSolid::step`]: super::FemSolid::step
    pub max_speed: f64,
    /// Chord matrix warped by per-node rotations from its reference shape to the current shape
    /// (`R A R^T`, see [`crate::warp`]): a bending or swinging belt keeps the chord's contraction
    /// without refactoring as often. The solution is the same to the Newton tolerance; only the
    /// iteration and refactor counts change (`false`: the plain factored matrix).
    pub warped_chord: bool,
    /// Contact model. 0 (the default): contacts are constraints resolved by active-set rounds
    /// with exact Coulomb friction (no penetration beyond the solver tolerance). `s > 0`: every
    /// contact is a penalty energy of stiffness `s m / dt^2` per node (`m` the node's mass, so
    /// a node's weight presses it about `g dt^2 / s` into what it rests on: 0.03 mm at 1/60 s
    /// and `s` = 100) with lagged, smoothed Coulomb friction, all in one smooth minimisation:
    /// no active set that can fail to settle. For bodies that press along many contacts at
    /// once while moved hard (a rod rammed along a wall by a learning policy), where the rounds
    /// do not settle, leave nodes moving at metres per second and end in a blow-up.
    pub penalty_contacts: f64,
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
            penalty_contacts: 0.0,
        }
    }
}

impl FemConfig {
    /// Checks every field is finite and in range.
    pub fn validate(&self) -> Result<(), FemError> {
        let checks: [(&'static str, f64, bool, &'static str); 8] = [
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
            (
                "config.penalty_contacts",
                self.penalty_contacts,
                self.penalty_contacts >= 0.0,
                ">= 0 (0: active-set contacts; else the penalty stiffness in m / dt^2)",
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
    /// Nodes moved out of a collider after the solve, by more than the solve's tolerance,
    /// because the active-set rounds ran out with them inside (and not in the contact set): a
    /// correction the elastic solution did not see, which shows as a velocity kick.
    pub projected: usize,
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
