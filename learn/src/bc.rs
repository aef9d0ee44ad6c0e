//! Behaviour cloning: a deterministic policy regressed on demonstrations (observation, action
//! pairs) by mean squared error, written as a policy folder like PPO's and SAC's (`algo: "bc"`,
//! the SAC actor's network: the action is `tanh` of the mean head, scaled into the bounds), so
//! `Policy::load`, `modesuite eval` and `run --policy` use it unchanged.
//!
//! Observations are normalised by the demonstrations' mean and variance (kept in the policy
//! file); actions are regressed in the `[-1, 1]` units of the squashed head. Discrete keys
//! (`Demos::discrete`, the viewer's 14 teleoperation keys) are learned by a classification
//! head instead: the mean head gives one logit per key, trained by cross-entropy, and the
//! policy acts with the arg-max. Training is minibatch Adam over shuffled epochs,
//! deterministic for a seed.

use std::path::Path;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::activation::log_softmax;
use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use crate::actors::{record_bytes, SacActor, NORM_EPS};
use crate::config::SacConfig;
use crate::nets::Activation;
use crate::policy::{self, ObsNorm, PolicyMeta, POLICY_FORMAT_VERSION};
use crate::rng::Rng;
use crate::tensors::{scalar, tensor2};
use crate::LearnError;

/// Settings of behaviour cloning.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BcConfig {
    /// Hidden widths.
    pub hidden: Vec<usize>,
    /// Hidden nonlinearity.
    pub activation: Activation,
    /// Adam's learning rate.
    pub learning_rate: f64,
    /// Passes over the demonstrations.
    pub epochs: usize,
    /// Samples per gradient step.
    pub batch_size: usize,
    /// Seed of the initial weights and the shuffling.
    pub seed: u64,
    /// Normalised observations are clipped to +-this.
    pub obs_clip: f64,
    /// Actions predicted per observation (action chunking, continuous actions only): the
    /// network learns the next `chunk` actions of the demonstration (the episode's last one
    /// repeated past its end) and a policy acting in an env plays a whole chunk before it looks
    /// again. 1 (default): one action per observation.
    pub chunk: usize,
    /// ACT's temporal ensembling of the chunks (`chunk` > 1 only): `Some(m)` makes the policy
    /// observe at every step and play the weighted mean of every chunk's prediction for that
    /// step, the prediction made `i` steps ago weighted `exp(m i)` (the oldest weighs most, as
    /// ACT's `exp(-m j)` with `j = 0` the oldest; ACT's m = 0.01); `None` (default): each chunk
    /// played open-loop to its end. Kept in `policy.json` as `ensemble`.
    pub ensemble: Option<f64>,
    /// Standard deviation of Gaussian noise added to the normalised observations of every
    /// minibatch (fresh noise each time a sample is drawn; 0, the default: none). It teaches the
    /// policy the demonstration's actions in states a little off the demonstrated ones, where a
    /// policy that drifts finds itself. Only training uses it.
    pub input_noise: f64,
    /// Networks trained on the same demonstrations from different initial weights and
    /// shuffles (a deep ensemble; 1, the default: one network). The policy acts with the mean
    /// of their outputs (of their logits for discrete keys), which evens out the luck of one
    /// training seed. Member 0 is the network a single-member run trains; member `m >= 1`
    /// draws from its own streams of `seed`. Kept in `policy.json` as `members`.
    pub members: usize,
}

impl Default for BcConfig {
    fn default() -> Self {
        Self {
            hidden: vec![256, 256],
            activation: Activation::Elu,
            learning_rate: 1e-3,
            epochs: 300,
            batch_size: 256,
            seed: 0,
            obs_clip: 10.0,
            chunk: 1,
            ensemble: None,
            input_noise: 0.0,
            members: 1,
        }
    }
}

