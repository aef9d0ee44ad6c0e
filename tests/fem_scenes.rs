//! The FEM example scenes: the clamped reference rod sags as beam theory says and stays stable
//! for 60 s; the dropped torus comes to rest on the ground.

mod common;

use common::{nodes, run_scene as run};
use modesuite::fem::FemContext;

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
    let mut env = run("scenes/examples/torus_drop.scene.ron", 600);
    let n = nodes(&mut env, "torus");
    let zmin = n.iter().map(|p| p.z).fold(f64::MAX, f64::min);
    let zmax = n.iter().map(|p| p.z).fold(f64::MIN, f64::max);
    let ke = env.app.world.resource::<FemContext>().bodies[0]
        .solver
        .kinetic_energy();
    println!("after 10 s: torus z in [{zmin:.4}, {zmax:.4}] m (lying flat: [0, ~0.08]), kinetic energy {ke:.2e} J (< 1e-4)");
    assert!(zmin > -1e-3, "no penetration beyond 1 mm");
    assert!(zmax < 0.1, "lies flat");
    assert!(ke < 1e-4);
}
