//! `modesuite record` and `dataset info|replay` (issue 31, points 1 and 2): recorded episodes
//! re-simulate bit for bit, action noise varies them, a recording killed with SIGKILL at any
//! moment leaves a dataset that loads with the episodes committed before the kill and continues
//! with the same command, and a full disk ends with a clear error and a loadable dataset.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_modesuite")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("modesuite-dataset-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn cli(args: &[&str]) -> Output {
    Command::new(bin()).args(args).output().unwrap()
}

fn ok(o: Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "exit {:?}: {err}", o.status.code());
    String::from_utf8_lossy(&o.stdout).into_owned()
}

const TASK: &str = "MoDe-Franka-Place-v0";

fn info(dir: &Path) -> serde_json::Value {
    let out = ok(cli(&["dataset", "info", dir.to_str().unwrap(), "--json"]));
    serde_json::from_str(out.trim()).unwrap()
}

fn record(dir: &Path, episodes: u32, noise: &str) -> Vec<String> {
    let e = episodes.to_string();
    let out = ok(cli(&[
        "record",
        TASK,
        "--episodes",
        &e,
        "--seed",
        "3",
        "--steps",
        "50",
        "--noise",
        noise,
        "--out",
        dir.to_str().unwrap(),
        "--json",
    ]));
    out.lines().map(str::to_string).collect()
}

