//! Tests of `modesuite train`, `eval` and `plot` on a simulator task (the learners themselves
//! are tested in `learn/`).

use std::path::{Path, PathBuf};
mod common;

use common::{modesuite_cmd as modesuite, stdout_ok};

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("modesuite-learn-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    let _ = std::fs::remove_dir_all(&p);
    p
}

/// `train` of Franka Place into `dir` with `envs` envs for `steps` env steps and `extra` flags.
fn train(dir: &Path, envs: &str, steps: &str, extra: &[&str]) -> String {
    stdout_ok(
        modesuite()
            .args([
                "train",
                "MoDe-Franka-Place-v0",
                "--envs",
                envs,
                "--env-steps",
                steps,
            ])
            .args(extra)
            .arg("--out")
            .arg(dir),
    )
}

/// The short runs' settings: small rollouts, a checkpoint every two iterations.
const SHORT: &[&str] = &["--set", "horizon=16", "--checkpoint-every", "2"];

fn lines(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn train_resume_eval_and_plot_a_task() {
    let dir = tmp("place");
    let out = train(&dir, "4", "128", SHORT);
    assert!(out.contains("done: 2 iterations, 128 env steps"), "{out}");
    for f in [
        "config.ron",
        "metrics.jsonl",
        "checkpoint.bin",
        "policy/policy.json",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    let first = lines(&dir.join("metrics.jsonl"));
    assert_eq!(first.len(), 2);
    // the same command with more steps continues the run
    let out = train(&dir, "4", "256", SHORT);
    assert!(
        out.contains("(resumed)") && out.contains("4 iterations"),
        "{out}"
    );
    let all = lines(&dir.join("metrics.jsonl"));
    assert_eq!(all.len(), 4);
    assert_eq!(all[..2], first[..]);
    // a fresh run of 256 steps with the same seed ends with the same metrics (one process,
    // the learner's order of operations is fixed)
    let straight = tmp("straight");
    train(&straight, "4", "256", SHORT);
    let s = lines(&straight.join("metrics.jsonl"));
    for (a, b) in s.iter().zip(&all) {
        assert_eq!(a["actor_loss"], b["actor_loss"]);
        assert_eq!(a["critic_loss"], b["critic_loss"]);
    }
    // another configuration is not resumed into this folder
    let out = modesuite()
        .args([
            "train",
            "MoDe-Franka-Place-v0",
            "--envs",
            "4",
            "--env-steps",
            "512",
        ])
        .args(["--set", "horizon=8", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("another run"), "{stderr}");

    // eval prints run --json's keys, on seeds far from training's
    let text = stdout_ok(
        modesuite()
            .args(["eval"])
            .arg(&dir)
            .args(["--episodes", "1", "--json"]),
    );
    let objs: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(objs[0]["seed"], 1_000_000);
    for key in [
        "episode",
        "return",
        "length",
        "success",
        "error",
        "ended",
        "terminations",
    ] {
        assert!(objs[0].get(key).is_some(), "{key} missing: {}", objs[0]);
    }
    let summary = &objs[1];
    assert_eq!(summary["summary"], true);
    assert_eq!(summary["target"], "MoDe-Franka-Place-v0");
    assert!(summary["success_rate"].is_number());
    // run --policy DIR acts with the same policy
    let run = stdout_ok(
        modesuite()
            .args([
                "run",
                "MoDe-Franka-Place-v0",
                "--steps",
                "5",
                "--json",
                "--seed",
                "1000000",
                "--policy",
            ])
            .arg(dir.join("policy")),
    );
    let r: serde_json::Value = serde_json::from_str(run.lines().next().unwrap()).unwrap();
    assert_eq!(r["length"], 5);

    // plot of a run with finished episodes: a PNG of the stated size
    let long = tmp("long");
    train(
        &long,
        "2",
        "1280",
        &["--set", "horizon=64", "--set", "hidden=[16]"],
    );
    assert!(lines(&long.join("metrics.jsonl"))
        .iter()
        .any(|m| m["return_mean"].is_number()));
    // held-out evaluations as scripts/results.py appends them are drawn on the success panel
    std::fs::write(
        long.join("evals.jsonl"),
        "{\"env_steps\": 640, \"success_rate\": 0.5, \"errors\": 0}\n",
    )
    .unwrap();
    let png = long.join("curves.png");
    stdout_ok(
        modesuite()
            .args(["plot"])
            .arg(&long)
            .arg(&long)
            .arg("--out")
            .arg(&png),
    );
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[1..4], b"PNG");
    // width and height in the IHDR chunk
    assert_eq!(u32::from_be_bytes(bytes[16..20].try_into().unwrap()), 1200);
    assert_eq!(u32::from_be_bytes(bytes[20..24].try_into().unwrap()), 480);
}

#[test]
fn checkpoints_continue_the_episodes_under_way() {
    // a checkpoint every 16 env steps: before the envs' states went into the checkpoint, each
    // one reset the envs and no training episode outlived it
    let dir = tmp("continue");
    train(
        &dir,
        "1",
        "640",
        &[
            "--set",
            "horizon=16",
            "--set",
            "hidden=[16]",
            "--checkpoint-every",
            "1",
        ],
    );
    let longest = lines(&dir.join("metrics.jsonl"))
        .iter()
        .filter_map(|m| m["length_mean"].as_f64())
        .fold(0.0, f64::max);
    println!("longest training episode {longest} steps across checkpoints every 16 steps (> 16)");
    assert!(longest > 16.0, "{longest}");
}

#[test]
fn bad_learning_input_is_a_clear_error() {
    let cases: [(&[&str], &str); 5] = [
        (
            &["train", "MoDe-Franka-Place-v0", "--algo", "dqn", "--out"],
            "ppo or sac",
        ),
        (
            &["train", "MoDe-Franka-Place-v0", "--set", "nope=1", "--out"],
            "valid: ",
        ),
        (
            &["train", "MoDe-Franka-Place-v0", "--set", "gamma=2", "--out"],
            "gamma",
        ),
        (
            &[
                "train",
                "MoDe-Franka-Place-v0",
                "--actions",
                "(discrete: true)",
                "--out",
            ],
            "Discrete",
        ),
        (&["eval"], "not a policy folder"),
    ];
    for (args, expected) in cases {
        let out = modesuite().args(args).arg(tmp("bad")).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
}

#[test]
fn an_episode_ended_by_an_error_is_a_cut_that_bootstraps_from_the_state_before_or_a_penalised_end()
{
    use modesuite::learn::VecEnvironment;
    // two Franka Place envs on one thread, failures ending as `penalty` says
    let sim_env = |penalty: Option<f32>| {
        let vec = modesuite::make::make_vec(
            "MoDe-Franka-Place-v0",
            &modesuite::make::MakeOptions::default(),
            2,
            1,
        )
        .unwrap();
        modesuite::learning::SimEnv::new(vec, "MoDe-Franka-Place-v0", None)
            .unwrap()
            .with_error_penalty(penalty)
    };
    let mut env = sim_env(None);
    env.reset(0).unwrap();
    let zero = vec![0.0f32; 2 * env.act_dim()];
    let s1 = env.step(&zero).unwrap();
    let mut bad = zero.clone();
    bad[0] = f32::NAN;
    let s2 = env.step(&bad).unwrap();
    assert_eq!((s2.terminated[0], s2.truncated[0]), (false, true));
    assert_eq!((s2.terminated[1], s2.truncated[1]), (false, false));
    let dim = env.obs_dim();
    assert_eq!(s2.final_obs[0].as_deref(), Some(&s1.obs[..dim]));
    assert!(s2.final_obs[1].is_none());
    assert!(s2.obs.iter().all(|v| v.is_finite()));
    assert_eq!(s2.rewards[0], 0.0);

    // with an error penalty (the learners' `error_penalty`) the failure is terminal and costs it
    let mut env = sim_env(Some(-250.0));
    env.reset(0).unwrap();
    let p1 = env.step(&zero).unwrap();
    assert_eq!(p1.obs, s1.obs);
    let p2 = env.step(&bad).unwrap();
    assert_eq!((p2.terminated[0], p2.truncated[0]), (true, false));
    assert_eq!((p2.terminated[1], p2.truncated[1]), (false, false));
    assert_eq!((p2.rewards[0], p2.rewards[1]), (-250.0, s2.rewards[1]));
    assert_eq!(p2.final_obs[0].as_deref(), Some(&s1.obs[..dim]));
}

#[test]
fn a_failure_penalty_is_added_to_the_step_on_which_the_task_ends_an_episode_as_failed() {
    use modesuite::learn::VecEnvironment;
    // Franka Lift driving forward: the belt it holds reaches the base's hull box, a
    // termination term (`belt_on_body`), which ends the episode as failed
    let run = |penalty: Option<f32>| {
        let vec = modesuite::make::make_vec(
            "MoDe-Franka-Lift-v0",
            &modesuite::make::MakeOptions::default(),
            1,
            1,
        )
        .unwrap();
        let mut env = modesuite::learning::SimEnv::new(vec, "MoDe-Franka-Lift-v0", None)
            .unwrap()
            .with_failure_penalty(penalty);
        env.reset(0).unwrap();
        let mut forward = vec![0.0f32; env.act_dim()];
        forward[0] = 1.0;
        let mut rewards = Vec::new();
        for _ in 0..200 {
            let s = env.step(&forward).unwrap();
            rewards.push(s.rewards[0]);
            if s.terminated[0] || s.truncated[0] {
                assert_eq!((s.terminated[0], s.success[0]), (true, Some(false)));
                return rewards;
            }
        }
        panic!("driving into the belt did not end the episode in 200 steps");
    };
    let plain = run(None);
    let penalised = run(Some(-300.0));
    let n = plain.len();
    println!(
        "Franka Lift driving forward fails at step {n}; last reward {} -> {} with the penalty",
        plain[n - 1],
        penalised[n - 1]
    );
    assert_eq!(penalised.len(), n);
    assert_eq!(penalised[..n - 1], plain[..n - 1]);
    assert_eq!(penalised[n - 1], plain[n - 1] - 300.0);
}
