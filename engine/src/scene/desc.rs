//! The scene schema: what a `*.scene.ron` file may say. Unknown fields are errors.
//!
//! ```ron
//! Scene(
//!     physics: (dt: 0.016666666666666666, substeps: 2, gravity: (0.0, 0.0, -9.81)),
//!     materials: { "rubber": (friction: 0.9, restitution: 0.1, density: 1100.0) },
//!     objects: [
//!         (name: "ground", shape: Plane(size: (10.0, 10.0)), body: Static),
//!         (name: "box", shape: Box(size: (0.2, 0.2, 0.2)), pose: (pos: (0.0, 0.0, 1.0)), body: Dynamic()),
//!         (name: "rod", shape: Cylinder(radius: 0.04, height: 0.82), body: Kind(kind: "fem.solid", params: (youngs_modulus: 1e6))),
//!     ],
//!     frames: { "target": (pos: (1.5, 1.5, 0.9)) },
//! )
//! ```

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Translation3, Vector3};
use ron::value::RawValue;
use serde::{Deserialize, Serialize};

use crate::shapes::ShapeDesc;

fn default_dt() -> f64 {
    1.0 / 60.0
}
fn one() -> u32 {
    1
}
fn default_gravity() -> [f64; 3] {
    [0.0, 0.0, -9.81]
}

/// A whole scene.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, rename = "Scene")]
pub struct SceneDesc {
    /// One line saying what the scene is for.
    #[serde(default)]
    pub description: Option<String>,
    /// Timing and gravity.
    #[serde(default)]
    pub physics: PhysicsDesc,
    /// Named materials; `"default"` exists unless overridden (friction 0.5, restitution 0, density 1000).
    #[serde(default)]
    pub materials: BTreeMap<String, MaterialDesc>,
    /// The objects, in spawn order; names are unique.
    #[serde(default)]
    pub objects: Vec<ObjectDesc>,
    /// Named frames and targets (world poses).
    #[serde(default)]
    pub frames: BTreeMap<String, PoseDesc>,
    /// Episode length in env steps (truncation); none = unlimited.
    #[serde(default)]
    pub episode_steps: Option<u64>,
    /// Scene-level sections owned by plugins (robots, cameras, tasks), kept as raw RON.
    #[serde(default)]
    pub extensions: BTreeMap<String, Box<RawValue>>,
    /// Reward terms: the step reward is the sum of `weight x value` (see `crate::terms`).
    #[serde(default)]
    pub rewards: Vec<RewardDesc>,
    /// Termination terms: a non-zero value ends the episode (terminated).
    #[serde(default)]
    pub terminations: Vec<TermDesc>,
    /// Observation terms: their values, in order, are the env's observation.
    #[serde(default)]
    pub observations: Vec<TermDesc>,
    /// Passive forces on deformable objects, applied every substep.
    #[serde(default)]
    pub passive_forces: Vec<PassiveForceDesc>,
}

fn unit_weight() -> f64 {
    1.0
}

/// A reward term of a scene: `(term: "acme.height", weight: 2.0, params: (object: "box"))`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RewardDesc {
    /// Registered term name (of kind Reward).
    pub term: String,
    /// Weight (default 1).
    #[serde(default = "unit_weight")]
    pub weight: f64,
    /// The term's parameters, raw RON (default `()`).
    #[serde(default)]
    pub params: Option<Box<RawValue>>,
}

/// An observation or termination term of a scene: `(term: "acme.below", params: (z: 0.1))`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TermDesc {
    /// Registered term name.
    pub term: String,
    /// The term's parameters, raw RON (default `()`).
    #[serde(default)]
    pub params: Option<Box<RawValue>>,
}

/// A passive force of a scene: `(force: "acme.wind", objects: ["tube"], params: (...))`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PassiveForceDesc {
    /// Registered passive force name.
    pub force: String,
    /// Names of the deformable objects it acts on.
    pub objects: Vec<String>,
    /// The force's parameters, raw RON (default `()`).
    #[serde(default)]
    pub params: Option<Box<RawValue>>,
}

/// Timing and gravity of the simulation.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PhysicsDesc {
    /// Physics step, s (default 1/60).
    #[serde(default = "default_dt")]
    pub dt: f64,
    /// Substeps per physics step (default 1).
    #[serde(default = "one")]
    pub substeps: u32,
    /// Physics steps per env step (default 1).
    #[serde(default = "one")]
    pub decimation: u32,
    /// Gravity, m/s^2, world frame (default (0, 0, -9.81)).
    #[serde(default = "default_gravity")]
    pub gravity: [f64; 3],
    /// Internal solver substeps of each rapier step (rapier's `num_solver_iterations`, default
    /// 4). Multibodies (robots) rebuild their mass matrix in each, so robot scenes that already
    /// take `substeps` use 1.
    #[serde(default = "four")]
    pub rigid_iterations: u32,
    /// Projected Gauss-Seidel sweeps per internal solver substep (rapier's
    /// `num_internal_pgs_iterations`, default 1). Unlike `rigid_iterations` they reuse the
    /// substep's multibody mass matrix, so they are the cheap way to converge friction: a
    /// standing Spot whose joints are held creeps 0.5 m in 3 s with 1 sweep at 1/240 s, 1 cm
    /// with 4 (robot tests, `spot_stands_on_its_legs`).
    #[serde(default = "one")]
    pub rigid_pgs_iterations: u32,
    /// Rapier's `friction_in_bias_pass` (default false, rapier's): friction is solved in the
    /// position-correcting pass of each substep too, not only in the velocity pass. Planted
    /// multibody feet creep less with it (a standing Spot that crept 1.5 cm/s in rapier's
    /// default did not; a trotting Spot's velocity loop needed 0.16 m/s of correction instead
    /// of its 0.25 bound: ARCHITECTURE.md, Robots). No shipped scene sets it yet.
    #[serde(default)]
    pub rigid_friction_in_bias_pass: bool,
    /// Deformable steps per physics step (default: `substeps`). A divisor of `substeps`:
    /// deformable bodies (FEM, cloth) then step every `substeps / deformable_substeps` rigid
    /// substeps, over that much time, while the rigid world (robots) keeps its finer substeps.
    /// A multiple of `substeps`: they step `deformable_substeps / substeps` times per rigid
    /// substep, grasps and attachments following the last rigid substep's motion subdivided,
    /// while the rigid world (robots) takes the coarser substeps.
    #[serde(default)]
    pub deformable_substeps: Option<u32>,
    /// Linear speed (m/s) of any rigid body, by its velocity or by its displacement over a rapier
    /// step, above which the rigid physics counts as blown up and the episode ends with an error
    /// naming the body (default 100). Rapier only flags
    /// non-finite states; a robot flung by diverging contact forces moves at finite, absurd
    /// speeds (a Spot link at 10^9 m after 500 steps) and would otherwise keep scoring.
    #[serde(default = "default_max_body_speed")]
    pub max_body_speed: f64,
}

