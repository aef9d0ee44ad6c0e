//! Penalty contacts (`FemConfig::penalty_contacts`): a block resting on the ground sinks by its
//! weight over the contact stiffness, and one sliding on it stops where Coulomb friction says.

use modesuite_fem::testing::box_mesh;
use modesuite_fem::{FemConfig, FemSolid, HalfSpace, Material};
use nalgebra::Vector3;

const G: f64 = 9.81;
const DT: f64 = 1.0 / 60.0;
const SCALE: f64 = 100.0;

/// A 0.2 x 0.04 x 0.04 m foam block (E 1e5 Pa, 200 kg/m^3) standing on z = 0.
fn block() -> FemSolid {
    let (nodes, tets) = box_mesh(Vector3::zeros(), Vector3::new(0.2, 0.04, 0.04), [4, 1, 1]);
    let config = FemConfig {
        penalty_contacts: SCALE,
        ..FemConfig::default()
    };
    FemSolid::new(
        &nodes,
        &tets,
        Material::new(1e5, 0.3, 200.0).unwrap(),
        config,
    )
    .unwrap()
}

fn ground(friction: f64) -> HalfSpace {
    HalfSpace {
        origin: Vector3::zeros(),
        normal: Vector3::z(),
        friction,
        body: 0,
        velocity: Vector3::zeros(),
    }
}

fn centroid(s: &FemSolid) -> Vector3<f64> {
    let m: f64 = s.masses().iter().sum();
    s.positions()
        .iter()
        .zip(s.masses())
        .map(|(x, mi)| x * *mi)
        .sum::<Vector3<f64>>()
        / m
}

#[test]
fn a_resting_block_sinks_by_its_weight_over_the_contact_stiffness() {
    let mut s = block();
    let floor = ground(0.5);
    let bottom = s.rest_nodes_where(|p| p.z.abs() < 1e-12);
    let mut reactions = Vec::new();
    for _ in 0..180 {
        s.step(DT, Vector3::new(0.0, 0.0, -G), &floor, &mut reactions)
            .unwrap();
    }
    // the weight spread over the bottom nodes' springs k_i = SCALE m_i / dt^2, the block
    // nearly rigid against them: every bottom node sinks by M g / sum k_i
    let total: f64 = s.masses().iter().sum();
    let k: f64 = bottom
        .iter()
        .map(|&i| SCALE * s.masses()[i as usize] / (DT * DT))
        .sum();
    let expected = total * G / k;
    let sunk = -bottom
        .iter()
        .map(|&i| s.positions()[i as usize].z)
        .sum::<f64>()
        / bottom.len() as f64;
    let speed = s.velocities().iter().map(|v| v.norm()).fold(0.0, f64::max);
    println!(
        "resting block: sank {sunk:.3e} m, M g / sum k = {expected:.3e} m (within 10 %); \
         fastest node {speed:.1e} m/s (limit 1e-3)"
    );
    assert!((sunk / expected - 1.0).abs() < 0.1);
    assert!(speed < 1e-3);
}

#[test]
fn a_block_sliding_on_the_ground_stops_where_coulomb_friction_says() {
    let mu = 0.5;
    let v0 = 1.0;
    let mut s = block();
    let floor = ground(mu);
    let mut reactions = Vec::new();
    // settle, then launch along x
    for _ in 0..30 {
        s.step(DT, Vector3::new(0.0, 0.0, -G), &floor, &mut reactions)
            .unwrap();
    }
    let pos = s.positions().to_vec();
    let vel = vec![Vector3::new(v0, 0.0, 0.0); pos.len()];
    s.set_positions_velocities(&pos, &vel).unwrap();
    let start = centroid(&s);
    let mut impulse = Vector3::zeros();
    for _ in 0..90 {
        reactions.clear();
        s.step(DT, Vector3::new(0.0, 0.0, -G), &floor, &mut reactions)
            .unwrap();
        impulse += reactions.iter().map(|r| r.impulse).sum::<Vector3<f64>>();
    }
    let slid = (centroid(&s) - start).x;
    let coulomb = v0 * v0 / (2.0 * mu * G);
    let speed = s.velocities().iter().map(|v| v.norm()).fold(0.0, f64::max);
    let total: f64 = s.masses().iter().sum();
    println!(
        "sliding block: slid {slid:.4} m, Coulomb v0^2 / (2 mu g) = {coulomb:.4} m (within 5 %); \
         at rest {speed:.1e} m/s (limit 1e-2); friction impulse on the ground {:.4} N s, \
         the block's momentum {:.4} N s (within 5 %)",
        impulse.x,
        total * v0
    );
    assert!((slid / coulomb - 1.0).abs() < 0.05);
    assert!(speed < 1e-2);
    assert!((impulse.x / (total * v0) - 1.0).abs() < 0.05);
}

