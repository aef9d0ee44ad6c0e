//! Compiled plugins loaded at run time through the C ABI: the example plugin `acme`
//! (examples/plugin-trefoil) and the fixtures in tests/fixtures/ (a plugin built for another ABI
//! version, a plugin that panics). The plugins are built here with the same cargo, target folder
//! and profile as this test, so `cargo test` needs no manual step.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use common::root;
use modesuite::engine::deps::plugin_abi::ABI_VERSION;
use modesuite::engine::dynamic::{DynamicPlugin, PluginLoadError};
use modesuite::engine::scene::{self, SceneError};
use modesuite::engine::shapes::{GeneratedMesh, MeshKind, ShapeDesc};
use modesuite::prelude::*;

const TREFOIL_SCENE: &str = "examples/plugin-trefoil/trefoil.scene.ron";

/// Builds the plugin crates once and returns the folder holding the libraries.
fn plugin_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        // This test runs from <target>/<profile>/deps/; the libraries land in <target>/<profile>.
        let exe = std::env::current_exe().expect("test executable path");
        let profile_dir = exe
            .parent()
            .and_then(Path::parent)
            .expect("<target>/<profile>/deps")
            .to_path_buf();
        let target_dir = profile_dir.parent().expect("<target>").to_path_buf();
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_string());
        let mut cmd = Command::new(cargo);
        cmd.current_dir(root())
            .args(["build", "--quiet", "--locked"])
            .args(["-p", "plugin-trefoil", "-p", "plugin-bad-version"])
            .args(["-p", "plugin-panics", "--target-dir"])
            .arg(&target_dir);
        if profile_dir.file_name().is_some_and(|n| n == "release") {
            cmd.arg("--release");
        }
        let out = cmd.output().expect("cargo runs");
        assert!(
            out.status.success(),
            "building the plugins failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        profile_dir
    })
}

/// Path of a plugin library built by [`plugin_dir`].
fn lib(crate_name: &str) -> PathBuf {
    plugin_dir().join(format!(
        "{}{}{}",
        std::env::consts::DLL_PREFIX,
        crate_name.replace('-', "_"),
        std::env::consts::DLL_SUFFIX
    ))
}

fn trefoil_app() -> (SimApp, SceneDesc, SceneSource) {
    let mut app = modesuite::make::default_app();
    app.load_plugin(lib("plugin-trefoil"))
        .expect("plugin loads");
    let (desc, source) = scene::load_file(&root().join(TREFOIL_SCENE)).expect("scene parses");
    (app, desc, source)
}

fn env_of(mut app: SimApp, desc: &SceneDesc, source: &SceneSource) -> Env {
    let model = app.compile_scene(desc, source).expect("scene compiles");
    app.spawn_scene(model).expect("scene spawns");
    Env::new(app)
}

fn nodes_of(env: &mut Env, name: &str) -> Vec<nalgebra::Vector3<f64>> {
    let mut q = env.app.world.query::<(&Object, &DeformableNodes)>();
    q.iter(&env.app.world)
        .find(|(o, _)| o.name == name)
        .map(|(_, n)| n.0.clone())
        .expect("deformable object")
}

/// Mean of the node positions, summed in order as the plugin does.
fn centroid(nodes: &[nalgebra::Vector3<f64>]) -> [f64; 3] {
    let mut c = [0.0; 3];
    for p in nodes {
        for k in 0..3 {
            c[k] += p[k];
        }
    }
    c.map(|x| x / nodes.len() as f64)
}

/// Length of the trefoil `s (sin t + 2 sin 2t, cos t - 2 cos 2t, -sin 3t)` (fine polyline).
fn trefoil_length(s: f64) -> f64 {
    let n = 100_000;
    let p = |i: usize| {
        let t = std::f64::consts::TAU * i as f64 / n as f64;
        nalgebra::Vector3::new(
            t.sin() + 2.0 * (2.0 * t).sin(),
            t.cos() - 2.0 * (2.0 * t).cos(),
            -(3.0 * t).sin(),
        ) * s
    };
    (0..n).map(|i| (p(i + 1) - p(i)).norm()).sum()
}

