//! The MoDeSuite task environments: spaces, action modes, success and rewards on constructed
//! states, reset randomisation, episode ends, the scripted expert, and task-section errors.

use bevy_ecs::entity::Entity;
use modesuite::engine::scene::{SceneDesc, SceneSource};
use modesuite::engine::{Env, RigidContext, Space};
use modesuite::robots::Robots;
use modesuite::tasks::{make_policy, PolicyKind, TaskPoints, TaskState};
use nalgebra::Vector3;

const PLACE: &str = "MoDe-Franka-Place-v0";

fn load(id: &str, actions: Option<&str>) -> (SceneDesc, SceneSource) {
    let (mut desc, source) = modesuite::make::load_target(id).unwrap_or_else(|e| panic!("{e}"));
    if let Some(a) = actions {
        modesuite::make::override_actions(&mut desc, a).unwrap_or_else(|e| panic!("{e}"));
    }
    (desc, source)
}

fn make(id: &str, actions: Option<&str>) -> Env {
    let (desc, source) = load(id, actions);
    let mut app = modesuite::make::default_app();
    let model = app
        .compile_scene(&desc, &source)
        .unwrap_or_else(|e| panic!("{e}"));
    app.spawn_scene(model).unwrap_or_else(|e| panic!("{e}"));
    let mut env = Env::new(app);
    env.reset(Some(0));
    env
}

fn point(env: &Env, name: &str) -> Vector3<f64> {
    env.app.world.resource::<TaskPoints>().0[name]
}

fn base(env: &Env) -> nalgebra::Isometry3<f64> {
    let r = &env.app.world.resource::<Robots>().robots[0];
    r.observe(env.app.world.resource::<RigidContext>())
        .unwrap()
        .base
}

fn scene_error(text: &str) -> String {
    scene_error_in("place", text)
}

/// The error of compiling and spawning `text`, a scene in scenes/`task`.
fn scene_error_in(task: &str, text: &str) -> String {
    let desc = modesuite::engine::scene::parse_str(text, "<test>").unwrap();
    let mut app = modesuite::make::default_app();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(task);
    match app
        .compile_scene(&desc, &SceneSource::in_memory(dir))
        .and_then(|m| app.spawn_scene(m))
    {
        Ok(_) => panic!("the scene compiled and spawned: {text}"),
        Err(e) => e.to_string(),
    }
}

/// The Franka scene file of `task` (its folder under scenes/) with `from` replaced by `to`.
fn task_text(task: &str, from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("scenes")
            .join(task)
            .join("franka.scene.ron"),
    )
    .unwrap();
    assert!(text.contains(from), "{from}");
    text.replace(from, to)
}

/// An app with `text` (a scene in scenes/`task`) compiled and spawned.
fn task_app(task: &str, text: &str) -> modesuite::engine::SimApp {
    let desc = modesuite::engine::scene::parse_str(text, "<test>").unwrap();
    let mut app = modesuite::make::default_app();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(task);
    let model = app
        .compile_scene(&desc, &SceneSource::in_memory(dir))
        .unwrap_or_else(|e| panic!("{e}"));
    app.spawn_scene(model).unwrap_or_else(|e| panic!("{e}"));
    app
}

/// The Franka Place scene file with `from` replaced by `to`.
fn place_text(from: &str, to: &str) -> String {
    task_text("place", from, to)
}

/// An app with `text` (a scene in scenes/place) compiled and spawned.
fn place_app(text: &str) -> modesuite::engine::SimApp {
    task_app("place", text)
}

