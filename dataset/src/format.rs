//! The LeRobot v3.0 layout: `meta/info.json`, features, file paths.

use std::path::{Path, PathBuf};

use serde::de::{MapAccess, Visitor};
use serde::ser::SerializeMap;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use serde_json::Value;

use crate::DatasetError;

/// `codebase_version` of the datasets written and read.
pub const CODEBASE_VERSION: &str = "v3.0";
/// Files per chunk folder (LeRobot's `DEFAULT_CHUNK_SIZE`).
pub const CHUNKS_SIZE: usize = 1000;
/// `data_path` of `info.json`.
pub const DATA_PATH: &str = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet";
/// `video_path` of `info.json`.
pub const VIDEO_PATH: &str = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4";
/// The features every frame has, after the user's (names, dtypes), all of shape `[1]`.
pub const DEFAULT_FEATURES: [(&str, &str); 5] = [
    ("timestamp", "float32"),
    ("frame_index", "int64"),
    ("episode_index", "int64"),
    ("index", "int64"),
    ("task_index", "int64"),
];

/// One feature of `info.json`: `dtype` (`float32`, `int64`, `bool`, or `video`), `shape`,
/// `names`, and for videos `info` (codec, size, fps).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Feature {
    /// numpy dtype name, or `video`.
    pub dtype: String,
    /// Shape of one frame's value (`[1]` for a scalar; `[H, W, 3]` for a video).
    pub shape: Vec<usize>,
    /// Names of the values (a list, or null).
    pub names: Value,
    /// Video stream facts (`video.height`, `video.codec`, ...), videos only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub info: Option<Value>,
}

impl Feature {
    /// A float32 vector (or scalar for `dim == 1`) with value names.
    pub fn f32(names: &[String]) -> Self {
        Self {
            dtype: "float32".into(),
            shape: vec![names.len().max(1)],
            names: Value::from(names.to_vec()),
            info: None,
        }
    }

    /// A scalar of `dtype` without names.
    pub fn scalar(dtype: &str) -> Self {
        Self {
            dtype: dtype.into(),
            shape: vec![1],
            names: Value::Null,
            info: None,
        }
    }

    /// A video of `width x height` RGB frames at `fps`, encoded with `codec` (`h264`).
    pub fn video(width: u32, height: u32, fps: u32, codec: &str) -> Self {
        Self {
            dtype: "video".into(),
            shape: vec![height as usize, width as usize, 3],
            names: serde_json::json!(["height", "width", "channels"]),
            info: Some(serde_json::json!({
                "video.height": height, "video.width": width, "video.codec": codec,
                "video.pix_fmt": "yuv420p", "video.is_depth_map": false, "video.fps": fps,
                "video.channels": 3, "has_audio": false
            })),
        }
    }

    /// Whether it is stored as a video (not in the data files).
    pub fn is_video(&self) -> bool {
        self.dtype == "video"
    }

    /// Values per frame (the product of the shape).
    pub fn dim(&self) -> usize {
        self.shape.iter().product()
    }
}

/// Features in their order (`info.json` keeps it: data columns follow it).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Features(pub Vec<(String, Feature)>);

impl Features {
    /// The feature called `name`.
    pub fn get(&self, name: &str) -> Option<&Feature> {
        self.0.iter().find(|(n, _)| n == name).map(|(_, f)| f)
    }

    /// The user's features followed by the five default ones.
    pub fn with_defaults(user: Vec<(String, Feature)>) -> Self {
        let mut all = user;
        for (name, dtype) in DEFAULT_FEATURES {
            all.push((name.to_string(), Feature::scalar(dtype)));
        }
        Self(all)
    }

    /// The video features' names.
    pub fn videos(&self) -> Vec<&str> {
        self.0
            .iter()
            .filter(|(_, f)| f.is_video())
            .map(|(n, _)| n.as_str())
            .collect()
    }
}

impl Serialize for Features {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in &self.0 {
            m.serialize_entry(k, v)?;
        }
        m.end()
    }
}

impl<'de> Deserialize<'de> for Features {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Features;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a map of feature names to {dtype, shape, names}")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut a: A) -> Result<Features, A::Error> {
                let mut out = Vec::new();
                while let Some((k, v)) = a.next_entry::<String, Feature>()? {
                    out.push((k, v));
                }
                Ok(Features(out))
            }
        }
        d.deserialize_map(V)
    }
}

