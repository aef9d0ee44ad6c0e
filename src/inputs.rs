//! What an imitation policy observes: the task's state observation, image features of a scene
//! camera (an [`ImageEncoder`] over the rendered RGB-D image), or both, features first.
//!
//! `record --cameras robot --encoder NAME` caches the features of each frame in the dataset
//! (`observation.features.<NAME>`); `train --algo bc|retrieval --inputs features|features+state`
//! learns on them and writes the [`InputSpec`] into the policy's note; `run --policy` and `eval`
//! then render the camera and encode it at every step ([`Observer`]), before the policy acts,
//! as the recording did.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use modesuite_engine::prelude::*;
use modesuite_learn::encoder::{encoder_by_name, Image, ImageEncoder};
use modesuite_render::{CameraDesc, CameraFrame, EnvRenderer};

/// Image features of one camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageFeatures {
    /// Encoder name (`modesuite_learn::encoder::ENCODERS`).
    pub encoder: String,
    /// Camera of the scene's render section (`robot` in the task environments).
    pub camera: String,
    /// The encoder's weights file, if it needs one.
    #[serde(default)]
    pub weights: Option<PathBuf>,
}

fn yes() -> bool {
    true
}

/// A policy's inputs; the default is the state observation alone.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InputSpec {
    /// Image features, first in the input vector.
    #[serde(default)]
    pub features: Option<ImageFeatures>,
    /// The task's state (`policy`) observation, after the features.
    #[serde(default = "yes")]
    pub state: bool,
}

impl Default for InputSpec {
    fn default() -> Self {
        Self {
            features: None,
            state: true,
        }
    }
}

/// The values of `--inputs`.
pub const INPUT_KINDS: &str = "state, features, features+state";

impl InputSpec {
    /// From `--inputs` (`state`, `features`, `features+state`) and the dataset's features.
    pub fn parse(kind: &str, features: Option<ImageFeatures>) -> Result<Self, String> {
        let (with_features, state) = match kind {
            "state" => (false, true),
            "features" => (true, false),
            "features+state" | "state+features" => (true, true),
            _ => return Err(format!("--inputs {kind:?}: one of {INPUT_KINDS}")),
        };
        if !with_features {
            return Ok(Self::default());
        }
        let features = features.ok_or_else(|| {
            format!(
                "--inputs {kind}: the dataset has no image features (record it with \
                 --cameras CAMERA --encoder NAME)"
            )
        })?;
        Ok(Self {
            features: Some(features),
            state,
        })
    }

    /// The dataset column of the features, if any.
    pub fn feature_column(&self) -> Option<String> {
        self.features
            .as_ref()
            .map(|f| format!("observation.features.{}", f.encoder))
    }

    /// `state`, `features` or `features+state`, with the encoder and camera.
    pub fn describe(&self) -> String {
        match (&self.features, self.state) {
            (None, _) => "state".into(),
            (Some(f), s) => format!(
                "features{} ({} of camera {})",
                if s { "+state" } else { "" },
                f.encoder,
                f.camera
            ),
        }
    }
}

/// Features of a rendered camera frame (its RGB and depth).
pub fn encode_frame(enc: &dyn ImageEncoder, frame: &CameraFrame) -> Result<Vec<f32>, String> {
    let image = Image::rgbd(
        frame.width as usize,
        frame.height as usize,
        &frame.rgb,
        Some(&frame.depth),
    )
    .map_err(|e| e.to_string())?;
    enc.encode(&image).map_err(|e| e.to_string())
}

/// Computes a policy's input vector from an env: renders and encodes the camera if the spec
/// has features (the renderer is made on first use), then appends the state observation.
pub struct Observer {
    spec: InputSpec,
    encoder: Option<Box<dyn ImageEncoder>>,
    camera: Option<(EnvRenderer, CameraDesc)>,
}

impl Observer {
    /// An observer of `spec`; makes (and for DINOv2 loads) the encoder.
    pub fn new(spec: InputSpec) -> Result<Self, String> {
        let encoder = match &spec.features {
            Some(f) => {
                Some(encoder_by_name(&f.encoder, f.weights.as_deref()).map_err(|e| e.to_string())?)
            }
            None => None,
        };
        Ok(Self {
            spec,
            encoder,
            camera: None,
        })
    }

    /// The state observation alone.
    pub fn state() -> Self {
        Self {
            spec: InputSpec::default(),
            encoder: None,
            camera: None,
        }
    }

    /// The spec observed.
    pub fn spec(&self) -> &InputSpec {
        &self.spec
    }

    /// The input vector in `env`'s current state.
    pub fn observe(&mut self, env: &Env) -> Result<Vec<f32>, String> {
        let mut v = Vec::new();
        if let (Some(f), Some(enc)) = (&self.spec.features, &self.encoder) {
            if self.camera.is_none() {
                let model = env
                    .app
                    .scene()
                    .ok_or("image inputs: the env has no scene to render")?
                    .clone();
                let r = EnvRenderer::for_scene(model).map_err(|e| e.to_string())?;
                let cam = r
                    .scene_camera(&f.camera)
                    .map_err(|e| e.to_string())?
                    .clone();
                self.camera = Some((r, cam));
            }
            let (r, cam) = self.camera.as_mut().expect("camera made above");
            let frames = r
                .render_cameras(&env.app.world, std::slice::from_ref(cam))
                .map_err(|e| e.to_string())?;
            let frame = frames.first().ok_or("image inputs: no frame rendered")?;
            v = encode_frame(enc.as_ref(), frame)?;
        }
        if self.spec.state {
            v.extend(env.observation());
        }
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_parse_and_describe() {
        let f = ImageFeatures {
            encoder: "pooled".into(),
            camera: "robot".into(),
            weights: None,
        };
        assert_eq!(
            InputSpec::parse("state", None).unwrap(),
            InputSpec::default()
        );
        let s = InputSpec::parse("features+state", Some(f.clone())).unwrap();
        assert!(s.state);
        assert_eq!(s.describe(), "features+state (pooled of camera robot)");
        assert_eq!(
            s.feature_column().as_deref(),
            Some("observation.features.pooled")
        );
        assert!(!InputSpec::parse("features", Some(f)).unwrap().state);
        let e = InputSpec::parse("features", None).unwrap_err();
        assert!(e.contains("--encoder"), "{e}");
        let e = InputSpec::parse("pixels", None).unwrap_err();
        assert!(e.contains(INPUT_KINDS), "{e}");
        // a note without inputs is the state alone
        let old: InputSpec = serde_json::from_str("{}").unwrap();
        assert_eq!(old, InputSpec::default());
    }
}
