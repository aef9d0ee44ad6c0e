//! Errors of shape description, generation, meshing and mesh-file loading.

use std::path::PathBuf;

/// Largest number of elements (triangles or tetrahedra) or nodes a generator or loader will produce.
///
/// Larger requests are refused with [`ShapeError::TooLarge`] before any memory is allocated for them.
pub const MAX_ELEMENTS: u64 = 10_000_000;

/// Everything that can go wrong while validating, generating or loading a shape.
///
/// Messages name the field (or file and line), the offending value and what would be valid.
/// [`ShapeError::Invalid`] carries the field path as data so a caller (the scene compiler) can prefix
/// it with [`ShapeError::prefixed`], e.g. `objects[3].shape.` + `radius`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShapeError {
    /// A parameter has a value outside its valid range.
    #[error("{field} = {value}: {expected}")]
    Invalid {
        /// Path of the field inside the shape description, e.g. `profile.radius` or `points[2]`.
        field: String,
        /// The offending value as written (Debug formatting).
        value: String,
        /// What would be valid, e.g. `must be a finite number > 0`.
        expected: String,
    },
    /// The request would create more elements than [`MAX_ELEMENTS`].
    #[error("{what}: {count} is too many (limit {limit}); lower the resolution")]
    TooLarge {
        /// What was counted, e.g. `Box divisions: tetrahedra`.
        what: String,
        /// The number that was requested (saturated at `u64::MAX`).
        count: u64,
        /// The limit that applies.
        limit: u64,
    },
    /// The shape cannot produce the requested kind of mesh (e.g. a volume mesh of a sphere).
    #[error("{shape}: {reason}")]
    Unsupported {
        /// The shape variant, e.g. `Sphere`.
        shape: String,
        /// Why, and what would work instead.
        reason: String,
    },
    /// A feature that is planned but not implemented.
    #[error("not implemented: {what}")]
    NotImplemented {
        /// What is missing, and the alternative if there is one.
        what: String,
    },
    /// A mesh file path resolves outside the scene folder and every asset root.
    #[error(
        "mesh file '{file}' resolves to '{}', which is outside the scene folder '{}' and every asset root; \
         move the file under one of them or add an asset root",
        resolved.display(),
        base.display()
    )]
    PathEscape {
        /// The path as written in the scene.
        file: String,
        /// The canonical path it resolved to.
        resolved: PathBuf,
        /// The scene folder it was resolved against.
        base: PathBuf,
    },
    /// A mesh file does not exist (or cannot be canonicalized).
    #[error(
        "mesh file '{file}' not found (tried {})",
        tried.iter().map(|p| format!("'{}'", p.display())).collect::<Vec<_>>().join(", ")
    )]
    NotFound {
        /// The path as written in the scene.
        file: String,
        /// The paths that were tried on disk, in order (scene folder first, then asset roots).
        tried: Vec<PathBuf>,
    },
    /// Reading a mesh file failed.
    #[error("mesh file '{}': {message}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's message.
        message: String,
    },
    /// A mesh file has a syntax or content error.
    #[error("{}{}: {message}", path.display(), line_suffix(*line))]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number (0 when the error concerns the whole file).
        line: usize,
        /// What is wrong and what was expected.
        message: String,
    },
    /// A mesh contains a bad element (inverted, degenerate, or with an out-of-range index).
    #[error("{mesh}: element {index} is {problem}")]
    BadElement {
        /// Which mesh, e.g. `volume mesh`.
        mesh: String,
        /// Index of the first bad element.
        index: usize,
        /// What is wrong with it, including its measured figures.
        problem: String,
    },
    /// A `Gen` shape names a generator that is not registered.
    #[error("unknown shape generator '{name}'; registered generators: [{}]; a generator from a compiled plugin is loaded with `--plugin PATH`", known.join(", "))]
    UnknownGenerator {
        /// The name in the scene.
        name: String,
        /// The names that are registered (may be empty).
        known: Vec<String>,
    },
    /// A registered generator reported an error.
    #[error("shape generator '{name}' failed: {message}")]
    Generator {
        /// The generator's name.
        name: String,
        /// Its message.
        message: String,
    },
}

/// `":<line>"`, or nothing for line 0 (an error about the whole file).
fn line_suffix(line: usize) -> String {
    if line == 0 {
        String::new()
    } else {
        format!(":{line}")
    }
}

impl ShapeError {
    /// Builds an [`ShapeError::Invalid`] from a field path, any debuggable value and an expectation.
    pub fn invalid(
        field: impl Into<String>,
        value: impl std::fmt::Debug,
        expected: impl Into<String>,
    ) -> Self {
        ShapeError::Invalid {
            field: field.into(),
            value: format!("{value:?}"),
            expected: expected.into(),
        }
    }

    /// Prefixes the field path of an [`ShapeError::Invalid`] (e.g. with `objects[3].shape.`);
    /// other variants are returned unchanged.
    pub fn prefixed(self, prefix: &str) -> Self {
        match self {
            ShapeError::Invalid {
                field,
                value,
                expected,
            } => ShapeError::Invalid {
                field: format!("{prefix}{field}"),
                value,
                expected,
            },
            other => other,
        }
    }

    /// The field path of an [`ShapeError::Invalid`], if this is one.
    pub fn field(&self) -> Option<&str> {
        match self {
            ShapeError::Invalid { field, .. } => Some(field),
            _ => None,
        }
    }
}

/// Largest magnitude accepted for any length or coordinate, metres (and for turn counts): a sanity
/// bound far beyond any scene, so absurd inputs get a clear message instead of overflowing later.
pub const MAX_MAGNITUDE: f64 = 1e6;

/// Checks that `value` is finite, strictly positive and at most [`MAX_MAGNITUDE`].
pub(super) fn positive(field: &str, value: f64) -> Result<(), ShapeError> {
    if value.is_finite() && value > 0.0 && value <= MAX_MAGNITUDE {
        Ok(())
    } else {
        Err(ShapeError::invalid(
            field,
            value,
            "must be a finite number > 0 (and <= 1e6)",
        ))
    }
}

/// Checks that `value` is finite with magnitude at most [`MAX_MAGNITUDE`].
pub(super) fn finite(field: &str, value: f64) -> Result<(), ShapeError> {
    if in_range(value) {
        Ok(())
    } else {
        Err(ShapeError::invalid(
            field,
            value,
            "must be a finite number with magnitude <= 1e6",
        ))
    }
}

/// True if `value` is finite with magnitude at most [`MAX_MAGNITUDE`].
pub(super) fn in_range(value: f64) -> bool {
    value.is_finite() && value.abs() <= MAX_MAGNITUDE
}

/// Checks that an integer resolution lies in `[min, max]`.
pub(super) fn count_in(field: &str, value: u32, min: u32, max: u32) -> Result<(), ShapeError> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(ShapeError::invalid(
            field,
            value,
            format!("must be an integer in [{min}, {max}]"),
        ))
    }
}

/// Checks an element count against [`MAX_ELEMENTS`].
pub(super) fn check_count(what: &str, count: u64) -> Result<(), ShapeError> {
    if count > MAX_ELEMENTS {
        Err(ShapeError::TooLarge {
            what: what.to_string(),
            count,
            limit: MAX_ELEMENTS,
        })
    } else {
        Ok(())
    }
}
