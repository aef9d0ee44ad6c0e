//! What every encoder takes ([`Image`]) and what it is ([`ImageEncoder`]).

use crate::LearnError;

/// One camera image: row-major, top row first; RGB bytes (3 per pixel) and an optional depth
/// image (metres, one per pixel; 0 or non-finite where nothing was hit).
#[derive(Clone, Copy, Debug)]
pub struct Image<'a> {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `3 * width * height` bytes, R, G, B per pixel.
    pub rgb: &'a [u8],
    /// `width * height` depths (m), if the camera gives them.
    pub depth: Option<&'a [f32]>,
}

impl<'a> Image<'a> {
    /// An RGB image; checks the length.
    pub fn rgb(width: usize, height: usize, rgb: &'a [u8]) -> Result<Self, LearnError> {
        Self::rgbd(width, height, rgb, None)
    }

    /// An RGB image with an optional depth image; checks the lengths.
    pub fn rgbd(
        width: usize,
        height: usize,
        rgb: &'a [u8],
        depth: Option<&'a [f32]>,
    ) -> Result<Self, LearnError> {
        if width == 0 || height == 0 {
            return Err(LearnError::Config(format!(
                "image size {width} x {height}: both must be at least 1"
            )));
        }
        if rgb.len() != 3 * width * height {
            return Err(LearnError::Config(format!(
                "image rgb has {} bytes; a {width} x {height} RGB image has {}",
                rgb.len(),
                3 * width * height
            )));
        }
        if let Some(d) = depth {
            if d.len() != width * height {
                return Err(LearnError::Config(format!(
                    "image depth has {} values; a {width} x {height} image has {}",
                    d.len(),
                    width * height
                )));
            }
        }
        Ok(Self {
            width,
            height,
            rgb,
            depth,
        })
    }
}

/// An image encoder: deterministic, the same image always gives the same feature.
pub trait ImageEncoder: Send + Sync {
    /// The encoder's name (the dataset column is `observation.features.<name>`).
    fn name(&self) -> &str;
    /// Length of the feature vector.
    fn dim(&self) -> usize;
    /// Features of a batch of images, one vector of [`ImageEncoder::dim`] values each.
    fn encode_batch(&self, images: &[Image<'_>]) -> Result<Vec<Vec<f32>>, LearnError>;
    /// Features of one image.
    fn encode(&self, image: &Image<'_>) -> Result<Vec<f32>, LearnError> {
        Ok(self
            .encode_batch(std::slice::from_ref(image))?
            .pop()
            .unwrap_or_default())
    }
}
