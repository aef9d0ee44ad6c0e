//! Generalised advantage estimation with terminal states and time limits told apart.

/// Advantages and value targets (returns) for a rollout of `T` steps of `n` environments.
///
/// All slices are laid out step-major: index `t * n + i` is step `t` of environment `i`.
/// - `values`: the value of the observation each step acted on.
/// - `last_values`: the value of the observation after the last step (`n` long).
/// - `final_values`: where a step ended its episode, the value of that episode's final
///   observation (`BatchStep::final_obs`); read only for truncated, non-terminated steps.
///
/// A terminated step contributes no value beyond it. A truncated step (time limit) bootstraps
/// from its final observation: `delta = r + gamma * V(final_obs) - V(s)`. Either way the
/// advantage does not flow across the episode boundary.
#[allow(clippy::too_many_arguments)]
pub fn gae(
    n: usize,
    rewards: &[f32],
    values: &[f32],
    last_values: &[f32],
    final_values: &[f32],
    terminated: &[bool],
    truncated: &[bool],
    gamma: f32,
    lambda: f32,
) -> (Vec<f32>, Vec<f32>) {
    let len = rewards.len();
    assert!(
        n > 0 && len.is_multiple_of(n),
        "rollout length {len} is not a multiple of {n}"
    );
    for (name, l) in [
        ("values", values.len()),
        ("final_values", final_values.len()),
        ("terminated", terminated.len()),
        ("truncated", truncated.len()),
    ] {
        assert_eq!(l, len, "{name} has {l} entries, rewards {len}");
    }
    assert_eq!(last_values.len(), n, "last_values");
    let steps = len / n;
    let mut adv = vec![0.0f32; len];
    for (i, &last_value) in last_values.iter().enumerate() {
        let mut next_adv = 0.0f32;
        for t in (0..steps).rev() {
            let k = t * n + i;
            let (next_value, continues) = if terminated[k] {
                (0.0, false)
            } else if truncated[k] {
                (final_values[k], false)
            } else if t + 1 < steps {
                (values[k + n], true)
            } else {
                (last_value, true)
            };
            let delta = rewards[k] + gamma * next_value - values[k];
            let a = if continues {
                delta + gamma * lambda * next_adv
            } else {
                delta
            };
            adv[k] = a;
            next_adv = a;
        }
    }
    let returns = adv.iter().zip(values).map(|(a, v)| a + v).collect();
    (adv, returns)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two environments, three steps, gamma = lambda = 0.5 (all values exact in binary).
    ///
    /// Env 0 terminates at t = 1 (its final value 7 must be ignored); the rollout ends
    /// mid-episode, bootstrapped with last value 2:
    ///   t2: delta = 3 + 0.5 * 2 - 1.5 = 2.5;           A = 2.5
    ///   t1: delta = 2 + 0 - 1 = 1 (terminal);        A = 1
    ///   t0: delta = 1 + 0.5 * 1 - 0.5 = 1;             A = 1 + 0.25 * 1 = 1.25
    /// Env 1 hits a time limit at t = 0 with final value 6, and is bootstrapped with 8:
    ///   t2: delta = -1 + 0.5 * 8 - 4 = -1;             A = -1
    ///   t1: delta = 1 + 0.5 * 4 - 2 = 1;               A = 1 + 0.25 * -1 = 0.75
    ///   t0: delta = 0 + 0.5 * 6 - 1 = 2 (time limit);  A = 2
    #[test]
    fn fixture_with_terminal_and_time_limit() {
        let rewards = [1.0, 0.0, 2.0, 1.0, 3.0, -1.0];
        let values = [0.5, 1.0, 1.0, 2.0, 1.5, 4.0];
        let final_values = [0.0, 6.0, 7.0, 0.0, 0.0, 0.0];
        let terminated = [false, false, true, false, false, false];
        let truncated = [false, true, false, false, false, false];
        let last = [2.0, 8.0];
        let (adv, ret) = gae(
            2,
            &rewards,
            &values,
            &last,
            &final_values,
            &terminated,
            &truncated,
            0.5,
            0.5,
        );
        assert_eq!(adv, vec![1.25, 2.0, 1.0, 0.75, 2.5, -1.0]);
        assert_eq!(ret, vec![1.75, 3.0, 2.0, 2.75, 4.0, 3.0]);

        // Treating the time limit as a terminal state would lose the bootstrap (delta = -1).
        let (adv_wrong, _) = gae(
            2,
            &rewards,
            &values,
            &last,
            &final_values,
            &[false, true, true, false, false, false],
            &truncated,
            0.5,
            0.5,
        );
        assert_eq!(adv_wrong[1], -1.0);
    }

    #[test]
    fn matches_discounted_sum_when_lambda_is_one_and_values_zero() {
        let r = [1.0f32, 2.0, 3.0, 4.0];
        let z = [0.0f32; 4];
        let f = [false; 4];
        let (adv, _) = gae(1, &r, &z, &[10.0], &z, &f, &f, 0.9, 1.0);
        let expect3 = 4.0 + 0.9 * 10.0;
        let expect2 = 3.0 + 0.9 * expect3;
        let expect1 = 2.0 + 0.9 * expect2;
        let expect0 = 1.0 + 0.9 * expect1;
        for (a, e) in adv.iter().zip([expect0, expect1, expect2, expect3]) {
            assert!((a - e).abs() < 1e-5, "{adv:?}");
        }
    }
}
