//! Errors of the cloth solver.

use std::fmt;

/// Everything that can go wrong when building or stepping a cloth. Values, never panics.
#[derive(Debug, Clone, PartialEq)]
pub enum PbdError {
    /// A construction or call parameter is out of range; names the field, the value and what
    /// would be valid.
    InvalidParameter {
        /// Field or argument name, e.g. `material.areal_density`.
        field: &'static str,
        /// The offending value, formatted.
        value: String,
        /// What would be valid.
        expected: &'static str,
    },
    /// The triangle mesh is unusable (index out of range, degenerate triangle, ...).
    InvalidMesh(String),
    /// A particle position or velocity became non-finite during a step. The cloth state was
    /// rolled back to the start of that step.
    NonFinite {
        /// Index of the first non-finite particle.
        particle: usize,
        /// Simulation step counter at which it happened.
        step: u64,
    },
    /// A rigid collider query returned a non-finite contact; the step was rolled back.
    NonFiniteContact {
        /// Particle whose query returned it.
        particle: usize,
    },
    /// An unknown attachment, frame or group id/name.
    Unknown(String),
    /// A state vector passed to `set_state` does not fit this cloth.
    BadState(String),
}

impl fmt::Display for PbdError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PbdError::InvalidParameter { field, value, expected } => {
                write!(f, "invalid {field} = {value}: expected {expected}")
            }
            PbdError::InvalidMesh(m) => write!(f, "invalid cloth mesh: {m}"),
            PbdError::NonFinite { particle, step } => write!(
                f,
                "cloth blew up: particle {particle} became non-finite at step {step} (state rolled back)"
            ),
            PbdError::NonFiniteContact { particle } => write!(
                f,
                "collider query for particle {particle} returned a non-finite contact (state rolled back)"
            ),
            PbdError::Unknown(m) => write!(f, "unknown {m}"),
            PbdError::BadState(m) => write!(f, "bad cloth state vector: {m}"),
        }
    }
}

impl std::error::Error for PbdError {}

/// Checks that `value` is finite and `>= min` (or `> min` when `strict`).
pub(crate) fn check_param(
    field: &'static str,
    value: f64,
    min: f64,
    strict: bool,
    expected: &'static str,
) -> Result<(), PbdError> {
    let ok = value.is_finite() && if strict { value > min } else { value >= min };
    if ok {
        Ok(())
    } else {
        Err(PbdError::InvalidParameter {
            field,
            value: format!("{value}"),
            expected,
        })
    }
}
