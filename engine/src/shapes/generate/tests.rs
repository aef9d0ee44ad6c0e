//! Tests of mesh generation: volumes, quality, layouts, surfaces, hostile parameters and
//! generators.

use std::f64::consts::PI;

use super::super::{FaceCensus, ShapeGenerators};
use super::*;

fn ctx() -> ShapeContext<'static> {
    ShapeContext::new(std::path::Path::new("."))
}

/// Checks everything a finite-element body needs and prints the figures; returns the relative volume
/// error against `expected`.
fn assert_valid_volume(name: &str, m: &VolumeMesh, expected: f64) -> f64 {
    let q = m.quality();
    let census = m.face_census();
    let surface = m.boundary_surface();
    let volume = m.volume();
    let enclosed = surface.enclosed_volume();
    let rel = (volume - expected).abs() / expected;
    println!(
        "{name}: {} tets, {} nodes, dihedral {:.2}..{:.2} deg, volume {volume:.6e} vs {expected:.6e} \
         (rel err {rel:.3e}), |boundary - tets| / V = {:.1e} (tol 1e-9)",
        q.tets,
        q.nodes,
        q.min_dihedral_deg,
        q.max_dihedral_deg,
        (enclosed - volume).abs() / volume
    );
    assert_eq!(q.inverted, 0, "{name}: inverted tets");
    assert_eq!(q.degenerate, 0, "{name}: degenerate tets");
    assert!(q.min_dihedral_deg > 0.0);
    assert_eq!(census.overshared, 0, "{name}: faces shared by 3+ tets");
    assert_eq!(census.boundary, surface.triangles.len());
    assert_eq!(
        census.interior * 2 + census.boundary,
        m.tets.len() * 4,
        "{name}: every face is counted once or twice"
    );
    assert!(
        surface.is_closed(),
        "{name}: boundary not closed (non-conforming?)"
    );
    assert!(
        (enclosed - volume).abs() <= 1e-9 * volume,
        "{name}: boundary volume differs"
    );
    m.check().unwrap();
    rel
}

#[test]
fn kuhn_box_40x2x2_counts_and_volume() {
    let shape = ShapeDesc::box_grid([0.82, 0.04, 0.04], [40, 2, 2]);
    let m = shape.volume(&ctx()).unwrap();
    assert_eq!(m.tets.len(), 960);
    assert_eq!(m.nodes.len(), 369);
    let rel = assert_valid_volume("box 40x2x2", &m, 0.82 * 0.04 * 0.04);
    assert!(rel < 1e-12, "rel {rel} (tol 1e-12)");
    // Cube cells: Kuhn tetrahedra have dihedral angles of exactly 45, 60 and 90 degrees.
    let cube = ShapeDesc::box_grid([1.0, 1.0, 1.0], [3, 3, 3])
        .volume(&ctx())
        .unwrap();
    let q = cube.quality();
    assert!((q.min_dihedral_deg - 45.0).abs() < 1e-9 && (q.max_dihedral_deg - 90.0).abs() < 1e-9);
    assert_valid_volume("cube 3x3x3", &cube, 1.0);
    let single = ShapeDesc::cuboid([1.0, 0.5, 0.2]).volume(&ctx()).unwrap();
    assert_eq!(single.tets.len(), 6);
    assert_valid_volume("box 1x1x1", &single, 0.1);
    let s = ShapeDesc::cuboid([1.0, 0.5, 0.2]).surface(&ctx()).unwrap();
    assert_eq!((s.positions.len(), s.triangles.len()), (8, 12));
}

#[test]
fn cylinder_and_rod_volumes_converge() {
    let (r, h) = (0.04, 0.82);
    let exact = PI * r * r * h;
    let mut last = f64::INFINITY;
    for segments in [8, 16, 32, 64] {
        let m = ShapeDesc::cylinder(r, h, segments).volume(&ctx()).unwrap();
        let polygon =
            0.5 * f64::from(segments) * r * r * (2.0 * PI / f64::from(segments)).sin() * h;
        let rel = assert_valid_volume(&format!("cylinder n={segments}"), &m, exact);
        assert!(
            (m.volume() - polygon).abs() < 1e-12 * polygon,
            "matches the inscribed polygon prism"
        );
        assert!(rel < last * 0.3, "converges: {rel} after {last}");
        last = rel;
    }
    assert!(last < 2e-3, "64 segments: rel err {last} (tol 2e-3)");
    // The task rods (SPEC.md): 0.82 x 0.08 and 0.92 x 0.06, along x.
    for (len, dia) in [(0.82, 0.08), (0.92, 0.06)] {
        let m = ShapeDesc::rod(len, 0.5 * dia, 16, None)
            .volume(&ctx())
            .unwrap();
        let rel = assert_valid_volume(
            &format!("rod {len} x {dia}"),
            &m,
            PI * 0.25 * dia * dia * len,
        );
        assert!(rel < 0.03, "16-gon rod: rel err {rel} (tol 0.03)");
        let (lo, hi) = m.bounds().unwrap();
        assert!((hi.x - lo.x - len).abs() < 1e-12 && (lo.x + 0.5 * len).abs() < 1e-12);
    }
}

