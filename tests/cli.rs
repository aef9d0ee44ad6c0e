//! Tests of the `modesuite` command line (its public contracts).

mod common;

use common::{modesuite_cmd as modesuite, stdout_ok};

fn tmp(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("modesuite-cli-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn drop_scene_dump_shows_bodies_at_rest_on_the_ground() {
    let dump = tmp("drop.json");
    let out = modesuite()
        .args([
            "run",
            "scenes/examples/drop.scene.ron",
            "--steps",
            "300",
            "--dump-state",
        ])
        .arg(&dump)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&dump).unwrap()).unwrap();
    assert_eq!(v["format"], "modesuite.state.v1");
    assert_eq!(v["step"], 300);
    let obj = &v["objects"];
    let z = |name: &str| obj[name]["position"][2].as_f64().unwrap();
    let speed = |name: &str| {
        let l = &obj[name]["linear_velocity"];
        (0..3)
            .map(|i| l[i].as_f64().unwrap().powi(2))
            .sum::<f64>()
            .sqrt()
    };
    println!(
        "after 5 s: box z {:.4} m (rests on a face: 0.05, 0.10 or 0.15), speed {:.2e}; ball z {:.4} (0.1), speed {:.2e}; ring z {:.4}",
        z("box"), speed("box"), z("ball"), speed("ball"), z("ring")
    );
    let bz = z("box");
    assert!(
        [0.05, 0.10, 0.15].iter().any(|h| (bz - h).abs() < 0.005),
        "box z {bz}"
    );
    assert!(speed("box") < 1e-2);
    assert!((z("ball") - 0.1).abs() < 0.005);
    assert!(speed("ball") < 1e-2);
    assert!((z("ring") - 0.05).abs() < 1e-9);
    assert_eq!(obj["ring"]["kind"], "static");
    assert_eq!(obj["box"]["kind"], "dynamic");
    assert_eq!(obj["box"]["quat_wxyz"].as_array().unwrap().len(), 4);
}

#[test]
fn run_json_prints_one_object_per_episode_and_a_summary() {
    let out = modesuite()
        .args([
            "run",
            "scenes/examples/drop.scene.ron",
            "--steps",
            "20",
            "--episodes",
            "3",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 4, "{text}");
    for (i, l) in lines[..3].iter().enumerate() {
        assert_eq!(l["episode"], i);
        assert_eq!(l["length"], 20);
        for k in [
            "seed",
            "return",
            "success",
            "error",
            "wall_s",
            "steps_per_s",
        ] {
            assert!(l.get(k).is_some(), "missing {k} in {l}");
        }
        // no task: the run's --steps end every episode
        assert_eq!(l["ended"], "steps", "{l}");
        assert_eq!(l["terminations"], serde_json::json!([]), "{l}");
    }
    assert_eq!(lines[3]["summary"], true);
    assert_eq!(lines[3]["episodes"], 3);
    assert_eq!(lines[3]["ended"], serde_json::json!({"steps": 3}));
    assert!(lines[3]["env_steps_per_s"].as_f64().unwrap() > 0.0);
}

/// `run --json`'s lines without the wall-time keys.
fn episodes_json(args: &[&str]) -> Vec<serde_json::Value> {
    stdout_ok(modesuite().args(args))
        .lines()
        .map(|l| {
            let mut v: serde_json::Value = serde_json::from_str(l).unwrap();
            let o = v.as_object_mut().unwrap();
            for k in ["wall_s", "steps_per_s", "env_steps_per_s"] {
                o.remove(k);
            }
            v
        })
        .collect()
}

#[test]
fn episodes_run_side_by_side_on_threads_give_the_same_results() {
    // the expert on Franka Place (FEM rod, rigid robot): 5 episodes on 1, 2 and 3 threads
    let run = |threads: &str| {
        episodes_json(&[
            "run",
            "MoDe-Franka-Place-v0",
            "--policy",
            "scripted",
            "--episodes",
            "5",
            "--seed",
            "7",
            "--json",
            "--threads",
            threads,
        ])
    };
    let one = run("1");
    assert_eq!(one.len(), 6);
    for (i, l) in one[..5].iter().enumerate() {
        assert_eq!(l["episode"], i, "{l}");
        assert_eq!(l["seed"], 7 + i, "{l}");
    }
    println!("summary on 1 thread: {}", one[5]);
    assert_eq!(run("2"), one);
    assert_eq!(run("3"), one);
}

#[test]
fn bench_json_has_the_stable_keys() {
    let text = stdout_ok(modesuite().args(["bench", "engine", "--json", "--scale", "0.002"]));
    let mut cases = Vec::new();
    for l in text.lines() {
        let v: serde_json::Value = serde_json::from_str(l).unwrap();
        for k in ["case", "steps_per_s", "threads", "envs", "us_per_env_step"] {
            assert!(v.get(k).is_some(), "missing {k} in {v}");
        }
        assert!(v["steps_per_s"].as_f64().unwrap() > 0.0);
        cases.push(v["case"].as_str().unwrap().to_string());
    }
    println!("cases: {cases:?}");
    for c in ["schedule", "empty_env", "empty_x16"] {
        assert!(cases.iter().any(|x| x == c), "case {c} missing");
    }
}

#[test]
fn bad_input_exits_2_with_a_located_message_and_no_panic() {
    let bad = tmp("bad.scene.ron");
    std::fs::write(&bad, "Scene(\n  objects: [\n    (name: \"x\", shape: Sphere(radius: 0.1), body: Static, mass: 3.0),\n  ],\n)\n").unwrap();
    let out = modesuite().arg("validate").arg(&bad).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    println!("{err}");
    assert_eq!(out.status.code(), Some(2));
    assert!(err.contains(&format!("{}:3:", bad.display())), "{err}");
    assert!(!err.contains("panicked"));

    let nan = tmp("nan.scene.ron");
    std::fs::write(
        &nan,
        "Scene(objects: [(name: \"x\", shape: Box(size: (1.0, NaN, 1.0)), body: Static)])",
    )
    .unwrap();
    let out = modesuite().arg("run").arg(&nan).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    println!("{err}");
    assert_eq!(out.status.code(), Some(2));
    assert!(err.contains("objects[0] \"x\".shape.size"), "{err}");

    for args in [
        vec!["run", "no/such/file.scene.ron"],
        vec!["run", "MoDe-Franka-Plase-v0"],
        vec!["bench", "nonsense"],
        vec!["list", "nonsense"],
        vec!["run", "scenes/examples/drop.scene.ron", "--steps", "0"],
    ] {
        let out = modesuite().args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        println!("{args:?}: {err}");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(err.starts_with("error: "));
    }
}

#[test]
fn validate_every_example_and_list_categories() {
    let out = modesuite()
        .args(["validate", "scenes/examples/drop.scene.ron"])
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("ok (4 objects"));
    let out = modesuite().args(["list", "body-kinds"]).output().unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("Dynamic"));
}