#[test]
fn trefoil_generator_makes_a_valid_tube_with_the_expected_volume() {
    let (app, desc, _) = trefoil_app();
    let ShapeDesc::Gen { name, params } = &desc.objects[1].shape else {
        panic!("the tube is a Gen shape");
    };
    let generator = app
        .registry()
        .shapes
        .get(name)
        .expect("acme.trefoil")
        .clone();
    let GeneratedMesh::Volume(mesh) = generator
        .generate(params.get_ron(), MeshKind::Volume)
        .expect("generates")
    else {
        panic!("a volume mesh");
    };
    mesh.check().expect("valid tets");
    let q = mesh.quality();
    let census = mesh.face_census();
    let (scale, radius, segments) = (0.06, 0.012, 6.0);
    let area = 0.5 * segments * (std::f64::consts::TAU / segments).sin() * radius * radius;
    let expected = area * trefoil_length(scale);
    println!(
        "acme.trefoil: {} nodes, {} tets, dihedral {:.1}..{:.1} deg, {} inverted, {} degenerate, faces {census:?}; volume {:.4e} m^3, section area x length {expected:.4e}, ratio {:.4}",
        q.nodes, q.tets, q.min_dihedral_deg, q.max_dihedral_deg, q.inverted, q.degenerate,
        mesh.volume(), mesh.volume() / expected
    );
    assert_eq!((q.inverted, q.degenerate, census.overshared), (0, 0, 0));
    assert!(q.min_tet_volume > 0.0);
    assert!(
        mesh.boundary_surface().is_closed(),
        "a closed, conforming tube"
    );
    assert!((mesh.volume() / expected - 1.0).abs() < 0.02);
    // Parameter errors name the parameter.
    let e = generator
        .generate("(scale: 0.06, radius: 0.3)", MeshKind::Volume)
        .unwrap_err();
    assert!(e.contains("radius = 0.3"), "{e}");
}

#[test]
fn trefoil_scene_rewards_observations_and_plugin_state_follow_the_tube_and_reset() {
    let (app, desc, source) = trefoil_app();
    let mut env = env_of(app, &desc, &source);
    assert_eq!(env.app.ambiguities(), Vec::<String>::new());
    env.autoreset = false;
    let steps = 4;
    let mut episodes = Vec::new();
    for _ in 0..2 {
        env.reset(Some(0));
        let mut rewards = Vec::new();
        let mut prev_z = None;
        for _ in 0..steps {
            let o = env.step(&[]);
            assert!(o.info.error.is_none(), "{:?}", o.info.error);
            let c = centroid(&nodes_of(&mut env, "tube"));
            let height = o.info.values["reward/acme.centroid_height"];
            let fall = o.info.values["reward/acme.fall_progress"];
            assert_eq!(height, c[2]);
            let expected_fall = prev_z.map_or(0.0, |p: f64| 10.0 * (p - c[2]));
            assert!(
                (fall - expected_fall).abs() < 1e-12,
                "{fall} {expected_fall}"
            );
            assert_eq!(o.reward, height + fall);
            assert_eq!(o.observation, c.map(|x| x as f32).to_vec());
            assert_eq!(o.info.values["termination/acme.below"], 0.0);
            prev_z = Some(c[2]);
            rewards.push((o.reward, env.state_hash()));
        }
        println!("episode rewards (sag under gravity and wind): {rewards:?}");
        episodes.push(rewards);
    }
    // The plugin's state slots are in the snapshot: the second episode repeats the first bit for bit.
    assert_eq!(episodes[0], episodes[1]);
}

