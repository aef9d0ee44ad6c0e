//! Command-line tests of the render features: videos, PNG frames, `bench render`, and the viewer
//! under Xvfb (the set-up installs xvfb and xdotool).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use modesuite::render::video::{gif_info, read_png};

fn modesuite() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_modesuite"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"));
    c
}

fn tmp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "modesuite-render-cli-{}-{name}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn ok(out: &std::process::Output) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "exit {:?}\nstdout: {stdout}\nstderr: {}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

#[test]
fn run_with_video_writes_a_decodable_gif_and_png_frames() {
    let dir = tmp_dir("gif");
    let gif = dir.join("drop.gif");
    let frames = dir.join("frames");
    let out = modesuite()
        .args([
            "run",
            "scenes/examples/drop.scene.ron",
            "--steps",
            "20",
            "--video-size",
            "96x64",
            "--video",
        ])
        .arg(&gif)
        .arg("--frames")
        .arg(&frames)
        // a headless session (CI, a container): no Wayland probe noise on stderr
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("NODEVICE_SELECT")
        .env_remove("MESA_VK_DEVICE_SELECT")
        .output()
        .unwrap();
    let stdout = ok(&out);
    println!("{stdout}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("error"),
        "a successful headless run printed errors:\n{stderr}"
    );
    // dt 1/60: one frame every 2 env steps, plus the reset frame: 11 frames.
    let (w, h, n) = gif_info(&gif).unwrap_or_else(|e| panic!("{e}"));
    println!("gif {w}x{h}, {n} frames (expected 96x64, 11)");
    assert_eq!((w, h, n), (96, 64, 11));
    let mut pngs: Vec<_> = std::fs::read_dir(&frames)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    pngs.sort();
    assert_eq!(pngs.len(), 11, "{pngs:?}");
    let (pw, ph, first) = read_png(&pngs[0]).unwrap();
    let (_, _, last) = read_png(&pngs[10]).unwrap();
    assert_eq!((pw, ph), (96, 64));
    let diff = first.iter().zip(&last).filter(|(a, b)| a != b).count();
    println!("{diff} bytes differ between the first and the last frame (the bodies fall)");
    assert!(diff > 50);
}

#[test]
fn run_with_overlays_draws_the_status_text_into_frames() {
    let dir = tmp_dir("overlays");
    let white = |png: &std::path::Path| {
        let (w, _, img) = read_png(png).unwrap_or_else(|e| panic!("{e}"));
        // The text box: 4 px from the top-left corner, one 7 px line.
        (4..15)
            .flat_map(|y| (4..w as usize).map(move |x| 3 * (y * w as usize + x)))
            .filter(|&i| img[i..i + 3] == [255, 255, 255])
            .count()
    };
    let mut counts = Vec::new();
    for overlays in [false, true] {
        let frames = dir.join(format!("frames_{overlays}"));
        let mut cmd = modesuite();
        cmd.args([
            "run",
            "scenes/examples/drop.scene.ron",
            "--steps",
            "4",
            "--video-size",
            "240x160",
            "--frames",
        ])
        .arg(&frames);
        if overlays {
            cmd.arg("--overlays");
        }
        ok(&cmd.output().unwrap());
        counts.push(white(&frames.join("frame_00002.png")));
    }
    println!("white text pixels without / with --overlays: {counts:?}");
    assert_eq!(counts[0], 0, "no text without --overlays");
    assert!(counts[1] > 100, "the status line is drawn");
}

#[test]
fn run_with_a_scene_camera_and_mp4_when_ffmpeg_exists() {
    let dir = tmp_dir("mp4");
    let has_ffmpeg = modesuite::render::video::ffmpeg_available();
    let video = dir.join("tabletop.mp4");
    let out = modesuite()
        .args([
            "run",
            "scenes/examples/tabletop_cameras.scene.ron",
            "--steps",
            "8",
            "--camera",
            "overhead",
            "--video",
        ])
        .arg(&video)
        .output()
        .unwrap();
    if !has_ffmpeg {
        let err = String::from_utf8_lossy(&out.stderr);
        println!("no ffmpeg: {err}");
        assert_eq!(out.status.code(), Some(1));
        assert!(err.contains("ffmpeg") && err.contains(".gif"), "{err}");
        return;
    }
    ok(&out);
    let probe = Command::new("ffprobe")
        .args([
            "-v",
            "error",
            "-count_frames",
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=width,height,nb_read_frames",
            "-of",
            "csv=p=0",
        ])
        .arg(&video)
        .output()
        .expect("ffprobe comes with ffmpeg");
    let s = String::from_utf8_lossy(&probe.stdout).trim().to_string();
    println!("ffprobe: {s} (expected 128,128,5)");
    assert_eq!(s, "128,128,5");
}

