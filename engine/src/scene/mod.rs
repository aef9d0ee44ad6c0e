//! Scenes: parse (RON) -> validate -> compile ([`SceneModel`], immutable, shared through `Arc`)
//! -> spawn (per env).
//!
//! A scene can come from a `*.scene.ron` file ([`load_file`]), from a string ([`parse_str`]) or
//! be built in Rust as a [`SceneDesc`] value. Compilation resolves materials, validates every
//! number (NaN/inf, non-positive sizes and masses, unknown names, escaping asset paths), meshes the
//! shapes and lets plugin body kinds compile their own parameters. Errors carry file:line:col for
//! syntax and unknown fields, and `object.field = value: what is valid` for semantic errors.

mod compile;
mod desc;
mod error;
mod model;
mod select;
mod source;

pub use crate::registry::{BodyModel, ObjectModel};
pub use crate::settings::EpisodeLimit;
pub use compile::{compile, CompiledSceneSection, NamedFrames, SceneModel};
pub use desc::{
    BodyDesc, MaterialDesc, ObjectDesc, PassiveForceDesc, PhysicsDesc, PoseDesc, RewardDesc,
    SceneDesc, TermDesc,
};
pub use error::SceneError;
pub use model::{RigidKind, RigidModel, RigidShape};
pub use select::NodeSelect;
pub use source::{
    default_asset_roots, load_file, parse_str, plugin_params_error, ron_options, SceneSource,
};
