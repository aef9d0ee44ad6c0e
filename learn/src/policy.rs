//! Trained policies as files: `policy.json` (what the network is, how observations are
//! normalised, the action bounds, where it came from) and `weights.bpk` (burnpack; a behaviour
//! cloning ensemble adds `weights.member<m>.bpk` for members 1, 2, ...), and [`Policy`], which
//! loads them and acts deterministically (the mean action; an ensemble's members' mean).

use burn::module::Module;
use burn::tensor::Device;
use serde::{Deserialize, Serialize};
use std::path::Path;

use crate::actors::{load_record, record_bytes, ActorCritic, SacActor, NORM_EPS};
use crate::checkpoint::{write_atomic, Identity};
use crate::config::{PpoConfig, SacConfig};
use crate::nets::Activation;
use crate::normalize::RunningMeanStd;
use crate::rng::Rng;
use crate::runner::{rescale, EnvShape};
use crate::tensors::{tensor2, to_vec};
use crate::LearnError;

/// Largest action chunk of a policy ([`crate::bc::BcConfig::chunk`]).
pub const MAX_CHUNK: usize = 100;
/// Most networks of a behaviour-cloning ensemble ([`crate::bc::BcConfig::members`]).
pub const MAX_MEMBERS: usize = 32;

pub use crate::chunks::{check_ensemble, ChunkPlayer, MAX_ENSEMBLE};

/// Version of the policy files' layout.
pub const POLICY_FORMAT_VERSION: u32 = 1;

/// Observation normalisation of a policy.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObsNorm {
    /// Mean per dimension.
    pub mean: Vec<f64>,
    /// Variance per dimension.
    pub var: Vec<f64>,
    /// Added to the variance under the square root.
    pub eps: f64,
    /// Normalised values are clipped to +-this.
    pub clip: f64,
}

/// The contents of `policy.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolicyMeta {
    /// [`POLICY_FORMAT_VERSION`] at writing.
    pub format_version: u32,
    /// `"ppo"`, `"sac"` or `"bc"`.
    pub algo: String,
    /// The environment's identity string.
    pub env: String,
    /// Observation length.
    pub obs_dim: usize,
    /// Action length.
    pub act_dim: usize,
    /// Lower action bounds.
    pub low: Vec<f32>,
    /// Upper action bounds.
    pub high: Vec<f32>,
    /// Hidden widths.
    pub hidden: Vec<usize>,
    /// Hidden nonlinearity.
    pub activation: Activation,
    /// PPO: separate actor and critic trunks.
    pub separate: bool,
    /// Observation normalisation, if any.
    pub obs_norm: Option<ObsNorm>,
    /// Training iterations behind the weights.
    pub iteration: u64,
    /// Environment steps behind the weights.
    pub env_steps: u64,
    /// The training configuration (RON).
    pub config_ron: String,
    /// Free text from the run (the command that made it, say).
    pub note: String,
    /// `Some(n)`: the action is one of `n` discrete keys (`act_dim` 1, the key index), chosen
    /// as the arg-max of the network's `n` logits (behaviour cloning's classification head).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub discrete: Option<usize>,
    /// Actions per observation (behaviour cloning's action chunks): the network gives `chunk`
    /// actions one after another; [`Policy::act`] returns the first, [`Policy::act_chunk`] all.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub chunk: usize,
    /// Temporal ensembling of the chunks when the policy acts in an env
    /// ([`crate::bc::BcConfig::ensemble`], [`ChunkPlayer`]); `None`: chunks played open-loop.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ensemble: Option<f64>,
    /// Networks of a behaviour-cloning ensemble ([`crate::bc::BcConfig::members`]): member 0's
    /// weights in `weights.bpk`, member `m`'s in `weights.member<m>.bpk`; the policy acts with
    /// the mean of their outputs (of their logits for discrete keys).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub members: usize,
}

/// The weights file of ensemble member `m` (0: `weights.bpk`).
pub fn weights_file(m: usize) -> String {
    if m == 0 {
        "weights.bpk".into()
    } else {
        format!("weights.member{m}.bpk")
    }
}

fn one() -> usize {
    1
}

fn is_one(n: &usize) -> bool {
    *n == 1
}

enum Net {
    Ppo(ActorCritic),
    Sac(SacActor),
}

/// A trained policy, loaded from its folder.
pub struct Policy {
    meta: PolicyMeta,
    /// One network, or an ensemble's members in order.
    nets: Vec<Net>,
    device: Device,
}

/// Writes a policy folder: the weights, then `policy.json` (each atomically).
pub(crate) fn write(dir: &Path, meta: &PolicyMeta, weights: Vec<u8>) -> Result<(), LearnError> {
    write_members(dir, meta, vec![weights])
}

