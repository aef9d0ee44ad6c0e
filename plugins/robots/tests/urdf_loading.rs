//! URDF loading: both models load with the expected structure and numbers, kinematics match the
//! manufacturers' figures, and bad input gives named errors (never a panic).

mod common;

use std::path::{Path, PathBuf};

use modesuite_engine::deps::nalgebra::Isometry3;
use modesuite_engine::RigidContext;
use modesuite_robots::urdf::{parse_urdf, JointKind};
use modesuite_robots::{
    forward_kinematics, spawn_robot, AssetPaths, RobotError, RootMount, SpawnOptions,
};

#[test]
fn franka_ridgeback_structure_and_kinematics() {
    let (spec, model) = common::model("franka");
    let actuated: Vec<_> = model
        .joints
        .iter()
        .filter(|j| j.kind.is_actuated())
        .collect();
    println!(
        "franka: {} links, {} joints ({} actuated), total mass {:.2} kg",
        model.links.len(),
        model.joints.len(),
        actuated.len(),
        model.total_mass()
    );
    assert_eq!(actuated.len(), 12, "3 base + 7 arm + 2 fingers");
    let j = |n: &str| model.joints[model.joint_index(n).expect(n)].clone();
    // Franka limits and efforts of SPEC.md.
    let expect = [
        ("panda_joint1", -2.8973, 2.8973, 87.0),
        ("panda_joint2", -1.7628, 1.7628, 87.0),
        ("panda_joint3", -2.8973, 2.8973, 87.0),
        ("panda_joint4", -3.0718, -0.0698, 87.0),
        ("panda_joint5", -2.8973, 2.8973, 12.0),
        ("panda_joint6", -0.0175, 3.7525, 12.0),
        ("panda_joint7", -2.8973, 2.8973, 12.0),
    ];
    for (name, lo, hi, effort) in expect {
        let jj = j(name);
        assert_eq!(jj.kind, JointKind::Revolute);
        assert!(
            (jj.lower - lo).abs() < 1e-9 && (jj.upper - hi).abs() < 1e-9,
            "{name}"
        );
        assert!((jj.effort - effort).abs() < 1e-9, "{name}");
    }
    assert!(j("panda_finger_joint2").mimic.is_some());
    assert_eq!(j("base_yaw").kind, JointKind::Continuous);
    let base = model.link_index("base_link").unwrap();
    let m = model.links[base].inertial.as_ref().unwrap().mass;
    assert!((m - 135.0).abs() < 1e-9, "ridgeback mass {m}");

    // Kinematics: with every joint at zero the TCP sits at (0.298, 0, 1.1285) m (Franka DH:
    // 0.21 mount offset + a7 0.088; 0.3059 mount height + 0.333 + 0.316 + 0.384 - 0.107 - 0.1034).
    let mut ctx = RigidContext::new();
    let robot = spec.spawn(&mut ctx, &model, Isometry3::identity()).unwrap();
    let tcp = robot.frame_index(&spec.ee_frame).unwrap();
    let zeros = vec![0.0; robot.num_joints()];
    let p = forward_kinematics(&robot, &ctx, tcp, &zeros)
        .unwrap()
        .translation
        .vector;
    let err = (p - modesuite_engine::deps::nalgebra::Vector3::new(0.298, 0.0, 1.1285)).norm();
    println!("franka TCP at zero joints: {:.4?} (expected [0.298, 0, 1.1285]), error {:.2e} m (tol 1e-4)", p, err);
    assert!(err < 1e-4);
    // Home pose: joints where the spec puts them, mimic finger equal to the first.
    let q = robot.joint_positions(&ctx).unwrap();
    let j4 = robot.joint_index("panda_joint4").unwrap();
    let f1 = robot.joint_index("panda_finger_joint1").unwrap();
    let f2 = robot.joint_index("panda_finger_joint2").unwrap();
    println!(
        "franka home: j4 {:.4} (set -2.810), fingers {:.4} / {:.4} (set 0.04)",
        q[j4], q[f1], q[f2]
    );
    assert!((q[j4] + 2.810).abs() < 1e-5);
    assert!((q[f1] - 0.04).abs() < 1e-6 && (q[f2] - 0.04).abs() < 1e-6);
    println!("franka spawned mass {:.2} kg", robot.total_mass());
}

#[test]
fn spot_structure_and_standing_height() {
    let (spec, model) = common::model("spot");
    let actuated = model.joints.iter().filter(|j| j.kind.is_actuated()).count();
    println!(
        "spot: {} links, {} joints ({actuated} actuated), total mass {:.2} kg (BD: 32.5 kg + 8 kg arm)",
        model.links.len(),
        model.joints.len(),
        model.total_mass()
    );
    assert_eq!(actuated, 19, "12 legs + 6 arm + 1 finger");
    assert!((model.total_mass() - 39.07).abs() < 0.1);
    let kn = &model.joints[model.joint_index("fl_kn").unwrap()];
    assert!((kn.lower + 2.7929).abs() < 1e-9 && (kn.upper + 0.2471).abs() < 1e-9);
    // Feet are spheres.
    let lleg = &model.links[model.link_index("fl_lleg").unwrap()];
    assert!(lleg
        .collisions
        .iter()
        .any(|c| matches!(c.geometry, modesuite_robots::urdf::Geometry::Sphere { .. })));

    let mut ctx = RigidContext::new();
    let robot = spec.spawn(&mut ctx, &model, Isometry3::identity()).unwrap();
    assert_eq!(robot.root_mount, RootMount::Floating);
    // Lowest foot point in the home pose: the body stands 0.55 m above it.
    let mut lowest = f64::INFINITY;
    for leg in ["fl", "fr", "hl", "hr"] {
        let f = robot.frame_index(&format!("{leg}_foot")).unwrap();
        let z = robot.frame_pose(&ctx, f).unwrap().translation.z - 0.036;
        lowest = lowest.min(z);
    }
    let body_z = robot.body_pose(&ctx, 0).unwrap().translation.z;
    let height = body_z - lowest;
    println!("spot standing height (body origin above the foot soles): {height:.4} m (target 0.55 +- 0.01)");
    assert!((height - 0.55).abs() < 0.01);
}

