//! Soft actor-critic: twin Q networks with Polyak-averaged targets, a tanh-squashed Gaussian
//! actor (log-probabilities corrected by the tanh log-determinant), a learned temperature
//! aiming at a target entropy (default `-act_dim`), a uniform replay buffer, and targets that
//! bootstrap through time limits (only terminal states cut the return).

use burn::module::{Module, Param};
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Tensor, TensorData};
use std::time::Instant;

pub use crate::actors::SacActor;
use crate::actors::{guarded, load_record, rec_err, record_bytes};
use crate::checkpoint::{Checkpoint, Identity};
use crate::config::{AlgoConfig, SacConfig};
use crate::metrics::{EpisodeTracker, Metrics};
use crate::nets::{clip_grad_norm, flat_params, polyak, Dense, Mlp};
use crate::rng::Rng;
use crate::runner::{check_step, rescale, restart, EnvShape, Trainer};
use crate::tensors::{scalar, tensor1, tensor2, to_vec};
use crate::{LearnError, VecEnvironment};

/// One Q network on the concatenation of observation and action.
#[derive(Module, Debug)]
pub struct QNet {
    /// Hidden layers.
    pub trunk: Mlp,
    /// Output layer.
    pub out: Dense,
}

impl QNet {
    fn new(
        rng: &mut Rng,
        obs_dim: usize,
        act_dim: usize,
        cfg: &SacConfig,
        device: &Device,
    ) -> Self {
        let trunk = Mlp::new(rng, obs_dim + act_dim, &cfg.hidden, cfg.activation, device);
        let h = trunk.out_dim(obs_dim + act_dim);
        QNet {
            trunk,
            out: Dense::new(rng, h, 1, 1.0, device),
        }
    }

    /// Q values `[batch]`.
    pub fn forward(&self, obs: Tensor<2>, act: Tensor<2>) -> Tensor<1> {
        self.out
            .forward(self.trunk.forward(Tensor::cat(vec![obs, act], 1)))
            .squeeze_dim(1)
    }
}

/// The twin critics.
#[derive(Module, Debug)]
pub struct TwinQ {
    /// First critic.
    pub q1: QNet,
    /// Second critic.
    pub q2: QNet,
}

impl TwinQ {
    /// Both Q values.
    pub fn forward(&self, obs: Tensor<2>, act: Tensor<2>) -> (Tensor<1>, Tensor<1>) {
        (
            self.q1.forward(obs.clone(), act.clone()),
            self.q2.forward(obs, act),
        )
    }
}

/// The learned temperature, as its logarithm.
#[derive(Module, Debug)]
pub struct Temperature {
    /// `ln(alpha)`, one element.
    pub log_alpha: Param<Tensor<1>>,
}

/// Uniform replay buffer of transitions (ring buffer).
#[derive(Clone, Debug, PartialEq)]
pub struct Replay {
    cap: usize,
    obs_dim: usize,
    act_dim: usize,
    obs: Vec<f32>,
    act: Vec<f32>,
    rew: Vec<f32>,
    next: Vec<f32>,
    term: Vec<f32>,
    len: usize,
    pos: usize,
}

impl Replay {
    /// An empty buffer (memory grows as it fills).
    pub fn new(cap: usize, obs_dim: usize, act_dim: usize) -> Self {
        Replay {
            cap,
            obs_dim,
            act_dim,
            obs: Vec::new(),
            act: Vec::new(),
            rew: Vec::new(),
            next: Vec::new(),
            term: Vec::new(),
            len: 0,
            pos: 0,
        }
    }

    /// Transitions held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether it holds nothing.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Adds one transition; `next` is the final observation where the episode ended, and
    /// `terminal` is true only for terminal states (not time limits).
    pub fn push(&mut self, obs: &[f32], act: &[f32], rew: f32, next: &[f32], terminal: bool) {
        let (od, ad) = (self.obs_dim, self.act_dim);
        if self.len < self.cap {
            self.obs.extend_from_slice(obs);
            self.act.extend_from_slice(act);
            self.rew.push(rew);
            self.next.extend_from_slice(next);
            self.term.push(terminal as u8 as f32);
            self.len += 1;
        } else {
            let p = self.pos;
            self.obs[p * od..(p + 1) * od].copy_from_slice(obs);
            self.act[p * ad..(p + 1) * ad].copy_from_slice(act);
            self.rew[p] = rew;
            self.next[p * od..(p + 1) * od].copy_from_slice(next);
            self.term[p] = terminal as u8 as f32;
        }
        self.pos = (self.pos + 1) % self.cap;
    }

