//! temporary probe
use modesuite_fem::bench::reference_rod;
use modesuite_fem::{FemConfig, NoContacts};
use nalgebra::Vector3;
fn main() {
    for qn in [true, false] {
        let (mut rod, _) = reference_rod(1e8, 0.3, [40, 2, 2], FemConfig { quasi_newton: qn, ..FemConfig::default() }).unwrap();
        let mut r = Vec::new();
        let (mut n, mut l, mut f) = (0, 0, 0);
        let t0 = std::time::Instant::now();
        for _ in 0..60 {
            let s = rod.step(1.0 / 60.0, Vector3::new(0.0, 0.0, -9.81), &NoContacts, &mut r).unwrap();
            n += s.newton_iterations;
            l += s.linear_iterations;
            f += s.factorizations;
        }
        println!("qn {qn}: {:.1} steps/s, newton {n} linear {l} factorizations {f}", 60.0 / t0.elapsed().as_secs_f64());
    }
}
