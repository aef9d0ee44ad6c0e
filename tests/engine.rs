//! Engine integration tests: scenes, determinism, snapshots, schedule ambiguities, bad input,
//! environments and autoreset.

mod common;

use std::path::{Path, PathBuf};

use common::{app_from_ron, drop_scene, poke_app, poke_app_desc, root};
use modesuite::engine::scene::{self, SceneError};
use modesuite::engine::state::Snapshot;
use modesuite::prelude::*;

fn scene_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .expect("scenes/ is readable")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            scene_files(&p, out);
        } else if p.to_string_lossy().ends_with(".scene.ron") {
            out.push(p);
        }
    }
}

#[test]
fn every_scene_file_validates_compiles_and_steps() {
    let mut files = Vec::new();
    scene_files(&root().join("scenes"), &mut files);
    assert!(!files.is_empty(), "no scene files found under scenes/");
    for f in &files {
        let (desc, source) = scene::load_file(f).unwrap_or_else(|e| panic!("{e}"));
        let mut app = modesuite::make::default_app();
        let model = app
            .compile_scene(&desc, &source)
            .unwrap_or_else(|e| panic!("{e}"));
        app.spawn_scene(model).unwrap_or_else(|e| panic!("{e}"));
        let mut env = Env::new(app);
        env.reset(Some(0));
        let act = vec![0.0; env.spaces().action.flat_dim()];
        for _ in 0..10 {
            let o = env.step(&act);
            assert!(
                o.info.error.is_none(),
                "{}: {:?}",
                f.display(),
                o.info.error
            );
        }
        println!(
            "{}: {} objects, stepped 10 times",
            f.display(),
            desc.objects.len()
        );
    }
}

fn action_at(env: usize, step: usize) -> f32 {
    ((step as f32) * 0.05 + env as f32).sin()
}

fn run_vec(n_envs: usize, threads: usize, steps: usize) -> Vec<u64> {
    let scene = drop_scene();
    let mut v = VecEnv::build(n_envs, threads, |_| Ok::<_, String>(poke_app(&scene, None)))
        .expect("vec env");
    v.reset(Some(100));
    let mut actions = vec![0.0f32; n_envs];
    for s in 0..steps {
        for (e, a) in actions.iter_mut().enumerate() {
            *a = action_at(e, s);
        }
        v.step(&actions).expect("step");
    }
    v.state_hashes()
}

#[test]
fn determinism_same_seed_is_bit_identical_for_threads_and_env_counts() {
    let steps = 1000;
    // Single envs with the seeds env 0 and env 15 get in a 16-env run (seed + i).
    let single0 = run_vec(1, 1, steps)[0];
    let again0 = run_vec(1, 1, steps)[0];
    let one_thread = run_vec(16, 1, steps);
    let two_threads = run_vec(16, 2, steps);
    println!(
        "hash env0 single {single0:016x}, 16 envs/1 thread {:016x}, 16 envs/2 threads {:016x}",
        one_thread[0], two_threads[0]
    );
    assert_eq!(single0, again0, "same run twice");
    assert_eq!(one_thread, two_threads, "1 vs 2 threads");
    assert_eq!(single0, one_thread[0], "1 vs 16 envs");
    // Env 15 of the batch differs from env 0 (its seed and actions differ) ...
    assert_ne!(one_thread[0], one_thread[15]);
    // ... and equals a single env given env 15's seed and actions.
    let scene = drop_scene();
    let mut e = Env::new(poke_app(&scene, None));
    e.reset(Some(115));
    for s in 0..steps {
        e.step(&[action_at(15, s)]);
    }
    assert_eq!(e.state_hash(), one_thread[15], "env 15 alone");
}