/// `meta/info.json`, its keys in LeRobot's order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Info {
    /// `v3.0`.
    pub codebase_version: String,
    /// The robot (`franka_ridgeback`, `spot`), or null.
    pub robot_type: Option<String>,
    /// Episodes committed.
    pub total_episodes: usize,
    /// Frames (data rows) of those episodes.
    pub total_frames: usize,
    /// Rows of `meta/tasks.parquet`.
    pub total_tasks: usize,
    /// Files per chunk folder.
    pub chunks_size: usize,
    /// LeRobot's data file size limit (this writer writes one episode per file).
    pub data_files_size_in_mb: usize,
    /// LeRobot's video file size limit (one episode per file here).
    pub video_files_size_in_mb: usize,
    /// Frames per second.
    pub fps: u32,
    /// `{"train": "0:N"}` once there are episodes.
    pub splits: serde_json::Map<String, Value>,
    /// The data file template.
    pub data_path: String,
    /// The video file template (null without videos).
    pub video_path: Option<String>,
    /// The features.
    pub features: Features,
}

impl Info {
    /// An empty dataset's info.
    pub fn new(fps: u32, robot_type: Option<String>, features: Features) -> Self {
        let has_video = !features.videos().is_empty();
        Self {
            codebase_version: CODEBASE_VERSION.into(),
            robot_type,
            total_episodes: 0,
            total_frames: 0,
            total_tasks: 0,
            chunks_size: CHUNKS_SIZE,
            data_files_size_in_mb: 100,
            video_files_size_in_mb: 500,
            fps,
            splits: Default::default(),
            data_path: DATA_PATH.into(),
            video_path: has_video.then(|| VIDEO_PATH.into()),
            features,
        }
    }

    /// Reads `DIR/meta/info.json`.
    pub fn read(dir: &Path) -> Result<Self, DatasetError> {
        let path = dir.join("meta/info.json");
        let text = std::fs::read_to_string(&path).map_err(|e| DatasetError::io(&path, e))?;
        let info: Info = serde_json::from_str(&text).map_err(|e| {
            DatasetError::new(format!(
                "{}:{}:{}: {e}",
                path.display(),
                e.line(),
                e.column()
            ))
        })?;
        if info.codebase_version != CODEBASE_VERSION {
            return Err(DatasetError::new(format!(
                "{}: codebase_version = {:?}: only {CODEBASE_VERSION} datasets are read",
                path.display(),
                info.codebase_version
            )));
        }
        if info.fps == 0 || info.chunks_size == 0 {
            return Err(DatasetError::new(format!(
                "{}: fps = {}, chunks_size = {}: both must be at least 1",
                path.display(),
                info.fps,
                info.chunks_size
            )));
        }
        for (name, dtype) in DEFAULT_FEATURES {
            match info.features.get(name) {
                Some(f) if f.dtype == dtype && f.shape == [1] => {}
                _ => {
                    return Err(DatasetError::new(format!(
                        "{}: features.{name}: missing or not {dtype} of shape [1]",
                        path.display()
                    )))
                }
            }
        }
        Ok(info)
    }
}

/// `(chunk_index, file_index)` of the file of episode `episode` (one episode per file).
pub fn chunk_file(episode: usize, chunks_size: usize) -> (usize, usize) {
    (episode / chunks_size, episode % chunks_size)
}

/// `DIR/data/chunk-CCC/file-FFF.parquet`.
pub fn data_file(dir: &Path, chunk: usize, file: usize) -> PathBuf {
    dir.join(format!("data/chunk-{chunk:03}/file-{file:03}.parquet"))
}

/// `DIR/videos/KEY/chunk-CCC/file-FFF.mp4`.
pub fn video_file(dir: &Path, key: &str, chunk: usize, file: usize) -> PathBuf {
    dir.join(format!("videos/{key}/chunk-{chunk:03}/file-{file:03}.mp4"))
}

/// `DIR/meta/episodes/chunk-000/file-000.parquet`: every episode's row (rewritten whole).
pub fn episodes_file(dir: &Path) -> PathBuf {
    dir.join("meta/episodes/chunk-000/file-000.parquet")
}
