//! The `info` dicts of the Gymnasium environments: what one env reports per step and reset,
//! and how a vector env batches them exactly as Gymnasium 1.x's own vector envs do
//! (`VectorEnv._add_info`: a key's values in one array of the batch, a boolean `_key` mask of
//! the envs that reported it, dicts batched recursively; `final_obs` an object array).
//!
//! One env's step info: `success` (bool, when the task defines success), `values` (the step's
//! named diagnostics: `reward/<term>`, `termination/<term>`, `success/<term>`, ...). On the step
//! that ends an episode also `is_success` (Stable-Baselines3's key; an episode ended by an
//! error counts as a failure), `ended` (`success`, `failure`, `time_limit`, `error`),
//! `terminations` (the failure terms that fired) and `error` (`None` or the reason), as in
//! `run --json`. A reset's info is empty, or holds `error` when the reset failed.

use modesuite_engine::EnvInfo;

use crate::episode::{final_success, EpisodeEnd};

/// A value of an info dict; `O` is an observation (for `final_obs`).
#[derive(Debug, Clone, PartialEq)]
pub enum InfoValue<O> {
    /// Python `bool` (batched as `np.bool_`).
    Bool(bool),
    /// Python `float` (batched as `np.float64`).
    F64(f64),
    /// Python `str` (batched in an object array).
    Str(String),
    /// Python `None` (batched in an object array).
    None,
    /// Python `list[str]` (batched in an object array).
    StrList(Vec<String>),
    /// A nested dict (batched recursively).
    Dict(Info<O>),
    /// An observation (`final_obs`; batched in an object array).
    Obs(O),
}

/// An info dict, keys in insertion order.
pub type Info<O> = Vec<(String, InfoValue<O>)>;

/// What one env remembers between steps to report its episode's end like `run --json`.
#[derive(Debug, Clone, Copy, Default)]
pub struct EpisodeTracker {
    /// The success of this episode's last step (`None` before the first or without criterion).
    last_success: Option<bool>,
}

impl EpisodeTracker {
    /// A new episode starts.
    pub fn reset(&mut self) {
        self.last_success = None;
    }

    /// The info of a step (`info` is that step's own info, not a same-step-reset one); `done`
    /// when it ended the episode (the tracker then starts over).
    pub fn step_info<O>(&mut self, info: &EnvInfo, terminated: bool, done: bool) -> Info<O> {
        let mut out = Vec::with_capacity(if done { 6 } else { 2 });
        if let Some(s) = info.success {
            out.push(("success".to_string(), InfoValue::Bool(s)));
        }
        out.push((
            "values".to_string(),
            InfoValue::Dict(
                info.values
                    .iter()
                    .map(|(k, v)| (k.clone(), InfoValue::F64(*v)))
                    .collect(),
            ),
        ));
        if done {
            let error = info.error.is_some();
            if let Some(s) = final_success(self.last_success, info.success, error) {
                out.push(("is_success".to_string(), InfoValue::Bool(s)));
            }
            let end = EpisodeEnd::from_info(terminated, info);
            out.push(("ended".to_string(), InfoValue::Str(end.name().to_string())));
            out.push((
                "terminations".to_string(),
                InfoValue::StrList(end.terminations().to_vec()),
            ));
            out.push((
                "error".to_string(),
                info.error.clone().map_or(InfoValue::None, InfoValue::Str),
            ));
            self.reset();
        } else {
            self.last_success = info.success;
        }
        out
    }
}

/// The info of a reset whose error (if any) is `error`.
pub fn reset_info<O>(error: Option<&str>) -> Info<O> {
    error
        .map(|e| vec![("error".to_string(), InfoValue::Str(e.to_string()))])
        .unwrap_or_default()
}

/// One key's values over the envs of a batch.
#[derive(Debug, Clone, PartialEq)]
pub enum ColumnData<O> {
    /// `np.bool_` array.
    Bool(Vec<bool>),
    /// `np.float64` array.
    F64(Vec<f64>),
    /// Object array (`None` where an env did not report the key).
    Object(Vec<InfoValue<O>>),
    /// A nested batched dict.
    Dict(Batch<O>),
}

/// One key of a batched info: its values and its mask (`_key`).
#[derive(Debug, Clone, PartialEq)]
pub struct Column<O> {
    /// The values.
    pub data: ColumnData<O>,
    /// Which envs reported the key.
    pub mask: Vec<bool>,
}

/// A batched info dict of `n` envs.
#[derive(Debug, Clone, PartialEq)]
pub struct Batch<O> {
    n: usize,
    /// Keys in first-seen order (each is returned with its `_key` mask beside it).
    pub cols: Vec<(String, Column<O>)>,
}

impl<O> Batch<O> {
    /// An empty batch of `n` envs.
    pub fn new(n: usize) -> Self {
        Self {
            n,
            cols: Vec::new(),
        }
    }