#[test]
fn snapshot_restore_step_equals_uninterrupted_run() {
    let scene = drop_scene();
    let mut env = Env::new(poke_app(&scene, None));
    env.reset(Some(3));
    for s in 0..40 {
        env.step(&[action_at(0, s)]);
    }
    let snap = Snapshot::take(&env.app.world);
    let mut first = Vec::new();
    for s in 40..160 {
        env.step(&[action_at(0, s)]);
        first.push(env.state_hash());
    }
    snap.restore(&mut env.app.world)
        .expect("a snapshot of the same env restores");
    let mut second = Vec::new();
    for s in 40..160 {
        env.step(&[action_at(0, s)]);
        second.push(env.state_hash());
    }
    let diverged = first.iter().zip(&second).position(|(a, b)| a != b);
    println!("120 steps after restore; first divergence: {diverged:?} (expected None)");
    assert_eq!(first, second);
}

#[test]
fn schedules_have_no_ambiguities() {
    let mut app = poke_app(&drop_scene(), None);
    let amb = app.ambiguities();
    println!(
        "ambiguous system pairs: {} (expected 0) {amb:#?}",
        amb.len()
    );
    assert!(amb.is_empty());
}

#[test]
fn rapier_solver_settings_reach_the_rigid_world() {
    // rigid_iterations, rigid_pgs_iterations and rigid_friction_in_bias_pass become rapier's
    // integration parameters; without them, rapier's defaults (4, 1, false).
    for (text, want) in [
        ("Scene()", (4, 1, false)),
        (
            "Scene(physics: (rigid_iterations: 1, rigid_pgs_iterations: 8, rigid_friction_in_bias_pass: true))",
            (1, 8, true),
        ),
    ] {
        let app = app_from_ron(text);
        let p = &app.world.resource::<RigidContext>().params;
        let got = (
            p.num_solver_iterations,
            p.num_internal_pgs_iterations,
            p.friction_in_bias_pass,
        );
        println!("{text}: rapier (solver substeps, sweeps, friction in bias pass) = {got:?}");
        assert_eq!(got, want);
    }
}

#[test]
fn decimation_and_substeps_are_counted() {
    let text = r#"Scene(physics: (dt: 0.01, substeps: 3, decimation: 4))"#;
    let mut app = app_from_ron(text);
    for _ in 0..5 {
        app.step();
    }
    let c = *app.world.resource::<SimClock>();
    println!(
        "5 env steps -> {} physics steps, {} substeps, t = {}",
        c.physics_steps, c.substeps, c.time
    );
    assert_eq!(c.episode_steps, 5);
    assert_eq!(c.physics_steps, 20);
    assert_eq!(c.substeps, 60);
    assert!((c.time - 0.2).abs() < 1e-12);
}

fn compile_text(text: &str) -> Result<(), SceneError> {
    let desc = scene::parse_str(text, "test.scene.ron")?;
    let app = modesuite::make::default_app();
    let dir = root().join("scenes/examples");
    let source = SceneSource {
        file: Some(dir.join("test.scene.ron")),
        base_dir: dir,
        asset_roots: vec![root().join("assets")],
        text: Some(text.to_string()),
    };
    app.compile_scene(&desc, &source).map(|_| ())
}

#[test]
fn ron_errors_carry_line_and_column() {
    let text = "Scene(\n    objects: [\n        (name: \"a\", shape: Sphere(radius: 0.1), body: Static, colour: None),\n    ],\n)";
    let e = compile_text(text).unwrap_err();
    println!("{e}");
    match e {
        SceneError::Syntax {
            line,
            col,
            ref message,
            ..
        } => {
            assert_eq!(line, 3);
            assert!(col > 40, "column {col}");
            assert!(
                message.contains("colour") && message.contains("color"),
                "{message}"
            );
        }
        other => panic!("expected a syntax error, got {other}"),
    }
    let e =
        compile_text("Scene(objects: [(name: \"a\", shape: Sphere(radius: 0.1), body: Static)]")
            .unwrap_err();
    assert!(matches!(e, SceneError::Syntax { line: 1, .. }), "{e}");
    assert!(e.to_string().starts_with("test.scene.ron:1:"), "{e}");
}

fn expect_semantic(text: &str, path_part: &str, expected_part: &str) {
    let e = compile_text(text).expect_err("must be rejected");
    let s = e.to_string();
    println!("{s}");
    assert!(s.contains(path_part), "{s} should name {path_part}");
    assert!(s.contains(expected_part), "{s} should say {expected_part}");
}

