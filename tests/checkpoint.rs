//! State files (`run --save-state` / `--load-state`, `Env::save_state` / `load_state`): a saved
//! state continued in a fresh env (or a new process) gives the same steps, bit for bit, as the
//! run that was never interrupted; files of another scene, or damaged files, are refused and
//! leave the env as it was.

mod common;

use common::{modesuite_cmd as modesuite, stdout_ok};
use modesuite::engine::checkpoint::StateError;
use modesuite::make::{make, MakeOptions};
use modesuite::prelude::*;

fn env(target: &str) -> Env {
    make(target, &MakeOptions::default()).unwrap_or_else(|e| panic!("{target}: {e}"))
}

/// A varied, deterministic action: every component sweeps its range at its own rate.
fn action(env: &Env, t: usize) -> Vec<f32> {
    let dim = env.spaces().action.flat_dim();
    (0..dim)
        .map(|k| (0.8 * ((t as f64) * 0.07 + k as f64 * 1.3).sin()) as f32)
        .collect()
}

/// (observation bits, reward bits, terminated, truncated, state hash) of every step.
type Trace = Vec<(Vec<u32>, u64, bool, bool, u64)>;

fn run(env: &mut Env, from: usize, steps: usize) -> Trace {
    (from..from + steps)
        .map(|t| {
            let a = action(env, t);
            let o = env.step(&a);
            (
                o.observation.iter().map(|x| x.to_bits()).collect(),
                o.reward.to_bits(),
                o.terminated,
                o.truncated,
                env.state_hash(),
            )
        })
        .collect()
}

/// 100 steps, save; 100 more steps straight on; then a fresh env loads the file and takes the
/// same 100 steps: the two traces are identical.
fn round_trip(target: &str) {
    let mut a = env(target);
    a.reset(Some(7));
    let first = run(&mut a, 0, 100);
    let bytes = a.save_state().unwrap();
    let hash_at_save = a.state_hash();
    let straight = run(&mut a, 100, 100);

    let mut b = env(target);
    b.reset(Some(123)); // another episode entirely: the load replaces all of it
    b.load_state(&bytes)
        .unwrap_or_else(|e| panic!("{target}: {e}"));
    assert_eq!(b.state_hash(), hash_at_save, "{target}: hash after load");
    let resumed = run(&mut b, 100, 100);
    let first_diff = straight.iter().zip(&resumed).position(|(x, y)| x != y);
    println!(
        "{target}: state file {} kB, 100 + 100 steps, first differing step: {first_diff:?} (want None); errors in the run: {}",
        bytes.len() / 1024,
        first.iter().chain(&straight).filter(|s| s.3).count()
    );
    assert_eq!(first_diff, None, "{target}: resumed run differs");
}

#[test]
fn franka_fem_task_continues_bit_exactly_from_a_state_file() {
    round_trip("MoDe-Franka-Bend-v0");
}

#[test]
fn spot_cloth_task_continues_bit_exactly_from_a_state_file() {
    round_trip("MoDe-Spot-Cover-v0");
}

#[test]
fn franka_cloth_task_continues_bit_exactly_from_a_state_file() {
    round_trip("MoDe-Franka-Uncover-v0");
}

#[test]
fn spot_fem_task_continues_bit_exactly_from_a_state_file() {
    round_trip("MoDe-Spot-Transport-v0");
}

#[test]
fn fem_task_with_penalty_contacts_continues_bit_exactly_from_a_state_file() {
    // the belt's penalty contacts: their lagged friction lives in the contact memory, and the
    // factor holding their Hessians is rebuilt from the state after a load
    round_trip("MoDe-Spot-Drag-v0");
}

#[test]
fn rigid_contacts_continue_bit_exactly_from_a_state_file() {
    // boxes tumbling onto each other and the ground: contact manifolds and warm starts
    round_trip("scenes/examples/drop.scene.ron");
}

#[test]
fn a_file_of_another_scene_or_a_damaged_file_is_refused_and_changes_nothing() {
    let mut bend = env("MoDe-Franka-Bend-v0");
    bend.reset(Some(1));
    run(&mut bend, 0, 5);
    let bytes = bend.save_state().unwrap();

    let mut place = env("MoDe-Franka-Place-v0");
    place.reset(Some(2));
    run(&mut place, 0, 3);
    let before = place.state_hash();
    let obs = place.observation();
    let refused = |e: &StateError| e.to_string();

    let e = place.load_state(&bytes).unwrap_err();
    println!("another scene: {}", refused(&e));
    assert!(matches!(e, StateError::Foreign(_)), "{e}");
    assert!(e.to_string().contains("scene"), "{e}");

    let mut flipped = bytes.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0x10;
    let e = bend.load_state(&flipped).unwrap_err();
    println!("one bit flipped: {}", refused(&e));
    assert!(matches!(e, StateError::Corrupt(_)), "{e}");

    let e = bend.load_state(&bytes[..bytes.len() - 100]).unwrap_err();
    println!("truncated: {}", refused(&e));
    assert!(matches!(e, StateError::Corrupt(_)), "{e}");

    let e = bend
        .load_state(b"{\"format\": \"modesuite.state.v1\"}")
        .unwrap_err();
    println!("a JSON dump: {}", refused(&e));
    assert!(matches!(e, StateError::NotAStateFile), "{e}");

    let mut other_version = bytes.clone();
    other_version[16] = 99;
    let e = bend.load_state(&other_version).unwrap_err();
    println!("another version: {}", refused(&e));
    assert!(matches!(e, StateError::Version { found: 99, .. }), "{e}");

    assert_eq!(place.state_hash(), before, "a refused load changed the env");
    assert_eq!(place.observation(), obs);
}

