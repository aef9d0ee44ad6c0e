//! Checkpoints: an env's complete state as a versioned binary file, restored bit-exactly in
//! another process (`run --save-state FILE` / `--load-state FILE`, [`Env::save_state`],
//! [`Env::load_state`]).
//!
//! **One codec for every part.** Each registered state part (solver contexts, the rigid world,
//! components, task and robot state, plugin slots) implements [`Persist`]: it writes itself into
//! an [`Encoder`] and reads itself back in place from a [`Decoder`]. Both speak postcard (serde's
//! compact binary format: floats as their exact little-endian bits), so a part whose state is a
//! plain serde type needs one line ([`persist_by_serde!`](crate::persist_by_serde)); the rigid
//! world goes through rapier's own serde representation.
//!
//! **File layout** (all integers little-endian):
//! `MAGIC` (16 bytes) | format version (u32) | body (postcard) | checksum (u64, FNV-1a of all
//! bytes before it). The body holds a [`Header`] (build, fingerprint of the env, plugin and part
//! lists, space sizes), the env's own episode bookkeeping, every part's bytes by name, and the
//! state hash at save time.
//!
//! **Refusals.** A file is refused, with the reason, when it is not a state file, is truncated or
//! corrupt (checksum), has another format version or build, comes from another scene (the
//! fingerprint is the hash of the env's spawn state, so any other scene, size, material layout
//! or robot differs), another plugin set, or another list of state parts. Loading is
//! all-or-nothing: a part that fails to decode, or a decoded state whose hash differs from the
//! recorded one, leaves the env exactly as it was before the call.

use std::path::Path;

use serde::{Deserialize, Serialize};

pub use crate::codec::{Decoder, Encoder, Persist, StateError, BUILD, FORMAT_VERSION, MAGIC};

use crate::env::{Env, ObservationBuffer};
use crate::state::{state_hash, Snapshot, StateHasher};

/// What a state file says about the env it was written from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// [`BUILD`] of the writer.
    pub build: String,
    /// Hash of the env's spawn state ([`Env::fingerprint`]).
    pub fingerprint: u64,
    /// The app's plugins, in load order.
    pub plugins: Vec<String>,
    /// The registered state parts, in registration order.
    pub parts: Vec<String>,
    /// Flat observation size.
    pub obs_dim: u64,
    /// Flat action size.
    pub act_dim: u64,
}

/// The env's own bookkeeping, beside the world's parts.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct EnvFields {
    episode_return: f64,
    error_count: u64,
    reset_error: Option<String>,
    observation: Vec<f32>,
}

#[derive(Debug, Serialize, Deserialize)]
struct Body {
    header: Header,
    env: EnvFields,
    parts: Vec<(String, Vec<u8>)>,
    state_hash: u64,
}

fn checksum(bytes: &[u8]) -> u64 {
    let mut h = StateHasher::default();
    h.write_bytes(bytes);
    h.finish()
}

/// Reads a state file's bytes up to its body, checking magic, version and checksum.
fn read_body(bytes: &[u8]) -> Result<Body, StateError> {
    if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
        return Err(StateError::NotAStateFile);
    }
    let rest = &bytes[MAGIC.len()..];
    if rest.len() < 4 + 8 {
        return Err(StateError::Corrupt(format!(
            "{} bytes in all, too short for a header",
            bytes.len()
        )));
    }
    let version = u32::from_le_bytes(rest[..4].try_into().expect("4 bytes"));
    if version != FORMAT_VERSION {
        return Err(StateError::Version {
            found: version,
            expected: FORMAT_VERSION,
        });
    }
    let (covered, sum) = bytes.split_at(bytes.len() - 8);
    let sum = u64::from_le_bytes(sum.try_into().expect("8 bytes"));
    if checksum(covered) != sum {
        return Err(StateError::Corrupt(format!(
            "checksum mismatch over {} bytes",
            covered.len()
        )));
    }
    let body = &covered[MAGIC.len() + 4..];
    let (b, left) = postcard::take_from_bytes::<Body>(body)
        .map_err(|e| StateError::Corrupt(format!("body: {e}")))?;
    if !left.is_empty() {
        return Err(StateError::Corrupt(format!(
            "{} bytes after the body",
            left.len()
        )));
    }
    Ok(b)
}

/// Reads only the header of a state file (for `modesuite` tools that describe a file).
pub fn read_header(bytes: &[u8]) -> Result<Header, StateError> {
    read_body(bytes).map(|b| b.header)
}

fn foreign(what: &str, file: impl std::fmt::Debug, env: impl std::fmt::Debug) -> StateError {
    StateError::Foreign(format!(
        "{what}: the file has {file:?}, this env has {env:?}"
    ))
}

