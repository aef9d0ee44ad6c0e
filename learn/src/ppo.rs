//! Proximal policy optimisation as rl_games' `a2c_continuous` runs it: a Gaussian policy with a
//! state-independent log standard deviation, shared or separate MLPs, GAE with time limits
//! bootstrapped, clipped surrogate and clipped value loss, adaptive-KL learning rate per
//! minibatch, running observation and value normalisation, bounds loss and global
//! gradient-norm clipping.
//!
//! Differences from rl_games, on purpose: observation statistics are updated once per
//! environment step with the observations acted on (rl_games updates them in every training
//! forward pass, counting each sample once per epoch); value statistics are updated with each
//! rollout's returns only; minibatches are shuffled every epoch; a time-limit step bootstraps
//! from the value of its final observation (rl_games uses the value of the observation acted
//! on).

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Tensor};
use std::time::Instant;

pub use crate::actors::ActorCritic;
use crate::actors::{guarded, load_record, rec_err, record_bytes, NORM_EPS};
use crate::checkpoint::{Checkpoint, Identity};
use crate::config::{AlgoConfig, PpoConfig};
use crate::dist::{bounds_loss, gaussian_entropy, gaussian_kl, gaussian_log_prob};
use crate::gae::gae;
use crate::metrics::{EpisodeTracker, Metrics};
use crate::nets::{clip_grad_norm, flat_params};
use crate::normalize::RunningMeanStd;
use crate::rng::Rng;
use crate::runner::{check_step, gather_rows, rescale, restart, EnvShape, Trainer};
use crate::tensors::{scalar, tensor1, tensor2, to_vec};
use crate::{LearnError, VecEnvironment};

/// rl_games clips normalised values to +-5.
const VALUE_CLIP: f64 = 5.0;

/// Statistics of one PPO update that tests and diagnostics look at.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UpdateStats {
    /// Largest |ratio - 1| in the first minibatch of the first epoch (0 when the rollout's
    /// log-probabilities are reproduced exactly).
    pub first_minibatch_max_ratio_deviation: f32,
    /// Clip fraction of that minibatch.
    pub first_minibatch_clip_fraction: f32,
}

struct Rollout {
    obs: Vec<f32>,
    actions: Vec<f32>,
    logp: Vec<f32>,
    mu: Vec<f32>,
    values: Vec<f32>,
    rewards: Vec<f32>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
    final_values: Vec<f32>,
}

/// A PPO learner attached to an environment batch (see [`crate::train`]).
pub struct Ppo {
    cfg: PpoConfig,
    shape: EnvShape,
    device: Device,
    model: ActorCritic,
    optim: ModuleOptimizer,
    lr: f64,
    obs_rms: RunningMeanStd,
    value_rms: RunningMeanStd,
    rng: Rng,
    obs: Vec<f32>,
    tracker: EpisodeTracker,
    iteration: u64,
    env_steps: u64,
    wall_s: f64,
    resets: u64,
    /// Statistics of the last update.
    pub last_update: UpdateStats,
}

fn optimizer(cfg: &PpoConfig) -> ModuleOptimizer {
    AdamConfig::new().with_epsilon(cfg.adam_eps).init()
}

impl Ppo {
    /// A new learner; resets the environments with the configuration's seed.
    pub fn new(cfg: &PpoConfig, env: &mut dyn VecEnvironment) -> Result<Self, LearnError> {
        AlgoConfig::Ppo(cfg.clone()).validate()?;
        let shape = EnvShape::of(env)?;
        let device = Device::flex().autodiff();
        let mut rng = Rng::new(cfg.seed);
        let model = ActorCritic::new(&mut rng, shape.obs_dim, shape.act_dim, cfg, &device);
        let obs = env.reset(cfg.seed).map_err(LearnError::Env)?;
        shape.check_obs(&obs, "reset")?;
        Ok(Ppo {
            cfg: cfg.clone(),
            optim: optimizer(cfg),
            lr: cfg.learning_rate,
            obs_rms: RunningMeanStd::new(shape.obs_dim),
            value_rms: RunningMeanStd::new(1),
            tracker: EpisodeTracker::new(shape.n),
            shape,
            device,
            model,
            rng,
            obs,
            iteration: 0,
            env_steps: 0,
            wall_s: 0.0,
            resets: 0,
            last_update: UpdateStats::default(),
        })
    }