#[test]
fn plugin_wind_force_reaches_the_fem_nodes() {
    let run = |wind: bool| {
        let (app, mut desc, source) = trefoil_app();
        if !wind {
            desc.passive_forces.clear();
        }
        let mut env = env_of(app, &desc, &source);
        env.reset(Some(0));
        for _ in 0..3 {
            env.step(&[]);
        }
        centroid(&nodes_of(&mut env, "tube"))
    };
    let (calm, windy) = (run(false), run(true));
    println!(
        "centroid x after 3 steps: calm {:.6e} m, in a 0.5 N wind along +x {:.6e} m",
        calm[0], windy[0]
    );
    assert!(windy[0] > calm[0] + 1e-7);
}

#[test]
fn a_plugin_for_another_abi_version_is_refused_before_any_call() {
    // The fixture's entry aborts the process if called: reaching the asserts proves it was not.
    let path = lib("plugin-bad-version");
    let e = DynamicPlugin::load(&path).unwrap_err();
    let message = e.to_string();
    println!("{message}");
    assert_eq!(
        e,
        PluginLoadError::VersionMismatch {
            path: path.clone(),
            found: ABI_VERSION + 1,
            expected: ABI_VERSION
        }
    );
    assert!(message.contains(&format!("built for plugin ABI version {}", ABI_VERSION + 1)));
    assert!(message.contains(&format!("expects version {ABI_VERSION}")));
}

#[test]
fn missing_and_non_plugin_files_give_clear_errors() {
    let missing = root().join("no/such/plugin.so");
    let e = DynamicPlugin::load(&missing).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!("plugin {}: no such file", missing.display())
    );
    let text = root().join("Cargo.toml");
    let e = DynamicPlugin::load(&text).unwrap_err();
    println!("{e}");
    assert!(matches!(e, PluginLoadError::NotALibrary { .. }), "{e}");
    assert!(e.to_string().contains("not a loadable shared library"));
    // A shared library that is not a plugin: the C maths library, where the system has one.
    let libm = [
        "/lib/x86_64-linux-gnu/libm.so.6",
        "/usr/lib/x86_64-linux-gnu/libm.so.6",
        "/lib64/libm.so.6",
    ]
    .iter()
    .map(PathBuf::from)
    .find(|p| p.is_file());
    match libm {
        Some(p) => {
            let e = DynamicPlugin::load(&p).unwrap_err();
            println!("{e}");
            assert!(
                e.to_string().contains(
                    "not a modesuite plugin: it does not export `MODESUITE_PLUGIN_ABI_VERSION`"
                ),
                "{e}"
            );
        }
        None => println!("no libm found: the non-plugin library case is skipped"),
    }
}

#[test]
fn loading_the_same_plugin_twice_into_one_app_is_refused() {
    let (mut app, _, _) = trefoil_app();
    let e = app.load_plugin(lib("plugin-trefoil")).unwrap_err();
    assert!(
        e.to_string()
            .contains("a plugin named \"acme\" is already added"),
        "{e}"
    );
}

const PANIC_SCENE: &str = r#"Scene(
    objects: [
        (name: "ground", shape: Plane(size: (4.0, 4.0)), body: Static),
        (name: "arm", shape: Box(size: (0.1, 0.1, 0.1)), pose: (pos: (0.0, 0.0, 0.05)), body: Static),
    ],
    rewards: [(term: "fixture.panics_on_third_call")],
    observations: [(term: "fixture.arm_joints", params: 2)],
)"#;

