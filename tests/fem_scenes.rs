//! The FEM example scenes: the clamped reference rod sags as beam theory says and stays stable
//! for 60 s; the dropped torus comes to rest on the ground; the belt pushed up by a box is lifted,
//! never penetrated, gives the box no energy and settles (60 s); and the regression case of a
//! light box launched fast against a thin belt (it used to explode within 8 steps); a bad
//! `penalty_contacts` is refused with the object named.

mod common;

use common::{nodes, root, run_scene as run};
use modesuite::engine::components::{Object, Pose, Velocity};
use modesuite::fem::FemContext;
use modesuite::prelude::*;
use nalgebra::Vector3;

#[test]
fn clamped_rod_sags_like_a_beam_and_is_stable_for_60_s() {
    let mut env = run("scenes/examples/rod_clamped.scene.ron", 3600);
    let n = nodes(&mut env, "rod");
    assert!(n.iter().all(|p| p.iter().all(|x| x.is_finite())));
    // Tip: the mean height of the nodes of the free end face (rest x = 1.0).
    let ctx = env.app.world.resource::<FemContext>();
    let solid = &ctx.bodies[0].solver;
    let tip: Vec<usize> = solid
        .rest_positions()
        .iter()
        .enumerate()
        .filter(|(_, p)| (p.x - 1.0).abs() < 1e-9)
        .map(|(i, _)| i)
        .collect();
    let z_tip = tip.iter().map(|&i| n[i].z).sum::<f64>() / tip.len() as f64;
    let deflection = 1.0 - z_tip;
    // Euler-Bernoulli: q L^4 / (8 E I), q = rho g A.
    let (e, rho, a, l): (f64, f64, f64, f64) = (1e8, 1000.0, 0.04 * 0.04, 1.0);
    let i = 0.04f64.powi(4) / 12.0;
    let theory = rho * 9.81 * a * l.powi(4) / (8.0 * e * i);
    let ke = solid.kinetic_energy();
    println!(
        "after 60 s: tip deflection {:.2} mm, beam theory {:.2} mm, ratio {:.4} (within 5 %: 0.95..1.05; 10x1x1 grid); kinetic energy {ke:.2e} J",
        1e3 * deflection,
        1e3 * theory,
        deflection / theory
    );
    assert!((deflection / theory - 1.0).abs() < 0.05);
    assert!(ke < 1e-6);
}

#[test]
fn dropped_torus_comes_to_rest_on_the_ground() {
    let mut env = run("scenes/examples/torus_drop.scene.ron", 3600);
    let n = nodes(&mut env, "torus");
    let zmin = n.iter().map(|p| p.z).fold(f64::MAX, f64::min);
    let zmax = n.iter().map(|p| p.z).fold(f64::MIN, f64::max);
    let ke = env.app.world.resource::<FemContext>().bodies[0]
        .solver
        .kinetic_energy();
    println!("after 60 s: torus z in [{zmin:.4}, {zmax:.4}] m (lying flat: [0, ~0.08]), kinetic energy {ke:.2e} J (< 1e-4)");
    assert!(zmin > -1e-3, "no penetration beyond 1 mm");
    assert!(zmax < 0.1, "lies flat");
    assert!(ke < 1e-4);
}

/// What a run of a belt scene with a box named "pusher" measured.
struct BeltRun {
    /// Largest rise of a belt node above its rest height, m.
    max_lift: f64,
    /// Largest depth of a belt node inside the box, m.
    max_penetration: f64,
    /// Largest gain of the box's mechanical energy over its initial value, J.
    max_energy_gain: f64,
    /// Largest belt node speed, m/s.
    max_node_speed: f64,
    /// Largest box angular speed, rad/s.
    max_spin: f64,
    env: Env,
}

