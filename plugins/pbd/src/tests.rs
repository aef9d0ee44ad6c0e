//! Unit tests of the cloth (fast ones; the slower validation rows are in `tests/validation.rs`).

use crate::testing::{AnalyticCollider, AnalyticColliders, Shape};
use crate::*;
use nalgebra::{Isometry3, Vector3};

const G: f64 = 9.81;

fn gravity() -> Vector3<f64> {
    Vector3::new(0.0, 0.0, -G)
}

/// A vertical chain: particle 0 pinned at z = 0, particles 1..=n below at rest spacing `l0`.
fn chain(n: usize, m: f64, alpha: f64, l0: f64, settings: SolverSettings) -> Cloth {
    let pos: Vec<Vector3<f64>> = (0..=n)
        .map(|i| Vector3::new(0.0, 0.0, -(i as f64) * l0))
        .collect();
    let masses = vec![m; n + 1];
    let cons: Vec<DistanceConstraint> = (0..n)
        .map(|i| DistanceConstraint {
            particles: [i as u32, i as u32 + 1],
            rest_length: l0,
            compliance: alpha,
        })
        .collect();
    let material = ClothMaterial {
        damping: 2.0,
        ..ClothMaterial::default()
    };
    let mut c = Cloth::from_distance_constraints(&pos, &masses, &cons, material, settings).unwrap();
    c.pin_to_world(&[0]).unwrap();
    c
}

/// Total stretch of the chain after `seconds` of settling.
fn settled_chain_stretch(
    n: usize,
    alpha: f64,
    dt: f64,
    substeps: u32,
    iterations: u32,
    seconds: f64,
) -> f64 {
    let (m, l0) = (0.1, 0.1);
    let settings = SolverSettings {
        substeps,
        iterations,
        tethers: false,
        ..SolverSettings::default()
    };
    let mut c = chain(n, m, alpha, l0, settings);
    let mut r = Vec::new();
    let steps = (seconds / dt).round() as usize;
    for _ in 0..steps {
        c.step(dt, &gravity(), &NoColliders, &mut r).unwrap();
    }
    assert!(
        c.kinetic_energy() < 1e-12,
        "chain not at rest: KE {}",
        c.kinetic_energy()
    );
    -c.positions()[n].z - n as f64 * l0
}

#[test]
fn validation_hanging_chain_converged_stretch() {
    let (n, m, alpha) = (10usize, 0.1, 1e-3);
    let exact = alpha * m * G * (n * (n + 1)) as f64 / 2.0;
    let s60 = settled_chain_stretch(n, alpha, 1.0 / 60.0, 1, 400, 20.0);
    let s240 = settled_chain_stretch(n, alpha, 1.0 / 240.0, 1, 400, 20.0);
    let e60 = (s60 / exact - 1.0).abs();
    let e240 = (s240 / exact - 1.0).abs();
    let agree = (s60 / s240 - 1.0).abs();
    println!("hanging chain N={n}: exact {exact:.6e} m, dt 1/60 {s60:.6e} m (rel err {e60:.2e}), dt 1/240 {s240:.6e} m (rel err {e240:.2e}); tolerance 1e-3");
    println!("hanging chain: dt 1/60 vs 1/240 differ by {agree:.2e} (tolerance 1e-3)");
    assert!(e60 <= 1e-3 && e240 <= 1e-3);
    assert!(agree <= 1e-3);
}

#[test]
fn validation_single_spring_converged_stretch() {
    // N = 1: stretch = alpha m g
    let exact = 1e-3 * 0.1 * G;
    let s = settled_chain_stretch(1, 1e-3, 1.0 / 60.0, 1, 50, 10.0);
    let e = (s / exact - 1.0).abs();
    println!(
        "single spring: exact {exact:.6e} m, measured {s:.6e} m, rel err {e:.2e} (tolerance 1e-3)"
    );
    assert!(e <= 1e-3);
}

