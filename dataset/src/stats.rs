//! Feature statistics as LeRobot keeps them: per episode (`stats/<feature>/<stat>` columns of
//! the episodes file) and over the dataset (`meta/stats.json`): `min`, `max`, `mean`, `std`
//! (population), `count`, and the quantiles `q01 q10 q50 q90 q99` (numpy's linear rule).

use serde_json::{json, Value};

/// The quantiles kept, and their names.
pub const QUANTILES: [(f64, &str); 5] = [
    (0.01, "q01"),
    (0.10, "q10"),
    (0.50, "q50"),
    (0.90, "q90"),
    (0.99, "q99"),
];

/// The names of the statistics, in the order of the episodes file's columns.
pub const STAT_NAMES: [&str; 10] = [
    "min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99",
];

/// Statistics of one feature: one value per component (per channel for images).
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureStats {
    /// Smallest value.
    pub min: Vec<f64>,
    /// Largest value.
    pub max: Vec<f64>,
    /// Mean.
    pub mean: Vec<f64>,
    /// Population standard deviation.
    pub std: Vec<f64>,
    /// Frames (or sampled image frames) counted.
    pub count: u64,
    /// `q01 q10 q50 q90 q99` per component.
    pub quantiles: [Vec<f64>; 5],
    /// Written as `[[[c]], ...]` (shape `[3, 1, 1]`), as LeRobot keeps image statistics.
    pub image: bool,
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = (lo + 1).min(sorted.len() - 1);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

impl FeatureStats {
    /// Statistics of `rows` rows of `dim` components (`values` row-major); `rows >= 1`.
    pub fn of(values: &[f64], dim: usize) -> Self {
        let rows = values.len() / dim.max(1);
        let mut s = FeatureStats {
            min: Vec::with_capacity(dim),
            max: Vec::with_capacity(dim),
            mean: Vec::with_capacity(dim),
            std: Vec::with_capacity(dim),
            count: rows as u64,
            quantiles: Default::default(),
            image: false,
        };
        let mut col = Vec::with_capacity(rows);
        for d in 0..dim {
            col.clear();
            col.extend((0..rows).map(|r| values[r * dim + d]));
            col.sort_by(f64::total_cmp);
            let n = rows.max(1) as f64;
            let mean = col.iter().sum::<f64>() / n;
            let var = col.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n;
            s.min.push(col.first().copied().unwrap_or(0.0));
            s.max.push(col.last().copied().unwrap_or(0.0));
            s.mean.push(mean);
            s.std.push(var.sqrt());
            for (k, (q, _)) in QUANTILES.iter().enumerate() {
                s.quantiles[k].push(if col.is_empty() {
                    0.0
                } else {
                    quantile(&col, *q)
                });
            }
        }
        s
    }

    /// Per-channel statistics of RGB frames (values scaled to 0..1), for video features.
    pub fn of_rgb(frames: &[&[u8]]) -> Self {
        let mut values = Vec::new();
        for f in frames {
            // every 4th pixel: LeRobot also samples large images
            for px in f.chunks_exact(3).step_by(4) {
                values.extend(px.iter().map(|&v| f64::from(v) / 255.0));
            }
        }
        let mut s = Self::of(&values, 3);
        s.count = frames.len() as u64;
        s.image = true;
        s
    }

    /// The statistics of several episodes' statistics together, as LeRobot aggregates them:
    /// min and max element-wise, means weighted by count, variances by the parallel rule,
    /// quantiles as count-weighted means (an approximation, LeRobot's).
    pub fn aggregate(parts: &[&FeatureStats]) -> Option<Self> {
        let first = parts.first()?;
        let dim = first.mean.len();
        let total: u64 = parts.iter().map(|p| p.count).sum();
        let w = |p: &FeatureStats| p.count as f64 / total.max(1) as f64;
        let mut out = FeatureStats {
            min: first.min.clone(),
            max: first.max.clone(),
            mean: vec![0.0; dim],
            std: vec![0.0; dim],
            count: total,
            quantiles: std::array::from_fn(|_| vec![0.0; dim]),
            image: first.image,
        };
        for p in parts {
            for d in 0..dim {
                out.min[d] = out.min[d].min(p.min[d]);
                out.max[d] = out.max[d].max(p.max[d]);
                out.mean[d] += w(p) * p.mean[d];
                for k in 0..5 {
                    out.quantiles[k][d] += w(p) * p.quantiles[k][d];
                }
            }
        }
        for d in 0..dim {
            let var: f64 = parts
                .iter()
                .map(|p| w(p) * (p.std[d] * p.std[d] + (p.mean[d] - out.mean[d]).powi(2)))
                .sum();
            out.std[d] = var.sqrt();
        }
        Some(out)
    }

    /// One statistic's values (`count` as one value).
    pub fn values(&self, stat: &str) -> Vec<f64> {
        match stat {
            "min" => self.min.clone(),
            "max" => self.max.clone(),
            "mean" => self.mean.clone(),
            "std" => self.std.clone(),
            "count" => vec![self.count as f64],
            q => QUANTILES
                .iter()
                .position(|(_, n)| *n == q)
                .map(|k| self.quantiles[k].clone())
                .unwrap_or_default(),
        }
    }

    /// Rebuilds statistics from the values of each statistic (`values` per name).
    pub fn from_values(get: impl Fn(&str) -> Option<Vec<f64>>, image: bool) -> Option<Self> {
        Some(FeatureStats {
            min: get("min")?,
            max: get("max")?,
            mean: get("mean")?,
            std: get("std")?,
            count: get("count")?.first().copied()? as u64,
            quantiles: [
                get("q01")?,
                get("q10")?,
                get("q50")?,
                get("q90")?,
                get("q99")?,
            ],
            image,
        })
    }

    /// The statistics as `meta/stats.json` writes them.
    pub fn to_json(&self) -> Value {
        let v = |x: &[f64]| -> Value {
            if self.image {
                Value::from(x.iter().map(|c| json!([[c]])).collect::<Vec<_>>())
            } else {
                Value::from(x.to_vec())
            }
        };
        let mut m = serde_json::Map::new();
        m.insert("min".into(), v(&self.min));
        m.insert("max".into(), v(&self.max));
        m.insert("mean".into(), v(&self.mean));
        m.insert("std".into(), v(&self.std));
        m.insert("count".into(), json!([self.count]));
        for (k, (_, name)) in QUANTILES.iter().enumerate() {
            m.insert((*name).into(), v(&self.quantiles[k]));
        }
        Value::Object(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_match_numpy() {
        // numpy: a = [3, 1, 4, 1, 5]; np.quantile(a, [.01, .1, .5, .9, .99]) =
        // [1.0, 1.0, 3.0, 4.6, 4.96]; mean 2.8, std 1.6
        let s = FeatureStats::of(&[3.0, 1.0, 4.0, 1.0, 5.0], 1);
        assert_eq!((s.min[0], s.max[0], s.count), (1.0, 5.0, 5));
        assert!((s.mean[0] - 2.8).abs() < 1e-12 && (s.std[0] - 1.6).abs() < 1e-12);
        let q: Vec<f64> = s.quantiles.iter().map(|q| q[0]).collect();
        for (got, want) in q.iter().zip([1.0, 1.0, 3.0, 4.6, 4.96]) {
            assert!((got - want).abs() < 1e-12, "{q:?}");
        }
    }

    #[test]
    fn aggregation_of_two_halves_equals_the_whole_for_moments() {
        let a = [1.0, 2.0, 3.0, 10.0];
        let b = [-4.0, 0.5];
        let whole: Vec<f64> = a.iter().chain(&b).copied().collect();
        let agg =
            FeatureStats::aggregate(&[&FeatureStats::of(&a, 1), &FeatureStats::of(&b, 1)]).unwrap();
        let w = FeatureStats::of(&whole, 1);
        assert_eq!((agg.min, agg.max, agg.count), (w.min, w.max, w.count));
        assert!((agg.mean[0] - w.mean[0]).abs() < 1e-12);
        assert!((agg.std[0] - w.std[0]).abs() < 1e-12);
    }
}
