//! The robots plugin: robots in scene files, their per-env controllers and action modes.
//!
//! A scene names its robots in the `robots` section:
//! ```ron
//! extensions: {
//!     "robots": [
//!         (name: "robot", model: "franka", pose: (pos: (0, 0, 0), rpy: (0, 0, 0)),
//!          actions: (arm: EePoseDelta)),
//!     ],
//! }
//! ```
//! `model` is a registered robot (`franka`, `spot`, or one a plugin registers: a [`RobotSpec`]
//! payload) or the path of a robot description file (`*.robot.ron`, relative to the scene's
//! folder; see [`crate::description`]). Each env spawns
//! the robot as a rapier multibody, one entity per rapier body (`"robot/panda_link3"`, kind
//! `robot.link`, so `--dump-state` lists link poses and deformables can touch the links), and a
//! root entity (`"robot"`, kind `robot`) with the [`JointState`]. Per env, the [`Robots`]
//! resource holds every robot's controller state (targets, commands, gripper); it is part of the
//! env state, so resets and snapshots restore it.
//!
//! Systems: in `EnvSystems::ProcessActions` each robot reads its slice of the action (see
//! [`crate::actions`]) or follows its `script`; in `SubstepSystems::Predict` the walking
//! controllers plan and the joint controllers write motor targets and gravity compensation before every rapier substep; in
//! `PhysicsSystems::Writeback` the joint states are copied to the root entities.
//!
//! Files: the plugin here; `section` (the `robots` section: descriptions, scripts, compile),
//! `spawn` (a robot's entities and runtime), `runtime` (the per-env [`Robots`] state and
//! [`RobotObservation`]) and `systems` (actions, scripts and control each step).

mod model;
mod runtime;
mod section;
mod spawn;
mod systems;

use std::sync::Arc;

use bevy_ecs::prelude::*;

use modesuite_engine::components::JointState;
use modesuite_engine::coupling::Grippers;
use modesuite_engine::registry::RobotEntry;
use modesuite_engine::{
    EnvSystems, PhysicsSystems, Plugin, RigidSystems, SimApp, Substep, SubstepSystems,
};

use crate::description::BUILTIN;
use crate::models::RobotSpec;

pub use model::{
    BrokenRobot, CompiledRobot, RobotDesc, Script, ScriptBase, ScriptEe, ScriptGripper,
};
pub use runtime::{RobotFixed, RobotObservation, RobotRuntime, Robots};
pub use section::RobotsSection;
pub use systems::BASE_LIMITS;
use systems::{robot_actions, robot_control, robot_writeback};

/// Registers the robots built into the binary (`franka`, `spot`, each a [`RobotSpec`] from its
/// description file, by id), the `robots` scene section and the controller systems.
pub struct RobotsPlugin;

impl Plugin for RobotsPlugin {
    fn name(&self) -> &str {
        "modesuite.robots"
    }

    fn build(&self, app: &mut SimApp) {
        for (b, spec) in BUILTIN.iter().zip(RobotSpec::builtins()) {
            // A built-in file that does not load (the robots crate's tests parse them all) is
            // registered under its file name with the error, which a scene naming it reports.
            let (name, description, payload): (_, _, Arc<dyn std::any::Any + Send + Sync>) =
                match spec {
                    Ok(spec) => (spec.id.clone(), spec.description.clone(), Arc::new(spec)),
                    Err(e) => {
                        let name = b.file.rsplit('/').next().unwrap_or(b.file);
                        let name = name.trim_end_matches(".robot.ron").to_string();
                        let message = format!("built-in robot file does not load: {e}");
                        (name, message.clone(), Arc::new(BrokenRobot(message)))
                    }
                };
            app.register_robot(RobotEntry {
                name,
                description,
                payload,
            });
        }
        app.register_section(RobotsSection);
        app.register_stateful::<Robots>();
        app.register_stateful_component::<JointState>();
        app.world.init_resource::<Robots>();
        app.world.init_resource::<Grippers>();
        app.add_systems(
            modesuite_engine::EnvStep,
            robot_actions.in_set(EnvSystems::ProcessActions),
        );
        app.add_systems(Substep, robot_control.in_set(SubstepSystems::Predict));
        app.add_systems(
            modesuite_engine::PhysicsStep,
            robot_writeback
                .in_set(PhysicsSystems::Writeback)
                .after(RigidSystems::Writeback),
        );
    }
}