/// Writes a policy folder of one or more members' weights (in order, `meta.members` of them),
/// then `policy.json` (each atomically; the file naming the members comes last).
pub(crate) fn write_members(
    dir: &Path,
    meta: &PolicyMeta,
    weights: Vec<Vec<u8>>,
) -> Result<(), LearnError> {
    debug_assert_eq!(weights.len(), meta.members);
    for (m, w) in weights.iter().enumerate() {
        write_atomic(&dir.join(weights_file(m)), w)?;
    }
    let json = serde_json::to_string_pretty(meta).map_err(|e| LearnError::Io(e.to_string()))?;
    write_atomic(&dir.join("policy.json"), json.as_bytes())
}

fn obs_norm(rms: Option<&RunningMeanStd>, clip: f64) -> Option<ObsNorm> {
    rms.map(|r| ObsNorm {
        mean: r.mean.clone(),
        var: r.var.clone(),
        eps: NORM_EPS,
        clip,
    })
}

/// Writes a PPO policy.
#[allow(clippy::too_many_arguments)]
pub(crate) fn export_ppo(
    dir: &Path,
    model: &ActorCritic,
    cfg: &PpoConfig,
    shape: &EnvShape,
    rms: Option<&RunningMeanStd>,
    identity: &Identity,
    iteration: u64,
    env_steps: u64,
    note: &str,
) -> Result<(), LearnError> {
    let meta = PolicyMeta {
        format_version: POLICY_FORMAT_VERSION,
        algo: "ppo".into(),
        env: identity.env.clone(),
        obs_dim: shape.obs_dim,
        act_dim: shape.act_dim,
        low: shape.low.clone(),
        high: shape.high.clone(),
        hidden: cfg.hidden.clone(),
        activation: cfg.activation,
        separate: cfg.separate,
        obs_norm: obs_norm(rms, cfg.obs_clip as f64),
        iteration,
        env_steps,
        config_ron: crate::config::AlgoConfig::Ppo(cfg.clone()).to_ron(),
        note: note.to_string(),
        discrete: None,
        chunk: 1,
        ensemble: None,
        members: 1,
    };
    write(dir, &meta, record_bytes(model.valid())?)
}

/// Writes a SAC policy (the actor).
#[allow(clippy::too_many_arguments)]
pub(crate) fn export_sac(
    dir: &Path,
    actor: &SacActor,
    cfg: &SacConfig,
    shape: &EnvShape,
    identity: &Identity,
    iteration: u64,
    env_steps: u64,
    note: &str,
) -> Result<(), LearnError> {
    let meta = PolicyMeta {
        format_version: POLICY_FORMAT_VERSION,
        algo: "sac".into(),
        env: identity.env.clone(),
        obs_dim: shape.obs_dim,
        act_dim: shape.act_dim,
        low: shape.low.clone(),
        high: shape.high.clone(),
        hidden: cfg.hidden.clone(),
        activation: cfg.activation,
        separate: false,
        obs_norm: None,
        iteration,
        env_steps,
        config_ron: crate::config::AlgoConfig::Sac(cfg.clone()).to_ron(),
        note: note.to_string(),
        discrete: None,
        chunk: 1,
        ensemble: None,
        members: 1,
    };
    write(dir, &meta, record_bytes(actor.valid())?)
}

/// Largest sizes a policy file may declare (a damaged or hostile file must not make
/// [`Policy::load`] allocate without bound).
const MAX_DIM: usize = 1 << 20;
const MAX_PARAMETERS: usize = 1 << 27;

impl PolicyMeta {
    /// Outputs of the network: the logits of a discrete policy, else the action values.
    pub fn net_outputs(&self) -> usize {
        self.discrete.unwrap_or(self.act_dim * self.chunk)
    }

