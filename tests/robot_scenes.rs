//! Robots in scene files: the `robots` section, action modes, discrete keys, scripts, resets,
//! and robots as data (description files, a robot added with files only).

mod common;

use std::path::{Path, PathBuf};

use modesuite::engine::scene::SceneSource;
use modesuite::engine::{Env, RigidContext, Space};
use modesuite::make::{make, MakeOptions};
use modesuite::robots::{DiscreteKey, RobotFile, RobotObservation, RobotSpec, Robots};
use nalgebra::Vector3;

fn franka_scene(actions: &str) -> String {
    format!(
        r#"Scene(
    physics: (dt: 0.016666666666666666, substeps: 4, rigid_iterations: 1),
    objects: [(name: "ground", shape: Plane(size: (20.0, 20.0)), body: Static)],
    extensions: {{ "robots": [(name: "robot", model: "franka", actions: {actions})] }},
)"#
    )
}

fn env(text: &str) -> Env {
    let mut env = Env::new(common::app_from_ron(text));
    env.reset(Some(1));
    env
}

fn ee_and_base(env: &Env) -> (Vector3<f64>, Vector3<f64>, bool) {
    let robots = env.app.world.resource::<Robots>();
    let ctx = env.app.world.resource::<RigidContext>();
    let o = robots.robots[0].observe(ctx).unwrap();
    (
        o.ee.translation.vector,
        o.base.translation.vector,
        o.gripper_closed,
    )
}

/// An env of an example scene, reset with seed 0.
fn scene_env(name: &str) -> Env {
    let path = common::root().join(format!("scenes/examples/{name}.scene.ron"));
    let (desc, source) = modesuite::engine::scene::load_file(&path).unwrap();
    let mut app = modesuite::make::default_app();
    let model = app.compile_scene(&desc, &source).unwrap();
    app.spawn_scene(model).unwrap();
    let mut e = Env::new(app);
    // The tests run these scripted scenes to their last step: without this that step's autoreset
    // would put the robot back at its start before its final pose is read.
    e.autoreset = false;
    e.reset(Some(0));
    e
}