    fn sample(&self, rng: &mut Rng, b: usize) -> [Vec<f32>; 5] {
        let (od, ad) = (self.obs_dim, self.act_dim);
        let mut out = [
            Vec::with_capacity(b * od),
            Vec::with_capacity(b * ad),
            Vec::with_capacity(b),
            Vec::with_capacity(b * od),
            Vec::with_capacity(b),
        ];
        for _ in 0..b {
            let i = rng.below(self.len);
            out[0].extend_from_slice(&self.obs[i * od..(i + 1) * od]);
            out[1].extend_from_slice(&self.act[i * ad..(i + 1) * ad]);
            out[2].push(self.rew[i]);
            out[3].extend_from_slice(&self.next[i * od..(i + 1) * od]);
            out[4].push(self.term[i]);
        }
        out
    }

    fn write(&self, c: &mut Checkpoint) {
        c.put_f32s("replay.obs", &self.obs);
        c.put_f32s("replay.act", &self.act);
        c.put_f32s("replay.rew", &self.rew);
        c.put_f32s("replay.next", &self.next);
        c.put_f32s("replay.term", &self.term);
        c.put_u64s(
            "replay.meta",
            &[self.cap as u64, self.len as u64, self.pos as u64],
        );
    }

    fn read(&mut self, c: &Checkpoint) -> Result<(), LearnError> {
        let [cap, len, pos] = c.u64_array::<3>("replay.meta")?;
        let (len, pos) = (len as usize, pos as usize);
        let (od, ad) = (self.obs_dim, self.act_dim);
        let r = Replay {
            cap: cap as usize,
            obs_dim: od,
            act_dim: ad,
            obs: c.f32s("replay.obs")?,
            act: c.f32s("replay.act")?,
            rew: c.f32s("replay.rew")?,
            next: c.f32s("replay.next")?,
            term: c.f32s("replay.term")?,
            len,
            pos,
        };
        let ok = r.cap == self.cap
            && r.obs.len() == len * od
            && r.next.len() == len * od
            && r.act.len() == len * ad
            && r.rew.len() == len
            && r.term.len() == len
            && len <= r.cap
            && pos < r.cap.max(1);
        if !ok {
            return Err(LearnError::Checkpoint(
                "replay buffer sections are inconsistent".into(),
            ));
        }
        *self = r;
        Ok(())
    }
}

/// A SAC learner attached to an environment batch (see [`crate::train`]).
pub struct Sac {
    cfg: SacConfig,
    shape: EnvShape,
    device: Device,
    actor: SacActor,
    critic: TwinQ,
    target: TwinQ,
    temp: Temperature,
    actor_opt: ModuleOptimizer,
    critic_opt: ModuleOptimizer,
    temp_opt: ModuleOptimizer,
    replay: Replay,
    rng: Rng,
    obs: Vec<f32>,
    tracker: EpisodeTracker,
    iteration: u64,
    env_steps: u64,
    grad_steps: u64,
    wall_s: f64,
    resets: u64,
}

#[derive(Default)]
struct Sums {
    actor: f64,
    critic: f64,
    q: f64,
    entropy: f64,
    grad_norm: f64,
    n: usize,
}

fn adam() -> ModuleOptimizer {
    AdamConfig::new().with_epsilon(1e-8).init()
}

