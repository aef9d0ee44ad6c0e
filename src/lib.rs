//! # modesuite
//!
//! A simulation framework and benchmark for mobile manipulation of deformable objects
//! (MoDeSuite re-implemented in Rust). This umbrella crate re-exports the workspace crates and
//! provides [`DefaultPlugins`] and the `modesuite` command-line tool.
//!
//! See `ARCHITECTURE.md` for the crate map and the schedule, and the README for the CLI.
#![warn(missing_docs)]

pub use modesuite_engine as engine;
pub use modesuite_engine::prelude;
pub use modesuite_fem as fem;
pub use modesuite_learn as learn;
pub use modesuite_pbd as pbd;
pub use modesuite_render as render;
pub use modesuite_robots as robots;
pub use modesuite_tasks as tasks;

pub mod bench_contact;
pub mod bench_learn;
pub mod benches;
pub mod cli;
pub mod episode;
pub mod fuzz;
pub mod gym;
pub mod inputs;
pub mod learning;
pub mod make;
pub mod plot;
pub mod retrieval;

use std::sync::Arc;

use modesuite_engine::{Plugin, PluginGroup};

/// Every plugin of the default build, in build order (what the CLI uses).
pub struct DefaultPlugins;

impl PluginGroup for DefaultPlugins {
    fn plugins(self) -> Vec<Arc<dyn Plugin>> {
        let mut p = modesuite_engine::EnginePlugins.plugins();
        p.push(Arc::new(modesuite_fem::FemPlugin));
        p.push(Arc::new(modesuite_pbd::PbdPlugin));
        p.push(Arc::new(modesuite_robots::RobotsPlugin));
        p.push(Arc::new(modesuite_tasks::TasksPlugin));
        p.push(Arc::new(modesuite_render::RenderPlugin));
        p
    }
}

/// The task `modesuite` without arguments runs (its scene is embedded in the binary), with the
/// scripted expert and a video.
pub const DEFAULT_TASK: &str = "MoDe-Franka-Place-v0";
/// Where the default run writes its video.
pub const DEFAULT_VIDEO: &str = "out/MoDe-Franka-Place-v0.gif";

/// A small embedded example scene (a box dropped on the ground) used by tests and examples.
pub const DEFAULT_SCENE: &str = include_str!("../scenes/examples/drop.scene.ron");
/// The file name the embedded default scene is reported under.
pub const DEFAULT_SCENE_NAME: &str = "scenes/examples/drop.scene.ron";
