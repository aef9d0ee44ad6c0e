//! Small vectorised control problems for tests and examples: a point mass that must reach a
//! goal, and the classic torque-limited pendulum swing-up (the physics of Gymnasium's
//! Pendulum-v1). Both save and restore their complete state.

use crate::rng::Rng;
use crate::{BatchStep, VecEnvironment};

fn push_f64s(out: &mut Vec<u8>, v: &[f64]) {
    for x in v {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

fn read_f64s(bytes: &[u8], at: &mut usize, n: usize) -> Result<Vec<f64>, String> {
    let end = *at + 8 * n;
    let b = bytes
        .get(*at..end)
        .ok_or("environment state is truncated")?;
    *at = end;
    Ok(b.chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect())
}

fn read_u64s(bytes: &[u8], at: &mut usize, n: usize) -> Result<Vec<u64>, String> {
    Ok(read_f64s(bytes, at, n)?
        .into_iter()
        .map(f64::to_bits)
        .collect())
}

fn push_u64s(out: &mut Vec<u8>, v: &[u64]) {
    for x in v {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

/// A point mass on a plane pushed by a bounded force towards a random goal.
///
/// Observation `[goal - pos (2), velocity (2)]`; action: force in [-1, 1]^2. Each step
/// (0.1 s): `v <- 0.95 v + a dt`, `p <- p + v dt`, the position kept within +-1.5. Reward:
/// minus the distance to the goal. The episode terminates successfully when the distance is
/// under 0.1, and is truncated after 60 steps. Starts and goals are uniform in [-1, 1]^2.
pub struct PointReach {
    n: usize,
    pos: Vec<f64>,
    vel: Vec<f64>,
    goal: Vec<f64>,
    t: Vec<u64>,
    rngs: Vec<Rng>,
}

/// Steps after which a point-reach episode is truncated.
pub const POINT_REACH_LIMIT: u64 = 60;
/// Distance under which a point-reach episode succeeds.
pub const POINT_REACH_RADIUS: f64 = 0.1;
const PR_DT: f64 = 0.1;

impl PointReach {
    /// `n` environments.
    pub fn new(n: usize) -> Self {
        PointReach {
            n,
            pos: vec![0.0; 2 * n],
            vel: vec![0.0; 2 * n],
            goal: vec![0.0; 2 * n],
            t: vec![0; n],
            rngs: (0..n).map(|i| Rng::derive(0, i as u64)).collect(),
        }
    }

    fn reset_one(&mut self, i: usize) {
        let r = &mut self.rngs[i];
        for k in 0..2 {
            self.pos[2 * i + k] = r.uniform_range(-1.0, 1.0);
            self.goal[2 * i + k] = r.uniform_range(-1.0, 1.0);
            self.vel[2 * i + k] = 0.0;
        }
        self.t[i] = 0;
    }

    fn obs_one(&self, i: usize, out: &mut Vec<f32>) {
        for k in 0..2 {
            out.push((self.goal[2 * i + k] - self.pos[2 * i + k]) as f32);
        }
        for k in 0..2 {
            out.push(self.vel[2 * i + k] as f32);
        }
    }

    fn dist(&self, i: usize) -> f64 {
        let dx = self.goal[2 * i] - self.pos[2 * i];
        let dy = self.goal[2 * i + 1] - self.pos[2 * i + 1];
        (dx * dx + dy * dy).sqrt()
    }

    /// A proportional-derivative controller: the reference a learned policy is compared with.
    pub fn pd_action(obs: &[f32]) -> Vec<f32> {
        obs.chunks_exact(4)
            .flat_map(|o| {
                [
                    (3.0 * o[0] - 1.5 * o[2]).clamp(-1.0, 1.0),
                    (3.0 * o[1] - 1.5 * o[3]).clamp(-1.0, 1.0),
                ]
            })
            .collect()
    }
}

impl VecEnvironment for PointReach {
    fn num_envs(&self) -> usize {
        self.n
    }
    fn obs_dim(&self) -> usize {
        4
    }
    fn act_dim(&self) -> usize {
        2
    }
    fn action_bounds(&self) -> (Vec<f32>, Vec<f32>) {
        (vec![-1.0; 2], vec![1.0; 2])
    }
    fn identity(&self) -> String {
        format!("point-reach-v1 obs 4 act 2 limit {POINT_REACH_LIMIT}")
    }
    fn reset(&mut self, seed: u64) -> Result<Vec<f32>, String> {
        let mut out = Vec::with_capacity(4 * self.n);
        for i in 0..self.n {
            self.rngs[i] = Rng::derive(seed, i as u64);
            self.reset_one(i);
            self.obs_one(i, &mut out);
        }
        Ok(out)
    }
    fn step(&mut self, actions: &[f32]) -> Result<BatchStep, String> {
        if actions.len() != 2 * self.n {
            return Err(format!(
                "{} actions for {} envs of 2",
                actions.len(),
                self.n
            ));
        }
        let mut s = BatchStep {
            obs: Vec::with_capacity(4 * self.n),
            ..Default::default()
        };
        for i in 0..self.n {
            for k in 0..2 {
                let a = (actions[2 * i + k] as f64).clamp(-1.0, 1.0);
                let j = 2 * i + k;
                self.vel[j] = 0.95 * self.vel[j] + a * PR_DT;
                self.pos[j] += self.vel[j] * PR_DT;
                if self.pos[j].abs() > 1.5 {
                    self.pos[j] = self.pos[j].clamp(-1.5, 1.5);
                    self.vel[j] = 0.0;
                }
            }
            self.t[i] += 1;
            let d = self.dist(i);
            let success = d < POINT_REACH_RADIUS;
            let truncated = !success && self.t[i] >= POINT_REACH_LIMIT;
            s.rewards.push(-d as f32);
            s.terminated.push(success);
            s.truncated.push(truncated);
            if success || truncated {
                let mut f = Vec::with_capacity(4);
                self.obs_one(i, &mut f);
                s.final_obs.push(Some(f));
                s.success.push(Some(success));
                self.reset_one(i);
            } else {
                s.final_obs.push(None);
                s.success.push(None);
            }
            self.obs_one(i, &mut s.obs);
        }
        Ok(s)
    }
    fn save_state(&self) -> Option<Vec<u8>> {
        let mut out = Vec::new();
        push_f64s(&mut out, &self.pos);
        push_f64s(&mut out, &self.vel);
        push_f64s(&mut out, &self.goal);
        push_u64s(&mut out, &self.t);
        for r in &self.rngs {
            push_u64s(&mut out, &r.state());
        }
        Some(out)
    }
    fn load_state(&mut self, b: &[u8]) -> Result<(), String> {
        let n = self.n;
        let mut at = 0;
        let pos = read_f64s(b, &mut at, 2 * n)?;
        let vel = read_f64s(b, &mut at, 2 * n)?;
        let goal = read_f64s(b, &mut at, 2 * n)?;
        let t = read_u64s(b, &mut at, n)?;
        let mut rngs = Vec::with_capacity(n);
        for _ in 0..n {
            let s = read_u64s(b, &mut at, 4)?;
            rngs.push(Rng::from_state([s[0], s[1], s[2], s[3]]));
        }
        if at != b.len() {
            return Err(format!(
                "environment state has {} bytes, expected {at}",
                b.len()
            ));
        }
        (self.pos, self.vel, self.goal, self.t, self.rngs) = (pos, vel, goal, t, rngs);
        Ok(())
    }
}

/// Torque-limited pendulum swing-up (Gymnasium Pendulum-v1 physics and reward).
///
/// Observation `[cos th, sin th, th_dot]`, action: torque in [-2, 2]. Reward
/// `-(th^2 + 0.1 th_dot^2 + 0.001 u^2)` with `th` wrapped to [-pi, pi) (0 is upright). No
/// terminal states; truncated after 200 steps. Starts uniform in th in [-pi, pi], th_dot in
/// [-1, 1].
pub struct Pendulum {
    n: usize,
    th: Vec<f64>,
    thdot: Vec<f64>,
    t: Vec<u64>,
    rngs: Vec<Rng>,
}

/// Steps after which a pendulum episode is truncated.
pub const PENDULUM_LIMIT: u64 = 200;

impl Pendulum {
    /// `n` environments.
    pub fn new(n: usize) -> Self {
        Pendulum {
            n,
            th: vec![0.0; n],
            thdot: vec![0.0; n],
            t: vec![0; n],
            rngs: (0..n).map(|i| Rng::derive(0, i as u64)).collect(),
        }
    }

    fn reset_one(&mut self, i: usize) {
        let r = &mut self.rngs[i];
        self.th[i] = r.uniform_range(-std::f64::consts::PI, std::f64::consts::PI);
        self.thdot[i] = r.uniform_range(-1.0, 1.0);
        self.t[i] = 0;
    }

    fn obs_one(&self, i: usize, out: &mut Vec<f32>) {
        out.extend_from_slice(&[
            self.th[i].cos() as f32,
            self.th[i].sin() as f32,
            self.thdot[i] as f32,
        ]);
    }
}

fn wrap_angle(x: f64) -> f64 {
    use std::f64::consts::PI;
    (x + PI).rem_euclid(2.0 * PI) - PI
}

impl VecEnvironment for Pendulum {
    fn num_envs(&self) -> usize {
        self.n
    }
    fn obs_dim(&self) -> usize {
        3
    }
    fn act_dim(&self) -> usize {
        1
    }
    fn action_bounds(&self) -> (Vec<f32>, Vec<f32>) {
        (vec![-2.0], vec![2.0])
    }
    fn identity(&self) -> String {
        format!("pendulum-v1 obs 3 act 1 limit {PENDULUM_LIMIT}")
    }
    fn reset(&mut self, seed: u64) -> Result<Vec<f32>, String> {
        let mut out = Vec::with_capacity(3 * self.n);
        for i in 0..self.n {
            self.rngs[i] = Rng::derive(seed, i as u64);
            self.reset_one(i);
            self.obs_one(i, &mut out);
        }
        Ok(out)
    }
    fn step(&mut self, actions: &[f32]) -> Result<BatchStep, String> {
        if actions.len() != self.n {
            return Err(format!(
                "{} actions for {} envs of 1",
                actions.len(),
                self.n
            ));
        }
        let (g, m, l, dt) = (10.0, 1.0, 1.0, 0.05);
        let mut s = BatchStep {
            obs: Vec::with_capacity(3 * self.n),
            ..Default::default()
        };
        for (i, &action) in actions.iter().enumerate() {
            let u = (action as f64).clamp(-2.0, 2.0);
            let th = self.th[i];
            let thdot = self.thdot[i];
            let cost = wrap_angle(th).powi(2) + 0.1 * thdot * thdot + 0.001 * u * u;
            let new_thdot = (thdot + (3.0 * g / (2.0 * l) * th.sin() + 3.0 / (m * l * l) * u) * dt)
                .clamp(-8.0, 8.0);
            self.th[i] = th + new_thdot * dt;
            self.thdot[i] = new_thdot;
            self.t[i] += 1;
            let truncated = self.t[i] >= PENDULUM_LIMIT;
            s.rewards.push(-cost as f32);
            s.terminated.push(false);
            s.truncated.push(truncated);
            s.success.push(None);
            if truncated {
                let mut f = Vec::with_capacity(3);
                self.obs_one(i, &mut f);
                s.final_obs.push(Some(f));
                self.reset_one(i);
            } else {
                s.final_obs.push(None);
            }
            self.obs_one(i, &mut s.obs);
        }
        Ok(s)
    }
    fn save_state(&self) -> Option<Vec<u8>> {
        let mut out = Vec::new();
        push_f64s(&mut out, &self.th);
        push_f64s(&mut out, &self.thdot);
        push_u64s(&mut out, &self.t);
        for r in &self.rngs {
            push_u64s(&mut out, &r.state());
        }
        Some(out)
    }
    fn load_state(&mut self, b: &[u8]) -> Result<(), String> {
        let n = self.n;
        let mut at = 0;
        let th = read_f64s(b, &mut at, n)?;
        let thdot = read_f64s(b, &mut at, n)?;
        let t = read_u64s(b, &mut at, n)?;
        let mut rngs = Vec::with_capacity(n);
        for _ in 0..n {
            let s = read_u64s(b, &mut at, 4)?;
            rngs.push(Rng::from_state([s[0], s[1], s[2], s[3]]));
        }
        if at != b.len() {
            return Err(format!(
                "environment state has {} bytes, expected {at}",
                b.len()
            ));
        }
        (self.th, self.thdot, self.t, self.rngs) = (th, thdot, t, rngs);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_reach_pd_controller_succeeds_and_state_round_trips() {
        let mut env = PointReach::new(8);
        let mut obs = env.reset(5).unwrap();
        let mut ok = 0;
        let mut ended = 0;
        for _ in 0..600 {
            let s = env.step(&PointReach::pd_action(&obs)).unwrap();
            for i in 0..8 {
                if let Some(succ) = s.success[i] {
                    ended += 1;
                    ok += succ as usize;
                    assert!(s.final_obs[i].is_some());
                }
            }
            obs = s.obs;
        }
        assert!(ended > 50 && ok == ended, "{ok} of {ended}");
        // Restoring a saved state replays the same steps.
        let saved = env.save_state().unwrap();
        let a: Vec<f32> = vec![0.3; 16];
        let s1 = env.step(&a).unwrap();
        env.load_state(&saved).unwrap();
        assert_eq!(env.step(&a).unwrap(), s1);
        assert!(env.step(&a[1..]).is_err());
        assert!(env.load_state(&saved[1..]).is_err());
    }

    #[test]
    fn pendulum_matches_hand_step_and_truncates() {
        let mut env = Pendulum::new(1);
        env.reset(0).unwrap();
        env.th[0] = 0.5;
        env.thdot[0] = 0.0;
        let s = env.step(&[1.0]).unwrap();
        let thdot = (15.0 * 0.5f64.sin() + 3.0) * 0.05;
        assert!((env.thdot[0] - thdot).abs() < 1e-12);
        assert!((env.th[0] - (0.5 + thdot * 0.05)).abs() < 1e-12);
        assert!((s.rewards[0] as f64 + 0.25 + 0.001).abs() < 1e-6);
        let mut truncs = 0;
        for _ in 0..399 {
            truncs += env.step(&[0.0]).unwrap().truncated[0] as usize;
        }
        assert_eq!(truncs, 2);
    }
}