#[test]
fn default_command_runs_the_embedded_default() {
    // From an empty folder: the task files are embedded; the video goes to ./out.
    let dir = tmp("default");
    std::fs::create_dir_all(&dir).unwrap();
    let text = stdout_ok(modesuite().current_dir(&dir).env("MODESUITE_SCENES", &dir));
    println!("{text}");
    assert!(text.contains("MoDe-Franka-Place-v0"), "{text}");
    assert!(
        text.contains("summary: 1 episodes, success rate 100.0 %"),
        "{text}"
    );
    // the table's last column says how the episode ended
    assert!(
        text.lines()
            .any(|l| l.trim_start().starts_with("0 ") && l.trim_end().ends_with(" success")),
        "{text}"
    );
    let gif = std::fs::read(dir.join("out/MoDe-Franka-Place-v0.gif")).unwrap();
    assert!(
        gif.starts_with(b"GIF89a") && gif.len() > 10_000,
        "a GIF video"
    );
}

#[test]
fn bench_suites_json_have_their_keys() {
    for (suite, cases, keys) in [
        (
            "fem",
            &[
                "rod_soft",
                "rod_stiff",
                "rod_stiff_peer_grid",
                "rod_stiff_x16",
            ][..],
            &["tip_deflection_m", "theory_m", "nodes", "element_type"][..],
        ),
        (
            "pbd",
            &["cloth", "cloth_selfcollide", "cloth_x16"][..],
            &["stretch_mean", "stretch_max", "particles_inside"][..],
        ),
        (
            "robots",
            &["franka", "spot"][..],
            &["robot", "mode", "distance_m", "substeps"][..],
        ),
        (
            "tasks",
            &["MoDe-Franka-Place-v0", "MoDe-Franka-Place-v0_x16"][..],
            &["task"][..],
        ),
        (
            "learn",
            &["vecenv_x16", "ppo_x16", "sac_x16"][..],
            &["task"][..],
        ),
        (
            "contact",
            &[
                "tori_stacked",
                "cloth_over_torus",
                "cloths_falling",
                "box_on_foam",
                "box_on_torus",
                "K_box_on_block",
                "K_blocks",
                "K_cloth_on_block",
            ][..],
            &["steps", "deepest_mm", "max_speed"][..],
        ),
    ] {
        let text = stdout_ok(modesuite().args(["bench", suite, "--json", "--scale", "0.01"]));
        let lines: Vec<serde_json::Value> = text
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        for c in cases {
            let l = lines
                .iter()
                .find(|l| l["case"] == *c)
                .unwrap_or_else(|| panic!("{suite}: case {c} missing"));
            for k in keys.iter().chain(["steps_per_s", "threads", "envs"].iter()) {
                assert!(l.get(*k).is_some(), "{suite}/{c}: missing {k} in {l}");
            }
            println!("{l}");
        }
        if suite == "learn" {
            // whole iterations (one at this scale) and a share of the time in the learner
            for (case, steps) in [("ppo_x16", 512), ("sac_x16", 256)] {
                for l in lines.iter().filter(|l| l["case"] == case) {
                    assert_eq!(l["env_steps"], steps, "{l}");
                    let share = l["learner_share"].as_f64().unwrap();
                    assert!(share > 0.0 && share < 1.0, "{l}");
                    // the replay of the training's env calls (same states, checked)
                    assert!(l["replay_steps_per_s"].as_f64().unwrap() > 0.0, "{l}");
                    assert!(l["vs_vecenv"].as_f64().unwrap() > 0.0, "{l}");
                }
            }
        }
        if suite == "tasks" {
            // the single env's rounds interleaved with the x16 ones, and the overhead per round
            let single = lines
                .iter()
                .find(|l| l["case"] == "MoDe-Franka-Place-v0")
                .unwrap();
            let numbers = |v: &serde_json::Value, key: &str, n: usize| {
                let a = v[key].as_array().unwrap_or_else(|| panic!("{key} in {v}"));
                assert_eq!(a.len(), n, "{key} in {v}");
                a.iter()
                    .map(|r| r.as_f64().expect("a number"))
                    .collect::<Vec<_>>()
            };
            let runs = numbers(single, "single_runs", modesuite::benches::TASK_ROUNDS);
            assert!(runs.iter().all(|&v| v > 0.0));
            let x16 = lines
                .iter()
                .find(|l| l["case"] == "MoDe-Franka-Place-v0_x16" && l["threads"] == 1)
                .expect("one-thread x16 case");
            assert!(x16["overhead"].as_f64().is_some_and(|o| o > -1.0));
            let per_round = numbers(x16, "overhead_rounds", modesuite::benches::TASK_ROUNDS);
            assert!(per_round.iter().all(|&o| o > -1.0));
            // the overhead splits into the plain loop's (caches) and the VecEnv's over it (path)
            let part = |k: &str| x16[k].as_f64().unwrap_or_else(|| panic!("{k} in {x16}"));
            let (turns, path) = (part("turns_overhead"), part("path_overhead"));
            let whole = x16["overhead"].as_f64().unwrap();
            assert!(turns > -1.0 && path > -1.0);
            assert!(
                ((1.0 + turns) * (1.0 + path) - (1.0 + whole)).abs() < 1e-9,
                "turns {turns} and path {path} do not compose to the overhead {whole}"
            );
        }
    }
}

