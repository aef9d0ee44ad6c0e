//! Appending episodes to a dataset, each completely or not at all.
//!
//! An episode is committed in this order: its data file (`data/chunk-C/file-F.parquet`, one
//! episode per file, written atomically) and its videos (renamed into `videos/`), then the
//! episodes file, `meta/tasks.parquet` and `meta/stats.json` (each rewritten atomically), and
//! last `meta/info.json`, whose `total_episodes` is the commit: readers take the first
//! `total_episodes` episodes. A writer killed before that leaves files of one unfinished
//! episode that no metadata names; their rows come after every committed row in path order (so
//! LeRobot's loader, which reads every data file, still finds each committed frame at its
//! `index`), `Dataset::open` lists them as orphans, and the next writer on the folder deletes
//! them before it appends.

use std::path::{Path, PathBuf};

use crate::episodes::{self, EpisodeMeta, VideoSpan};
use crate::format::{chunk_file, data_file, video_file, Info};
use crate::reader::Dataset;
use crate::stats::FeatureStats;
use crate::table::{self, Column};
use crate::DatasetError;

/// One finished episode to append.
#[derive(Debug, Clone)]
pub struct EpisodeInput {
    /// Its task (natural-language instruction).
    pub task: String,
    /// One column per non-video user feature, in the features' order, one row per frame.
    pub columns: Vec<(String, Column)>,
    /// Per video feature (in the features' order): the finished MP4 (moved into the dataset)
    /// and the statistics of its frames.
    pub videos: Vec<(PathBuf, FeatureStats)>,
    /// The env seed it was recorded from.
    pub seed: u64,
    /// Whether it ended in success (None: no criterion).
    pub success: Option<bool>,
}

/// A dataset open for appending.
pub struct DatasetWriter {
    dir: PathBuf,
    info: Info,
    tasks: Vec<String>,
    episodes: Vec<EpisodeMeta>,
}

fn write_json(path: &Path, v: &impl serde::Serialize) -> Result<(), DatasetError> {
    let text = serde_json::to_string_pretty(v)
        .map_err(|e| DatasetError::new(format!("{}: {e}", path.display())))?;
    modesuite_engine::fsio::write_atomic(path, text.as_bytes())
        .map_err(|e| DatasetError::new(format!("{}: {e}", path.display())))
}

