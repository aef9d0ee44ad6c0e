//! Running mean and variance (parallel merge of Chan, Golub and LeVeque) and the normalisers
//! built on them.

use serde::{Deserialize, Serialize};

/// Per-dimension running mean and (population) variance over every sample seen.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunningMeanStd {
    /// Mean per dimension.
    pub mean: Vec<f64>,
    /// Population variance per dimension.
    pub var: Vec<f64>,
    /// Number of samples merged so far.
    pub count: f64,
}

impl RunningMeanStd {
    /// Empty statistics for `dim` dimensions (mean 0, variance 1 until data arrives).
    pub fn new(dim: usize) -> Self {
        RunningMeanStd {
            mean: vec![0.0; dim],
            var: vec![1.0; dim],
            count: 0.0,
        }
    }

    /// Number of dimensions.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Statistics of one batch of rows (`data.len()` a multiple of `dim`), two-pass.
    pub fn from_batch(dim: usize, data: &[f32]) -> Self {
        assert!(dim > 0 && data.len().is_multiple_of(dim));
        let rows = data.len() / dim;
        let mut mean = vec![0.0f64; dim];
        for row in data.chunks_exact(dim) {
            for (m, &x) in mean.iter_mut().zip(row) {
                *m += x as f64;
            }
        }
        for m in &mut mean {
            *m /= rows.max(1) as f64;
        }
        let mut var = vec![0.0f64; dim];
        for row in data.chunks_exact(dim) {
            for ((v, &x), m) in var.iter_mut().zip(row).zip(&mean) {
                *v += (x as f64 - m).powi(2);
            }
        }
        for v in &mut var {
            *v /= rows.max(1) as f64;
        }
        RunningMeanStd {
            mean,
            var,
            count: rows as f64,
        }
    }

    /// Merges another set of statistics into this one (Chan et al.'s parallel update).
    pub fn merge(&mut self, other: &RunningMeanStd) {
        assert_eq!(self.dim(), other.dim());
        if other.count == 0.0 {
            return;
        }
        if self.count == 0.0 {
            *self = other.clone();
            return;
        }
        let total = self.count + other.count;
        for d in 0..self.dim() {
            let delta = other.mean[d] - self.mean[d];
            let m2 = self.var[d] * self.count
                + other.var[d] * other.count
                + delta * delta * self.count * other.count / total;
            self.mean[d] += delta * other.count / total;
            self.var[d] = m2 / total;
        }
        self.count = total;
    }

    /// Adds a batch of rows.
    pub fn update(&mut self, data: &[f32]) {
        let batch = RunningMeanStd::from_batch(self.dim(), data);
        self.merge(&batch);
    }

    /// `(x - mean) / sqrt(var + eps)`, clipped to `[-clip, clip]`, row by row in place.
    pub fn normalize(&self, data: &mut [f32], eps: f64, clip: f64) {
        for row in data.chunks_exact_mut(self.dim()) {
            for (d, x) in row.iter_mut().enumerate() {
                let z = (*x as f64 - self.mean[d]) / (self.var[d] + eps).sqrt();
                *x = z.clamp(-clip, clip) as f32;
            }
        }
    }

    /// `x * sqrt(var + eps) + mean`, row by row in place.
    pub fn denormalize(&self, data: &mut [f32], eps: f64) {
        for row in data.chunks_exact_mut(self.dim()) {
            for (d, x) in row.iter_mut().enumerate() {
                *x = (*x as f64 * (self.var[d] + eps).sqrt() + self.mean[d]) as f32;
            }
        }
    }

    /// The statistics as flat numbers (mean, var, count) for checkpoints.
    pub fn to_flat(&self) -> Vec<f64> {
        let mut v = self.mean.clone();
        v.extend_from_slice(&self.var);
        v.push(self.count);
        v
    }

    /// Statistics from [`to_flat`](Self::to_flat)'s numbers.
    pub fn from_flat(flat: &[f64]) -> Option<Self> {
        if flat.is_empty() || flat.len().is_multiple_of(2) {
            return None;
        }
        let dim = (flat.len() - 1) / 2;
        Some(RunningMeanStd {
            mean: flat[..dim].to_vec(),
            var: flat[dim..2 * dim].to_vec(),
            count: flat[2 * dim],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn two_pass(dim: usize, data: &[f32]) -> (Vec<f64>, Vec<f64>) {
        let rows = (data.len() / dim) as f64;
        let mut mean = vec![0.0; dim];
        for r in data.chunks(dim) {
            for d in 0..dim {
                mean[d] += r[d] as f64 / rows;
            }
        }
        let mut var = vec![0.0; dim];
        for r in data.chunks(dim) {
            for d in 0..dim {
                var[d] += (r[d] as f64 - mean[d]).powi(2) / rows;
            }
        }
        (mean, var)
    }

    #[test]
    fn merges_of_uneven_chunks_match_two_pass() {
        let mut rng = Rng::new(3);
        let dim = 3;
        // Large offset and spread per dimension: the naive sum-of-squares formula loses digits.
        let data: Vec<f32> = (0..1000 * dim)
            .map(|k| (1e3 * (k % dim) as f64 + (1.0 + k as f64 % 3.0) * rng.normal()) as f32)
            .collect();
        let (mean, var) = two_pass(dim, &data);
        let mut rms = RunningMeanStd::new(dim);
        let mut start = 0;
        for len in [1usize, 2, 7, 100, 333, 557] {
            rms.update(&data[start * dim..(start + len) * dim]);
            start += len;
        }
        assert_eq!(start, 1000);
        assert_eq!(rms.count, 1000.0);
        for d in 0..dim {
            assert!((rms.mean[d] - mean[d]).abs() <= 1e-9 * mean[d].abs().max(1.0));
            assert!(
                (rms.var[d] - var[d]).abs() <= 1e-9 * var[d],
                "{} {}",
                rms.var[d],
                var[d]
            );
        }
        // Merging two accumulated halves gives the same as accumulating everything.
        let mut a = RunningMeanStd::new(dim);
        a.update(&data[..400 * dim]);
        let mut b = RunningMeanStd::new(dim);
        b.update(&data[400 * dim..]);
        a.merge(&b);
        for (got, want) in a.var.iter().zip(&var) {
            assert!((got - want).abs() <= 1e-9 * want);
        }
        let back = RunningMeanStd::from_flat(&a.to_flat()).unwrap();
        assert_eq!(back, a);
    }

    #[test]
    fn normalize_then_denormalize_round_trips() {
        let mut rms = RunningMeanStd::new(2);
        rms.update(&[1.0, 10.0, 3.0, 30.0, 5.0, 20.0]);
        let mut x = vec![3.0f32, 20.0];
        rms.normalize(&mut x, 1e-8, 5.0);
        assert!(x[0].abs() < 1e-6 && x[1].abs() < 1e-6, "{x:?}");
        let mut y = vec![1.0f32, -1.0];
        rms.denormalize(&mut y, 1e-8);
        rms.normalize(&mut y, 1e-8, 5.0);
        assert!((y[0] - 1.0).abs() < 1e-5 && (y[1] + 1.0).abs() < 1e-5);
    }
}