#[test]
fn validation_under_iterated_is_never_stiffer() {
    let (n, alpha) = (10usize, 1e-3);
    let converged = settled_chain_stretch(n, alpha, 1.0 / 60.0, 1, 400, 20.0);
    for (substeps, iterations) in [(1, 1), (1, 2), (1, 5), (1, 20), (2, 1), (4, 1), (8, 2)] {
        let s = settled_chain_stretch(n, alpha, 1.0 / 60.0, substeps, iterations, 30.0);
        println!(
            "under-iterated chain: {substeps} substeps x {iterations} iterations: stretch {s:.6e} m vs converged {converged:.6e} m (ratio {:.4}, must be >= 1)",
            s / converged
        );
        assert!(s >= converged * (1.0 - 1e-9), "stiffer than converged");
    }
}

#[test]
fn state_round_trip_is_bit_exact_and_stepping_deterministic() {
    let sheet = GridSheet::new(0.4, 0.3, 9, 7, Vector3::new(0.0, 0.0, 0.3)).unwrap();
    let settings = SolverSettings {
        self_collision: true,
        ..SolverSettings::default()
    };
    let mut a = Cloth::new(
        &sheet.positions,
        &sheet.triangles,
        ClothMaterial::default(),
        settings,
    )
    .unwrap();
    let f = a.add_frame(Isometry3::identity(), 3).unwrap();
    a.attach_to_frame(f, &[sheet.index(0, 0)], 0.05).unwrap();
    a.pin_to_world(&[sheet.index(8, 6)]).unwrap();
    let table = AnalyticColliders::new(vec![AnalyticCollider {
        shape: Shape::Plane {
            point: Vector3::zeros(),
            normal: Vector3::z(),
        },
        friction: 0.5,
        body: 1,
        velocity: Vector3::zeros(),
    }]);
    let mut b = a.clone();
    let mut r = Vec::new();
    let run = |c: &mut Cloth, k: usize, r: &mut Vec<Reaction>| {
        for s in 0..k {
            let t = c.time();
            c.set_frame_pose(
                f,
                Isometry3::translation(0.1 * t, 0.0, 0.05 * (s as f64 * 0.1).sin()),
            )
            .unwrap();
            c.step(1.0 / 60.0, &gravity(), &table, r).unwrap();
        }
    };
    run(&mut a, 40, &mut r);
    run(&mut b, 40, &mut r);
    assert_eq!(a.get_state(), b.get_state(), "two identical runs differ");
    let snap = a.get_state();
    run(&mut a, 40, &mut r);
    let end_a = a.get_state();
    let mut c = b.clone();
    run(&mut c, 10, &mut r); // diverge, then restore
    c.set_state(&snap).unwrap();
    assert_eq!(c.get_state(), snap, "set_state/get_state not a round trip");
    run(&mut c, 40, &mut r);
    let end_c = c.get_state();
    assert_eq!(end_a.len(), end_c.len());
    assert!(
        end_a
            .iter()
            .zip(&end_c)
            .all(|(x, y)| x.to_bits() == y.to_bits()),
        "restore + step not bit-identical"
    );
    assert!(c.set_state(&snap[..snap.len() - 1]).is_err());
    let mut bad = snap.clone();
    bad[5] = f64::NAN;
    assert!(c.set_state(&bad).is_err());
}

struct NanQuery;
impl ContactQuery for NanQuery {
    fn contacts_near(&self, _p: &Vector3<f64>, _d: f64, out: &mut Vec<PointContact>) {
        out.push(PointContact {
            point: Vector3::new(f64::NAN, 0.0, 0.0),
            normal: Vector3::z(),
            distance: 0.0,
            friction: 0.5,
            body: 0,
            velocity: Vector3::zeros(),
        });
    }
}

struct HugeQuery;
impl ContactQuery for HugeQuery {
    fn contacts_near(&self, _p: &Vector3<f64>, _d: f64, out: &mut Vec<PointContact>) {
        out.push(PointContact {
            point: Vector3::new(0.0, 0.0, 1e308),
            normal: Vector3::z(),
            distance: -1e308,
            friction: 0.0,
            body: 0,
            velocity: Vector3::new(0.0, 0.0, 1e308),
        });
    }
}

