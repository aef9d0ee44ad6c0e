//! The scene's `render` section: cameras, light and markers, parsed from the scene's
//! `extensions` (raw RON owned by this plugin) and validated.
//!
//! ```ron
//! extensions: {
//!     "render": (
//!         cameras: [
//!             (name: "top", width: 128, height: 128, intrinsics: Fov(60.0),
//!              pose: (pos: (0.0, 0.0, 2.0)), look_at: (0.0, 0.0, 0.0)),
//!             (name: "wrist", width: 64, height: 48,
//!              intrinsics: Pinhole(fx: 50.0, fy: 50.0, cx: 31.5, cy: 23.5),
//!              attach: "box", pose: (pos: (0.0, 0.0, 0.2)), look_at: (0.0, 0.0, 0.0)),
//!         ],
//!         light: (direction: (-0.4, -0.3, -1.0), shadow_map: 512),
//!     ),
//! }
//! ```
//!
//! Camera frames follow the optical convention (x right, y down, z forward). A camera's `pose`
//! is `parent_from_camera` (parent = the world, or the object named by `attach`); with `look_at`
//! (a point in the parent frame) the orientation is computed from the position, the point and
//! the parent's +z as up, and `pose.rpy` must stay zero.

use modesuite_engine::registry::CameraMount;
use modesuite_engine::scene::{PoseDesc, SceneError, SceneModel};
use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;

/// The extension key of the render section in a scene's `extensions`.
pub const EXTENSION_KEY: &str = "render";

fn default_near() -> f64 {
    0.01
}
fn default_far() -> f64 {
    100.0
}
fn default_direction() -> [f64; 3] {
    [-0.4, -0.3, -1.0]
}
fn default_ambient() -> f32 {
    0.35
}
fn default_background() -> [f32; 3] {
    [0.62, 0.72, 0.85]
}
fn default_marker_radius() -> f64 {
    0.05
}

/// The whole `render` section.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RenderConfig {
    /// Camera sensors, by unique name.
    #[serde(default)]
    pub cameras: Vec<CameraDesc>,
    /// The directional light and its shadows.
    #[serde(default)]
    pub light: LightDesc,
    /// Background colour (linear RGB in [0, 1]).
    #[serde(default = "default_background")]
    pub background: [f32; 3],
    /// Radius of the translucent target markers drawn at the scene's named frames, m.
    #[serde(default = "default_marker_radius")]
    pub marker_radius: f64,
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            cameras: Vec::new(),
            light: LightDesc::default(),
            background: default_background(),
            marker_radius: default_marker_radius(),
        }
    }
}

/// A directional light with a shadow map.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LightDesc {
    /// Direction the light travels, world frame (normalised on use).
    #[serde(default = "default_direction")]
    pub direction: [f64; 3],
    /// Ambient fraction of the light in [0, 1].
    #[serde(default = "default_ambient")]
    pub ambient: f32,
    /// Shadow map resolution in texels (0 = no shadows; default: the largest side of the cameras
    /// rendered together, rounded up to a power of two in 256..=2048).
    #[serde(default)]
    pub shadow_map: Option<u32>,
}

impl Default for LightDesc {
    fn default() -> Self {
        Self {
            direction: default_direction(),
            ambient: default_ambient(),
            shadow_map: None,
        }
    }
}

/// Camera intrinsics.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
pub enum Intrinsics {
    /// Vertical field of view in degrees, square pixels, principal point at the image centre.
    Fov(f64),
    /// Pinhole model in pixels (OpenCV convention: pixel centres at integer coordinates).
    Pinhole {
        /// Focal length along x, px.
        fx: f64,
        /// Focal length along y, px.
        fy: f64,
        /// Principal point x, px.
        cx: f64,
        /// Principal point y, px.
        cy: f64,
    },
}

impl Default for Intrinsics {
    fn default() -> Self {
        Intrinsics::Fov(60.0)
    }
}

/// What a camera renders (all three by default).
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, PartialOrd, Ord)]
pub enum Channel {
    /// Colour, u8 RGB.
    Rgb,
    /// Depth along the optical axis, f32 metres (0 where nothing was hit).
    Depth,
    /// Object id per pixel, u32 (object index + 1; 0 = background).
    Segmentation,
}

