//! The CI tier of the fuzzers (`modesuite fuzz` runs longer campaigns): every target's seed
//! corpus, its committed regression inputs (`fuzz/regressions/<target>/`) and a fixed number of
//! mutants (same seed, same inputs), with no panic and no hang allowed; and random actions on
//! the 16 tasks with nothing non-finite returned. Counts are printed beside the limits.

use std::time::Duration;

use modesuite::fuzz::{run_campaign, target, Campaign};

/// Runs `iterations` mutants of `name` after its corpus and regressions; no input may panic.
fn tier(name: &str, iterations: u64) {
    let t = target(name).expect("target");
    let c = Campaign {
        iterations,
        seed: 20261127,
        time_limit: None,
        hang_limit: Duration::from_secs(120),
        out: None,
    };
    let r = run_campaign(t, &c, &mut |_| {});
    println!("fuzz {} (panics allowed: 0)", r.line());
    assert!(r.panics.is_empty(), "{name}: panics {:?}", r.panics);
    assert!(r.tried > iterations, "{name}: the corpus ran");
    assert!(
        r.accepted > 0,
        "{name}: no input was accepted (a broken corpus)"
    );
}

#[test]
fn fuzz_meshes() {
    for name in ["obj", "stl", "msh", "medit"] {
        tier(name, 10_000);
    }
}

#[test]
fn fuzz_urdf() {
    tier("urdf", 5000);
}

#[test]
fn fuzz_scene() {
    tier("scene", 400);
}

#[test]
fn fuzz_task() {
    tier("task", 3000);
}

#[test]
fn fuzz_robot() {
    tier("robot", 2000);
}

#[test]
fn fuzz_actions() {
    tier("actions", 2000);
}

#[test]
fn fuzz_state() {
    tier("state", 2000);
}

#[test]
fn fuzz_state_body() {
    tier("state_body", 2000);
}

#[test]
fn fuzz_generated_scenes() {
    tier("generated", 24);
}

#[test]
fn fuzz_tasks_random_and_bang_bang_actions() {
    tier("tasks", 4);
}

#[test]
fn fuzz_training_checkpoints() {
    tier("checkpoint", 200);
    tier("checkpoint_body", 200);
}

#[test]
fn fuzz_policies() {
    tier("policy", 1000);
}