/// Steps a scene (RON text) with a belt ("belt", rest height `z_rest`) and a dynamic 0.1 m cube of
/// mass `mass` ("pusher"), measuring every step; the box's spin only counts while it is above
/// z = 0.2 m (in reach of the belt, not landing on the ground).
fn run_belt(file: &str, text: &str, steps: u64, z_rest: f64, mass: f64) -> BeltRun {
    let desc = modesuite::engine::scene::parse_str(text, file).unwrap();
    let source = SceneSource::in_memory(root());
    let mut app = modesuite::make::default_app();
    let model = app.compile_scene(&desc, &source).unwrap();
    app.spawn_scene(model).unwrap();
    let mut env = Env::new(app);
    env.autoreset = false;
    env.reset(Some(0));
    let g = 9.81;
    let inertia = mass * (0.1f64.powi(2) + 0.1f64.powi(2)) / 12.0;
    let box_state = |env: &mut Env| {
        let mut q = env.app.world.query::<(&Object, &Pose, &Velocity)>();
        q.iter(&env.app.world)
            .find(|(o, _, _)| o.name == "pusher")
            .map(|(_, p, v)| (p.0, v.linear, v.angular))
            .unwrap()
    };
    let energy = |v: &Vector3<f64>, w: &Vector3<f64>, z: f64| {
        0.5 * mass * v.norm_squared() + 0.5 * inertia * w.norm_squared() + mass * g * z
    };
    let (p0, v0, w0) = box_state(&mut env);
    let e0 = energy(&v0, &w0, p0.translation.z);
    let mut run = BeltRun {
        max_lift: 0.0,
        max_penetration: 0.0,
        max_energy_gain: f64::MIN,
        max_node_speed: 0.0,
        max_spin: 0.0,
        env,
    };
    let mut prev = nodes(&mut run.env, "belt");
    for i in 0..steps {
        let o = run.env.step(&[]);
        assert!(
            o.info.error.is_none(),
            "{file} step {i}: {:?}",
            o.info.error
        );
        let n = nodes(&mut run.env, "belt");
        let (pose, v, w) = box_state(&mut run.env);
        let inv = pose.inverse();
        for (x, xp) in n.iter().zip(&prev) {
            assert!(
                x.iter().all(|c| c.is_finite()),
                "{file} step {i}: non-finite node"
            );
            run.max_lift = run.max_lift.max(x.z - z_rest);
            run.max_node_speed = run.max_node_speed.max((x - xp).norm() * 60.0);
            let l = inv * nalgebra::Point3::from(*x);
            let depth = (0..3).map(|k| 0.05 - l[k].abs()).fold(f64::MAX, f64::min);
            run.max_penetration = run.max_penetration.max(depth);
        }
        run.max_energy_gain = run
            .max_energy_gain
            .max(energy(&v, &w, pose.translation.z) - e0);
        if pose.translation.z > 0.2 {
            run.max_spin = run.max_spin.max(w.norm());
        }
        prev = n;
    }
    run
}

#[test]
fn belt_pushed_up_by_a_box_is_lifted_without_penetration_and_settles_in_60_s() {
    let file = "scenes/examples/belt_pushed.scene.ron";
    let text = std::fs::read_to_string(root().join(file)).unwrap();
    let mut r = run_belt(file, &text, 3600, 0.502, 2.0);
    let ke = r.env.app.world.resource::<FemContext>().bodies[0]
        .solver
        .kinetic_energy();
    let mut q = r.env.app.world.query::<(&Object, &Pose)>();
    let box_z = q
        .iter(&r.env.app.world)
        .find(|(o, _)| o.name == "pusher")
        .map(|(_, p)| p.0.translation.z)
        .unwrap();
    println!(
        "belt pushed by a 2 kg box at 1.5 m/s, 60 s: max lift {:.1} mm (> 30), max node depth inside the box {:.2} mm (<= 1), box energy gain {:.2e} J (<= 1e-3), max node speed {:.2} m/s (< 5), max box spin near the belt {:.3} rad/s (< 1); at the end belt kinetic energy {ke:.2e} J (< 1e-6), box height {box_z:.4} m (on the ground: 0.05)",
        1e3 * r.max_lift,
        1e3 * r.max_penetration,
        r.max_energy_gain,
        r.max_node_speed,
        r.max_spin
    );
    assert!(r.max_lift > 0.03, "the box lifts the belt");
    assert!(r.max_penetration <= 1e-3, "no node inside the box");
    assert!(
        r.max_energy_gain <= 1e-3,
        "the belt gives the box no energy"
    );
    assert!(r.max_node_speed < 5.0);
    assert!(r.max_spin < 1.0, "the box is not spun by the reactions");
    assert!(ke < 1e-6, "the belt settles");
    assert!((box_z - 0.05).abs() < 2e-3, "the box rests on the ground");
}

#[test]
fn light_fast_box_against_a_thin_belt_does_not_explode() {
    // Regression (docs/repro/fem_belt_pushed_by_box.scene.ron): a box launched at a 4 mm belt
    // blew the belt up within 8 steps and flung the box away (node speeds 1e3 m/s). Causes: the
    // belt's far-side nodes were constrained onto the box face too (crushing every element), the
    // contact nodes alone were moved to the box (inverting the elements next to them), and the
    // unconverged solve's gradient went to the box as reactions. Here: the belt scene with a
    // 0.5 kg box at 3 m/s (it moves 5 cm, 12 belt thicknesses, per step).
    let file = "scenes/examples/belt_pushed.scene.ron";
    let text = std::fs::read_to_string(root().join(file)).unwrap().replace(
        "Dynamic(mass: 2.0, linear_velocity: (0.0, 0.0, 1.5))",
        "Dynamic(mass: 0.5, linear_velocity: (0.0, 0.0, 3.0))",
    );
    assert!(text.contains("mass: 0.5"));
    let r = run_belt(file, &text, 40, 0.502, 0.5);
    println!(
        "0.5 kg box at 3 m/s, 40 steps: max lift {:.1} mm (> 50), max node depth inside the box {:.2} mm (<= 1), box energy gain {:.2e} J (<= 1e-3), max node speed {:.2} m/s (< 10), max box spin near the belt {:.3} rad/s (< 1)",
        1e3 * r.max_lift,
        1e3 * r.max_penetration,
        r.max_energy_gain,
        r.max_node_speed,
        r.max_spin
    );
    assert!(r.max_lift > 0.05);
    assert!(r.max_penetration <= 1e-3);
    assert!(r.max_energy_gain <= 1e-3);
    assert!(r.max_node_speed < 10.0);
    assert!(r.max_spin < 1.0);
}