fn compile_err(text: &str) -> String {
    let desc = modesuite::engine::scene::parse_str(text, "<test>").unwrap();
    let app = modesuite::make::default_app();
    match app.compile_scene(&desc, &SceneSource::in_memory(".")) {
        Ok(_) => panic!("scene compiled"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn action_spaces_follow_the_modes() {
    let cases = [
        ("()", vec![3, 7, 1]),
        ("(arm: EePoseDelta)", vec![3, 6, 1]),
        ("(arm: JointPosition, base: Off)", vec![7, 1]),
        ("(arm: EePoseAbsolute, gripper: Off)", vec![3, 6]),
    ];
    for (actions, dims) in cases {
        let e = env(&franka_scene(actions));
        let space = e.spaces().action;
        let got: Vec<usize> = match &space {
            Space::Dict(items) => items.iter().map(|(_, s)| s.flat_dim()).collect(),
            other => vec![other.flat_dim()],
        };
        println!("franka actions {actions}: dims {got:?} (expected {dims:?})");
        assert_eq!(got, dims);
    }
    let e = env(&franka_scene("(discrete: true)"));
    assert_eq!(e.spaces().action, Space::Discrete { n: 14 });
}

#[test]
fn base_velocity_and_gripper_actions_move_the_franka() {
    let mut e = env(&franka_scene("()"));
    let (_, b0, _) = ee_and_base(&e);
    // vx = 0.5 of 0.5 m/s for 2 s, gripper closed.
    let mut a = vec![0.0f32; 11];
    a[0] = 0.5;
    a[10] = 1.0;
    for _ in 0..120 {
        let out = e.step(&a);
        assert!(out.info.error.is_none(), "{:?}", out.info.error);
    }
    let (_, b1, closed) = ee_and_base(&e);
    let dx = b1.x - b0.x;
    println!("base moved {dx:.4} m in 2 s at 0.25 m/s (expected 0.5 - ramp, tol [0.45, 0.51])");
    assert!((0.45..=0.51).contains(&dx), "dx {dx}");
    assert!(closed);
    let q = e
        .app
        .world
        .resource::<Robots>()
        .robots
        .first()
        .map(|r| {
            let ctx = e.app.world.resource::<RigidContext>();
            r.fixed.robot.joint_positions(ctx).unwrap()[r.fixed.gripper]
        })
        .unwrap();
    println!("finger joint after closing: {q:.4} m (tol < 0.005)");
    assert!(q < 0.005);
}

#[test]
fn ee_pose_delta_moves_the_hand_in_the_base_frame() {
    let mut e = env(&franka_scene("(arm: EePoseDelta)"));
    let (p0, _, _) = ee_and_base(&e);
    // Hand up at 0.25 m/s for 1 s.
    let mut a = vec![0.0f32; 10];
    a[5] = 1.0;
    for _ in 0..60 {
        e.step(&a);
    }
    // Let it settle with zero command.
    let zero = vec![0.0f32; 10];
    for _ in 0..30 {
        e.step(&zero);
    }
    let (p1, _, _) = ee_and_base(&e);
    let d = p1 - p0;
    println!(
        "hand moved ({:.4}, {:.4}, {:.4}) m for 0.25 m up (tol 0.01 along z, 0.01 across)",
        d.x, d.y, d.z
    );
    assert!((d.z - 0.25).abs() <= 0.01);
    assert!(d.x.abs() <= 0.01 && d.y.abs() <= 0.01);
}

#[test]
fn discrete_keys_drive_base_and_hand() {
    let mut e = env(&franka_scene("(discrete: true)"));
    let (p0, b0, _) = ee_and_base(&e);
    let key = |k: DiscreteKey| vec![DiscreteKey::ALL.iter().position(|x| *x == k).unwrap() as f32];
    for _ in 0..60 {
        e.step(&key(DiscreteKey::BodyForward));
    }
    let (_, b1, _) = ee_and_base(&e);
    for _ in 0..40 {
        e.step(&key(DiscreteKey::HandDown));
    }
    for _ in 0..10 {
        e.step(&key(DiscreteKey::Grasp));
    }
    for _ in 0..30 {
        e.step(&key(DiscreteKey::Release));
    }
    let (p2, b2, closed) = ee_and_base(&e);
    let drive = b1.x - b0.x;
    let hand_dz = (p2.z - p0.z) - (b2.z - b0.z);
    println!(
        "1 s of body_forward: {drive:.4} m (tol [0.4, 0.51]); 40 steps of hand_down: {hand_dz:.4} m (expected -0.167, tol 0.02)"
    );
    assert!((0.4..=0.51).contains(&drive));
    assert!((hand_dz + 40.0 / 60.0 * 0.25).abs() <= 0.02);
    assert!(!closed, "release opens the gripper");
    assert_eq!(DiscreteKey::ALL.len(), 14);
}

#[test]
fn reset_restores_the_robot_and_runs_are_deterministic() {
    let run = || {
        let mut e = env(&franka_scene("(arm: EePoseDelta)"));
        let mut a = vec![0.0f32; 10];
        for i in 0..90 {
            a[0] = ((i as f32) * 0.1).sin();
            a[3] = 0.5;
            a[9] = if i > 45 { 1.0 } else { -1.0 };
            e.step(&a);
        }
        e
    };
    let mut e1 = run();
    let e2 = run();
    println!("state hashes {:x} {:x}", e1.state_hash(), e2.state_hash());
    assert_eq!(e1.state_hash(), e2.state_hash());
    let fresh = env(&franka_scene("(arm: EePoseDelta)"));
    e1.reset(Some(1));
    assert_eq!(e1.state_hash(), fresh.state_hash());
}

#[test]
fn franka_square_scene_follows_its_script() {
    let mut e = scene_env("franka_square");
    let mut corners = Vec::new();
    let mut worst_ee: f64 = 0.0;
    for step in 1..=960 {
        let out = e.step(&[]);
        assert!(out.info.error.is_none(), "{:?}", out.info.error);
        if step % 240 == 0 {
            corners.push(ee_and_base(&e).1);
        }
        if step % 60 == 30 {
            // Mid-segment: the hand is within 2 cm of its target (base frame).
            let robots = e.app.world.resource::<Robots>();
            let ctx = e.app.world.resource::<RigidContext>();
            let r = &robots.robots[0];
            let o = r.observe(ctx).unwrap();
            let target = o.base * r.ee_target;
            let err = (o.ee.translation.vector - target.translation.vector).norm();
            if err > 0.02 {
                println!("t {:.2}: hand error {err:.4} m", step as f64 / 60.0);
            }
            worst_ee = worst_ee.max(err);
        }
    }
    let expect = [[1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]];
    for (c, x) in corners.iter().zip(expect) {
        println!(
            "corner ({:.3}, {:.3}) expected ({}, {}) (tol 0.05 m)",
            c.x, c.y, x[0], x[1]
        );
        assert!((c.x - x[0]).abs() <= 0.05 && (c.y - x[1]).abs() <= 0.05);
    }
    println!("worst hand tracking error {worst_ee:.4} m (tol 0.02)");
    assert!(worst_ee <= 0.02);
}

#[test]
fn robot_section_errors_name_the_field() {
    let e =
        compile_err(r#"Scene(objects: [], extensions: { "robots": [(name: "r", model: "ur5")] })"#);
    println!("{e}");
    assert!(e.contains("model") && e.contains("ur5") && e.contains("franka"));
    let e = compile_err(
        r#"Scene(objects: [], extensions: { "robots": [(name: "r", model: "franka", actions: (base: LegJoints))] })"#,
    );
    println!("{e}");
    assert!(e.contains("actions.base") && e.contains("Velocity"));
    let e = compile_err(r#"Scene(objects: [], extensions: { "robtos": [] })"#);
    println!("{e}");
    assert!(e.contains("robtos") && e.contains("robots") && e.contains("--plugin"));
    let e = compile_err(
        r#"Scene(objects: [], extensions: { "robots": [(name: "r", model: "franka", colour: 1)] })"#,
    );
    println!("{e}");
    assert!(e.contains("colour"));
    // the walking controller's parameters: only for legged robots, in range, known fields
    let e = compile_err(
        r#"Scene(objects: [], extensions: { "robots": [(name: "r", model: "franka", gait: (period: 0.3))] })"#,
    );
    println!("{e}");
    assert!(e.contains("gait") && e.contains("legged"));
    let e = compile_err(
        r#"Scene(objects: [], extensions: { "robots": [(name: "r", model: "spot", gait: (period: -0.3))] })"#,
    );
    println!("{e}");
    assert!(e.contains("gait") && e.contains("period"));
    let e = compile_err(
        r#"Scene(objects: [], extensions: { "robots": [(name: "r", model: "spot", gait: (perod: 0.3))] })"#,
    );
    println!("{e}");
    assert!(e.contains("perod"));
}

#[test]
fn a_scene_gait_sets_the_walking_controller() {
    // The trot's command limit lowered to 0.25 m/s: a full forward action (0.5 m/s) walks at it.
    let text = r#"Scene(
    physics: (dt: 0.016666666666666666, substeps: 1, rigid_iterations: 1, rigid_pgs_iterations: 24),
    objects: [(name: "ground", shape: Plane(size: (40.0, 40.0)), body: Static)],
    extensions: { "robots": [(name: "spot", model: "spot", gait: (max_command: (0.25, 0.5, 1.0)))] },
)"#;
    let mut e = env(text);
    let mut a = vec![0.0f32; e.spaces().action.flat_dim()];
    a[0] = 1.0;
    let mut x = Vec::new();
    for _ in 0..300 {
        let out = e.step(&a);
        assert!(out.info.error.is_none(), "{:?}", out.info.error);
        x.push(ee_and_base(&e).1.x);
    }
    let v = (x[299] - x[179]) / 2.0;
    println!("spot with gait max_command 0.25 m/s, commanded 0.5: {v:.3} m/s (tol 0.25 +- 0.05)");
    assert!((v - 0.25).abs() <= 0.05);
}

#[test]
fn spot_leg_joint_mode_stands_with_zero_action() {
    let text = r#"Scene(
    physics: (dt: 0.016666666666666666, substeps: 4, rigid_iterations: 1, rigid_pgs_iterations: 4),
    objects: [(name: "ground", shape: Plane(size: (20.0, 20.0)), body: Static)],
    extensions: { "robots": [(name: "spot", model: "spot", actions: (base: LegJoints))] },
)"#;
    let mut e = env(text);
    let n = e.spaces().action.flat_dim();
    assert_eq!(n, 12 + 6 + 1);
    let (_, b0, _) = ee_and_base(&e);
    for _ in 0..180 {
        let out = e.step(&vec![0.0; n]);
        assert!(out.info.error.is_none(), "{:?}", out.info.error);
    }
    let (_, b, _) = ee_and_base(&e);
    let drift = (b - b0).xy().norm();
    println!(
        "spot body height after 3 s: {:.4} m (tol 0.55 +- 0.03), xy drift {drift:.4} m (tol 0.05; 0.5 m with one PGS sweep)",
        b.z
    );
    assert!((b.z - 0.55).abs() <= 0.03);
    assert!(drift <= 0.05);
}

#[test]
fn spot_walks_through_the_locomotion_action() {
    let text = r#"Scene(
    physics: (dt: 0.016666666666666666, substeps: 4, rigid_iterations: 1, rigid_pgs_iterations: 4),
    objects: [(name: "ground", shape: Plane(size: (40.0, 40.0)), body: Static)],
    extensions: { "robots": [(name: "spot", model: "spot")] },
)"#;
    let mut e = env(text);
    let n = e.spaces().action.flat_dim();
    assert_eq!(n, 3 + 6 + 1);
    let mut a = vec![0.0f32; n];
    a[0] = 1.0; // 0.5 m/s forward
    let mut x = Vec::new();
    for step in 0..360 {
        let out = e.step(&a);
        assert!(out.info.error.is_none(), "{:?}", out.info.error);
        x.push((step, ee_and_base(&e).1));
    }
    // Mean speed over the last 3 s (after a 3 s start).
    let v = (x[359].1.x - x[179].1.x) / 3.0;
    let z = x.iter().map(|(_, b)| b.z).fold(f64::INFINITY, f64::min);
    println!("spot walking through the env: {v:.3} m/s for 0.5 (tol 20 %), lowest body {z:.3} m");
    assert!((v - 0.5).abs() <= 0.1);
    assert!(z > 0.35);
}

#[test]
fn spot_figure_eight_scene_walks_both_loops() {
    let mut e = scene_env("spot_figure_eight");
    let (mut ymin, mut ymax, mut zmin) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY);
    let mut last = Vector3::zeros();
    for _ in 0..1885 {
        let out = e.step(&[]);
        assert!(out.info.error.is_none(), "{:?}", out.info.error);
        last = ee_and_base(&e).1;
        ymin = ymin.min(last.y);
        ymax = ymax.max(last.y);
        zmin = zmin.min(last.z);
    }
    println!(
        "figure eight: y in [{ymin:.3}, {ymax:.3}] (expected about [-2, 2], tol each end 0.6), end ({:.3}, {:.3}) (start (0, 0), tol 0.75 m), lowest body {zmin:.3} m (> 0.35)",
        last.x, last.y
    );
    assert!(ymax > 1.4 && ymax < 2.6 && ymin < -1.4 && ymin > -2.6);
    assert!(last.xy().norm() < 0.75);
    assert!(zmin > 0.35);
}

#[test]
fn arm_joint_targets_respect_velocity_limits() {
    let mut e = env(&franka_scene(
        "(arm: JointPosition, base: Off, gripper: Off)",
    ));
    // Joint 1 asked to jump across its whole range (5.8 rad).
    let mut a = vec![0.0f32; 7];
    a[0] = 1.0;
    let (limit, j) = {
        let r = &e.app.world.resource::<Robots>().robots[0];
        (
            r.fixed.robot.joints[r.fixed.arm[0]].velocity,
            r.fixed.arm[0],
        )
    };
    let mut peak: f64 = 0.0;
    for _ in 0..60 {
        e.step(&a);
        let r = &e.app.world.resource::<Robots>().robots[0];
        let qd = r
            .fixed
            .robot
            .joint_velocities(e.app.world.resource::<RigidContext>())
            .unwrap()[j];
        peak = peak.max(qd.abs());
    }
    println!("joint 1 peak speed {peak:.3} rad/s for a limit of {limit} rad/s (tol +10 %)");
    assert!(peak <= limit * 1.1);
    assert!(peak >= limit * 0.8, "it should move at about the limit");
}

/// Height range (min, max) of a deformable object's nodes.
fn z_range(env: &mut Env, name: &str) -> (f64, f64) {
    use modesuite::engine::components::{DeformableNodes, Object};
    let mut q = env.app.world.query::<(&Object, &DeformableNodes)>();
    let (_, nodes) = q
        .iter(&env.app.world)
        .find(|(o, _)| o.name == name)
        .unwrap_or_else(|| panic!("no deformable named {name}"));
    nodes
        .0
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.z), hi.max(p.z))
        })
}