#[test]
fn non_finite_is_reported_and_rolled_back() {
    let sheet = GridSheet::new(0.2, 0.2, 5, 5, Vector3::zeros()).unwrap();
    let mut c = Cloth::new(
        &sheet.positions,
        &sheet.triangles,
        ClothMaterial::default(),
        SolverSettings::default(),
    )
    .unwrap();
    let mut r = Vec::new();
    c.step(1.0 / 60.0, &gravity(), &NoColliders, &mut r)
        .unwrap();
    let before = c.get_state();
    let e = c
        .step(1.0 / 60.0, &gravity(), &NanQuery, &mut r)
        .unwrap_err();
    println!("NaN contact: {e}");
    assert!(matches!(e, PbdError::NonFiniteContact { .. }));
    assert_eq!(c.get_state(), before);
    let e = c
        .step(1.0 / 60.0, &gravity(), &HugeQuery, &mut r)
        .unwrap_err();
    println!("overflow: {e}");
    assert!(matches!(e, PbdError::NonFinite { .. }));
    assert_eq!(c.get_state(), before);
    assert!(r.is_empty());
    assert!(c.step(f64::NAN, &gravity(), &NoColliders, &mut r).is_err());
    assert!(c
        .step(
            1.0 / 60.0,
            &Vector3::new(0.0, f64::INFINITY, 0.0),
            &NoColliders,
            &mut r
        )
        .is_err());
    let f = c.add_frame(Isometry3::identity(), u32::MAX).unwrap();
    assert!(c
        .set_frame_pose(f, Isometry3::translation(f64::NAN, 0.0, 0.0))
        .is_err());
    // bad parameters name the field
    let bad = ClothMaterial {
        areal_density: -1.0,
        ..ClothMaterial::default()
    };
    let e = Cloth::new(
        &sheet.positions,
        &sheet.triangles,
        bad,
        SolverSettings::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("areal_density"), "{e}");
    let e = Cloth::new(
        &sheet.positions,
        &[[0, 1, 99]],
        ClothMaterial::default(),
        SolverSettings::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("99"), "{e}");
}

#[test]
fn reactions_carry_the_weight_of_a_resting_cloth() {
    let sheet = GridSheet::new(0.3, 0.3, 11, 11, Vector3::new(-0.15, -0.15, 0.002)).unwrap();
    let mut c = Cloth::new(
        &sheet.positions,
        &sheet.triangles,
        ClothMaterial::default(),
        SolverSettings::default(),
    )
    .unwrap();
    let table = AnalyticColliders::new(vec![AnalyticCollider {
        shape: Shape::Plane {
            point: Vector3::zeros(),
            normal: Vector3::z(),
        },
        friction: 0.5,
        body: 7,
        velocity: Vector3::zeros(),
    }]);
    let dt = 1.0 / 60.0;
    let mut r = Vec::new();
    for _ in 0..120 {
        r.clear();
        c.step(dt, &gravity(), &table, &mut r).unwrap();
    }
    let total: Vector3<f64> = r.iter().map(|x| x.impulse).sum();
    let weight_impulse = c.total_mass() * G * dt;
    let rel = (total.z / -weight_impulse - 1.0).abs();
    println!("table reaction over one step: {:.6e} N s, weight x dt {:.6e} N s, rel err {rel:.2e} (tolerance 1e-3)", total.z, -weight_impulse);
    assert!(r.iter().all(|x| x.body == 7));
    assert!(rel < 1e-3);
    let tangential = (total.x.abs() + total.y.abs()) / weight_impulse;
    println!("table reaction, tangential / normal: {tangential:.2e} (tolerance 1e-3: a cloth at rest needs no friction)");
    assert!(tangential < 1e-3);
}