impl BcConfig {
    /// Checks the settings; the message names the field.
    pub fn validate(&self) -> Result<(), LearnError> {
        let bad = |m: String| Err(LearnError::Config(m));
        if self.hidden.is_empty() || self.hidden.contains(&0) {
            return bad(format!(
                "hidden = {:?}: at least one layer of >= 1 units",
                self.hidden
            ));
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return bad(format!("learning_rate = {}: > 0", self.learning_rate));
        }
        if self.epochs == 0 || self.batch_size == 0 {
            return bad(format!(
                "epochs = {}, batch_size = {}: each >= 1",
                self.epochs, self.batch_size
            ));
        }
        if !(self.obs_clip.is_finite() && self.obs_clip > 0.0) {
            return bad(format!("obs_clip = {}: > 0", self.obs_clip));
        }
        if !(1..=MAX_CHUNK).contains(&self.chunk) {
            return bad(format!("chunk = {}: 1..={MAX_CHUNK} actions", self.chunk));
        }
        if !(self.input_noise.is_finite() && self.input_noise >= 0.0) {
            return bad(format!("input_noise = {}: a number >= 0", self.input_noise));
        }
        if !(1..=MAX_MEMBERS).contains(&self.members) {
            return bad(format!(
                "members = {}: 1..={MAX_MEMBERS} networks",
                self.members
            ));
        }
        crate::chunks::check_ensemble(self.ensemble, self.chunk, "chunk")
            .map_err(LearnError::Config)
    }
}

pub use crate::policy::{MAX_CHUNK, MAX_ENSEMBLE, MAX_MEMBERS};

/// Demonstrations: one observation and the action taken per sample, row-major.
#[derive(Clone, Debug, Default)]
pub struct Demos {
    /// Observations (`samples x obs_dim`).
    pub obs: Vec<f32>,
    /// Actions (`samples x act_dim`).
    pub act: Vec<f32>,
    /// Observation length.
    pub obs_dim: usize,
    /// Action length.
    pub act_dim: usize,
    /// Lower action bounds (finite).
    pub low: Vec<f32>,
    /// Upper action bounds (finite).
    pub high: Vec<f32>,
    /// `Some(n)`: each action is one key index in `0..n` (`act_dim` 1), learned by a
    /// classification head; `None`: continuous actions.
    pub discrete: Option<usize>,
    /// One past the last sample of each demonstration, increasing (empty: the samples are one
    /// demonstration); action chunks stop at these.
    pub episode_ends: Vec<usize>,
}