#[test]
fn bad_input_is_reported_with_object_field_and_value() {
    let obj = |shape: &str, body: &str| {
        format!("Scene(objects: [(name: \"thing\", shape: {shape}, body: {body})])")
    };
    expect_semantic(
        &obj("Sphere(radius: NaN)", "Static"),
        "objects[0] \"thing\".shape.radius",
        "NaN",
    );
    expect_semantic(
        &obj("Box(size: (1.0, -2.0, 1.0))", "Static"),
        "objects[0] \"thing\".shape.size",
        "-2",
    );
    expect_semantic(
        &obj("Sphere(radius: inf)", "Dynamic()"),
        "shape.radius",
        "inf",
    );
    expect_semantic(
        &obj("Sphere(radius: 0.1)", "Dynamic(mass: Some(0.0))"),
        "body.mass",
        "> 0",
    );
    expect_semantic(
        &obj(
            "Sphere(radius: 0.1)",
            "Kind(kind: \"acme.goo\", params: ())",
        ),
        "body.kind",
        "--plugin",
    );
    expect_semantic(
        &obj("Plane(size: (1.0, 1.0))", "Dynamic()"),
        "body",
        "only be Static",
    );
    expect_semantic(
        &obj("Mesh(file: \"missing.obj\")", "Static"),
        "shape",
        "missing.obj",
    );
    expect_semantic(
        &obj("Mesh(file: \"../../../../etc/passwd.obj\")", "Static"),
        "shape",
        "passwd",
    );
    expect_semantic(
        &obj("Gen(name: \"acme.trefoil\", params: (turns: 3))", "Static"),
        "shape",
        "acme.trefoil",
    );
    expect_semantic(
        "Scene(objects: [(name: \"a\", shape: Sphere(radius: 0.1), body: Static), (name: \"a\", shape: Sphere(radius: 0.1), body: Static)])",
        "objects[1] \"a\".name",
        "unique",
    );
    expect_semantic(
        "Scene(objects: [(name: \"a\", shape: Sphere(radius: 0.1), body: Static, material: Some(\"steel\"))])",
        "material",
        "default",
    );
    expect_semantic("Scene(physics: (dt: 0.0))", "physics.dt", "0 < dt");
    expect_semantic(
        "Scene(physics: (gravity: (0.0, 0.0, NaN)))",
        "physics.gravity",
        "finite",
    );
    expect_semantic(
        "Scene(materials: {\"m\": (friction: -1.0)})",
        "materials[\"m\"].friction",
        ">= 0",
    );
    expect_semantic(
        "Scene(frames: {\"t\": (pos: (0.0, inf, 0.0))})",
        "frames[\"t\"].pos",
        "finite",
    );
    expect_semantic("Scene(episode_steps: Some(0))", "episode_steps", "positive");
    expect_semantic(
        "Scene(physics: (substeps: 4, deformable_substeps: Some(3)))",
        "physics.deformable_substeps",
        "divisor or multiple (at most 1000) of physics.substeps (4)",
    );
    expect_semantic(
        "Scene(physics: (substeps: 4, deformable_substeps: Some(6)))",
        "physics.deformable_substeps",
        "divisor or multiple",
    );
    compile_text("Scene(physics: (substeps: 4, deformable_substeps: Some(8)))")
        .unwrap_or_else(|e| panic!("a multiple of substeps is valid: {e}"));
    expect_semantic(
        "Scene(physics: (max_body_speed: -1.0))",
        "physics.max_body_speed",
        "above 0",
    );
    expect_semantic(
        "Scene(physics: (rigid_pgs_iterations: 0))",
        "physics.rigid_pgs_iterations",
        "1..=100",
    );
    expect_semantic(
        "Scene(physics: (substeps: 4, deformable_substeps: Some(0)))",
        "physics.deformable_substeps",
        "positive divisor",
    );
    // A float where an integer is expected gets a hint.
    let e = compile_text("Scene(physics: (substeps: 2.5))").unwrap_err();
    println!("{e}");
    assert!(matches!(e, SceneError::Syntax { .. }));
    assert!(
        e.to_string()
            .ends_with("Expected comma (hint: a float where an integer is expected, e.g. `4.0` for a count, also reads like this)"),
        "{e}"
    );
}

