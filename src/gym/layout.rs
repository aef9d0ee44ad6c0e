//! How the engine's flat observation and action buffers map to the Gymnasium spaces that
//! Python users see.
//!
//! Observations: a task without camera terms has one unbounded `Box` (float32). A task with
//! camera terms has a `Dict`; each image item `<camera>_<channels>` of the engine (RGB in
//! [0, 1], depth in metres, `(.., height, width, channels)`) becomes `<camera>_rgb` (uint8 in
//! [0, 255], three channels: Stable-Baselines3's image convention) and/or `<camera>_depth`
//! (float32 metres, one channel); state items stay float32. Actions: one flat float32 `Box`
//! (the robot parts `base`, `arm`, `gripper` one after another; [`ActLayout::parts`] names
//! the slices) or `Discrete(14)` for the teleoperation keys.

use modesuite_engine::Space;

/// One item of a `Dict` observation as the engine lays it out in the flat buffer.
#[derive(Debug, Clone)]
pub struct ObsItem {
    /// The engine's name (`state`, `robot_rgbd`, ...).
    pub name: String,
    /// Offset in the flat per-env buffer.
    pub offset: usize,
    /// Number of f32 values.
    pub len: usize,
    /// Shape (for images `(.., height, width, channels)`).
    pub shape: Vec<usize>,
    /// For images: the camera name and the channels (`rgb`, `depth`, `rgbd`).
    pub image: Option<(String, String)>,
}

/// The observation layout of an env.
#[derive(Debug, Clone)]
pub enum ObsLayout {
    /// One float32 box of `dim` values.
    Flat {
        /// Values per env.
        dim: usize,
    },
    /// A dict of items.
    Dict(Vec<ObsItem>),
}

/// One array of a converted observation: its key, dtype and shape (without the batch axis).
#[derive(Debug, Clone, PartialEq)]
pub struct OutKey {
    /// Key in the Python dict.
    pub key: String,
    /// `float32` or `uint8`.
    pub dtype: &'static str,
    /// Shape.
    pub shape: Vec<usize>,
    /// Lower bound (every element).
    pub low: f32,
    /// Upper bound (every element).
    pub high: f32,
}

impl ObsLayout {
    /// The layout of an observation space; `Err` for a space the binding cannot express.
    pub fn of(space: &Space) -> Result<Self, String> {
        match space {
            Space::Box { shape, .. } if shape.len() <= 1 => Ok(ObsLayout::Flat {
                dim: space.flat_dim(),
            }),
            Space::Dict(items) => {
                let mut out = Vec::with_capacity(items.len());
                let mut offset = 0;
                for (name, s) in items {
                    let Space::Box { shape, .. } = s else {
                        return Err(format!("observation item {name}: only boxes are supported"));
                    };
                    let len = s.flat_dim();
                    let image = name
                        .rsplit_once('_')
                        .filter(|(_, ch)| matches!(*ch, "rgb" | "depth" | "rgbd"))
                        .filter(|_| shape.len() >= 3)
                        .map(|(cam, ch)| (cam.to_string(), ch.to_string()));
                    if let Some((_, ch)) = &image {
                        let want = match ch.as_str() {
                            "rgb" => 3,
                            "depth" => 1,
                            _ => 4,
                        };
                        if shape.last() != Some(&want) {
                            return Err(format!(
                                "observation item {name}: {want} channels expected, shape {shape:?}"
                            ));
                        }
                    }
                    out.push(ObsItem {
                        name: name.clone(),
                        offset,
                        len,
                        shape: shape.clone(),
                        image,
                    });
                    offset += len;
                }
                Ok(ObsLayout::Dict(out))
            }
            other => Err(format!(
                "observation space {other:?}: only a flat box or a dict of boxes is supported"
            )),
        }
    }

    /// Values per env in the flat buffer.
    pub fn flat_dim(&self) -> usize {
        match self {
            ObsLayout::Flat { dim } => *dim,
            ObsLayout::Dict(items) => items.iter().map(|i| i.len).sum(),
        }
    }

    /// The arrays a converted observation holds (one for a flat layout, with key `""`).
    pub fn out_keys(&self) -> Vec<OutKey> {
        match self {
            ObsLayout::Flat { dim } => vec![OutKey {
                key: String::new(),
                dtype: "float32",
                shape: vec![*dim],
                low: f32::NEG_INFINITY,
                high: f32::INFINITY,
            }],
            ObsLayout::Dict(items) => items.iter().flat_map(item_keys).collect(),
        }
    }
}

/// The output arrays of one item.
fn item_keys(item: &ObsItem) -> Vec<OutKey> {
    let Some((cam, ch)) = &item.image else {
        return vec![OutKey {
            key: item.name.clone(),
            dtype: "float32",
            shape: item.shape.clone(),
            low: f32::NEG_INFINITY,
            high: f32::INFINITY,
        }];
    };
    let with_channels = |c: usize| {
        let mut s = item.shape.clone();
        if let Some(last) = s.last_mut() {
            *last = c;
        }
        s
    };
    let rgb = OutKey {
        key: format!("{cam}_rgb"),
        dtype: "uint8",
        shape: with_channels(3),
        low: 0.0,
        high: 255.0,
    };
    let depth = OutKey {
        key: format!("{cam}_depth"),
        dtype: "float32",
        shape: with_channels(1),
        low: 0.0,
        high: f32::INFINITY,
    };
    match ch.as_str() {
        "rgb" => vec![rgb],
        "depth" => vec![depth],
        _ => vec![rgb, depth],
    }
}

