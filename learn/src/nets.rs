//! Networks (multilayer perceptrons and the policy/value heads) and parameter utilities:
//! flat views, hashing, Polyak averaging and global gradient-norm clipping.

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param, ParamId};
use burn::optim::GradientsParams;
use burn::tensor::activation::{elu, relu};
use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use crate::rng::Rng;

/// Hidden-layer nonlinearity.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Activation {
    /// Exponential linear unit (alpha 1), rl_games' choice for Isaac Lab.
    Elu,
    /// Rectified linear unit.
    Relu,
    /// Hyperbolic tangent.
    Tanh,
}

impl Activation {
    /// Applies the nonlinearity.
    pub fn apply<const D: usize>(self, x: Tensor<D>) -> Tensor<D> {
        match self {
            Activation::Elu => elu(x, 1.0),
            Activation::Relu => relu(x),
            Activation::Tanh => x.tanh(),
        }
    }
}

/// A fully connected layer `y = x W + b`, with `W` of shape `[d_in, d_out]`.
#[derive(Module, Debug)]
pub struct Dense {
    /// Weights `[d_in, d_out]`.
    pub weight: Param<Tensor<2>>,
    /// Bias `[d_out]`.
    pub bias: Param<Tensor<1>>,
}

impl Dense {
    /// Weights and biases uniform in `+-scale / sqrt(d_in)` (PyTorch's default at scale 1).
    pub fn new(rng: &mut Rng, d_in: usize, d_out: usize, scale: f64, device: &Device) -> Self {
        let bound = scale / (d_in as f64).sqrt();
        let w: Vec<f32> = (0..d_in * d_out)
            .map(|_| rng.uniform_range(-bound, bound) as f32)
            .collect();
        let b: Vec<f32> = (0..d_out)
            .map(|_| rng.uniform_range(-bound, bound) as f32)
            .collect();
        Dense {
            weight: Param::from_tensor(Tensor::from_data(
                TensorData::new(w, [d_in, d_out]),
                device,
            )),
            bias: Param::from_tensor(Tensor::from_data(TensorData::new(b, [d_out]), device)),
        }
    }

    /// Applies the layer to `[batch, d_in]`.
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        x.matmul(self.weight.val()) + self.bias.val().unsqueeze_dim(0)
    }
}

/// Hidden layers, each followed by the activation.
#[derive(Module, Debug)]
pub struct Mlp {
    /// The layers in order.
    pub layers: Vec<Dense>,
    /// The nonlinearity after each layer.
    #[module(skip)]
    pub activation: Activation,
}

impl Mlp {
    /// Layers `d_in -> hidden[0] -> ... -> hidden[last]`.
    pub fn new(
        rng: &mut Rng,
        d_in: usize,
        hidden: &[usize],
        activation: Activation,
        device: &Device,
    ) -> Self {
        let mut layers = Vec::new();
        let mut d = d_in;
        for &h in hidden {
            layers.push(Dense::new(rng, d, h, 1.0, device));
            d = h;
        }
        Mlp { layers, activation }
    }

    /// Width of the output (the input width when there are no layers).
    pub fn out_dim(&self, d_in: usize) -> usize {
        self.layers
            .last()
            .map(|l| l.weight.val().dims()[1])
            .unwrap_or(d_in)
    }

    /// Applies the layers.
    pub fn forward(&self, mut x: Tensor<2>) -> Tensor<2> {
        for l in &self.layers {
            x = self.activation.apply(l.forward(x));
        }
        x
    }
}

struct FlatCollector {
    ids: Vec<(ParamId, usize)>,
    values: Vec<f32>,
    want_values: bool,
}

impl ModuleVisitor for FlatCollector {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.ids.push((param.id, D));
        if self.want_values {
            let data = param.val().into_data().convert::<f32>();
            self.values
                .extend(data.as_slice::<f32>().expect("f32 parameter"));
        }
    }
}

/// The ids and ranks of a module's float parameters, in visiting order.
pub fn param_ids<M: Module>(m: &M) -> Vec<(ParamId, usize)> {
    let mut c = FlatCollector {
        ids: Vec::new(),
        values: Vec::new(),
        want_values: false,
    };
    m.visit(&mut c);
    c.ids
}

/// All float parameters of a module concatenated, in visiting order.
pub fn flat_params<M: Module>(m: &M) -> Vec<f32> {
    let mut c = FlatCollector {
        ids: Vec::new(),
        values: Vec::new(),
        want_values: true,
    };
    m.visit(&mut c);
    c.values
}

struct FlatSetter<'a> {
    values: &'a [f32],
    at: usize,
}

impl ModuleMapper for FlatSetter<'_> {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        param.map(|t| {
            let shape = t.shape();
            let n = shape.num_elements();
            let device = t.device();
            let grad = t.is_require_grad();
            let slice = self.values[self.at..self.at + n].to_vec();
            self.at += n;
            let fresh: Tensor<D> = Tensor::from_data(TensorData::new(slice, shape), &device);
            if grad {
                fresh.require_grad()
            } else {
                fresh
            }
        })
    }
}