fn default_max_body_speed() -> f64 {
    crate::app::DEFAULT_MAX_BODY_SPEED
}

fn four() -> u32 {
    4
}

impl Default for PhysicsDesc {
    fn default() -> Self {
        Self {
            dt: default_dt(),
            substeps: 1,
            decimation: 1,
            gravity: default_gravity(),
            rigid_iterations: 4,
            rigid_pgs_iterations: 1,
            rigid_friction_in_bias_pass: false,
            deformable_substeps: None,
            max_body_speed: default_max_body_speed(),
        }
    }
}

fn half() -> f64 {
    0.5
}
fn water() -> f64 {
    1000.0
}

/// Surface and bulk properties of a rigid object.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MaterialDesc {
    /// Coulomb friction coefficient (>= 0; default 0.5).
    #[serde(default = "half")]
    pub friction: f64,
    /// Restitution in [0, 1] (default 0).
    #[serde(default)]
    pub restitution: f64,
    /// Density, kg/m^3 (> 0; default 1000).
    #[serde(default = "water")]
    pub density: f64,
    /// Contact thickness of deformable surfaces made of it, m (in [0, 0.05]; default 0): other
    /// deformables touch the surface this far out of its triangles (both sides of a cloth).
    #[serde(default)]
    pub contact_thickness: f64,
}

impl Default for MaterialDesc {
    fn default() -> Self {
        Self {
            friction: 0.5,
            restitution: 0.0,
            density: 1000.0,
            contact_thickness: 0.0,
        }
    }
}

/// A pose: position (m) and roll-pitch-yaw (rad, extrinsic x then y then z).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct PoseDesc {
    /// Position, m.
    #[serde(default)]
    pub pos: [f64; 3],
    /// Roll, pitch, yaw, rad.
    #[serde(default)]
    pub rpy: [f64; 3],
}

impl PoseDesc {
    /// As an isometry (`world_from_body`).
    pub fn isometry(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(self.pos[0], self.pos[1], self.pos[2]),
            crate::math::rpy(self.rpy[0], self.rpy[1], self.rpy[2]),
        )
    }
}

/// One object of the scene.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectDesc {
    /// Unique name (what `--dump-state`, tasks and observations refer to).
    pub name: String,
    /// Geometry.
    pub shape: ShapeDesc,
    /// Initial pose (default: origin).
    #[serde(default)]
    pub pose: PoseDesc,
    /// How the object moves.
    pub body: BodyDesc,
    /// Material name (default `"default"`).
    #[serde(default)]
    pub material: Option<String>,
    /// Display colour, linear RGB in [0, 1] (renderer).
    #[serde(default)]
    pub color: Option<[f32; 3]>,
    /// Whether a deformable body touches other deformables (default true); rigid colliders
    /// always collide.
    #[serde(default = "yes")]
    pub collide: bool,
    /// Deformable bodies sharing a collision group do not touch each other (default: none).
    #[serde(default)]
    pub collision_group: Option<String>,
}

fn yes() -> bool {
    true
}

/// How an object moves.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum BodyDesc {
    /// Never moves (ground, tables, walls). Any shape; meshes become triangle meshes.
    Static,
    /// Moved by the simulation. Meshes become a convex decomposition.
    Dynamic {
        /// Mass, kg; default from the material's density and the shape's volume.
        #[serde(default)]
        mass: Option<f64>,
        /// Initial linear velocity, m/s.
        #[serde(default)]
        linear_velocity: [f64; 3],
        /// Initial angular velocity, rad/s.
        #[serde(default)]
        angular_velocity: [f64; 3],
    },
    /// Moved only by the program (pose targets), pushes dynamic bodies.
    Kinematic,
    /// A body kind provided by a plugin, e.g. `Kind(kind: "fem.solid", params: (...))`.
    Kind {
        /// Registered body kind name.
        kind: String,
        /// Parameters owned by that plugin, kept as raw RON.
        params: Box<RawValue>,
    },
}

/// Gravity vector of a physics description.
pub(crate) fn gravity_of(p: &PhysicsDesc) -> Vector3<f64> {
    Vector3::new(p.gravity[0], p.gravity[1], p.gravity[2])
}
