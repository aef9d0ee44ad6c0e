//! Retrieval: nearest-neighbour imitation over demonstration frames, in the spirit of VINN
//! (Pari et al.) and DeMoBot: the policy keeps every demonstration frame's observation and
//! action; for an observation it finds the `k` nearest frames (Euclidean distance after scaling
//! each observation value by the demonstrations' standard deviation) and returns their actions'
//! mean weighted by `1 / distance` (a frame at distance 0 alone decides). With `k = 1` this
//! replays the matched frame's action, so a demonstration started from its own seed is replayed
//! exactly. Observations are what the policy's inputs say (`crate::inputs`: the state, image
//! features, or both).
//!
//! With a `horizon` H > 1 (and `k = 1`), the matched demonstration's actions are replayed: the
//! policy takes the matched frame's action and the next H - 1 actions of the same
//! demonstration (fewer at its end) before it looks again, as DeMoBot replays a retrieved
//! segment; between two looks it neither observes nor renders. With an `ensemble` exponent it
//! looks at every step instead and plays the weighted mean of the segments retrieved for that
//! step (ACT's temporal ensembling, `modesuite_learn::policy::ChunkPlayer`).
//!
//! A retrieval policy is a folder like a trained one: `policy.json` (`algo: "retrieval"`,
//! sizes, `k`, `horizon`, `ensemble` when set, the demonstrations' `episode_ends`, the note
//! with target and action modes) and `retrieval.bin` (little-endian f32: the scales, the
//! scaled observations, the actions).

use std::path::Path;

use modesuite_learn::policy::ChunkPlayer;
use serde_json::json;

/// Version of the retrieval folder's layout (2 added `horizon` and `episode_ends`, 3 the
/// optional `ensemble`; version 1 folders still load, as horizon 1, and version 2 ones).
pub const RETRIEVAL_FORMAT_VERSION: u64 = 3;
/// Largest number of frames a retrieval policy may declare (a damaged file must not make
/// loading allocate without bound).
const MAX_FRAMES: usize = 1 << 24;

/// A nearest-neighbour policy over demonstration frames.
#[derive(Debug, Clone, PartialEq)]
pub struct Retrieval {
    obs_dim: usize,
    act_dim: usize,
    k: usize,
    horizon: usize,
    /// Temporal ensembling of the replayed segments (`horizon` >= 2), see the module.
    ensemble: Option<f64>,
    /// One past the last frame of each demonstration, ascending (the last is `len()`).
    episode_ends: Vec<usize>,
    scale: Vec<f32>,
    obs: Vec<f32>,
    act: Vec<f32>,
}

impl Retrieval {
    /// The policy of frames `obs` (`n x obs_dim`) and their actions (`n x act_dim`); `k >= 1`.
    /// The frames form one demonstration; see [`Retrieval::with_replay`].
    pub fn new(obs: &[f32], act: &[f32], obs_dim: usize, act_dim: usize, k: usize) -> Self {
        let n = obs.len() / obs_dim.max(1);
        let mut scale = vec![1.0f32; obs_dim];
        for (d, s) in scale.iter_mut().enumerate() {
            let mean =
                (0..n).map(|i| f64::from(obs[i * obs_dim + d])).sum::<f64>() / n.max(1) as f64;
            let var = (0..n)
                .map(|i| (f64::from(obs[i * obs_dim + d]) - mean).powi(2))
                .sum::<f64>()
                / n.max(1) as f64;
            *s = (1.0 / var.sqrt().max(1e-6)) as f32;
        }
        let scaled = obs
            .chunks_exact(obs_dim)
            .flat_map(|row| row.iter().zip(&scale).map(|(x, s)| x * s))
            .collect();
        Self {
            obs_dim,
            act_dim,
            k: k.max(1),
            horizon: 1,
            ensemble: None,
            episode_ends: vec![n],
            scale,
            obs: scaled,
            act: act.to_vec(),
        }
    }