impl Demos {
    /// Samples.
    pub fn len(&self) -> usize {
        self.obs.len() / self.obs_dim.max(1)
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// What a behaviour-cloning run did.
#[derive(Clone, Debug, PartialEq)]
pub struct BcSummary {
    /// Samples trained on.
    pub samples: usize,
    /// Loss of the last epoch: mean squared error in the squashed units, or the cross-entropy
    /// of discrete keys (an ensemble's: the mean over its members).
    pub final_loss: f64,
    /// Gradient steps taken (all members together).
    pub steps: u64,
}

fn normaliser(d: &Demos, clip: f64) -> ObsNorm {
    let n = d.len().max(1) as f64;
    let mut mean = vec![0.0; d.obs_dim];
    let mut var = vec![0.0; d.obs_dim];
    for row in d.obs.chunks_exact(d.obs_dim) {
        for (k, x) in row.iter().enumerate() {
            mean[k] += f64::from(*x) / n;
        }
    }
    for row in d.obs.chunks_exact(d.obs_dim) {
        for (k, x) in row.iter().enumerate() {
            var[k] += (f64::from(*x) - mean[k]).powi(2) / n;
        }
    }
    ObsNorm {
        mean,
        var,
        eps: NORM_EPS,
        clip,
    }
}

/// Trains a policy on `demos` and writes it into `out` (`policy.json`, `weights.bpk`, and
/// `weights.member<m>.bpk` for each further member); `progress(epoch, loss)` after each epoch,
/// its first argument counting the epochs finished so far by all members together
/// (`members x epochs` in all; the summary's loss is the members' mean). An ensemble's members
/// train on up to `threads` threads side by side (0: all cores); each draws from its own
/// random streams, so the policy does not depend on `threads`. `env` is the environment's
/// identity string and `note` the policy's note (the CLI records the target and action modes
/// there).
pub fn train_bc(
    demos: &Demos,
    cfg: &BcConfig,
    threads: usize,
    env: &str,
    note: &str,
    out: &Path,
    mut progress: impl FnMut(usize, f64),
) -> Result<BcSummary, LearnError> {
    cfg.validate()?;
    let (od, ad, n) = (demos.obs_dim, demos.act_dim, demos.len());
    if n == 0 || od == 0 || ad == 0 || demos.act.len() != n * ad {
        return Err(LearnError::Config(format!(
            "demonstrations: {n} samples of {od} observation and {ad} action values ({} actions given)",
            demos.act.len()
        )));
    }
    if demos.low.len() != ad || demos.high.len() != ad {
        return Err(LearnError::Config(
            "action bounds: one low and high per action value".into(),
        ));
    }
    if let Some(k) = demos.discrete {
        let bad = demos
            .act
            .iter()
            .position(|a| !(a.fract() == 0.0 && *a >= 0.0 && (*a as usize) < k));
        if ad != 1 || k < 2 || bad.is_some() {
            return Err(LearnError::Config(format!(
                "discrete demonstrations: one key index in 0..{k} per sample (act_dim {ad}{})",
                bad.map_or(String::new(), |i| format!(
                    ", sample {i} has {}",
                    demos.act[i]
                ))
            )));
        }
    }
    let k = cfg.chunk;
    if k > 1 && demos.discrete.is_some() {
        return Err(LearnError::Config(format!(
            "chunk = {k}: action chunks are for continuous actions (these are discrete keys)"
        )));
    }
    if demos.episode_ends.windows(2).any(|w| w[0] >= w[1])
        || demos.episode_ends.last().is_some_and(|e| *e != n)
    {
        return Err(LearnError::Config(format!(
            "episode_ends: increasing, the last = the {n} samples"
        )));
    }
    let norm = normaliser(demos, cfg.obs_clip);
    let obs: Vec<f32> = demos
        .obs
        .chunks_exact(od)
        .flat_map(|row| {
            row.iter().enumerate().map(|(k, x)| {
                let z = (f64::from(*x) - norm.mean[k]) / (norm.var[k] + norm.eps).sqrt();
                z.clamp(-norm.clip, norm.clip) as f32
            })
        })
        .collect();
    // targets: one-hot keys, or the squashed head's units kept off +-1 (no tanh preimage)
    let outputs = demos.discrete.unwrap_or(ad * k);
    let target: Vec<f32> = match demos.discrete {
        Some(k) => demos
            .act
            .iter()
            .flat_map(|a| (0..k).map(move |j| if j == *a as usize { 1.0 } else { 0.0 }))
            .collect(),
        None => {
            let squashed: Vec<f32> = demos
                .act
                .iter()
                .enumerate()
                .map(|(i, a)| {
                    let (l, h) = (demos.low[i % ad], demos.high[i % ad]);
                    let u = if h > l {
                        2.0 * (a - l) / (h - l) - 1.0
                    } else {
                        0.0
                    };
                    u.clamp(-0.999, 0.999)
                })
                .collect();
            // each sample's next k actions, the demonstration's last repeated past its end
            let ends: &[usize] = if demos.episode_ends.is_empty() {
                &[n]
            } else {
                &demos.episode_ends
            };
            let mut t = Vec::with_capacity(n * ad * k);
            let mut begin = 0;
            for &end in ends {
                for i in begin..end {
                    for j in 0..k {
                        let s = (i + j).min(end - 1);
                        t.extend_from_slice(&squashed[s * ad..(s + 1) * ad]);
                    }
                }
                begin = end;
            }
            t
        }
    };
    let data = MemberData {
        obs: &obs,
        target: &target,
        od,
        outputs,
        discrete: demos.discrete.is_some(),
    };
    let trained = train_members(&data, cfg, threads, &mut progress)?;
    let loss_sum: f64 = trained.iter().map(|m| m.final_loss).sum();
    let steps = trained.iter().map(|m| m.steps).sum();
    let weights = trained.into_iter().map(|m| m.weights).collect();
    let meta = PolicyMeta {
        format_version: POLICY_FORMAT_VERSION,
        algo: "bc".into(),
        env: env.to_string(),
        obs_dim: od,
        act_dim: ad,
        low: demos.low.clone(),
        high: demos.high.clone(),
        hidden: cfg.hidden.clone(),
        activation: cfg.activation,
        separate: false,
        obs_norm: Some(norm),
        iteration: cfg.epochs as u64,
        env_steps: n as u64,
        config_ron: ron::ser::to_string_pretty(cfg, ron::ser::PrettyConfig::default())
            .map_err(|e| LearnError::Config(e.to_string()))?,
        note: note.to_string(),
        discrete: demos.discrete,
        chunk: k,
        ensemble: cfg.ensemble,
        members: cfg.members,
    };
    std::fs::create_dir_all(out).map_err(|e| LearnError::Io(format!("{}: {e}", out.display())))?;
    policy::write_members(out, &meta, weights)?;
    Ok(BcSummary {
        samples: n,
        final_loss: loss_sum / cfg.members as f64,
        steps,
    })
}

/// The normalised inputs and targets every member trains on.
struct MemberData<'a> {
    obs: &'a [f32],
    target: &'a [f32],
    od: usize,
    outputs: usize,
    discrete: bool,
}

/// One trained member: its weights (burnpack bytes), last epoch's loss and gradient steps.
struct Member {
    weights: Vec<u8>,
    final_loss: f64,
    steps: u64,
}

/// Trains the `cfg.members` networks on up to `threads` worker threads (0: all cores; one
/// worker trains them one after another), and returns them in member order; `progress` is
/// called on this thread after every epoch of any member.
fn train_members(
    data: &MemberData,
    cfg: &BcConfig,
    threads: usize,
    progress: &mut impl FnMut(usize, f64),
) -> Result<Vec<Member>, LearnError> {
    let threads = match threads {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        t => t,
    }
    .clamp(1, cfg.members);
    let (tx, rx) = std::sync::mpsc::channel::<f64>();
    let results = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..threads)
            .map(|w| {
                let tx = tx.clone();
                scope.spawn(move || {
                    // worker w trains members w, w + threads, ... and stops at its first error
                    let mut out = Vec::new();
                    for m in (w..cfg.members).step_by(threads) {
                        let r = train_member(m, data, cfg, &mut |loss| {
                            let _ = tx.send(loss);
                        });
                        let failed = r.is_err();
                        out.push((m, r));
                        if failed {
                            break;
                        }
                    }
                    out
                })
            })
            .collect();
        drop(tx);
        for (done, loss) in rx.into_iter().enumerate() {
            progress(done, loss);
        }
        workers
            .into_iter()
            .flat_map(|h| h.join().expect("a BC member's thread panicked"))
            .collect::<Vec<_>>()
    });
    let mut ordered: Vec<Option<Result<Member, LearnError>>> =
        (0..cfg.members).map(|_| None).collect();
    for (m, r) in results {
        ordered[m] = Some(r);
    }
    // in member order: a worker's error comes before the members it left untrained
    let mut members = Vec::with_capacity(cfg.members);
    for r in ordered {
        members.push(r.expect("members after a failed one are not reached")?);
    }
    Ok(members)
}