fn step_n(env: &mut Env, n: usize) {
    for _ in 0..n {
        let o = env.step(&[]);
        assert!(o.info.error.is_none(), "{:?}", o.info.error);
    }
}

#[test]
fn a_closed_gripper_lifts_the_napkin_and_opening_releases_it() {
    let mut env = scene_env("franka_cloth_grasp");
    let (z0, _) = z_range(&mut env, "napkin");
    step_n(&mut env, 200); // t = 3.3 s: fingers around the near edge, still open
    let (_, before) = z_range(&mut env, "napkin");
    step_n(&mut env, 220); // closed at 3.5 s, lifted by 5.5 s, carried sideways by 7 s
    let (_, lifted) = z_range(&mut env, "napkin");
    let held = env
        .app
        .world
        .resource::<modesuite::pbd::PbdContext>()
        .bodies[0]
        .solver
        .attachment_ids()
        .len();
    step_n(&mut env, 120); // opened at 8 s, t = 9 s (the episode ends at 10 s)
    let (_, dropped) = z_range(&mut env, "napkin");
    println!(
        "napkin top: start {z0:.3} m, before closing {before:.3}, held {lifted:.3} ({held} grasp), after opening {dropped:.3}"
    );
    assert!(
        before < 0.47,
        "the open gripper leaves the napkin on the table"
    );
    assert_eq!(held, 1, "one grasp while the gripper is closed");
    assert!(
        lifted > 0.65,
        "the grasped edge is lifted with the hand (> 0.65 m)"
    );
    assert!(dropped < 0.46, "the released napkin falls back");
    let attachments = env
        .app
        .world
        .resource::<modesuite::pbd::PbdContext>()
        .bodies[0]
        .solver
        .attachment_ids()
        .len();
    assert_eq!(attachments, 0, "opening released the grasp");
}

