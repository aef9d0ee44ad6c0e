//! Prints per-step solver statistics of the reference rod (diagnostics).
use modesuite_fem::bench::reference_rod;
use modesuite_fem::{FemConfig, NoContacts};
use nalgebra::Vector3;
fn main() {
    let arg = |i: usize, d: f64| {
        std::env::args()
            .nth(i)
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let config = FemConfig {
        refactor_iterations: arg(2, 40.0) as usize,
        linear_tolerance: arg(3, 1e-6),
        ..FemConfig::default()
    };
    let (mut rod, tip) = reference_rod(arg(1, 1e8), 0.3, [10, 1, 1], config).unwrap();
    let mut r = Vec::new();
    let t0 = std::time::Instant::now();
    let (mut nn, mut pp) = (0, 0);
    for k in 0..600 {
        let s = rod
            .step(
                1.0 / 60.0,
                Vector3::new(0.0, 0.0, -9.81),
                &NoContacts,
                &mut r,
            )
            .unwrap();
        nn += s.newton_iterations;
        pp += s.linear_iterations;
        if k % 100 == 0 {
            println!("step {k}: {s:?} tip z {:.6}", rod.embedded_position(&tip).z);
        }
    }
    let t = t0.elapsed().as_secs_f64();
    println!(
        "{:.0} steps/s newton/step {:.2} pcg/step {:.2} tip {:.6}",
        600.0 / t,
        nn as f64 / 600.0,
        pp as f64 / 600.0,
        rod.embedded_position(&tip).z
    );
}
