//! Costs of burn (flex backend) for this crate's network sizes. Ignored by default: run with
//! `cargo test -p modesuite-learn --test speed -- --ignored --nocapture`.

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::Device;
use modesuite_learn::nets::{flat_params, Activation, Mlp};
use modesuite_learn::rng::Rng;
use modesuite_learn::tensors::{tensor2, to_vec};
use std::time::Instant;

fn time<F: FnMut()>(reps: usize, mut f: F) -> f64 {
    f();
    let start = Instant::now();
    for _ in 0..reps {
        f();
    }
    start.elapsed().as_secs_f64() / reps as f64
}

/// The same MLP by hand (row-major weights `[in, out]`), one observation.
fn by_hand(layers: &[(Vec<f32>, Vec<f32>, usize, usize)], x: &[f32]) -> Vec<f32> {
    let mut h = x.to_vec();
    for (w, b, d_in, d_out) in layers {
        let mut y = b.clone();
        for i in 0..*d_in {
            let xi = h[i];
            let row = &w[i * d_out..(i + 1) * d_out];
            for (yj, wij) in y.iter_mut().zip(row) {
                *yj += xi * wij;
            }
        }
        for v in &mut y {
            *v = if *v > 0.0 { *v } else { v.exp_m1() };
        }
        h = y;
    }
    h
}

#[test]
#[ignore]
fn burn_costs_for_small_mlps() {
    let (obs, hidden) = (40usize, [256usize, 128, 64]);
    let ad = Device::flex().autodiff();
    let mut rng = Rng::new(0);
    let mut net = Mlp::new(&mut rng, obs, &hidden, Activation::Elu, &ad);
    let mut opt = AdamConfig::new().init();
    for batch in [256usize, 4096] {
        let x: Vec<f32> = (0..batch * obs).map(|_| rng.normal() as f32).collect();
        let s = time(20, || {
            let out = net.forward(tensor2(&x, batch, obs, &ad));
            let loss = out.square().mean();
            let g = GradientsParams::from_grads(loss.backward(), &net);
            net = opt.step(1e-4, net.clone(), g);
        });
        println!(
            "forward + backward + Adam, 40-256-128-64 ELU, batch {batch}: {:.2} ms ({:.0} samples/s)",
            s * 1e3,
            batch as f64 / s
        );
    }
    let plain = net.valid();
    let dev = Device::flex();
    for batch in [1usize, 16, 256] {
        let x: Vec<f32> = (0..batch * obs).map(|_| rng.normal() as f32).collect();
        let s = time(200, || {
            let _ = to_vec(plain.forward(tensor2(&x, batch, obs, &dev)));
        });
        let s_ad = time(200, || {
            let _ = to_vec(net.forward(tensor2(&x, batch, obs, &ad)));
        });
        println!(
            "inference, batch {batch}: {:.1} us (plain device), {:.1} us (autodiff device, no backward)",
            s * 1e6,
            s_ad * 1e6
        );
    }
    // The same forward pass written by hand, for the per-operation overhead.
    let flat = flat_params(&plain);
    let mut layers = Vec::new();
    let (mut at, mut d_in) = (0, obs);
    for &h in &hidden {
        let w = flat[at..at + d_in * h].to_vec();
        at += d_in * h;
        let b = flat[at..at + h].to_vec();
        at += h;
        layers.push((w, b, d_in, h));
        d_in = h;
    }
    let x: Vec<f32> = (0..obs).map(|_| rng.normal() as f32).collect();
    let burn_out = to_vec(plain.forward(tensor2(&x, 1, obs, &dev)));
    let hand_out = by_hand(&layers, &x);
    for (a, b) in burn_out.iter().zip(&hand_out) {
        assert!((a - b).abs() < 1e-4, "{a} vs {b}");
    }
    let s = time(2000, || {
        std::hint::black_box(by_hand(&layers, std::hint::black_box(&x)));
    });
    println!(
        "inference by hand (plain loops), batch 1: {:.1} us",
        s * 1e6
    );
}