#[test]
fn a_closed_gripper_lifts_a_foam_rod_and_a_reset_drops_the_grasp() {
    let text = std::fs::read_to_string(common::root().join("scenes/examples/franka_cloth_grasp.scene.ron"))
        .unwrap()
        .replace(
            r#"shape: Grid(size: (0.3, 0.3), resolution: (13, 13)),
            pose: (pos: (0.82, 0.0, 0.455)),
            body: Kind(kind: "pbd.cloth", params: (
                areal_density: 0.2,
                friction: 0.6,
                groups: {"edge": Near(at: (-0.15, 0.0, 0.0), radius: 0.03)},
            )),"#,
            r#"shape: Box(size: (0.3, 0.03, 0.03), divisions: (6, 1, 1)),
            pose: (pos: (0.83, 0.0, 0.466)),
            body: Kind(kind: "fem.solid", params: (youngs_modulus: 1e6, poisson_ratio: 0.35, density: 60.0, rayleigh_mass: 1.0)),"#,
        );
    assert!(text.contains("fem.solid"));
    let mut env = Env::new(common::app_from_ron(&text));
    env.reset(Some(0));
    let hash0 = env.state_hash();
    step_n(&mut env, 200);
    let (_, before) = z_range(&mut env, "napkin");
    step_n(&mut env, 220);
    let (_, lifted) = z_range(&mut env, "napkin");
    let grasps = |env: &Env| {
        env.app
            .world
            .resource::<modesuite::fem::FemContext>()
            .bodies[0]
            .solver
            .attached_bodies()
            .len()
    };
    let held = grasps(&env);
    println!("rod top: before closing {before:.3} m, held {lifted:.3} ({held} grasping body)");
    assert!(before < 0.49);
    assert_eq!(held, 1);
    assert!(
        lifted > 0.6,
        "the grasped end is lifted with the hand (> 0.6 m)"
    );
    env.reset(Some(0));
    assert_eq!(
        grasps(&env),
        0,
        "a reset restores the state before the grasp"
    );
    assert_eq!(env.state_hash(), hash0);
}