#[test]
fn bad_render_arguments_exit_2_with_a_message() {
    let cases: [(&[&str], &str); 4] = [
        (
            &[
                "run",
                "scenes/examples/tabletop_cameras.scene.ron",
                "--steps",
                "2",
                "--video",
                "x.gif",
                "--camera",
                "nope",
            ],
            "overhead",
        ),
        (
            &[
                "run",
                "scenes/examples/drop.scene.ron",
                "--steps",
                "2",
                "--video",
                "x.gif",
                "--video-size",
                "12",
            ],
            "WIDTHxHEIGHT",
        ),
        (
            &[
                "run",
                "scenes/examples/drop.scene.ron",
                "--steps",
                "2",
                "--camera",
                "overhead",
            ],
            "--video",
        ),
        (
            &["view", "scenes/examples/drop.scene.ron", "--size", "0x10"],
            "WIDTHxHEIGHT",
        ),
    ];
    for (args, want) in cases {
        let out = modesuite().args(args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        println!("{args:?}: {err}");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(err.contains(want), "{err}");
    }
    let out = modesuite()
        .args([
            "run",
            "scenes/examples/drop.scene.ron",
            "--steps",
            "2",
            "--video",
            "x.avi",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains(".gif or .mp4"));
}

#[test]
fn bench_render_json_has_the_three_cases() {
    let out = modesuite()
        .args(["bench", "render", "--json", "--scale", "0.02"])
        .output()
        .unwrap();
    let stdout = ok(&out);
    let lines: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let cases: Vec<&str> = lines.iter().map(|v| v["case"].as_str().unwrap()).collect();
    println!("{stdout}");
    assert_eq!(cases, ["rgbd_128", "rgbd_640", "rgbd_128_x16"]);
    for v in &lines {
        assert!(v["steps_per_s"].as_f64().unwrap() > 0.0);
        for k in ["threads", "envs", "width", "height", "adapter"] {
            assert!(!v[k].is_null(), "{k} in {v}");
        }
    }
    assert_eq!(lines[2]["envs"], 16);
}

/// Xvfb on a free display, killed on drop.
struct Display {
    child: Child,
    name: String,
}

impl Drop for Display {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start_xvfb() -> Display {
    for n in 0..20 {
        let name = format!(":{}", 90 + (std::process::id() as usize + n) % 400);
        let lock = format!("/tmp/.X{}-lock", &name[1..]);
        if Path::new(&lock).exists() {
            continue;
        }
        let child = Command::new("Xvfb")
            .args([
                name.as_str(),
                "-screen",
                "0",
                "1024x768x24",
                "-nolisten",
                "tcp",
                // Without it the server resets whenever its last client disconnects (every
                // xdotool poll), and a client connecting during a reset is refused.
                "-noreset",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| {
                panic!("Xvfb: {e} (install the xvfb package; scripts/setup.sh does)")
            });
        let mut d = Display { child, name };
        // Our own server must be the one answering: one that exited (display taken by a server
        // without a lock file) is not ours.
        if wait_for(Duration::from_secs(20), || {
            xdotool(&d, &["getdisplaygeometry"]).is_some()
        }) && matches!(d.child.try_wait(), Ok(None))
        {
            return d;
        }
    }
    panic!("could not start Xvfb on a free display");
}

fn xdotool(d: &Display, args: &[&str]) -> Option<String> {
    let out = Command::new("xdotool")
        .args(args)
        .env("DISPLAY", &d.name)
        .output()
        .unwrap_or_else(|e| {
            panic!("xdotool: {e} (install the xdotool package; scripts/setup.sh does)")
        });
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// Polls `f` until it holds or `limit` passes (a readiness wait, not a timing assertion).
fn wait_for(limit: Duration, mut f: impl FnMut() -> bool) -> bool {
    let t = Instant::now();
    while t.elapsed() < limit {
        if f() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    false
}

#[test]
fn viewer_under_xvfb_takes_keys_moves_the_camera_and_records_actions() {
    let display = start_xvfb();
    let dir = tmp_dir("viewer");
    let record = dir.join("episode.json");
    let spawn_viewer = || {
        modesuite()
            .args([
                "view",
                "MoDe-Franka-Place-v0",
                "--actions",
                "(discrete: true)",
                "--size",
                "320x240",
                "--paused",
                "--seed",
                "5",
                "--record",
            ])
            .arg(&record)
            .arg("--dump-state")
            .arg(dir.join("final.json"))
            .arg("--screenshot-dir")
            .arg(&dir)
            .env("DISPLAY", &display.name)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    // A viewer that could not connect to the fresh X server (its error says so) is started
    // again, at most twice: a readiness retry, any other failure ends the test.
    let mut window = String::new();
    let mut viewer = spawn_viewer();
    for attempt in 0..3 {
        let found = wait_for(Duration::from_secs(120), || {
            if let Some(w) = xdotool(&display, &["search", "--name", "modesuite view"]) {
                window = w.lines().next().unwrap_or("").to_string();
            }
            // A viewer that has exited will not open a window: stop waiting.
            !window.is_empty() || !matches!(viewer.try_wait(), Ok(None))
        }) && !window.is_empty();
        if found {
            break;
        }
        let _ = viewer.kill();
        let out = viewer.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        if attempt == 2 || !stderr.contains("cannot open a window") {
            panic!("no viewer window; stderr: {stderr}");
        }
        println!("viewer attempt {attempt} could not open a window, again: {stderr}");
        viewer = spawn_viewer();
    }
    let key = |k: &str| {
        xdotool(&display, &["windowfocus", "--sync", &window]);
        xdotool(&display, &["key", k]).expect("xdotool key");
    };
    let shot = |i: usize| dir.join(format!("modesuite-view-{i:04}.png"));
    // A window that has just been mapped may drop the first keys on a loaded machine: press `p`
    // until the first screenshot appears, then count what arrived before going on.
    let mut first = false;
    for _ in 0..6 {
        key("p");
        if wait_for(Duration::from_secs(10), || shot(0).exists()) {
            first = true;
            break;
        }
    }
    if !first {
        let _ = viewer.kill();
        let out = viewer.wait_with_output().unwrap();
        panic!(
            "the viewer took no screenshot on `p`; stderr: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    std::thread::sleep(Duration::from_secs(2));
    let before = (0..).take_while(|i| shot(*i).exists()).count();
    // Orbit the camera, issue teleoperation actions (a discrete env steps once per key: grasp,
    // then twenty steps forward), take another screenshot.
    key("Left");
    key("Left");
    key("g");
    for _ in 0..20 {
        key("w");
    }
    key("p");
    assert!(
        wait_for(Duration::from_secs(60), || shot(before).exists()),
        "second screenshot"
    );
    key("Escape");
    let exited = wait_for(Duration::from_secs(60), || {
        matches!(viewer.try_wait(), Ok(Some(_)))
    });
    if !exited {
        let _ = viewer.kill();
    }
    let out = viewer.wait_with_output().unwrap();
    println!(
        "viewer: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(exited && out.status.success(), "the viewer quits on escape");
    // Screenshots are written when the next frame is drawn: wait for a complete file.
    let (w0, h0, a) = read_png(&shot(before - 1)).unwrap_or_else(|e| panic!("{e}"));
    let (_, _, b) = read_png(&shot(before)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((w0, h0), (320, 240));
    let diff = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| (**x as i32 - **y as i32).abs() > 8)
        .count();
    println!(
        "screenshots differ in {diff} of {} bytes after two orbit steps",
        a.len()
    );
    assert!(diff > 1000, "the camera moved");
    // The heads-up text (white 5 x 7 glyphs on a dark box at the top left) is in the shots.
    let white = |img: &[u8]| {
        (6..27)
            .flat_map(|y| (6..300).map(move |x| 3 * (y * 320 + x)))
            .filter(|&i| img[i..i + 3] == [255, 255, 255])
            .count()
    };
    println!(
        "heads-up text: {} and {} white pixels",
        white(&a),
        white(&b)
    );
    assert!(white(&a) > 100 && white(&b) > 100, "heads-up text drawn");
    let rec = modesuite::render::teleop::Recording::load(&record).unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<_> = rec.episodes[0].actions.iter().map(|a| a.name).collect();
    println!("recorded: seed {} actions {names:?}", rec.episodes[0].seed);
    assert_eq!(rec.episodes[0].seed, 5);
    use modesuite::render::teleop::TeleopAction;
    let mut expect = vec![TeleopAction::Grasp];
    expect.extend([TeleopAction::BodyForward; 20]);
    assert_eq!(names, expect);
    // The robot drove forward: compare the final base with the same task reset with seed 5.
    let mut env =
        modesuite::make::env_for_target("MoDe-Franka-Place-v0", Some("(discrete: true)")).unwrap();
    env.reset(Some(5));
    let x0 = {
        let r = &env.app.world.resource::<modesuite::robots::Robots>().robots[0];
        r.observe(env.app.world.resource::<modesuite::engine::RigidContext>())
            .unwrap()
            .base
            .translation
            .vector
    };
    let dump: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("final.json")).unwrap()).unwrap();
    let p = &dump["objects"]["robot"]["position"];
    let x1 = nalgebra::Vector3::new(
        p[0].as_f64().unwrap(),
        p[1].as_f64().unwrap(),
        p[2].as_f64().unwrap(),
    );
    println!(
        "base moved {:.3} m in {} steps",
        (x1 - x0).xy().norm(),
        dump["step"]
    );
    assert_eq!(dump["episode_length"], 21);
    assert!((x1 - x0).xy().norm() > 0.06, "the robot drove forward");
}
