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

fn train(data: &Path, out: &Path) -> String {
    ok(cli(&[
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
    ]))
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
    let log = train(&data, &a);
    println!("{log}");
    let run = ok(cli(&[
        "run",
        TASK,
        "--policy",
        a.to_str().unwrap(),
        "--seed",
        "7",
        "--json",
    ]));
    let summary: serde_json::Value = serde_json::from_str(run.lines().last().unwrap()).unwrap();
    let episode: serde_json::Value = serde_json::from_str(run.lines().next().unwrap()).unwrap();
    println!("BC policy from the demonstration's seed: {episode}");
    assert_eq!(summary["success_rate"], 1.0, "{run}");
    // the same seed trains the same weights
    let b = scratch("b");
    train(&data, &b);
    // (compared by what they do: weight files hold burn's random parameter ids)
    let returns = |dir: &Path| -> Vec<String> {
        let run = ok(cli(&[
            "run",
            TASK,
            "--policy",
            dir.to_str().unwrap(),
            "--seed",
            "8",
            "--episodes",
            "2",
            "--json",
        ]));
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
    println!(
        "{}",
        ok(cli(&[
            "train",
            TASK,
            "--algo",
            "retrieval",
            "--dataset",
            data.to_str().unwrap(),
            "--out",
            r.to_str().unwrap()
        ]))
    );
    let run = ok(cli(&[
        "run",
        TASK,
        "--policy",
        r.to_str().unwrap(),
        "--seed",
        "7",
        "--json",
    ]));
    let replayed: serde_json::Value = serde_json::from_str(run.lines().next().unwrap()).unwrap();
    println!("retrieval from the demonstration's seed: {replayed}");
    assert_eq!(
        replayed["return"], recorded["return"],
        "{replayed} vs {recorded}"
    );
    assert_eq!(replayed["success"], true);
    for d in [data, a, b, r] {
        let _ = std::fs::remove_dir_all(d);
    }
}
