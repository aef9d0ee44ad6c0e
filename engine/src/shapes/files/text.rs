//! Line-oriented parsing helpers of the mesh file readers.

use std::path::Path;

use nalgebra::Vector3;

use super::super::error::ShapeError;

/// A parse error at `line` of `path`.
pub(super) fn parse_error(path: &Path, line: usize, message: impl Into<String>) -> ShapeError {
    ShapeError::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// Parses `n` whitespace-separated floats from `tokens`, naming `what` in errors.
pub(super) fn floats<'a>(
    path: &Path,
    line: usize,
    tokens: &mut impl Iterator<Item = &'a str>,
    what: &str,
) -> Result<Vector3<f64>, ShapeError> {
    let mut v = Vector3::zeros();
    for k in 0..3 {
        let tok = tokens.next().ok_or_else(|| {
            parse_error(
                path,
                line,
                format!("{what}: expected 3 coordinates, found {k}"),
            )
        })?;
        let x: f64 = tok
            .parse()
            .map_err(|_| parse_error(path, line, format!("{what}: '{tok}' is not a number")))?;
        if !x.is_finite() {
            return Err(parse_error(
                path,
                line,
                format!("{what}: coordinate {tok} is not finite"),
            ));
        }
        v[k] = x;
    }
    Ok(v)
}