#[test]
fn torus_volume_converges_and_seam_is_stitched() {
    let (big, small) = (0.3, 0.05);
    let exact = 2.0 * PI * PI * big * small * small;
    let mut last = f64::INFINITY;
    for (nm, ns) in [(16, 8), (32, 16), (64, 32)] {
        let m = ShapeDesc::torus(big, small, nm, ns).volume(&ctx()).unwrap();
        let rel = assert_valid_volume(&format!("torus {nm}x{ns}"), &m, exact);
        assert!(rel < last * 0.3, "converges: {rel} after {last}");
        last = rel;
        // No duplicated seam nodes: all nodes are distinct points.
        let mut keys: Vec<[i64; 3]> = m
            .nodes
            .iter()
            .map(|p| p.map(|x| (x * 1e9).round() as i64).into())
            .collect();
        keys.sort_unstable();
        let before = keys.len();
        keys.dedup();
        assert_eq!(keys.len(), before, "duplicate nodes at the seam");
    }
    assert!(last < 2e-2, "torus 64x32: rel err {last} (tol 2e-2)");
    // The same torus as a circle swept along a full-turn arc.
    let swept = ShapeDesc::Sweep {
        profile: Profile::Circle {
            radius: small,
            segments: 16,
            rings: None,
        },
        path: SweepPath::Arc {
            radius: big,
            angle: TAU,
        },
        segments: Some(32),
    };
    assert_valid_volume("torus as swept arc", &swept.volume(&ctx()).unwrap(), exact);
}

#[test]
fn ring_and_partial_revolve_are_exact_polyhedra() {
    // A rectangular ring is an extruded n-gon annulus: exact to round-off.
    let (radius, width, height, n) = (0.3, 0.04, 0.02, 48);
    let m = ShapeDesc::ring(radius, width, height, n)
        .volume(&ctx())
        .unwrap();
    let (a, b) = (radius - 0.5 * width, radius + 0.5 * width);
    let polygonal = height * 0.5 * f64::from(n) * (TAU / f64::from(n)).sin() * (b * b - a * a);
    let rel = assert_valid_volume("ring 48", &m, polygonal);
    assert!(rel < 1e-12, "rel {rel} (tol 1e-12)");
    let half = ShapeDesc::Revolve {
        profile: Profile::Rect {
            width,
            height,
            divisions: Some((2, 1)),
        },
        radius,
        segments: Some(24),
        angle: PI,
    };
    let m = half.volume(&ctx()).unwrap();
    let polygonal = height * 0.5 * 24.0 * (PI / 24.0).sin() * (b * b - a * a);
    let rel = assert_valid_volume("half ring", &m, polygonal);
    assert!(rel < 1e-12, "rel {rel} (tol 1e-12)");
}

#[test]
fn belt_and_extrude_volumes_are_exact() {
    for (len, name) in [(0.9, "Drag belt"), (1.4, "Lift belt")] {
        let m = ShapeDesc::belt(len, 0.05, 0.004, None, None)
            .volume(&ctx())
            .unwrap();
        let rel = assert_valid_volume(name, &m, len * 0.05 * 0.004);
        assert!(rel < 1e-12, "rel {rel} (tol 1e-12)");
        let (lo, hi) = m.bounds().unwrap();
        let extent = hi - lo;
        assert!(
            (extent - Vector3::new(len, 0.05, 0.004)).norm() < 1e-12,
            "belt extent {extent:?}"
        );
    }
    let l_shape = vec![
        (0.0, 0.0),
        (0.2, 0.0),
        (0.2, 0.1),
        (0.1, 0.1),
        (0.1, 0.2),
        (0.0, 0.2),
    ];
    let m = ShapeDesc::extrude(l_shape.clone(), 0.05)
        .volume(&ctx())
        .unwrap();
    let rel = assert_valid_volume("extruded L", &m, 0.03 * 0.05);
    assert!(rel < 1e-12, "rel {rel} (tol 1e-12)");
    let mut clockwise = l_shape;
    clockwise.reverse();
    let m = ShapeDesc::Extrude {
        polygon: clockwise,
        height: 0.05,
        layers: Some(3),
    }
    .volume(&ctx())
    .unwrap();
    assert_valid_volume("extruded L, clockwise", &m, 0.03 * 0.05);
}