/// One camera sensor.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraDesc {
    /// Unique name.
    pub name: String,
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Intrinsics (default: 60 degrees vertical field of view).
    #[serde(default)]
    pub intrinsics: Intrinsics,
    /// `parent_from_camera` (optical frame: x right, y down, z forward).
    #[serde(default)]
    pub pose: PoseDesc,
    /// Aim the camera at this point of the parent frame (up = parent +z).
    #[serde(default)]
    pub look_at: Option<[f64; 3]>,
    /// Name of the object (or robot link) the camera moves with; none = fixed in the world.
    #[serde(default)]
    pub attach: Option<String>,
    /// Near clipping distance, m.
    #[serde(default = "default_near")]
    pub near: f64,
    /// Far clipping distance, m.
    #[serde(default = "default_far")]
    pub far: f64,
    /// Draw the translucent target markers (default off for sensors).
    #[serde(default)]
    pub markers: bool,
    /// Draw contact (red) and grasp (yellow) markers (default off).
    #[serde(default)]
    pub overlays: bool,
}

impl CameraDesc {
    /// A camera at `eye` looking at `target` (world frame).
    pub fn looking_at(
        name: &str,
        width: u32,
        height: u32,
        fov_y_deg: f64,
        eye: [f64; 3],
        target: [f64; 3],
    ) -> Self {
        Self {
            name: name.to_string(),
            width,
            height,
            intrinsics: Intrinsics::Fov(fov_y_deg),
            pose: PoseDesc {
                pos: eye,
                rpy: [0.0; 3],
            },
            look_at: Some(target),
            attach: None,
            near: default_near(),
            far: default_far(),
            markers: false,
            overlays: false,
        }
    }

    /// Pinhole intrinsics in pixels `(fx, fy, cx, cy)`.
    pub fn pinhole(&self) -> (f64, f64, f64, f64) {
        match self.intrinsics {
            Intrinsics::Fov(deg) => {
                let f = 0.5 * self.height as f64 / (0.5 * deg.to_radians()).tan();
                (
                    f,
                    f,
                    0.5 * (self.width as f64 - 1.0),
                    0.5 * (self.height as f64 - 1.0),
                )
            }
            Intrinsics::Pinhole { fx, fy, cx, cy } => (fx, fy, cx, cy),
        }
    }

    /// `parent_from_camera` as an isometry (optical frame).
    pub fn parent_from_camera(&self) -> Isometry3<f64> {
        match self.look_at {
            Some(t) => look_at(
                &Vector3::from(self.pose.pos),
                &Vector3::from(t),
                &Vector3::z(),
            ),
            None => self.pose.isometry(),
        }
    }

    fn validate(&self, path: &str) -> Result<(), SceneError> {
        let bad = |field: &str, value: String, expected: &str| {
            Err(SceneError::semantic(
                format!("{path}.{field}"),
                value,
                expected,
            ))
        };
        if self.name.trim().is_empty() {
            return bad(
                "name",
                format!("{:?}", self.name),
                "a non-empty unique name",
            );
        }
        for (field, v) in [("width", self.width), ("height", self.height)] {
            if !(1..=8192).contains(&v) {
                return bad(field, v.to_string(), "an image size in 1..=8192 px");
            }
        }
        match self.intrinsics {
            Intrinsics::Fov(d) => {
                if !(d.is_finite() && d > 0.0 && d < 179.0) {
                    return bad(
                        "intrinsics",
                        format!("Fov({d})"),
                        "a vertical field of view in (0, 179) degrees",
                    );
                }
            }
            Intrinsics::Pinhole { fx, fy, cx, cy } => {
                let finite = [fx, fy, cx, cy].iter().all(|x| x.is_finite());
                if !(finite && fx > 0.0 && fy > 0.0) {
                    return bad(
                        "intrinsics",
                        format!("Pinhole(fx: {fx}, fy: {fy}, cx: {cx}, cy: {cy})"),
                        "finite focal lengths > 0 and a finite principal point, px",
                    );
                }
            }
        }
        let finite = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
        if !finite(&self.pose.pos) || !finite(&self.pose.rpy) {
            return bad(
                "pose",
                format!("{:?}", self.pose),
                "finite position (m) and angles (rad)",
            );
        }
        if let Some(t) = self.look_at {
            if !finite(&t) {
                return bad("look_at", format!("{t:?}"), "a finite point, m");
            }
            if self.pose.rpy != [0.0; 3] {
                return bad(
                    "pose.rpy",
                    format!("{:?}", self.pose.rpy),
                    "zero when look_at sets the orientation",
                );
            }
            if (Vector3::from(t) - Vector3::from(self.pose.pos)).norm() < 1e-9 {
                return bad(
                    "look_at",
                    format!("{t:?}"),
                    "a point different from the camera position",
                );
            }
        }
        if !(self.near.is_finite() && self.near > 0.0) {
            return bad("near", self.near.to_string(), "a finite distance > 0, m");
        }
        if !(self.far.is_finite() && self.far > self.near) {
            return bad("far", self.far.to_string(), "a finite distance > near, m");
        }
        Ok(())
    }
}

