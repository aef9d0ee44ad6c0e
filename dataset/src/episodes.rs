//! `meta/episodes/…parquet` (one row per episode), `meta/tasks.parquet` and `meta/stats.json`.

use std::collections::HashMap;
use std::path::Path;

use arrow_array::{
    Array, BooleanArray, Float64Array, Int64Array, ListArray, StringArray, UInt64Array,
};

use crate::format::{episodes_file, Info};
use crate::stats::{FeatureStats, STAT_NAMES};
use crate::table;
use crate::DatasetError;

/// Where one video feature's frames of an episode are.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoSpan {
    /// The video feature.
    pub key: String,
    /// Its chunk folder.
    pub chunk: usize,
    /// Its file in the chunk.
    pub file: usize,
    /// Seconds into the file where the episode starts.
    pub from_timestamp: f64,
    /// Seconds into the file where it ends.
    pub to_timestamp: f64,
}

/// One episode's row of the episodes file.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeMeta {
    /// `episode_index`.
    pub index: usize,
    /// Its task strings.
    pub tasks: Vec<String>,
    /// Frames.
    pub length: usize,
    /// `data/chunk_index`.
    pub data_chunk: usize,
    /// `data/file_index`.
    pub data_file: usize,
    /// Global index of its first frame.
    pub from_index: usize,
    /// Global index after its last frame (exclusive).
    pub to_index: usize,
    /// Its videos.
    pub videos: Vec<VideoSpan>,
    /// Statistics of each feature over the episode.
    pub stats: Vec<(String, FeatureStats)>,
    /// The env seed it was recorded from (`modesuite/seed`).
    pub seed: u64,
    /// Whether it ended in the task's success (`modesuite/success`; null without a criterion).
    pub success: Option<bool>,
}

/// Writes every episode's row (the whole file, atomically).
pub fn write_episodes(dir: &Path, info: &Info, eps: &[EpisodeMeta]) -> Result<(), DatasetError> {
    let ints = |name: &str, f: &dyn Fn(&EpisodeMeta) -> usize| {
        let v: Vec<i64> = eps.iter().map(|e| f(e) as i64).collect();
        crate::table::Column::I64(v).to_arrow(name)
    };
    let mut cols = vec![
        ints("episode_index", &|e| e.index),
        table::list_str(
            "tasks",
            &eps.iter().map(|e| e.tasks.clone()).collect::<Vec<_>>(),
        ),
        ints("length", &|e| e.length),
        ints("data/chunk_index", &|e| e.data_chunk),
        ints("data/file_index", &|e| e.data_file),
        ints("dataset_from_index", &|e| e.from_index),
        ints("dataset_to_index", &|e| e.to_index),
    ];
    for (k, key) in info.features.videos().into_iter().enumerate() {
        let span = |e: &EpisodeMeta| e.videos[k].clone();
        cols.push(ints(&format!("videos/{key}/chunk_index"), &|e| {
            span(e).chunk
        }));
        cols.push(ints(&format!("videos/{key}/file_index"), &|e| span(e).file));
        let from: Vec<f64> = eps.iter().map(|e| span(e).from_timestamp).collect();
        let to: Vec<f64> = eps.iter().map(|e| span(e).to_timestamp).collect();
        cols.push(table::f64s(&format!("videos/{key}/from_timestamp"), &from));
        cols.push(table::f64s(&format!("videos/{key}/to_timestamp"), &to));
    }
    if let Some(first) = eps.first() {
        for (f, (name, _)) in first.stats.iter().enumerate() {
            for stat in STAT_NAMES {
                let col = format!("stats/{name}/{stat}");
                if stat == "count" {
                    let rows: Vec<Vec<i64>> = eps
                        .iter()
                        .map(|e| vec![e.stats[f].1.count as i64])
                        .collect();
                    cols.push(table::list_i64(&col, &rows));
                } else {
                    let rows: Vec<Vec<f64>> =
                        eps.iter().map(|e| e.stats[f].1.values(stat)).collect();
                    cols.push(table::list_f64(&col, &rows));
                }
            }
        }
    }
    cols.push(table::u64s(
        "modesuite/seed",
        &eps.iter().map(|e| e.seed).collect::<Vec<_>>(),
    ));
    cols.push(table::opt_bools(
        "modesuite/success",
        &eps.iter().map(|e| e.success).collect::<Vec<_>>(),
    ));
    cols.push(ints("meta/episodes/chunk_index", &|_| 0));
    cols.push(ints("meta/episodes/file_index", &|_| 0));
    table::write(&episodes_file(dir), cols, HashMap::new())
}

