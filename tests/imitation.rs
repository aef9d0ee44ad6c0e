//! Behaviour cloning and retrieval from a recorded dataset (issue 31, point 4): a policy trained
//! on one expert demonstration overfits it closely enough to replay it successfully from its
//! seed, retrieval replays it exactly, and
//! the training is deterministic for a seed (the two policies act identically, bit for bit).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_modesuite")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("modesuite-bc-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn ok(o: Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "exit {:?}: {err}", o.status.code());
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn cli(args: &[&str]) -> Output {
    Command::new(bin()).args(args).output().unwrap()
}

const TASK: &str = "MoDe-Franka-Place-v0";

/// Behaviour cloning of Franka Place on `data` into `out` (seed 1, 1,500 epochs), with `extra`
/// arguments.
fn train(data: &Path, out: &Path, extra: &[&str]) -> String {
    ok(train_cmd(data, out, extra))
}

/// [`train`]'s command, its output unchecked.
fn train_cmd(data: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "train",
        TASK,
        "--algo",
        "bc",
        "--dataset",
        data.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--seed",
        "1",
        "--set",
        "epochs=1500",
    ];
    args.extend_from_slice(extra);
    cli(&args)
}

/// `modesuite run TASK --policy DIR` with `extra` arguments: its output.
fn run_policy(dir: &Path, extra: &[&str]) -> String {
    let mut args = vec!["run", TASK, "--policy", dir.to_str().unwrap()];
    args.extend_from_slice(extra);
    ok(cli(&args))
}

/// Runs the policy folder `dir` on `TASK` from seed 7 (the demonstration's) and checks that
/// the episode succeeds.
fn succeeds_from_seed_7(dir: &Path, label: &str) {
    let run = run_policy(dir, &["--seed", "7", "--json"]);
    let summary: serde_json::Value = serde_json::from_str(run.lines().last().unwrap()).unwrap();
    println!(
        "{label} from the demonstration's seed: {}",
        run.lines().next().unwrap()
    );
    assert_eq!(summary["success_rate"], 1.0, "{run}");
}

/// Trains a retrieval policy of `task` on `data` into `out` with `extra` arguments and runs it
/// for one episode from `seed`: the training's output and the episode's JSON object.
fn retrieval_run(
    task: &str,
    data: &Path,
    out: &Path,
    extra: &[&str],
    seed: &str,
) -> (String, serde_json::Value) {
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    let mut args = vec![
        "train",
        task,
        "--algo",
        "retrieval",
        "--dataset",
        d,
        "--out",
        o,
    ];
    args.extend_from_slice(extra);
    let trained = ok(cli(&args));
    let run = ok(cli(&["run", task, "--policy", o, "--seed", seed, "--json"]));
    let episode = serde_json::from_str(run.lines().next().unwrap()).unwrap();
    (trained, episode)
}