/// `world_from_camera` (optical frame) of a camera at `eye` looking at `target` with `up` as the
/// image's up direction (a fallback up is used when looking along `up`).
pub fn look_at(eye: &Vector3<f64>, target: &Vector3<f64>, up: &Vector3<f64>) -> Isometry3<f64> {
    let forward = (target - eye).normalize();
    let mut right = forward.cross(up);
    if right.norm() < 1e-9 {
        right = forward.cross(&Vector3::y());
    }
    let right = right.normalize();
    let down = forward.cross(&right);
    let rot = Rotation3::from_basis_unchecked(&[right, down, forward]);
    Isometry3::from_parts(
        Translation3::from(*eye),
        UnitQuaternion::from_rotation_matrix(&rot),
    )
}

/// Projects a world point through a camera (`world_from_camera`, pinhole `(fx, fy, cx, cy)`);
/// returns pixel coordinates (OpenCV convention) and the depth, or `None` behind the camera.
pub fn project(
    world_from_camera: &Isometry3<f64>,
    pinhole: (f64, f64, f64, f64),
    p: &Vector3<f64>,
) -> Option<(f64, f64, f64)> {
    let c = world_from_camera.inverse_transform_point(&Point3::from(*p));
    if c.z <= 0.0 {
        return None;
    }
    let (fx, fy, cx, cy) = pinhole;
    Some((fx * c.x / c.z + cx, fy * c.y / c.z + cy, c.z))
}