#[test]
fn an_absolute_ee_target_from_a_rotation_vector_holds_the_hand() {
    // The Franka's initial hand rotation has w < 0; the same rotation sent back as a rotation
    // vector has w >= 0. Both are one rotation: the hand must stay where it is.
    let mut env = env(&franka_scene(
        "(base: Off, arm: EePoseAbsolute, gripper: Off)",
    ));
    let t0 = env.app.world.resource::<Robots>().robots[0].ee_target;
    let rv = t0.rotation.scaled_axis();
    let a: Vec<f32> = [t0.translation.vector, rv]
        .iter()
        .flat_map(|v| v.iter().map(|x| *x as f32))
        .collect();
    let (ee0, _, _) = ee_and_base(&env);
    for _ in 0..60 {
        env.step(&a);
    }
    let (ee1, _, _) = ee_and_base(&env);
    let drift = (ee1 - ee0).norm();
    println!(
        "hand drift after 1 s of the absolute target it started at: {drift:.4} m (tolerance 0.01)"
    );
    assert!(drift < 0.01);
}

// Robots as data: robot description files (`*.robot.ron`). The built-in robots are their
// files; a third robot, the Franka on a fixed pedestal, is added with files only (its URDF from
// assets/robots/generate_models.py, its description file, a scene with a task) and runs a task
// episode; a description file's errors name the file and the place.

