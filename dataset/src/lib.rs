//! Demonstration datasets in the LeRobot v3.0 layout, as modesuite's `record` writes them and
//! `dataset info|replay` reads them:
//!
//! ```text
//! meta/info.json  meta/stats.json  meta/tasks.parquet  meta/modesuite.json
//! meta/episodes/chunk-000/file-000.parquet      one row per episode
//! data/chunk-CCC/file-FFF.parquet               one episode per file: its frames
//! videos/<feature>/chunk-CCC/file-FFF.mp4       one episode per file per camera
//! ```
//!
//! Episodes are appended atomically ([`writer`]): a recording killed at any moment leaves a
//! dataset with every episode committed before the kill. `meta/modesuite.json` (modesuite's
//! own, ignored by LeRobot) says what recorded the dataset; the episodes file's
//! `modesuite/seed` and `modesuite/success` columns say each episode's env seed and outcome.

pub mod episodes;
pub mod format;
pub mod reader;
pub mod stats;
pub mod table;
pub mod writer;

pub use format::{Feature, Features, Info};
pub use reader::Dataset;
pub use stats::FeatureStats;
pub use table::Column;
pub use writer::{DatasetWriter, EpisodeInput};

/// What went wrong reading or writing a dataset (names the file).
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetError(pub String);

impl DatasetError {
    /// An error with this message.
    pub fn new(msg: impl Into<String>) -> Self {
        Self(msg.into())
    }

    /// An I/O error on `path`.
    pub fn io(path: &std::path::Path, e: std::io::Error) -> Self {
        Self(format!("{}: {e}", path.display()))
    }
}

impl std::fmt::Display for DatasetError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for DatasetError {}
