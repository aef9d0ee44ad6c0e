//! Fault injection for every writer of the CLI (state files, state dumps, videos, frames,
//! training checkpoints and metrics, plots): a folder nobody may write into (`/sys`, refused even
//! to root) and a full disk (the file size limit `ulimit -f`, whose signal is ignored, so writes
//! fail with EFBIG as on a full disk). Each must end with exit code 1 and a message naming the
//! file, and leave nothing behind that looks complete: no file at the path asked for (or the
//! previous complete one) and no temporary file.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_modesuite")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("modesuite-faults-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs the CLI with `args`; with `limit_kib`, under a file size limit of that many KiB.
fn cli(args: &[&str], limit_kib: Option<u32>) -> Output {
    match limit_kib {
        None => Command::new(bin()).args(args).output().unwrap(),
        Some(k) => Command::new("bash")
            .arg("-c")
            .arg(format!("ulimit -f {k}; trap '' XFSZ; exec \"$0\" \"$@\""))
            .arg(bin())
            .args(args)
            .output()
            .unwrap(),
    }
}

/// Every file under `dir`, relative, sorted.
fn files(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().display().to_string());
            }
        }
    }
    out.sort();
    out
}

/// A failed write: exit code 1, an error naming `what`.
fn assert_refused(o: &Output, what: &str, case: &str) {
    let err = String::from_utf8_lossy(&o.stderr);
    println!(
        "{case}: exit {:?}: {}",
        o.status.code(),
        err.trim().lines().last().unwrap_or("")
    );
    assert_eq!(o.status.code(), Some(1), "{case}: {err}");
    assert!(
        err.contains("error:") && err.contains(what),
        "{case}: {err}"
    );
    assert!(!err.contains("panicked"), "{case}: {err}");
}

const TASK: &str = "MoDe-Franka-Place-v0";

/// The `run` writers: each into /sys, then under a 8 KiB file size limit.
#[test]
fn run_writers_fail_cleanly_on_a_read_only_folder_and_a_full_disk() {
    for (flag, name) in [
        ("--save-state", "x.state"),
        ("--dump-state", "x.json"),
        ("--video", "x.gif"),
        ("--frames", "frames"),
    ] {
        let o = cli(
            &["run", TASK, "--steps", "12", flag, &format!("/sys/{name}")],
            None,
        );
        assert_refused(&o, "/sys/", &format!("{flag} into /sys"));
        let dir = scratch(name);
        let target = dir.join(name);
        let o = cli(
            &["run", TASK, "--steps", "12", flag, target.to_str().unwrap()],
            Some(8),
        );
        assert_refused(&o, name, &format!("{flag} on a full disk"));
        let left = files(&dir);
        assert!(left.is_empty(), "{flag}: left behind {left:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// A state file that already exists survives a failed overwrite whole.
#[test]
fn a_failed_overwrite_keeps_the_previous_state_file() {
    let dir = scratch("overwrite");
    let f = dir.join("x.state");
    let ok = cli(
        &[
            "run",
            TASK,
            "--steps",
            "3",
            "--save-state",
            f.to_str().unwrap(),
        ],
        None,
    );
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let before = std::fs::read(&f).unwrap();
    let o = cli(
        &[
            "run",
            TASK,
            "--steps",
            "9",
            "--save-state",
            f.to_str().unwrap(),
        ],
        Some(8),
    );
    assert_refused(&o, "x.state", "overwrite on a full disk");
    assert_eq!(
        std::fs::read(&f).unwrap(),
        before,
        "the previous file changed"
    );
    assert_eq!(files(&dir), ["x.state"]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Training on a full disk stops with an error and no partial checkpoint; the same command
/// without the limit then completes the run; a plot into /sys or onto a full disk fails cleanly.
#[test]
fn training_and_plot_writers_fail_cleanly() {
    let o = cli(
        &[
            "train",
            TASK,
            "--env-steps",
            "512",
            "--envs",
            "4",
            "--out",
            "/sys/run",
        ],
        None,
    );
    assert_refused(&o, "/sys/run", "train into /sys");
    let dir = scratch("train");
    let run = dir.join("run");
    let args = [
        "train",
        TASK,
        "--env-steps",
        "1280",
        "--envs",
        "2",
        "--set",
        "horizon=64",
        "--set",
        "hidden=[16]",
        "--checkpoint-every",
        "1",
        "--out",
        run.to_str().unwrap(),
    ];
    let o = cli(&args, Some(4));
    assert_refused(&o, "checkpoint", "train on a full disk");
    let left = files(&run);
    assert!(
        !left
            .iter()
            .any(|f| f.contains("partial") || f == "checkpoint.bin"),
        "{left:?}"
    );
    let o = cli(&args, None);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(run.join("checkpoint.bin").is_file());
    // Short runs finish no episode: give the plot metrics that did (returns and successes).
    let metrics = std::fs::read_to_string(run.join("metrics.jsonl")).unwrap();
    let with_episodes: String = metrics
        .lines()
        .enumerate()
        .map(|(i, l)| {
            let mut m: serde_json::Value = serde_json::from_str(l).unwrap();
            m["return_mean"] = serde_json::json!(-100.0 + i as f64);
            m["success_rate"] = serde_json::json!(0.1 * (i % 10) as f64);
            format!("{m}\n")
        })
        .collect();
    std::fs::write(run.join("metrics.jsonl"), with_episodes).unwrap();
    let o = cli(
        &["plot", run.to_str().unwrap(), "--out", "/sys/p.png"],
        None,
    );
    assert_refused(&o, "/sys/p.png", "plot into /sys");
    let png = dir.join("p.png");
    let o = cli(
        &[
            "plot",
            run.to_str().unwrap(),
            "--out",
            png.to_str().unwrap(),
        ],
        Some(4),
    );
    assert_refused(&o, "p.png", "plot on a full disk");
    assert!(!png.exists());
    assert!(
        !files(&dir).iter().any(|f| f.contains("partial")),
        "{:?}",
        files(&dir)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
