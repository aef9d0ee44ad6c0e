//! The networks a policy file holds ([`ActorCritic`] for PPO, [`SacActor`] for SAC and behaviour
//! cloning) and their byte records, below the trainers that make them and the policy files
//! that load them.

use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData};

use crate::config::{PpoConfig, SacConfig};
use crate::dist::tanh_gaussian_log_prob;
use crate::nets::{Dense, Mlp};
use crate::rng::Rng;
use crate::LearnError;

/// Epsilon of the normalisers' standard deviations.
pub(crate) const NORM_EPS: f64 = 1e-5;
/// The actor-critic network: Gaussian mean head, value head, state-independent log std.
#[derive(Module, Debug)]
pub struct ActorCritic {
    /// Actor trunk (also the critic's when not separate).
    pub trunk: Mlp,
    /// Critic trunk when the networks are separate.
    pub critic_trunk: Option<Mlp>,
    /// Action-mean head.
    pub mu: Dense,
    /// Value head (one output: the normalised value when value normalisation is on).
    pub value: Dense,
    /// Log standard deviation, `[1, act_dim]`.
    pub log_std: Param<Tensor<2>>,
}

impl ActorCritic {
    /// A freshly initialised network.
    pub fn new(
        rng: &mut Rng,
        obs_dim: usize,
        act_dim: usize,
        cfg: &PpoConfig,
        device: &Device,
    ) -> Self {
        let trunk = Mlp::new(rng, obs_dim, &cfg.hidden, cfg.activation, device);
        let critic_trunk = cfg
            .separate
            .then(|| Mlp::new(rng, obs_dim, &cfg.hidden, cfg.activation, device));
        let h = trunk.out_dim(obs_dim);
        // A small action-mean head starts the policy near zero mean.
        let mu = Dense::new(rng, h, act_dim, 0.01, device);
        let value = Dense::new(rng, h, 1, 1.0, device);
        let log_std = Param::from_tensor(Tensor::from_data(
            TensorData::new(vec![cfg.init_log_std; act_dim], [1, act_dim]),
            device,
        ));
        ActorCritic {
            trunk,
            critic_trunk,
            mu,
            value,
            log_std,
        }
    }

    /// Action means `[batch, act]` and values `[batch, 1]`.
    pub fn forward(&self, obs: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let h = self.trunk.forward(obs.clone());
        let mu = self.mu.forward(h.clone());
        let v = match &self.critic_trunk {
            Some(c) => self.value.forward(c.forward(obs)),
            None => self.value.forward(h),
        };
        (mu, v)
    }

    /// Action means only.
    pub fn mean(&self, obs: Tensor<2>) -> Tensor<2> {
        self.mu.forward(self.trunk.forward(obs))
    }
}

/// The actor: a trunk, a mean head and a state-dependent log-std head squashed into bounds.
#[derive(Module, Debug)]
pub struct SacActor {
    /// Hidden layers.
    pub trunk: Mlp,
    /// Mean of the pre-squash Gaussian.
    pub mu: Dense,
    /// Raw log standard deviation (mapped into the bounds with tanh).
    pub log_std: Dense,
    /// Lower bound of the log standard deviation.
    pub log_std_min: f32,
    /// Upper bound of the log standard deviation.
    pub log_std_max: f32,
}

impl SacActor {
    /// A freshly initialised actor.
    pub fn new(
        rng: &mut Rng,
        obs_dim: usize,
        act_dim: usize,
        cfg: &SacConfig,
        device: &Device,
    ) -> Self {
        let trunk = Mlp::new(rng, obs_dim, &cfg.hidden, cfg.activation, device);
        let h = trunk.out_dim(obs_dim);
        SacActor {
            trunk,
            mu: Dense::new(rng, h, act_dim, 1.0, device),
            log_std: Dense::new(rng, h, act_dim, 1.0, device),
            log_std_min: cfg.log_std_bounds.0,
            log_std_max: cfg.log_std_bounds.1,
        }
    }

    /// Pre-squash mean and log standard deviation.
    pub fn forward(&self, obs: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let h = self.trunk.forward(obs);
        let mu = self.mu.forward(h.clone());
        let raw = self.log_std.forward(h).tanh();
        let half = 0.5 * (self.log_std_max - self.log_std_min);
        let log_std = raw
            .add_scalar(1.0)
            .mul_scalar(half)
            .add_scalar(self.log_std_min);
        (mu, log_std)
    }

    /// The deterministic action `tanh(mu)` in [-1, 1].
    pub fn mean_action(&self, obs: Tensor<2>) -> Tensor<2> {
        self.forward(obs).0.tanh()
    }

    /// A reparameterised sample `tanh(mu + std * eps)` and its log-probability, for noise
    /// `eps` of shape `[batch, act]`.
    pub fn sample(&self, obs: Tensor<2>, eps: Tensor<2>) -> (Tensor<2>, Tensor<1>) {
        let (mu, log_std) = self.forward(obs);
        let u = mu.clone() + log_std.clone().exp() * eps;
        let logp = tanh_gaussian_log_prob(u.clone(), mu, log_std);
        (u.tanh(), logp)
    }
}

pub(crate) fn rec_err(e: burn::store::RecordError) -> LearnError {
    LearnError::Checkpoint(format!("{e:?}"))
}

pub(crate) fn record_bytes<M: Module>(m: M) -> Result<Vec<u8>, LearnError> {
    Ok(m.into_record().into_bytes().map_err(rec_err)?.to_vec())
}

pub(crate) fn load_record<M: Module>(m: M, bytes: &[u8]) -> Result<M, LearnError> {
    guarded("record", || {
        let rec = burn::store::ModuleRecord::from_bytes(burn::tensor::Bytes::from_bytes_vec(
            bytes.to_vec(),
        ))
        .map_err(rec_err)?;
        m.try_load_record(rec).map_err(rec_err)
    })
}

/// Runs a decoder of burn records, turning a panic inside burn (it asserts on some malformed
/// records, e.g. optimizer tensors without a parameter id) into a checkpoint error naming
/// `what`.
pub(crate) fn guarded<T>(
    what: &str,
    f: impl FnOnce() -> Result<T, LearnError>,
) -> Result<T, LearnError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|p| {
        let why = p
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_default();
        Err(LearnError::Checkpoint(format!(
            "section '{what}' is malformed ({why})"
        )))
    })
}