    /// Checks sizes, bounds and normaliser statistics: the message names the field.
    pub fn check(&self) -> Result<(), String> {
        if !(1..=MAX_DIM).contains(&self.obs_dim) || !(1..=MAX_DIM).contains(&self.act_dim) {
            return Err(format!(
                "obs_dim = {}, act_dim = {}: each in 1..={MAX_DIM}",
                self.obs_dim, self.act_dim
            ));
        }
        if self.hidden.is_empty()
            || self.hidden.len() > 16
            || self.hidden.iter().any(|h| !(1..=MAX_DIM).contains(h))
        {
            return Err(format!(
                "hidden = {:?}: 1 to 16 layers of 1..={MAX_DIM} units",
                self.hidden
            ));
        }
        if let Some(n) = self.discrete {
            if !(2..=MAX_DIM).contains(&n) || self.act_dim != 1 || self.algo != "bc" {
                return Err(format!(
                    "discrete = {n} (algo {}, act_dim {}): 2..={MAX_DIM} keys of a bc policy with act_dim 1",
                    self.algo, self.act_dim
                ));
            }
        }
        if !(1..=MAX_CHUNK).contains(&self.chunk)
            || (self.chunk > 1 && (self.discrete.is_some() || self.algo != "bc"))
        {
            return Err(format!(
                "chunk = {} (algo {}): 1..={} actions, above 1 only for a continuous bc policy",
                self.chunk, self.algo, MAX_CHUNK
            ));
        }
        check_ensemble(self.ensemble, self.chunk, "chunk")?;
        if !(1..=MAX_MEMBERS).contains(&self.members) || (self.members > 1 && self.algo != "bc") {
            return Err(format!(
                "members = {} (algo {}): 1..={MAX_MEMBERS} networks, above 1 only for a bc policy",
                self.members, self.algo
            ));
        }
        let mut params = 0usize;
        let mut width = self.obs_dim;
        for &h in self.hidden.iter().chain([&self.net_outputs()]) {
            params = params.saturating_add(width.saturating_mul(h).saturating_add(h));
            width = h;
        }
        if params > MAX_PARAMETERS {
            return Err(format!(
                "a network of {params} parameters (obs_dim {}, hidden {:?}, act_dim {}): at most {MAX_PARAMETERS}",
                self.obs_dim, self.hidden, self.act_dim
            ));
        }
        if self.low.len() != self.act_dim || self.high.len() != self.act_dim {
            return Err(format!(
                "low and high have {} and {} values: act_dim = {} each",
                self.low.len(),
                self.high.len(),
                self.act_dim
            ));
        }
        if let Some(k) = (0..self.act_dim).find(|&k| {
            let (l, h) = (self.low[k], self.high[k]);
            !(l.is_finite() && h.is_finite() && l <= h && (h - l).is_finite())
        }) {
            return Err(format!(
                "low[{k}] = {}, high[{k}] = {}: finite with low <= high",
                self.low[k], self.high[k]
            ));
        }
        if let Some(n) = &self.obs_norm {
            let stats_ok = n.mean.len() == self.obs_dim
                && n.var.len() == self.obs_dim
                && n.mean.iter().all(|m| m.is_finite())
                && n.var.iter().all(|v| v.is_finite() && *v >= 0.0)
                && n.eps.is_finite()
                && n.eps > 0.0
                && n.clip.is_finite()
                && n.clip > 0.0;
            if !stats_ok {
                return Err(format!(
                    "obs_norm: obs_dim = {} finite means, as many finite variances >= 0, eps > 0 and clip > 0",
                    self.obs_dim
                ));
            }
        }
        Ok(())
    }
}

impl Policy {
    /// Loads a policy from its folder (holding `policy.json`) or from a run folder (holding
    /// `policy/policy.json`).
    pub fn load(dir: impl AsRef<Path>) -> Result<Self, LearnError> {
        let dir = dir.as_ref();
        let dir = if dir.join("policy.json").exists() {
            dir.to_path_buf()
        } else {
            dir.join("policy")
        };
        let meta_path = dir.join("policy.json");
        let text = std::fs::read_to_string(&meta_path)
            .map_err(|e| LearnError::Io(format!("{}: {e}", meta_path.display())))?;
        let meta: PolicyMeta = serde_json::from_str(&text)
            .map_err(|e| LearnError::Checkpoint(format!("{}: {e}", meta_path.display())))?;
        if meta.format_version != POLICY_FORMAT_VERSION {
            return Err(LearnError::Incompatible(format!(
                "{}: policy format version {}, this build reads version {POLICY_FORMAT_VERSION}",
                meta_path.display(),
                meta.format_version
            )));
        }
        meta.check()
            .map_err(|m| LearnError::Checkpoint(format!("{}: {m}", meta_path.display())))?;
        let device = Device::flex();
        let mut nets = Vec::with_capacity(meta.members);
        for m in 0..meta.members {
            let w_path = dir.join(weights_file(m));
            let weights = std::fs::read(&w_path)
                .map_err(|e| LearnError::Io(format!("{}: {e}", w_path.display())))?;
            nets.push(load_net(&meta, &weights, &device)?);
        }
        let policy = Policy { meta, nets, device };
        // Damaged weights (a NaN anywhere in a bias or in the first layer) show in the action
        // of a plain observation: refuse them here rather than return NaN actions later.
        for (m, net) in policy.nets.iter().enumerate() {
            for probe in [0.0f32, 1.0] {
                let x = tensor2(
                    &vec![probe; policy.meta.obs_dim],
                    1,
                    policy.meta.obs_dim,
                    &policy.device,
                );
                if policy.outputs(net, x).iter().any(|v| !v.is_finite()) {
                    return Err(LearnError::Checkpoint(format!(
                        "{}: the weights give non-finite actions (a damaged file?)",
                        dir.join(weights_file(m)).display()
                    )));
                }
            }
        }
        Ok(policy)
    }