#[test]
fn a_torus_of_any_radii_is_written_in_ron_and_becomes_a_static_ring() {
    for (r_major, r_minor, seg) in [(0.3, 0.05, 24), (1.2, 0.2, 40), (0.05, 0.01, 12)] {
        let text = format!(
            "Scene(objects: [(name: \"ring\", shape: Revolve(profile: Circle(radius: {r_minor}, segments: 12), radius: {r_major}, segments: {seg}), body: Static)])"
        );
        compile_text(&text).unwrap_or_else(|e| panic!("{e}"));
    }
}

#[test]
fn non_finite_action_never_reaches_the_solver_and_ends_the_episode() {
    let mut env = Env::new(poke_app(&drop_scene(), None));
    env.reset(Some(0));
    env.step(&[0.5]);
    let before = env.app.world.resource::<SimClock>().physics_steps;
    let o = env.step(&[f32::NAN]);
    println!(
        "NaN action -> truncated {}, error {:?}",
        o.truncated, o.info.error
    );
    assert!(o.truncated && !o.terminated);
    let err = o.info.error.clone().expect("error in info");
    assert!(err.contains("NaN"), "{err}");
    assert_eq!(env.error_count, 1);
    let stats = o.info.episode.expect("episode stats");
    assert!(stats.error);
    assert_eq!(stats.length, 1, "the NaN step was not simulated");
    // Autoreset happened; the physics step count of the finished episode did not grow.
    assert_eq!(before, 1);
    assert_eq!(env.app.world.resource::<SimClock>().episode_steps, 0);
    // Wrong length is an error too.
    let o = env.step(&[0.1, 0.2]);
    assert!(o.info.error.unwrap().contains("length 2"));
}

/// Steps the zero action until an episode is truncated (at most `max` steps): the step's
/// number (from 1), its error and its reward.
fn step_until_truncated(env: &mut Env, max: u64) -> Option<(u64, Option<String>, f64)> {
    (1..=max).find_map(|i| {
        let o = env.step(&[0.0]);
        o.truncated.then(|| (i, o.info.error.clone(), o.reward))
    })
}

#[test]
fn physics_blow_up_ends_the_episode_with_a_reason_not_the_process() {
    let mut env = Env::new(poke_app(&drop_scene(), Some(3)));
    env.reset(Some(0));
    let ended = step_until_truncated(&mut env, 10);
    println!("blow-up: {ended:?}");
    let (step, err, reward) = ended.expect("the episode ended");
    // poisoned once 3 env steps have run: the 4th fails
    assert_eq!(step, 4);
    assert_eq!(reward, 0.0, "a failed step's reward is 0");
    assert!(err.expect("error").contains("non-finite"));
    // The env goes on after the autoreset.
    let o = env.step(&[0.0]);
    assert!(o.info.error.is_none());
    assert!(o.observation.iter().all(|x| x.is_finite()));
}

#[test]
fn a_body_faster_than_max_body_speed_ends_the_episode_naming_it() {
    // Rapier flags only non-finite states; a body flung at finite, absurd speeds is caught by
    // `physics.max_body_speed`. Here the limit is 2 m/s, which the falling box and ball pass
    // together at t = 2 / 9.81 = 0.204 s (the 13th step of 1/60 s), before either lands.
    let (mut desc, source) = scene::load_file(&drop_scene()).unwrap();
    desc.physics.max_body_speed = 2.0;
    let mut env = Env::new(poke_app_desc(&desc, &source, None));
    env.reset(Some(0));
    let ended = step_until_truncated(&mut env, 30);
    println!("max_body_speed 2 m/s: {ended:?} (expected at step 13)");
    let (step, err, reward) = ended.expect("the episode ended");
    assert_eq!(step, 13);
    assert_eq!(reward, 0.0);
    let err = err.expect("error");
    assert!(err.contains("physics.max_body_speed = 2 m/s"), "{err}");
    assert!(err.contains("\"box\"") || err.contains("\"ball\""), "{err}");
    // The default (100 m/s) lets the same scene run to rest.
    let mut env = Env::new(poke_app(&drop_scene(), None));
    env.reset(Some(0));
    for _ in 0..120 {
        assert!(env.step(&[0.0]).info.error.is_none());
    }
}