    /// The network.
    pub fn model(&self) -> &ActorCritic {
        &self.model
    }

    /// Current learning rate.
    pub fn learning_rate(&self) -> f64 {
        self.lr
    }

    fn normalized(&self, obs: &[f32]) -> Vec<f32> {
        let mut o = obs.to_vec();
        if self.cfg.normalize_obs {
            self.obs_rms
                .normalize(&mut o, NORM_EPS, self.cfg.obs_clip as f64);
        }
        o
    }

    fn denorm_values(&self, v: &mut [f32]) {
        if self.cfg.normalize_value {
            self.value_rms.denormalize(v, NORM_EPS);
        }
    }

    fn collect(&mut self, env: &mut dyn VecEnvironment) -> Result<Rollout, LearnError> {
        let (n, od, ad) = (self.shape.n, self.shape.obs_dim, self.shape.act_dim);
        let t_len = self.cfg.horizon;
        let infer = self.model.valid();
        let dev = Device::flex();
        let log_std = to_vec(infer.log_std.val());
        let std: Vec<f32> = log_std.iter().map(|l| l.exp()).collect();
        let log_std_t = tensor2(&log_std, 1, ad, &dev);
        let mut r = Rollout {
            obs: Vec::with_capacity(t_len * n * od),
            actions: Vec::with_capacity(t_len * n * ad),
            logp: Vec::with_capacity(t_len * n),
            mu: Vec::with_capacity(t_len * n * ad),
            values: Vec::with_capacity(t_len * n),
            rewards: Vec::with_capacity(t_len * n),
            terminated: Vec::with_capacity(t_len * n),
            truncated: Vec::with_capacity(t_len * n),
            final_values: Vec::with_capacity(t_len * n),
        };
        for _ in 0..t_len {
            if self.cfg.normalize_obs {
                self.obs_rms.update(&self.obs);
            }
            let obs_n = self.normalized(&self.obs);
            let (mu_t, v_t) = infer.forward(tensor2(&obs_n, n, od, &dev));
            let mu = to_vec(mu_t.clone());
            let mut v = to_vec(v_t);
            self.denorm_values(&mut v);
            let mut a = vec![0.0f32; n * ad];
            for (k, x) in a.iter_mut().enumerate() {
                *x = mu[k] + std[k % ad] * self.rng.normal() as f32;
            }
            let logp = to_vec(gaussian_log_prob(
                tensor2(&a, n, ad, &dev),
                mu_t,
                log_std_t.clone(),
            ));
            let env_actions = rescale(&a, &self.shape.low, &self.shape.high);
            let step = env.step(&env_actions).map_err(LearnError::Env)?;
            check_step(&self.shape, &step)?;
            self.tracker.record(&step);
            // Values of the final observations of episodes cut by a time limit.
            let mut final_values = vec![0.0f32; n];
            let cut: Vec<usize> = (0..n)
                .filter(|&i| {
                    step.truncated[i] && !step.terminated[i] && self.cfg.bootstrap_truncation
                })
                .collect();
            if !cut.is_empty() {
                let mut fo = Vec::with_capacity(cut.len() * od);
                for &i in &cut {
                    fo.extend_from_slice(
                        step.final_obs[i].as_ref().expect("checked by check_step"),
                    );
                }
                let fo = self.normalized(&fo);
                let (_, fv) = infer.forward(tensor2(&fo, cut.len(), od, &dev));
                let mut fv = to_vec(fv);
                self.denorm_values(&mut fv);
                for (j, &i) in cut.iter().enumerate() {
                    final_values[i] = fv[j];
                }
            }
            r.obs.extend_from_slice(&obs_n);
            r.actions.extend_from_slice(&a);
            r.logp.extend_from_slice(&logp);
            r.mu.extend_from_slice(&mu);
            r.values.extend_from_slice(&v);
            r.rewards.extend_from_slice(&step.rewards);
            if self.cfg.bootstrap_truncation {
                r.terminated.extend_from_slice(&step.terminated);
            } else {
                r.terminated
                    .extend((0..n).map(|i| step.terminated[i] || step.truncated[i]));
            }
            r.truncated.extend_from_slice(&step.truncated);
            r.final_values.extend_from_slice(&final_values);
            self.obs = step.obs;
            self.env_steps += n as u64;
        }
        Ok(r)
    }