#[test]
fn measures_on_a_flat_sheet() {
    let sheet = GridSheet::new(1.0, 0.5, 11, 6, Vector3::zeros()).unwrap();
    let c = Cloth::new(
        &sheet.positions,
        &sheet.triangles,
        ClothMaterial::default(),
        SolverSettings::default(),
    )
    .unwrap();
    let s = c.stretch_stats();
    assert!(s.max.abs() < 1e-12 && s.mean.abs() < 1e-12);
    assert!((c.total_mass() - 0.2 * 0.5).abs() < 1e-12);
    // region covering the left half of the sheet and beyond
    let region = Region {
        min: [-0.5, -0.5],
        max: [0.5, 1.0],
    };
    let a = c.covered_area(&region, 400);
    println!("covered area {a:.5} m^2 (exact 0.25)");
    assert!((a - 0.25).abs() < 0.005);
    let f = c.fraction_above(&Region {
        min: [-0.01, -0.01],
        max: [0.45, 0.6],
    });
    assert!((f - 5.0 / 11.0).abs() < 1e-12, "{f}");
    let mut c = c;
    c.add_group("handle", &[sheet.index(5, 0)]).unwrap();
    let p = c.group_positions("handle").unwrap();
    assert!((p[0] - Vector3::new(0.5, 0.0, 0.0)).norm() < 1e-12);
    assert!(c.group("missing").is_err());
}

#[test]
fn pinned_particles_follow_their_frame() {
    let sheet = GridSheet::new(0.2, 0.2, 5, 5, Vector3::zeros()).unwrap();
    let mut c = Cloth::new(
        &sheet.positions,
        &sheet.triangles,
        ClothMaterial::default(),
        SolverSettings::default(),
    )
    .unwrap();
    let f = c.add_frame(Isometry3::identity(), u32::MAX).unwrap();
    let id = c.pin_to_frame(f, &[0, 4]).unwrap();
    let mut r = Vec::new();
    for k in 1..=30 {
        c.set_frame_pose(f, Isometry3::translation(0.0, 0.0, 0.01 * k as f64))
            .unwrap();
        c.step(1.0 / 60.0, &gravity(), &NoColliders, &mut r)
            .unwrap();
    }
    assert!((c.positions()[4] - Vector3::new(0.2, 0.0, 0.3)).norm() < 1e-12);
    c.step(1.0 / 60.0, &gravity(), &NoColliders, &mut r)
        .unwrap(); // frame at rest
    assert!(c.velocities()[4].norm() < 1e-12);
    c.release(id).unwrap();
    assert!(c.release(id).is_err());
    for _ in 0..10 {
        c.step(1.0 / 60.0, &gravity(), &NoColliders, &mut r)
            .unwrap();
    }
    assert!(c.positions()[4].z < 0.29, "released particle did not fall");
}