    /// What the policy is.
    pub fn meta(&self) -> &PolicyMeta {
        &self.meta
    }

    /// Observation length.
    pub fn obs_dim(&self) -> usize {
        self.meta.obs_dim
    }

    /// Action length.
    pub fn act_dim(&self) -> usize {
        self.meta.act_dim
    }

    /// Deterministic (mean) actions in the environment's units for one or more observations
    /// (`obs.len()` a multiple of `obs_dim`; one row of `act_dim` actions each). A policy of
    /// action chunks gives the first action of each chunk.
    pub fn act(&self, obs: &[f32]) -> Vec<f32> {
        let all = self.act_chunk(obs);
        let (ad, k) = (self.meta.act_dim, self.meta.chunk);
        if k == 1 {
            return all;
        }
        all.chunks_exact(ad * k)
            .flat_map(|c| c[..ad].iter().copied())
            .collect()
    }

    /// [`Policy::act`] with every action of each chunk: `chunk` rows of `act_dim` actions per
    /// observation, to be taken one after another.
    pub fn act_chunk(&self, obs: &[f32]) -> Vec<f32> {
        let od = self.meta.obs_dim;
        assert!(
            !obs.is_empty() && obs.len().is_multiple_of(od),
            "Policy::act: {} values is not a positive multiple of obs_dim {od}",
            obs.len()
        );
        let rows = obs.len() / od;
        let mut o = obs.to_vec();
        if let Some(n) = &self.meta.obs_norm {
            for row in o.chunks_exact_mut(od) {
                for (d, x) in row.iter_mut().enumerate() {
                    let z = (*x as f64 - n.mean[d]) / (n.var[d] + n.eps).sqrt();
                    *x = z.clamp(-n.clip, n.clip) as f32;
                }
            }
        }
        let x = tensor2(&o, rows, od, &self.device);
        // the members' mean (summed in member order, in f64; one network's outputs come back
        // unchanged: an f32 through f64 divided by 1 is itself)
        let mut sum: Vec<f64> = Vec::new();
        for net in &self.nets {
            let y = self.outputs(net, x.clone());
            sum.resize(y.len(), 0.0);
            for (s, v) in sum.iter_mut().zip(&y) {
                *s += f64::from(*v);
            }
        }
        let n = self.nets.len() as f64;
        let out: Vec<f32> = sum.iter().map(|s| (s / n) as f32).collect();
        match self.meta.discrete {
            // the first of the largest logits
            Some(n) => out
                .chunks_exact(n)
                .map(|l| {
                    let mut best = 0;
                    for (k, v) in l.iter().enumerate() {
                        if *v > l[best] {
                            best = k;
                        }
                    }
                    best as f32
                })
                .collect(),
            None => rescale(&out, &self.meta.low, &self.meta.high),
        }
    }

    /// A network's raw outputs for the normalised observations `x`: the logits of a discrete
    /// policy, else the mean action in `[-1, 1]` units.
    fn outputs(&self, net: &Net, x: burn::tensor::Tensor<2>) -> Vec<f32> {
        match (net, self.meta.discrete) {
            (Net::Sac(m), Some(_)) => to_vec(m.forward(x).0),
            (Net::Sac(m), None) => to_vec(m.mean_action(x)),
            (Net::Ppo(m), _) => to_vec(m.mean(x)),
        }
    }
}

/// The network `meta` describes, with the weights `bytes`.
fn load_net(meta: &PolicyMeta, bytes: &[u8], device: &Device) -> Result<Net, LearnError> {
    let mut rng = Rng::new(0);
    Ok(match meta.algo.as_str() {
        "ppo" => {
            let cfg = PpoConfig {
                hidden: meta.hidden.clone(),
                activation: meta.activation,
                separate: meta.separate,
                ..PpoConfig::default()
            };
            let m = ActorCritic::new(&mut rng, meta.obs_dim, meta.act_dim, &cfg, device);
            Net::Ppo(load_record(m, bytes)?)
        }
        // behaviour cloning trains the SAC actor's network
        "sac" | "bc" => {
            let cfg = SacConfig {
                hidden: meta.hidden.clone(),
                activation: meta.activation,
                ..SacConfig::default()
            };
            let m = SacActor::new(&mut rng, meta.obs_dim, meta.net_outputs(), &cfg, device);
            Net::Sac(load_record(m, bytes)?)
        }
        other => {
            return Err(LearnError::Incompatible(format!(
                "unknown policy algorithm '{other}'"
            )));
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn policy_can_be_shared_between_threads() {
        fn send_sync<T: Send + Sync>() {}
        send_sync::<Policy>();
    }
}
