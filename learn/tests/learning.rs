//! Learning, determinism and resume tests on the crate's own small environments.
//!
//! Thresholds are stated next to each test; the measured values are printed beside them
//! (`cargo test -p modesuite-learn -- --nocapture`).

use modesuite_learn::checkpoint::Checkpoint;
use modesuite_learn::envs::{Pendulum, PointReach};
use modesuite_learn::{
    evaluate, read_metrics, train, AlgoConfig, Control, Metrics, Policy, PpoConfig, RunOptions,
    SacConfig, Silent, VecEnvironment,
};
use std::path::PathBuf;
use std::time::Instant;

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("mslearn-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// PPO settings for the point-mass reach: the defaults (256-128-64 ELU network, rl_games'
/// Isaac Lab values) with a smaller rollout and minibatch.
fn ppo_reach(seed: u64) -> AlgoConfig {
    AlgoConfig::Ppo(PpoConfig {
        seed,
        horizon: 32,
        minibatch_size: 256,
        mini_epochs: 5,
        ..PpoConfig::default()
    })
}

/// SAC settings for the pendulum: a 64-64 network, learning rates 1e-3 and Polyak 0.01 (with
/// 0.005, one seed of seven, seed 5, still failed to swing up from some starts at 12,000 steps;
/// with 0.01 seeds 3 to 9 all scored -161 to -165).
fn sac_pendulum(seed: u64) -> AlgoConfig {
    AlgoConfig::Sac(SacConfig {
        seed,
        hidden: vec![64, 64],
        batch_size: 128,
        learning_starts: 1000,
        steps_per_iteration: 500,
        actor_lr: 1e-3,
        critic_lr: 1e-3,
        alpha_lr: 1e-3,
        tau: 0.01,
        ..SacConfig::default()
    })
}

/// Point-mass reach PPO: after 120,000 env steps (16 envs) the deterministic policy must
/// succeed in at least 95 % of 200 held-out episodes with a mean return within 25 % of the
/// hand-tuned PD controller's. Two runs with the same seed must end with identical
/// parameters.
#[test]
fn ppo_solves_point_reach_deterministically() {
    let steps = 120_000;
    let mut hashes = Vec::new();
    let mut dirs = Vec::new();
    for run in 0..2 {
        let dir = tmp(&format!("ppo-reach-{run}"));
        let mut env = PointReach::new(16);
        let start = Instant::now();
        let mut opts = RunOptions::new(&dir, steps);
        opts.checkpoint_every = 0;
        let s = train(&ppo_reach(1), &mut env, &opts, &mut Silent).unwrap();
        let secs = start.elapsed().as_secs_f64();
        let last = s.last.clone().unwrap();
        println!(
            "ppo reach run {run}: {} updates, {} env steps in {secs:.1} s ({:.0} steps/s, {:.2} updates/s); last training return {:.2}, success {:?}, hash {:016x}",
            s.iterations,
            s.env_steps,
            s.env_steps as f64 / secs,
            s.iterations as f64 / secs,
            last.return_mean.unwrap_or(f64::NAN),
            last.success_rate,
            s.param_hash
        );
        hashes.push(s.param_hash);
        dirs.push(dir);
    }
    assert_eq!(hashes[0], hashes[1], "same seed, different parameters");

    let policy = Policy::load(&dirs[0]).unwrap();
    let mut env = PointReach::new(16);
    let learned = evaluate(&mut env, 200, 10_000, |o| policy.act(o)).unwrap();
    let reference = evaluate(&mut env, 200, 10_000, PointReach::pd_action).unwrap();
    let threshold = reference.return_mean() * 1.25;
    println!(
        "ppo reach eval (200 episodes, seed 10000): success {:.3} (threshold 0.95), return {:.3} (threshold {threshold:.3}; PD controller {:.3}, success {:.3})",
        learned.success_rate().unwrap(),
        learned.return_mean(),
        reference.return_mean(),
        reference.success_rate().unwrap()
    );
    assert!(learned.success_rate().unwrap() >= 0.95);
    assert!(learned.return_mean() >= threshold);
    for d in dirs {
        std::fs::remove_dir_all(d).unwrap();
    }
}

/// Pendulum SAC: after 12,000 env steps (one env) the deterministic policy's mean return over
/// 20 held-out episodes must be at least -250 (a random policy scores about -1200). Two runs
/// with the same seed must end with identical parameters.
#[test]
fn sac_solves_pendulum_deterministically() {
    let steps = 12_000;
    let mut hashes = Vec::new();
    let mut dirs = Vec::new();
    for run in 0..2 {
        let dir = tmp(&format!("sac-pendulum-{run}"));
        let mut env = Pendulum::new(1);
        let start = Instant::now();
        let mut opts = RunOptions::new(&dir, steps);
        opts.checkpoint_every = 0;
        let s = train(&sac_pendulum(3), &mut env, &opts, &mut Silent).unwrap();
        let secs = start.elapsed().as_secs_f64();
        let last = s.last.clone().unwrap();
        println!(
            "sac pendulum run {run}: {} env steps in {secs:.1} s ({:.0} steps/s with one gradient step each); last training return {:.1}, alpha {:.4}, hash {:016x}",
            s.env_steps,
            s.env_steps as f64 / secs,
            last.return_mean.unwrap_or(f64::NAN),
            last.alpha.unwrap(),
            s.param_hash
        );
        hashes.push(s.param_hash);
        dirs.push(dir);
    }
    assert_eq!(hashes[0], hashes[1], "same seed, different parameters");
    let policy = Policy::load(&dirs[0]).unwrap();
    let mut env = Pendulum::new(4);
    let learned = evaluate(&mut env, 20, 20_000, |o| policy.act(o)).unwrap();
    let zero = evaluate(&mut env, 20, 20_000, |o| {
        o.iter().step_by(3).map(|_| 0.0).collect()
    })
    .unwrap();
    println!(
        "sac pendulum eval (20 episodes, seed 20000): return {:.1} (threshold -250; zero torque {:.1})",
        learned.return_mean(),
        zero.return_mean()
    );
    assert!(learned.return_mean() >= -250.0);
    for d in dirs {
        std::fs::remove_dir_all(d).unwrap();
    }
}

/// An environment with part of its state handling taken away: without `saves` it hides
/// `save_state` (the trainer then resets the environments at each checkpoint); without
/// `restores` it cannot restore a saved state (a checkpoint of another build of the simulator).
struct Limited<E> {
    env: E,
    saves: bool,
    restores: bool,
}

impl<E: VecEnvironment> VecEnvironment for Limited<E> {
    fn num_envs(&self) -> usize {
        self.env.num_envs()
    }
    fn obs_dim(&self) -> usize {
        self.env.obs_dim()
    }
    fn act_dim(&self) -> usize {
        self.env.act_dim()
    }
    fn action_bounds(&self) -> (Vec<f32>, Vec<f32>) {
        self.env.action_bounds()
    }
    fn identity(&self) -> String {
        self.env.identity()
    }
    fn reset(&mut self, seed: u64) -> Result<Vec<f32>, String> {
        self.env.reset(seed)
    }
    fn step(&mut self, actions: &[f32]) -> Result<modesuite_learn::BatchStep, String> {
        self.env.step(actions)
    }
    fn save_state(&self) -> Option<Vec<u8>> {
        self.saves.then(|| self.env.save_state()).flatten()
    }
    fn load_state(&mut self, state: &[u8]) -> Result<(), String> {
        if self.restores {
            self.env.load_state(state)
        } else {
            Err("written by another build".into())
        }
    }
}

#[test]
fn a_run_whose_saved_envs_cannot_be_restored_resumes_with_reset_envs() {
    let cfg = AlgoConfig::Ppo(PpoConfig {
        hidden: vec![16],
        horizon: 16,
        minibatch_size: 64,
        ..PpoConfig::default()
    });
    let dir = tmp("unrestorable");
    let opts = |total| RunOptions {
        checkpoint_every: 2,
        ..RunOptions::new(&dir, total)
    };
    let mut env = Limited {
        env: PointReach::new(4),
        saves: true,
        restores: false,
    };
    let first = train(&cfg, &mut env, &opts(4 * 16 * 2), &mut Silent).unwrap();
    assert_eq!(first.envs_reset, None);
    let mut env = Limited {
        env: PointReach::new(4),
        saves: true,
        restores: false,
    };
    let rest = train(&cfg, &mut env, &opts(4 * 16 * 4), &mut Silent).unwrap();
    assert!(rest.resumed && rest.iterations == 4);
    assert_eq!(rest.envs_reset.as_deref(), Some("written by another build"));
    std::fs::remove_dir_all(&dir).unwrap();
}

fn comparable(m: &[Metrics]) -> Vec<Metrics> {
    m.iter()
        .map(|m| Metrics {
            wall_s: 0.0,
            steps_per_s: 0.0,
            ..m.clone()
        })
        .collect()
}

/// Trains `total` steps uninterrupted, and again interrupted after `stop_at` iterations and
/// resumed from the checkpoint by a fresh learner and environment; both must end with
/// bit-identical parameters, learner state and metrics.
///
/// `kill` false: the run is stopped gracefully (it writes a checkpoint at `stop_at`).
/// `kill` true: as if killed (-9) after iteration `stop_at` wrote its metrics line: the
/// folder is left with the last periodic checkpoint, so the resumed run redoes iterations.
#[allow(clippy::too_many_arguments)]
fn resume_matches<E: VecEnvironment>(
    name: &str,
    cfg: &AlgoConfig,
    make: impl Fn() -> E,
    total: u64,
    every: u64,
    stop_at: u64,
    kill: bool,
) {
    let a = tmp(&format!("{name}-a"));
    let b = tmp(&format!("{name}-b"));
    let opts = |dir: &PathBuf| RunOptions {
        checkpoint_every: every,
        ..RunOptions::new(dir, total)
    };
    let full = train(cfg, &mut make(), &opts(&a), &mut Silent).unwrap();
    let mut last_periodic = None;
    let ckpt = b.join("checkpoint.bin");
    let mut stopper = |m: &Metrics| {
        if m.iteration == stop_at {
            last_periodic = std::fs::read(&ckpt).ok();
            Control::Stop
        } else {
            Control::Continue
        }
    };
    let first = train(cfg, &mut make(), &opts(&b), &mut stopper).unwrap();
    assert!(first.stopped && first.iterations == stop_at);
    if kill {
        std::fs::write(
            &ckpt,
            last_periodic.expect("a periodic checkpoint before the kill"),
        )
        .unwrap();
    } else {
        // An unfinished metrics line, as a run killed after writing it would leave: resuming
        // drops it.
        let extra = serde_json::to_string(&Metrics {
            iteration: stop_at + 1,
            ..Default::default()
        })
        .unwrap();
        let text = std::fs::read_to_string(b.join("metrics.jsonl")).unwrap();
        std::fs::write(b.join("metrics.jsonl"), text + &extra + "\n").unwrap();
    }
    let rest = train(cfg, &mut make(), &opts(&b), &mut Silent).unwrap();
    assert!(rest.resumed);
    println!(
        "{name}: uninterrupted {:016x}, resumed at iteration {stop_at} {:016x}",
        full.param_hash, rest.param_hash
    );
    let ma = comparable(&read_metrics(&a.join("metrics.jsonl")).unwrap());
    let mb = comparable(&read_metrics(&b.join("metrics.jsonl")).unwrap());
    for (x, y) in ma.iter().zip(&mb) {
        assert_eq!(x, y, "first differing metrics line");
    }
    assert_eq!(ma.len(), mb.len());
    assert_eq!(full.param_hash, rest.param_hash);
    assert_eq!(full.env_steps, rest.env_steps);
    // Learner state that must match bit for bit (the trained parameters are in the hash;
    // optimiser moments show up in it through the updates after the resume).
    let ca = Checkpoint::load(&a.join("checkpoint.bin")).unwrap();
    let cb = Checkpoint::load(&b.join("checkpoint.bin")).unwrap();
    for section in [
        "rng",
        "obs",
        "ep_ret",
        "ep_len",
        "obs_rms",
        "value_rms",
        "replay.obs",
        "replay.act",
        "replay.rew",
        "replay.next",
        "replay.term",
        "replay.meta",
        "env_state",
    ] {
        if ca.has(section) || cb.has(section) {
            assert_eq!(
                ca.bytes(section).unwrap(),
                cb.bytes(section).unwrap(),
                "section {section}"
            );
        }
    }
    std::fs::remove_dir_all(a).unwrap();
    std::fs::remove_dir_all(b).unwrap();
}

#[test]
fn ppo_resume_is_bit_identical() {
    let cfg = AlgoConfig::Ppo(PpoConfig {
        hidden: vec![32, 32],
        horizon: 16,
        minibatch_size: 64,
        mini_epochs: 3,
        ..PpoConfig::default()
    });
    resume_matches(
        "ppo-resume",
        &cfg,
        || PointReach::new(8),
        8 * 16 * 7,
        2,
        3,
        false,
    );
    resume_matches(
        "ppo-resume-killed",
        &cfg,
        || PointReach::new(8),
        8 * 16 * 7,
        2,
        3,
        true,
    );
    // Environments that cannot save their state are reset at every checkpoint instead.
    resume_matches(
        "ppo-resume-stateless",
        &cfg,
        || Limited {
            env: PointReach::new(8),
            saves: false,
            restores: true,
        },
        8 * 16 * 7,
        2,
        3,
        true,
    );
}

#[test]
fn sac_resume_is_bit_identical() {
    let cfg = AlgoConfig::Sac(SacConfig {
        hidden: vec![32, 32],
        batch_size: 32,
        learning_starts: 100,
        steps_per_iteration: 50,
        ..SacConfig::default()
    });
    resume_matches(
        "sac-resume",
        &cfg,
        || Pendulum::new(2),
        2 * 50 * 5,
        2,
        3,
        false,
    );
    resume_matches(
        "sac-resume-killed",
        &cfg,
        || Pendulum::new(2),
        2 * 50 * 5,
        2,
        3,
        true,
    );
}

#[test]
fn resume_refuses_another_environment_or_configuration() {
    let dir = tmp("refuse");
    let cfg = AlgoConfig::Ppo(PpoConfig {
        hidden: vec![8],
        horizon: 4,
        minibatch_size: 16,
        ..PpoConfig::default()
    });
    train(
        &cfg,
        &mut PointReach::new(4),
        &RunOptions::new(&dir, 32),
        &mut Silent,
    )
    .unwrap();
    let e = train(
        &cfg,
        &mut PointReach::new(3),
        &RunOptions::new(&dir, 64),
        &mut Silent,
    )
    .unwrap_err();
    assert!(format!("{e}").contains("another run"), "{e}");
    let sac = AlgoConfig::Sac(SacConfig::default());
    let e = train(
        &sac,
        &mut PointReach::new(4),
        &RunOptions::new(&dir, 64),
        &mut Silent,
    )
    .unwrap_err();
    assert!(format!("{e}").contains("written by ppo"), "{e}");
    let mut other = cfg.clone();
    other.set_seed(9);
    let e = train(
        &other,
        &mut PointReach::new(4),
        &RunOptions::new(&dir, 64),
        &mut Silent,
    )
    .unwrap_err();
    assert!(format!("{e}").contains("configuration differs"), "{e}");
    let e = train(
        &cfg,
        &mut PointReach::new(4),
        &RunOptions {
            resume: false,
            ..RunOptions::new(&dir, 64)
        },
        &mut Silent,
    )
    .unwrap_err();
    assert!(format!("{e}").contains("already holds a checkpoint"), "{e}");
    // The saved configuration resumes the run.
    let s = train(
        &modesuite_learn::run_config(&dir).unwrap(),
        &mut PointReach::new(4),
        &RunOptions::new(&dir, 64),
        &mut Silent,
    )
    .unwrap();
    assert!(s.resumed && s.env_steps == 64);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn policy_acts_deterministically_and_matches_the_learner() {
    let dir = tmp("policy");
    let cfg = PpoConfig {
        hidden: vec![16, 16],
        horizon: 8,
        minibatch_size: 32,
        ..PpoConfig::default()
    };
    let mut env = PointReach::new(4);
    let mut ppo = modesuite_learn::ppo::Ppo::new(&cfg, &mut env).unwrap();
    let mut opts = RunOptions::new(&dir, 4 * 8 * 3);
    opts.note = "test policy".into();
    modesuite_learn::runner::run(&mut ppo, &mut env, &opts, &mut Silent).unwrap();
    let p = Policy::load(&dir).unwrap();
    assert_eq!(p.meta().note, "test policy");
    assert_eq!((p.obs_dim(), p.act_dim()), (4, 2));
    let obs = [0.5, -0.3, 0.1, 0.0, -1.0, 1.0, 0.0, 0.2];
    let a1 = p.act(&obs);
    assert_eq!(a1, p.act(&obs));
    assert_eq!(a1.len(), 4);
    let direct = ppo.act_deterministic(&obs);
    for (x, y) in a1.iter().zip(&direct) {
        assert!((x - y).abs() < 1e-6, "{a1:?} vs {direct:?}");
    }
    assert!(a1.iter().all(|x| (-1.0..=1.0).contains(x)));
    // The policy folder itself loads too.
    assert_eq!(Policy::load(dir.join("policy")).unwrap().act(&obs), a1);
    std::fs::remove_dir_all(dir).unwrap();
}

/// Rewards of 1e30 overflow an unnormalised value loss: training stops with an error and
/// writes no checkpoint from the poisoned state.
#[test]
fn divergence_is_an_error_not_a_checkpoint() {
    struct Huge(PointReach);
    impl VecEnvironment for Huge {
        fn num_envs(&self) -> usize {
            self.0.num_envs()
        }
        fn obs_dim(&self) -> usize {
            4
        }
        fn act_dim(&self) -> usize {
            2
        }
        fn action_bounds(&self) -> (Vec<f32>, Vec<f32>) {
            self.0.action_bounds()
        }
        fn identity(&self) -> String {
            "huge".into()
        }
        fn reset(&mut self, seed: u64) -> Result<Vec<f32>, String> {
            self.0.reset(seed)
        }
        fn step(&mut self, actions: &[f32]) -> Result<modesuite_learn::BatchStep, String> {
            let mut s = self.0.step(actions)?;
            s.rewards.iter_mut().for_each(|r| *r = 1e30);
            Ok(s)
        }
    }
    let dir = tmp("diverge");
    let cfg = AlgoConfig::Ppo(PpoConfig {
        hidden: vec![8],
        horizon: 4,
        minibatch_size: 16,
        normalize_value: false,
        ..PpoConfig::default()
    });
    let e = train(
        &cfg,
        &mut Huge(PointReach::new(4)),
        &RunOptions::new(&dir, 64),
        &mut Silent,
    )
    .unwrap_err();
    assert!(matches!(e, modesuite_learn::LearnError::Diverged(_)), "{e}");
    assert!(!dir.join("checkpoint.bin").exists());
    std::fs::remove_dir_all(dir).unwrap();
}

/// The two learning tests' settings on other seeds (not run in CI: about 1.5 minutes).
#[test]
#[ignore]
fn learning_on_other_seeds() {
    for seed in [2, 3, 4] {
        let dir = tmp(&format!("ppo-seed-{seed}"));
        let mut opts = RunOptions::new(&dir, 120_000);
        opts.checkpoint_every = 0;
        train(
            &ppo_reach(seed),
            &mut PointReach::new(16),
            &opts,
            &mut Silent,
        )
        .unwrap();
        let p = Policy::load(&dir).unwrap();
        let e = evaluate(&mut PointReach::new(16), 200, 10_000, |o| p.act(o)).unwrap();
        println!(
            "ppo reach seed {seed}: success {:.3} (threshold 0.95), return {:.3} (threshold -12.910)",
            e.success_rate().unwrap(),
            e.return_mean()
        );
        assert!(e.success_rate().unwrap() >= 0.95 && e.return_mean() >= -12.91);
        std::fs::remove_dir_all(dir).unwrap();
    }
    for seed in [4, 5, 6] {
        let dir = tmp(&format!("sac-seed-{seed}"));
        let mut opts = RunOptions::new(&dir, 12_000);
        opts.checkpoint_every = 0;
        train(
            &sac_pendulum(seed),
            &mut Pendulum::new(1),
            &opts,
            &mut Silent,
        )
        .unwrap();
        let p = Policy::load(&dir).unwrap();
        let e = evaluate(&mut Pendulum::new(4), 20, 20_000, |o| p.act(o)).unwrap();
        println!(
            "sac pendulum seed {seed}: return {:.1} (threshold -250)",
            e.return_mean()
        );
        assert!(e.return_mean() >= -250.0);
        std::fs::remove_dir_all(dir).unwrap();
    }
}

/// An environment error ends training with that error; the last checkpoint stays as it was.
#[test]
fn environment_errors_end_training() {
    struct Failing(PointReach, u32);
    impl VecEnvironment for Failing {
        fn num_envs(&self) -> usize {
            self.0.num_envs()
        }
        fn obs_dim(&self) -> usize {
            4
        }
        fn act_dim(&self) -> usize {
            2
        }
        fn action_bounds(&self) -> (Vec<f32>, Vec<f32>) {
            self.0.action_bounds()
        }
        fn identity(&self) -> String {
            "failing".into()
        }
        fn reset(&mut self, seed: u64) -> Result<Vec<f32>, String> {
            self.0.reset(seed)
        }
        fn step(&mut self, actions: &[f32]) -> Result<modesuite_learn::BatchStep, String> {
            self.1 += 1;
            if self.1 == 30 {
                return Err("the simulator failed".into());
            }
            self.0.step(actions)
        }
    }
    let dir = tmp("env-error");
    let cfg = AlgoConfig::Ppo(PpoConfig {
        hidden: vec![8],
        horizon: 4,
        minibatch_size: 16,
        ..PpoConfig::default()
    });
    let mut opts = RunOptions::new(&dir, 1000);
    opts.checkpoint_every = 2;
    let e = train(
        &cfg,
        &mut Failing(PointReach::new(4), 0),
        &opts,
        &mut Silent,
    )
    .unwrap_err();
    assert!(format!("{e}").contains("the simulator failed"), "{e}");
    // Iterations 1-7 stepped 28 times; the checkpoint of iteration 6 is the last one.
    let c = Checkpoint::load(&dir.join("checkpoint.bin")).unwrap();
    assert_eq!(c.u64s("counters").unwrap()[0], 6);
    std::fs::remove_dir_all(dir).unwrap();
}