    fn last_values(&self) -> Vec<f32> {
        let infer = self.model.valid();
        let obs_n = self.normalized(&self.obs);
        let (_, v) = infer.forward(tensor2(
            &obs_n,
            self.shape.n,
            self.shape.obs_dim,
            &Device::flex(),
        ));
        let mut v = to_vec(v);
        self.denorm_values(&mut v);
        v
    }

    fn update(&mut self, r: Rollout, m: &mut Metrics) -> Result<(), LearnError> {
        let (n, od, ad) = (self.shape.n, self.shape.obs_dim, self.shape.act_dim);
        let cfg = self.cfg.clone();
        let last = self.last_values();
        let (mut adv, returns) = gae(
            n,
            &r.rewards,
            &r.values,
            &last,
            &r.final_values,
            &r.terminated,
            &r.truncated,
            cfg.gamma,
            cfg.lambda,
        );
        let mut old_v = r.values.clone();
        let mut ret = returns;
        if cfg.normalize_value {
            self.value_rms.update(&ret);
            self.value_rms.normalize(&mut old_v, NORM_EPS, VALUE_CLIP);
            self.value_rms.normalize(&mut ret, NORM_EPS, VALUE_CLIP);
        }
        if cfg.normalize_advantage {
            let mean = adv.iter().map(|a| *a as f64).sum::<f64>() / adv.len() as f64;
            let var =
                adv.iter().map(|a| (*a as f64 - mean).powi(2)).sum::<f64>() / adv.len() as f64;
            let std = var.sqrt();
            for a in &mut adv {
                *a = ((*a as f64 - mean) / (std + 1e-8)) as f32;
            }
        }
        let total = adv.len();
        let mb = cfg.minibatch_size.min(total);
        let batches = total / mb;
        let old_sigma: Vec<f32> = to_vec(self.model.log_std.val())
            .iter()
            .map(|l| l.exp())
            .collect();
        let mut idx: Vec<usize> = (0..total).collect();
        let (mut sum_a, mut sum_c, mut sum_e, mut sum_b, mut sum_kl, mut sum_clip, mut sum_gn) =
            (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let mut count = 0usize;
        for epoch in 0..cfg.mini_epochs {
            self.rng.shuffle(&mut idx);
            for b in 0..batches {
                let ids = &idx[b * mb..(b + 1) * mb];
                let d = &self.device;
                let obs = tensor2(&gather_rows(&r.obs, od, ids), mb, od, d);
                let act = tensor2(&gather_rows(&r.actions, ad, ids), mb, ad, d);
                let old_logp = tensor1(&gather_rows(&r.logp, 1, ids), d);
                let old_mu = tensor2(&gather_rows(&r.mu, ad, ids), mb, ad, d);
                let a_t = tensor1(&gather_rows(&adv, 1, ids), d);
                let ov = tensor1(&gather_rows(&old_v, 1, ids), d);
                let rt = tensor1(&gather_rows(&ret, 1, ids), d);

                let (mu, v) = self.model.forward(obs);
                let v: Tensor<1> = v.squeeze_dim(1);
                let log_std = self.model.log_std.val();
                let logp = gaussian_log_prob(act, mu.clone(), log_std.clone());
                let ratio = (logp - old_logp).exp();
                let surr1 = ratio.clone() * a_t.clone();
                let surr2 = ratio.clone().clamp(1.0 - cfg.clip, 1.0 + cfg.clip) * a_t;
                let actor_loss = surr1.min_pair(surr2).mean().neg();
                let vl = (v.clone() - rt.clone()).square();
                let critic_loss = if cfg.clip_value {
                    let vc = ov.clone() + (v - ov).clamp(-cfg.clip, cfg.clip);
                    vl.max_pair((vc - rt).square()).mean()
                } else {
                    vl.mean()
                };
                let entropy = gaussian_entropy(log_std.clone()).mean();
                let b_loss = bounds_loss(mu.clone(), 1.1).mean();
                let loss = actor_loss.clone()
                    + critic_loss.clone().mul_scalar(0.5 * cfg.critic_coef)
                    - entropy.clone().mul_scalar(cfg.entropy_coef)
                    + b_loss.clone().mul_scalar(cfg.bounds_loss_coef);
                let grads = loss.backward();
                let mut grads = GradientsParams::from_grads(grads, &self.model);
                let gn = match cfg.grad_norm {
                    Some(max) => clip_grad_norm(&mut grads, &self.model, max),
                    None => 0.0,
                };

                let ratio_v = to_vec(ratio.detach());
                let clipped = ratio_v
                    .iter()
                    .filter(|x| (**x - 1.0).abs() > cfg.clip)
                    .count();
                let clip_frac = clipped as f32 / mb as f32;
                if epoch == 0 && b == 0 {
                    self.last_update = UpdateStats {
                        first_minibatch_max_ratio_deviation: ratio_v
                            .iter()
                            .map(|x| (x - 1.0).abs())
                            .fold(0.0, f32::max),
                        first_minibatch_clip_fraction: clip_frac,
                    };
                }
                let sigma = log_std.detach().exp();
                let old_sigma_t = tensor2(&old_sigma, 1, ad, d);
                let kl = scalar(
                    gaussian_kl(
                        mu.detach(),
                        sigma.expand([mb, ad]),
                        old_mu,
                        old_sigma_t.expand([mb, ad]),
                    )
                    .mean(),
                );
                self.model = self.optim.step(self.lr, self.model.clone(), grads);
                if let Some(ak) = &cfg.adaptive_kl {
                    self.lr = ak.update(self.lr, kl);
                }
                sum_a += scalar(actor_loss) as f64;
                sum_c += scalar(critic_loss) as f64;
                sum_e += scalar(entropy) as f64;
                sum_b += scalar(b_loss) as f64;
                sum_kl += kl as f64;
                sum_clip += clip_frac as f64;
                sum_gn += gn as f64;
                count += 1;
            }
        }
        if ![sum_a, sum_c, sum_e, sum_b, sum_kl]
            .iter()
            .all(|v| v.is_finite())
        {
            return Err(LearnError::Diverged(format!(
                "ppo iteration {}: actor loss {sum_a}, critic loss {sum_c}, kl {sum_kl}",
                self.iteration + 1
            )));
        }
        let c = count.max(1) as f64;
        m.actor_loss = Some(sum_a / c);
        m.critic_loss = Some(sum_c / c);
        m.entropy = Some(sum_e / c);
        m.bounds_loss = Some(sum_b / c);
        m.approx_kl = Some(sum_kl / c);
        m.clip_fraction = Some(sum_clip / c);
        m.grad_norm = cfg.grad_norm.map(|_| sum_gn / c);
        m.lr = Some(self.lr);
        Ok(())
    }

    /// Runs one iteration: a rollout of `horizon` steps and the update on it.
    pub fn iterate(&mut self, env: &mut dyn VecEnvironment) -> Result<Metrics, LearnError> {
        let start = Instant::now();
        let steps_before = self.env_steps;
        let rollout = self.collect(env)?;
        let mut m = Metrics {
            algo: "ppo".into(),
            ..Default::default()
        };
        self.update(rollout, &mut m)?;
        self.iteration += 1;
        let dt = start.elapsed().as_secs_f64();
        self.wall_s += dt;
        m.iteration = self.iteration;
        m.env_steps = self.env_steps;
        m.wall_s = self.wall_s;
        m.steps_per_s = (self.env_steps - steps_before) as f64 / dt.max(1e-9);
        self.tracker.drain_into(&mut m);
        Ok(m)
    }

    /// Mean actions in the environment's units for raw observations (no exploration noise).
    pub fn act_deterministic(&self, obs: &[f32]) -> Vec<f32> {
        let rows = obs.len() / self.shape.obs_dim;
        let o = self.normalized(obs);
        let mu = to_vec(self.model.valid().mean(tensor2(
            &o,
            rows,
            self.shape.obs_dim,
            &Device::flex(),
        )));
        rescale(&mu, &self.shape.low, &self.shape.high)
    }
}

impl Trainer for Ppo {
    fn algo(&self) -> &'static str {
        "ppo"
    }
    fn iteration(&self) -> u64 {
        self.iteration
    }
    fn env_steps(&self) -> u64 {
        self.env_steps
    }
    fn iterate(&mut self, env: &mut dyn VecEnvironment) -> Result<Metrics, LearnError> {
        Ppo::iterate(self, env)
    }
    fn param_hash(&self) -> u64 {
        crate::nets::hash_f32(&flat_params(&self.model))
    }
    fn config(&self) -> AlgoConfig {
        AlgoConfig::Ppo(self.cfg.clone())
    }