    /// Replays `horizon` actions of the matched demonstration per look (`k` must be 1 for
    /// `horizon > 1`); `episode_ends` are one past each demonstration's last frame, ascending,
    /// the last equal to the number of frames.
    pub fn with_replay(mut self, horizon: usize, episode_ends: Vec<usize>) -> Result<Self, String> {
        if horizon == 0 || (horizon > 1 && self.k > 1) {
            return Err(format!(
                "horizon = {horizon}, k = {}: horizon >= 1, and k = 1 to replay more than one action",
                self.k
            ));
        }
        let sorted = episode_ends.windows(2).all(|w| w[0] < w[1]);
        if !sorted || episode_ends.first() == Some(&0) || episode_ends.last() != Some(&self.len()) {
            return Err(format!(
                "episode_ends {episode_ends:?}: ascending, positive, the last = {} frames",
                self.len()
            ));
        }
        self.horizon = horizon;
        self.episode_ends = episode_ends;
        Ok(self)
    }

    /// Looks at every step and ensembles the segments retrieved (exponent `m`, see
    /// `BcConfig::ensemble`); needs `horizon >= 2` (call after [`Retrieval::with_replay`]).
    pub fn with_ensemble(mut self, m: Option<f64>) -> Result<Self, String> {
        modesuite_learn::policy::check_ensemble(m, self.horizon, "horizon")?;
        self.ensemble = m;
        Ok(self)
    }

    /// Actions replayed per look.
    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// The temporal-ensembling exponent, if any.
    pub fn ensemble(&self) -> Option<f64> {
        self.ensemble
    }

    /// The frame after `frame` in its demonstration, if any.
    pub fn next_in_demo(&self, frame: usize) -> Option<usize> {
        let end =
            self.episode_ends[self.episode_ends.partition_point(|&e| e <= frame)..].first()?;
        (frame + 1 < *end).then_some(frame + 1)
    }

    /// The action of a frame.
    pub fn action_of(&self, frame: usize) -> &[f32] {
        &self.act[frame * self.act_dim..(frame + 1) * self.act_dim]
    }

    /// Frames held.
    pub fn len(&self) -> usize {
        self.obs.len() / self.obs_dim.max(1)
    }

    /// Whether it holds none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Observation length.
    pub fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    /// Action length.
    pub fn act_dim(&self) -> usize {
        self.act_dim
    }

    /// The `k` frames nearest to `obs` as `(frame, distance)`, nearest first (ties: the
    /// earlier frame).
    pub fn nearest(&self, obs: &[f32], k: usize) -> Vec<(usize, f32)> {
        let q: Vec<f32> = obs.iter().zip(&self.scale).map(|(x, s)| x * s).collect();
        let mut d: Vec<(usize, f32)> = self
            .obs
            .chunks_exact(self.obs_dim)
            .enumerate()
            .map(|(i, row)| {
                let s: f32 = row.iter().zip(&q).map(|(a, b)| (a - b) * (a - b)).sum();
                (i, s.sqrt())
            })
            .collect();
        d.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        d.truncate(k);
        d
    }

    /// The action for `obs` (see the module).
    pub fn act(&self, obs: &[f32]) -> Vec<f32> {
        self.act_matched(obs).0
    }

    /// [`Retrieval::act`] and the frame whose action it is, when one frame decides (`k = 1`
    /// or a frame at distance 0).
    pub fn act_matched(&self, obs: &[f32]) -> (Vec<f32>, Option<usize>) {
        let near = self.nearest(obs, self.k);
        if let Some(&(i, d)) = near.first() {
            if d == 0.0 || near.len() == 1 {
                return (self.action_of(i).to_vec(), Some(i));
            }
        }
        let mut out = vec![0.0f64; self.act_dim];
        let mut total = 0.0f64;
        for (i, d) in near {
            let w = 1.0 / f64::from(d);
            total += w;
            for (o, a) in out.iter_mut().zip(self.action_of(i)) {
                *o += w * f64::from(*a);
            }
        }
        let mean = out.iter().map(|o| (o / total.max(1e-300)) as f32).collect();
        (mean, None)
    }