/// Reads the first `info.total_episodes` rows of the episodes file (rows after them belong to
/// an episode whose recording was killed before its commit, and are ignored).
pub fn read_episodes(dir: &Path, info: &Info) -> Result<Vec<EpisodeMeta>, DatasetError> {
    let path = episodes_file(dir);
    if info.total_episodes == 0 && !path.exists() {
        return Ok(Vec::new());
    }
    let mut out = Vec::new();
    let videos = info.features.videos();
    let stat_features: Vec<(&str, bool)> = info
        .features
        .0
        .iter()
        .map(|(n, f)| (n.as_str(), f.is_video()))
        .collect();
    for batch in table::read(&path)? {
        let int = |name: &str| -> Result<&Int64Array, DatasetError> {
            table::get::<Int64Array>(&batch, name, "int64", &path)
        };
        let index = int("episode_index")?;
        let tasks = table::get::<ListArray>(&batch, "tasks", "list<string>", &path)?;
        let length = int("length")?;
        let (dc, df) = (int("data/chunk_index")?, int("data/file_index")?);
        let (from, to) = (int("dataset_from_index")?, int("dataset_to_index")?);
        let seed = table::get::<UInt64Array>(&batch, "modesuite/seed", "uint64", &path)?;
        let success = table::get::<BooleanArray>(&batch, "modesuite/success", "bool", &path)?;
        for r in 0..batch.num_rows() {
            if out.len() == info.total_episodes {
                break;
            }
            let mut spans = Vec::new();
            for key in &videos {
                let f = |s: &str| format!("videos/{key}/{s}");
                let ts = |s: &str| -> Result<f64, DatasetError> {
                    let n = f(s);
                    Ok(table::get::<Float64Array>(&batch, &n, "double", &path)?.value(r))
                };
                spans.push(VideoSpan {
                    key: key.to_string(),
                    chunk: int(&f("chunk_index"))?.value(r) as usize,
                    file: int(&f("file_index"))?.value(r) as usize,
                    from_timestamp: ts("from_timestamp")?,
                    to_timestamp: ts("to_timestamp")?,
                });
            }
            let mut stats = Vec::new();
            for (name, image) in &stat_features {
                let get = |stat: &str| -> Option<Vec<f64>> {
                    let col = batch.column_by_name(&format!("stats/{name}/{stat}"))?;
                    table::list_row_f64(col.as_any().downcast_ref::<ListArray>()?, r)
                };
                if let Some(s) = FeatureStats::from_values(get, *image) {
                    stats.push((name.to_string(), s));
                }
            }
            let bad =
                |what: &str| DatasetError::new(format!("{}: row {r}: {what}", path.display()));
            let e = EpisodeMeta {
                index: index.value(r) as usize,
                tasks: table::list_row_str(tasks, r)
                    .ok_or_else(|| bad("tasks is not a list of strings"))?,
                length: length.value(r) as usize,
                data_chunk: dc.value(r) as usize,
                data_file: df.value(r) as usize,
                from_index: from.value(r) as usize,
                to_index: to.value(r) as usize,
                videos: spans,
                stats,
                seed: seed.value(r),
                success: success.is_valid(r).then(|| success.value(r)),
            };
            if e.index != out.len() {
                return Err(bad(&format!(
                    "episode_index = {}, expected {}",
                    e.index,
                    out.len()
                )));
            }
            out.push(e);
        }
    }
    if out.len() != info.total_episodes {
        return Err(DatasetError::new(format!(
            "{}: {} episode rows, but meta/info.json has total_episodes = {}",
            path.display(),
            out.len(),
            info.total_episodes
        )));
    }
    Ok(out)
}

/// Writes `meta/tasks.parquet`: the task strings and their `task_index`, with the pandas
/// metadata that makes the task the frame's index (as LeRobot reads it).
pub fn write_tasks(dir: &Path, tasks: &[String]) -> Result<(), DatasetError> {
    let idx: Vec<i64> = (0..tasks.len() as i64).collect();
    let pandas = serde_json::json!({
        "index_columns": ["task"],
        "column_indexes": [{"name": null, "field_name": null, "pandas_type": "unicode",
                            "numpy_type": "object", "metadata": {"encoding": "UTF-8"}}],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64",
             "numpy_type": "int64", "metadata": null},
            {"name": "task", "field_name": "task", "pandas_type": "unicode",
             "numpy_type": "object", "metadata": null}
        ],
        "creator": {"library": "modesuite", "version": env!("CARGO_PKG_VERSION")},
        "pandas_version": "2.2.3"
    });
    let meta = HashMap::from([("pandas".to_string(), pandas.to_string())]);
    table::write(
        &dir.join("meta/tasks.parquet"),
        vec![
            crate::table::Column::I64(idx).to_arrow("task_index"),
            table::strings("task", tasks),
        ],
        meta,
    )
}

/// Reads `meta/tasks.parquet` (in `task_index` order).
pub fn read_tasks(dir: &Path) -> Result<Vec<String>, DatasetError> {
    let path = dir.join("meta/tasks.parquet");
    if !path.exists() {
        return Ok(Vec::new());
    }
    let mut out: Vec<(i64, String)> = Vec::new();
    for batch in table::read(&path)? {
        let idx = table::get::<Int64Array>(&batch, "task_index", "int64", &path)?;
        let task = table::get::<StringArray>(&batch, "task", "string", &path)?;
        for r in 0..batch.num_rows() {
            out.push((idx.value(r), task.value(r).to_string()));
        }
    }
    out.sort();
    Ok(out.into_iter().map(|(_, t)| t).collect())
}

/// Writes `meta/stats.json`: each feature's statistics over every episode.
pub fn write_stats(dir: &Path, info: &Info, eps: &[EpisodeMeta]) -> Result<(), DatasetError> {
    let mut m = serde_json::Map::new();
    for (name, _) in &info.features.0 {
        let parts: Vec<&FeatureStats> = eps
            .iter()
            .filter_map(|e| e.stats.iter().find(|(n, _)| n == name).map(|(_, s)| s))
            .collect();
        if let Some(s) = FeatureStats::aggregate(&parts) {
            m.insert(name.clone(), s.to_json());
        }
    }
    let path = dir.join("meta/stats.json");
    let text = serde_json::to_string_pretty(&serde_json::Value::Object(m))
        .map_err(|e| DatasetError::new(format!("{}: {e}", path.display())))?;
    modesuite_engine::fsio::write_atomic(&path, text.as_bytes())
        .map_err(|e| DatasetError::new(format!("{}: {e}", path.display())))
}