impl Sac {
    /// A new learner; resets the environments with the configuration's seed.
    pub fn new(cfg: &SacConfig, env: &mut dyn VecEnvironment) -> Result<Self, LearnError> {
        AlgoConfig::Sac(cfg.clone()).validate()?;
        let shape = EnvShape::of(env)?;
        let device = Device::flex().autodiff();
        let mut rng = Rng::new(cfg.seed);
        let (od, ad) = (shape.obs_dim, shape.act_dim);
        let actor = SacActor::new(&mut rng, od, ad, cfg, &device);
        let critic = TwinQ {
            q1: QNet::new(&mut rng, od, ad, cfg, &device),
            q2: QNet::new(&mut rng, od, ad, cfg, &device),
        };
        let target = critic.valid();
        let temp = Temperature {
            log_alpha: Param::from_tensor(Tensor::from_data(
                TensorData::new(vec![cfg.init_alpha.ln()], [1]),
                &device,
            )),
        };
        let obs = env.reset(cfg.seed).map_err(LearnError::Env)?;
        shape.check_obs(&obs, "reset")?;
        Ok(Sac {
            replay: Replay::new(cfg.buffer_size, od, ad),
            tracker: EpisodeTracker::new(shape.n),
            cfg: cfg.clone(),
            shape,
            device,
            actor,
            critic,
            target,
            temp,
            actor_opt: adam(),
            critic_opt: adam(),
            temp_opt: adam(),
            rng,
            obs,
            iteration: 0,
            env_steps: 0,
            grad_steps: 0,
            wall_s: 0.0,
            resets: 0,
        })
    }

    /// The actor.
    pub fn actor(&self) -> &SacActor {
        &self.actor
    }

    /// Current temperature.
    pub fn alpha(&self) -> f32 {
        scalar(self.temp.log_alpha.val().exp())
    }

    fn target_entropy(&self) -> f32 {
        self.cfg
            .target_entropy
            .unwrap_or(-(self.shape.act_dim as f32))
    }

    fn noise(&mut self, rows: usize) -> Vec<f32> {
        (0..rows * self.shape.act_dim)
            .map(|_| self.rng.normal() as f32)
            .collect()
    }

    fn env_step(&mut self, env: &mut dyn VecEnvironment) -> Result<(), LearnError> {
        let (n, od, ad) = (self.shape.n, self.shape.obs_dim, self.shape.act_dim);
        let a: Vec<f32> = if self.env_steps < self.cfg.learning_starts {
            (0..n * ad)
                .map(|_| self.rng.uniform_range(-1.0, 1.0) as f32)
                .collect()
        } else {
            let eps = self.noise(n);
            let infer = self.actor.valid();
            let dev = Device::flex();
            let (a, _) = infer.sample(tensor2(&self.obs, n, od, &dev), tensor2(&eps, n, ad, &dev));
            to_vec(a)
        };
        let step = env
            .step(&rescale(&a, &self.shape.low, &self.shape.high))
            .map_err(LearnError::Env)?;
        check_step(&self.shape, &step)?;
        self.tracker.record(&step);
        for i in 0..n {
            let ended = step.terminated[i] || step.truncated[i];
            let next = if ended {
                step.final_obs[i].as_deref().expect("checked by check_step")
            } else {
                &step.obs[i * od..(i + 1) * od]
            };
            self.replay.push(
                &self.obs[i * od..(i + 1) * od],
                &a[i * ad..(i + 1) * ad],
                step.rewards[i],
                next,
                step.terminated[i],
            );
        }
        self.obs = step.obs;
        self.env_steps += n as u64;
        Ok(())
    }