    /// Adds env `i`'s `info` (Gymnasium's `_add_info(infos, info, i)`): the first env to report
    /// a key sets the column's kind (bool, float, dict, else object), as numpy arrays made from
    /// the first value do.
    pub fn add(&mut self, info: Info<O>, i: usize) {
        for (key, value) in info {
            let n = self.n;
            let pos = match self.cols.iter().position(|(k, _)| *k == key) {
                Some(p) => p,
                None => {
                    let data = match (&value, key.as_str()) {
                        (_, "final_obs") => ColumnData::Object(new_objects(n)),
                        (InfoValue::Bool(_), _) => ColumnData::Bool(vec![false; n]),
                        (InfoValue::F64(_), _) => ColumnData::F64(vec![0.0; n]),
                        (InfoValue::Dict(_), _) => ColumnData::Dict(Batch::new(n)),
                        _ => ColumnData::Object(new_objects(n)),
                    };
                    self.cols.push((
                        key,
                        Column {
                            data,
                            mask: vec![false; n],
                        },
                    ));
                    self.cols.len() - 1
                }
            };
            let col = &mut self.cols[pos].1;
            col.mask[i] = true;
            match (&mut col.data, value) {
                (ColumnData::Dict(b), InfoValue::Dict(d)) => b.add(d, i),
                (ColumnData::Bool(a), InfoValue::Bool(x)) => a[i] = x,
                (ColumnData::Bool(a), InfoValue::F64(x)) => a[i] = x != 0.0,
                (ColumnData::F64(a), InfoValue::F64(x)) => a[i] = x,
                (ColumnData::F64(a), InfoValue::Bool(x)) => a[i] = f64::from(u8::from(x)),
                (ColumnData::Object(a), v) => a[i] = v,
                // a key whose kind changes between envs (never made by this module): kept in an
                // object array rather than lost
                (data, v) => {
                    let mut objects = data.take_objects(n);
                    objects[i] = v;
                    *data = ColumnData::Object(objects);
                }
            }
        }
    }
}

impl<O> ColumnData<O> {
    /// The values as an object column (bools and floats kept, a dict's rows lost).
    fn take_objects(&mut self, n: usize) -> Vec<InfoValue<O>> {
        match std::mem::replace(self, ColumnData::Bool(Vec::new())) {
            ColumnData::Bool(a) => a.into_iter().map(InfoValue::Bool).collect(),
            ColumnData::F64(a) => a.into_iter().map(InfoValue::F64).collect(),
            ColumnData::Object(a) => a,
            ColumnData::Dict(_) => new_objects(n),
        }
    }
}

fn new_objects<O>(n: usize) -> Vec<InfoValue<O>> {
    (0..n).map(|_| InfoValue::None).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    type V = InfoValue<()>;

    #[test]
    fn batches_like_gymnasium_add_info() {
        let mut b: Batch<()> = Batch::new(3);
        b.add(vec![("success".into(), V::Bool(true))], 0);
        b.add(
            vec![
                ("final_obs".into(), V::Obs(())),
                (
                    "final_info".into(),
                    V::Dict(vec![("error".into(), V::Str("boom".into()))]),
                ),
            ],
            2,
        );
        b.add(vec![("success".into(), V::Bool(false))], 2);
        let keys: Vec<_> = b.cols.iter().map(|(k, _)| k.as_str()).collect();
        assert_eq!(keys, ["success", "final_obs", "final_info"]);
        assert_eq!(b.cols[0].1.mask, [true, false, true]);
        assert_eq!(b.cols[0].1.data, ColumnData::Bool(vec![true, false, false]));
        assert_eq!(
            b.cols[1].1.data,
            ColumnData::Object(vec![V::None, V::None, V::Obs(())])
        );
        let ColumnData::Dict(fi) = &b.cols[2].1.data else {
            panic!("final_info is a dict")
        };
        assert_eq!(fi.cols[0].1.mask, [false, false, true]);
        assert_eq!(
            fi.cols[0].1.data,
            ColumnData::Object(vec![V::None, V::None, V::Str("boom".into())])
        );
    }

    #[test]
    fn an_errored_episode_of_a_task_with_success_reports_failure() {
        let mut t = EpisodeTracker::default();
        let ok = EnvInfo {
            success: Some(false),
            ..EnvInfo::default()
        };
        let info: Info<()> = t.step_info(&ok, false, false);
        assert!(!info.iter().any(|(k, _)| k == "is_success"));
        let err = EnvInfo {
            error: Some("physics: exploded".into()),
            ..EnvInfo::default()
        };
        let info: Info<()> = t.step_info(&err, false, true);
        let get = |k: &str| info.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone());
        assert_eq!(get("is_success"), Some(V::Bool(false)));
        assert_eq!(get("ended"), Some(V::Str("error".into())));
        assert_eq!(get("error"), Some(V::Str("physics: exploded".into())));
        // the next episode starts over: an error on its first step has no success to report
        let info: Info<()> = t.step_info(&err, false, true);
        assert!(!info.iter().any(|(k, _)| k == "is_success"));
    }
}
