//! Image encoders: a camera's RGB-D image to a feature vector, for imitation learning on
//! images (behaviour cloning and retrieval on the robot camera, issue 31).
//!
//! Every encoder implements [`ImageEncoder`] and is made by name with [`encoder_by_name`]:
//!
//! | name | feature | needs |
//! |---|---|---|
//! | `pooled` | 256: an 8 x 8 grid of mean R, G, B (0..1) and mean depth (0..1 over 0..5 m) | nothing (the default) |
//! | `dinov2` | 384: DINOv2 ViT-S/14's final-norm CLS token at 224 x 224 | the published weights as safetensors |
//!
//! ```no_run
//! use modesuite_learn::encoder::{encoder_by_name, Image};
//! let enc = encoder_by_name("dinov2", Some("dinov2-small.safetensors".as_ref()))?;
//! let rgb = vec![128u8; 128 * 128 * 3];
//! let feature = enc.encode(&Image::rgb(128, 128, &rgb)?)?;
//! assert_eq!(feature.len(), 384);
//! # Ok::<(), modesuite_learn::LearnError>(())
//! ```

pub mod dinov2;
mod image;
pub mod pooled;
mod resample;

pub use dinov2::Dinov2;
pub use image::{Image, ImageEncoder};
pub use pooled::Pooled;

use crate::LearnError;
use std::path::Path;

/// The encoders [`encoder_by_name`] knows, with a line each (for help texts and errors).
pub const ENCODERS: &[(&str, &str)] = &[
    (
        "pooled",
        "weights-free: 8 x 8 grid of mean RGB and depth (256 values)",
    ),
    (
        "dinov2",
        "DINOv2 ViT-S/14 CLS feature (384 values); needs --weights FILE.safetensors",
    ),
];

/// Makes the encoder `name` ([`ENCODERS`]); `weights` is the weights file of an encoder that
/// needs one (`dinov2`) and must be absent for one that does not.
pub fn encoder_by_name(
    name: &str,
    weights: Option<&Path>,
) -> Result<Box<dyn ImageEncoder>, LearnError> {
    match (name, weights) {
        ("pooled", None) => Ok(Box::new(Pooled::default())),
        ("pooled", Some(w)) => Err(LearnError::Config(format!(
            "encoder pooled needs no weights (got {})",
            w.display()
        ))),
        ("dinov2", Some(w)) => Ok(Box::new(Dinov2::load(w)?)),
        ("dinov2", None) => Err(LearnError::Config(
            "encoder dinov2 needs the weights file of DINOv2 ViT-S/14 (safetensors, \
             facebook/dinov2-small or the original/timm key names; docs/learning.md says \
             where to get it)"
                .into(),
        )),
        _ => Err(LearnError::Config(format!(
            "encoder {name:?}: unknown; valid: {}",
            ENCODERS
                .iter()
                .map(|(n, _)| *n)
                .collect::<Vec<_>>()
                .join(", ")
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_lengths_are_checked() {
        let rgb = vec![0u8; 12];
        assert!(Image::rgb(2, 2, &rgb).is_ok());
        let e = Image::rgb(3, 2, &rgb).unwrap_err().to_string();
        assert!(e.contains("12 bytes") && e.contains("18"), "{e}");
        let d = vec![0.0f32; 3];
        let e = Image::rgbd(2, 2, &rgb, Some(&d)).unwrap_err().to_string();
        assert!(e.contains("3 values"), "{e}");
        assert!(Image::rgb(0, 2, &[]).is_err());
    }

    #[test]
    fn encoders_by_name() {
        assert_eq!(encoder_by_name("pooled", None).unwrap().dim(), 256);
        let e = encoder_by_name("dinov2", None).err().unwrap().to_string();
        assert!(e.contains("weights"), "{e}");
        let e = encoder_by_name("clip", None).err().unwrap().to_string();
        assert!(e.contains("pooled, dinov2"), "{e}");
        let e = encoder_by_name("pooled", Some(Path::new("w.safetensors")))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("no weights"), "{e}");
    }
}