#[test]
fn a_panicking_plugin_term_ends_the_episode_with_an_error_and_the_process_goes_on() {
    let mut app = modesuite::make::default_app();
    app.load_plugin(lib("plugin-panics"))
        .expect("fixture loads");
    let desc = scene::parse_str(PANIC_SCENE, "<panic scene>").unwrap();
    let model = app
        .compile_scene(&desc, &SceneSource::in_memory("."))
        .unwrap();
    app.spawn_scene(model).unwrap();
    // The joint state a robot plugin would write; the plugin observes it.
    let arm = {
        let mut q = app.world.query::<(Entity, &Object)>();
        q.iter(&app.world).find(|(_, o)| o.name == "arm").unwrap().0
    };
    app.world.entity_mut(arm).insert(JointState {
        names: vec!["j1".to_string(), "j2".to_string()].into(),
        positions: vec![0.25, -1.5],
        velocities: vec![0.0, 0.0],
    });
    let mut env = Env::new(app);
    assert_eq!(env.spaces().observation.flat_dim(), 2);
    let (obs, _) = env.reset(Some(0));
    assert_eq!(obs, vec![0.25, -1.5]);
    let mut log = Vec::new();
    for _ in 0..6 {
        let o = env.step(&[]);
        log.push((o.reward, o.truncated, o.info.error.clone()));
    }
    println!("{log:#?}");
    // Rewards 1, 2, then the panic ends the episode; the reset restores the plugin's counter.
    for episode in [&log[0..3], &log[3..6]] {
        assert_eq!((episode[0].0, episode[0].1), (1.0, false));
        assert_eq!((episode[1].0, episode[1].1), (2.0, false));
        let (reward, truncated, error) = &episode[2];
        assert_eq!((*reward, *truncated), (0.0, true));
        let error = error.as_deref().expect("an error");
        assert!(
            error.contains("reward term \"fixture.panics_on_third_call\"")
                && error.contains("plugin \"fixture\" evaluate: panicked: fixture: third call"),
            "{error}"
        );
    }
    assert_eq!(env.error_count, 2);
}

#[test]
fn a_panicking_plugin_generator_is_a_scene_error() {
    let mut app = modesuite::make::default_app();
    app.load_plugin(lib("plugin-panics"))
        .expect("fixture loads");
    let desc = scene::parse_str(
        r#"Scene(objects: [(name: "x", shape: Gen(name: "fixture.panicking_shape", params: ()), body: Static)])"#,
        "<gen>",
    )
    .unwrap();
    let e = match app.compile_scene(&desc, &SceneSource::in_memory(".")) {
        Err(e) => e,
        Ok(_) => panic!("a panicking generator cannot compile"),
    };
    println!("{e}");
    assert!(matches!(e, SceneError::Semantic { .. }));
    assert!(
        e.to_string()
            .contains("panicked: fixture: generator panics"),
        "{e}"
    );
}

fn modesuite() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_modesuite"));
    c.current_dir(root());
    c
}

#[test]
fn cli_validates_and_runs_the_trefoil_scene_only_with_the_plugin() {
    let out = modesuite()
        .args(["validate", TREFOIL_SCENE])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("without --plugin: {stderr}");
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr.contains("unknown shape generator 'acme.trefoil'")
            && stderr.contains("`--plugin PATH`"),
        "{stderr}"
    );
    let plugin = lib("plugin-trefoil");
    let out = modesuite()
        .args(["validate", TREFOIL_SCENE, "--plugin"])
        .arg(&plugin)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = modesuite()
        .args(["run", TREFOIL_SCENE, "--steps", "2", "--json", "--plugin"])
        .arg(&plugin)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let first: serde_json::Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
    println!("{first}");
    let ret = first["return"].as_f64().unwrap();
    // Two steps of centroid height (about 0.5 m each) plus a tiny fall reward.
    assert!((ret - 1.0).abs() < 0.05, "return {ret}");
    assert!(first["error"].is_null());
    let out = modesuite()
        .args(["list", "terms", "--plugin"])
        .arg(&plugin)
        .output()
        .unwrap();
    let listing = String::from_utf8_lossy(&out.stdout);
    assert!(listing.contains("acme.fall_progress"), "{listing}");
}

#[test]
fn cli_refuses_bad_plugins_with_exit_code_2() {
    for (plugin, expected) in [
        (lib("plugin-bad-version"), "expects version"),
        (root().join("no/such.so"), "no such file"),
    ] {
        let out = modesuite()
            .args(["run", TREFOIL_SCENE, "--plugin"])
            .arg(&plugin)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert!(
            stderr.contains("--plugin: plugin ") && stderr.contains(expected),
            "{stderr}"
        );
    }
}

