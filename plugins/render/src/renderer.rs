//! [`EnvRenderer`]: renders the cameras of one env's world (extraction + GPU targets), alone or
//! batched with other envs into one submission.

use std::sync::Arc;

use bevy_ecs::prelude::*;
use modesuite_engine::components::{Object, Pose};
use modesuite_engine::math::pose_from_rapier;
use modesuite_engine::rigid::RigidRef;
use modesuite_engine::scene::SceneModel;
use modesuite_engine::RigidContext;
use nalgebra::{Isometry3, Vector3};

use crate::config::{CameraDesc, RenderConfig};
use crate::geometry::{FrameGeometry, Markers, SceneExtractor};
use crate::gpu::{CameraFrame, RenderDevice, Targets, ViewSetup};
use crate::RenderError;

/// Renders one env: the scene's cameras and any camera given by the caller.
pub struct EnvRenderer {
    config: RenderConfig,
    extractor: SceneExtractor,
    targets: Targets,
    geometry: FrameGeometry,
}

/// The current world pose of the object named `name` (rigid body pose, else its `Pose`).
pub fn object_pose(world: &World, name: &str) -> Option<Isometry3<f64>> {
    let mut q = world.try_query::<(Entity, &Object)>()?;
    let entity = q
        .iter(world)
        .find(|(_, o)| o.name == name)
        .map(|(e, _)| e)?;
    if let (Some(r), Some(ctx)) = (
        world.get::<RigidRef>(entity),
        world.get_resource::<RigidContext>(),
    ) {
        if let Some(b) = ctx.bodies.get(r.0) {
            return Some(pose_from_rapier(b.position()));
        }
    }
    world.get::<Pose>(entity).map(|p| p.0)
}

impl EnvRenderer {
    /// A renderer for worlds spawned from `model`, with the scene's render section.
    pub fn new(device: Arc<RenderDevice>, model: Arc<SceneModel>, config: RenderConfig) -> Self {
        Self {
            targets: Targets::new(device, &config.light, config.background),
            extractor: SceneExtractor::new(model, config.marker_radius),
            config,
            geometry: FrameGeometry::default(),
        }
    }

    /// A renderer with the scene's own render section and the shared device.
    pub fn for_scene(model: Arc<SceneModel>) -> Result<Self, RenderError> {
        let config = RenderConfig::from_scene(&model)?;
        Ok(Self::new(RenderDevice::shared()?, model, config))
    }

    /// The render section in use.
    pub fn config(&self) -> &RenderConfig {
        &self.config
    }

    /// The device.
    pub fn device(&self) -> &Arc<RenderDevice> {
        self.targets.device()
    }

    /// Triangles drawn in the last frame (opaque and markers).
    pub fn last_triangles(&self) -> usize {
        self.geometry.indices.len() / 3
    }

    /// The scene camera of this name, or an error listing the cameras.
    pub fn scene_camera(&self, name: &str) -> Result<&CameraDesc, RenderError> {
        self.config
            .camera(name)
            .ok_or_else(|| RenderError::UnknownCamera {
                name: name.to_string(),
                available: self.config.cameras.iter().map(|c| c.name.clone()).collect(),
            })
    }

    /// A camera framing the scene's current geometry from an orbit (azimuth and elevation in
    /// degrees), at `width x height` with a 50 degree vertical field of view, markers on.
    pub fn orbit_camera(
        &mut self,
        world: &World,
        name: &str,
        width: u32,
        height: u32,
        orbit: Orbit,
    ) -> CameraDesc {
        let (lo, hi) = self.scene_bounds(world);
        let mut cam = orbit.camera(name, width, height, &lo, &hi);
        cam.markers = true;
        cam
    }

    /// The bounding box of the world's current finite geometry (everything but ground planes;
    /// a unit box at the origin when there is none).
    pub fn scene_bounds(&mut self, world: &World) -> (Vector3<f64>, Vector3<f64>) {
        self.extractor
            .extract(world, Markers::default(), &mut self.geometry);
        self.geometry
            .focus
            .unwrap_or((Vector3::repeat(-0.5), Vector3::repeat(0.5)))
    }

    /// Where a camera is this frame.
    fn view_of(&self, world: &World, cam: &CameraDesc) -> Result<ViewSetup, RenderError> {
        let parent = match &cam.attach {
            None => Isometry3::identity(),
            Some(name) => object_pose(world, name).ok_or_else(|| RenderError::UnknownObject {
                camera: cam.name.clone(),
                object: name.clone(),
            })?,
        };
        Ok(ViewSetup {
            world_from_camera: parent * cam.parent_from_camera(),
            pinhole: cam.pinhole(),
            width: cam.width,
            height: cam.height,
            near: cam.near,
            far: cam.far,
            markers: cam.markers,
            overlays: cam.overlays,
        })
    }

