//! Reference-rod benchmark: `cargo run -p modesuite-fem --release --example rod_bench -- [E] [nx ny nz] [steps]`.

use modesuite_fem::bench::{run_rod_bench, RodBench};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let num = |i: usize, d: f64| args.get(i).and_then(|s| s.parse::<f64>().ok()).unwrap_or(d);
    let b = RodBench {
        youngs_modulus: num(0, 1e8),
        cells: [
            num(1, 10.0) as usize,
            num(2, 1.0) as usize,
            num(3, 1.0) as usize,
        ],
        steps: num(4, 600.0) as usize,
        ..RodBench::default()
    };
    match run_rod_bench(&b) {
        Ok(r) => {
            println!(
                "reference rod E={:e} grid {:?}: {} nodes, {} tet10 elements",
                b.youngs_modulus, b.cells, r.nodes, r.elements
            );
            println!(
                "  {} steps dt=1/60 in {:.3} s: {:.0} steps/s, {:.2} Newton/step, {:.2} PCG/step",
                r.steps, r.seconds, r.steps_per_second, r.newton_per_step, r.pcg_per_step
            );
            println!(
                "  tip deflection: linear static {:.3} mm ({:.4} of theory), nonlinear static {:.3} mm ({:.4}), end of dynamic run {:.3} mm; theory qL^4/8EI {:.3} mm",
                r.linear_static_deflection * 1e3,
                r.linear_static_deflection / r.theory,
                r.nonlinear_static_deflection * 1e3,
                r.nonlinear_static_deflection / r.theory,
                r.final_dynamic_deflection * 1e3,
                r.theory * 1e3
            );
        }
        Err(e) => {
            eprintln!("benchmark failed: {e}");
            std::process::exit(1);
        }
    }
}
