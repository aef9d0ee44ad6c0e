//! Playing a policy's action chunks in an env, one action per step: open-loop (each chunk to
//! its end before the policy observes again) or with ACT's temporal ensembling (the policy
//! observes at every step; the action played is the weighted mean of every chunk's
//! prediction for that step).

use std::collections::VecDeque;

/// The actions still to play of a chunked policy ([`crate::PolicyMeta::chunk`],
/// [`crate::PolicyMeta::ensemble`]). A policy of one action per observation passes through.
#[derive(Clone, Debug)]
pub struct ChunkPlayer {
    act_dim: usize,
    chunk: usize,
    ensemble: Option<f64>,
    /// Open-loop: the current chunk's remaining actions. Ensembling: for each coming step, the
    /// weighted sum of the predictions made for it so far and the sum of their weights.
    pending: VecDeque<(Vec<f64>, f64)>,
}

impl ChunkPlayer {
    /// A player for chunks of `chunk` actions of `act_dim` values, ensembled with exponent
    /// `ensemble` (`None`: open-loop).
    pub fn new(act_dim: usize, chunk: usize, ensemble: Option<f64>) -> Self {
        Self {
            act_dim,
            chunk: chunk.max(1),
            ensemble,
            pending: VecDeque::new(),
        }
    }

    /// Forgets what is pending (a new episode).
    pub fn reset(&mut self) {
        self.pending.clear();
    }

    /// Whether the next action needs a new chunk, i.e. the policy observes at this step.
    pub fn needs_chunk(&self) -> bool {
        self.ensemble.is_some() || self.pending.is_empty()
    }

    /// Writes this step's action into `action`; `chunk` (up to `chunk` actions of `act_dim`
    /// values, at least one, predicted from this step's observation: a shorter one, such as a
    /// demonstration's last frames, plays fewer steps open-loop and predicts fewer ahead) must
    /// be given when [`ChunkPlayer::needs_chunk`] says so and is ignored otherwise.
    ///
    /// # Panics
    /// If a chunk is needed and missing or has the wrong length (a caller's bug).
    pub fn play(&mut self, chunk: Option<&[f32]>, action: &mut [f32]) {
        let ad = self.act_dim;
        assert_eq!(action.len(), ad, "ChunkPlayer::play: action length");
        if self.needs_chunk() {
            let c = chunk.expect("ChunkPlayer::play: this step needs a chunk");
            assert!(
                !c.is_empty() && c.len().is_multiple_of(ad) && c.len() <= ad * self.chunk,
                "ChunkPlayer::play: chunk length {} (act_dim {ad}, chunk {})",
                c.len(),
                self.chunk
            );
            match self.ensemble {
                None => self.pending.extend(
                    c.chunks_exact(ad)
                        .map(|a| (a.iter().map(|&x| f64::from(x)).collect(), 1.0)),
                ),
                Some(m) => {
                    while self.pending.len() < self.chunk {
                        self.pending.push_back((vec![0.0; ad], 0.0));
                    }
                    // the prediction for `i` steps ahead is `i` steps old when it is played
                    for (i, (a, (sum, weight))) in
                        c.chunks_exact(ad).zip(self.pending.iter_mut()).enumerate()
                    {
                        let w = (m * i as f64).exp();
                        for (s, &x) in sum.iter_mut().zip(a) {
                            *s += w * f64::from(x);
                        }
                        *weight += w;
                    }
                }
            }
        }
        let (mut sum, weight) = self.pending.pop_front().expect("filled above");
        for (o, s) in action.iter_mut().zip(&sum) {
            *o = (s / weight) as f32;
        }
        if self.ensemble.is_some() {
            // the slot comes back empty for the step a chunk ahead: no allocation per step
            sum.fill(0.0);
            self.pending.push_back((sum, 0.0));
        }
    }
}

/// Checks a temporal-ensembling exponent (`BcConfig::ensemble`, `PolicyMeta::ensemble`, a
/// retrieval policy's): finite, in `0..=`[`MAX_ENSEMBLE`], and only for chunks of `chunk >= 2`
/// actions; `name` is what the chunk is called there (`chunk`, `horizon`).
pub fn check_ensemble(ensemble: Option<f64>, chunk: usize, name: &str) -> Result<(), String> {
    match ensemble {
        Some(m) if !(m.is_finite() && (0.0..=MAX_ENSEMBLE).contains(&m)) || chunk < 2 => {
            Err(format!(
                "ensemble = {m} ({name} {chunk}): a weight exponent in 0..={MAX_ENSEMBLE}, for {name} >= 2"
            ))
        }
        _ => Ok(()),
    }
}

/// Largest temporal-ensembling exponent: the oldest of [`crate::policy::MAX_CHUNK`]
/// predictions then weighs `exp(5 * 99)`, still a finite `f64`.
pub const MAX_ENSEMBLE: f64 = 5.0;

#[cfg(test)]
mod tests {
    use super::*;

    /// Chunks of 3 one-value actions, the step's index `t` predicted as `10 t + i` for `i`
    /// steps ahead: open-loop plays `0, 1, 2, 30, 31, 32`; ensembling averages the
    /// predictions made for each step (ACT's weights: the older, the heavier).
    #[test]
    fn chunks_play_open_loop_or_ensembled() {
        let chunk_at = |t: usize| -> Vec<f32> { (0..3).map(|i| (10 * t + i) as f32).collect() };
        let mut open = ChunkPlayer::new(1, 3, None);
        let mut played = Vec::new();
        for t in 0..6 {
            let mut a = [0.0f32];
            let c = open.needs_chunk().then(|| chunk_at(t));
            open.play(c.as_deref(), &mut a);
            played.push(a[0]);
        }
        assert_eq!(played, [0.0, 1.0, 2.0, 30.0, 31.0, 32.0]);
        let m = 0.5f64;
        let mut ens = ChunkPlayer::new(1, 3, Some(m));
        let mut played = Vec::new();
        for t in 0..4 {
            let mut a = [0.0f32];
            assert!(ens.needs_chunk());
            ens.play(Some(&chunk_at(t)), &mut a);
            played.push(a[0]);
        }
        // step 2: predictions 2 (made at 0, age 2), 11 (at 1, age 1), 20 (at 2, age 0)
        let (w2, w1) = ((2.0 * m).exp(), m.exp());
        let step2 = (w2 * 2.0 + w1 * 11.0 + 20.0) / (w2 + w1 + 1.0);
        let step3 = (w2 * 12.0 + w1 * 21.0 + 30.0) / (w2 + w1 + 1.0);
        let step1 = (w1 * 1.0 + 10.0) / (w1 + 1.0);
        let want = [0.0, step1 as f32, step2 as f32, step3 as f32];
        println!("ensembled {played:?}, closed forms {want:?}");
        assert_eq!(played, want);
        ens.reset();
        let mut a = [0.0f32];
        ens.play(Some(&chunk_at(7)), &mut a);
        assert_eq!(a[0], 70.0, "a reset forgets the pending predictions");
        // a shorter chunk (a demonstration's end): open-loop plays it and looks again
        let mut open = ChunkPlayer::new(1, 3, None);
        open.play(Some(&[5.0, 6.0]), &mut a);
        assert!(!open.needs_chunk() && a[0] == 5.0);
        open.play(None, &mut a);
        assert!(open.needs_chunk() && a[0] == 6.0);
    }
}