const PEDESTAL_SCENE: &str = "scenes/examples/franka_pedestal.scene.ron";
const PEDESTAL_FILE: &str = "assets/robots/franka_pedestal/franka_pedestal.robot.ron";

/// Largest distance of an arm joint from its home position after 200 zero-action steps, rad.
/// The PD motors hold their home targets with gravity compensation of the arm's own links; the
/// foam rod held in the hand (0.24 kg, its centre about 0.4 m ahead of the hand) is not
/// compensated, and the wrist (joint 6, whose inertia-scaled gain is small) gives way by about
/// 0.03 rad under it.
const HOME_TOL: f64 = 0.05;

/// How far the pedestal (the fixed root) may move, m and rad: not at all.
const BASE_TOL: f64 = 1e-9;

fn observe(env: &Env) -> RobotObservation {
    let robots = env.app.world.resource::<Robots>();
    let ctx = env.app.world.resource::<RigidContext>();
    robots.robots[0].observe(ctx).unwrap()
}

fn pedestal_file() -> RobotFile {
    let text = std::fs::read_to_string(common::root().join(PEDESTAL_FILE)).unwrap();
    RobotFile::parse(&text, PEDESTAL_FILE).unwrap()
}

#[test]
fn a_pedestal_franka_from_files_only_runs_a_task_episode() {
    let path = common::root().join(PEDESTAL_SCENE);
    let mut env = make(path.to_str().unwrap(), &MakeOptions::default()).unwrap();
    env.autoreset = false;
    env.reset(Some(0));
    let n = env.spaces().action.flat_dim();
    assert_eq!(n, 6, "EePoseDelta only: no base and no gripper action");
    let start = observe(&env);
    let mut ret = 0.0;
    for _ in 0..200 {
        let out = env.step(&vec![0.0; n]);
        assert!(out.info.error.is_none(), "{:?}", out.info.error);
        assert!(out.reward.is_finite());
        ret += out.reward;
    }
    let end = observe(&env);
    let file = pedestal_file();
    let robots = env.app.world.resource::<Robots>();
    let fixed = &robots.robots[0].fixed;
    assert_eq!(fixed.model, "franka_pedestal");
    let mut worst = (0.0f64, String::new());
    for &j in &fixed.arm {
        let name = &fixed.robot.joints[j].name;
        let home = file.home.get(name).copied().unwrap_or(0.0);
        let err = (end.q[j] - home).abs();
        if err > worst.0 {
            worst = (err, name.clone());
        }
    }
    println!(
        "pedestal Franka, 200 zero-action steps (return {ret:.2}): arm max |q - q_home| = {:.4} rad ({}) (tol {HOME_TOL})",
        worst.0, worst.1
    );
    assert!(worst.0 <= HOME_TOL);
    let moved = (end.base.translation.vector - start.base.translation.vector).norm();
    let turned = end.base.rotation.angle_to(&start.base.rotation);
    println!("pedestal base: moved {moved:.2e} m, turned {turned:.2e} rad (tol {BASE_TOL})");
    assert!(moved <= BASE_TOL && turned <= BASE_TOL);
}

