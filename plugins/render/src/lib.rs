//! # modesuite-render
//!
//! Rendering for modesuite: headless RGB, depth and segmentation cameras with wgpu, episode
//! videos (GIF, MP4 through ffmpeg, PNG frames) and the interactive viewer with keyboard
//! teleoperation.
//!
//! ## Architecture
//!
//! - [`RenderDevice`]: adapter, device, queue and pipelines, created once per process
//!   ([`RenderDevice::shared`]) and shared by every env through an `Arc`. It runs on a GPU when
//!   there is one and on Mesa's software drivers otherwise (Vulkan lavapipe, GL llvmpipe); with
//!   no adapter at all it fails with [`RenderError::NoAdapter`], naming the packages to install.
//! - [`geometry`]: per frame, the world's colliders (scene objects and robot links alike),
//!   deformable surfaces (FEM boundary faces through the edge nodes, cloth triangles; normals
//!   recomputed each frame, both sides lit) and translucent target markers become one list of
//!   world-space triangles.
//! - [`EnvRenderer`]: one env's cameras: extraction, GPU targets, one shadow pass from the
//!   directional light, and per camera an opaque pass writing colour and (linear depth bits,
//!   segmentation id), an optional marker pass, and a readback into flat buffers
//!   ([`CameraFrame`]). [`render_batch`] renders many envs with one submission.
//! - [`RenderPlugin`]: the `camera.rgbd` sensor in the registry, and a system in
//!   `EnvSystems::Sense` that renders the cameras named in [`CameraRequests`] into
//!   [`CameraImages`], only when something asked. [`prepare`] attaches a renderer to an app
//!   whose scene is spawned. Rendering only reads the world: physics is unaffected.
//! - [`video`]: GIF (Rust encoder), MP4 (ffmpeg subprocess) and PNG frame writers.
//! - [`teleop`]: the 14 discrete teleoperation actions, their key bindings, the action resource
//!   robots consume, and episode recordings (seed + actions).
//! - `viewer` (feature `viewer`, default on): a winit window with an orbit camera.
//!
//! Cameras are declared in a scene's `extensions: {"render": (cameras: [...])}` section; see
//! [`config`].

#![warn(missing_docs)]

pub mod config;
pub mod geometry;
pub mod gpu;
pub mod hud;
pub mod renderer;
pub mod teleop;
pub mod video;
#[cfg(feature = "viewer")]
pub mod viewer;

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use bevy_ecs::prelude::*;
use modesuite_engine::registry::SensorEntry;
use modesuite_engine::scene::SceneError;
use modesuite_engine::{EnvStep, EnvSystems, Plugin, SimApp, SimErrors};

pub use config::{CameraDesc, Intrinsics, LightDesc, RenderConfig};
pub use gpu::{CameraFrame, RenderDevice};
pub use renderer::{object_pose, render_batch, EnvRenderer, Orbit};

/// Errors of the renderer.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// No usable graphics adapter (the message names the packages that provide one).
    #[error("{0}")]
    NoAdapter(String),
    /// The device failed (creation, submission, readback).
    #[error("graphics device: {0}")]
    Device(String),
    /// The scene's render section is invalid.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// A camera name that the scene does not declare.
    #[error("camera {name:?}: not declared in the scene's render section; cameras: [{}]", available.join(", "))]
    UnknownCamera {
        /// The name asked for.
        name: String,
        /// The scene's cameras.
        available: Vec<String>,
    },
    /// A camera attached to an object that the world does not have.
    #[error("camera {camera:?}: attach = {object:?}: no object of that name in the world")]
    UnknownObject {
        /// The camera.
        camera: String,
        /// The missing object.
        object: String,
    },
    /// Writing an image or a video failed.
    #[error("{0}")]
    Output(String),
}

/// Sets of the render plugin.
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub enum RenderSystems {
    /// Renders the requested cameras (in `EnvSystems::Sense`).
    Capture,
}

/// The registry name of the camera sensor.
pub const CAMERA_SENSOR: &str = "camera.rgbd";

/// What the `camera.rgbd` registry entry carries: the channels and their layouts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CameraSensorInfo {
    /// Channel name and per-pixel layout.
    pub channels: Vec<(&'static str, &'static str)>,
}