fn write_tmp(dir: &Path, name: &str, text: &str) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

const ONE_JOINT: &str = r#"<robot name="r">
  <link name="a"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <link name="b"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>GEOM</link>
  <joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>LIMIT</joint>
</robot>"#;

fn variant(geom: &str, limit: &str) -> String {
    ONE_JOINT.replace("GEOM", geom).replace("LIMIT", limit)
}

const OK_LIMIT: &str = r#"<limit lower="-1" upper="1" effort="10" velocity="1"/>"#;

#[test]
fn bad_input_gives_named_errors() {
    let root = std::env::temp_dir().join(format!("modesuite-robots-test-{}", std::process::id()));
    let assets_dir = root.join("assets");
    let assets = AssetPaths::new(&assets_dir).with_package("pkg", assets_dir.join("pkg"));
    write_tmp(
        &assets_dir.join("pkg/meshes"),
        "m.stl",
        "solid x\nendsolid x\n",
    );
    write_tmp(&root, "secret.stl", "solid x\nendsolid x\n");
    let base = assets_dir.clone();
    let parse = |text: &str| parse_urdf(text, "test.urdf", &base, &assets);

    // A valid file loads; a package:// visual mesh resolves through the package map.
    let good = variant(
        r#"<visual><geometry><mesh filename="package://pkg/meshes/m.stl"/></geometry></visual>"#,
        OK_LIMIT,
    );
    let m = parse(&good).expect("valid URDF");
    println!("resolved mesh: {:?}", m.links[1].visuals[0].geometry);

    let cases: Vec<(&str, String, &str)> = vec![
        ("not xml", "<robot".to_string(), "invalid URDF"),
        (
            "unknown package",
            variant(
                r#"<visual><geometry><mesh filename="package://nope/m.stl"/></geometry></visual>"#,
                OK_LIMIT,
            ),
            "unknown package `nope`",
        ),
        (
            "escaping path",
            variant(
                r#"<visual><geometry><mesh filename="../secret.stl"/></geometry></visual>"#,
                OK_LIMIT,
            ),
            "outside the asset roots",
        ),
        (
            "escaping package path",
            variant(
                r#"<visual><geometry><mesh filename="package://pkg/../../secret.stl"/></geometry></visual>"#,
                OK_LIMIT,
            ),
            "outside the asset roots",
        ),
        (
            "inverted limits",
            variant(
                "",
                r#"<limit lower="1" upper="-1" effort="10" velocity="1"/>"#,
            ),
            "joint `j`: lower limit",
        ),
        (
            "zero effort",
            variant(
                "",
                r#"<limit lower="-1" upper="1" effort="0" velocity="1"/>"#,
            ),
            "joint `j`: effort",
        ),
        (
            "negative radius",
            variant(
                r#"<collision><geometry><sphere radius="-1"/></geometry></collision>"#,
                OK_LIMIT,
            ),
            "link `b`: sphere radius",
        ),
        (
            "unknown parent",
            good.replace(r#"<parent link="a"/>"#, r#"<parent link="zz"/>"#),
            "unknown parent link `zz`",
        ),
        (
            "two roots",
            good.replace("</robot>", r#"<link name="c"/></robot>"#),
            "exactly one root",
        ),
        (
            "floating joint",
            good.replace(r#"type="revolute""#, r#"type="floating""#),
            "not supported",
        ),
    ];
    for (what, text, needle) in cases {
        let err = parse(&text).expect_err(what);
        let msg = err.to_string();
        println!("{what}: {msg}");
        assert!(msg.contains(needle), "{what}: `{msg}` lacks `{needle}`");
    }

    // read_urdf refuses a file outside the roots.
    let outside = write_tmp(&root, "outside.urdf", &good);
    let err = modesuite_robots::read_urdf(&outside, &assets).expect_err("outside root");
    println!("outside file: {err}");
    assert!(matches!(err, RobotError::OutsideAssetRoots { .. }));

    // A collision mesh is refused at build time, naming the link, and leaves nothing behind.
    let mesh_col = variant(
        r#"<collision><geometry><mesh filename="package://pkg/meshes/m.stl"/></geometry></collision>"#,
        OK_LIMIT,
    );
    let m = parse(&mesh_col).unwrap();
    let mut ctx = RigidContext::new();
    let err = spawn_robot(&mut ctx, &m, &SpawnOptions::default()).expect_err("mesh collision");
    println!("collision mesh: {err}");
    assert!(err.to_string().contains("link `b`"));
    assert_eq!(ctx.bodies.len(), 0, "bodies left after a failed build");

    // An initial position outside the limits is refused with the joint's name.
    let m = parse(&good).unwrap();
    let err = spawn_robot(
        &mut ctx,
        &m,
        &SpawnOptions {
            initial: vec![("j".into(), 2.0)],
            ..SpawnOptions::default()
        },
    )
    .expect_err("outside limits");
    println!("initial outside limits: {err}");
    assert!(err.to_string().contains("joint `j`"));
    assert_eq!(ctx.bodies.len(), 0);
    let _ = std::fs::remove_dir_all(&root);
}