fn tmp(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("modesuite-ckpt-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn dump_without_length(path: &std::path::Path) -> serde_json::Value {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    // the episode length counts this run's steps; the state itself must be equal
    v.as_object_mut().unwrap().remove("episode_length");
    v
}

/// The proof through the CLI: 100 steps and `--save-state`, then `--load-state` and
/// 100 steps in a new process, ends in the state of 200 straight steps.
fn cli_round_trip(target: &str, policy: &str) {
    let tag = target.replace(['/', '.'], "_");
    let state = tmp(&format!("{tag}.state"));
    let straight = tmp(&format!("{tag}-200.json"));
    let resumed = tmp(&format!("{tag}-100-100.json"));
    let run = |steps: &str| {
        let mut c = modesuite();
        c.args([
            "run", target, "--seed", "5", "--policy", policy, "--steps", steps,
        ]);
        c
    };
    stdout_ok(run("200").arg("--dump-state").arg(&straight));
    stdout_ok(run("100").arg("--save-state").arg(&state));
    stdout_ok(
        run("100")
            .arg("--load-state")
            .arg(&state)
            .arg("--dump-state")
            .arg(&resumed),
    );
    let (a, b) = (
        dump_without_length(&straight),
        dump_without_length(&resumed),
    );
    println!(
        "{target} --policy {policy}: state file {} kB; 200 straight == 100 + 100 resumed: {}",
        std::fs::metadata(&state).unwrap().len() / 1024,
        a == b
    );
    assert_eq!(a["step"], 200);
    assert_eq!(a, b, "{target}: the resumed run's final state differs");
}

#[test]
fn cli_save_and_load_state_continue_a_franka_fem_episode_in_a_new_process() {
    // (the library tests above drive the robots with varied actions; the CLI's stateless
    // policies are zero and trained ones, and the shipped trained policy ends Place before
    // step 100 by succeeding)
    cli_round_trip("MoDe-Franka-Bend-v0", "zero");
}

#[test]
fn cli_save_and_load_state_continue_a_spot_cloth_episode_in_a_new_process() {
    cli_round_trip("MoDe-Spot-Cover-v0", "zero");
}

#[test]
fn cli_refuses_a_state_file_of_another_task_with_a_clear_error() {
    let state = tmp("bend.state");
    stdout_ok(
        modesuite()
            .args(["run", "MoDe-Franka-Bend-v0", "--steps", "2", "--save-state"])
            .arg(&state),
    );
    let out = modesuite()
        .args(["run", "MoDe-Franka-Lift-v0", "--steps", "2", "--load-state"])
        .arg(&state)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    println!("exit {:?}: {err}", out.status.code());
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--load-state") && err.contains("another env"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}

/// Damaged bodies that pass the checksum (it is recomputed after each change, as a careless
/// tool would write them) never panic: each load either fails with a reason and leaves the env
/// unchanged, or decodes to a state whose hash matches the recorded one (a change in bytes the
/// hash does not cover, such as collider data). The checksum is what guards against damage.
#[test]
fn corrupted_state_bodies_with_a_valid_checksum_never_panic() {
    let mut env = env("MoDe-Franka-Bend-v0");
    env.reset(Some(1));
    run(&mut env, 0, 10);
    let bytes = env.save_state().unwrap();
    let before = env.state_hash();
    let mut rng = modesuite::engine::rng::EnvRng::from_seed(42);
    let (mut refused, mut accepted) = (0, 0);
    for _ in 0..300 {
        let mut b = bytes.clone();
        let body = 20..b.len() - 8;
        let at = body.start + (rng.next_u64() as usize) % body.len();
        b[at] = (rng.next_u64() & 0xff) as u8;
        let n = b.len() - 8;
        let mut h = modesuite::engine::state::StateHasher::default();
        h.write_bytes(&b[..n]);
        let sum = h.finish().to_le_bytes();
        b[n..].copy_from_slice(&sum);
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| env.load_state(&b)));
        match r {
            Ok(Ok(())) => {
                accepted += 1;
                // An accepted state steps (or ends its episode with an error) without panicking
                // or hanging, and returns finite values.
                for _ in 0..4 {
                    let o = env.step(&vec![0.0; env.spaces().action.flat_dim()]);
                    assert!(o.observation.iter().all(|x| x.is_finite()) && o.reward.is_finite());
                }
            }
            Ok(Err(_)) => {
                refused += 1;
                assert_eq!(env.state_hash(), before, "a refused load changed the env");
            }
            Err(_) => panic!("load_state panicked on a byte changed at {at}"),
        }
        // back to the saved state for the next case
        env.load_state(&bytes).unwrap();
    }
    println!("300 one-byte corruptions with valid checksums: {refused} refused, {accepted} loaded (a byte that changed nothing, or a value the hash does not cover) and stepped 4 times, 0 panics");
}
