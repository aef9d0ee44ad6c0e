//! Shared test set-up.
#![allow(dead_code)]

use modesuite_engine::deps::nalgebra::Isometry3;
use modesuite_engine::RigidContext;
use modesuite_robots::{AssetPaths, Robot, RobotSpec, UrdfModel};

/// Physics substep of a robot alone: 1/60 s split into its `RobotSpec::substeps` (1/60 s for
/// both robots), as its robot-only scenes and `modesuite bench robots` run it.
pub fn dt(id: &str) -> f64 {
    1.0 / (60.0 * f64::from(spec(id).substeps))
}

/// A built-in robot (`franka`, `spot`).
pub fn spec(id: &str) -> RobotSpec {
    RobotSpec::builtin(id).expect("built-in robot")
}

pub fn assets() -> AssetPaths {
    AssetPaths::workspace_default()
}

pub fn model(id: &str) -> (RobotSpec, UrdfModel) {
    let spec = spec(id);
    let model = spec.load().expect("model loads");
    (spec, model)
}

/// A rigid context with the rapier settings of robot scenes: one solver substep per step
/// (`physics.rigid_iterations: 1`) and `pgs` Gauss-Seidel sweeps per substep
/// (`physics.rigid_pgs_iterations`).
pub fn rapier_context(pgs: u32) -> RigidContext {
    let mut ctx = RigidContext::new();
    ctx.params.num_solver_iterations = 1;
    ctx.params.num_internal_pgs_iterations = pgs as usize;
    ctx
}

/// [`rapier_context`] with the robot's own sweeps (`RobotSpec::pgs_iterations`).
pub fn scene_context(id: &str) -> RigidContext {
    rapier_context(spec(id).pgs_iterations)
}

pub fn spawn(id: &str) -> (RigidContext, RobotSpec, Robot) {
    let (spec, model) = model(id);
    let mut ctx = scene_context(id);
    let robot = spec
        .spawn(&mut ctx, &model, Isometry3::identity())
        .expect("robot spawns");
    (ctx, spec, robot)
}
