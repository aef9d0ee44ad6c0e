//! DINOv2 ViT-S/14 (Oquab et al. 2023) on burn's CPU backend, inference only.
//!
//! The forward pass, as the published model computes it:
//! 1. the RGB image is resized bilinearly to 224 x 224 (`align_corners=False`), scaled to 0..1
//!    and normalised with ImageNet's mean (0.485, 0.456, 0.406) and deviation (0.229, 0.224,
//!    0.225);
//! 2. 14 x 14 patches (16 x 16 of them) are embedded linearly (the stride-14 convolution), a CLS
//!    token is prepended and the position embedding added. The published one is for 37 x 37
//!    patches (518 px); it is resampled to 16 x 16 bicubically with DINOv2's scale factor
//!    `(16 + 0.1) / 37` (`interpolate_offset` 0.1, no antialiasing), once, when loading;
//! 3. 12 pre-norm blocks: `x += ls1 * attn(norm1(x))`, `x += ls2 * mlp(norm2(x))`, with 6-head
//!    self-attention (head size 64, scale 1/8), an MLP of 1,536 with exact (erf) GELU, layer
//!    norms with eps 1e-6 and LayerScale vectors;
//! 4. the final layer norm; the feature is its CLS token (384 values).
//!
//! Weights come from a safetensors file in either key layout, detected from its names:
//! Hugging Face `facebook/dinov2-small` (`embeddings.cls_token`, `encoder.layer.{i}.attention.
//! attention.query.weight`, ..., `layer_scale1.lambda1`, `layernorm.weight`) or the original
//! repository's and timm's (`cls_token`, `blocks.{i}.attn.qkv.weight`, `blocks.{i}.ls1.gamma`,
//! `norm.weight`); a common prefix (such as `dinov2.`) is allowed. F32, F16, BF16 and F64
//! tensors load. The width, depth and patch size are read from the shapes (other ViT sizes
//! load too, with heads of 64); register tokens and SwiGLU MLPs (ViT-g) are refused.

use std::collections::HashMap;
use std::path::Path;

use burn::tensor::activation::{gelu, softmax};
use burn::tensor::{Device, Tensor, TensorData};
use safetensors::{Dtype, SafeTensors};

use super::image::{Image, ImageEncoder};
use super::resample::{bicubic_grid, resize_rgb};
use crate::tensors::to_vec;
use crate::LearnError;

/// Input side (pixels).
pub const INPUT: usize = 224;
/// ImageNet mean of the normalisation, R, G, B.
pub const MEAN: [f32; 3] = [0.485, 0.456, 0.406];
/// ImageNet standard deviation of the normalisation.
pub const STD: [f32; 3] = [0.229, 0.224, 0.225];
/// Layer-norm epsilon of DINOv2.
const LN_EPS: f64 = 1e-6;
/// Attention head size of the DINOv2 family.
const HEAD_DIM: usize = 64;
/// Offset added to the patch grid before computing the position embedding's scale factor.
const INTERPOLATE_OFFSET: f64 = 0.1;

/// Which key names a weights file uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeyLayout {
    /// Hugging Face transformers (`facebook/dinov2-small`).
    HuggingFace,
    /// The original repository and timm.
    Original,
}

struct Block {
    norm1: (Tensor<1>, Tensor<1>),
    qkv: (Tensor<2>, Tensor<1>),
    proj: (Tensor<2>, Tensor<1>),
    ls1: Tensor<1>,
    norm2: (Tensor<1>, Tensor<1>),
    fc1: (Tensor<2>, Tensor<1>),
    fc2: (Tensor<2>, Tensor<1>),
    ls2: Tensor<1>,
}

/// DINOv2 with loaded weights (see the module documentation).
pub struct Dinov2 {
    dim: usize,
    heads: usize,
    patch: usize,
    grid: usize,
    layout: KeyLayout,
    patch_embed: (Tensor<2>, Tensor<1>),
    cls_pos: Tensor<2>,
    patch_pos: Tensor<2>,
    blocks: Vec<Block>,
    norm: (Tensor<1>, Tensor<1>),
    device: Device,
}

/// The tensors of a safetensors file, as `f32` with their shapes.
struct Weights {
    prefix: String,
    map: HashMap<String, (Vec<usize>, Vec<f32>)>,
    file: String,
}

fn weights_err(file: &str, msg: impl std::fmt::Display) -> LearnError {
    LearnError::Weights(format!("{file}: {msg}"))
}

