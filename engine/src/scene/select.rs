//! Selecting nodes or particles of a deformable by region, for pins, fixed ends and handles.
//!
//! RON: `Near(at: (x, y, z), radius: r)` (every node within `r` of a point) or
//! `Box(min: (x, y, z), max: (x, y, z))` (every node inside an axis-aligned box). Coordinates are
//! in the object's frame at its rest shape, metres.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::SceneError;

/// A region of an object's rest shape that selects nodes or particles.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub enum NodeSelect {
    /// Nodes within `radius` of `at`.
    Near {
        /// Point, m, object frame.
        at: (f64, f64, f64),
        /// Distance, m (> 0).
        radius: f64,
    },
    /// Nodes inside the box `min..=max`.
    Box {
        /// Lower corner, m, object frame.
        min: (f64, f64, f64),
        /// Upper corner, m, object frame.
        max: (f64, f64, f64),
    },
}

fn finite(t: (f64, f64, f64)) -> bool {
    t.0.is_finite() && t.1.is_finite() && t.2.is_finite()
}

fn v(t: (f64, f64, f64)) -> Vector3<f64> {
    Vector3::new(t.0, t.1, t.2)
}

impl NodeSelect {
    /// Checks the numbers; `path` names the selector in errors.
    pub fn validate(&self, path: &str) -> Result<(), SceneError> {
        match *self {
            NodeSelect::Near { at, radius } => {
                if !finite(at) {
                    return Err(SceneError::semantic(
                        format!("{path}.at"),
                        format!("{at:?}"),
                        "three finite numbers, m (object frame)",
                    ));
                }
                if !(radius.is_finite() && radius > 0.0) {
                    return Err(SceneError::semantic(
                        format!("{path}.radius"),
                        radius.to_string(),
                        "a finite distance > 0, m",
                    ));
                }
            }
            NodeSelect::Box { min, max } => {
                if !finite(min) || !finite(max) {
                    return Err(SceneError::semantic(
                        path,
                        format!("Box(min: {min:?}, max: {max:?})"),
                        "finite corners, m (object frame)",
                    ));
                }
                if min.0 > max.0 || min.1 > max.1 || min.2 > max.2 {
                    return Err(SceneError::semantic(
                        path,
                        format!("Box(min: {min:?}, max: {max:?})"),
                        "min <= max on every axis",
                    ));
                }
            }
        }
        Ok(())
    }

    /// Whether a rest position (object frame) is selected.
    pub fn contains(&self, p: &Vector3<f64>) -> bool {
        match *self {
            NodeSelect::Near { at, radius } => (p - v(at)).norm() <= radius,
            NodeSelect::Box { min, max } => {
                let (lo, hi) = (v(min), v(max));
                (0..3).all(|i| p[i] >= lo[i] && p[i] <= hi[i])
            }
        }
    }

    /// Indices of the selected rest positions; an error when the selection is invalid or empty.
    pub fn select(&self, path: &str, rest: &[Vector3<f64>]) -> Result<Vec<u32>, SceneError> {
        self.validate(path)?;
        let sel: Vec<u32> = rest
            .iter()
            .enumerate()
            .filter(|(_, p)| self.contains(p))
            .map(|(i, _)| i as u32)
            .collect();
        if sel.is_empty() {
            return Err(SceneError::semantic(
                path,
                format!("{self:?}"),
                "selects no node: move it onto the object's rest shape (object frame) or enlarge it",
            ));
        }
        Ok(sel)
    }
}