    fn write_state(&self, c: &mut Checkpoint) -> Result<(), LearnError> {
        c.put_bytes("model", record_bytes(self.model.clone())?);
        c.put_bytes("optim", self.optim.into_bytes().map_err(rec_err)?.to_vec());
        c.put_f64s("obs_rms", &self.obs_rms.to_flat());
        c.put_f64s("value_rms", &self.value_rms.to_flat());
        c.put_u64s("rng", &self.rng.state());
        c.put_f32s("obs", &self.obs);
        c.put_f64s("ep_ret", &self.tracker.ret);
        c.put_u64s("ep_len", &self.tracker.len);
        c.put_u64s(
            "counters",
            &[
                self.iteration,
                self.env_steps,
                self.wall_s.to_bits(),
                self.lr.to_bits(),
                self.resets,
            ],
        );
        Ok(())
    }

    fn read_state(&mut self, c: &Checkpoint) -> Result<(), LearnError> {
        self.model = load_record(self.model.clone(), c.bytes("model")?)?;
        let bytes = c.bytes("optim")?.to_vec();
        self.optim = guarded("optim", || {
            optimizer(&self.cfg)
                .from_bytes(burn::tensor::Bytes::from_bytes_vec(bytes))
                .map_err(rec_err)
        })?;
        self.obs_rms = rms_from(c, "obs_rms", self.shape.obs_dim)?;
        self.value_rms = rms_from(c, "value_rms", 1)?;
        self.rng = Rng::from_state(c.u64_array::<4>("rng")?);
        self.obs = c.f32s("obs")?;
        self.shape.check_obs(&self.obs, "checkpoint")?;
        self.tracker.ret = c.f64s("ep_ret")?;
        self.tracker.len = c.u64s("ep_len")?;
        let [it, steps, wall, lr, resets] = c.u64_array::<5>("counters")?;
        self.iteration = it;
        self.env_steps = steps;
        self.wall_s = f64::from_bits(wall);
        self.lr = f64::from_bits(lr);
        self.resets = resets;
        Ok(())
    }