fn to_f32(dtype: Dtype, bytes: &[u8]) -> Option<Vec<f32>> {
    let le2 = |c: &[u8]| u16::from_le_bytes([c[0], c[1]]);
    Some(match dtype {
        Dtype::F32 => bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
        Dtype::F64 => bytes
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")) as f32)
            .collect(),
        Dtype::F16 => bytes
            .chunks_exact(2)
            .map(|c| half::f16::from_bits(le2(c)).to_f32())
            .collect(),
        Dtype::BF16 => bytes
            .chunks_exact(2)
            .map(|c| half::bf16::from_bits(le2(c)).to_f32())
            .collect(),
        _ => return None,
    })
}

impl Weights {
    fn read(path: &Path) -> Result<(Self, KeyLayout), LearnError> {
        let file = path.display().to_string();
        let bytes = std::fs::read(path)
            .map_err(|e| LearnError::Io(format!("weights {file}: cannot read: {e}")))?;
        let st = SafeTensors::deserialize(&bytes)
            .map_err(|e| weights_err(&file, format!("not a safetensors file: {e}")))?;
        let names = st.names();
        let find = |suffix: &str| {
            names
                .iter()
                .find(|n| **n == suffix || n.ends_with(&format!(".{suffix}")))
                .map(|n| n[..n.len() - suffix.len()].to_string())
        };
        let (prefix, layout) = if let Some(p) = find("embeddings.cls_token") {
            (p, KeyLayout::HuggingFace)
        } else if let Some(p) = find("cls_token") {
            (p, KeyLayout::Original)
        } else {
            return Err(weights_err(
                &file,
                "no cls_token: not a DINOv2 checkpoint (expected facebook/dinov2-small's \
                 `embeddings.cls_token` or the original/timm `cls_token`)",
            ));
        };
        if names.iter().any(|n| n.contains("register_tokens")) {
            return Err(weights_err(
                &file,
                "DINOv2 with register tokens is not supported (use dinov2-small without registers)",
            ));
        }
        let mut map = HashMap::new();
        for (name, view) in st.tensors() {
            let Some(key) = name.strip_prefix(prefix.as_str()) else {
                continue;
            };
            let v = to_f32(view.dtype(), view.data()).ok_or_else(|| {
                weights_err(
                    &file,
                    format!(
                        "{name}: dtype {:?}, expected F32, F16, BF16 or F64",
                        view.dtype()
                    ),
                )
            })?;
            map.insert(key.to_string(), (view.shape().to_vec(), v));
        }
        Ok((Self { prefix, map, file }, layout))
    }

    fn get(&self, key: &str, shape: &[usize]) -> Result<Vec<f32>, LearnError> {
        let (s, v) = self.map.get(key).ok_or_else(|| {
            weights_err(&self.file, format!("missing tensor {}{key}", self.prefix))
        })?;
        if s != shape {
            return Err(weights_err(
                &self.file,
                format!("{}{key} has shape {s:?}, expected {shape:?}", self.prefix),
            ));
        }
        if v.iter().any(|x| !x.is_finite()) {
            return Err(weights_err(
                &self.file,
                format!("{}{key} holds non-finite values", self.prefix),
            ));
        }
        Ok(v.clone())
    }

    fn shape(&self, key: &str) -> Result<&[usize], LearnError> {
        self.map
            .get(key)
            .map(|(s, _)| s.as_slice())
            .ok_or_else(|| weights_err(&self.file, format!("missing tensor {}{key}", self.prefix)))
    }
}

/// `[out, in]` (PyTorch's linear weight) transposed to `[in, out]`, row-major.
fn transpose(w: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    let mut t = vec![0.0; w.len()];
    for r in 0..rows {
        for c in 0..cols {
            t[c * rows + r] = w[r * cols + c];
        }
    }
    t
}