impl RenderConfig {
    /// Parses RON text of a render section (the scene's RON options) and validates it.
    pub fn parse(text: &str) -> Result<Self, SceneError> {
        let cfg: RenderConfig = modesuite_engine::scene::ron_options()
            .from_str(text)
            .map_err(|e| {
                SceneError::semantic(
                    format!("extensions[\"{EXTENSION_KEY}\"]"),
                    text.trim(),
                    format!("{} (at {} within the section)", e.code, e.span.start),
                )
            })?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The render section of a compiled scene (defaults when it has none), with file positions
    /// in errors when the section can be found in the scene text.
    /// The cameras that the scene's other sections bring (a robot file's, see
    /// [`SceneSection::cameras`](modesuite_engine::registry::SceneSection::cameras)) follow the
    /// section's own, except where the section has a camera of that name.
    pub fn from_scene(model: &SceneModel) -> Result<Self, SceneError> {
        let mut cfg = Self::from_section(model)?;
        let before = cfg.cameras.len();
        cfg.add_mounted(
            model
                .sections
                .iter()
                .flat_map(|s| s.handler.cameras(&s.compiled)),
        );
        if cfg.cameras.len() > before {
            cfg.validate()?;
        }
        Ok(cfg)
    }

    /// Adds cameras other sections bring ([`CameraMount`]s) after the section's own, except
    /// where the section has a camera of the same name (the section's wins). Not validated.
    pub fn add_mounted(&mut self, mounts: impl IntoIterator<Item = CameraMount>) {
        for m in mounts {
            if self.camera(&m.name).is_some() {
                continue;
            }
            self.cameras.push(CameraDesc {
                name: m.name,
                width: m.width,
                height: m.height,
                intrinsics: Intrinsics::Fov(m.fov_y_deg),
                pose: m.pose,
                look_at: m.look_at,
                attach: Some(m.attach),
                near: default_near(),
                far: default_far(),
                markers: false,
                overlays: false,
            });
        }
    }

    /// The scene's render section alone.
    fn from_section(model: &SceneModel) -> Result<Self, SceneError> {
        let Some(raw) = model.extensions.get(EXTENSION_KEY) else {
            return Ok(Self::default());
        };
        let text = raw.get_ron();
        let path = format!("extensions[\"{EXTENSION_KEY}\"]");
        let cfg: RenderConfig = modesuite_engine::scene::ron_options()
            .from_str(text)
            .map_err(|e| {
                modesuite_engine::scene::plugin_params_error(&model.source, text, &path, &e)
                    .in_file(
                        model
                            .source
                            .file
                            .as_ref()
                            .map(|f| f.display().to_string())
                            .as_deref(),
                    )
            })?;
        cfg.validate()?;
        cfg.check_attach(&path, &model.objects)?;
        Ok(cfg)
    }

    /// Checks that every camera's `attach` names an object of the scene; a robot link
    /// (`robot/link`, spawned by the robots section) is checked when the renderer is attached
    /// ([`crate::prepare`]).
    pub fn check_attach(
        &self,
        path: &str,
        objects: &[modesuite_engine::scene::ObjectModel],
    ) -> Result<(), SceneError> {
        for (i, c) in self.cameras.iter().enumerate() {
            if let Some(a) = &c.attach {
                if !a.contains('/') && !objects.iter().any(|o| &o.name == a) {
                    return Err(SceneError::semantic(
                        format!("{path}.cameras[{i}].attach"),
                        format!("{a:?}"),
                        format!(
                            "the name of a scene object: [{}], or a robot link `robot/link`",
                            objects
                                .iter()
                                .map(|o| o.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Validates every number and name.
    pub fn validate(&self) -> Result<(), SceneError> {
        let path = format!("extensions[\"{EXTENSION_KEY}\"]");
        for (i, c) in self.cameras.iter().enumerate() {
            c.validate(&format!("{path}.cameras[{i}]"))?;
            if self.cameras[..i].iter().any(|d| d.name == c.name) {
                return Err(SceneError::semantic(
                    format!("{path}.cameras[{i}].name"),
                    format!("{:?}", c.name),
                    "camera names must be unique",
                ));
            }
        }
        let d = self.light.direction;
        if !(d.iter().all(|x| x.is_finite()) && Vector3::from(d).norm() > 1e-9) {
            return Err(SceneError::semantic(
                format!("{path}.light.direction"),
                format!("{d:?}"),
                "a finite non-zero direction",
            ));
        }
        if !(self.light.ambient.is_finite() && (0.0..=1.0).contains(&self.light.ambient)) {
            return Err(SceneError::semantic(
                format!("{path}.light.ambient"),
                self.light.ambient.to_string(),
                "a number in [0, 1]",
            ));
        }
        if let Some(n) = self.light.shadow_map.filter(|n| *n > 8192) {
            return Err(SceneError::semantic(
                format!("{path}.light.shadow_map"),
                n.to_string(),
                "a resolution in 0..=8192 texels (0 = no shadows)",
            ));
        }
        if !self
            .background
            .iter()
            .all(|x| x.is_finite() && (0.0..=1.0).contains(x))
        {
            return Err(SceneError::semantic(
                format!("{path}.background"),
                format!("{:?}", self.background),
                "three numbers in [0, 1]",
            ));
        }
        if !(self.marker_radius.is_finite() && self.marker_radius > 0.0) {
            return Err(SceneError::semantic(
                format!("{path}.marker_radius"),
                self.marker_radius.to_string(),
                "a finite radius > 0, m",
            ));
        }
        Ok(())
    }

    /// The camera of this name.
    pub fn camera(&self, name: &str) -> Option<&CameraDesc> {
        self.cameras.iter().find(|c| c.name == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_frame_is_optical() {
        let iso = look_at(
            &Vector3::new(0.0, 0.0, 2.0),
            &Vector3::zeros(),
            &Vector3::z(),
        );
        // Looking straight down: forward is -z.
        let fwd = iso.rotation * Vector3::z();
        assert!((fwd - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12, "{fwd}");
        let iso = look_at(&Vector3::zeros(), &Vector3::x(), &Vector3::z());
        let right = iso.rotation * Vector3::x();
        let down = iso.rotation * Vector3::y();
        assert!((right + Vector3::y()).norm() < 1e-12, "right {right}");
        assert!((down + Vector3::z()).norm() < 1e-12, "down {down}");
    }

    #[test]
    fn projection_of_the_axis_is_the_principal_point() {
        let cam = CameraDesc::looking_at("c", 64, 48, 60.0, [0.0, 0.0, 3.0], [0.0, 0.0, 0.0]);
        let (u, v, z) =
            project(&cam.parent_from_camera(), cam.pinhole(), &Vector3::zeros()).expect("in front");
        assert!(
            (u - 31.5).abs() < 1e-9 && (v - 23.5).abs() < 1e-9,
            "{u} {v}"
        );
        assert!((z - 3.0).abs() < 1e-12);
    }

    #[test]
    fn bad_values_are_located() {
        let e = RenderConfig::parse("(cameras: [(name: \"a\", width: 0, height: 4)])")
            .expect_err("width 0");
        assert!(e.to_string().contains("cameras[0].width"), "{e}");
        let e = RenderConfig::parse("(cameras: [(name: \"a\", width: 4, height: 4, fov: 3)])")
            .expect_err("unknown field");
        assert!(e.to_string().contains("fov"), "{e}");
        let e = RenderConfig::parse(
            "(cameras: [(name: \"a\", width: 4, height: 4), (name: \"a\", width: 4, height: 4)])",
        )
        .expect_err("duplicate");
        assert!(e.to_string().contains("unique"), "{e}");
    }
}