#[test]
fn scene_term_sections_name_unknown_terms_wrong_kinds_and_bad_params() {
    let app = |plugin: bool| {
        let mut app = modesuite::make::default_app();
        if plugin {
            app.load_plugin(lib("plugin-trefoil"))
                .expect("plugin loads");
        }
        app
    };
    let compile = |app: &SimApp, sections: &str| {
        let text = format!(
            r#"Scene(objects: [(name: "box", shape: Box(size: (0.1, 0.1, 0.1)), body: Dynamic())], {sections})"#
        );
        let desc = scene::parse_str(&text, "<terms>").unwrap();
        match app.compile_scene(&desc, &SceneSource::in_memory(".")) {
            Ok(_) => String::new(),
            Err(e) => e.to_string(),
        }
    };
    let without = app(false);
    let e = compile(
        &without,
        r#"rewards: [(term: "acme.centroid_height", params: (object: "box"))]"#,
    );
    println!("{e}");
    assert!(
        e.contains("rewards[0].term = \"acme.centroid_height\"") && e.contains("`--plugin PATH`"),
        "{e}"
    );
    let with = app(true);
    assert_eq!(
        compile(
            &with,
            r#"rewards: [(term: "acme.centroid_height", weight: 2.0, params: (object: "box"))]"#
        ),
        ""
    );
    let e = compile(
        &with,
        r#"rewards: [(term: "acme.centroid", params: (object: "box"))]"#,
    );
    assert!(
        e.contains("(a Observation term)") && e.contains("acme.fall_progress"),
        "{e}"
    );
    let e = compile(
        &with,
        r#"terminations: [(term: "acme.below", params: (object: "box"))]"#,
    );
    println!("{e}");
    assert!(e.contains("terminations[0] \"acme.below\".params"), "{e}");
    let e = compile(
        &with,
        r#"passive_forces: [(force: "acme.wind", objects: ["box"], params: (force: (1.0, 0.0, 0.0)))]"#,
    );
    assert!(
        e.contains("passive_forces[0].objects[0]")
            && e.contains("rigid bodies take no passive forces"),
        "{e}"
    );
}

/// One term registry for scenes and tasks: a compiled plugin's terms (engine terms, C ABI) work
/// in a task section, beside the task terms, with their plugin state; the reward they add is
/// the plugin's own figure.
#[test]
fn a_compiled_plugins_terms_work_in_a_task() {
    let dir = root().join("scenes/place");
    let text = std::fs::read_to_string(dir.join("franka.scene.ron")).unwrap();
    let from = r#"extends: "place.task.ron","#;
    assert!(text.contains(from));
    let text = text.replace(
        from,
        r#"extends: "place.task.ron",
            rewards: {"rod_height": (term: "acme.centroid_height", weight: 2.0, params: (object: "rod"))},
            terminations: {"rod_fell": (term: "acme.below", params: (object: "rod", z: -1.0))},"#,
    );
    let desc = scene::parse_str(&text, "<place with acme terms>").expect("parses");
    let source = SceneSource::in_memory(&dir);
    let mut app = modesuite::make::default_app();
    app.load_plugin(lib("plugin-trefoil"))
        .expect("plugin loads");
    let mut env = env_of(app, &desc, &source);
    env.reset(Some(0));
    let act = env.spaces().action.flat_dim();
    for step in 0..5 {
        let o = env.step(&vec![0.0; act]);
        assert!(o.info.error.is_none(), "{:?}", o.info.error);
        let term = o.info.values["reward/rod_height"];
        let z = centroid(&nodes_of(&mut env, "rod"))[2];
        println!("step {step}: reward/rod_height {term:.6} = 2 x rod centroid z {z:.6}");
        assert_eq!(term.to_bits(), (2.0 * z).to_bits());
        assert!(!o.terminated && !o.truncated);
    }
    // without the plugin the task names the missing term
    let bare = modesuite::make::default_app();
    let e = bare
        .compile_scene(&desc, &source)
        .err()
        .expect("the term is unknown without the plugin")
        .to_string();
    println!("{e}");
    assert!(e.contains("acme.centroid_height"), "{e}");
}