impl Env {
    /// What a state file must match to be loaded into this env.
    pub fn state_header(&self) -> Header {
        let spaces = self.spaces();
        Header {
            build: BUILD.to_string(),
            fingerprint: self.fingerprint(),
            plugins: self.app.plugin_names(),
            parts: self
                .app
                .world
                .resource::<crate::state::StateRegistry>()
                .names()
                .into_iter()
                .map(str::to_string)
                .collect(),
            obs_dim: spaces.observation.flat_dim() as u64,
            act_dim: spaces.action.flat_dim() as u64,
        }
    }

    /// The env's complete current state as the bytes of a state file.
    pub fn save_state(&self) -> Result<Vec<u8>, StateError> {
        let body = Body {
            header: self.state_header(),
            env: EnvFields {
                episode_return: self.episode_return,
                error_count: self.error_count,
                reset_error: self.reset_error.clone(),
                observation: self.observation(),
            },
            parts: crate::state::encode_parts(&self.app.world)?,
            state_hash: self.state_hash(),
        };
        let mut out = Vec::with_capacity(1 << 16);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        let mut e = Encoder::after(out);
        e.put(&body);
        let mut out = e.into_bytes().map_err(|m| StateError::part("(file)", m))?;
        let sum = checksum(&out);
        out.extend_from_slice(&sum.to_le_bytes());
        Ok(out)
    }

    /// Replaces the env's state with the one in `bytes` (made by [`Env::save_state`] of an env
    /// of the same scene, plugins and build). All or nothing: on error the env is unchanged.
    /// The next [`Env::step`] continues the saved episode exactly as it would have continued
    /// in the env that saved it.
    pub fn load_state(&mut self, bytes: &[u8]) -> Result<(), StateError> {
        let body = read_body(bytes)?;
        let mine = self.state_header();
        let theirs = &body.header;
        if theirs.build != mine.build {
            return Err(foreign("build", &theirs.build, &mine.build));
        }
        if theirs.plugins != mine.plugins {
            return Err(foreign("plugins", &theirs.plugins, &mine.plugins));
        }
        if theirs.fingerprint != mine.fingerprint {
            return Err(StateError::Foreign(format!(
                "scene: the file's spawn state hashes to {:016x}, this env's to {:016x} (another scene, or the same scene with other objects, sizes or robots)",
                theirs.fingerprint, mine.fingerprint
            )));
        }
        if theirs.parts != mine.parts {
            return Err(foreign("state parts", &theirs.parts, &mine.parts));
        }
        if (theirs.obs_dim, theirs.act_dim) != (mine.obs_dim, mine.act_dim) {
            return Err(foreign(
                "observation and action sizes",
                (theirs.obs_dim, theirs.act_dim),
                (mine.obs_dim, mine.act_dim),
            ));
        }
        if body.env.observation.len() as u64 != mine.obs_dim {
            return Err(StateError::Corrupt(format!(
                "observation of {} values, the space has {}",
                body.env.observation.len(),
                mine.obs_dim
            )));
        }
        let backup = Snapshot::take(&self.app.world);
        let restored =
            crate::state::decode_parts(&mut self.app.world, &body.parts).and_then(|()| {
                let h = state_hash(&self.app.world);
                if h == body.state_hash {
                    Ok(())
                } else {
                    Err(StateError::Corrupt(format!(
                        "the restored state hashes to {h:016x}, the file recorded {:016x}",
                        body.state_hash
                    )))
                }
            });
        if let Err(e) = restored {
            // A snapshot of this same world: its restore cannot mismatch.
            return Err(match backup.restore(&mut self.app.world) {
                Ok(()) => e,
                Err(b) => StateError::Corrupt(format!("{e}; restoring the env failed too: {b}")),
            });
        }
        self.episode_return = body.env.episode_return;
        self.error_count = body.env.error_count;
        self.reset_error = body.env.reset_error;
        self.app.world.resource_mut::<ObservationBuffer>().0 = body.env.observation;
        Ok(())
    }

    /// [`Env::save_state`] into a file, atomically ([`crate::fsio::write_atomic`]): the file is
    /// the old one or the complete new one, never a part.
    pub fn save_state_file(&self, path: &Path) -> Result<(), StateError> {
        crate::fsio::write_atomic(path, &self.save_state()?).map_err(|message| StateError::Io {
            path: path.display().to_string(),
            message,
        })
    }

    /// [`Env::load_state`] from a file (its errors keep their kind; callers name the file).
    pub fn load_state_file(&mut self, path: &Path) -> Result<(), StateError> {
        let bytes = std::fs::read(path).map_err(|e| StateError::Io {
            path: path.display().to_string(),
            message: format!("cannot read: {e}"),
        })?;
        self.load_state(&bytes)
    }
}