    /// Writes the policy folder `dir` (`policy.json` last, each file atomically).
    pub fn save(&self, dir: &Path, note: &str) -> Result<(), String> {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let mut bytes =
            Vec::with_capacity(4 * (self.scale.len() + self.obs.len() + self.act.len()));
        for v in self.scale.iter().chain(&self.obs).chain(&self.act) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let bin = dir.join("retrieval.bin");
        modesuite_engine::fsio::write_atomic(&bin, &bytes)
            .map_err(|e| format!("{}: {e}", bin.display()))?;
        let mut meta = json!({"format_version": RETRIEVAL_FORMAT_VERSION, "algo": "retrieval",
                          "obs_dim": self.obs_dim, "act_dim": self.act_dim, "k": self.k,
                          "horizon": self.horizon, "episode_ends": self.episode_ends,
                          "frames": self.len(), "note": note});
        if let Some(m) = self.ensemble {
            meta["ensemble"] = json!(m);
        }
        let path = dir.join("policy.json");
        let text = serde_json::to_string_pretty(&meta).map_err(|e| e.to_string())?;
        modesuite_engine::fsio::write_atomic(&path, text.as_bytes())
            .map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Reads a policy folder written by [`Retrieval::save`]; errors name the file and field.
    pub fn load(dir: &Path) -> Result<Self, String> {
        let path = dir.join("policy.json");
        let text =
            std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let meta: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        let field = |k: &str| -> Result<usize, String> {
            meta[k]
                .as_u64()
                .map(|v| v as usize)
                .ok_or_else(|| format!("{}: {k} is missing or not a count", path.display()))
        };
        let (od, ad, k, n) = (
            field("obs_dim")?,
            field("act_dim")?,
            field("k")?,
            field("frames")?,
        );
        let version = meta["format_version"].as_u64();
        if !matches!(version, Some(1..=RETRIEVAL_FORMAT_VERSION)) {
            return Err(format!(
                "{}: format_version: this build reads 1 to {RETRIEVAL_FORMAT_VERSION}",
                path.display()
            ));
        }
        if !(1..=1 << 20).contains(&od)
            || !(1..=1 << 20).contains(&ad)
            || k == 0
            || !(1..=MAX_FRAMES).contains(&n)
        {
            return Err(format!(
                "{}: obs_dim = {od}, act_dim = {ad}, k = {k}, frames = {n}: each >= 1 (frames at most {MAX_FRAMES})",
                path.display()
            ));
        }
        let bin = dir.join("retrieval.bin");
        let bytes = std::fs::read(&bin).map_err(|e| format!("{}: {e}", bin.display()))?;
        let want = 4 * (od + n * od + n * ad);
        if bytes.len() != want {
            return Err(format!(
                "{}: {} bytes, the sizes in policy.json need {want}",
                bin.display(),
                bytes.len()
            ));
        }
        let v: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        if v.iter().any(|x| !x.is_finite()) {
            return Err(format!(
                "{}: non-finite values (a damaged file?)",
                bin.display()
            ));
        }
        let loaded = Self {
            obs_dim: od,
            act_dim: ad,
            k,
            horizon: 1,
            ensemble: None,
            episode_ends: vec![n],
            scale: v[..od].to_vec(),
            obs: v[od..od + n * od].to_vec(),
            act: v[od + n * od..].to_vec(),
        };
        if version == Some(1) {
            return Ok(loaded);
        }
        let horizon = field("horizon")?;
        let ends: Option<Vec<usize>> = meta["episode_ends"].as_array().map(|a| {
            a.iter()
                .map(|v| v.as_u64().map_or(0, |v| v as usize))
                .collect()
        });
        let ends = ends.ok_or_else(|| format!("{}: episode_ends is missing", path.display()))?;
        let ensemble = match &meta["ensemble"] {
            serde_json::Value::Null => None,
            v => Some(
                v.as_f64()
                    .ok_or_else(|| format!("{}: ensemble = {v}: a number", path.display()))?,
            ),
        };
        loaded
            .with_replay(horizon, ends)
            .and_then(|r| r.with_ensemble(ensemble))
            .map_err(|e| format!("{}: {e}", path.display()))
    }
}

/// A retrieval policy acting in one env (`run --policy DIR`, `eval`).
pub struct RetrievalPolicy {
    /// The demonstration frames.
    pub r: Retrieval,
    /// What it observes.
    pub inputs: crate::inputs::Observer,
    /// The retrieved actions still to play (open-loop, or ensembled).
    player: ChunkPlayer,
}

impl RetrievalPolicy {
    /// The policy of `r` observing `inputs`.
    pub fn new(r: Retrieval, inputs: crate::inputs::Observer) -> Self {
        let player = ChunkPlayer::new(r.act_dim(), r.horizon(), r.ensemble());
        Self { r, inputs, player }
    }
}

impl modesuite_tasks::expert::Policy for RetrievalPolicy {
    fn reset(&mut self, _seed: u64) {
        self.player.reset();
    }

