//! Checkpoint files: one file per run, written atomically.
//!
//! Layout: the magic `MSLEARN\0`, the format version (u32 LE), the length of a JSON header
//! (u64 LE), the header, then named binary sections back to back, and last an FNV-1a 64 hash
//! of everything before it. The header holds the identity of the run (algorithm, the
//! environment's identity string, the configuration) and the table of sections; numbers that
//! must come back bit for bit (parameters, optimiser moments, normalisers, replay buffer, RNG
//! states, counters) live in the sections, never as decimal text.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

use crate::LearnError;

/// Version of the checkpoint layout and of the meaning of its sections. Files of another
/// version are refused.
pub const FORMAT_VERSION: u32 = 1;
const MAGIC: &[u8; 8] = b"MSLEARN\0";

/// The identity a checkpoint must share with the run that resumes from it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Identity {
    /// `"ppo"` or `"sac"`.
    pub algo: String,
    /// The environment's [`identity`](crate::VecEnvironment::identity).
    pub env: String,
    /// Number of environments in the batch.
    pub num_envs: usize,
}

#[derive(Serialize, Deserialize)]
struct Header {
    identity: Identity,
    crate_version: String,
    config_ron: String,
    sections: Vec<(String, u64)>,
}

/// A checkpoint in memory: identity, configuration and named byte sections.
#[derive(Clone, Debug, Default)]
pub struct Checkpoint {
    /// Who may resume from it.
    pub identity: Option<Identity>,
    /// The configuration of the run, as RON.
    pub config_ron: String,
    sections: BTreeMap<String, Vec<u8>>,
}

/// 64-bit FNV-1a of `bytes`: the checksum that ends a checkpoint file.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= *b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01B3);
    }
    h
}

impl Checkpoint {
    /// An empty checkpoint for a run.
    pub fn new(identity: Identity, config_ron: String) -> Self {
        Checkpoint {
            identity: Some(identity),
            config_ron,
            sections: BTreeMap::new(),
        }
    }

    /// Stores raw bytes under `name`.
    pub fn put_bytes(&mut self, name: &str, bytes: Vec<u8>) {
        self.sections.insert(name.to_string(), bytes);
    }

    /// Stores f32 values (bit exact).
    pub fn put_f32s(&mut self, name: &str, v: &[f32]) {
        self.put_bytes(name, v.iter().flat_map(|x| x.to_le_bytes()).collect());
    }

    /// Stores f64 values (bit exact).
    pub fn put_f64s(&mut self, name: &str, v: &[f64]) {
        self.put_bytes(name, v.iter().flat_map(|x| x.to_le_bytes()).collect());
    }

    /// Stores u64 values.
    pub fn put_u64s(&mut self, name: &str, v: &[u64]) {
        self.put_bytes(name, v.iter().flat_map(|x| x.to_le_bytes()).collect());
    }

    /// The bytes under `name`.
    pub fn bytes(&self, name: &str) -> Result<&[u8], LearnError> {
        self.sections
            .get(name)
            .map(|v| v.as_slice())
            .ok_or_else(|| LearnError::Checkpoint(format!("section '{name}' is missing")))
    }

    /// Whether a section exists.
    pub fn has(&self, name: &str) -> bool {
        self.sections.contains_key(name)
    }

    fn words<const N: usize>(&self, name: &str) -> Result<Vec<[u8; N]>, LearnError> {
        let b = self.bytes(name)?;
        if b.len() % N != 0 {
            return Err(LearnError::Checkpoint(format!(
                "section '{name}' has a partial value"
            )));
        }
        Ok(b.chunks_exact(N).map(|c| c.try_into().unwrap()).collect())
    }

    /// f32 values under `name`.
    pub fn f32s(&self, name: &str) -> Result<Vec<f32>, LearnError> {
        Ok(self
            .words::<4>(name)?
            .into_iter()
            .map(f32::from_le_bytes)
            .collect())
    }

    /// f64 values under `name`.
    pub fn f64s(&self, name: &str) -> Result<Vec<f64>, LearnError> {
        Ok(self
            .words::<8>(name)?
            .into_iter()
            .map(f64::from_le_bytes)
            .collect())
    }

    /// u64 values under `name`.
    pub fn u64s(&self, name: &str) -> Result<Vec<u64>, LearnError> {
        Ok(self
            .words::<8>(name)?
            .into_iter()
            .map(u64::from_le_bytes)
            .collect())
    }