    fn restart_episodes(&mut self, env: &mut dyn VecEnvironment) -> Result<(), LearnError> {
        self.resets += 1;
        self.obs = restart(
            env,
            self.cfg.seed,
            self.resets,
            &self.shape,
            &mut self.tracker,
        )?;
        Ok(())
    }

    fn write_policy(
        &self,
        dir: &std::path::Path,
        identity: &Identity,
        note: &str,
    ) -> Result<(), LearnError> {
        crate::policy::export_ppo(
            dir,
            &self.model,
            &self.cfg,
            &self.shape,
            self.cfg.normalize_obs.then_some(&self.obs_rms),
            identity,
            self.iteration,
            self.env_steps,
            note,
        )
    }
}

pub(crate) fn rms_from(
    c: &Checkpoint,
    name: &str,
    dim: usize,
) -> Result<RunningMeanStd, LearnError> {
    RunningMeanStd::from_flat(&c.f64s(name)?)
        .filter(|r| r.dim() == dim)
        .ok_or_else(|| {
            LearnError::Checkpoint(format!("section '{name}' does not hold {dim}-d statistics"))
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::PointReach;

    #[test]
    fn first_minibatch_has_ratio_one_and_no_clipping() {
        for separate in [false, true] {
            first_minibatch_check(separate);
        }
    }

    fn first_minibatch_check(separate: bool) {
        let cfg = PpoConfig {
            hidden: vec![32, 32],
            separate,
            horizon: 16,
            minibatch_size: 64,
            mini_epochs: 2,
            ..PpoConfig::default()
        };
        let mut env = PointReach::new(8);
        let mut ppo = Ppo::new(&cfg, &mut env).unwrap();
        for it in 0..3 {
            let m = ppo.iterate(&mut env).unwrap();
            let u = &ppo.last_update;
            println!(
                "separate {separate}, iteration {it}: first minibatch max |ratio - 1| = {:e}, clip fraction {}, later kl {:?}",
                u.first_minibatch_max_ratio_deviation, u.first_minibatch_clip_fraction, m.approx_kl
            );
            assert_eq!(u.first_minibatch_max_ratio_deviation, 0.0);
            assert_eq!(u.first_minibatch_clip_fraction, 0.0);
            // Later minibatches do move the policy.
            assert!(m.approx_kl.unwrap() > 0.0);
        }
    }
}
