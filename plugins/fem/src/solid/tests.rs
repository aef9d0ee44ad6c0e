//! Tests of the solid's state format and its contact memory.

use super::*;
use crate::coupling::HalfSpace;
use crate::error::FemError;
use crate::material::Material;
use crate::testing::box_mesh;

fn block_on_floor() -> FemSolid {
    let (nodes, tets) = box_mesh(Vector3::zeros(), Vector3::new(0.2, 0.04, 0.04), [4, 1, 1]);
    let material = Material::new(1e5, 0.35, 200.0).unwrap();
    FemSolid::new(&nodes, &tets, material, FemConfig::default()).unwrap()
}

#[test]
fn the_state_keeps_the_contact_memory_and_reads_the_old_format() {
    let floor = HalfSpace {
        origin: Vector3::zeros(),
        normal: Vector3::z(),
        friction: 0.5,
        body: 3,
        velocity: Vector3::zeros(),
    };
    let mut a = block_on_floor();
    let vel = vec![Vector3::new(0.3, 0.0, 0.0); a.n_nodes()];
    let pos = a.positions().to_vec();
    a.set_positions_velocities(&pos, &vel).unwrap();
    let mut reactions = Vec::new();
    for _ in 0..5 {
        a.step(
            1.0 / 60.0,
            Vector3::new(0.0, 0.0, -9.81),
            &floor,
            &mut reactions,
        )
        .unwrap();
    }
    let k = a.contact_memory.len();
    assert!(k > 0, "the block rests on the floor");
    assert!(a.contact_memory.iter().any(|m| !m.stick), "and slides");
    let state = a.get_state();
    let mut b = block_on_floor();
    b.set_state(&state).unwrap();
    assert_eq!(b.contact_memory, a.contact_memory);
    assert_eq!(b.factor_anchor, a.factor_anchor);
    // version 2: without the factor's anchor (a restored solid factors afresh)
    let m = a.factor_anchor.len();
    assert!(m > 0, "the resting block's contacts are in the factor");
    let mut v2 = state[..state.len() - 1 - 5 * m].to_vec();
    v2[0] = STATE_MAGIC_V2;
    let mut c2 = block_on_floor();
    c2.set_state(&v2).unwrap();
    assert_eq!(c2.contact_memory, a.contact_memory);
    assert!(c2.factor_anchor.is_empty());
    // version 1: the same without the memory (a restored solid starts from scratch)
    let mut v1 = v2[..v2.len() - 1 - 7 * k].to_vec();
    v1[0] = STATE_MAGIC_V1;
    let mut c = block_on_floor();
    c.set_state(&v1).unwrap();
    assert!(c.contact_memory.is_empty());
    assert_eq!(c.positions(), a.positions());
    // a version-1 tag with the memory appended is trailing data
    let mut bad = v2.clone();
    bad[0] = STATE_MAGIC_V1;
    assert!(matches!(b.set_state(&bad), Err(FemError::InvalidState(_))));
    // setting positions by hand forgets the contacts
    b.set_positions_velocities(&pos, &vel).unwrap();
    assert!(b.contact_memory.is_empty());
}

#[test]
fn a_remembered_frictionless_slide_sticks_once_the_surface_has_friction() {
    let floor = |friction| HalfSpace {
        origin: Vector3::zeros(),
        normal: Vector3::z(),
        friction,
        body: 3,
        velocity: Vector3::zeros(),
    };
    let g = Vector3::new(0.0, 0.0, -9.81);
    let mut s = block_on_floor();
    let mut reactions = Vec::new();
    for _ in 0..10 {
        s.step(1.0 / 60.0, g, &floor(0.0), &mut reactions).unwrap();
    }
    // resting on a frictionless floor: sliding contacts, most without a direction
    let mem = &s.contact_memory;
    assert!(!mem.is_empty() && mem.iter().all(|m| !m.stick));
    assert!(mem.iter().any(|m| m.slip_dir == Vector3::zeros()));
    // friction 0.5 and a push of 0.2 times the weight: static friction holds the block
    let push: Vec<Vector3<f64>> = s
        .masses()
        .iter()
        .map(|m| Vector3::new(0.2 * 9.81 * m, 0.0, 0.0))
        .collect();
    s.set_external_forces(&push).unwrap();
    let x0 = s.positions()[0];
    for _ in 0..10 {
        s.step(1.0 / 60.0, g, &floor(0.5), &mut reactions).unwrap();
    }
    let moved = (s.positions()[0] - x0).x.abs();
    println!("slide along the push: {moved:e} m (< 1e-6)");
    assert!(moved < 1e-6);
}

#[test]
fn a_split_step_moves_attached_nodes_in_proportion() {
    // one Newton iteration does not meet the tolerance for the whole step, so its strict solve
    // fails and the step is split
    let (nodes, tets) = box_mesh(Vector3::zeros(), Vector3::new(0.2, 0.04, 0.04), [4, 1, 1]);
    let material = Material::new(1e5, 0.35, 200.0).unwrap();
    let config = FemConfig {
        newton_max_iterations: 1,
        ..FemConfig::default()
    };
    let mut s = FemSolid::new(&nodes, &tets, material, config).unwrap();
    let held = s.nodes_where(|p| p.x < 1e-9);
    s.attach_to_body(1, Isometry3::identity(), &held).unwrap();
    let dt = 1.0 / 60.0;
    let shift = Vector3::new(0.01, 0.0, 0.02);
    s.set_body_pose(1, Isometry3::translation(shift.x, shift.y, shift.z))
        .unwrap();
    let rest = s.positions().to_vec();
    let mut reactions = Vec::new();
    let stats = s
        .step(
            dt,
            Vector3::zeros(),
            &crate::coupling::NoContacts,
            &mut reactions,
        )
        .unwrap();
    assert!(stats.halvings >= 1, "the step was split");
    // each part moved the held nodes its share of the way: they end at the body's speed (all of
    // the motion in the first part would leave them at rest in the last)
    let speed = shift / dt;
    for &n in &held {
        let n = n as usize;
        assert!((s.positions()[n] - rest[n] - shift).norm() < 1e-12);
        let err = (s.velocities()[n] - speed).norm();
        assert!(
            err < 1e-9,
            "node {n}: velocity {:?} vs the body's {speed:?}",
            s.velocities()[n]
        );
    }
    assert_eq!(
        s.poses_start, s.poses,
        "the next step starts where this one ended"
    );
}
