//! The cloth example scenes stay stable for 60 s of simulated time.

mod common;

use common::{nodes, run_scene as run};
use modesuite::pbd::PbdContext;

#[test]
fn cloth_drapes_over_the_table_and_comes_to_rest_in_60_s() {
    let mut env = run("scenes/examples/cloth_drape.scene.ron", 3600);
    let n = nodes(&mut env, "sheet");
    assert!(n.iter().all(|p| p.iter().all(|x| x.is_finite())));
    let inside = n
        .iter()
        .filter(|p| p.x.abs() < 0.4 && p.y.abs() < 0.3 && p.z < 0.75 - 1e-4)
        .count();
    let top = n.iter().map(|p| p.z).fold(f64::MIN, f64::max);
    let ke = env.app.world.resource::<PbdContext>().bodies[0]
        .solver
        .kinetic_energy();
    println!("after 60 s: {inside} particles inside the table (0), top z {top:.4} (table 0.75 + 0.002), kinetic energy {ke:.2e} J (< 1e-4)");
    assert_eq!(inside, 0);
    assert!((top - 0.752).abs() < 2e-3);
    assert!(ke < 1e-4);
}

#[test]
fn curtain_is_pushed_aside_and_stays_on_its_bar_for_60_s() {
    let mut env = run("scenes/examples/curtain.scene.ron", 3600);
    let n = nodes(&mut env, "curtain");
    assert!(n.iter().all(|p| p.iter().all(|x| x.is_finite())));
    let top = n.iter().filter(|p| (p.z - 1.25).abs() < 1e-9).count();
    let dump = modesuite::engine::dump::dump_state(&env.app.world);
    let px = dump["objects"]["pusher"]["position"][0].as_f64().unwrap();
    let lowest = n.iter().map(|p| p.z).fold(f64::MAX, f64::min);
    println!("after 60 s: {top} particles still at the bar height, pusher at x = {px:.3} (passed the curtain at x = 0), lowest particle z {lowest:.3}");
    assert!(top >= 10, "pinned top edge stays");
    assert!(px > 0.3, "the box went through");
    assert!(
        lowest > 0.2 && lowest < 0.3,
        "the curtain hangs again: {lowest}"
    );
}

#[test]
fn folded_cloth_is_dragged_by_its_fold_without_layers_crossing_for_60_s() {
    use modesuite::engine::env::Env;
    use modesuite::pbd::testing::layer_crossings;
    let (at, radius) = (-0.02, 0.01); // the scene's fold
    let mut env = run("scenes/examples/cloth_folded_drag.scene.ron", 0);
    // layers from the flat rest shape (pose: translation only): top = beyond the fold's arc,
    // bottom = triangles before the fold
    let (top, bottom, start_x) = {
        let c = &env.app.world.resource::<PbdContext>().bodies[0].solver;
        let rest = c.rest_positions();
        let arc_end = at + std::f64::consts::PI * radius;
        let top: Vec<u32> = (0..rest.len() as u32)
            .filter(|&i| rest[i as usize].x > arc_end + 0.01)
            .collect();
        let bottom: Vec<[u32; 3]> = c
            .triangles()
            .iter()
            .copied()
            .filter(|t| t.iter().all(|&v| rest[v as usize].x < at))
            .collect();
        let x = c.positions().iter().map(|p| p.x).sum::<f64>() / rest.len() as f64;
        (top, bottom, x)
    };
    let step = |env: &mut Env, k: u64| {
        let o = env.step(&[]);
        assert!(o.info.error.is_none(), "step {k}: {:?}", o.info.error);
    };
    let mut max_cross = 0;
    let mut lowest = f64::MAX;
    for k in 0..3600 {
        step(&mut env, k);
        if k % 4 == 0 {
            let c = &env.app.world.resource::<PbdContext>().bodies[0].solver;
            max_cross = max_cross.max(layer_crossings(c.positions(), &top, &bottom));
            lowest = c.positions().iter().map(|p| p.z).fold(lowest, f64::min);
        }
    }
    let n = nodes(&mut env, "cloth");
    assert!(n.iter().all(|p| p.iter().all(|x| x.is_finite())));
    let c = &env.app.world.resource::<PbdContext>().bodies[0].solver;
    let x = n.iter().map(|p| p.x).sum::<f64>() / n.len() as f64;
    let ke = c.kinetic_energy();
    let s = c.stretch_stats();
    println!(
        "folded drag, 60 s: {max_cross} layer crossings (demand 0, checked every 4th step); centroid x {start_x:.3} -> {x:.3} m (handle moved 0.30 m; demand > 0.2); lowest particle z {lowest:.4} m (floor 0, half thickness 0.002); kinetic energy {ke:.2e} J (< 1e-4); stretch mean {:.3} % max {:.2} %",
        100.0 * s.mean,
        100.0 * s.max
    );
    assert_eq!(max_cross, 0);
    assert!(x - start_x > 0.2, "the cloth was not dragged");
    assert!(lowest > 0.0, "a particle went through the floor");
    assert!(ke < 1e-4, "not at rest after the drag");
    assert!(s.max < 0.5, "torn-looking stretch {}", s.max);
}