#[test]
fn bc_overfits_one_demonstration_and_replays_it() {
    let data = scratch("data");
    let rec = ok(cli(&[
        "record",
        TASK,
        "--episodes",
        "1",
        "--seed",
        "7",
        "--json",
        "--out",
        data.to_str().unwrap(),
    ]));
    let recorded: serde_json::Value = serde_json::from_str(rec.trim()).unwrap();
    let a = scratch("a");
    let log = train(&data, &a, &[]);
    println!("{log}");
    succeeds_from_seed_7(&a, "BC policy");
    // the same seed trains the same weights
    let b = scratch("b");
    train(&data, &b, &[]);
    // (compared by what they do: weight files hold burn's random parameter ids)
    let returns = |dir: &Path| -> Vec<String> {
        let run = run_policy(dir, &["--seed", "8", "--episodes", "2", "--json"]);
        run.lines()
            .map(|l| {
                let v: serde_json::Value = serde_json::from_str(l).unwrap();
                format!("{} {} {}", v["return"], v["length"], v["mean_return"])
            })
            .collect()
    };
    let (ra, rb) = (returns(&a), returns(&b));
    println!("seed 8 with two BC runs of seed 1: {ra:?}");
    assert_eq!(ra, rb, "two BC runs with seed 1 act differently");
    // a dataset of another task is refused
    let o = cli(&[
        "train",
        "MoDe-Spot-Place-v0",
        "--algo",
        "bc",
        "--dataset",
        data.to_str().unwrap(),
        "--out",
        b.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("recorded on"), "{err}");
    // retrieval (k = 1) replays the demonstration exactly: the same return, bit for bit
    let r = scratch("r");
    let (trained, replayed) = retrieval_run(TASK, &data, &r, &[], "7");
    println!("{trained}retrieval from the demonstration's seed: {replayed}");
    assert_eq!(
        replayed["return"], recorded["return"],
        "{replayed} vs {recorded}"
    );
    assert_eq!(replayed["success"], true);
    // replaying 5 actions of the matched demonstration per look reproduces it too
    let h = scratch("h");
    let (_, chunked) = retrieval_run(TASK, &data, &h, &["--set", "horizon=5"], "7");
    println!("retrieval with horizon 5: {chunked}");
    assert_eq!(chunked["return"], recorded["return"]);
    // and looking at every step, the segments retrieved for each step ensembled: still exact
    let he = scratch("he");
    let (_, ens) = retrieval_run(
        TASK,
        &data,
        &he,
        &["--set", "horizon=5", "--set", "ensemble=0.01"],
        "7",
    );
    println!("retrieval with horizon 5, ensembled: {ens}");
    assert_eq!(ens["return"], recorded["return"]);
    // BC with action chunks (5 actions per look, played before the next look) overfits it too,
    // and so it does acting with ACT's temporal ensembling (observing every step, the chunks'
    // predictions for each step averaged)
    let (c, e) = (scratch("c"), scratch("e"));
    for (dir, set, label) in [
        (&c, &["--set", "chunk=5"][..], "BC with chunks of 5"),
        (
            &e,
            &["--set", "chunk=5", "--set", "ensemble=0.01"][..],
            "BC with chunks of 5, ensembled,",
        ),
    ] {
        train(&data, dir, set);
        succeeds_from_seed_7(dir, label);
    }
    // an ensemble without chunks is refused, naming the field
    let o = train_cmd(&data, &e, &["--set", "ensemble=0.01"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("ensemble = 0.01 (chunk 1)"), "{err}");
    for d in [data, a, b, r, h, he, c, e] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// Image inputs: a recording with the robot camera's pooled features cached per frame; a
/// retrieval policy on the features alone renders and encodes its camera when it acts and, from
/// the demonstration's seed, finds each recorded frame again (distance 0) and replays the
/// demonstration exactly. A feature policy on a dataset without features is refused.
#[test]
fn retrieval_on_image_features_replays_its_demonstration() {
    let task = "MoDe-Spot-Uncover-v0";
    let data = scratch("img-data");
    let rec = ok(cli(&[
        "record",
        task,
        "--episodes",
        "1",
        "--seed",
        "11",
        "--cameras",
        "robot",
        "--encoder",
        "pooled",
        "--json",
        "--out",
        data.to_str().unwrap(),
    ]));
    let recorded: serde_json::Value = serde_json::from_str(rec.lines().next().unwrap()).unwrap();
    println!("recorded: {recorded}");
    assert_eq!(recorded["success"], true);
    let info = ok(cli(&["dataset", "info", data.to_str().unwrap(), "--json"]));
    assert!(info.contains("observation.features.pooled"), "{info}");
    let r = scratch("img-r");
    let (trained, replayed) = retrieval_run(task, &data, &r, &["--inputs", "features"], "11");
    println!("{trained}");
    assert!(
        trained.contains("features (pooled of camera robot)"),
        "{trained}"
    );
    println!("retrieval on image features from the demonstration's seed: {replayed}");
    assert_eq!(replayed["length"], recorded["length"]);
    assert_eq!(replayed["return"], recorded["return"]);
    assert_eq!(replayed["success"], true);
    // a dataset without features cannot train a feature policy
    let plain = scratch("img-plain");
    ok(cli(&[
        "record",
        task,
        "--episodes",
        "1",
        "--steps",
        "5",
        "--out",
        plain.to_str().unwrap(),
    ]));
    let o = cli(&[
        "train",
        task,
        "--algo",
        "bc",
        "--inputs",
        "features",
        "--dataset",
        plain.to_str().unwrap(),
        "--out",
        r.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("no image features"), "{err}");
    for d in [data, r, plain] {
        let _ = std::fs::remove_dir_all(d);
    }
}
