//! `modesuite.Encoder`: the image encoders of the learning crate (`pooled`, DINOv2 ViT-S/14)
//! on numpy images, the features `record --encoder` caches and image policies compute.

use std::borrow::Cow;
use std::path::PathBuf;

use numpy::{Element, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use modesuite::learn::encoder::{encoder_by_name, Image, ImageEncoder};

use crate::convert;

/// The values of `a` in row-major order: borrowed when contiguous, copied from a strided view
/// (a transposed or sliced image).
fn row_major<'a, T: Element + Copy>(a: &'a PyReadonlyArrayDyn<'_, T>) -> Cow<'a, [T]> {
    match a.as_slice() {
        Ok(s) => Cow::Borrowed(s),
        Err(_) => Cow::Owned(a.as_array().iter().copied().collect()),
    }
}

/// An image encoder: `Encoder("pooled")` (weights-free) or `Encoder("dinov2",
/// weights="model.safetensors")` (DINOv2 ViT-S/14, Hugging Face or original/timm key names).
#[pyclass(module = "modesuite._core")]
pub struct Encoder {
    inner: Box<dyn ImageEncoder>,
}

#[pymethods]
impl Encoder {
    /// Makes the encoder `name`, loading its weights file if it needs one.
    #[new]
    #[pyo3(signature = (name = "pooled", weights = None))]
    fn new(name: &str, weights: Option<PathBuf>) -> PyResult<Self> {
        let inner = encoder_by_name(name, weights.as_deref())
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(Self { inner })
    }

    /// Features (float32) of RGB images, uint8 `(h, w, 3)` or a batch `(n, h, w, 3)`, with
    /// optional depths in metres, float32 `(h, w)` or `(n, h, w)` (0 or not finite: nothing
    /// hit): `(dim,)` or `(n, dim)`.
    #[pyo3(signature = (rgb, depth = None))]
    fn encode<'py>(
        &self,
        py: Python<'py>,
        rgb: PyReadonlyArrayDyn<'py, u8>,
        depth: Option<PyReadonlyArrayDyn<'py, f32>>,
    ) -> PyResult<Py<PyAny>> {
        let shape = rgb.shape().to_vec();
        let (batch, h, w) = match shape.as_slice() {
            [h, w, 3] => (None, *h, *w),
            [n, h, w, 3] => (Some(*n), *h, *w),
            _ => {
                return Err(PyValueError::new_err(format!(
                    "rgb of shape {shape:?}: expected (h, w, 3) or (n, h, w, 3) uint8"
                )))
            }
        };
        let n = batch.unwrap_or(1);
        let rgb = row_major(&rgb);
        let depth_values = match &depth {
            Some(d) => {
                let want: Vec<usize> = batch.into_iter().chain([h, w]).collect();
                if d.shape() != want.as_slice() {
                    return Err(PyValueError::new_err(format!(
                        "depth of shape {:?}: expected {want:?} float32 to match rgb",
                        d.shape()
                    )));
                }
                Some(row_major(d))
            }
            None => None,
        };
        let mut images = Vec::with_capacity(n);
        for i in 0..n {
            let px = h * w;
            let d = depth_values.as_deref().map(|d| &d[i * px..(i + 1) * px]);
            images.push(
                Image::rgbd(w, h, &rgb[i * 3 * px..(i + 1) * 3 * px], d)
                    .map_err(|e| PyValueError::new_err(e.to_string()))?,
            );
        }
        let features = py
            .detach(|| self.inner.encode_batch(&images))
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        let dim = self.inner.dim();
        let flat: Vec<f32> = features.into_iter().flatten().collect();
        match batch {
            Some(n) => convert::array(py, flat, &[n, dim]),
            None => convert::array(py, flat, &[dim]),
        }
    }

    /// `pooled` or `dinov2` (the dataset column is `observation.features.<name>`).
    #[getter]
    fn name(&self) -> String {
        self.inner.name().to_string()
    }

    /// Values per feature.
    #[getter]
    fn dim(&self) -> usize {
        self.inner.dim()
    }
}
