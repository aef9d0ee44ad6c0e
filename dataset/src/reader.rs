//! Reading a dataset: its metadata, an episode's frames, and what an interrupted recording
//! left behind.

use std::path::{Path, PathBuf};

use crate::episodes::{self, EpisodeMeta};
use crate::format::{chunk_file, data_file, video_file, Info};
use crate::table::{self, Column};
use crate::DatasetError;

/// A dataset as committed (`meta/info.json`'s `total_episodes` episodes).
#[derive(Debug, Clone)]
pub struct Dataset {
    /// Its folder.
    pub dir: PathBuf,
    /// `meta/info.json`.
    pub info: Info,
    /// `meta/tasks.parquet`, in `task_index` order.
    pub tasks: Vec<String>,
    /// One row per committed episode.
    pub episodes: Vec<EpisodeMeta>,
    /// `meta/modesuite.json` (what recorded it), or null.
    pub extra: serde_json::Value,
    /// Files of an episode whose recording was killed before its commit (ignored; the next
    /// writer deletes them), and temporary files of atomic writes.
    pub orphans: Vec<PathBuf>,
}

fn files_under(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in rd.flatten() {
        let p = entry.path();
        if p.is_dir() {
            files_under(&p, out);
        } else {
            out.push(p);
        }
    }
}

impl Dataset {
    /// Opens the dataset in `dir`: reads its metadata and checks that every committed
    /// episode's files are there.
    pub fn open(dir: &Path) -> Result<Self, DatasetError> {
        let info = Info::read(dir)?;
        let episodes = episodes::read_episodes(dir, &info)?;
        let tasks = episodes::read_tasks(dir)?;
        let extra_path = dir.join("meta/modesuite.json");
        let extra = match std::fs::read_to_string(&extra_path) {
            Ok(t) => serde_json::from_str(&t).map_err(|e| {
                DatasetError::new(format!(
                    "{}:{}:{}: {e}",
                    extra_path.display(),
                    e.line(),
                    e.column()
                ))
            })?,
            Err(_) => serde_json::Value::Null,
        };
        let mut expected = Vec::new();
        for e in &episodes {
            expected.push(data_file(dir, e.data_chunk, e.data_file));
            for v in &e.videos {
                expected.push(video_file(dir, &v.key, v.chunk, v.file));
            }
        }
        for p in &expected {
            if !p.is_file() {
                return Err(DatasetError::new(format!(
                    "{}: missing (named by meta/episodes for a committed episode)",
                    p.display()
                )));
            }
        }
        // what no committed episode names under data/ and videos/, and partial files anywhere
        let mut all = Vec::new();
        for sub in ["data", "videos", "meta"] {
            files_under(&dir.join(sub), &mut all);
        }
        let orphans = all
            .into_iter()
            .filter(|p| {
                let name = p
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let partial = name.starts_with('.') && name.contains(".partial");
                let in_data = p.starts_with(dir.join("data")) || p.starts_with(dir.join("videos"));
                partial || (in_data && !expected.contains(p))
            })
            .collect();
        Ok(Self {
            dir: dir.to_path_buf(),
            info,
            tasks,
            episodes,
            extra,
            orphans,
        })
    }

    /// Every data column of episode `i` (user features, then the five default ones).
    pub fn read_episode(&self, i: usize) -> Result<Vec<(String, Column)>, DatasetError> {
        let e = self.episodes.get(i).ok_or_else(|| {
            DatasetError::new(format!(
                "episode {i}: the dataset has {} (0..{})",
                self.episodes.len(),
                self.episodes.len()
            ))
        })?;
        let path = data_file(&self.dir, e.data_chunk, e.data_file);
        let mut cols: Vec<(String, Column)> = Vec::new();
        for batch in table::read(&path)? {
            let ep_col = table::column(&batch, "episode_index", &path)?;
            let Some(Column::I64(ep_idx)) = Column::from_arrow(ep_col.as_ref()) else {
                return Err(DatasetError::new(format!(
                    "{}: episode_index is not int64",
                    path.display()
                )));
            };
            let rows: Vec<usize> = (0..ep_idx.len())
                .filter(|&r| ep_idx[r] == i as i64)
                .collect();
            for (name, f) in &self.info.features.0 {
                if f.is_video() {
                    continue;
                }
                let a = table::column(&batch, name, &path)?;
                let c = Column::from_arrow(a.as_ref()).ok_or_else(|| {
                    DatasetError::new(format!(
                        "{}: column {name:?} is {}, not a feature column",
                        path.display(),
                        a.data_type()
                    ))
                })?;
                let picked = pick(&c, &rows);
                match cols.iter_mut().find(|(n, _)| n == name) {
                    Some((_, acc)) => append(acc, picked),
                    None => cols.push((name.clone(), picked)),
                }
            }
        }
        let len = cols.first().map_or(0, |(_, c)| c.rows());
        if len != e.length {
            return Err(DatasetError::new(format!(
                "{}: {len} rows of episode {i}, meta/episodes says {}",
                path.display(),
                e.length
            )));
        }
        Ok(cols)
    }

    /// The video file of feature `key` of episode `i`.
    pub fn video_path(&self, key: &str, i: usize) -> Option<PathBuf> {
        let e = self.episodes.get(i)?;
        let v = e.videos.iter().find(|v| v.key == key)?;
        Some(video_file(&self.dir, key, v.chunk, v.file))
    }

    /// `(chunk, file)` the next episode will be written to.
    pub fn next_chunk_file(&self) -> (usize, usize) {
        chunk_file(self.info.total_episodes, self.info.chunks_size)
    }
}

fn pick(c: &Column, rows: &[usize]) -> Column {
    match c {
        Column::F32 { dim, values } => Column::F32 {
            dim: *dim,
            values: rows
                .iter()
                .flat_map(|&r| values[r * dim..(r + 1) * dim].iter().copied())
                .collect(),
        },
        Column::I64(v) => Column::I64(rows.iter().map(|&r| v[r]).collect()),
        Column::Bool(v) => Column::Bool(rows.iter().map(|&r| v[r]).collect()),
    }
}

fn append(acc: &mut Column, more: Column) {
    match (acc, more) {
        (Column::F32 { values, .. }, Column::F32 { values: m, .. }) => values.extend(m),
        (Column::I64(v), Column::I64(m)) => v.extend(m),
        (Column::Bool(v), Column::Bool(m)) => v.extend(m),
        _ => {}
    }
}