    fn gradient_step(&mut self, sums: &mut Sums) {
        let (od, ad) = (self.shape.obs_dim, self.shape.act_dim);
        let b = self.cfg.batch_size;
        let [obs, act, rew, next, term] = self.replay.sample(&mut self.rng, b);
        let eps_next = self.noise(b);
        let eps_now = self.noise(b);
        let alpha = self.alpha();
        let d = self.device.clone();
        let plain = Device::flex();

        // Target: r + gamma (1 - terminal) (min Q'(s', a') - alpha log pi(a'|s')).
        let y = {
            let actor = self.actor.valid();
            let next_t = tensor2(&next, b, od, &plain);
            let (a2, logp2) = actor.sample(next_t.clone(), tensor2(&eps_next, b, ad, &plain));
            let (t1, t2) = self.target.forward(next_t, a2);
            let soft = t1.min_pair(t2) - logp2.mul_scalar(alpha);
            let not_done = tensor1(&term, &plain).neg().add_scalar(1.0);
            let y = tensor1(&rew, &plain) + soft * not_done.mul_scalar(self.cfg.gamma);
            to_vec(y)
        };
        let obs_t = tensor2(&obs, b, od, &d);
        let y_t = tensor1(&y, &d);
        let (q1, q2) = self.critic.forward(obs_t.clone(), tensor2(&act, b, ad, &d));
        sums.q += scalar(q1.clone().detach().mean()) as f64;
        let critic_loss = (q1 - y_t.clone()).square().mean() + (q2 - y_t).square().mean();
        let mut grads = GradientsParams::from_grads(critic_loss.backward(), &self.critic);
        if let Some(max) = self.cfg.grad_norm {
            sums.grad_norm += clip_grad_norm(&mut grads, &self.critic, max) as f64;
        }
        self.critic = self
            .critic_opt
            .step(self.cfg.critic_lr, self.critic.clone(), grads);
        sums.critic += scalar(critic_loss) as f64;

        // Actor: minimise alpha log pi(a|s) - min Q(s, a) with a reparameterised sample.
        let (a_new, logp) = self
            .actor
            .sample(obs_t.clone(), tensor2(&eps_now, b, ad, &d));
        let (p1, p2) = self.critic.forward(obs_t, a_new);
        let actor_loss = (logp.clone().mul_scalar(alpha) - p1.min_pair(p2)).mean();
        let mut grads = GradientsParams::from_grads(actor_loss.backward(), &self.actor);
        if let Some(max) = self.cfg.grad_norm {
            clip_grad_norm(&mut grads, &self.actor, max);
        }
        self.actor = self
            .actor_opt
            .step(self.cfg.actor_lr, self.actor.clone(), grads);
        sums.actor += scalar(actor_loss) as f64;
        let logp_v = to_vec(logp.detach());
        let mean_logp = logp_v.iter().map(|x| *x as f64).sum::<f64>() / b as f64;
        sums.entropy -= mean_logp;

        // Temperature: minimise -ln(alpha) (log pi + target entropy), the bracket held fixed.
        if self.cfg.learn_alpha {
            let bracket = (mean_logp + self.target_entropy() as f64) as f32;
            let loss = self.temp.log_alpha.val().mul_scalar(-bracket).sum();
            let grads = GradientsParams::from_grads(loss.backward(), &self.temp);
            self.temp = self
                .temp_opt
                .step(self.cfg.alpha_lr, self.temp.clone(), grads);
        }

        self.target = polyak(self.target.clone(), &self.critic.valid(), self.cfg.tau);
        self.grad_steps += 1;
        sums.n += 1;
    }

    /// Runs one iteration: `steps_per_iteration` batched environment steps, each followed by
    /// `gradient_steps` updates once `learning_starts` steps are done.
    pub fn iterate(&mut self, env: &mut dyn VecEnvironment) -> Result<Metrics, LearnError> {
        let start = Instant::now();
        let steps_before = self.env_steps;
        let mut sums = Sums::default();
        for _ in 0..self.cfg.steps_per_iteration {
            self.env_step(env)?;
            if self.env_steps >= self.cfg.learning_starts
                && self.replay.len() >= self.cfg.batch_size
            {
                for _ in 0..self.cfg.gradient_steps {
                    self.gradient_step(&mut sums);
                }
            }
        }
        self.iteration += 1;
        let dt = start.elapsed().as_secs_f64();
        self.wall_s += dt;
        let mut m = Metrics {
            algo: "sac".into(),
            iteration: self.iteration,
            env_steps: self.env_steps,
            wall_s: self.wall_s,
            steps_per_s: (self.env_steps - steps_before) as f64 / dt.max(1e-9),
            lr: Some(self.cfg.actor_lr),
            alpha: Some(self.alpha() as f64),
            ..Default::default()
        };
        if ![sums.actor, sums.critic, sums.q, m.alpha.unwrap_or(0.0)]
            .iter()
            .all(|v| v.is_finite())
        {
            return Err(LearnError::Diverged(format!(
                "sac iteration {}: actor loss {}, critic loss {}, alpha {:?}",
                self.iteration, sums.actor, sums.critic, m.alpha
            )));
        }
        if sums.n > 0 {
            let c = sums.n as f64;
            m.actor_loss = Some(sums.actor / c);
            m.critic_loss = Some(sums.critic / c);
            m.q_mean = Some(sums.q / c);
            m.entropy = Some(sums.entropy / c);
            m.grad_norm = self.cfg.grad_norm.map(|_| sums.grad_norm / c);
        }
        self.tracker.drain_into(&mut m);
        Ok(m)
    }