#[test]
fn coarse_task_meshes_stay_valid() {
    // Cheaper resolutions a real-time FEM might pick for the SPEC.md rods and belts.
    let cases = [
        (
            "rod 0.82 x d0.08, 8-gon, 1 ring, 20 steps",
            ShapeDesc::Sweep {
                profile: Profile::Circle {
                    radius: 0.04,
                    segments: 8,
                    rings: Some(1),
                },
                path: SweepPath::Line {
                    length: 0.82,
                    axis: (1.0, 0.0, 0.0),
                },
                segments: Some(20),
            },
            PI * 0.0016 * 0.82,
        ),
        (
            "rod 0.92 x d0.06, 12-gon, auto rings, 30 steps",
            ShapeDesc::rod(0.92, 0.03, 12, Some(30)),
            PI * 0.0009 * 0.92,
        ),
        (
            "belt 0.9, 4x1 cells, 90 steps",
            ShapeDesc::belt(0.9, 0.05, 0.004, Some((4, 1)), Some(90)),
            0.9 * 0.05 * 0.004,
        ),
        (
            "belt 1.4, 2x1 cells, 70 steps",
            ShapeDesc::belt(1.4, 0.05, 0.004, Some((2, 1)), Some(70)),
            1.4 * 0.05 * 0.004,
        ),
    ];
    for (name, shape, smooth) in cases {
        let m = shape.volume(&ctx()).unwrap();
        let rel = assert_valid_volume(name, &m, m.volume());
        assert!(rel < 1e-12);
        println!(
            "    ({name}: {:.2} % below the smooth shape's volume)",
            100.0 * (1.0 - m.volume() / smooth)
        );
    }
}

#[test]
fn tubes_along_curved_paths_are_valid() {
    let helix = ShapeDesc::tube(
        SweepPath::Helix {
            radius: 0.1,
            pitch: 0.06,
            turns: 2.5,
        },
        0.01,
        12,
    );
    let m = helix.volume(&ctx()).unwrap();
    let length = 2.5 * (TAU * 0.1f64).hypot(0.06);
    // A curved tube's volume is area x centre-line length (Pappus), up to discretisation.
    let rel = assert_valid_volume("helix tube", &m, PI * 0.01 * 0.01 * length);
    assert!(rel < 0.05, "rel {rel} (tol 0.05)");
    // A closed, non-planar loop needs the twist correction to close its seam.
    let knot = ShapeDesc::Sweep {
        profile: Profile::Rect {
            width: 0.02,
            height: 0.01,
            divisions: Some((2, 1)),
        },
        path: SweepPath::Polyline {
            points: vec![
                (0.0, 0.0, 0.0),
                (0.3, 0.0, 0.1),
                (0.3, 0.3, 0.0),
                (0.0, 0.3, 0.1),
            ],
            closed: true,
        },
        segments: Some(40),
    };
    let m = knot.volume(&ctx()).unwrap();
    assert_valid_volume("closed skew loop", &m, m.volume());
    let open = ShapeDesc::Sweep {
        profile: Profile::Polygon {
            points: vec![(0.0, 0.0), (0.01, 0.0), (0.0, 0.01)],
        },
        path: SweepPath::Polyline {
            points: vec![(0.0, 0.0, 0.0), (0.2, 0.0, 0.0), (0.3, 0.1, 0.05)],
            closed: false,
        },
        segments: None,
    };
    assert_valid_volume(
        "polygon along polyline",
        &open.volume(&ctx()).unwrap(),
        0.5e-4 * open_length(),
    );
    fn open_length() -> f64 {
        0.2 + (0.01f64 + 0.01 + 0.0025).sqrt()
    }
}

#[test]
fn sharp_turn_is_reported_not_inverted() {
    let tube = ShapeDesc::Sweep {
        profile: Profile::Circle {
            radius: 0.1,
            segments: 8,
            rings: Some(1),
        },
        path: SweepPath::Polyline {
            points: vec![(0.0, 0.0, 0.0), (0.2, 0.0, 0.0), (0.0, 0.05, 0.0)],
            closed: false,
        },
        segments: Some(4),
    };
    let err = tube.volume(&ctx()).unwrap_err().to_string();
    println!("{err}");
    assert!(
        err.contains("inverted") || err.contains("degenerate") || err.contains("turns back"),
        "{err}"
    );
}