    fn act(
        &mut self,
        env: &modesuite_engine::prelude::Env,
        action: &mut [f32],
    ) -> Result<(), String> {
        // replaying the matched demonstration: its next action, without looking
        if !self.player.needs_chunk() {
            self.player.play(None, action);
            return Ok(());
        }
        let (r, player) = (&self.r, &mut self.player);
        crate::learning::act_on_inputs(
            &mut self.inputs,
            env,
            action,
            r.obs_dim(),
            r.act_dim(),
            |o| {
                // the matched frame's action and the next ones of its demonstration (fewer at
                // its end), or the k frames' mean alone
                let (mut segment, matched) = r.act_matched(o);
                let mut frame = matched.filter(|_| r.horizon() > 1);
                for _ in 1..r.horizon() {
                    match frame.and_then(|f| r.next_in_demo(f)) {
                        Some(next) => {
                            segment.extend_from_slice(r.action_of(next));
                            frame = Some(next);
                        }
                        None => break,
                    }
                }
                let mut a = vec![0.0; r.act_dim()];
                player.play(Some(&segment), &mut a);
                a
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn demo() -> Retrieval {
        // 5 frames of 3 values, 2 action values
        let obs: Vec<f32> = (0..15).map(|i| (i * i % 7) as f32 - 2.0).collect();
        let act: Vec<f32> = (0..10).map(|i| i as f32 * 0.1).collect();
        Retrieval::new(&obs, &act, 3, 2, 3)
    }

    #[test]
    fn a_demonstration_frame_retrieves_itself_at_distance_zero() {
        let r = demo();
        let obs: Vec<f32> = (0..15).map(|i| (i * i % 7) as f32 - 2.0).collect();
        let act: Vec<f32> = (0..10).map(|i| i as f32 * 0.1).collect();
        for f in 0..5 {
            let near = r.nearest(&obs[f * 3..(f + 1) * 3], 3);
            println!("frame {f}: nearest {near:?}");
            assert_eq!(near[0], (f, 0.0));
            assert_eq!(
                r.act(&obs[f * 3..(f + 1) * 3]),
                act[f * 2..f * 2 + 2].to_vec()
            );
        }
    }

    #[test]
    fn replay_stays_inside_a_demonstration_and_round_trips() {
        // frames 0..2 are one demonstration, 2..5 another
        let r = demo();
        let e = r.clone().with_replay(4, vec![2, 5]).unwrap_err();
        assert!(e.contains("k = 1"), "{e}");
        let obs: Vec<f32> = (0..15).map(|i| (i * i % 7) as f32 - 2.0).collect();
        let act: Vec<f32> = (0..10).map(|i| i as f32 * 0.1).collect();
        let r = Retrieval::new(&obs, &act, 3, 2, 1)
            .with_replay(4, vec![2, 5])
            .unwrap();
        let next: Vec<Option<usize>> = (0..5).map(|f| r.next_in_demo(f)).collect();
        assert_eq!(next, [Some(1), None, Some(3), Some(4), None]);
        assert_eq!(r.action_of(3), &act[6..8]);
        for bad in [vec![2, 4], vec![0, 5], vec![3, 2, 5]] {
            assert!(r.clone().with_replay(2, bad).is_err());
        }
        let dir = std::env::temp_dir().join(format!("modesuite-replay-{}", std::process::id()));
        r.save(&dir, "{}").unwrap();
        assert_eq!(Retrieval::load(&dir).unwrap(), r);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn save_and_load_round_trip_and_damage_is_refused() {
        let r = demo();
        let dir = std::env::temp_dir().join(format!("modesuite-retrieval-{}", std::process::id()));
        r.save(&dir, "{}").unwrap();
        assert_eq!(Retrieval::load(&dir).unwrap(), r);
        std::fs::write(dir.join("retrieval.bin"), [0u8; 8]).unwrap();
        let e = Retrieval::load(&dir).unwrap_err();
        assert!(e.contains("retrieval.bin") && e.contains("bytes"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