fn replay_all(dir: &Path) -> Vec<serde_json::Value> {
    let out = ok(cli(&["dataset", "replay", dir.to_str().unwrap(), "--json"]));
    out.lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn recorded_episodes_replay_bit_for_bit_and_noise_varies_them() {
    let dir = scratch("replay");
    let lines = record(&dir, 3, "0.2");
    assert_eq!(lines.len(), 3, "{lines:?}");
    let replays = replay_all(&dir);
    for r in &replays {
        println!("{r}");
        assert_eq!(r["identical"], true, "{r}");
    }
    assert_eq!(replays.len(), 3);
    let i = info(&dir);
    assert_eq!(
        (i["episodes"].as_u64(), i["codebase_version"].as_str()),
        (Some(3), Some("v3.0"))
    );
    assert_eq!(i["recorded_by"]["target"], TASK);
    // the same seeds without noise give other actions, hence other data files
    let quiet = scratch("quiet");
    record(&quiet, 1, "0");
    let a = std::fs::read(dir.join("data/chunk-000/file-000.parquet")).unwrap();
    let b = std::fs::read(quiet.join("data/chunk-000/file-000.parquet")).unwrap();
    assert_ne!(a, b, "noise 0.2 left the episode as it was");
    // recording more into the folder appends; a folder with other features is refused
    record(&dir, 4, "0.2");
    assert_eq!(info(&dir)["episodes"], 4);
    let o = cli(&[
        "record",
        TASK,
        "--episodes",
        "5",
        "--steps",
        "50",
        "--cameras",
        "robot",
        "--out",
        dir.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    println!("other features: {}", err.trim());
    assert_eq!(o.status.code(), Some(1));
    assert!(err.contains("other features"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&quiet);
}

fn committed(dir: &Path) -> u64 {
    std::fs::read_to_string(dir.join("meta/info.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| v["total_episodes"].as_u64())
        .unwrap_or(0)
}

/// SIGKILL at several moments after a commit (0 to 40 ms into the next episode, which takes
/// about as long: some kills land inside the commit's file writes); after each, the dataset
/// loads with exactly the committed episodes, and every one of them replays.
#[test]
fn a_recording_killed_at_any_moment_keeps_its_committed_episodes() {
    let dir = scratch("kill");
    let args = [
        "record",
        TASK,
        "--episodes",
        "12",
        "--seed",
        "11",
        "--steps",
        "30",
        "--noise",
        "0.1",
        "--out",
        dir.to_str().unwrap(),
    ];
    let mut orphans_seen = 0;
    for (round, delay_ms) in [0u64, 3, 7, 13, 21, 40].into_iter().enumerate() {
        let before = committed(&dir);
        let mut child = Command::new(bin())
            .args(args)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let start = Instant::now();
        while committed(&dir) <= before && start.elapsed() < Duration::from_secs(120) {
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_millis(delay_ms));
        child.kill().unwrap();
        child.wait().unwrap();
        let i = info(&dir);
        let n = committed(&dir);
        orphans_seen += i["orphans"].as_array().unwrap().len();
        println!(
            "round {round}: killed {delay_ms} ms after commit {}: {n} episodes, orphans {}",
            before + 1,
            i["orphans"]
        );
        assert_eq!(i["episodes"].as_u64(), Some(n));
        assert!(n > before);
        for r in replay_all(&dir) {
            assert_eq!(r["identical"], true, "round {round}: {r}");
        }
    }
    // the same command finishes the dataset, deleting what the kills left
    ok(cli(&args));
    let i = info(&dir);
    println!(
        "finished: {} episodes, orphans {} (seen after kills: {orphans_seen})",
        i["episodes"], i["orphans"]
    );
    assert_eq!(i["episodes"], 12);
    assert_eq!(i["orphans"].as_array().unwrap().len(), 0);
    let seeds: Vec<u64> = replay_all(&dir)
        .iter()
        .map(|r| r["seed"].as_u64().unwrap())
        .collect();
    assert_eq!(seeds, (11..23).collect::<Vec<_>>());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_full_disk_ends_the_recording_with_a_clear_error_and_a_loadable_dataset() {
    let dir = scratch("full");
    // 96 KiB per file: the first episodes fit, the episodes file (about 55 KiB + 3 KiB per
    // episode) soon does not
    let o = Command::new("bash")
        .arg("-c")
        .arg("ulimit -f 96; trap '' XFSZ; exec \"$0\" \"$@\"")
        .arg(bin())
        .args([
            "record",
            TASK,
            "--episodes",
            "40",
            "--steps",
            "40",
            "--out",
            dir.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    println!("full disk: exit {:?}: {}", o.status.code(), err.trim());
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("error:") && err.contains(dir.to_str().unwrap()),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    let i = info(&dir);
    let n = i["episodes"].as_u64().unwrap();
    println!("{n} episodes committed before the disk was full");
    assert!((1..40).contains(&n));
    for r in replay_all(&dir) {
        assert_eq!(r["identical"], true, "{r}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Keyboard demonstrations (`dataset import-teleop`, the path `view --record-dataset` takes for
/// each ended episode): a recording of the discrete keys becomes a dataset whose actions are
/// the keys, which re-simulates bit for bit; behaviour cloning with the classification head
/// learns it and presses the same keys from its seed; a recording of a continuous-action env,
/// or one whose keys are not one per step, is refused.
#[test]
fn teleoperation_recordings_import_as_datasets() {
    let names = [
        "body_forward",
        "body_left",
        "body_right",
        "body_back",
        "turn_left",
        "turn_right",
        "hand_forward",
        "hand_back",
        "hand_left",
        "hand_right",
        "hand_up",
        "hand_down",
        "grasp",
        "release",
    ];
    // two episodes: 24 keys (mostly forward), then an empty one (the viewer's last, unused)
    let keys: Vec<usize> = (0..24).map(|j| [0, 0, 0, 10, 6, 4, 0, 12][j % 8]).collect();
    let actions: Vec<serde_json::Value> = keys
        .iter()
        .enumerate()
        .map(|(j, &k)| serde_json::json!({"step": j, "action": k, "name": names[k]}))
        .collect();
    let rec = serde_json::json!({"format": "modesuite.teleop.v1", "scene": "MoDe-Spot-Uncover-v0",
        "episodes": [{"seed": 5, "actions": actions, "length": 24},
                     {"seed": 6, "actions": [], "length": 0}]});
    let dir = scratch("teleop");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("teleop.json");
    std::fs::write(&file, rec.to_string()).unwrap();
    let out = dir.join("ds");
    let (f, o) = (file.to_str().unwrap(), out.to_str().unwrap());
    let discrete = "(discrete: true)";
    let line = ok(cli(&[
        "dataset",
        "import-teleop",
        f,
        "--out",
        o,
        "--actions",
        discrete,
        "--json",
    ]));
    println!("{line}");
    let v = info(&out);
    assert_eq!(
        (v["episodes"].as_u64(), v["frames"].as_u64()),
        (Some(1), Some(24))
    );
    let replay = ok(cli(&["dataset", "replay", o]));
    println!("{replay}");
    // the recorded actions are the keys
    let ds = modesuite_dataset::Dataset::open(&out).unwrap();
    let cols = ds.read_episode(0).unwrap();
    let Some((_, modesuite_dataset::Column::F32 { dim: 1, values })) =
        cols.iter().find(|(n, _)| n == "action")
    else {
        panic!("no action column");
    };
    let expect: Vec<f32> = keys.iter().map(|&k| k as f32).collect();
    assert_eq!(values, &expect);
    // behaviour cloning of the keys (the classification head) replays the demonstration
    let bc = dir.join("bc");
    let trained = ok(cli(&[
        "train",
        "MoDe-Spot-Uncover-v0",
        "--algo",
        "bc",
        "--dataset",
        o,
        "--actions",
        discrete,
        "--out",
        bc.to_str().unwrap(),
        "--set",
        "epochs=300",
    ]));
    println!("{trained}");
    // recorded from the demonstration's seed, the BC policy presses the same 24 keys
    let again = dir.join("again");
    ok(cli(&[
        "record",
        "MoDe-Spot-Uncover-v0",
        "--policy",
        bc.to_str().unwrap(),
        "--episodes",
        "1",
        "--seed",
        "5",
        "--steps",
        "24",
        "--out",
        again.to_str().unwrap(),
    ]));
    let ds2 = modesuite_dataset::Dataset::open(&again).unwrap();
    let cols2 = ds2.read_episode(0).unwrap();
    let Some((
        _,
        modesuite_dataset::Column::F32 {
            values: pressed, ..
        },
    )) = cols2.iter().find(|(n, _)| n == "action")
    else {
        panic!("no action column");
    };
    println!("keys pressed by BC from seed 5: {pressed:?}");
    assert_eq!(pressed, &expect);
    // a continuous-action env cannot re-simulate keys
    let o2 = cli(&["dataset", "import-teleop", f, "--out", &format!("{o}2")]);
    let err = String::from_utf8_lossy(&o2.stderr);
    assert_eq!(o2.status.code(), Some(2), "{err}");
    assert!(err.contains("discrete keys"), "{err}");
    // keys not one per step (a continuous viewer's recording) are refused
    let mut bad = rec.clone();
    bad["episodes"][0]["actions"][3]["step"] = serde_json::json!(9);
    std::fs::write(&file, bad.to_string()).unwrap();
    let o3 = cli(&[
        "dataset",
        "import-teleop",
        f,
        "--out",
        &format!("{o}3"),
        "--actions",
        discrete,
    ]);
    let err = String::from_utf8_lossy(&o3.stderr);
    assert_eq!(o3.status.code(), Some(2), "{err}");
    assert!(err.contains("key 3"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