    /// Deterministic actions in the environment's units for raw observations.
    pub fn act_deterministic(&self, obs: &[f32]) -> Vec<f32> {
        let rows = obs.len() / self.shape.obs_dim;
        let a = to_vec(self.actor.valid().mean_action(tensor2(
            obs,
            rows,
            self.shape.obs_dim,
            &Device::flex(),
        )));
        rescale(&a, &self.shape.low, &self.shape.high)
    }
}

impl Trainer for Sac {
    fn algo(&self) -> &'static str {
        "sac"
    }
    fn iteration(&self) -> u64 {
        self.iteration
    }
    fn env_steps(&self) -> u64 {
        self.env_steps
    }
    fn iterate(&mut self, env: &mut dyn VecEnvironment) -> Result<Metrics, LearnError> {
        Sac::iterate(self, env)
    }
    fn param_hash(&self) -> u64 {
        let mut all = flat_params(&self.actor);
        all.extend(flat_params(&self.critic));
        all.extend(flat_params(&self.target));
        all.extend(flat_params(&self.temp));
        crate::nets::hash_f32(&all)
    }
    fn config(&self) -> AlgoConfig {
        AlgoConfig::Sac(self.cfg.clone())
    }

    fn write_state(&self, c: &mut Checkpoint) -> Result<(), LearnError> {
        c.put_bytes("actor", record_bytes(self.actor.clone())?);
        c.put_bytes("critic", record_bytes(self.critic.clone())?);
        c.put_bytes("target", record_bytes(self.target.clone())?);
        c.put_bytes("temp", record_bytes(self.temp.clone())?);
        c.put_bytes(
            "actor_opt",
            self.actor_opt.into_bytes().map_err(rec_err)?.to_vec(),
        );
        c.put_bytes(
            "critic_opt",
            self.critic_opt.into_bytes().map_err(rec_err)?.to_vec(),
        );
        c.put_bytes(
            "temp_opt",
            self.temp_opt.into_bytes().map_err(rec_err)?.to_vec(),
        );
        self.replay.write(c);
        c.put_u64s("rng", &self.rng.state());
        c.put_f32s("obs", &self.obs);
        c.put_f64s("ep_ret", &self.tracker.ret);
        c.put_u64s("ep_len", &self.tracker.len);
        c.put_u64s(
            "counters",
            &[
                self.iteration,
                self.env_steps,
                self.grad_steps,
                self.wall_s.to_bits(),
                self.resets,
            ],
        );
        Ok(())
    }

    fn read_state(&mut self, c: &Checkpoint) -> Result<(), LearnError> {
        let opt = |name: &str| -> Result<ModuleOptimizer, LearnError> {
            let bytes = c.bytes(name)?.to_vec();
            guarded(name, || {
                adam()
                    .from_bytes(burn::tensor::Bytes::from_bytes_vec(bytes))
                    .map_err(rec_err)
            })
        };
        self.actor = load_record(self.actor.clone(), c.bytes("actor")?)?;
        self.critic = load_record(self.critic.clone(), c.bytes("critic")?)?;
        self.target = load_record(self.target.clone(), c.bytes("target")?)?;
        self.temp = load_record(self.temp.clone(), c.bytes("temp")?)?;
        self.actor_opt = opt("actor_opt")?;
        self.critic_opt = opt("critic_opt")?;
        self.temp_opt = opt("temp_opt")?;
        self.replay.read(c)?;
        self.rng = Rng::from_state(c.u64_array::<4>("rng")?);
        self.obs = c.f32s("obs")?;
        self.shape.check_obs(&self.obs, "checkpoint")?;
        self.tracker.ret = c.f64s("ep_ret")?;
        self.tracker.len = c.u64s("ep_len")?;
        let [it, steps, grad_steps, wall, resets] = c.u64_array::<5>("counters")?;
        self.iteration = it;
        self.env_steps = steps;
        self.grad_steps = grad_steps;
        self.wall_s = f64::from_bits(wall);
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
        crate::policy::export_sac(
            dir,
            &self.actor,
            &self.cfg,
            &self.shape,
            identity,
            self.iteration,
            self.env_steps,
            note,
        )
    }
}