#[test]
fn extends_cannot_leave_the_scene_folder() {
    for bad in [
        "../place/place.task.ron",
        "/etc/passwd",
        "sub/../../x.task.ron",
        "place.ron",
    ] {
        let text = format!(
            "(objects: [(name: \"ground\", shape: Plane(size: (2.0, 2.0)), body: Static)],
              extensions: {{\"task\": (extends: \"{bad}\")}})"
        );
        let e = match modesuite::make::env_from_text(&text) {
            Ok(_) => panic!("{bad}: accepted"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains("without `..`") && e.contains(bad), "{bad}: {e}");
    }
}

/// The task ids users see (`modesuite list tasks`, Python's `TASK_IDS`) are exactly the task
/// folders' scene files, `scenes/<task>/<robot>.scene.ron` in each folder holding a
/// `<task>.task.ron`; they are the 16 environments of the design (8 tasks for each of the Franka
/// and the Spot), all implemented; each id resolves to its file, which is also embedded (with its
/// task file) for installs without the scenes folder; a misspelt id says what is valid.
#[test]
fn ids_are_the_task_folders_scene_files_and_each_resolves() {
    use modesuite::tasks::{all_ids, embedded, parse_id, task_scene_path, IMPLEMENTED};
    use std::collections::{BTreeMap, BTreeSet};
    let scenes = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let capital = |s: &str| s[..1].to_uppercase() + &s[1..];
    let mut from_files = BTreeSet::new();
    for dir in std::fs::read_dir(&scenes).unwrap() {
        let dir = dir.unwrap().path();
        let task = dir.file_name().unwrap().to_str().unwrap().to_string();
        if !dir.join(format!("{task}.task.ron")).is_file() {
            continue;
        }
        for file in std::fs::read_dir(&dir).unwrap() {
            let name = file.unwrap().file_name().into_string().unwrap();
            if let Some(robot) = name.strip_suffix(".scene.ron") {
                from_files.insert(format!("MoDe-{}-{}-v0", capital(robot), capital(&task)));
            }
        }
    }
    let listed = all_ids();
    let ids: BTreeSet<String> = listed.iter().cloned().collect();
    assert_eq!(ids.len(), listed.len(), "an id is listed twice: {listed:?}");
    assert_eq!(
        ids, from_files,
        "listed ids vs the task folders' scene files"
    );
    let implemented: BTreeSet<String> = IMPLEMENTED.iter().map(|s| s.to_string()).collect();
    assert_eq!(implemented, ids, "implemented vs listed ids");
    let mut tasks_of: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
    for id in &ids {
        let (robot, task) = parse_id(id).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(format!("MoDe-{robot}-{task}-v0"), *id);
        tasks_of.entry(robot).or_default().insert(task);
        let file = task_scene_path(&scenes, id).unwrap_or_else(|e| panic!("{e}"));
        assert!(file.is_file(), "{id}: {}", file.display());
        let rel = file.strip_prefix(&scenes).unwrap().to_str().unwrap();
        let task_file = format!("{0}/{0}.task.ron", task.to_lowercase());
        for f in [rel, task_file.as_str()] {
            assert!(
                embedded(f).is_some(),
                "{id}: {f} is not in modesuite_tasks::EMBEDDED"
            );
        }
        if let Err(e) = modesuite::make::load_target(id) {
            panic!("{id}: {e}");
        }
    }
    // The design (SPEC.md, "Tasks (8 tasks x 2 robots = 16 environments)"): the Franka and the
    // Spot, each with the same 8 tasks.
    let robots: Vec<&str> = tasks_of.keys().copied().collect();
    assert_eq!(robots, ["Franka", "Spot"]);
    for (robot, tasks) in &tasks_of {
        assert_eq!(tasks.len(), 8, "{robot}: {tasks:?}");
        assert_eq!(tasks, &tasks_of["Franka"], "{robot}");
    }
    let e = modesuite::make::load_target("MoDe-Franka-Plase-v0")
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("Place") && e.contains("Franka"), "{e}");
}

#[test]
fn observation_and_action_sizes_match_docs_tasks_md() {
    // docs/tasks.md: (id, observation, default action).
    for (id, obs, act) in [
        ("MoDe-Franka-Place-v0", 43, 9),
        ("MoDe-Spot-Place-v0", 41, 9),
        ("MoDe-Franka-Curtain-v0", 43, 10),
        ("MoDe-Spot-Curtain-v0", 41, 10),
        ("MoDe-Franka-Bend-v0", 43, 9),
        ("MoDe-Spot-Bend-v0", 41, 9),
        ("MoDe-Franka-Transport-v0", 43, 9),
        ("MoDe-Spot-Transport-v0", 41, 9),
        ("MoDe-Franka-Drag-v0", 43, 9),
        ("MoDe-Spot-Drag-v0", 41, 9),
        ("MoDe-Franka-Lift-v0", 43, 10),
        ("MoDe-Spot-Lift-v0", 41, 10),
        ("MoDe-Franka-Uncover-v0", 46, 10),
        ("MoDe-Spot-Uncover-v0", 44, 10),
        ("MoDe-Franka-Cover-v0", 46, 10),
        ("MoDe-Spot-Cover-v0", 44, 10),
    ] {
        let env = make(id, None);
        let s = env.spaces();
        assert_eq!(
            (s.observation.flat_dim(), s.action.flat_dim()),
            (obs, act),
            "{id}"
        );
        assert_eq!(env.observation().len(), obs);
    }
}

#[test]
fn place_spaces_match_the_documented_layout() {
    let env = make(PLACE, None);
    let s = env.spaces();
    // docs/tasks.md: base xy 2 + quaternion 4 + (7 arm + gripper) x 2 + 4 tracked x 3 + 3 targets x 3.
    assert_eq!(s.observation.flat_dim(), 2 + 4 + 16 + 12 + 9);
    match &s.action {
        Space::Dict(items) => {
            let dims: Vec<(&str, usize)> = items
                .iter()
                .map(|(n, s)| (n.as_str(), s.flat_dim()))
                .collect();
            assert_eq!(dims, [("robot/base", 3), ("robot/arm", 6)]);
        }
        other => panic!("{other:?}"),
    }
    let o = env.observation();
    let b = base(&env);
    assert_eq!(o.len(), 43);
    assert!((f64::from(o[0]) - b.translation.x).abs() < 1e-6);
    let table = point(&env, "table");
    assert!((f64::from(o[34]) - table.x).abs() < 1e-6 && (f64::from(o[36]) - table.z).abs() < 1e-6);
}

/// Teleports the Franka's holonomic base (virtual joints, world x, y with the robot spawned at
/// the origin).
fn set_base(env: &mut Env, x: f64, y: f64) {
    let f = env.app.world.resource::<Robots>().robots[0].fixed.clone();
    let b = f.base.unwrap();
    let mut ctx = env.app.world.resource_mut::<RigidContext>();
    let mut q = f.robot.joint_positions(&ctx).unwrap();
    q[b.x] = x;
    q[b.y] = y;
    q[b.yaw] = 0.0;
    f.robot.set_joint_positions(&mut ctx, &q).unwrap();
}

#[test]
fn curtain_success_and_frame_contact_on_constructed_states() {
    const CURTAIN: &str = "MoDe-Franka-Curtain-v0";
    let zero = [0.0f32; 10];
    for (x, y, success, touched) in [
        (2.2, 0.0, true, false),  // through
        (1.9, 0.0, false, false), // near miss: 0.1 m short
        (1.5, 0.45, false, true), // against the right post (y = 0.6)
    ] {
        let mut env = make(CURTAIN, None);
        set_base(&mut env, x, y);
        let o = env.step(&zero);
        let contact = o.info.values["termination/touched_frame"];
        println!(
            "base at ({x}, {y}): success {:?}, frame contact {contact}",
            o.info.success
        );
        assert_eq!(o.info.success, Some(success));
        assert_eq!(contact != 0.0, touched);
        assert_eq!(o.terminated, success || touched);
        assert_eq!(o.reward, if success { 1.0 } else { 0.0 });
    }
}

#[test]
fn uncover_success_needs_the_table_cleared_and_the_handle_pulled_out() {
    const UNCOVER: &str = "MoDe-Franka-Uncover-v0";
    let zero = [0.0f32; 10];
    // the cover is spawned flat at z 0.754 over x 1.0 .. 2.6, y -0.6 .. 0.6 (+- its offset);
    // each case moves it rigidly by (dx, dy, dz)
    for (d, success, cleared, out) in [
        // on the table: neither
        ((0.0, 0.0, 0.0), false, false, false),
        // beside the table on the floor, handle at x ~ 0.0: success
        ((-1.0, 1.5, -0.75), true, true, true),
        // pulled 1.2 m: handle at x ~ -0.2 but 6 of 41 columns (10 %) still over the top
        ((-1.2, 0.0, 0.0), false, false, true),
        // beside the table on the floor, handle not pulled out (x ~ 1.0 > 0.9)
        ((0.0, 1.5, -0.75), false, true, false),
    ] {
        let mut env = make(UNCOVER, None);
        translate_cloth(&mut env, |_| Vector3::new(d.0, d.1, d.2));
        let o = env.step(&zero);
        let v = &o.info.values;
        println!(
            "cover moved by {d:?}: success {:?}, uncovered {}, handle out {}",
            o.info.success, v["success/uncovered"], v["success/handle_out"]
        );
        assert_eq!(v["success/uncovered"] != 0.0, cleared, "{d:?}");
        assert_eq!(v["success/handle_out"] != 0.0, out, "{d:?}");
        assert_eq!(o.info.success, Some(success));
        assert_eq!(o.terminated, success);
        assert_eq!(o.reward, if success { 1.0 } else { 0.0 });
    }
}

/// Moves the scene's (first) cloth rigidly by the offset `by` computes from its positions.
fn translate_cloth(env: &mut Env, by: impl Fn(&[Vector3<f64>]) -> Vector3<f64>) {
    let mut ctx = env.app.world.resource_mut::<modesuite::pbd::PbdContext>();
    let cloth = &mut ctx.bodies[0].solver;
    let d = by(cloth.positions());
    let moved: Vec<_> = cloth.positions().iter().map(|p| p + d).collect();
    cloth.set_positions(&moved).unwrap();
}

#[test]
fn cover_success_needs_the_gap_spanned_and_the_handle_on_the_second_cube() {
    const COVER: &str = "MoDe-Franka-Cover-v0";
    let zero = [0.0f32; 10];
    // the fabric is spawned flat on the floor over x 0.4 .. 1.2, y -1.1 .. -0.5 (+- its
    // offset), its handle at the corner (1.2, -0.5); each case moves it rigidly, handle first
    for (handle, success, covered, on_cube) in [
        // handle at (1.64, 0.35, 0.31): the fabric spans x 0.84 .. 1.64, y -0.25 .. 0.35 on
        // the cube tops: 97 % of the gap's x range
        ((1.64, 0.35, 0.31), true, true, true),
        // fabric centred over the gap, handle beyond the cube's top (x 1.8 + 0.1)
        ((1.9, 0.3, 0.31), false, true, false),
        // handle on the cube but the fabric reaches only x 1.45: a third of the gap open
        ((1.45, 0.35, 0.31), false, false, true),
    ] {
        let mut env = make(COVER, None);
        // the handle corner is the particle with the largest x + y
        translate_cloth(&mut env, |pos| {
            let h = pos
                .iter()
                .copied()
                .max_by(|a, b| (a.x + a.y).total_cmp(&(b.x + b.y)))
                .unwrap();
            Vector3::new(handle.0, handle.1, handle.2) - h
        });
        let o = env.step(&zero);
        let v = &o.info.values;
        println!(
            "handle moved to {handle:?}: success {:?}, gap covered {}, handle on cube {}",
            o.info.success, v["success/gap_covered"], v["success/handle_on_cube"]
        );
        assert_eq!(v["success/gap_covered"] != 0.0, covered, "{handle:?}");
        assert_eq!(v["success/handle_on_cube"] != 0.0, on_cube, "{handle:?}");
        assert_eq!(o.info.success, Some(success));
        assert_eq!(o.reward, if success { 1.0 } else { 0.0 });
    }
}

#[test]
fn route_legs_with_bad_hand_goals_are_refused_with_the_leg() {
    for (from, to, expect) in [
        (
            r#"hand_at: "handle", hand_tolerance: 0.015"#,
            r#"hand_at: "handel", hand_tolerance: 0.015"#,
            r#"extensions["task"].route[4].hand_at = "handel": a point or target of the task"#,
        ),
        (
            "hand_tolerance: 0.015",
            "hand_tolerance: -0.015",
            r#"extensions["task"].route[4].hand_tolerance = -0.015: a positive number"#,
        ),
        (
            "hand_rpy: (180.0, -50.0, 0.0)",
            "hand_rpy: (180.0, inf, 0.0)",
            r#"extensions["task"].route[0].hand_rpy = (180, inf, 0): finite"#,
        ),
    ] {
        // Refused when the scene compiles (so `modesuite validate` reports it).
        let e = scene_error_in("uncover", &task_text("uncover", from, to));
        println!("{e}");
        assert!(e.contains(expect), "{e}");
    }
}

#[test]
fn transport_goal_moves_from_t1_to_t2_once_the_base_reaches_t1() {
    let mut env = make("MoDe-Franka-Transport-v0", None);
    let zero = [0.0f32; 9];
    let goal = |env: &Env| point(env, "goal");
    assert_eq!(goal(&env), point(&env, "t1"), "T1 first");
    // T1 0.6 m from the base: not reached; the reward measures to T1.
    let b = base(&env).translation.vector;
    env.app.world.resource_mut::<TaskState>().targets[0] = b + Vector3::new(0.6, 0.0, 0.0);
    let o = env.step(&zero);
    let (b, end, g) = (
        base(&env).translation.vector,
        point(&env, "rod_end"),
        goal(&env),
    );
    assert_eq!(g, point(&env, "t1"));
    let hand = -((end - g).xy().norm() + (b - g).xy().norm());
    println!(
        "T1 0.6 m away: reward {:.6}, hand-computed {hand:.6}",
        o.reward
    );
    assert!((o.reward - hand).abs() < 1e-9);
    // T1 0.3 m from the base: reached, the goal is T2 from this step on.
    env.app.world.resource_mut::<TaskState>().targets[0] = b + Vector3::new(0.3, 0.0, 0.0);
    env.step(&zero);
    assert_eq!(goal(&env), point(&env, "t2"), "T2 after T1 is reached");
    assert_eq!(env.app.world.resource::<TaskState>().stages, vec![1]);
    // Moving T1 away again does not bring it back (progress is kept) ...
    env.app.world.resource_mut::<TaskState>().targets[0] = Vector3::new(-5.0, 0.0, 0.0);
    env.step(&zero);
    assert_eq!(goal(&env), point(&env, "t2"));
    // ... until the next reset.
    env.reset(Some(1));
    assert_eq!(env.app.world.resource::<TaskState>().stages, vec![0]);
    assert_eq!(goal(&env), point(&env, "t1"));
}

#[test]
fn bend_and_drag_success_need_every_condition() {
    // Bend: L1_xy(rod end, T) < 0.5.
    for (dx, dy, expect) in [(0.3, 0.15, true), (0.3, 0.25, false)] {
        let mut env = make("MoDe-Franka-Bend-v0", None);
        let end = point(&env, "rod_end");
        env.app.world.resource_mut::<TaskState>().targets[0] = end + Vector3::new(dx, dy, 0.0);
        let o = env.step(&[0.0; 9]);
        println!(
            "bend: target ({dx}, {dy}) from the end: success {:?}",
            o.info.success
        );
        assert_eq!(o.info.success, Some(expect));
    }
    // Drag: both targets on the spot (distance sum ~0) but the belt is still on the near side
    // of the post: no success; the sum condition alone is met.
    let mut env = make("MoDe-Franka-Drag-v0", None);
    let (mid, b) = (point(&env, "belt_mid"), base(&env).translation.vector);
    {
        let mut st = env.app.world.resource_mut::<TaskState>();
        // targets in name order: "belt", "robot"
        st.targets[0] = mid;
        st.targets[1] = b;
    }
    let o = env.step(&[0.0; 9]);
    let v = &o.info.values;
    println!(
        "drag: near_targets {}, beyond_post {}, success {:?}",
        v["success/near_targets"], v["success/beyond_post"], o.info.success
    );
    assert_eq!(v["success/near_targets"], 1.0);
    assert_eq!(v["success/beyond_post"], 0.0);
    assert_eq!(o.info.success, Some(false));
}

const LIFT: &str = "MoDe-Franka-Lift-v0";

/// Franka Lift: base velocity, hand delta, gripper; the gripper closed (it holds the belt).
const LIFT_HOLD: [f32; 10] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0];

#[test]
fn lift_success_near_miss_and_the_belt_term_dropped_past_x_2_2() {
    // Robot target (2.0, 0) +- 0.05; success within 0.3 m. The belt term counts while base x < 2.2.
    for (x, success, belt_term) in [(2.1, true, true), (2.4, false, false), (1.6, false, true)] {
        let mut env = make(LIFT, None);
        // keep the final state of a successful step (autoreset would show the next episode's)
        env.autoreset = false;
        let target = env.app.world.resource::<TaskState>().targets[1];
        set_base(&mut env, x, 0.0);
        let o = env.step(&LIFT_HOLD);
        let v = &o.info.values;
        let belt = v["reward/belt_to_target"];
        let d = (point(&env, "belt_mid") - env.app.world.resource::<TaskState>().targets[0]).norm();
        println!(
            "base x {x} (target x {:.3}): success {:?}, belt term {belt:.4} (-d = {:.4})",
            target.x, o.info.success, -d
        );
        assert_eq!(o.info.success, Some(success));
        assert_eq!(o.terminated, success);
        if belt_term {
            // the term and the distance of the same state
            assert!(belt < 0.0 && (belt + d).abs() < 1e-9, "{belt} vs {}", -d);
        } else {
            assert_eq!(belt, 0.0);
        }
    }
}

#[test]
fn lift_fails_when_the_belt_is_inside_the_body_box() {
    // The scene's box (the Ridgeback's hull) does not hold the belt at the start; a box reaching
    // up to the belt (x 0.5, z 0.55 in the base frame) does, and the first step ends the episode
    // as a failure.
    for (max, inside) in [
        ("max: (0.5, 0.415, 0.33)", false),
        ("max: (0.6, 0.415, 0.6)", true),
    ] {
        let text = task_text("lift", "max: (0.5, 0.415, 0.33)", max);
        let mut env = Env::new(task_app("lift", &text));
        env.reset(Some(0));
        let o = env.step(&LIFT_HOLD);
        let t = o.info.values["termination/belt_on_body"];
        println!(
            "box {max}: belt_on_body {t}, terminated {}, success {:?}",
            o.terminated, o.info.success
        );
        assert_eq!(t, f64::from(u8::from(inside)));
        assert_eq!(o.terminated, inside);
        assert_eq!(o.info.success, Some(false));
    }
}

#[test]
fn a_held_grasp_holds_the_belt_until_the_gripper_opens() {
    // The belt's middle starts in the closed gripper at z 0.55; closed, it stays there; opened,
    // the grasp releases and the middle sags (to about 0.4 m).
    for (closed, expect_held) in [(1.0f32, true), (-1.0, false)] {
        let mut env = make(LIFT, None);
        let mut a = LIFT_HOLD;
        a[9] = closed;
        for _ in 0..90 {
            let o = env.step(&a);
            assert!(o.info.error.is_none(), "{:?}", o.info.error);
        }
        let z = point(&env, "belt_mid").z;
        println!("gripper {closed}: belt middle at z {z:.3} after 1.5 s (held: above 0.5, released: below 0.47)");
        if expect_held {
            assert!(z > 0.5, "{z}");
        } else {
            assert!(z < 0.47, "{z}");
        }
    }
}

#[test]
fn every_action_mode_resets_and_steps() {
    // (modes with V for the robot's base velocity mode, action size Franka, Spot).
    let modes = [
        ("(base: V, arm: EePoseDelta, gripper: Off)", 9, 9),
        ("(base: V, arm: EePoseAbsolute, gripper: Binary)", 10, 10),
        ("(base: V, arm: JointDelta, gripper: Binary)", 11, 10),
        ("(base: V, arm: JointPosition, gripper: Off)", 10, 9),
        ("(base: Off, arm: Off, gripper: Binary)", 1, 1),
        ("(discrete: true)", 1, 1),
        ("(base: LegJoints, arm: Off, gripper: Off)", 0, 12),
    ];
    for id in modesuite::tasks::IMPLEMENTED {
        let spot = id.contains("Spot");
        for (m, franka_dim, spot_dim) in modes {
            let dim = if spot { spot_dim } else { franka_dim };
            if dim == 0 {
                continue;
            }
            let m = m.replace("V", if spot { "Locomotion" } else { "Velocity" });
            check_mode(id, &m, dim);
        }
    }
}

fn check_mode(id: &str, m: &str, dim: usize) {
    let mut env = make(id, Some(m));
    assert_eq!(env.spaces().action.flat_dim(), dim, "{id} {m}");
    let obs_dim = env.spaces().observation.flat_dim();
    let mut policy = make_policy(PolicyKind::Random, &env).unwrap();
    policy.reset(3);
    let mut a = vec![0.0; dim];
    for _ in 0..20 {
        policy.act(&env, &mut a).unwrap();
        let o = env.step(&a);
        assert!(o.info.error.is_none(), "{id} {m}: {:?}", o.info.error);
        assert_eq!(o.observation.len(), obs_dim);
    }
    env.reset(Some(1));
}

#[test]
fn success_is_detected_on_constructed_states_and_near_misses_are_not() {
    // Put the table target where the rod end is (minus 5 cm in z): the end is inside the box.
    // Then 0.60 m away in x (the box is +-0.56 m): a near miss.
    for (dx, expect) in [(0.0, true), (0.45, true), (0.60, false), (-0.62, false)] {
        let mut env = make(PLACE, None);
        let end = point(&env, "rod_end");
        env.app.world.resource_mut::<TaskState>().targets[0] = end + Vector3::new(-dx, 0.0, -0.05);
        let o = env.step(&[0.0; 9]);
        println!(
            "target {dx:+.2} m from the rod end: success {:?}",
            o.info.success
        );
        assert_eq!(o.info.success, Some(expect), "dx {dx}");
        assert_eq!(o.terminated, expect);
        if expect {
            assert!(o.info.values["reward/success_bonus"] == 20.0);
        }
    }
}

#[test]
fn the_reward_is_the_hand_computed_distance_sum() {
    let mut env = make(PLACE, None);
    for _ in 0..5 {
        let o = env.step(&[0.3, -0.2, 0.1, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0]);
        let end = point(&env, "rod_end");
        let t = point(&env, "table");
        let b = base(&env).translation.vector;
        let hand = -((end - t).norm() + ((b - t).xy()).norm());
        println!("reward {:.6} hand-computed {hand:.6}", o.reward);
        assert!((o.reward - hand).abs() < 1e-9);
        assert!((o.info.values["reward/end_to_target"] + (end - t).norm()).abs() < 1e-9);
    }
}

#[test]
fn reset_randomisation_stays_in_range_and_is_deterministic_per_seed() {
    let mut env = make(PLACE, None);
    let mut seen = Vec::new();
    for seed in 0..12u64 {
        env.reset(Some(seed));
        let t = point(&env, "table");
        let b = base(&env);
        let (_, _, yaw) = b.rotation.euler_angles();
        assert!((t.x - 1.5).abs() <= 0.05 && (t.y - 1.5).abs() <= 0.05 && t.z == 0.83);
        assert!(b.translation.x.abs() <= 0.1 + 1e-9 && b.translation.y.abs() <= 0.1 + 1e-9);
        assert!(yaw.abs() <= 0.1 + 1e-9);
        // The rod moved with the base: its held end is still at the hand.
        let end = point(&env, "rod_end");
        let d = (end - b.translation.vector).xy().norm();
        assert!((d - 1.30).abs() < 0.02, "rod end {d:.3} m from the base");
        seen.push((seed, env.state_hash(), t.x));
    }
    // The randomised target is published as a named frame (drawn as a marker).
    let frames = env
        .app
        .world
        .resource::<modesuite::engine::scene::NamedFrames>();
    let marker = frames.0["target/table"].translation.vector;
    assert_eq!(marker, point(&env, "table"));
    let again: Vec<u64> = (0..12u64)
        .map(|s| {
            env.reset(Some(s));
            env.state_hash()
        })
        .collect();
    assert_eq!(again, seen.iter().map(|s| s.1).collect::<Vec<_>>());
    let distinct: std::collections::BTreeSet<u64> = seen.iter().map(|s| s.1).collect();
    assert_eq!(distinct.len(), 12, "every seed gives its own start");
}

#[test]
fn an_episode_ends_on_success_or_time_out_with_the_right_flags() {
    let mut env = make(PLACE, None);
    let mut expert = make_policy(PolicyKind::Scripted, &env).unwrap();
    let mut a = vec![0.0; 9];
    let mut ended = None;
    for i in 0..600 {
        expert.act(&env, &mut a).unwrap();
        let o = env.step(&a);
        if o.terminated || o.truncated {
            ended = Some((i + 1, o));
            break;
        }
    }
    let (n, o) = ended.expect("the expert's episode ends");
    let fi = o.info.final_info.as_ref().expect("same-step autoreset");
    println!("expert episode: {n} steps, return {:?}", o.info.episode);
    assert!(o.terminated && !o.truncated && fi.success == Some(true));
    assert!(n < 600);
    // The zero action never succeeds: the episode is cut at 600 steps.
    env.reset(Some(0));
    let mut last = None;
    for _ in 0..600 {
        last = Some(env.step(&[0.0; 9]));
    }
    let o = last.unwrap();
    assert!(o.truncated && !o.terminated);
    assert_eq!(o.info.episode.unwrap().length, 600);
    assert_eq!(o.info.final_info.unwrap().success, Some(false));
}

/// The seeds every expert test runs (each of both robots' environments of the task).
const EXPERT_SEEDS: [u64; 4] = [0, 7, 13, 21];

/// Defines one test per task running the experts of both robots on [`EXPERT_SEEDS`] (one test
/// per task so the test threads share them), and `EXPERT_TESTED`, the tasks so tested: the
/// list and the tests come from one place, so the check below sees the tests that exist.
macro_rules! expert_tests {
    ($($test:ident: $task:literal),* $(,)?) => {
        /// The tasks with an expert test, from [`expert_tests!`].
        const EXPERT_TESTED: &[&str] = &[$($task),*];
        $(
            #[test]
            fn $test() {
                task_experts($task);
            }
        )*
    };
}

expert_tests! {
    place_experts_succeed_on_several_seeds: "Place",
    curtain_experts_succeed_on_several_seeds: "Curtain",
    bend_experts_succeed_on_several_seeds: "Bend",
    transport_experts_succeed_on_several_seeds: "Transport",
    drag_experts_succeed_on_several_seeds: "Drag",
    lift_experts_succeed_on_several_seeds: "Lift",
    uncover_experts_succeed_on_several_seeds: "Uncover",
    cover_experts_succeed_on_several_seeds: "Cover",
}

/// The experts of one task (both robots) on [`EXPERT_SEEDS`].
fn task_experts(task: &str) {
    let ids: Vec<_> = modesuite::tasks::IMPLEMENTED
        .iter()
        .filter(|id| id.ends_with(&format!("-{task}-v0")))
        .collect();
    assert!(!ids.is_empty(), "no {task} environment");
    for id in ids {
        expert_seeds(id, &EXPERT_SEEDS);
    }
}

#[test]
fn every_implemented_environment_has_its_expert_tested() {
    let implemented: std::collections::BTreeSet<&str> = modesuite::tasks::IMPLEMENTED
        .iter()
        .map(|id| id.split('-').nth(2).unwrap())
        .collect();
    let tested: std::collections::BTreeSet<&str> = EXPERT_TESTED.iter().copied().collect();
    assert_eq!(
        tested.len(),
        EXPERT_TESTED.len(),
        "a task is tested twice: {EXPERT_TESTED:?}"
    );
    assert_eq!(
        implemented, tested,
        "the tasks of the implemented environments vs the tasks with an expert test (add one to expert_tests!)"
    );
}

/// Spot Lift, held-out seed 37: at step 455 the belt's chord solve took steps of 1e-19 m at
/// residual forces of 4e3 N and more for convergence (the step-size test alone), and the belt
/// flew apart unreported until the arm was flung at step 480. With the residual bound
/// (`FemSolid::residual_bound`) exact Newton takes that step and the expert succeeds.
#[test]
fn spot_lift_expert_gets_past_the_false_convergence_of_seed_37() {
    let mut env = make("MoDe-Spot-Lift-v0", None);
    let mut expert = make_policy(PolicyKind::Scripted, &env).unwrap();
    let mut a = vec![0.0; env.spaces().action.flat_dim()];
    env.reset(Some(37));
    expert.reset(37);
    let o = loop {
        expert.act(&env, &mut a).unwrap();
        let o = env.step(&a);
        if o.terminated || o.truncated {
            break o;
        }
    };
    let length = o.info.episode.as_ref().unwrap().length;
    println!(
        "Spot Lift seed 37: success {:?} after {length} steps, error {:?}",
        o.info.final_info.as_ref().unwrap().success,
        o.info.error
    );
    assert!(o.info.error.is_none(), "{:?}", o.info.error);
    assert_eq!(o.info.final_info.unwrap().success, Some(true));
}

/// Runs the scripted expert of `id` on each of `seeds` and asserts that every episode succeeds.
/// The simulator is deterministic (results do not depend on the CPU, the thread count or the
/// other envs), so an outcome is the same on every run: on 2026-11-27 all four seeds of each of
/// the 16 experts succeeded, and a seed that fails is a changed behaviour to look at, not
/// noise. The experts' rates over 20 seeds are in docs/tasks.md.
fn expert_seeds(id: &str, seeds: &[u64]) {
    let mut env = make(id, None);
    let mut expert = make_policy(PolicyKind::Scripted, &env).unwrap();
    let mut a = vec![0.0; env.spaces().action.flat_dim()];
    let mut failed = Vec::new();
    for &seed in seeds {
        env.reset(Some(seed));
        expert.reset(seed);
        loop {
            expert.act(&env, &mut a).unwrap();
            let o = env.step(&a);
            if o.terminated || o.truncated {
                let s = o.info.final_info.unwrap().success;
                println!(
                    "{id} seed {seed}: success {s:?}, {} steps, error {:?}",
                    o.info.episode.unwrap().length,
                    o.info.error
                );
                if s != Some(true) {
                    failed.push(seed);
                }
                break;
            }
        }
    }
    assert!(
        failed.is_empty(),
        "{id}: the expert failed on seeds {failed:?} of {seeds:?}"
    );
}

#[test]
fn task_section_errors_name_the_entry() {
    let scene = |task: &str| {
        place_text(
            r#"events: {"robot_start": RobotPose(xy: 0.1, yaw: 0.1, carry: ["rod"])},"#,
            task,
        )
    };
    let e = scene_error(&scene(
        r#"rewards: {"x": (term: "distanse", weight: 1.0, params: (a: Base, b: Ee))},"#,
    ));
    assert!(
        e.contains(r#"rewards["x"]"#) && e.contains("distance"),
        "{e}"
    );
    let e = scene_error(&scene(
        r#"rewards: {"x": (term: "distance", weight: 1.0, params: (a: Point("nope"), b: Ee))},"#,
    ));
    assert!(e.contains("nope") && e.contains("rod_end"), "{e}");
    let e = scene_error(&scene(
        r#"observations: {"policy": (terms: [(term: "base_xy")], history: 0)},"#,
    ));
    assert!(e.contains(r#"observations["policy"].history"#), "{e}");
    let e = scene_error(&scene(
        r#"observations: {"policy": (terms: [(term: "tracked", params: (object: "table", k: 4))])},"#,
    ));
    assert!(e.contains("table") && e.contains("deformable"), "{e}");
    let e = scene_error(&scene(r#"events: {"e": RobotPose(xy: -1.0, yaw: 0.1)},"#));
    assert!(e.contains(r#"events["e"]"#), "{e}");
    // within / sum_within need a positive max; Stages a positive reach and a stage.
    let e = scene_error(&scene(
        r#"success: {"w": (term: "within", params: (a: Base, b: Ee))},"#,
    ));
    assert!(e.contains(r#"success["w"]"#) && e.contains("max"), "{e}");
    let e = scene_error(&scene(
        r#"success: {"w": (term: "sum_within", params: (pairs: [], max: 0.4))},"#,
    ));
    assert!(e.contains("pairs"), "{e}");
    let e = scene_error(&scene(
        r#"points: {"g": Stages(stages: [Target("table")], by: Base, reach: 0.0)},"#,
    ));
    assert!(e.contains("reach"), "{e}");
    // A held grasp needs a gripper that starts closed; the body box needs min below max.
    let lift = |from: &str, to: &str| scene_error_in("lift", &task_text("lift", from, to));
    let e = lift(", start_closed: true", "");
    assert!(
        e.contains("held.grasp") && e.contains("start_closed"),
        "{e}"
    );
    let e = lift("min: (-0.5, -0.415, 0.0)", "min: (-0.5, -0.415, 0.4)");
    assert!(e.contains("belt_on_body") && e.contains("min"), "{e}");
    // Route legs need positive speeds (refused when the scene compiles).
    let err = scene_error_in(
        "lift",
        &task_text("lift", "hand_speed: 0.105", "hand_speed: -0.1"),
    );
    assert!(err.contains("route[4].hand_speed"), "{err}");
    // The route expert needs route legs.
    let app = place_app(&scene(r#"expert: "route","#));
    let env = Env::new(app);
    let err = make_policy(PolicyKind::Scripted, &env).err().unwrap();
    assert!(err.contains("route"), "{err}");
    // An override of the parent's reward by name.
    let app = place_app(&scene(
        r#"rewards: {"base_to_target": (term: "distance", weight: -0.5, params: (a: Base, b: Target("table"), planar: true))},"#,
    ));
    let task = app.world.resource::<modesuite::tasks::Task>();
    let w: Vec<(String, f64)> = task
        .model
        .rewards
        .iter()
        .map(|r| (r.term.name.clone(), r.weight))
        .collect();
    assert_eq!(
        w,
        [
            ("base_to_target".to_string(), -0.5),
            ("end_to_target".to_string(), -1.0)
        ]
    );
}

#[test]
fn a_task_env_has_no_ambiguous_systems() {
    let mut env = make(PLACE, None);
    let amb = env.app.ambiguities();
    println!(
        "ambiguous system pairs: {} (expected 0) {amb:#?}",
        amb.len()
    );
    assert!(amb.is_empty());
}

#[test]
fn a_failing_reset_event_is_reported_and_ends_the_first_step() {
    let text = place_text(r#"carry: ["rod"]"#, r#"carry: ["table"]"#);
    let mut env = Env::new(place_app(&text));
    let (_, info) = env.reset(Some(0));
    let e = info.error.expect("the reset reports the failed event");
    println!("{e}");
    assert!(
        e.contains("robot_start") && e.contains("\"table\" is not a deformable"),
        "{e}"
    );
    let o = env.step(&[0.0; 9]);
    assert!(
        o.truncated
            && o.info
                .final_info
                .unwrap()
                .error
                .unwrap()
                .contains("robot_start")
    );
}

#[test]
fn cloth_region_terms_measure_the_napkin() {
    // The napkin (0.3 x 0.3 m at (0.82, 0), flat on the table) of the grasp example, observed
    // by a task section added to the scene.
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("scenes/examples/franka_cloth_grasp.scene.ron"),
    )
    .unwrap()
    .replace(
        r#""robots": ["#,
        r#""task": (observations: {"policy": (terms: [
            (term: "cloth_fraction_above", params: (object: "napkin", min: (0.6, -0.3), max: (1.2, 0.3))),
            (term: "cloth_fraction_above", params: (object: "napkin", min: (0.6, -0.3), max: (0.82, 0.3), above: 0.4)),
            (term: "cloth_coverage", params: (object: "napkin", min: (0.72, -0.1), max: (0.92, 0.1))),
            (term: "cloth_coverage", params: (object: "napkin", min: (2.0, 2.0), max: (2.5, 2.5), at_least: 0.5)),
            (term: "cloth_fraction_above", params: (object: "napkin", min: (0.6, -0.3), max: (1.2, 0.3), at_most: 0.05)),
            (term: "cloth_coverage", params: (object: "napkin", min: (0.72, -0.1), max: (0.92, 0.1), above: 0.4)),
            (term: "cloth_coverage", params: (object: "napkin", min: (0.72, -0.1), max: (0.92, 0.1), above: 0.5)),
        ])}),
        "robots": ["#,
    );
    let desc = modesuite::engine::scene::parse_str(&text, "<test>").unwrap();
    let mut app = modesuite::make::default_app();
    let model = app
        .compile_scene(&desc, &SceneSource::in_memory("."))
        .unwrap();
    app.spawn_scene(model).unwrap();
    let mut env = Env::new(app);
    let (o, _) = env.reset(Some(0));
    println!("napkin terms: {o:?}");
    assert_eq!(o.len(), 7);
    assert_eq!(o[0], 1.0, "every particle over the table");
    // 13 x 13 particles, columns at x = 0.67 + 0.025 i: those with x <= 0.82 are 7 of 13.
    assert!((o[1] - 7.0 / 13.0).abs() < 1e-6, "{}", o[1]);
    assert!(
        o[2] > 0.99,
        "the region inside the napkin is covered: {}",
        o[2]
    );
    assert_eq!(o[3], 0.0, "a far region is not");
    assert_eq!(o[4], 0.0, "at_most 0.05 does not hold");
    // the napkin lies at 0.455 m: covering with `above: 0.4`, not with `above: 0.5`
    assert!(o[5] > 0.99 && o[5] == o[2], "{}", o[5]);
    assert_eq!(o[6], 0.0, "nothing above 0.5 m");
}

#[test]
fn friction_randomisation_stays_in_range_and_follows_the_seed() {
    let text = place_text(
        r#"events: {"robot_start""#,
        r#"events: {"table_friction": Friction(object: "table", range: (0.3, 0.9)), "robot_start""#,
    );
    let mut env = Env::new(place_app(&text));
    let friction = |env: &mut Env| {
        use modesuite::engine::components::Object;
        use modesuite::engine::rigid::RigidRef;
        let mut q = env.app.world.query::<(&Object, &RigidRef)>();
        let h = q
            .iter(&env.app.world)
            .find(|(o, _)| o.name == "table")
            .unwrap()
            .1
             .0;
        let ctx = env.app.world.resource::<RigidContext>();
        let c = ctx.bodies.get(h).unwrap().colliders()[0];
        ctx.colliders.get(c).unwrap().friction()
    };
    let mut seen = Vec::new();
    for seed in 0..6 {
        env.reset(Some(seed));
        let f = friction(&mut env);
        assert!((0.3..=0.9).contains(&f), "{f}");
        seen.push(f);
    }
    println!("table friction per seed: {seen:?}");
    env.reset(Some(2));
    assert_eq!(friction(&mut env), seen[2]);
    assert!(seen.windows(2).all(|w| w[0] != w[1]));
    let e = scene_error(&place_text(
        r#"events: {"robot_start""#,
        r#"events: {"f": Friction(object: "table", range: (0.9, 0.3)), "robot_start""#,
    ));
    assert!(e.contains(r#"events["f"].range"#), "{e}");
}

#[test]
fn material_randomisation_stays_in_range_follows_the_seed_and_changes_the_sag() {
    let with = |range: &str| {
        place_text(
            r#"events: {"robot_start""#,
            &format!(
                r#"events: {{"rod_material": Material(object: "rod", youngs_modulus: {range}), "robot_start""#
            ),
        )
    };
    let modulus = |env: &mut Env| {
        use modesuite::engine::components::Object;
        let mut q = env.app.world.query::<(Entity, &Object)>();
        let e = q
            .iter(&env.app.world)
            .find(|(_, o)| o.name == "rod")
            .unwrap()
            .0;
        env.app
            .world
            .resource::<modesuite::fem::FemContext>()
            .get(e)
            .unwrap()
            .youngs_modulus()
    };
    let mut env = Env::new(place_app(&with("(5e5, 2e6)")));
    let mut seen = Vec::new();
    for seed in 0..6 {
        env.reset(Some(seed));
        let e = modulus(&mut env);
        assert!((5e5..=2e6).contains(&e), "{e}");
        seen.push(e);
    }
    println!("rod Young's modulus per seed (Pa): {seen:?}");
    env.reset(Some(2));
    assert_eq!(modulus(&mut env), seen[2]);
    assert!(seen.windows(2).all(|w| w[0] != w[1]));
    // The rod is held at one end: the softer rod's free end hangs lower after 1 s.
    let mut ends = Vec::new();
    for range in ["(2e5, 2e5)", "(4e6, 4e6)"] {
        let mut env = Env::new(place_app(&with(range)));
        env.reset(Some(0));
        for _ in 0..60 {
            let o = env.step(&[0.0; 9]);
            assert!(o.info.error.is_none(), "{:?}", o.info.error);
        }
        ends.push(point(&env, "rod_end").z);
    }
    println!(
        "rod end after 1 s: z {:.4} m at E = 2e5 Pa, {:.4} m at E = 4e6 Pa (softer hangs lower)",
        ends[0], ends[1]
    );
    assert!(ends[0] < ends[1] - 0.01, "{ends:?}");
    // Errors: a bad range at compile time, a rigid object at reset.
    let e = scene_error(&with("(2e6, 5e5)"));
    assert!(
        e.contains(r#"events["rod_material"].youngs_modulus"#),
        "{e}"
    );
    let text = place_text(
        r#"events: {"robot_start""#,
        r#"events: {"m": Material(object: "table", youngs_modulus: (1e5, 2e5)), "robot_start""#,
    );
    let mut env = Env::new(place_app(&text));
    let (_, info) = env.reset(Some(0));
    let e = info
        .error
        .expect("a rigid object has no Young's modulus to set");
    println!("{e}");
    assert!(e.contains("table") && e.contains("fem.solid"), "{e}");
}

#[test]
fn spot_start_randomisation_moves_the_floating_base_within_range() {
    let mut env = make("MoDe-Spot-Curtain-v0", None);
    let mut starts = Vec::new();
    for seed in 0..6u64 {
        env.reset(Some(seed));
        let b = base(&env);
        let (_, _, yaw) = b.rotation.euler_angles();
        assert!(b.translation.x.abs() <= 0.1 + 1e-6 && b.translation.y.abs() <= 0.1 + 1e-6);
        assert!(yaw.abs() <= 0.1 + 1e-6);
        starts.push((b.translation.x, b.translation.y, yaw));
    }
    println!("Spot starts (x, y, yaw): {starts:?}");
    env.reset(Some(3));
    let b = base(&env);
    assert_eq!(
        (b.translation.x, b.translation.y),
        (starts[3].0, starts[3].1)
    );
    assert!(
        starts.windows(2).all(|w| w[0] != w[1]),
        "every seed its own start"
    );
}

/// The friction coefficient of a rigid object's first collider.
fn friction(env: &Env, object: &str) -> f32 {
    use modesuite::engine::components::Object;
    use modesuite::engine::rigid::RigidRef;
    let world = &env.app.world;
    let rigid = world.resource::<RigidContext>();
    let body = world
        .iter_entities()
        .find(|e| e.get::<Object>().is_some_and(|o| o.name == object))
        .and_then(|e| e.get::<RigidRef>().map(|r| r.0))
        .unwrap();
    let c = rigid.bodies.get(body).unwrap().colliders()[0];
    rigid.colliders.get(c).unwrap().friction()
}

/// The Place scene with a free box on the floor and `events` before the robot's start event.
fn place_with_events(events: &str) -> String {
    let text = place_text(
        r#"events: {"robot_start""#,
        &format!(r#"events: {{{events} "robot_start""#),
    );
    text.replace(
        r#"        (
            name: "rod","#,
        r#"        (name: "box", shape: Box(size: (0.2, 0.2, 0.2)), pose: (pos: (3.0, -2.0, 0.1)), body: Dynamic()),
        (
            name: "rod","#,
    )
}

#[test]
fn startup_events_hold_for_the_env_and_interval_events_run_on_time() {
    let text = place_with_events(
        r#""floor": Startup(Friction(object: "table", range: (0.1, 0.9))),
           "gust": Interval(every: (0.5, 0.5), event: Push(object: "box", velocity: (1.0, 1.0, 0.0))),"#,
    );
    // Startup: drawn at the env's first reset, the same after every later reset.
    let mut env = Env::new(place_app(&text));
    let mut seen = Vec::new();
    for seed in [0, 1, 5, 0] {
        env.reset(Some(seed));
        seen.push(friction(&env, "table"));
    }
    println!("table friction after resets with seeds 0, 1, 5, 0 of one env: {seen:?}");
    assert!((0.1..=0.9).contains(&seen[0]), "{seen:?}");
    assert!(seen.iter().all(|f| *f == seen[0]), "{seen:?}");
    let first = |seed: u64| {
        let mut env = Env::new(place_app(&text));
        env.reset(Some(seed));
        friction(&env, "table")
    };
    // A robot link by its `robot/link` name (checked when the event runs).
    let link_text = place_with_events(
        r#""grip": Friction(object: "robot/panda_leftfinger", range: (1.5, 1.5)), "bad": Friction(object: "robot/nope", range: (0.5, 0.5)),"#,
    );
    let mut env = Env::new(place_app(&link_text));
    let (_, info) = env.reset(Some(0));
    assert_eq!(friction(&env, "robot/panda_leftfinger"), 1.5);
    let e = info.error.expect("an unknown link is refused at reset");
    println!("{e}");
    assert!(
        e.contains("robot/nope") && e.contains("not a rigid body"),
        "{e}"
    );
    let (f0, f1) = (first(0), first(1));
    println!("a fresh env's table friction: first reset seed 0: {f0}, seed 1: {f1}");
    assert_eq!(f0, seen[0], "a function of the first reset's seed");
    assert_ne!(f0, f1, "every env its own draw");
    // Interval: every 0.5 s of episode time (30 steps at 60 Hz), before that step's physics.
    let box_speed = |env: &Env| {
        use modesuite::engine::components::Velocity;
        let world = &env.app.world;
        world
            .iter_entities()
            .find(|e| {
                e.get::<modesuite::engine::components::Object>()
                    .is_some_and(|o| o.name == "box")
            })
            .and_then(|e| e.get::<Velocity>().map(|v| v.linear.xy().norm()))
            .unwrap()
    };
    let next = |env: &Env| env.app.world.resource::<TaskState>().next_event.clone();
    let run = |seed: u64| {
        let mut env = Env::new(place_app(&text));
        env.reset(Some(seed));
        assert_eq!(next(&env), vec![0.5]);
        let mut speeds = Vec::new();
        for _ in 0..31 {
            let o = env.step(&[0.0; 9]);
            assert!(o.info.error.is_none(), "{:?}", o.info.error);
            speeds.push(box_speed(&env));
        }
        (speeds, next(&env), env.state_hash())
    };
    let (speeds, after, hash) = run(3);
    println!(
        "box speed after steps 29, 30, 31: {:.4} {:.4} {:.4} m/s; next run at {after:?} s",
        speeds[28], speeds[29], speeds[30]
    );
    assert!(speeds[..30].iter().all(|v| *v < 1e-3), "{speeds:?}");
    assert!(speeds[30] > 0.05, "pushed on step 31: {}", speeds[30]);
    assert_eq!(after, vec![1.0]);
    let (speeds2, _, hash2) = run(3);
    assert_eq!((speeds2, hash2), (speeds, hash), "deterministic per seed");
}

#[test]
fn push_moves_a_cloth_and_refuses_a_static_body() {
    let text = task_text(
        "uncover",
        r#""cover_start": ObjectOffset(object: "cover", xy: 0.05),"#,
        r#""cover_start": ObjectOffset(object: "cover", xy: 0.05), "gust": Push(object: "cover", velocity: (0.0, 0.0, 0.5)),"#,
    );
    let mut env = Env::new(task_app("uncover", &text));
    let (_, info) = env.reset(Some(4));
    assert!(info.error.is_none(), "{:?}", info.error);
    use modesuite::engine::components::Object;
    let e = env
        .app
        .world
        .iter_entities()
        .find(|e| e.get::<Object>().is_some_and(|o| o.name == "cover"))
        .unwrap()
        .id();
    let cloth = env
        .app
        .world
        .resource::<modesuite::pbd::PbdContext>()
        .get(e)
        .unwrap();
    let v = cloth.velocities();
    println!("cover velocity after the push: {:?}", v[0]);
    assert!(v[0].z.abs() > 0.0 && v[0].z.abs() <= 0.5 && v[0].xy().norm() == 0.0);
    assert!(v.iter().all(|w| *w == v[0]), "one push for every particle");
    let text = task_text(
        "uncover",
        r#""cover_start": ObjectOffset(object: "cover", xy: 0.05),"#,
        r#""p": Push(object: "table", velocity: (0.1, 0.1, 0.1)),"#,
    );
    let mut env = Env::new(task_app("uncover", &text));
    let e = env
        .reset(Some(0))
        .1
        .error
        .expect("a static body is refused");
    println!("{e}");
    assert!(
        e.contains("\"p\"") && e.contains("not a free dynamic body"),
        "{e}"
    );
}

#[test]
fn startup_and_interval_errors_name_the_event() {
    for (events, path, what) in [
        (
            r#""g": Interval(every: (0.0, 1.0), event: Push(object: "rod", velocity: (1.0, 0.0, 0.0))),"#,
            r#"events["g"].every"#,
            "0 < shortest",
        ),
        (
            r#""g": Interval(every: (1.0, 2.0), event: ObjectOffset(object: "rod", xy: 0.1)),"#,
            r#"events["g"].event"#,
            "teleport",
        ),
        (
            r#""g": Startup(Interval(every: (1.0, 2.0), event: Push(object: "rod", velocity: (1.0, 0.0, 0.0)))),"#,
            r#"events["g"].0"#,
            "do not nest",
        ),
        (
            r#""g": Interval(every: (1.0, 2.0), event: Push(object: "rod", velocity: (-1.0, 0.0, 0.0))),"#,
            r#"events["g"].event.velocity"#,
            ">= 0",
        ),
        (
            r#""g": Startup(Friction(object: "nope", range: (0.1, 0.2))),"#,
            r#"events["g"].0.object"#,
            "nope",
        ),
    ] {
        let e = scene_error(&place_with_events(events));
        println!("{e}");
        assert!(e.contains(path) && e.contains(what), "{e}");
    }
}

#[test]
fn rgbd_observation_of_the_robot_camera_follows_the_state_terms() {
    for id in [PLACE, "MoDe-Spot-Uncover-v0"] {
        let state_dim = make(id, None).spaces().observation.flat_dim();
        let (mut desc, source) = load(id, None);
        modesuite::make::override_rgbd(&mut desc, "robot").unwrap();
        let mut app = modesuite::make::default_app();
        let model = app
            .compile_scene(&desc, &source)
            .unwrap_or_else(|e| panic!("{e}"));
        modesuite::make::spawn_with_cameras(&mut app, model).unwrap_or_else(|e| panic!("{e}"));
        let mut env = Env::new(app);
        let space = env.spaces().observation.clone();
        let Space::Dict(items) = &space else {
            panic!("{space:?}")
        };
        let names: Vec<&str> = items.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["state", "robot_rgbd"]);
        assert_eq!(items[0].1.flat_dim(), state_dim);
        let Space::Box { shape, .. } = &items[1].1 else {
            panic!()
        };
        assert_eq!(shape, &vec![128, 128, 4]);
        let (obs, info) = env.reset(Some(0));
        assert!(info.error.is_none(), "{:?}", info.error);
        assert_eq!(obs.len(), state_dim + 128 * 128 * 4);
        let image = &obs[state_dim..];
        let rgb_ok = image
            .chunks_exact(4)
            .all(|p| p[..3].iter().all(|c| (0.0..=1.0).contains(c)));
        let depths: Vec<f32> = image.chunks_exact(4).map(|p| p[3]).collect();
        let hit = depths.iter().filter(|d| **d > 0.0).count();
        let (near, far) = depths
            .iter()
            .filter(|d| **d > 0.0)
            .fold((f32::MAX, 0.0f32), |(a, b), d| (a.min(*d), b.max(*d)));
        let mean_rgb = image
            .chunks_exact(4)
            .map(|p| p[0] + p[1] + p[2])
            .sum::<f32>()
            / (3.0 * 128.0 * 128.0);
        println!(
            "{id}: robot camera 128x128 RGB-D, {hit} of 16384 pixels hit, depth {near:.2}..{far:.2} m, mean RGB {mean_rgb:.3}"
        );
        assert!(rgb_ok);
        // The camera looks down at the floor and the task's furniture ahead of the robot.
        assert!(hit > 8000, "{hit}");
        assert!(
            near > 0.05 && far < 20.0 && far - near > 0.3,
            "{near} {far}"
        );
        // The state part is the state observation of the plain env at the same seed.
        let mut plain = make(id, None);
        let (plain_obs, _) = plain.reset(Some(0));
        assert_eq!(&obs[..state_dim], &plain_obs[..]);
        let o = env.step(&vec![0.0; env.spaces().action.flat_dim()]);
        assert!(o.info.error.is_none(), "{:?}", o.info.error);
        assert_eq!(o.observation.len(), obs.len());
    }
    // Error: a camera the scene does not have.
    let (mut desc, source) = load(PLACE, None);
    modesuite::make::override_rgbd(&mut desc, "nope").unwrap();
    let app = modesuite::make::default_app();
    let e = match app.compile_scene(&desc, &source) {
        Ok(_) => panic!("an unknown camera is refused"),
        Err(e) => e.to_string(),
    };
    println!("{e}");
    assert!(
        e.contains("camera_observation") && e.contains("\"nope\"") && e.contains("robot"),
        "{e}"
    );
}

#[test]
fn image_observations_stack_their_history_item_by_item() {
    // Two frames of (base xy, the robot camera's depth): a `Dict` of `state` (2, 2) and
    // `robot_depth` (2, 128, 128, 1), each item's frames oldest first (Gymnasium's frame
    // stacking); a reset repeats its first frame, each step shifts the frames by one.
    let text = place_text(
        r#"events: {"robot_start""#,
        r#"observations: {"policy": (terms: [(term: "base_xy"), (term: "camera", params: (camera: "robot", channels: Depth))], history: 2)}, events: {"robot_start""#,
    );
    let desc = modesuite::engine::scene::parse_str(&text, "<test>").unwrap();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/place");
    let mut app = modesuite::make::default_app();
    let model = app
        .compile_scene(&desc, &SceneSource::in_memory(dir))
        .unwrap_or_else(|e| panic!("{e}"));
    modesuite::make::spawn_with_cameras(&mut app, model).unwrap_or_else(|e| panic!("{e}"));
    let mut env = Env::new(app);
    let Space::Dict(items) = env.spaces().observation.clone() else {
        panic!("{:?}", env.spaces().observation)
    };
    let shapes: Vec<(&str, Vec<usize>)> = items
        .iter()
        .map(|(n, s)| match s {
            Space::Box { shape, .. } => (n.as_str(), shape.clone()),
            other => panic!("{other:?}"),
        })
        .collect();
    println!("{shapes:?}");
    assert_eq!(
        shapes,
        [("state", vec![2, 2]), ("robot_depth", vec![2, 128, 128, 1])]
    );
    let n = 128 * 128;
    let (mut prev, info) = env.reset(Some(0));
    assert!(info.error.is_none(), "{:?}", info.error);
    assert_eq!(prev.len(), 2 * 2 + 2 * n);
    assert_eq!(prev[0..2], prev[2..4], "a reset repeats its first frame");
    assert_eq!(prev[4..4 + n], prev[4 + n..]);
    let mut action = vec![0.0f32; env.spaces().action.flat_dim()];
    action[0] = 0.5;
    for _ in 0..5 {
        let o = env.step(&action);
        assert!(o.info.error.is_none(), "{:?}", o.info.error);
        let obs = o.observation;
        // the older frame of each item is the newer one of the step before
        assert_eq!(obs[0..2], prev[2..4]);
        assert_eq!(obs[4..4 + n], prev[4 + n..]);
        prev = obs;
    }
    println!("base xy: older {:?}, newer {:?}", &prev[0..2], &prev[2..4]);
    assert_ne!(prev[0..2], prev[2..4], "the base moved between the frames");
}

#[test]
fn envs_sharing_one_compiled_scene_step_as_separately_built_ones() {
    // `envs_for_target` compiles the scene once for all its envs (a `VecEnv`'s, the bench's):
    // each must still be its own world, bit-identical to an env built alone.
    for id in [PLACE, "MoDe-Spot-Uncover-v0"] {
        let mut shared = modesuite::make::envs_for_target(id, None, 3).unwrap();
        let mut alone = modesuite::make::env_for_target(id, None).unwrap();
        for (seed, e) in shared.iter_mut().enumerate() {
            e.reset(Some(seed as u64));
        }
        alone.reset(Some(2));
        let mut action = vec![0.0f32; alone.spaces().action.flat_dim()];
        action[0] = 0.5;
        for _ in 0..30 {
            for e in &mut shared {
                assert!(e.step(&action).info.error.is_none());
            }
            assert!(alone.step(&action).info.error.is_none());
        }
        let hashes: Vec<u64> = shared.iter().map(|e| e.state_hash()).collect();
        println!(
            "{id}: shared envs (seeds 0, 1, 2) {hashes:x?}, alone (seed 2) {:x}",
            alone.state_hash()
        );
        assert_eq!(hashes[2], alone.state_hash());
        assert_ne!(hashes[0], hashes[2]);
        assert_ne!(hashes[0], hashes[1]);
    }
}

#[test]
fn task_envs_are_bit_identical_on_one_or_two_threads_and_alone() {
    // The determinism promise for the benchmark itself, every environment: a `VecEnv` of task
    // envs gives the same bits on one thread and on two, and its env 2 the bits of an env run
    // alone with env 2's seed and actions (FEM contact-factor caches, cloth, walking Spot),
    // under changing actions.
    // step `s`'s actions; `first` is the index of `a[0]` among the batch's values
    let actions = |a: &mut [f32], first: usize, s: usize| {
        for (k, x) in a.iter_mut().enumerate() {
            *x = 0.5 * ((s as f32) * 0.1 + (first + k) as f32).sin();
        }
    };
    for id in modesuite::tasks::IMPLEMENTED {
        let run = |threads: usize| -> Vec<u64> {
            let envs = modesuite::make::envs_for_target(id, None, 3).unwrap();
            let mut v = modesuite::engine::VecEnv::new(envs, threads).unwrap();
            v.reset(Some(10));
            let dim = v.envs()[0].spaces().action.flat_dim();
            let mut a = vec![0.0f32; 3 * dim];
            for s in 0..25 {
                actions(&mut a, 0, s);
                let out = v.step(&a).unwrap();
                assert!(out.infos.iter().all(|i| i.error.is_none()), "{id}");
            }
            v.state_hashes()
        };
        let (one, two) = (run(1), run(2));
        let mut alone = modesuite::make::env_for_target(id, None).unwrap();
        alone.reset(Some(12));
        let dim = alone.spaces().action.flat_dim();
        let mut a = vec![0.0f32; dim];
        for s in 0..25 {
            actions(&mut a, 2 * dim, s);
            alone.step(&a);
        }
        println!(
            "{id}: 1 thread {one:x?}, 2 threads {two:x?}, alone (seed 12) {:x}",
            alone.state_hash()
        );
        assert_eq!(one, two, "{id}: 1 vs 2 threads");
        assert_eq!(one[2], alone.state_hash(), "{id}: env 2 vs alone");
        assert_ne!(one[0], one[1], "{id}: envs differ");
    }
}