/// The block with 0.5 kg pressing evenly on its top nodes, and those external forces.
fn loaded_block() -> (FemSolid, Vec<Vector3<f64>>) {
    let mut s = block();
    let top = s.rest_nodes_where(|p| (p.z - 0.04).abs() < 1e-12);
    let mut forces = vec![Vector3::zeros(); s.n_nodes()];
    for &i in &top {
        forces[i as usize] = Vector3::new(0.0, 0.0, -0.5 * G / top.len() as f64);
    }
    s.set_external_forces(&forces).unwrap();
    (s, forces)
}

#[test]
fn a_heavily_loaded_block_at_rest_keeps_its_factor_and_solves_directly() {
    // 0.5 kg pressing on the top of the 0.064 kg block: the bottom nodes' contact and sticking
    // friction stiffness is part of the factored matrix (chord matrix and preconditioner), so a
    // resting step converges in a few chord iterations with the factor of the step before;
    // without it a 20 kg box on a belt needed 100-250 conjugate-gradient iterations per solve
    let (mut s, _) = loaded_block();
    let floor = ground(0.5);
    let mut reactions = Vec::new();
    for _ in 0..300 {
        s.step(DT, Vector3::new(0.0, 0.0, -G), &floor, &mut reactions)
            .unwrap();
    }
    let (mut factorizations, mut newton, mut linear) = (0, 0, 0);
    for _ in 0..60 {
        let st = s
            .step(DT, Vector3::new(0.0, 0.0, -G), &floor, &mut reactions)
            .unwrap();
        assert!(st.converged);
        factorizations += st.factorizations;
        newton += st.newton_iterations;
        linear += st.linear_iterations;
    }
    let speed = s.velocities().iter().map(|v| v.norm()).fold(0.0, f64::max);
    println!(
        "loaded block, 60 steps at rest: {factorizations} factorisations (limit 0), {newton} \
         Newton or chord iterations (limit 180), {linear} linear iterations (limit 2 per \
         iteration: direct solves); fastest node {speed:.1e} m/s (limit 1e-3)"
    );
    assert_eq!(factorizations, 0);
    assert!(newton <= 180);
    assert!(linear <= 2 * newton);
    assert!(speed < 1e-3);
}

#[test]
fn a_loaded_sliding_block_continues_bit_exactly_from_its_state() {
    // the factor holding the contacts' Hessians is not state: it is rebuilt from the state
    // (positions, velocities, contact memory) and must give the same steps
    let (mut s, forces) = loaded_block();
    let floor = ground(0.5);
    let mut reactions = Vec::new();
    let g = Vector3::new(0.0, 0.0, -G);
    for _ in 0..60 {
        s.step(DT, g, &floor, &mut reactions).unwrap();
    }
    let pos = s.positions().to_vec();
    let vel = vec![Vector3::new(0.5, 0.0, 0.0); pos.len()];
    s.set_positions_velocities(&pos, &vel).unwrap();
    for _ in 0..5 {
        s.step(DT, g, &floor, &mut reactions).unwrap();
    }
    let saved = s.get_state();
    let mut copy = block();
    copy.set_external_forces(&forces).unwrap();
    copy.set_state(&saved).unwrap();
    let mut first_diff = None;
    for k in 0..40 {
        s.step(DT, g, &floor, &mut reactions).unwrap();
        copy.step(DT, g, &floor, &mut reactions).unwrap();
        let same = s.positions().iter().zip(copy.positions()).all(|(a, b)| {
            a.iter()
                .zip(b.iter())
                .all(|(x, y)| x.to_bits() == y.to_bits())
        });
        if !same && first_diff.is_none() {
            first_diff = Some(k);
        }
    }
    println!(
        "loaded sliding block from its state: first differing step {first_diff:?} (want None)"
    );
    assert_eq!(first_diff, None);
}
