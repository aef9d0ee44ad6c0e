//! Where scenes come from: [`SceneSource`], [`parse_str`], [`load_file`], and the RON options and
//! error positions shared with plugin-owned parameters ([`ron_options`],
//! [`plugin_params_error`]).

use std::path::{Path, PathBuf};

use super::desc::SceneDesc;
use super::error::SceneError;

/// Where a scene came from: used for error messages and to resolve relative mesh paths.
#[derive(Debug, Clone, Default)]
pub struct SceneSource {
    /// The file, if the scene was read from one.
    pub file: Option<PathBuf>,
    /// Folder relative mesh paths resolve against (the file's folder, or the current directory).
    pub base_dir: PathBuf,
    /// Further folders mesh paths may point into (for example the project's `assets/`).
    pub asset_roots: Vec<PathBuf>,
    /// The scene text (to locate plugin sections in the file for error positions).
    pub text: Option<String>,
}

impl SceneSource {
    /// A source for a scene built in memory, resolving paths against `base_dir`.
    pub fn in_memory(base_dir: impl Into<PathBuf>) -> Self {
        Self {
            base_dir: base_dir.into(),
            ..Self::default()
        }
    }

    /// The file name for messages (`<memory>` when none).
    pub fn label(&self) -> String {
        self.file
            .as_ref()
            .map(|f| f.display().to_string())
            .unwrap_or_else(|| "<memory>".to_string())
    }
}

/// The RON options of scene files, also for plugin-owned sections: optional fields may be
/// written without `Some(...)` (RON's `implicit_some` extension).
pub fn ron_options() -> ron::Options {
    ron::Options::default().with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
}

/// Parses scene text; `label` names the file in errors.
pub fn parse_str(text: &str, label: &str) -> Result<SceneDesc, SceneError> {
    ron_options()
        .from_str::<SceneDesc>(text)
        .map_err(|e| SceneError::from_ron(label, &e))
}

/// Reads and parses a scene file; the returned source resolves mesh paths next to the file.
pub fn load_file(path: &Path) -> Result<(SceneDesc, SceneSource), SceneError> {
    let text = std::fs::read_to_string(path).map_err(|e| SceneError::Io {
        file: path.display().to_string(),
        message: e.to_string(),
    })?;
    let desc = parse_str(&text, &path.display().to_string())?;
    let base_dir = path
        .parent()
        .map(Path::to_path_buf)
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or_else(|| PathBuf::from("."));
    Ok((
        desc,
        SceneSource {
            file: Some(path.to_path_buf()),
            base_dir,
            asset_roots: default_asset_roots(),
            text: Some(text),
        },
    ))
}

/// The project's asset folder when it can be found (`MODESUITE_ASSETS`, or `assets/` next to the
/// current directory).
pub fn default_asset_roots() -> Vec<PathBuf> {
    let mut roots = Vec::new();
    if let Ok(p) = std::env::var("MODESUITE_ASSETS") {
        roots.push(PathBuf::from(p));
    }
    let local = PathBuf::from("assets");
    if local.is_dir() {
        roots.push(local);
    }
    roots
}

/// Finds where `snippet` starts in `text` (1-based line, col), if it occurs exactly once.
fn locate(text: &str, snippet: &str) -> Option<(usize, usize)> {
    let start = text.find(snippet)?;
    if text[start + 1..].contains(snippet) {
        return None;
    }
    let before = &text[..start];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    Some((line, col))
}

/// Turns an error a plugin reported for its RON parameters into a file position when the
/// parameters can be found in the scene text.
pub fn plugin_params_error(
    source: &SceneSource,
    params_ron: &str,
    path: &str,
    e: &ron::error::SpannedError,
) -> SceneError {
    if let Some((l0, c0)) = source.text.as_deref().and_then(|t| locate(t, params_ron)) {
        let line = l0 + e.span.start.line - 1;
        let col = if e.span.start.line == 1 {
            c0 + e.span.start.col - 1
        } else {
            e.span.start.col
        };
        return SceneError::Syntax {
            file: source.label(),
            line,
            col,
            message: format!("{path}: {}", e.code),
        };
    }
    SceneError::semantic(
        path,
        params_ron.trim(),
        format!("{} (at {} within the parameters)", e.code, e.span.start),
    )
}
