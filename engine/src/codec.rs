//! The state codec every part of an env's state speaks: [`Persist`] (write yourself into an
//! [`Encoder`], read yourself back in place from a [`Decoder`]), [`StateError`], and
//! [`persist_by_serde!`](crate::persist_by_serde) for plain serde types. Both ends use postcard
//! (serde's compact binary format: floats as their exact little-endian bits). The file layout
//! around the parts is [`crate::checkpoint`]'s; this module sits below every stateful module
//! (state registry, components, RNG, rigid world, solvers) and depends on none of them.

use serde::de::DeserializeOwned;
use serde::Serialize;

/// First bytes of every state file.
pub const MAGIC: &[u8; 16] = b"MODESUITE-STATE\n";
/// The format version this build writes and reads.
pub const FORMAT_VERSION: u32 = 1;
/// The build that wrote a file (files of another build are refused: the parts' layouts may
/// differ).
pub const BUILD: &str = concat!("modesuite-engine ", env!("CARGO_PKG_VERSION"));

/// Why a state could not be saved or loaded.
#[derive(Debug, thiserror::Error)]
pub enum StateError {
    /// Reading or writing the file failed.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: String,
        /// What failed.
        message: String,
    },
    /// The bytes are not a modesuite state file.
    #[error("not a modesuite state file (it does not start with {:?})", String::from_utf8_lossy(MAGIC).trim_end())]
    NotAStateFile,
    /// Another format version.
    #[error("state format version {found}, but this build reads version {expected}")]
    Version {
        /// In the file.
        found: u32,
        /// Of this build.
        expected: u32,
    },
    /// Truncated or corrupt bytes.
    #[error("the state file is truncated or corrupt: {0}")]
    Corrupt(String),
    /// The file belongs to another build, scene, plugin set or list of state parts.
    #[error("the state file was written for another env: {0}")]
    Foreign(String),
    /// One state part could not be restored.
    #[error("state part {part}: {message}")]
    Part {
        /// The part (type name).
        part: String,
        /// What did not fit.
        message: String,
    },
}

impl StateError {
    /// A [`StateError::Part`] error.
    pub fn part(part: &str, message: impl Into<String>) -> Self {
        Self::Part {
            part: part.to_string(),
            message: message.into(),
        }
    }
}

/// Writes state values (postcard encoding, appended in order).
#[derive(Debug, Default)]
pub struct Encoder {
    buf: Vec<u8>,
    error: Option<String>,
}

impl Encoder {
    /// An encoder whose output starts with `prefix` (a file's magic and version).
    pub fn after(prefix: Vec<u8>) -> Self {
        Self {
            buf: prefix,
            error: None,
        }
    }

    /// Appends one serde value. Encoding into memory fails only for a value postcard cannot
    /// express (a sequence of unknown length); the first such failure is kept and reported by
    /// [`Encoder::into_bytes`].
    pub fn put<T: Serialize + ?Sized>(&mut self, value: &T) {
        if self.error.is_some() {
            return;
        }
        if let Err(e) = postcard::to_io(value, &mut self.buf) {
            self.error = Some(format!(
                "cannot encode a {}: {e}",
                std::any::type_name::<T>()
            ));
        }
    }

    /// The bytes written, or the first encoding failure.
    pub fn into_bytes(self) -> Result<Vec<u8>, String> {
        match self.error {
            None => Ok(self.buf),
            Some(e) => Err(e),
        }
    }
}

/// Reads state values written by an [`Encoder`], in the same order.
#[derive(Debug)]
pub struct Decoder<'a> {
    rest: &'a [u8],
    part: &'a str,
}

impl<'a> Decoder<'a> {
    /// Reads the bytes of part `part` (named in errors).
    pub fn new(bytes: &'a [u8], part: &'a str) -> Self {
        Self { rest: bytes, part }
    }

    /// Reads one serde value.
    pub fn take<T: DeserializeOwned>(&mut self) -> Result<T, StateError> {
        let (v, rest) = postcard::take_from_bytes::<T>(self.rest).map_err(|e| {
            StateError::part(
                self.part,
                format!("cannot read a {}: {e}", std::any::type_name::<T>()),
            )
        })?;
        self.rest = rest;
        Ok(v)
    }

    /// Reads a length written with `put(&len)` and checks it against the env's own count.
    pub fn take_len(&mut self, what: &str, expected: usize) -> Result<(), StateError> {
        let n: u64 = self.take()?;
        if n != expected as u64 {
            return Err(StateError::part(
                self.part,
                format!("the file has {n} {what}, this env has {expected}"),
            ));
        }
        Ok(())
    }

    /// The part being read (for error messages).
    pub fn part(&self) -> &str {
        self.part
    }

    /// Errors unless every byte was read.
    pub fn finish(self) -> Result<(), StateError> {
        if self.rest.is_empty() {
            Ok(())
        } else {
            Err(StateError::part(
                self.part,
                format!("{} bytes left over after reading it", self.rest.len()),
            ))
        }
    }
}

/// A value that can be written to a checkpoint and read back in place, bit-exactly.
pub trait Persist {
    /// Writes every bit of the state that affects future steps.
    fn encode(&self, e: &mut Encoder);
    /// Reads back what `encode` wrote, into `self` (whose non-state parts, such as meshes and
    /// parameters, were built from the same scene).
    fn decode(&mut self, d: &mut Decoder<'_>) -> Result<(), StateError>;
}

/// Implements [`Persist`] for types whose whole value is state and which derive serde's
/// `Serialize` and `Deserialize`: encode the value, decode a new value over it.
#[macro_export]
macro_rules! persist_by_serde {
    ($($t:ty),+ $(,)?) => {$(
        impl $crate::codec::Persist for $t {
            fn encode(&self, e: &mut $crate::codec::Encoder) {
                e.put(self);
            }
            fn decode(
                &mut self,
                d: &mut $crate::codec::Decoder<'_>,
            ) -> Result<(), $crate::codec::StateError> {
                *self = d.take()?;
                Ok(())
            }
        }
    )+};
}