impl DatasetWriter {
    /// Opens the dataset in `dir` for appending, or creates it with `info` (its features, fps
    /// and robot) and `extra` (`meta/modesuite.json`: what made it) when `dir` has none. An
    /// existing dataset must have the same features and fps; files of an episode whose
    /// recording was killed before its commit are deleted first.
    pub fn open_or_create(
        dir: &Path,
        info: Info,
        extra: &serde_json::Value,
    ) -> Result<Self, DatasetError> {
        if dir.join("meta/info.json").exists() {
            let ds = Dataset::open(dir)?;
            if ds.info.features != info.features || ds.info.fps != info.fps {
                return Err(DatasetError::new(format!(
                    "{}: a dataset with other features or fps is there already (features {:?}, fps {}); record into a new folder",
                    dir.display(),
                    ds.info.features.0.iter().map(|(n, f)| format!("{n} {} {:?}", f.dtype, f.shape)).collect::<Vec<_>>(),
                    ds.info.fps
                )));
            }
            for orphan in &ds.orphans {
                std::fs::remove_file(orphan).map_err(|e| DatasetError::io(orphan, e))?;
            }
            return Ok(Self {
                dir: dir.to_path_buf(),
                info: ds.info,
                tasks: ds.tasks,
                episodes: ds.episodes,
            });
        }
        std::fs::create_dir_all(dir.join("meta")).map_err(|e| DatasetError::io(dir, e))?;
        write_json(&dir.join("meta/modesuite.json"), extra)?;
        write_json(&dir.join("meta/info.json"), &info)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            info,
            tasks: Vec::new(),
            episodes: Vec::new(),
        })
    }

    /// The dataset's info as committed.
    pub fn info(&self) -> &Info {
        &self.info
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Appends one episode (see the module's commit order). On any error (a full disk, a bad
    /// column) the dataset is left as it was before the call, and so is this writer.
    pub fn append(&mut self, ep: EpisodeInput) -> Result<usize, DatasetError> {
        let e = self.info.total_episodes;
        let (chunk, file) = chunk_file(e, self.info.chunks_size);
        let data = data_file(&self.dir, chunk, file);
        let videos: Vec<PathBuf> = self
            .info
            .features
            .videos()
            .iter()
            .map(|k| video_file(&self.dir, k, chunk, file))
            .collect();
        let result = self.try_append(ep, e, chunk, file, &data, &videos);
        if result.is_err() {
            // nothing names these files yet: remove them so the folder stays as it was
            for p in std::iter::once(&data).chain(&videos) {
                let _ = std::fs::remove_file(p);
            }
        }
        result
    }

    fn try_append(
        &mut self,
        ep: EpisodeInput,
        e: usize,
        chunk: usize,
        file: usize,
        data: &Path,
        video_paths: &[PathBuf],
    ) -> Result<usize, DatasetError> {
        let len = self.check(&ep)?;
        let fps = self.info.fps;
        let task_index = match self.tasks.iter().position(|t| *t == ep.task) {
            Some(i) => i,
            None => self.tasks.len(),
        };
        let from = self.info.total_frames;
        let mut cols = ep.columns;
        cols.push((
            "timestamp".into(),
            Column::F32 {
                dim: 1,
                values: (0..len)
                    .map(|i| (i as f64 / f64::from(fps)) as f32)
                    .collect(),
            },
        ));
        cols.push(("frame_index".into(), Column::I64((0..len as i64).collect())));
        cols.push(("episode_index".into(), Column::I64(vec![e as i64; len])));
        cols.push((
            "index".into(),
            Column::I64((from as i64..(from + len) as i64).collect()),
        ));
        cols.push((
            "task_index".into(),
            Column::I64(vec![task_index as i64; len]),
        ));
        // statistics of every feature, the videos' from their frames
        let mut stats = Vec::new();
        let mut video_stats = ep.videos.iter().map(|(_, s)| s.clone());
        for (name, f) in &self.info.features.0 {
            let s = if f.is_video() {
                video_stats.next()
            } else {
                cols.iter()
                    .find(|(n, _)| n == name)
                    .map(|(_, c)| FeatureStats::of(&c.as_f64(), c.dim()))
            };
            if let Some(s) = s {
                stats.push((name.clone(), s));
            }
        }
        table::write(
            data,
            cols.iter().map(|(n, c)| c.to_arrow(n)).collect(),
            Default::default(),
        )?;
        let mut spans = Vec::new();
        for ((staged, _), (path, key)) in ep
            .videos
            .iter()
            .zip(video_paths.iter().zip(self.info.features.videos()))
        {
            if let Some(d) = path.parent() {
                std::fs::create_dir_all(d).map_err(|err| DatasetError::io(d, err))?;
            }
            std::fs::rename(staged, path).map_err(|err| {
                DatasetError::new(format!(
                    "moving {} to {}: {err}",
                    staged.display(),
                    path.display()
                ))
            })?;
            spans.push(VideoSpan {
                key: key.to_string(),
                chunk,
                file,
                from_timestamp: 0.0,
                to_timestamp: len as f64 / f64::from(fps),
            });
        }
        let meta = EpisodeMeta {
            index: e,
            tasks: vec![ep.task.clone()],
            length: len,
            data_chunk: chunk,
            data_file: file,
            from_index: from,
            to_index: from + len,
            videos: spans,
            stats,
            seed: ep.seed,
            success: ep.success,
        };
        let mut episodes = self.episodes.clone();
        episodes.push(meta);
        let mut tasks = self.tasks.clone();
        let new_task = task_index == tasks.len();
        if new_task {
            tasks.push(ep.task);
        }
        let mut info = self.info.clone();
        info.total_episodes = e + 1;
        info.total_frames = from + len;
        info.total_tasks = tasks.len();
        info.splits = serde_json::Map::from_iter([(
            "train".to_string(),
            serde_json::Value::from(format!("0:{}", e + 1)),
        )]);
        episodes::write_episodes(&self.dir, &info, &episodes)?;
        // the tasks table changes only with a new task
        if new_task {
            episodes::write_tasks(&self.dir, &tasks)?;
        }
        episodes::write_stats(&self.dir, &info, &episodes)?;
        // the commit
        write_json(&self.dir.join("meta/info.json"), &info)?;
        self.info = info;
        self.episodes = episodes;
        self.tasks = tasks;
        Ok(e)
    }

    /// Checks an episode's columns against the features; its length.
    fn check(&self, ep: &EpisodeInput) -> Result<usize, DatasetError> {
        let user: Vec<_> = self
            .info
            .features
            .0
            .iter()
            .filter(|(n, f)| {
                !f.is_video() && !crate::format::DEFAULT_FEATURES.iter().any(|(d, _)| d == n)
            })
            .collect();
        let names: Vec<&str> = ep.columns.iter().map(|(n, _)| n.as_str()).collect();
        let want: Vec<&str> = user.iter().map(|(n, _)| n.as_str()).collect();
        if names != want {
            return Err(DatasetError::new(format!(
                "episode columns {names:?}: expected {want:?}"
            )));
        }
        let len = ep.columns.first().map_or(0, |(_, c)| c.rows());
        if len == 0 {
            return Err(DatasetError::new("an episode needs at least one frame"));
        }
        for ((name, c), (_, f)) in ep.columns.iter().zip(&user) {
            if c.rows() != len || c.dim() != f.dim() || c.dtype() != f.dtype {
                return Err(DatasetError::new(format!(
                    "column {name}: {} rows of {} {} values, expected {len} rows of {} {}",
                    c.rows(),
                    c.dim(),
                    c.dtype(),
                    f.dim(),
                    f.dtype
                )));
            }
        }
        if ep.videos.len() != self.info.features.videos().len() {
            return Err(DatasetError::new(format!(
                "{} videos given, the dataset has {} video features",
                ep.videos.len(),
                self.info.features.videos().len()
            )));
        }
        Ok(len)
    }
}