#[test]
fn surfaces_of_every_variant() {
    let c = ctx();
    let sphere = ShapeDesc::Sphere {
        radius: 0.1,
        segments: 64,
        rings: 32,
    }
    .surface(&c)
    .unwrap();
    assert!(sphere.is_closed());
    let exact = 4.0 / 3.0 * PI * 1e-3;
    let rel = (sphere.enclosed_volume() - exact).abs() / exact;
    println!("sphere 64x32: enclosed volume rel err {rel:.3e} (tol 1e-2)");
    assert!(rel < 1e-2);
    let capsule = ShapeDesc::capsule(0.05, 0.2).surface(&c).unwrap();
    assert!(capsule.is_closed());
    let exact = PI * 0.0025 * 0.2 + 4.0 / 3.0 * PI * 0.05f64.powi(3);
    let rel = (capsule.enclosed_volume() - exact).abs() / exact;
    println!("capsule: enclosed volume rel err {rel:.3e} (tol 3e-2)");
    assert!(rel < 3e-2);
    let (lo, hi) = capsule.bounds().unwrap();
    assert!((hi.z - 0.15).abs() < 1e-12 && (lo.z + 0.15).abs() < 1e-12);
    let ball = ShapeDesc::Capsule {
        radius: 0.05,
        height: 0.0,
        segments: 8,
        rings: 3,
    }
    .surface(&c)
    .unwrap();
    assert!(ball.is_closed());

    let cloth = ShapeDesc::grid([1.6, 1.2], [41, 31]).surface(&c).unwrap();
    assert_eq!(cloth.positions.len(), 41 * 31);
    assert_eq!(cloth.triangles.len(), 2 * 40 * 30);
    assert!((cloth.area() - 1.92).abs() < 1e-12);
    assert!(cloth
        .vertex_normals()
        .iter()
        .all(|n| (n - Vector3::z()).norm() < 1e-12));
    assert!(
        (cloth.positions[1].x - cloth.positions[0].x - 0.04).abs() < 1e-12,
        "x fastest"
    );
    let plane = ShapeDesc::plane([10.0, 10.0]).surface(&c).unwrap();
    assert!((plane.area() - 100.0).abs() < 1e-12);
    assert!(plane
        .vertex_normals()
        .iter()
        .all(|n| (n - Vector3::z()).norm() < 1e-12));

    for shape in [
        ShapeDesc::cylinder(0.04, 0.82, 16),
        ShapeDesc::rod(0.82, 0.04, 16, None),
        ShapeDesc::belt(0.9, 0.05, 0.004, None, None),
        ShapeDesc::torus(0.3, 0.05, 32, 12),
        ShapeDesc::extrude(vec![(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)], 0.1),
        ShapeDesc::box_grid([1.0, 1.0, 1.0], [2, 3, 4]),
    ] {
        let s = shape.surface(&c).unwrap();
        let v = shape.volume(&c).unwrap();
        assert!(s.is_closed(), "{shape:?}");
        assert!(
            (s.enclosed_volume() - v.volume()).abs() < 1e-9 * v.volume(),
            "{shape:?}"
        );
        // Compacted: every vertex is used.
        assert!(s.positions.len() <= v.nodes.len());
    }
    let err = ShapeDesc::Polyline {
        points: vec![(0.0, 0.0, 0.0), (1.0, 0.0, 0.0)],
        closed: false,
    }
    .surface(&c)
    .unwrap_err();
    println!("{err}");
}