impl Dinov2 {
    /// Loads a DINOv2 checkpoint (safetensors, either key layout; see the module docs).
    pub fn load(path: &Path) -> Result<Self, LearnError> {
        let (w, layout) = Weights::read(path)?;
        let device = Device::flex();
        let hf = layout == KeyLayout::HuggingFace;
        let k = |hf_name: &str, orig: &str| {
            if hf {
                hf_name.to_string()
            } else {
                orig.to_string()
            }
        };
        let cls_key = k("embeddings.cls_token", "cls_token");
        let dim = *w.shape(&cls_key)?.last().unwrap_or(&0);
        if dim == 0 || dim % HEAD_DIM != 0 {
            return Err(weights_err(
                &w.file,
                format!("width {dim}: expected a multiple of {HEAD_DIM}"),
            ));
        }
        let pe_key = k("embeddings.patch_embeddings.projection", "patch_embed.proj");
        let pshape = w.shape(&format!("{pe_key}.weight"))?.to_vec();
        let patch = *pshape.last().unwrap_or(&0);
        if pshape.len() != 4 || pshape[..2] != [dim, 3] || pshape[2] != patch || patch == 0 {
            return Err(weights_err(
                &w.file,
                format!("{pe_key}.weight has shape {pshape:?}, expected [{dim}, 3, p, p]"),
            ));
        }
        let grid = INPUT / patch;
        let tensor2 = |v: Vec<f32>, r: usize, c: usize| {
            Tensor::<2>::from_data(TensorData::new(v, [r, c]), &device)
        };
        let tensor1 =
            |v: Vec<f32>| Tensor::<1>::from_data(TensorData::new(v.clone(), [v.len()]), &device);
        // a linear layer `name` with `inp` inputs and `out` outputs, as x W^T + b
        let linear = |name: &str, inp: usize, out: usize| -> Result<_, LearnError> {
            let wt = transpose(&w.get(&format!("{name}.weight"), &[out, inp])?, out, inp);
            Ok((
                tensor2(wt, inp, out),
                tensor1(w.get(&format!("{name}.bias"), &[out])?),
            ))
        };
        let norm = |name: &str| -> Result<_, LearnError> {
            Ok((
                tensor1(w.get(&format!("{name}.weight"), &[dim])?),
                tensor1(w.get(&format!("{name}.bias"), &[dim])?),
            ))
        };
        let pw = w.get(&format!("{pe_key}.weight"), &pshape)?;
        let patch_embed = (
            tensor2(
                transpose(&pw, dim, 3 * patch * patch),
                3 * patch * patch,
                dim,
            ),
            tensor1(w.get(&format!("{pe_key}.bias"), &[dim])?),
        );
        let cls = w.get(&cls_key, &[1, 1, dim])?;
        let pos_key = k("embeddings.position_embeddings", "pos_embed");
        let pos_shape = w.shape(&pos_key)?.to_vec();
        let n_pos = pos_shape.get(1).copied().unwrap_or(0);
        let m = ((n_pos.saturating_sub(1)) as f64).sqrt().round() as usize;
        if pos_shape.len() != 3 || pos_shape[0] != 1 || pos_shape[2] != dim || m * m + 1 != n_pos {
            return Err(weights_err(
                &w.file,
                format!("{pos_key} has shape {pos_shape:?}, expected [1, 1 + m * m, {dim}]"),
            ));
        }
        let pos = w.get(&pos_key, &pos_shape)?;
        let patch_grid: Vec<f64> = pos[dim..].iter().map(|&v| f64::from(v)).collect();
        let resampled = if m == grid {
            patch_grid
        } else {
            let scale = (grid as f64 + INTERPOLATE_OFFSET) / m as f64;
            bicubic_grid(&patch_grid, m, dim, grid, scale)
        };
        let cls_pos_v: Vec<f32> = cls.iter().zip(&pos[..dim]).map(|(c, p)| c + p).collect();
        let cls_pos = tensor2(cls_pos_v, 1, dim);
        let patch_pos = tensor2(
            resampled.iter().map(|&v| v as f32).collect(),
            grid * grid,
            dim,
        );
        // blocks 0.. until one is missing
        let block_key = |i: usize| {
            if hf {
                format!("encoder.layer.{i}")
            } else {
                format!("blocks.{i}")
            }
        };
        let depth = (0..)
            .take_while(|&i| {
                w.map
                    .contains_key(&format!("{}.norm1.weight", block_key(i)))
            })
            .count();
        if depth == 0 {
            return Err(weights_err(&w.file, "no transformer blocks"));
        }
        let mut blocks = Vec::with_capacity(depth);
        for i in 0..depth {
            let b = block_key(i);
            let hidden_key = format!("{b}.mlp.fc1.weight");
            if !w.map.contains_key(&hidden_key) {
                return Err(weights_err(
                    &w.file,
                    format!("{b}: no mlp.fc1 (SwiGLU MLPs, as in ViT-g, are not supported)"),
                ));
            }
            let hidden = w.shape(&hidden_key)?[0];
            let qkv = if hf {
                let a = format!("{b}.attention.attention");
                let mut wq = Vec::with_capacity(3 * dim * dim);
                let mut bq = Vec::with_capacity(3 * dim);
                for part in ["query", "key", "value"] {
                    wq.extend(w.get(&format!("{a}.{part}.weight"), &[dim, dim])?);
                    bq.extend(w.get(&format!("{a}.{part}.bias"), &[dim])?);
                }
                (
                    tensor2(transpose(&wq, 3 * dim, dim), dim, 3 * dim),
                    tensor1(bq),
                )
            } else {
                linear(&format!("{b}.attn.qkv"), dim, 3 * dim)?
            };
            let (proj, ls1, ls2) = if hf {
                (
                    format!("{b}.attention.output.dense"),
                    format!("{b}.layer_scale1.lambda1"),
                    format!("{b}.layer_scale2.lambda1"),
                )
            } else {
                (
                    format!("{b}.attn.proj"),
                    format!("{b}.ls1.gamma"),
                    format!("{b}.ls2.gamma"),
                )
            };
            blocks.push(Block {
                norm1: norm(&format!("{b}.norm1"))?,
                qkv,
                proj: linear(&proj, dim, dim)?,
                ls1: tensor1(w.get(&ls1, &[dim])?),
                norm2: norm(&format!("{b}.norm2"))?,
                fc1: linear(&format!("{b}.mlp.fc1"), dim, hidden)?,
                fc2: linear(&format!("{b}.mlp.fc2"), hidden, dim)?,
                ls2: tensor1(w.get(&ls2, &[dim])?),
            });
        }
        let norm_final = norm(&k("layernorm", "norm"))?;
        Ok(Self {
            dim,
            heads: dim / HEAD_DIM,
            patch,
            grid,
            layout,
            patch_embed,
            cls_pos,
            patch_pos,
            blocks,
            norm: norm_final,
            device,
        })
    }