    /// Exactly `N` u64 values under `name`.
    pub fn u64_array<const N: usize>(&self, name: &str) -> Result<[u64; N], LearnError> {
        let v = self.u64s(name)?;
        v.try_into().map_err(|v: Vec<u64>| {
            LearnError::Checkpoint(format!(
                "section '{name}' has {} values, expected {N}",
                v.len()
            ))
        })
    }

    /// The file's bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let header = Header {
            identity: self
                .identity
                .clone()
                .expect("a checkpoint to write has an identity"),
            crate_version: env!("CARGO_PKG_VERSION").to_string(),
            config_ron: self.config_ron.clone(),
            sections: self
                .sections
                .iter()
                .map(|(k, v)| (k.clone(), v.len() as u64))
                .collect(),
        };
        let header = serde_json::to_vec(&header).expect("header serialises");
        let mut out = Vec::new();
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        out.extend_from_slice(&(header.len() as u64).to_le_bytes());
        out.extend_from_slice(&header);
        for v in self.sections.values() {
            out.extend_from_slice(v);
        }
        let h = fnv1a(&out);
        out.extend_from_slice(&h.to_le_bytes());
        out
    }

    /// Parses a file's bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, LearnError> {
        let bad = |m: &str| LearnError::Checkpoint(m.to_string());
        if bytes.len() < 28 || &bytes[..8] != MAGIC {
            return Err(bad("not a modesuite-learn checkpoint"));
        }
        let version = u32::from_le_bytes(bytes[8..12].try_into().unwrap());
        if version != FORMAT_VERSION {
            return Err(LearnError::Incompatible(format!(
                "checkpoint format version {version}, this build reads version {FORMAT_VERSION}"
            )));
        }
        let (body, tail) = bytes.split_at(bytes.len() - 8);
        if fnv1a(body) != u64::from_le_bytes(tail.try_into().unwrap()) {
            return Err(bad("checkpoint is corrupt (hash mismatch)"));
        }
        let hlen = u64::from_le_bytes(body[12..20].try_into().unwrap());
        let header_end = usize::try_from(hlen)
            .ok()
            .and_then(|h| h.checked_add(20))
            .filter(|&e| e <= body.len())
            .ok_or_else(|| bad("checkpoint header is truncated"))?;
        let header: Header = serde_json::from_slice(&body[20..header_end])
            .map_err(|e| LearnError::Checkpoint(format!("checkpoint header: {e}")))?;
        let mut at = header_end;
        let mut sections = BTreeMap::new();
        for (name, len) in header.sections {
            let end = usize::try_from(len)
                .ok()
                .and_then(|l| l.checked_add(at))
                .filter(|&e| e <= body.len())
                .ok_or_else(|| bad("checkpoint section is truncated"))?;
            sections.insert(name, body[at..end].to_vec());
            at = end;
        }
        Ok(Checkpoint {
            identity: Some(header.identity),
            config_ron: header.config_ron,
            sections,
        })
    }

    /// Writes the checkpoint atomically.
    pub fn save(&self, path: &Path) -> Result<(), LearnError> {
        write_atomic(path, &self.to_bytes())
    }

    /// Reads a checkpoint file.
    pub fn load(path: &Path) -> Result<Self, LearnError> {
        let bytes =
            std::fs::read(path).map_err(|e| LearnError::Io(format!("{}: {e}", path.display())))?;
        Self::from_bytes(&bytes).map_err(|e| match e {
            LearnError::Checkpoint(m) => LearnError::Checkpoint(format!("{}: {m}", path.display())),
            LearnError::Incompatible(m) => {
                LearnError::Incompatible(format!("{}: {m}", path.display()))
            }
            other => other,
        })
    }

    /// Refuses to resume when the identity differs from the run's.
    pub fn check_identity(&self, expected: &Identity) -> Result<(), LearnError> {
        let got = self
            .identity
            .as_ref()
            .expect("loaded checkpoints have an identity");
        if got != expected {
            return Err(LearnError::Incompatible(format!(
                "the checkpoint belongs to another run: it was written by {} on environment '{}' with {} envs, \
                 this run is {} on '{}' with {} envs",
                got.algo, got.env, got.num_envs, expected.algo, expected.env, expected.num_envs
            )));
        }
        Ok(())
    }
}

