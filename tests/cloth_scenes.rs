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
