//! Steps the reference sheet for 630 steps without timing output (for `perf record`).
//! `SC=1` turns self-collision on, `EDGE=1` edge contacts; `CHECK=1` prints every particle deeper
//! than 5 mm inside the cube after each step.
use modesuite_pbd::bench::{reference_scene, BenchConfig, REFERENCE_DT};
use nalgebra::Vector3;

fn main() -> Result<(), modesuite_pbd::PbdError> {
    let mut cfg = BenchConfig::reference(std::env::var("SC").is_ok());
    cfg.settings.edge_contacts = std::env::var("EDGE").is_ok();
    let (mut cloth, cube) = reference_scene(&cfg)?;
    let g = Vector3::new(0.0, 0.0, -9.81);
    let mut r = Vec::new();
    for k in 0..630 {
        r.clear();
        let before = cloth.positions().to_vec();
        cloth.step(REFERENCE_DT, &g, &cube, &mut r)?;
        if std::env::var("CHECK").is_ok() {
            for (i, p) in cloth.positions().iter().enumerate() {
                let d = cube.colliders[0].closest(p).2;
                if d < -0.005 {
                    println!(
                        "step {k} particle {i} depth {d:.4} at {p:?} from {:?} v {:?}",
                        before[i],
                        cloth.velocities()[i]
                    );
                }
            }
        }
    }
    let s = cloth.stretch_stats();
    println!(
        "mean stretch {:.4} %, max {:.3} %, final KE {:.3e} J",
        100.0 * s.mean,
        100.0 * s.max,
        cloth.kinetic_energy()
    );
    Ok(())
}