#[test]
fn same_step_autoreset_keeps_final_observation_and_info() {
    let (mut desc, source) = scene::load_file(&drop_scene()).unwrap();
    desc.episode_steps = Some(5);
    let mut env = Env::new(poke_app_desc(&desc, &source, None));
    let (obs0, _) = env.reset(Some(1));
    assert_eq!(obs0[1], 0.0);
    let mut last = None;
    for _ in 0..5 {
        last = Some(env.step(&[0.0]));
    }
    let o = last.unwrap();
    println!(
        "step 5: truncated {}, obs {:?}, final obs {:?}",
        o.truncated, o.observation, o.info.final_observation
    );
    assert!(o.truncated && !o.terminated);
    assert_eq!(o.observation[1], 0.0, "observation of the new episode");
    assert_eq!(o.info.final_observation.as_ref().unwrap()[1], 5.0);
    let fi = o.info.final_info.as_ref().unwrap();
    assert!(fi.values.contains_key("height"));
    let ep = o.info.episode.unwrap();
    assert_eq!(ep.length, 5);
    assert!((ep.r#return - (0..5).map(|_| 0.0).sum::<f64>()).abs() >= 0.0);
}

#[test]
fn vec_env_checks_buffer_sizes_and_reports_spaces() {
    let scene = drop_scene();
    let mut v = VecEnv::build(3, 1, |_| Ok::<_, String>(poke_app(&scene, None))).unwrap();
    assert_eq!(v.spaces().action.flat_dim(), 1);
    assert_eq!(v.spaces().observation.flat_dim(), 2);
    let (obs, infos) = v.reset(Some(0));
    assert_eq!(obs.len(), 6);
    assert_eq!(infos.len(), 3);
    let e = v.step(&[0.0; 2]).unwrap_err();
    println!("{e}");
    assert!(e.to_string().contains("3 envs x 1"));
    let s = v.step(&[0.0; 3]).unwrap();
    assert_eq!(s.observations.len(), 6);
    assert_eq!(s.rewards.len(), 3);
}

#[test]
fn discrete_spaces_reject_out_of_range_values() {
    let s = Space::Dict(vec![
        ("move".into(), Space::Discrete { n: 14 }),
        ("gain".into(), Space::unbounded(2)),
    ]);
    assert_eq!(s.flat_dim(), 3);
    assert!(s.check(&[13.0, 0.5, -3.0]).is_ok());
    assert!(s.check(&[14.0, 0.5, -3.0]).is_err());
    assert!(s.check(&[2.5, 0.5, -3.0]).is_err());
    assert!(s.check(&[2.0, f32::INFINITY, -3.0]).is_err());
}

#[test]
fn coupling_query_finds_closest_points_normals_and_bodies() {
    use modesuite::engine::coupling::ContactQuery;
    let text = r#"Scene(objects: [
        (name: "ground", shape: Plane(size: (4.0, 4.0)), body: Static),
        (name: "cube", shape: Box(size: (0.5, 0.5, 0.5)), pose: (pos: (0.0, 0.0, 1.0)), body: Dynamic()),
    ])"#;
    let app = app_from_ron(text);
    let rigid = app.world.resource::<RigidContext>();
    let mut out = Vec::new();
    // Above the cube's top face (z = 1.25), before any step.
    rigid.contacts_near(&nalgebra::Vector3::new(0.1, 0.0, 1.3), 0.1, &mut out);
    println!("above the cube: {out:?}");
    assert_eq!(out.len(), 1);
    assert!((out[0].distance - 0.05).abs() < 1e-5);
    assert!((out[0].normal - nalgebra::Vector3::z()).norm() < 1e-5);
    assert_ne!(out[0].body, u32::MAX);
    // Inside the cube near its +x face: negative distance, normal +x.
    out.clear();
    rigid.contacts_near(&nalgebra::Vector3::new(0.2, 0.0, 1.0), 0.2, &mut out);
    assert_eq!(out.len(), 1);
    assert!((out[0].distance + 0.05).abs() < 1e-5, "{out:?}");
    assert!((out[0].normal - nalgebra::Vector3::x()).norm() < 1e-5);
    // Exactly on the ground: zero distance, normal +z from the gradient.
    out.clear();
    rigid.contacts_near(&nalgebra::Vector3::new(1.5, 1.5, 0.0), 0.05, &mut out);
    assert_eq!(out.len(), 1);
    assert!(out[0].distance.abs() < 1e-6);
    assert!(
        (out[0].normal - nalgebra::Vector3::z()).norm() < 1e-3,
        "{out:?}"
    );
    // Far from everything: nothing.
    out.clear();
    rigid.contacts_near(&nalgebra::Vector3::new(0.0, 0.0, 3.0), 0.1, &mut out);
    assert!(out.is_empty());
}