/// Writes `bytes` to `path` atomically: a temporary file in the same folder, flushed and
/// synced, renamed over `path`, then the folder synced. A reader (or a run killed at any
/// moment) sees the old file or the new one, never a mixture.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), LearnError> {
    let io = |e: std::io::Error| LearnError::Io(format!("{}: {e}", path.display()));
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(io)?;
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("file");
    let tmp = dir.join(format!(".{name}.tmp{}", std::process::id()));
    let written = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = written {
        // A full disk or a failed rename leaves the old file as it was and no temporary behind.
        let _ = std::fs::remove_file(&tmp);
        return Err(io(e));
    }
    if let Ok(d) = std::fs::File::open(dir) {
        // Persist the rename itself; not every platform can sync a folder.
        let _ = d.sync_all();
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ident() -> Identity {
        Identity {
            algo: "ppo".into(),
            env: "point-reach obs 6 act 2".into(),
            num_envs: 4,
        }
    }

    /// Lengths near 2^64 in a checkpoint whose hash is valid are refused, not overflowed.
    #[test]
    fn huge_lengths_with_a_valid_hash_are_refused() {
        let mut c = Checkpoint::new(ident(), "()".into());
        c.put_f32s("w", &[1.0, 2.0]);
        let good = c.to_bytes();
        let reseal = |mut b: Vec<u8>| {
            let n = b.len() - 8;
            let h = fnv1a(&b[..n]);
            b[n..].copy_from_slice(&h.to_le_bytes());
            b
        };
        // the header length
        let mut b = good.clone();
        b[12..20].copy_from_slice(&(u64::MAX - 3).to_le_bytes());
        let e = Checkpoint::from_bytes(&reseal(b)).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
        // a section length inside the JSON header
        let hlen = u64::from_le_bytes(good[12..20].try_into().unwrap()) as usize;
        let header = String::from_utf8(good[20..20 + hlen].to_vec()).unwrap();
        let huge = header.replace("[\"w\",8]", "[\"w\",18446744073709551615]");
        assert_ne!(
            huge, header,
            "the section list is written as [name, length]: {header}"
        );
        let mut b = good[..12].to_vec();
        b.extend((huge.len() as u64).to_le_bytes());
        b.extend(huge.as_bytes());
        b.extend(&good[20 + hlen..]);
        let e = Checkpoint::from_bytes(&reseal(b)).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
    }

    #[test]
    fn a_failed_atomic_write_leaves_no_temporary_file() {
        let dir = std::env::temp_dir().join(format!("mslearn-atomic-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        // the target is a non-empty folder: the rename over it fails
        let target = dir.join("taken");
        std::fs::create_dir_all(target.join("inside")).unwrap();
        let err = write_atomic(&target, b"data").unwrap_err();
        let left: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        println!("refused: {err}; left in the folder: {left:?}");
        assert_eq!(left, vec!["taken".to_string()]);
        assert!(target.join("inside").is_dir());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn round_trip_and_refusals() {
        let dir = std::env::temp_dir().join(format!("mslearn-ckpt-{}", std::process::id()));
        let path = dir.join("checkpoint.bin");
        let mut c = Checkpoint::new(ident(), "Ppo(())".into());
        c.put_f32s("a", &[1.5, -0.0, f32::MIN_POSITIVE]);
        c.put_f64s("b", &[std::f64::consts::PI]);
        c.put_u64s("rng", &[1, 2, 3, u64::MAX]);
        c.save(&path).unwrap();
        let r = Checkpoint::load(&path).unwrap();
        assert_eq!(
            r.f32s("a").unwrap()[2].to_bits(),
            f32::MIN_POSITIVE.to_bits()
        );
        assert_eq!(r.f32s("a").unwrap()[1].to_bits(), (-0.0f32).to_bits());
        assert_eq!(r.f64s("b").unwrap(), vec![std::f64::consts::PI]);
        assert_eq!(r.u64_array::<4>("rng").unwrap(), [1, 2, 3, u64::MAX]);
        assert!(r.check_identity(&ident()).is_ok());
        let mut other = ident();
        other.env = "pendulum obs 3 act 1".into();
        let e = r.check_identity(&other).unwrap_err();
        assert!(format!("{e}").contains("another run"), "{e}");
        assert!(matches!(r.bytes("missing"), Err(LearnError::Checkpoint(_))));

        // Another format version, and a corrupted byte, are refused with clear errors.
        let mut bytes = c.to_bytes();
        bytes[8] = 99;
        let e = Checkpoint::from_bytes(&bytes).unwrap_err();
        assert!(
            matches!(e, LearnError::Incompatible(_)) && format!("{e}").contains("version 99"),
            "{e}"
        );
        let mut bytes = c.to_bytes();
        let k = bytes.len() - 12;
        bytes[k] ^= 1;
        let e = Checkpoint::from_bytes(&bytes).unwrap_err();
        assert!(format!("{e}").contains("corrupt"), "{e}");
        // No temporary file is left behind.
        let leftovers: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp"))
            .collect();
        assert!(leftovers.is_empty());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
