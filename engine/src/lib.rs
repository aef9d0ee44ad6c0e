//! # modesuite-engine
//!
//! The engine of modesuite: a Bevy-shaped application layer over `bevy_ecs` ([`SimApp`],
//! [`Plugin`]), the public schedules and sets every plugin extends ([`EnvStep`], [`PhysicsStep`],
//! [`Substep`]), one ECS `World` per environment and a parallel [`VecEnv`], scenes in RON
//! ([`scene`]: parse -> validate -> compile -> spawn), shape generators and tetrahedral meshing
//! ([`shapes`]), rigid physics with rapier and the deformable coupling API ([`rigid`],
//! [`coupling`]), snapshots and determinism hashes ([`state`]), state files ([`checkpoint`]),
//! and per-env RNGs ([`rng`]).
//!
//! ```no_run
//! use modesuite_engine::prelude::*;
//!
//! let text = r#"Scene(objects: [
//!     (name: "ground", shape: Plane(size: (10.0, 10.0)), body: Static),
//!     (name: "box", shape: Box(size: (0.2, 0.2, 0.2)), pose: (pos: (0.0, 0.0, 1.0)), body: Dynamic()),
//! ])"#;
//! let desc = modesuite_engine::scene::parse_str(text, "<example>").unwrap();
//! let mut app = SimApp::new();
//! app.add_plugins(RigidPlugin);
//! let model = app.compile_scene(&desc, &SceneSource::in_memory(".")).unwrap();
//! app.spawn_scene(model).unwrap();
//! let mut env = Env::new(app);
//! env.reset(Some(0));
//! for _ in 0..60 {
//!     env.step(&[]);
//! }
//! ```
#![warn(missing_docs)]

pub mod app;
pub mod bench;
pub mod checkpoint;
pub mod codec;
pub mod components;
pub mod contact;
pub mod coupling;
pub mod deformable;
pub mod dump;
pub mod dynamic;
pub mod env;
pub mod events;
pub mod fsio;
pub mod math;
pub mod registry;
pub mod rigid;
pub mod rng;
pub mod scene;
pub mod settings;
pub mod shapes;
pub mod side;
pub mod signals;
pub mod simd;
pub mod state;
pub mod surface;
pub mod terms;

pub use app::{
    EngineSystems, EnvStep, EnvSystems, Phase, PhysicsStep, PhysicsSystems, Plugin, PluginGroup,
    Plugins, SimApp, SimClock, SimErrors, SimSettings, Substep, SubstepSystems,
};
pub use dynamic::{DynamicPlugin, PluginLoadError};
pub use env::{Env, EnvInfo, Space, Spaces, StepOutcome, VecEnv, VecStep};
pub use rigid::{DeformableSystems, RigidContext, RigidPlugin, RigidSystems};
pub use scene::{SceneDesc, SceneError, SceneModel, SceneSource};

/// Runs `f`, turning a panic into `Err` with its message (the payload's text, or empty): for
/// third-party code that asserts on input it should have refused (rapier on inconsistent sets,
/// parry on degenerate meshes), so that the caller can report an error instead of unwinding.
/// The panic is not printed (see [`with_quiet_panics`]): the error reports it.
pub fn catch_panic<R>(f: impl FnOnce() -> R) -> Result<R, String> {
    with_quiet_panics(|| std::panic::catch_unwind(std::panic::AssertUnwindSafe(f))).map_err(|p| {
        p.downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_default()
    })
}

thread_local! {
    /// Depth of [`with_quiet_panics`] calls on this thread.
    static QUIET_PANICS: std::cell::Cell<u32> = const { std::cell::Cell::new(0) };
}

/// Runs `f` with the panic messages of this thread silenced: for code whose panics are caught
/// and reported as errors ([`catch_panic`], the fuzz campaigns), so that users see the error
/// and not a panic message before it. A panic hook installed once per process does this and
/// otherwise calls the previous hook; with `MODESUITE_LOUD_PANICS` (or `MODESUITE_FUZZ_LOUD`)
/// set, every panic is printed, to see where one happened.
pub fn with_quiet_panics<R>(f: impl FnOnce() -> R) -> R {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        let loud = ["MODESUITE_LOUD_PANICS", "MODESUITE_FUZZ_LOUD"]
            .iter()
            .any(|v| std::env::var_os(v).is_some());
        std::panic::set_hook(Box::new(move |info| {
            if loud || QUIET_PANICS.with(|q| q.get()) == 0 {
                previous(info);
            }
        }));
    });
    struct Depth;
    impl Drop for Depth {
        fn drop(&mut self) {
            QUIET_PANICS.with(|q| q.set(q.get() - 1));
        }
    }
    QUIET_PANICS.with(|q| q.set(q.get() + 1));
    let _depth = Depth;
    f()
}

/// Re-exports of the math and ECS crates, so plugins use the same versions.
pub mod deps {
    pub use bevy_ecs;
    pub use modesuite_plugin_abi as plugin_abi;
    pub use nalgebra;
    pub use parry3d;
    pub use rapier3d;
    pub use ron;
}

/// The engine's own plugins (rigid physics).
pub struct EnginePlugins;

impl PluginGroup for EnginePlugins {
    fn plugins(self) -> Vec<std::sync::Arc<dyn Plugin>> {
        vec![std::sync::Arc::new(RigidPlugin)]
    }
}

/// Everything a plugin or scene author usually needs.
pub mod prelude {
    pub use crate::app::{
        EngineSystems, EnvStep, EnvSystems, Phase, PhysicsStep, PhysicsSystems, Plugin,
        PluginGroup, SimApp, SimClock, SimErrors, SimSettings, Substep, SubstepSystems,
    };
    pub use crate::components::{DeformableNodes, JointState, Object, Pose, Velocity};
    pub use crate::coupling::{ContactQuery, PointContact, Reaction};
    pub use crate::env::{Env, EnvInfo, Space, Spaces, StepOutcome, VecEnv};
    pub use crate::rigid::{DeformableSystems, RigidContext, RigidPlugin, RigidSystems};
    pub use crate::scene::{SceneDesc, SceneError, SceneSource};
    pub use crate::shapes::{ShapeDesc, SurfaceMesh, VolumeMesh};
    pub use crate::EnginePlugins;
    pub use bevy_ecs::prelude::*;
}