#[test]
fn body_pose_between_interpolates_the_last_rigid_step() {
    // A spinning, drifting cube without gravity: halfway through a step it is halfway between
    // its poses before and after it; the end of the step is the current pose exactly, and a
    // body moved outside a step (a reset) has nothing to interpolate from.
    let text = r#"Scene(physics: (dt: 0.01, substeps: 1, gravity: (0.0, 0.0, 0.0)), objects: [
        (name: "cube", shape: Box(size: (0.2, 0.2, 0.2)), pose: (pos: (0.3, -0.1, 1.0), rpy: (0.2, 0.1, 0.3)),
         body: Dynamic(linear_velocity: (0.5, -0.2, 0.1), angular_velocity: (0.0, 0.0, 2.0))),
    ])"#;
    let mut env = Env::new(app_from_ron(text));
    env.autoreset = false;
    env.reset(Some(0));
    let id = 0;
    let pose = |env: &Env, s: Option<f64>| {
        let rigid = env.app.world.resource::<RigidContext>();
        match s {
            Some(s) => rigid.body_pose_between(id, s).unwrap(),
            None => rigid.body_pose(id).unwrap(),
        }
    };
    let before = pose(&env, None);
    assert_eq!(
        pose(&env, Some(0.0)),
        before,
        "after a reset: the current pose"
    );
    env.step(&[]);
    let after = pose(&env, None);
    assert_eq!(pose(&env, Some(1.0)), after);
    let start = pose(&env, Some(0.0));
    let mid = pose(&env, Some(0.5));
    let d0 = (start.translation.vector - before.translation.vector).norm();
    let dm = (mid.translation.vector
        - (before.translation.vector + after.translation.vector) / 2.0)
        .norm();
    let am =
        mid.rotation.angle_to(&before.rotation) - 0.5 * after.rotation.angle_to(&before.rotation);
    println!(
        "step start vs pose before the step {d0:.1e} m (tol 1e-6), midpoint {dm:.1e} m (tol 1e-9), half turn {am:.1e} rad (tol 1e-9); moved {:.4} m",
        (after.translation.vector - before.translation.vector).norm()
    );
    assert!(d0 < 1e-6 && dm < 1e-9 && am.abs() < 1e-9);
    assert!((after.translation.vector - before.translation.vector).norm() > 0.005);
}