#[test]
fn the_cli_runs_the_pedestal_task_and_lists_the_built_in_robots() {
    let out = common::stdout_ok(common::modesuite_cmd().args([
        "run",
        PEDESTAL_SCENE,
        "--steps",
        "200",
        "--json",
    ]));
    println!("{out}");
    let summary = out.lines().last().unwrap();
    assert!(summary.contains("\"errors\":0") && summary.contains("\"mean_length\":200.0"));
    let out = common::stdout_ok(common::modesuite_cmd().args(["list", "robots"]));
    println!("{out}");
    for (b, spec) in RobotSpec::builtins().into_iter().enumerate() {
        let spec = spec.unwrap_or_else(|e| panic!("built-in {b}: {e}"));
        assert!(out.contains(&spec.id) && out.contains(&spec.description));
    }
}

#[test]
fn the_built_in_robots_are_their_description_files() {
    let app = modesuite::make::default_app();
    for id in ["franka", "spot"] {
        let entry = &app.registry().robots[id];
        let spec = entry.payload.downcast_ref::<RobotSpec>().unwrap();
        let text = std::fs::read_to_string(&spec.file).unwrap();
        let file = RobotFile::parse(&text, &spec.file.display().to_string()).unwrap();
        assert_eq!(file.id, id);
        assert_eq!(entry.description, file.description);
        assert_eq!(spec.arm_joints, file.arm);
        assert_eq!(spec.leg_joints, file.legs);
        assert_eq!(spec.legged(), id == "spot");
        let urdf = spec.file.parent().unwrap().join(&file.urdf);
        assert_eq!(
            std::fs::read_to_string(urdf).unwrap(),
            *spec.urdf_text,
            "{id}: the built-in URDF is the file's"
        );
    }
}

/// A folder of its own under the temporary directory.
fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "modesuite-robot-files-{}-{name}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Compiles a one-robot scene written into `dir`; the error's text when it fails.
fn compile(dir: &Path, model: &str, actions: &str) -> Result<(), String> {
    let scene = dir.join("robot.scene.ron");
    std::fs::write(
        &scene,
        format!(
            r#"Scene(objects: [(name: "ground", shape: Plane(size: (4.0, 4.0)), body: Static)],
    extensions: {{ "robots": [(name: "r", model: "{model}", actions: {actions})] }})"#
        ),
    )
    .unwrap();
    let (desc, source) = modesuite::engine::scene::load_file(&scene).map_err(|e| e.to_string())?;
    let app = modesuite::make::default_app();
    app.compile_scene(&desc, &source)
        .map(|_| ())
        .map_err(|e| e.to_string())
}

#[test]
fn robot_file_errors_name_the_file_and_the_place() {
    let dir = tmp("errors");
    // The pedestal's file copied next to a scene elsewhere, its URDF named by absolute path.
    let urdf = common::root().join("assets/robots/franka_pedestal/franka_pedestal.urdf");
    let good = std::fs::read_to_string(common::root().join(PEDESTAL_FILE))
        .unwrap()
        .replace(
            "urdf: \"franka_pedestal.urdf\"",
            &format!("urdf: {:?}", urdf.display().to_string()),
        );
    std::fs::write(dir.join("ped.robot.ron"), &good).unwrap();
    compile(&dir, "ped.robot.ron", "()").unwrap();
    // Writes a description file (when given), compiles a scene naming it: the error.
    let err = |name: &str, text: Option<&str>, actions: &str| {
        if let Some(t) = text {
            std::fs::write(dir.join(name), t).unwrap();
        }
        let e = compile(&dir, name, actions).unwrap_err();
        println!("{e}");
        e
    };
    // a misspelt field: file:line:col
    let typo = good.replace("ee_frame:", "ee_frme:");
    let e = err("typo.robot.ron", Some(&typo), "()");
    let line = typo.lines().position(|l| l.contains("ee_frme")).unwrap() + 1;
    assert!(e.contains(&format!("typo.robot.ron:{line}:")) && e.contains("ee_frme"));
    // a joint the URDF does not have: the field, the value and the valid joints
    let joint = good.replace("\"panda_joint7\",\n    ]", "\"panda_jont7\",\n    ]");
    let e = err("joint.robot.ron", Some(&joint), "()");
    assert!(e.contains("arm = \"panda_jont7\"") && e.contains("\"panda_joint7\""));
    // a value out of range
    let volume = good.replace("finger_volume: (0.015,", "finger_volume: (0.0,");
    let e = err("volume.robot.ron", Some(&volume), "()");
    assert!(e.contains("gripper.finger_volume = (0.0, 0.04, 0.02)") && e.contains("> 0"));
    // a camera on a link the URDF does not have, and a camera name with a '/'
    let cam = good.replace(
        "cameras: [(link: \"pedestal\"",
        "cameras: [(link: \"pedestl\"",
    );
    let e = err("cam.robot.ron", Some(&cam), "()");
    assert!(e.contains("cameras[0].link = \"pedestl\"") && e.contains("\"pedestal\""));
    let cam = good.replace("cameras: [(link:", "cameras: [(name: \"a/b\", link:");
    let e = err("camname.robot.ron", Some(&cam), "()");
    assert!(e.contains("cameras[0].name = \"a/b\"") && e.contains("without '/'"));
    // a base mode the robot does not have
    let e = err("ped.robot.ron", None, "(base: Velocity)");
    assert!(e.contains("actions.base") && e.contains("Velocity") && e.contains(": Off"));
    // no such file
    let e = err("none.robot.ron", None, "()");
    assert!(e.contains("none.robot.ron") && e.contains("tried"));
    // a file outside the scene's folder and every asset root
    let other = tmp("outside");
    std::fs::write(other.join("x.robot.ron"), &good).unwrap();
    let name = other.file_name().unwrap().to_string_lossy();
    let e = err(&format!("../{name}/x.robot.ron"), None, "()");
    assert!(e.contains("outside the asset roots"));
}