#[test]
fn run_json_says_how_each_episode_ended() {
    // A failure termination on the robot's base frame: inside the box it fires on the first
    // step; with the box elsewhere the scene's time limit ends the episode.
    let dir = tmp("ended");
    std::fs::create_dir_all(&dir).unwrap();
    let scene = |lo: f64, hi: f64| {
        format!(
            r#"Scene(
    objects: [(name: "ground", shape: Plane(size: (10.0, 10.0)), body: Static)],
    extensions: {{
        "robots": [(name: "robot", model: "franka")],
        "task": (terminations: {{"base_home": (term: "in_box", params: (
            point: Base, center: Const((0.0, 0.0, 0.0)),
            min: ({lo}, -0.5, -0.5), max: ({hi}, 0.5, 0.5),
        ))}}),
    }},
    episode_steps: Some(4),
)"#
        )
    };
    let episode = |name: &str, text: String| -> serde_json::Value {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let text = stdout_ok(modesuite().arg("run").arg(&path).arg("--json"));
        println!("{text}");
        serde_json::from_str(text.lines().next().unwrap()).unwrap()
    };
    let failed = episode("home.scene.ron", scene(-0.5, 0.5));
    assert_eq!(failed["ended"], "failure");
    assert_eq!(failed["terminations"], serde_json::json!(["base_home"]));
    assert_eq!(failed["length"], 1);
    let timed_out = episode("away.scene.ron", scene(5.0, 6.0));
    assert_eq!(timed_out["ended"], "time_limit");
    assert_eq!(timed_out["terminations"], serde_json::json!([]));
    assert_eq!(timed_out["length"], 4);
}

/// A panic of third-party code that modesuite catches (parry's convex decomposition of an
/// open mesh, found by the fuzzer) is reported as the located error alone, without the panic
/// message the default hook would print before it; `MODESUITE_LOUD_PANICS` prints it.
#[test]
fn a_caught_third_party_panic_prints_only_the_error() {
    let dir = tmp("open-mesh");
    let _ = std::fs::create_dir_all(&dir);
    std::fs::write(
        dir.join("fuzz-open.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 1 1 0\nvt 0 0\nvn 0 0 1\n\
         f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\nf 2/1 5/1 3/1\nf -1 -2 -3\n",
    )
    .unwrap();
    let scene = dir.join("s.scene.ron");
    std::fs::copy(
        common::root().join("fuzz/regressions/scene/moving-open-mesh-vhacd-panic.scene.ron"),
        &scene,
    )
    .unwrap();
    let out = modesuite().arg("validate").arg(&scene).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    println!("{err}");
    assert_eq!(out.status.code(), Some(2));
    assert!(err.contains("convex decomposition failed"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let loud = modesuite()
        .env("MODESUITE_LOUD_PANICS", "1")
        .arg("validate")
        .arg(&scene)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&loud.stderr);
    assert!(err.contains("panicked"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