/// Converted observation arrays of a batch of envs, one buffer per [`OutKey`] in order.
pub enum OutBuf {
    /// float32 values.
    F32(Vec<f32>),
    /// uint8 values.
    U8(Vec<u8>),
}

/// Converts `rows` flat per-env observations (`flat`, `rows x flat_dim`) into one buffer per
/// output key, each `rows x prod(shape)` row-major.
pub fn convert(layout: &ObsLayout, flat: &[f32], rows: usize) -> Vec<OutBuf> {
    let dim = layout.flat_dim();
    debug_assert_eq!(flat.len(), rows * dim);
    let items = match layout {
        ObsLayout::Flat { .. } => return vec![OutBuf::F32(flat.to_vec())],
        ObsLayout::Dict(items) => items,
    };
    let mut out = Vec::new();
    for item in items {
        let rows_of = || (0..rows).map(|r| &flat[r * dim + item.offset..][..item.len]);
        match item.image.as_ref().map(|(_, ch)| ch.as_str()) {
            None => out.push(OutBuf::F32(rows_of().flatten().copied().collect())),
            Some("rgb") => out.push(OutBuf::U8(rows_of().flatten().map(|v| to_u8(*v)).collect())),
            Some("depth") => out.push(OutBuf::F32(rows_of().flatten().copied().collect())),
            Some(_) => {
                let px = rows * item.len / 4;
                let mut rgb = Vec::with_capacity(px * 3);
                let mut depth = Vec::with_capacity(px);
                for row in rows_of() {
                    for p in row.chunks_exact(4) {
                        rgb.extend(p[..3].iter().map(|v| to_u8(*v)));
                        depth.push(p[3]);
                    }
                }
                out.push(OutBuf::U8(rgb));
                out.push(OutBuf::F32(depth));
            }
        }
    }
    out
}

/// An RGB value in [0, 1] as uint8 (rounded, clamped).
fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The flat action layout: the space the user sees and the named slices.
#[derive(Debug, Clone)]
pub struct ActLayout {
    /// `Discrete(n)` when the env takes one teleoperation key.
    pub discrete: Option<u64>,
    /// Values per env in the flat buffer.
    pub dim: usize,
    /// Lower bounds (box).
    pub low: Vec<f32>,
    /// Upper bounds (box).
    pub high: Vec<f32>,
    /// `(name, offset, len)` of each part (`franka/base`, `franka/arm`, ...).
    pub parts: Vec<(String, usize, usize)>,
}

impl ActLayout {
    /// The layout of an action space: a `Discrete` alone, or boxes (a dict of them flattened).
    pub fn of(space: &Space) -> Result<Self, String> {
        if let Space::Discrete { n } = space {
            return Ok(ActLayout {
                discrete: Some(*n),
                dim: 1,
                low: vec![0.0],
                high: vec![(*n as f32) - 1.0],
                parts: vec![("discrete".into(), 0, 1)],
            });
        }
        let items: Vec<(String, &Space)> = match space {
            Space::Dict(items) => items.iter().map(|(n, s)| (n.clone(), s)).collect(),
            other => vec![("action".to_string(), other)],
        };
        let mut out = ActLayout {
            discrete: None,
            dim: 0,
            low: Vec::new(),
            high: Vec::new(),
            parts: Vec::new(),
        };
        for (name, s) in items {
            let Space::Box { low, high, .. } = s else {
                return Err(format!(
                    "action item {name}: a Discrete action mixed with others is not supported"
                ));
            };
            out.parts.push((name, out.dim, low.len()));
            out.dim += low.len();
            out.low.extend_from_slice(low);
            out.high.extend_from_slice(high);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bx(shape: &[usize]) -> Space {
        let n = shape.iter().product();
        Space::Box {
            low: vec![0.0; n],
            high: vec![1.0; n],
            shape: shape.to_vec(),
        }
    }

    #[test]
    fn rgbd_items_split_into_uint8_rgb_and_float_depth() {
        let space = Space::Dict(vec![
            ("state".into(), bx(&[2])),
            ("robot_rgbd".into(), bx(&[1, 2, 4])),
        ]);
        let l = ObsLayout::of(&space).unwrap();
        let keys: Vec<_> = l.out_keys().into_iter().map(|k| (k.key, k.shape)).collect();
        assert_eq!(
            keys,
            [
                ("state".to_string(), vec![2]),
                ("robot_rgb".to_string(), vec![1, 2, 3]),
                ("robot_depth".to_string(), vec![1, 2, 1])
            ]
        );
        let flat = [7.0, 8.0, 0.0, 0.5, 1.0, 2.5, 1.2, -0.1, 0.2, 3.5];
        let out = convert(&l, &flat, 1);
        match (&out[0], &out[1], &out[2]) {
            (OutBuf::F32(s), OutBuf::U8(rgb), OutBuf::F32(d)) => {
                assert_eq!(s, &[7.0, 8.0]);
                assert_eq!(rgb, &[0, 128, 255, 255, 0, 51]);
                assert_eq!(d, &[2.5, 3.5]);
            }
            _ => panic!("wrong buffer kinds"),
        }
    }

    #[test]
    fn action_dicts_of_boxes_flatten_in_order() {
        let space = Space::Dict(vec![
            ("a/base".into(), bx(&[3])),
            ("a/arm".into(), bx(&[7])),
        ]);
        let l = ActLayout::of(&space).unwrap();
        assert_eq!(l.dim, 10);
        assert_eq!(l.parts[1], ("a/arm".to_string(), 3, 7));
        let d = ActLayout::of(&Space::Discrete { n: 14 }).unwrap();
        assert_eq!((d.discrete, d.dim), (Some(14), 1));
    }
}