#[test]
fn layouts_locate_end_faces_and_centre_lines() {
    let (len, r) = (0.82, 0.04);
    let (m, layout) = ShapeDesc::rod(len, r, 16, Some(41))
        .volume_with_layout(&ctx())
        .unwrap();
    let VolumeLayout::Swept {
        stations,
        section_points,
        closed,
        centre_point,
    } = layout.clone()
    else {
        panic!("rod is swept: {layout:?}");
    };
    assert_eq!((stations, closed, centre_point), (42, false, Some(0)));
    assert_eq!(m.nodes.len() as u32, stations * section_points);
    let line = layout.centre_line().unwrap();
    assert_eq!(line.len(), 42);
    for (k, &n) in line.iter().enumerate() {
        let p = m.nodes[n as usize];
        assert!((p - Vector3::new(len * (k as f64 / 41.0 - 0.5), 0.0, 0.0)).norm() < 1e-12);
    }
    for n in layout.station_nodes(0).unwrap() {
        assert!(
            (m.nodes[n as usize].x + 0.5 * len).abs() < 1e-12,
            "first station is the -x end face"
        );
    }
    for n in layout.station_nodes(41).unwrap() {
        assert!(
            (m.nodes[n as usize].x - 0.5 * len).abs() < 1e-12,
            "last station is the +x end face"
        );
    }
    assert!(layout.station_nodes(42).is_none());
    // A belt with an odd number of cells across has no centre point; an even one has.
    let (_, belt) = ShapeDesc::belt(0.9, 0.05, 0.004, None, Some(10))
        .volume_with_layout(&ctx())
        .unwrap();
    assert!(belt.centre_line().is_none());
    let (bm, belt) = ShapeDesc::belt(0.9, 0.05, 0.004, Some((4, 2)), Some(10))
        .volume_with_layout(&ctx())
        .unwrap();
    let line = belt.centre_line().unwrap();
    assert!(line
        .iter()
        .all(|&n| bm.nodes[n as usize].yz().norm() < 1e-12));
    // Box grid numbering.
    let (bx, grid) = ShapeDesc::box_grid([0.82, 0.04, 0.04], [40, 2, 2])
        .volume_with_layout(&ctx())
        .unwrap();
    assert_eq!(
        grid,
        VolumeLayout::HexGrid {
            divisions: [40, 2, 2]
        }
    );
    let node = |i: usize, j: usize, k: usize| bx.nodes[i + 41 * (j + 3 * k)];
    assert!((node(0, 0, 0) - Vector3::new(-0.41, -0.02, -0.02)).norm() < 1e-12);
    assert!((node(40, 2, 2) - Vector3::new(0.41, 0.02, 0.02)).norm() < 1e-12);
    assert!((node(20, 1, 1)).norm() < 1e-12);
    let (_, torus) = ShapeDesc::torus(0.3, 0.05, 24, 12)
        .volume_with_layout(&ctx())
        .unwrap();
    let rounded: ShapeDesc =
        ron::from_str("Revolve(profile: Circle(radius: 0.05), radius: 0.3, angle: 6.283)").unwrap();
    let (m, layout) = rounded.volume_with_layout(&ctx()).unwrap();
    assert!(
        matches!(layout, VolumeLayout::Swept { closed: true, .. }),
        "6.283 rad is a full turn"
    );
    assert!(m.boundary_surface().is_closed());
    assert!(
        matches!(
            torus,
            VolumeLayout::Swept {
                stations: 24,
                closed: true,
                ..
            }
        ),
        "{torus:?}"
    );
}

#[test]
fn volume_of_surface_only_shapes_is_a_clear_error() {
    for shape in [
        ShapeDesc::sphere(0.1),
        ShapeDesc::capsule(0.1, 0.2),
        ShapeDesc::plane([1.0, 1.0]),
        ShapeDesc::grid([1.0, 1.0], [3, 3]),
    ] {
        let err = shape.volume(&ctx()).unwrap_err().to_string();
        assert!(
            err.starts_with(shape.kind_name()) && err.contains("Box, Cylinder, Sweep"),
            "{err}"
        );
    }
    println!("{}", ShapeDesc::sphere(0.1).volume(&ctx()).unwrap_err());
}

#[test]
fn absurd_resolutions_are_refused_before_allocation() {
    let errors = [
        ShapeDesc::box_grid([1.0; 3], [1000, 1000, 1000])
            .volume(&ctx())
            .unwrap_err(),
        ShapeDesc::Cylinder {
            radius: 0.1,
            height: 1.0,
            segments: 64,
            rings: None,
            layers: Some(1_000_000),
        }
        .volume(&ctx())
        .unwrap_err(),
        // Automatic steps: 1 km of 1 mm rod.
        ShapeDesc::rod(1000.0, 0.0005, 16, None)
            .volume(&ctx())
            .unwrap_err(),
        ShapeDesc::grid([1.0, 1.0], [100_000, 100_000])
            .surface(&ctx())
            .unwrap_err(),
    ];
    for e in errors {
        println!("{e}");
        assert!(matches!(e, ShapeError::TooLarge { .. }), "{e:?}");
    }
}