/// Trains member `member` of the ensemble (member 0 draws exactly as a single network always
/// has, the others from streams of their own); `epoch_done(loss)` after each epoch.
fn train_member(
    member: usize,
    data: &MemberData,
    cfg: &BcConfig,
    epoch_done: &mut dyn FnMut(f64),
) -> Result<Member, LearnError> {
    let MemberData {
        obs,
        target,
        od,
        outputs,
        discrete,
    } = *data;
    let n = obs.len() / od;
    let device = Device::flex().autodiff();
    let sac = SacConfig {
        hidden: cfg.hidden.clone(),
        activation: cfg.activation,
        ..SacConfig::default()
    };
    let b = cfg.batch_size.min(n);
    let (mut rng, mut noise_rng) = if member == 0 {
        (Rng::new(cfg.seed), Rng::derive(cfg.seed, 1))
    } else {
        let m = member as u64;
        (
            Rng::derive(cfg.seed, 2 * m + 100),
            Rng::derive(cfg.seed, 2 * m + 101),
        )
    };
    let mut actor = SacActor::new(&mut rng, od, outputs, &sac, &device);
    let mut opt = AdamConfig::new().with_epsilon(1e-8).init();
    let mut order: Vec<usize> = (0..n).collect();
    let (mut final_loss, mut steps) = (0.0, 0u64);
    for epoch in 0..cfg.epochs {
        rng.shuffle(&mut order);
        let (mut sum, mut count) = (0.0, 0usize);
        for chunk in order.chunks(b) {
            let rows = chunk.len();
            let mut x = Vec::with_capacity(rows * od);
            let mut y = Vec::with_capacity(rows * outputs);
            for &i in chunk {
                x.extend_from_slice(&obs[i * od..(i + 1) * od]);
                y.extend_from_slice(&target[i * outputs..(i + 1) * outputs]);
            }
            if cfg.input_noise > 0.0 {
                for v in &mut x {
                    *v += (cfg.input_noise * noise_rng.normal()) as f32;
                }
            }
            let x = tensor2(&x, rows, od, &device);
            let y = tensor2(&y, rows, outputs, &device);
            let loss = if discrete {
                // cross-entropy of the logits against the one-hot keys
                let logp = log_softmax(actor.forward(x).0, 1);
                -(logp * y).sum_dim(1).mean()
            } else {
                (actor.mean_action(x) - y).square().mean()
            };
            let grads = GradientsParams::from_grads(loss.backward(), &actor);
            actor = opt.step(cfg.learning_rate, actor, grads);
            let l = f64::from(scalar(loss));
            if !l.is_finite() {
                return Err(LearnError::Diverged(format!(
                    "behaviour cloning: the loss became {l} in epoch {epoch}{}",
                    if member > 0 {
                        format!(" of member {member}")
                    } else {
                        String::new()
                    }
                )));
            }
            sum += l * rows as f64;
            count += rows;
            steps += 1;
        }
        final_loss = sum / count.max(1) as f64;
        epoch_done(final_loss);
    }
    Ok(Member {
        weights: record_bytes(actor.valid())?,
        final_loss,
        steps,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::policy::Policy;

    /// Continuous demonstrations of one observation and one action in [-1, 1].
    fn demos_1d(obs: Vec<f32>, act: Vec<f32>, episode_ends: Vec<usize>) -> Demos {
        Demos {
            obs,
            act,
            obs_dim: 1,
            act_dim: 1,
            low: vec![-1.0],
            high: vec![1.0],
            discrete: None,
            episode_ends,
        }
    }

    /// An ensemble of 3 members acts with the mean of its networks' outputs (in `[-1, 1]`
    /// units, then scaled into the bounds): each member loaded alone (its weights file renamed
    /// to `weights.bpk`, `members` 1) gives its part, member 0 is bit for bit the network a
    /// single-member run trains, the members differ, members trained on several threads give
    /// the same policy, and a discrete ensemble takes the arg-max of the mean logits.
    #[test]
    fn an_ensemble_acts_with_the_mean_of_its_members() {
        // a noisy target: the members fit it differently
        let obs: Vec<f32> = (0..40).map(|i| i as f32 * 0.05).collect();
        let act: Vec<f32> = obs.iter().map(|x| (3.0 * x).sin() * 0.6).collect();
        let demos = Demos {
            low: vec![-2.0],
            high: vec![2.0],
            ..demos_1d(obs, act, vec![40])
        };
        let cfg = BcConfig {
            hidden: vec![16],
            epochs: 20,
            batch_size: 8,
            members: 3,
            ..BcConfig::default()
        };
        let base =
            std::env::temp_dir().join(format!("modesuite-bc-members-{}", std::process::id()));
        let dir = base.join("ens");
        let mut epochs = 0;
        train_bc(&demos, &cfg, 1, "sine", "{}", &dir, |_, _| epochs += 1).unwrap();
        assert_eq!(epochs, 60, "progress counts every member's epochs");
        let ens = Policy::load(&dir).unwrap();
        assert_eq!(ens.meta().members, 3);
        let x = [0.3f32, 1.1, 1.9];
        let got = ens.act(&x);
        // the members trained on 2 and 3 threads side by side: the same policy, bit for bit
        for threads in [2, 3] {
            let d = base.join(format!("threads{threads}"));
            let mut count = 0;
            train_bc(&demos, &cfg, threads, "sine", "{}", &d, |_, _| count += 1).unwrap();
            assert_eq!(
                count, 60,
                "progress counts every member's epochs ({threads} threads)"
            );
            assert_eq!(Policy::load(&d).unwrap().act(&x), got, "{threads} threads");
        }
        // each member alone
        let parts: Vec<Vec<f32>> = (0..3)
            .map(|m| {
                let d = base.join(format!("m{m}"));
                std::fs::create_dir_all(&d).unwrap();
                std::fs::copy(
                    dir.join(crate::policy::weights_file(m)),
                    d.join("weights.bpk"),
                )
                .unwrap();
                let mut meta = ens.meta().clone();
                meta.members = 1;
                std::fs::write(d.join("policy.json"), serde_json::to_string(&meta).unwrap())
                    .unwrap();
                Policy::load(&d).unwrap().act(&x)
            })
            .collect();
        assert_ne!(parts[0], parts[1]);
        assert_ne!(parts[1], parts[2]);
        for (i, g) in got.iter().enumerate() {
            // back to [-1, 1] units (bounds -2..2), averaged, scaled again
            let mean = parts.iter().map(|p| f64::from(p[i]) / 2.0).sum::<f64>() / 3.0;
            println!(
                "members' mean at {}: {g} (from the parts {:.6}), tolerance 1e-6",
                x[i],
                2.0 * mean
            );
            assert!(
                (f64::from(*g) - 2.0 * mean).abs() < 1e-6,
                "{got:?} vs {parts:?}"
            );
        }
        // member 0 is the single network of the same seed
        let one = base.join("one");
        train_bc(
            &demos,
            &BcConfig {
                members: 1,
                ..cfg.clone()
            },
            1,
            "sine",
            "{}",
            &one,
            |_, _| {},
        )
        .unwrap();
        // (the files' bytes differ: burnpack records carry each parameter's own id)
        assert_eq!(Policy::load(&one).unwrap().act(&x), parts[0]);
        // discrete keys: the arg-max of the members' mean logits
        let keys = Demos {
            discrete: Some(3),
            act: (0..40).map(|i| (i / 14) as f32).collect(),
            ..demos.clone()
        };
        let kdir = base.join("keys");
        train_bc(
            &keys,
            &BcConfig {
                epochs: 200,
                ..cfg.clone()
            },
            1,
            "keys",
            "{}",
            &kdir,
            |_, _| {},
        )
        .unwrap();
        let kp = Policy::load(&kdir).unwrap();
        assert_eq!(kp.act(&[0.1, 1.0, 1.9]), vec![0.0, 1.0, 2.0]);
        // out of range, and a missing member's file, are refused with the field or the file
        let e = BcConfig {
            members: 0,
            ..cfg.clone()
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("members = 0"), "{e}");
        std::fs::remove_file(dir.join("weights.member2.bpk")).unwrap();
        let e = Policy::load(&dir).err().unwrap().to_string();
        assert!(e.contains("weights.member2.bpk"), "{e}");
        let _ = std::fs::remove_dir_all(&base);
    }

    /// Action chunks: a policy of chunk 3 learns each sample's next three actions, the
    /// demonstration's last one repeated past its end (never the next demonstration's), and
    /// `act` gives the first of them. Two demonstrations of a counter: observation t, action t
    /// (scaled), so the chunk after t is t, t+1, t+2 up to the end.
    #[test]
    fn action_chunks_are_the_next_actions_of_the_same_demonstration() {
        let (mut obs, mut act) = (Vec::new(), Vec::new());
        for len in [6usize, 4] {
            for t in 0..len {
                obs.push(t as f32);
                act.push(t as f32 * 0.1);
            }
        }
        let demos = demos_1d(obs, act, vec![6, 10]);
        let cfg = BcConfig {
            hidden: vec![64, 64],
            epochs: 3000,
            batch_size: 10,
            chunk: 3,
            ..BcConfig::default()
        };
        let dir = std::env::temp_dir().join(format!("modesuite-bc-chunk-{}", std::process::id()));
        let s = train_bc(&demos, &cfg, 1, "counter", "{}", &dir, |_, _| {}).unwrap();
        let p = Policy::load(&dir).unwrap();
        assert_eq!((p.meta().chunk, p.act_dim()), (3, 1));
        // t = 4 of the first demonstration: 0.4, 0.5, then its last (0.5) again, not the
        // second demonstration's first (0.0); at t = 3 the first goes on (0.3, 0.4, 0.5) and
        // the second ends (0.3, 0.3, 0.3): the network learns their mean
        let got = p.act_chunk(&[4.0]);
        let at3 = p.act_chunk(&[3.0]);
        println!(
            "chunk BC (MSE {:.2e}): after 4 {got:?} (0.4, 0.5, 0.5), after 3 {at3:?} (0.3, 0.35, 0.4), tolerance 0.02",
            s.final_loss
        );
        for (g, w) in got.iter().zip([0.4, 0.5, 0.5]) {
            assert!((g - w).abs() < 0.02, "{got:?}");
        }
        for (g, w) in at3.iter().zip([0.3, 0.35, 0.4]) {
            assert!((g - w).abs() < 0.02, "{at3:?}");
        }
        let last = at3;
        assert_eq!(p.act(&[4.0, 3.0]), vec![got[0], last[0]]);
        // chunks are for continuous actions; ends must close the samples
        let keys = Demos {
            discrete: Some(3),
            act: vec![0.0; 10],
            ..demos.clone()
        };
        let e = train_bc(&keys, &cfg, 1, "k", "{}", &dir, |_, _| {}).unwrap_err();
        assert!(e.to_string().contains("chunk = 3"), "{e}");
        let bad_ends = Demos {
            episode_ends: vec![6, 9],
            ..demos.clone()
        };
        let e = train_bc(&bad_ends, &cfg, 1, "k", "{}", &dir, |_, _| {}).unwrap_err();
        assert!(e.to_string().contains("episode_ends"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Input noise regresses the action on noisy observations: a step from -0.5 to 0.5 at 0
    /// is learned sharp without noise and smoothed to about the Gaussian's closed form with
    /// it (E[y | x + e = z] = 0.5 (2 Phi(z / s) - 1) well inside the data); bad values refused.
    #[test]
    fn input_noise_smooths_the_learned_action() {
        let obs: Vec<f32> = (0..200).map(|i| (i as f32 + 0.5) / 100.0 - 1.0).collect();
        let act: Vec<f32> = obs.iter().map(|x| 0.5 * x.signum()).collect();
        let demos = demos_1d(obs.clone(), act, Vec::new());
        let at = |noise: f64| {
            let cfg = BcConfig {
                hidden: vec![64, 64],
                epochs: 400,
                batch_size: 50,
                input_noise: noise,
                ..BcConfig::default()
            };
            let dir = std::env::temp_dir()
                .join(format!("modesuite-bc-noise-{noise}-{}", std::process::id()));
            train_bc(&demos, &cfg, 1, "step", "{}", &dir, |_, _| {}).unwrap();
            let a = Policy::load(&dir).unwrap().act(&[0.1])[0];
            let _ = std::fs::remove_dir_all(&dir);
            a
        };
        // x = 0.1 is z = 0.1 / std(x) = 0.173 in normalised units
        let std = (obs.iter().map(|x| x * x).sum::<f32>() / 200.0).sqrt();
        let z = f64::from(0.1 / std);
        // the normal CDF by Abramowitz and Stegun 7.1.26 (|error| < 1.5e-7), for u >= 0
        let phi = |u: f64| {
            let x = u / std::f64::consts::SQRT_2;
            let t = 1.0 / (1.0 + 0.327_591_1 * x);
            let poly = t
                * (0.254_829_592
                    + t * (-0.284_496_736
                        + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
            0.5 * (2.0 - poly * (-x * x).exp())
        };
        let want = 0.5 * (2.0 * phi(z / 0.5) - 1.0);
        let (sharp, smooth) = (at(0.0), at(0.5));
        println!(
            "BC at x = 0.1: no noise {sharp:.3} (tolerance > 0.4), noise 0.5 {smooth:.3} (closed form {want:.3} +- 0.08)"
        );
        assert!(sharp > 0.4, "{sharp}");
        assert!(
            (f64::from(smooth) - want).abs() < 0.08,
            "{smooth} vs {want}"
        );
        let cfg = BcConfig {
            input_noise: -0.1,
            ..BcConfig::default()
        };
        let e = cfg.validate().unwrap_err().to_string();
        assert!(e.contains("input_noise = -0.1"), "{e}");
    }

    /// Three keys by the sign pattern of a 2-d observation: the classification head learns
    /// them exactly, the saved policy acts with the arg-max, and bad keys are refused.
    #[test]
    fn discrete_keys_are_learned_by_a_classification_head() {
        let mut obs = Vec::new();
        let mut act = Vec::new();
        let key = |x: f32, y: f32| -> f32 {
            if x < -0.3 {
                0.0
            } else if y > 0.0 {
                1.0
            } else {
                2.0
            }
        };
        for i in 0..200 {
            let (x, y) = (
                ((i * 37) % 200) as f32 / 100.0 - 1.0,
                ((i * 71) % 200) as f32 / 100.0 - 1.0,
            );
            obs.extend([x, y]);
            act.push(key(x, y));
        }
        let demos = Demos {
            obs: obs.clone(),
            act: act.clone(),
            obs_dim: 2,
            act_dim: 1,
            low: vec![0.0],
            high: vec![2.0],
            discrete: Some(3),
            episode_ends: Vec::new(),
        };
        let cfg = BcConfig {
            hidden: vec![64, 64],
            epochs: 400,
            batch_size: 50,
            ..BcConfig::default()
        };
        let dir =
            std::env::temp_dir().join(format!("modesuite-bc-discrete-{}", std::process::id()));
        let s = train_bc(&demos, &cfg, 1, "keys", "{}", &dir, |_, _| {}).unwrap();
        let p = Policy::load(&dir).unwrap();
        assert_eq!((p.meta().discrete, p.act_dim()), (Some(3), 1));
        let got = p.act(&obs);
        let right = got.iter().zip(&act).filter(|(a, b)| a == b).count();
        println!(
            "discrete BC: cross-entropy {:.4}, {right}/200 keys right (tolerance: all)",
            s.final_loss
        );
        assert_eq!(right, 200);
        let mut bad = demos.clone();
        bad.act[7] = 3.0;
        let e = train_bc(&bad, &cfg, 1, "keys", "{}", &dir, |_, _| {}).unwrap_err();
        assert!(e.to_string().contains("sample 7 has 3"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
