//! The weights-free encoder: the image averaged over a grid of cells.

use super::image::{Image, ImageEncoder};
use crate::LearnError;

/// Depth (m) that maps to 1.0; farther, and pixels where nothing was hit (0 or not finite),
/// count as 1.0.
pub const MAX_DEPTH: f32 = 5.0;

/// Average pooling of an RGB-D image over a `grid` x `grid` cell grid: per cell (row-major,
/// top-left first) the mean red, green, blue (0..1) and the mean depth over [`MAX_DEPTH`]
/// (0..1; 0 when the image has no depth). Cells split the image as evenly as whole pixels
/// allow (`x0 = i * width / grid`); every cell has at least one pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pooled {
    /// Cells per side (8 by default: 256 values).
    pub grid: usize,
}

impl Default for Pooled {
    fn default() -> Self {
        Self { grid: 8 }
    }
}

/// The pixel range of cell `i` of `n` over `len` pixels.
fn cell(i: usize, n: usize, len: usize) -> (usize, usize) {
    let a = (i * len / n).min(len - 1);
    let b = ((i + 1) * len / n).clamp(a + 1, len);
    (a, b)
}

impl Pooled {
    fn encode_one(&self, im: &Image<'_>) -> Vec<f32> {
        let g = self.grid;
        let mut out = Vec::with_capacity(4 * g * g);
        for cy in 0..g {
            let (y0, y1) = cell(cy, g, im.height);
            for cx in 0..g {
                let (x0, x1) = cell(cx, g, im.width);
                let mut sum = [0.0f64; 4];
                for y in y0..y1 {
                    for x in x0..x1 {
                        let p = y * im.width + x;
                        for (c, s) in sum.iter_mut().take(3).enumerate() {
                            *s += f64::from(im.rgb[3 * p + c]) / 255.0;
                        }
                        if let Some(d) = im.depth {
                            let z = d[p];
                            let z = if z.is_finite() && z > 0.0 {
                                z.min(MAX_DEPTH) / MAX_DEPTH
                            } else {
                                1.0
                            };
                            sum[3] += f64::from(z);
                        }
                    }
                }
                let count = ((y1 - y0) * (x1 - x0)) as f64;
                out.extend(sum.iter().map(|s| (s / count) as f32));
            }
        }
        out
    }
}

impl ImageEncoder for Pooled {
    fn name(&self) -> &str {
        "pooled"
    }

    fn dim(&self) -> usize {
        4 * self.grid * self.grid
    }

    fn encode_batch(&self, images: &[Image<'_>]) -> Result<Vec<Vec<f32>>, LearnError> {
        if self.grid == 0 {
            return Err(LearnError::Config("pooled.grid = 0: at least 1".into()));
        }
        Ok(images.iter().map(|im| self.encode_one(im)).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_cover_the_image() {
        for len in [1, 5, 8, 13, 128] {
            let mut covered = vec![0; len];
            for i in 0..8 {
                let (a, b) = cell(i, 8, len);
                assert!(a < b && b <= len, "{len}: cell {i} = {a}..{b}");
                for c in &mut covered[a..b] {
                    *c += 1;
                }
            }
            assert!(covered.iter().all(|&c| c >= 1), "{len}: {covered:?}");
        }
    }

    #[test]
    fn means_of_a_two_colour_image() {
        // 16 x 16: left half red, right half blue; depth 1 m on top, nothing hit below
        let (w, h) = (16, 16);
        let mut rgb = vec![0u8; 3 * w * h];
        let mut depth = vec![1.0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let p = y * w + x;
                rgb[3 * p + if x < 8 { 0 } else { 2 }] = 255;
                if y >= 8 {
                    depth[p] = f32::INFINITY;
                }
            }
        }
        let f = Pooled::default()
            .encode(&Image::rgbd(w, h, &rgb, Some(&depth)).unwrap())
            .unwrap();
        assert_eq!(f.len(), 256);
        // cell (row 0, col 0): red, depth 0.2; cell (row 7, col 7): blue, far
        assert_eq!(&f[0..4], &[1.0, 0.0, 0.0, 0.2]);
        assert_eq!(&f[4 * 63..], &[0.0, 0.0, 1.0, 1.0]);
        let no_depth = Pooled::default()
            .encode(&Image::rgb(w, h, &rgb).unwrap())
            .unwrap();
        assert_eq!(no_depth[3], 0.0);
    }
}