#[test]
fn hostile_numbers_never_panic() {
    let values = [f64::NAN, f64::INFINITY, -1.0, 0.0, 1e-300, 1e-9, 1e300];
    let mut rejected = 0;
    let mut total = 0;
    for &a in &values {
        for &b in &values {
            let shapes = [
                ShapeDesc::cuboid([a, b, 1.0]),
                ShapeDesc::box_grid([a, 1.0, b], [3, 2, 1]),
                ShapeDesc::sphere(a),
                ShapeDesc::cylinder(a, b, 8),
                ShapeDesc::capsule(a, b),
                ShapeDesc::grid([a, b], [3, 3]),
                ShapeDesc::rod(a, b, 8, None),
                ShapeDesc::belt(a, b, 0.004, None, None),
                ShapeDesc::torus(a, b, 12, 8),
                ShapeDesc::ring(a, b, 0.01, 12),
                ShapeDesc::extrude(vec![(0.0, 0.0), (a, 0.0), (0.0, b)], 1.0),
                ShapeDesc::tube(
                    SweepPath::Helix {
                        radius: a,
                        pitch: b,
                        turns: 2.0,
                    },
                    0.01,
                    8,
                ),
                ShapeDesc::tube(
                    SweepPath::Arc {
                        radius: 1.0,
                        angle: a,
                    },
                    b,
                    8,
                ),
                ShapeDesc::tube(
                    SweepPath::Line {
                        length: 1.0,
                        axis: (a, b, 0.0),
                    },
                    0.1,
                    8,
                ),
            ];
            for s in shapes {
                total += 2;
                rejected += usize::from(s.surface(&ctx()).is_err());
                rejected += usize::from(s.volume(&ctx()).is_err());
            }
        }
    }
    for s in [
        ShapeDesc::cuboid([1e300, 1.0, 1.0]),
        ShapeDesc::rod(1e300, 0.1, 8, None),
        ShapeDesc::torus(1e300, 1.0, 12, 8),
    ] {
        println!("example: {}", s.volume(&ctx()).unwrap_err());
    }
    println!(
        "hostile parameters: {rejected} of {total} requests rejected with an error, none panicked"
    );
    assert!(rejected > total / 2);
}

struct Trefoil;

impl ShapeGenerators for Trefoil {
    fn generate(
        &self,
        name: &str,
        params_ron: &str,
        want: MeshKind,
    ) -> Result<GeneratedMesh, String> {
        #[derive(serde::Deserialize)]
        struct Params {
            size: f64,
        }
        let p: Params = ron::from_str(params_ron).map_err(|e| format!("{name} params: {e}"))?;
        let shape = ShapeDesc::box_grid([p.size; 3], [2, 2, 2]);
        let c = ShapeContext::new(std::path::Path::new("."));
        match want {
            MeshKind::Volume => shape.volume(&c).map(GeneratedMesh::Volume),
            MeshKind::Surface => shape.volume(&c).map(GeneratedMesh::Volume),
        }
        .map_err(|e| e.to_string())
    }
    fn names(&self) -> Vec<String> {
        vec!["acme.trefoil".into()]
    }
}

#[test]
fn generators_are_called_by_name() {
    let registry = Trefoil;
    let c = ShapeContext {
        base_dir: std::path::Path::new("."),
        asset_roots: &[],
        generators: Some(&registry),
    };
    let shape: ShapeDesc =
        ron::from_str(r#"Gen(name: "acme.trefoil", params: (size: 0.5))"#).unwrap();
    let v = shape.volume(&c).unwrap();
    assert_valid_volume("generated cube", &v, 0.125);
    let s = shape.surface(&c).unwrap();
    assert!(s.is_closed());
    let bad: ShapeDesc =
        ron::from_str(r#"Gen(name: "acme.trefoil", params: (sise: 0.5))"#).unwrap();
    let err = bad.volume(&c).unwrap_err().to_string();
    println!("{err}");
    assert!(
        err.contains("acme.trefoil") && err.contains("size"),
        "{err}"
    );
    let unknown: ShapeDesc = ron::from_str(r#"Gen(name: "acme.knot", params: ())"#).unwrap();
    let err = unknown.volume(&c).unwrap_err().to_string();
    println!("{err}");
    assert!(
        err.contains("acme.knot") && err.contains("acme.trefoil"),
        "{err}"
    );
    assert!(matches!(
        unknown.surface(&ctx()),
        Err(ShapeError::UnknownGenerator { .. })
    ));
    let census: FaceCensus = v.face_census();
    assert_eq!(census.overshared, 0);
}