/// A three-particle rope hung over the edge of a box: with `edge_contacts` the two edges wrap
/// around the box's corner instead of cutting through it.
fn rope_over_box_edge(edge_contacts: bool) -> f64 {
    let l0 = 0.03;
    let pos = vec![
        Vector3::new(-0.02, 0.0, 0.503),
        Vector3::new(0.005, 0.0, 0.503),
        Vector3::new(0.03, 0.0, 0.503),
    ];
    let cons = [
        DistanceConstraint {
            particles: [0, 1],
            rest_length: l0,
            compliance: 0.0,
        },
        DistanceConstraint {
            particles: [1, 2],
            rest_length: l0,
            compliance: 0.0,
        },
    ];
    let settings = SolverSettings {
        edge_contacts,
        ..SolverSettings::default()
    };
    let material = ClothMaterial {
        friction: 1.0,
        ..ClothMaterial::default()
    };
    let mut c =
        Cloth::from_distance_constraints(&pos, &[0.01; 3], &cons, material, settings).unwrap();
    c.pin_to_world(&[0]).unwrap();
    let cube = AnalyticCollider::fixed(
        Shape::Box {
            pose: Isometry3::translation(-0.5, 0.0, 0.0),
            half_extents: Vector3::repeat(0.5),
        },
        1.0,
    );
    let world = AnalyticColliders::new(vec![cube]);
    let mut r = Vec::new();
    for _ in 0..120 {
        c.step(1.0 / 60.0, &gravity(), &world, &mut r).unwrap();
    }
    let p = c.positions();
    [(0, 1), (1, 2)]
        .iter()
        .map(|&(a, b)| cube.closest(&((p[a] + p[b]) * 0.5)).2)
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn edge_contacts_keep_edges_out_of_box_corners() {
    let with = rope_over_box_edge(true);
    let without = rope_over_box_edge(false);
    println!("rope over a box edge: deepest edge midpoint {with:.2e} m with edge contacts (demand >= 0), {without:.2e} m without");
    assert!(with >= 0.0);
    assert!(without < with);
}

#[test]
fn task_cloths_build_and_step() {
    // Uncover: 1.6 x 1.2 m, 41 x 31, 0.2 kg/m^2, handle at the middle of the near edge
    let cover = GridSheet::new(1.6, 1.2, 41, 31, Vector3::new(-0.8, -0.6, 0.6)).unwrap();
    let mut uncover = Cloth::new(
        &cover.positions,
        &cover.triangles,
        ClothMaterial::default(),
        SolverSettings::default(),
    )
    .unwrap();
    uncover.add_group("handle", &[cover.index(20, 0)]).unwrap();
    // Cover: 0.8 x 0.6 m, 33 x 25, handle at a corner
    let small = GridSheet::new(0.8, 0.6, 33, 25, Vector3::new(0.0, 0.0, 0.8)).unwrap();
    let mut cov = Cloth::new(
        &small.positions,
        &small.triangles,
        ClothMaterial::default(),
        SolverSettings::default(),
    )
    .unwrap();
    cov.add_group("handle", &[small.index(0, 0)]).unwrap();
    // Curtain: 0.9 x 1.0 m, 51 x 51, 0.4 kg/m^2, top edge fixed for 0.2 m at each side
    let flat = GridSheet::new(0.9, 1.0, 51, 51, Vector3::zeros()).unwrap();
    let hanging: Vec<Vector3<f64>> = flat
        .positions
        .iter()
        .map(|p| Vector3::new(p.x, 0.0, 2.0 - p.y))
        .collect();
    let material = ClothMaterial {
        areal_density: 0.4,
        ..ClothMaterial::default()
    };
    let mut curtain = Cloth::new(
        &hanging,
        &flat.triangles,
        material,
        SolverSettings::default(),
    )
    .unwrap();
    let fixed: Vec<u32> = (0..51)
        .filter(|&i| {
            let x = 0.9 * i as f64 / 50.0;
            x <= 0.2 + 1e-9 || x >= 0.7 - 1e-9
        })
        .map(|i| flat.index(i, 0))
        .collect();
    assert_eq!(fixed.len(), 24);
    curtain.pin_to_world(&fixed).unwrap();
    assert!((curtain.total_mass() - 0.36).abs() < 1e-12);
    let table = AnalyticColliders::new(vec![AnalyticCollider::fixed(
        Shape::Box {
            pose: Isometry3::translation(0.0, 0.0, 0.25),
            half_extents: Vector3::new(1.0, 0.5, 0.25),
        },
        0.5,
    )]);
    let h = uncover.group_positions("handle").unwrap()[0];
    assert!((h.x - 0.0).abs() < 1e-9 && (h.y + 0.6).abs() < 1e-9);
    let mut r = Vec::new();
    for c in [&mut uncover, &mut cov, &mut curtain] {
        for _ in 0..10 {
            c.step(1.0 / 60.0, &gravity(), &table, &mut r).unwrap();
        }
        assert!(c.positions().iter().all(|p| p.z.is_finite()));
    }
    assert!(curtain.positions()[fixed[0] as usize] == hanging[fixed[0] as usize]);
}

#[test]
fn driven_particles_move_only_in_their_window_and_bad_drives_are_rejected() {
    let sheet = GridSheet::new(0.2, 0.2, 3, 3, Vector3::zeros()).unwrap();
    let mut c = Cloth::new(
        &sheet.positions,
        &sheet.triangles,
        ClothMaterial::default(),
        SolverSettings::default(),
    )
    .unwrap();
    let p = sheet.index(0, 0);
    let v = Vector3::new(0.3, 0.0, 0.0);
    let (start, stop) = (0.5, 1.0);
    c.drive_particles(&[p], v, start, stop).unwrap();
    let x0 = c.positions()[p as usize];
    let mut r = Vec::new();
    let dt = 1.0 / 60.0;
    let mut before = x0;
    for k in 1..=90 {
        c.step(dt, &Vector3::zeros(), &NoColliders, &mut r).unwrap();
        let t = k as f64 * dt;
        if t <= start {
            before = c.positions()[p as usize];
        }
    }
    let moved = c.positions()[p as usize] - x0;
    let want = v * (stop - start);
    println!(
        "driven particle: moved {:.6} m before the window (0), {:.6} m in total (want {:.6})",
        (before - x0).norm(),
        moved.x,
        want.x
    );
    assert!((before - x0).norm() < 1e-15);
    assert!((moved - want).norm() < 1e-12);
    assert!(c
        .drive_particles(&[p], Vector3::new(f64::NAN, 0.0, 0.0), 0.0, 1.0)
        .is_err());
    assert!(c.drive_particles(&[p], v, 1.0, 0.5).is_err());
    assert!(c.drive_particles(&[999], v, 0.0, 1.0).is_err());
}

#[test]
fn avx2_and_baseline_kernels_give_the_same_bits() {
    // the reference sheet swinging onto the cube: distances, bending, tethers, contacts and
    // self-collision, 120 steps
    let cfg = crate::bench::BenchConfig::reference(true);
    let (mut a, cube) = crate::bench::reference_scene(&cfg).unwrap();
    let mut b = a.clone();
    let simd = a.use_avx2(true);
    assert!(!b.use_avx2(false));
    let mut r = Vec::new();
    for _ in 0..120 {
        a.step(crate::bench::REFERENCE_DT, &gravity(), &cube, &mut r)
            .unwrap();
        b.step(crate::bench::REFERENCE_DT, &gravity(), &cube, &mut r)
            .unwrap();
    }
    let (sa, sb) = (a.get_state(), b.get_state());
    assert!(
        sa.iter().zip(&sb).all(|(x, y)| x.to_bits() == y.to_bits()),
        "AVX2 ({simd}) and baseline kernels differ"
    );
    if !simd {
        eprintln!("no AVX2 on this machine: only the baseline kernels ran");
    }
}

#[test]
fn cloths_of_one_object_share_equal_rows_and_step_as_alone() {
    let sheet = GridSheet::new(0.4, 0.3, 9, 7, Vector3::new(0.0, 0.0, 0.3)).unwrap();
    let make = || {
        Cloth::new(
            &sheet.positions,
            &sheet.triangles,
            ClothMaterial::default(),
            SolverSettings::default(),
        )
        .unwrap()
    };
    let cache = std::sync::Arc::new(crate::lanes::RowCache::default());
    let (mut a, mut b, mut c, mut alone) = (make(), make(), make(), make());
    for cl in [&mut a, &mut b, &mut c] {
        cl.share_rows(std::sync::Arc::clone(&cache));
    }
    // c pins a corner: its inverse masses, and so its rows, differ
    c.pin_to_world(&[sheet.index(0, 0)]).unwrap();
    let mut r = Vec::new();
    for _ in 0..20 {
        for cl in [&mut a, &mut b, &mut c, &mut alone] {
            cl.step(1.0 / 60.0, &gravity(), &NoColliders, &mut r)
                .unwrap();
        }
    }
    assert!(a.shares_rows_with(&b), "equal rows not shared");
    assert!(!a.shares_rows_with(&c), "different rows shared");
    // sharing changes nothing: a and b step bit for bit as the same cloth with its own rows
    assert_eq!(a.get_state(), alone.get_state());
    assert_eq!(b.get_state(), alone.get_state());
    assert_ne!(c.get_state(), alone.get_state());
}