/// A solid in free fall, whose only coupling is the grasp-free, contact-free world.
fn falling_block(physics: &str) -> Vec<Vector3<f64>> {
    let text = format!(
        r#"Scene(
    physics: {physics},
    objects: [(name: "block", shape: Box(size: (0.2, 0.1, 0.05), divisions: (2, 1, 1)),
               pose: (pos: (0.0, 0.0, 2.0)),
               body: Kind(kind: "fem.solid", params: (youngs_modulus: 1e5, poisson_ratio: 0.3, density: 500.0)))],
)"#
    );
    let mut env = Env::new(common::app_from_ron(&text));
    env.autoreset = false;
    env.reset(Some(0));
    for _ in 0..20 {
        let o = env.step(&[]);
        assert!(o.info.error.is_none(), "{:?}", o.info.error);
    }
    nodes(&mut env, "block")
}

/// Largest distance between corresponding nodes of two runs, m.
fn largest_gap(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q).norm())
        .fold(0.0, f64::max)
}

#[test]
fn deformable_substeps_step_deformables_at_their_own_rate() {
    // 4 rigid substeps with 2 deformable steps per physics step: the solid moves as with 2
    // substeps (same dt up to rounding), not as with 4 (a different implicit-Euler trajectory).
    let strided =
        falling_block("(dt: 0.016666666666666666, substeps: 4, deformable_substeps: Some(2))");
    let two = falling_block("(dt: 0.016666666666666666, substeps: 2)");
    let four = falling_block("(dt: 0.016666666666666666, substeps: 4)");
    let (d2, d4) = (largest_gap(&strided, &two), largest_gap(&strided, &four));
    println!("after 20 steps of free fall: strided vs 2 substeps {d2:.2e} m (<= 1e-9), vs 4 substeps {d4:.2e} m (> 1e-6)");
    assert!(d2 <= 1e-9);
    assert!(d4 > 1e-6);
    // and it fell: 20/60 s of free fall from rest, about 0.54 m
    let z = strided.iter().map(|p| p.z).sum::<f64>() / strided.len() as f64;
    assert!(z < 1.6, "mean height {z}");
}

#[test]
fn deformable_substeps_above_substeps_split_each_rigid_substep() {
    // 1 rigid substep with 4 deformable steps per physics step: the solid moves as with 4
    // substeps (same dt up to rounding), not as with 1.
    let split =
        falling_block("(dt: 0.016666666666666666, substeps: 1, deformable_substeps: Some(4))");
    let four = falling_block("(dt: 0.016666666666666666, substeps: 4)");
    let one = falling_block("(dt: 0.016666666666666666, substeps: 1)");
    let (d4, d1) = (largest_gap(&split, &four), largest_gap(&split, &one));
    println!("after 20 steps of free fall: split vs 4 substeps {d4:.2e} m (<= 1e-9), vs 1 substep {d1:.2e} m (> 1e-6)");
    assert!(d4 <= 1e-9);
    assert!(d1 > 1e-6);
}

#[test]
fn a_negative_penalty_contact_stiffness_is_refused_with_the_object_named() {
    let text = r#"Scene(
    objects: [
        (name: "ground", shape: Plane(size: (2.0, 2.0)), body: Static),
        (name: "rod", shape: Box(size: (0.4, 0.04, 0.04), divisions: (4, 1, 1)), pose: (pos: (0.0, 0.0, 0.1)),
         body: Kind(kind: "fem.solid", params: (youngs_modulus: 1e6, poisson_ratio: 0.3, penalty_contacts: Some(-1.0)))),
    ],
)"#;
    let err = modesuite::make::env_from_text(text)
        .err()
        .expect("refused")
        .to_string();
    println!("{err}");
    assert!(err.contains("\"rod\""), "{err}");
    assert!(err.contains("config.penalty_contacts"), "{err}");
    assert!(err.contains(">= 0"), "{err}");
    // and a valid one compiles
    let ok = text.replace("Some(-1.0)", "Some(100.0)");
    assert!(modesuite::make::env_from_text(&ok).is_ok());
}