/// The module with its float parameters replaced by `values` (as from [`flat_params`]);
/// parameter ids and devices are kept.
pub fn set_flat_params<M: Module>(m: M, values: &[f32]) -> M {
    let mut s = FlatSetter { values, at: 0 };
    let out = m.map(&mut s);
    assert_eq!(
        s.at,
        values.len(),
        "set_flat_params: {} values for {} parameters",
        values.len(),
        s.at
    );
    out
}

/// Polyak averaging: `target <- tau * online + (1 - tau) * target`.
pub fn polyak<M: Module>(target: M, online: &M, tau: f32) -> M {
    let online_v = flat_params(online);
    let mut t = flat_params(&target);
    for (a, b) in t.iter_mut().zip(&online_v) {
        *a = tau * b + (1.0 - tau) * *a;
    }
    set_flat_params(target, &t)
}

/// A 64-bit FNV-1a hash of the exact bits of a parameter vector.
pub fn hash_f32(values: &[f32]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for v in values {
        for b in v.to_bits().to_le_bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01B3);
        }
    }
    h
}

/// Scales the gradients of `module`'s parameters so that their global L2 norm is at most
/// `max_norm` (PyTorch's `clip_grad_norm_`). Returns the norm before clipping.
pub fn clip_grad_norm<M: Module>(grads: &mut GradientsParams, module: &M, max_norm: f32) -> f32 {
    let ids = param_ids(module);
    let mut total = 0.0f64;
    // Gradients are stored by rank; the networks of this crate hold ranks 1 and 2.
    for &(id, rank) in &ids {
        let sq = match rank {
            1 => grads.get::<1>(id).map(|g| g.square().sum()),
            2 => grads.get::<2>(id).map(|g| g.square().sum()),
            r => panic!("clip_grad_norm: parameter of rank {r}"),
        };
        if let Some(sq) = sq {
            total += crate::tensors::scalar(sq) as f64;
        }
    }
    let norm = total.sqrt() as f32;
    if norm.is_finite() && norm > max_norm {
        let factor = max_norm / (norm + 1e-6);
        for (id, rank) in ids {
            if rank == 1 {
                if let Some(g) = grads.remove::<1>(id) {
                    grads.register(id, g.mul_scalar(factor));
                }
            } else if let Some(g) = grads.remove::<2>(id) {
                grads.register(id, g.mul_scalar(factor));
            }
        }
    }
    norm
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tensors::{tensor2, to_vec};

    #[test]
    fn flat_round_trip_and_polyak() {
        let d = Device::flex().autodiff();
        let mut rng = Rng::new(1);
        let a = Mlp::new(&mut rng, 3, &[4, 2], Activation::Elu, &d);
        let b = Mlp::new(&mut rng, 3, &[4, 2], Activation::Elu, &d);
        let fa = flat_params(&a);
        assert_eq!(fa.len(), 3 * 4 + 4 + 4 * 2 + 2);
        let b2 = set_flat_params(b.clone(), &fa);
        assert_eq!(flat_params(&b2), fa);
        let fb = flat_params(&b);
        let mixed = flat_params(&polyak(b, &a, 0.25));
        for k in 0..fa.len() {
            assert_eq!(mixed[k], 0.25 * fa[k] + 0.75 * fb[k]);
        }
        assert_ne!(hash_f32(&fa), hash_f32(&fb));
        // Parameters keep receiving gradients after being set.
        let x = tensor2(&[1.0, 2.0, 3.0], 1, 3, &d);
        let g = b2.forward(x).sum().backward();
        let gp = GradientsParams::from_grads(g, &b2);
        assert_eq!(gp.len(), 4);
    }

    #[test]
    fn global_norm_clipping() {
        let d = Device::flex().autodiff();
        let mut rng = Rng::new(2);
        let m = Dense::new(&mut rng, 2, 1, 1.0, &d);
        // d/dW sum(x W + b) = x^T, d/db = 1: gradient norm sqrt(3^2 + 4^2 + 1) = sqrt(26).
        let x = tensor2(&[3.0, 4.0], 1, 2, &d);
        let g = m.forward(x).sum().backward();
        let mut gp = GradientsParams::from_grads(g, &m);
        let norm = clip_grad_norm(&mut gp, &m, 1.0);
        assert!((norm - 26f32.sqrt()).abs() < 1e-5);
        let gw = to_vec(gp.get::<2>(m.weight.id).unwrap());
        let gb = to_vec(gp.get::<1>(m.bias.id).unwrap());
        let clipped = (gw.iter().map(|v| v * v).sum::<f32>() + gb[0] * gb[0]).sqrt();
        assert!((clipped - 1.0).abs() < 1e-4, "{clipped}");
    }
}