#[test]
fn a_robot_file_brings_its_camera_and_a_render_section_overrides_it() {
    use modesuite::render::RenderConfig;
    let path = common::root().join(PEDESTAL_SCENE);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        !text.contains("\"render\""),
        "the pedestal scene has no render section"
    );
    let compile = |text: &str| {
        let source = SceneSource {
            text: Some(text.to_string()),
            ..SceneSource::in_memory(path.parent().unwrap())
        };
        let desc = modesuite::engine::scene::parse_str(text, "pedestal").unwrap();
        let model = modesuite::make::default_app()
            .compile_scene(&desc, &source)
            .unwrap_or_else(|e| panic!("{e}"));
        RenderConfig::from_scene(&model).unwrap()
    };
    // the robot file's unnamed camera is the robot's own: named like the scene robot
    let cfg = compile(&text);
    let names: Vec<&str> = cfg.cameras.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["robot"]);
    let cam = &cfg.cameras[0];
    assert_eq!(cam.attach.as_deref(), Some("robot/pedestal"));
    assert_eq!(
        (cam.width, cam.height, cam.look_at),
        (128, 128, Some([1.2, 0.0, 0.45]))
    );
    // a render section's camera of the same name wins; its others come first
    let own = text.replacen(
        "extensions: {",
        "extensions: {\"render\": (cameras: [(name: \"top\", width: 8, height: 8), (name: \"robot\", width: 16, height: 12)]),",
        1,
    );
    let cfg = compile(&own);
    let cams: Vec<(&str, u32)> = cfg
        .cameras
        .iter()
        .map(|c| (c.name.as_str(), c.width))
        .collect();
    assert_eq!(cams, [("top", 8), ("robot", 16)]);
    // the env renders it as the policy's image (`run --rgbd robot`)
    let mut env = make(
        path.to_str().unwrap(),
        &MakeOptions {
            rgbd: Some("robot".into()),
            ..MakeOptions::default()
        },
    )
    .unwrap();
    let (obs, info) = env.reset(Some(0));
    assert!(info.error.is_none(), "{:?}", info.error);
    let image = &obs[obs.len() - 128 * 128 * 4..];
    let hit = image.chunks_exact(4).filter(|p| p[3] > 0.0).count();
    println!("pedestal camera from the robot file: {hit} of 16384 pixels hit (> 8000)");
    assert!(hit > 8000);
}

#[test]
fn the_documented_franka_file_is_the_built_in_one() {
    // docs/robots.md shows the Franka's file without its comments
    let doc = std::fs::read_to_string(common::root().join("docs/robots.md")).unwrap();
    let block = doc
        .split("```ron\n")
        .nth(1)
        .and_then(|b| b.split("```").next())
        .unwrap();
    let file = std::fs::read_to_string(
        common::root().join("assets/robots/franka_ridgeback/franka.robot.ron"),
    )
    .unwrap();
    let code: String = file
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .map(|l| format!("{l}\n"))
        .collect();
    assert_eq!(block, code);
}