/// A compiled plugin's task event (C ABI) runs in a task section like the built-in events: at
/// reset, from the env's random stream (reproducible per seed), acting through the task's world
/// access; its errors end the episode with the plugin's message.
#[test]
fn a_compiled_plugins_event_works_in_a_task() {
    let dir = root().join("scenes/place");
    let text = std::fs::read_to_string(dir.join("franka.scene.ron")).unwrap();
    let from = r#"events: {"robot_start": RobotPose(xy: 0.1, yaw: 0.1, carry: ["rod"])},"#;
    assert!(text.contains(from));
    // keyed after robot_start, so the robot's start draws the same numbers as without it
    let with_event = |object: &str| {
        text.replace(
            from,
            &format!(
                r#"events: {{"robot_start": RobotPose(xy: 0.1, yaw: 0.1, carry: ["rod"]), "zz_nudge": Event(event: "acme.nudge", params: (object: "{object}", speed: 0.5))}},"#
            ),
        )
    };
    let source = SceneSource::in_memory(&dir);
    let plugin = DynamicPlugin::load(lib("plugin-trefoil")).expect("plugin loads");
    let run = |text: &str, seed: u64| -> (Vec<nalgebra::Vector3<f64>>, Option<String>) {
        let desc = scene::parse_str(text, "<place with acme.nudge>").expect("parses");
        let mut app = modesuite::make::default_app();
        app.add_dynamic_plugin(plugin.clone()).unwrap();
        let mut env = env_of(app, &desc, &source);
        env.autoreset = false;
        let (_, info) = env.reset(Some(seed));
        if info.error.is_some() {
            return (Vec::new(), info.error);
        }
        let act = env.spaces().action.flat_dim();
        for _ in 0..10 {
            let o = env.step(&vec![0.0; act]);
            assert!(o.info.error.is_none(), "{:?}", o.info.error);
        }
        (nodes_of(&mut env, "rod"), None)
    };
    let (plain, _) = run(&text, 0);
    let (nudged, err) = run(&with_event("rod"), 0);
    assert!(err.is_none(), "{err:?}");
    let (again, _) = run(&with_event("rod"), 0);
    let (other, _) = run(&with_event("rod"), 1);
    let (a, b) = (centroid(&plain), centroid(&nudged));
    let moved = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
    println!(
        "rod centroid after 10 steps: plain {a:.4?}, nudged {b:.4?} ({:.4} m apart horizontally; seed 1 {:.4?})",
        moved,
        centroid(&other)
    );
    assert!(moved > 1e-3, "the push moved the rod");
    assert_eq!(nudged, again, "same seed, same push");
    assert_ne!(nudged, other, "another seed, another push");
    // the plugin's error (an object the scene does not have) ends the reset with it
    let (_, err) = run(&with_event("nope"), 0);
    let err = err.expect("an unknown object is an error");
    println!("{err}");
    assert!(err.contains("nope"), "{err}");
    // bad parameters are a scene error at the event's place
    let desc = scene::parse_str(
        &with_event("rod").replace("speed: 0.5", "speed: -1.0"),
        "<bad nudge>",
    )
    .unwrap();
    let mut app = modesuite::make::default_app();
    app.add_dynamic_plugin(plugin.clone()).unwrap();
    let e = app
        .compile_scene(&desc, &source)
        .err()
        .expect("refused")
        .to_string();
    println!("{e}");
    assert!(e.contains("zz_nudge") && e.contains("speed = -1"), "{e}");
}