    fn encode(
        &mut self,
        world: &World,
        cams: &[&CameraDesc],
        encoder: &mut wgpu::CommandEncoder,
        readback: bool,
    ) -> Result<Vec<usize>, RenderError> {
        let mut views = Vec::with_capacity(cams.len());
        for cam in cams {
            let view = self.view_of(world, cam)?;
            let slot = self.targets.slot(&cam.name, cam.width, cam.height);
            views.push((slot, view));
        }
        let markers = Markers {
            targets: cams.iter().any(|c| c.markers),
            overlays: cams.iter().any(|c| c.overlays),
        };
        self.extractor.extract(world, markers, &mut self.geometry);
        self.targets
            .encode(encoder, &self.geometry, &views, readback);
        Ok(views.into_iter().map(|(s, _)| s).collect())
    }

    /// Renders the named scene cameras of `world` and reads them back.
    pub fn render(
        &mut self,
        world: &World,
        names: &[&str],
    ) -> Result<Vec<CameraFrame>, RenderError> {
        let cams: Vec<CameraDesc> = names
            .iter()
            .map(|n| self.scene_camera(n).cloned())
            .collect::<Result<_, _>>()?;
        self.render_cameras(world, &cams)
    }

    /// Renders the given cameras (scene cameras or the caller's own) and reads them back.
    pub fn render_cameras(
        &mut self,
        world: &World,
        cams: &[CameraDesc],
    ) -> Result<Vec<CameraFrame>, RenderError> {
        let mut one = [(self, world)];
        let mut out = render_batch(&mut one, cams)?;
        Ok(out.pop().unwrap_or_default())
    }

    /// Renders one camera without reading it back; returns the colour texture (the viewer
    /// draws it to its window).
    pub(crate) fn render_to_texture(
        &mut self,
        world: &World,
        cam: &CameraDesc,
    ) -> Result<&wgpu::Texture, RenderError> {
        let dev = self.targets.device().clone();
        let mut encoder = dev
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("view"),
            });
        let slots = self.encode(world, &[cam], &mut encoder, false)?;
        dev.queue.submit([encoder.finish()]);
        Ok(self.targets.color_texture(slots[0]))
    }
}

/// Renders the same cameras in several envs with one submission and one wait (the envs must
/// share a device). Returns, per env, one frame per camera.
pub fn render_batch(
    envs: &mut [(&mut EnvRenderer, &World)],
    cams: &[CameraDesc],
) -> Result<Vec<Vec<CameraFrame>>, RenderError> {
    let Some(dev) = envs.first().map(|(r, _)| r.targets.device().clone()) else {
        return Ok(Vec::new());
    };
    if envs
        .iter()
        .any(|(r, _)| !Arc::ptr_eq(r.targets.device(), &dev))
    {
        return Err(RenderError::Device(
            "render_batch: every env must use the same RenderDevice".into(),
        ));
    }
    let mut encoder = dev
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("cameras"),
        });
    let cam_refs: Vec<&CameraDesc> = cams.iter().collect();
    let mut slots = Vec::with_capacity(envs.len());
    for (r, world) in envs.iter_mut() {
        slots.push(r.encode(world, &cam_refs, &mut encoder, true)?);
    }
    dev.queue.submit([encoder.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    let mut pending = 0;
    for ((r, _), s) in envs.iter().zip(&slots) {
        for &slot in s {
            r.targets.map(slot, tx.clone());
            pending += 1;
        }
    }
    dev.device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| RenderError::Device(format!("waiting for the frame: {e}")))?;
    for _ in 0..pending {
        rx.recv()
            .map_err(|e| RenderError::Device(format!("readback: {e}")))?
            .map_err(|e| RenderError::Device(format!("readback: {e}")))?;
    }
    envs.iter()
        .zip(&slots)
        .map(|((r, _), s)| s.iter().map(|&slot| r.targets.read(slot)).collect())
        .collect()
}

/// An orbit around the scene: angles in degrees and a distance factor (1 = just framed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orbit {
    /// Azimuth about +z from +x, degrees.
    pub azimuth: f64,
    /// Elevation above the xy plane, degrees.
    pub elevation: f64,
    /// Distance as a multiple of the framing distance.
    pub zoom: f64,
    /// Offset of the orbit centre from the scene centre, m.
    pub pan: Vector3<f64>,
}

impl Default for Orbit {
    fn default() -> Self {
        Self {
            azimuth: -60.0,
            elevation: 30.0,
            zoom: 1.0,
            pan: Vector3::zeros(),
        }
    }
}

impl Orbit {
    /// The camera on this orbit around the box `lo..hi` (50 degree vertical field of view).
    pub fn camera(
        &self,
        name: &str,
        width: u32,
        height: u32,
        lo: &Vector3<f64>,
        hi: &Vector3<f64>,
    ) -> CameraDesc {
        let fov = 50.0f64;
        let centre = 0.5 * (lo + hi) + self.pan;
        let radius = (0.5 * (hi - lo).norm()).max(0.2);
        let aspect = width as f64 / height.max(1) as f64;
        let half = (0.5 * fov.to_radians()).tan() * aspect.min(1.0);
        let dist = self.zoom.max(0.05) * 1.1 * radius / half.max(1e-3).atan().sin();
        let (az, el) = (self.azimuth.to_radians(), self.elevation.to_radians());
        let eye = centre + dist * Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        let mut cam = CameraDesc::looking_at(name, width, height, fov, eye.into(), centre.into());
        cam.far = (dist + 4.0 * radius).max(100.0);
        cam
    }
}