#[test]
fn region_queries_return_the_same_contacts_in_the_same_order() {
    use modesuite::engine::coupling::ContactQuery;
    let text = r#"Scene(objects: [
        (name: "ground", shape: Plane(size: (4.0, 4.0)), body: Static),
        (name: "table", shape: Box(size: (1.0, 0.8, 0.05)), pose: (pos: (0.0, 0.0, 0.5)), body: Static),
        (name: "cube", shape: Box(size: (0.2, 0.2, 0.2)), pose: (pos: (0.3, 0.1, 0.65)), body: Dynamic()),
        (name: "ball", shape: Sphere(radius: 0.1), pose: (pos: (-0.3, -0.2, 0.62)), body: Static),
        (name: "far", shape: Box(size: (0.2, 0.2, 0.2)), pose: (pos: (3.0, 3.0, 0.1)), body: Static),
    ])"#;
    let mut app = app_from_ron(text);
    app.world.resource_mut::<RigidContext>().refresh_queries();
    let rigid = app.world.resource::<RigidContext>();
    let (lo, hi) = (
        nalgebra::Vector3::new(-0.8, -0.6, -0.1),
        nalgebra::Vector3::new(0.8, 0.6, 1.0),
    );
    let region = rigid
        .region(&lo, &hi)
        .expect("a refreshed context narrows queries");
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let mut compared = 0;
    let mut found = 0;
    for i in 0..13 {
        for j in 0..9 {
            for k in 0..11 {
                let r = 0.02 + 0.01 * ((i + j + k) % 5) as f64;
                let p = nalgebra::Vector3::new(
                    -0.7 + 0.115 * i as f64,
                    -0.5 + 0.12 * j as f64,
                    -0.05 + 0.095 * k as f64,
                );
                if (0..3).any(|c| p[c] - r < lo[c] || p[c] + r > hi[c]) {
                    continue;
                }
                a.clear();
                b.clear();
                rigid.contacts_near(&p, r, &mut a);
                region.contacts_near(&p, r, &mut b);
                assert_eq!(a, b, "at {p:?} within {r}");
                compared += 1;
                found += a.len();
            }
        }
    }
    println!("{compared} points compared, {found} contacts, all identical");
    assert!(compared > 500 && found > 100);
}

#[test]
fn reactions_push_dynamic_bodies() {
    use modesuite::engine::coupling::Reaction;
    let text = r#"Scene(physics: (gravity: (0.0, 0.0, 0.0)), objects: [
        (name: "cube", shape: Box(size: (0.1, 0.1, 0.1)), body: Dynamic(mass: Some(2.0))),
    ])"#;
    let mut app = app_from_ron(text);
    {
        let mut rigid = app.world.resource_mut::<RigidContext>();
        rigid.push_reaction(Reaction {
            body: 0,
            point: nalgebra::Vector3::zeros(),
            impulse: nalgebra::Vector3::new(0.4, 0.0, 0.0),
        });
    }
    app.step();
    app.step();
    let rigid = app.world.resource::<RigidContext>();
    let (h, _) = rigid.body_of_id(0).unwrap();
    let v = rigid.bodies[h].linvel();
    println!("velocity after a 0.4 N s impulse on 2 kg: {v:?} (expected 0.2 m/s along x)");
    assert!((f64::from(v.x) - 0.2).abs() < 1e-4);
}

#[test]
fn reactions_do_not_erase_forces_set_by_controllers() {
    use modesuite::engine::coupling::Reaction;
    use modesuite::engine::math::vec_to_rapier;
    let text = r#"Scene(physics: (gravity: (0.0, 0.0, 0.0), substeps: 4), objects: [
        (name: "cube", shape: Box(size: (0.1, 0.1, 0.1)), body: Dynamic(mass: Some(1.0))),
    ])"#;
    let mut app = app_from_ron(text);
    let mut rigid = app.world.resource_mut::<RigidContext>();
    let (h, _) = rigid.body_of_id(0).unwrap();
    // A controller's persistent force of 1 N along y, and one reaction of 0.01 N s along x.
    rigid.bodies[h].add_force(vec_to_rapier(&nalgebra::Vector3::new(0.0, 1.0, 0.0)), true);
    rigid.push_reaction(Reaction {
        body: 0,
        point: nalgebra::Vector3::zeros(),
        impulse: nalgebra::Vector3::new(0.01, 0.0, 0.0),
    });
    let dt = 0.25 / 60.0;
    for _ in 0..4 {
        rigid.step(dt).unwrap();
    }
    let v = rigid.bodies[h].linvel();
    let f = rigid.bodies[h].user_force();
    println!("after 4 substeps: v = {v:?} (x 0.01 from the reaction once, y 4 dt = {:.5}), force kept {f:?}", 4.0 * dt);
    assert!((f64::from(v.x) - 0.01).abs() < 1e-6);
    assert!((f64::from(v.y) - 4.0 * dt).abs() < 1e-6);
    assert!((f64::from(f.y) - 1.0).abs() < 1e-6 && f.x.abs() < 1e-6);
}
