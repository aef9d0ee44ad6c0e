//! Prints an FNV hash of the reference sheet's state after 630 steps (with and without
//! self-collision), for checking that a change keeps the arithmetic bit for bit.
use modesuite_pbd::bench::{reference_scene, BenchConfig, REFERENCE_DT};
use nalgebra::Vector3;

fn main() -> Result<(), modesuite_pbd::PbdError> {
    for sc in [false, true] {
        let cfg = BenchConfig::reference(sc);
        let (mut cloth, cube) = reference_scene(&cfg)?;
        let g = Vector3::new(0.0, 0.0, -9.81);
        let mut r = Vec::new();
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for _ in 0..630 {
            r.clear();
            cloth.step(REFERENCE_DT, &g, &cube, &mut r)?;
            for x in cloth.get_state() {
                h = (h ^ x.to_bits()).wrapping_mul(0x100_0000_01b3);
            }
        }
        let s = cloth.stretch_stats();
        println!(
            "self_collision={sc} hash {h:016x} stretch mean {:.4} % max {:.3} %",
            100.0 * s.mean,
            100.0 * s.max
        );
    }
    Ok(())
}