    /// The key layout the weights file used.
    pub fn layout(&self) -> KeyLayout {
        self.layout
    }

    /// Number of transformer blocks.
    pub fn depth(&self) -> usize {
        self.blocks.len()
    }

    /// The normalised 224 x 224 input of an image, cut into patches: `[grid^2][3 p p]`
    /// (channel, row, column within a patch, as the convolution's weight is laid out).
    fn patches(&self, im: &Image<'_>) -> Vec<f32> {
        let planes = resize_rgb(im.rgb, im.width, im.height, INPUT);
        let (p, g) = (self.patch, self.grid);
        let mut out = Vec::with_capacity(g * g * 3 * p * p);
        for py in 0..g {
            for px in 0..g {
                for c in 0..3 {
                    for i in 0..p {
                        let row = (c * INPUT + py * p + i) * INPUT + px * p;
                        out.extend(planes[row..row + p].iter().map(|v| (v - MEAN[c]) / STD[c]));
                    }
                }
            }
        }
        out
    }

    /// The CLS feature (`[1, dim]`) of one image's patches.
    fn forward(&self, patches: Vec<f32>) -> Tensor<2> {
        let (c, g2, p) = (self.dim, self.grid * self.grid, self.patch);
        let n = g2 + 1;
        let x = Tensor::<2>::from_data(TensorData::new(patches, [g2, 3 * p * p]), &self.device);
        let x = linear(x, &self.patch_embed) + self.patch_pos.clone();
        let mut x = Tensor::cat(vec![self.cls_pos.clone(), x], 0);
        let (h, hd) = (self.heads, HEAD_DIM);
        let scale = 1.0 / (hd as f64).sqrt();
        for b in &self.blocks {
            // [tokens, 3 h hd] -> q, k, v of [heads, tokens, hd]
            let qkv = linear(layer_norm(x.clone(), &b.norm1), &b.qkv)
                .reshape([n, 3, h, hd])
                .permute([1, 2, 0, 3]);
            let mut parts = qkv.chunk(3, 0).into_iter().map(|t| t.reshape([h, n, hd]));
            let (q, k, v) = (
                parts.next().expect("q"),
                parts.next().expect("k"),
                parts.next().expect("v"),
            );
            let attn = softmax(q.matmul(k.swap_dims(1, 2)) * scale, 2);
            let o = attn.matmul(v).swap_dims(0, 1).reshape([n, c]);
            x = x + linear(o, &b.proj) * b.ls1.clone().unsqueeze_dim(0);
            let m = gelu(linear(layer_norm(x.clone(), &b.norm2), &b.fc1));
            x = x + linear(m, &b.fc2) * b.ls2.clone().unsqueeze_dim(0);
        }
        layer_norm(x, &self.norm).narrow(0, 0, 1)
    }
}

fn linear(x: Tensor<2>, (w, b): &(Tensor<2>, Tensor<1>)) -> Tensor<2> {
    x.matmul(w.clone()) + b.clone().unsqueeze_dim(0)
}

fn layer_norm(x: Tensor<2>, (w, b): &(Tensor<1>, Tensor<1>)) -> Tensor<2> {
    let mean = x.clone().mean_dim(1);
    let centred = x - mean;
    let var = centred.clone().square().mean_dim(1);
    centred / (var + LN_EPS).sqrt() * w.clone().unsqueeze_dim(0) + b.clone().unsqueeze_dim(0)
}

impl ImageEncoder for Dinov2 {
    fn name(&self) -> &str {
        "dinov2"
    }

    fn dim(&self) -> usize {
        self.dim
    }

    fn encode_batch(&self, images: &[Image<'_>]) -> Result<Vec<Vec<f32>>, LearnError> {
        // One forward pass per image: a feature never depends on the batch it came in.
        let mut out = Vec::with_capacity(images.len());
        for im in images {
            out.push(to_vec(self.forward(self.patches(im))));
        }
        Ok(out)
    }
}