/// Names of the cameras to render in this env's `Sense` pass (observation terms and recorders
/// add theirs; nothing is rendered while the set is empty).
#[derive(Resource, Debug, Clone, Default, PartialEq, Eq)]
pub struct CameraRequests(pub BTreeSet<String>);

/// The latest frame of each requested camera (written in `Sense`).
#[derive(Resource, Debug, Clone, Default)]
pub struct CameraImages(pub BTreeMap<String, CameraFrame>);

/// The env's renderer (inserted by [`prepare`]; not part of the env state).
#[derive(Resource)]
pub struct RenderState(pub EnvRenderer);

/// Adds the `camera.rgbd` sensor and the on-demand capture system.
pub struct RenderPlugin;

impl Plugin for RenderPlugin {
    fn name(&self) -> &str {
        "modesuite.render"
    }

    fn build(&self, app: &mut SimApp) {
        app.register_sensor(SensorEntry {
            name: CAMERA_SENSOR.to_string(),
            description: "RGB (u8), depth (f32 m) and segmentation (u32 object id) cameras, wgpu; declared in extensions[\"render\"]".to_string(),
            payload: Arc::new(CameraSensorInfo {
                channels: vec![
                    ("rgb", "u8 x 3, sRGB"),
                    ("depth", "f32, metres along the optical axis, 0 = no hit"),
                    ("segmentation", "u32, object index + 1, 0 = background"),
                ],
            }),
        });
        app.register_section(RenderSection);
        app.insert_resource(CameraRequests::default());
        app.insert_resource(CameraImages::default());
        app.configure_sets(EnvStep, RenderSystems::Capture.in_set(EnvSystems::Sense));
        app.add_systems(EnvStep, capture_requested.in_set(RenderSystems::Capture));
    }
}

/// The `render` scene section: validated with the rest of the scene (unknown fields, bad
/// intrinsics, unknown attach targets are scene errors); the renderer itself is attached after
/// spawning by [`prepare`], which reads the same section.
pub struct RenderSection;

impl modesuite_engine::registry::SceneSection for RenderSection {
    fn name(&self) -> &str {
        config::EXTENSION_KEY
    }

    fn description(&self) -> &str {
        "cameras and render settings: (cameras: [...], shadow_map, ...)"
    }

    fn compile(
        &self,
        ctx: &modesuite_engine::registry::SectionCompileContext,
    ) -> Result<modesuite_engine::registry::CompiledSection, SceneError> {
        let cfg: RenderConfig = ctx.parse()?;
        cfg.validate()?;
        cfg.check_attach(&ctx.path(), ctx.objects)?;
        Ok(Arc::new(cfg))
    }

    fn spawn(
        &self,
        _app: &mut SimApp,
        _compiled: &modesuite_engine::registry::CompiledSection,
    ) -> Result<(), SceneError> {
        Ok(())
    }
}

/// Attaches a renderer (shared device) to an app whose scene is spawned; validates the scene's
/// render section.
pub fn prepare(app: &mut SimApp) -> Result<(), RenderError> {
    let model = app.scene().cloned().ok_or_else(|| {
        RenderError::Device(
            "prepare: spawn a scene into the app before attaching a renderer".into(),
        )
    })?;
    let renderer = EnvRenderer::for_scene(model)?;
    for c in &renderer.config().cameras {
        if let Some(a) = &c.attach {
            if object_pose(&app.world, a).is_none() {
                return Err(RenderError::UnknownObject {
                    camera: c.name.clone(),
                    object: a.clone(),
                });
            }
        }
    }
    app.insert_resource(RenderState(renderer));
    Ok(())
}

fn capture_requested(world: &mut World) {
    let names: Vec<String> = match world.get_resource::<CameraRequests>() {
        Some(r) if !r.0.is_empty() => r.0.iter().cloned().collect(),
        _ => return,
    };
    let Some(mut state) = world.remove_resource::<RenderState>() else {
        world.resource_mut::<SimErrors>().raise(
            "cameras were requested but no renderer is attached (call modesuite_render::prepare after spawning the scene)",
        );
        return;
    };
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let result = state.0.render(world, &refs);
    world.insert_resource(state);
    match result {
        Ok(frames) => {
            let mut images = world.resource_mut::<CameraImages>();
            for (n, f) in names.into_iter().zip(frames) {
                images.0.insert(n, f);
            }
        }
        Err(e) => world
            .resource_mut::<SimErrors>()
            .raise(format!("render: {e}")),
    }
}
