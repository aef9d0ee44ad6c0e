//! Tests of shape descriptions: RON round trips, the documented examples, validation errors.

use super::*;

const SCENE: &str = r#"[
    Box(size: (1.0, 0.5, 0.2)),
    Box(size: (0.82, 0.04, 0.04), divisions: Some((40, 2, 2))),
    Sphere(radius: 0.1),
    Sphere(radius: 0.1, segments: 8, rings: 4),
    Cylinder(radius: 0.04, height: 0.82),
    Cylinder(radius: 0.04, height: 0.82, segments: 12, rings: 2, layers: 40),
    Cylinder(radius: 0.04, height: 0.82, layers: Some(40), rings: None),
    Capsule(radius: 0.05, height: 0.3),
    Plane(size: (10.0, 10.0)),
    Grid(size: (1.6, 1.2), resolution: (41, 31)),
    Polyline(points: [(0.0, 0.0, 0.0), (1.0, 0.0, 0.5)], closed: false),
    Revolve(profile: Circle(radius: 0.02, segments: 12), radius: 0.3, segments: 32, angle: 6.283185307179586),
    Revolve(profile: Rect(width: 0.02, height: 0.01, divisions: Some((2, 1))), radius: 0.3, angle: 6.283),
    Sweep(profile: Rect(width: 0.05, height: 0.004), path: Line(length: 0.9)),
    Sweep(profile: Circle(radius: 0.01, rings: 2), path: Polyline(points: [(0, 0, 0), (1, 0, 0), (1, 1, 0)]), segments: 20),
    Sweep(profile: Polygon(points: [(0.0, 0.0), (0.01, 0.0), (0.0, 0.01)]), path: Arc(radius: 0.2, angle: 3.14159)),
    Sweep(profile: Circle(radius: 0.01), path: Helix(radius: 0.1, pitch: 0.05, turns: 3.0)),
    Sweep(profile: Circle(radius: 0.01), path: Line(length: 0.5, axis: (0.0, 0.0, 1.0))),
    Extrude(polygon: [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)], height: 0.1, layers: 4),
    Mesh(file: "meshes/bunny.obj"),
    Gen(name: "acme.trefoil", params: (turns: 3, scale: Some(0.2), kind: Knot(p: 2, q: 3), tags: ["a", "b"])),
]"#;

#[test]
fn ron_round_trip_of_every_variant() {
    let shapes: Vec<ShapeDesc> = ron::from_str(SCENE).unwrap();
    assert_eq!(shapes.len(), 21);
    let mut kinds: Vec<&str> = shapes.iter().map(ShapeDesc::kind_name).collect();
    kinds.dedup();
    assert_eq!(kinds.len(), 12, "every variant appears: {kinds:?}");
    for s in &shapes {
        s.validate().unwrap_or_else(|e| panic!("{s:?}: {e}"));
    }
    let text = ron::ser::to_string_pretty(&shapes, ron::ser::PrettyConfig::default()).unwrap();
    let back: Vec<ShapeDesc> = ron::from_str(&text).unwrap();
    assert_eq!(back, shapes);
    let compact = ron::to_string(&shapes).unwrap();
    assert_eq!(ron::from_str::<Vec<ShapeDesc>>(&compact).unwrap(), shapes);

    // Defaults and the count forms.
    assert_eq!(
        shapes[4],
        ShapeDesc::Cylinder {
            radius: 0.04,
            height: 0.82,
            segments: 16,
            rings: None,
            layers: None
        }
    );
    assert_eq!(
        shapes[6],
        ShapeDesc::Cylinder {
            radius: 0.04,
            height: 0.82,
            segments: 16,
            rings: None,
            layers: Some(40)
        }
    );

    // The generator's parameters stay raw RON that the plugin parses into its own type.
    let ShapeDesc::Gen { name, params } = &shapes[20] else {
        panic!("last entry is Gen");
    };
    assert_eq!(name, "acme.trefoil");
    #[derive(Debug, Deserialize, PartialEq)]
    enum Kind {
        Knot { p: u32, q: u32 },
    }
    #[derive(Debug, Deserialize)]
    struct Trefoil {
        turns: u32,
        scale: Option<f64>,
        kind: Kind,
        tags: Vec<String>,
    }
    let t: Trefoil = params.into_rust().unwrap();
    println!("Gen params as stored: {}", params.get_ron());
    assert_eq!((t.turns, t.scale, t.tags.len()), (3, Some(0.2), 2));
    assert_eq!(t.kind, Kind::Knot { p: 2, q: 3 });
    let built = ShapeDesc::generated("acme.trefoil", &(1.0, 2.0)).unwrap();
    let again: ShapeDesc = ron::from_str(&ron::to_string(&built).unwrap()).unwrap();
    assert_eq!(again, built);
}

#[test]
fn documented_ron_examples_parse_and_validate() {
    let source = include_str!("mod.rs");
    let start = source.find("/// RON examples:").unwrap();
    let block: Vec<&str> = source[start..]
        .lines()
        .skip(2)
        .take_while(|l| l.trim() != "/// ```")
        .map(|l| l.trim().trim_start_matches("///").trim())
        .collect();
    assert_eq!(block.len(), 15);
    for line in block {
        let shape: ShapeDesc = ron::from_str(line).unwrap_or_else(|e| panic!("{line}: {e}"));
        shape.validate().unwrap_or_else(|e| panic!("{line}: {e}"));
    }
}

#[test]
fn every_scene_entry_generates() {
    let shapes: Vec<ShapeDesc> = ron::from_str(SCENE).unwrap();
    let ctx = super::super::ShapeContext::new(std::path::Path::new("."));
    for s in shapes
        .iter()
        .filter(|s| !matches!(s, ShapeDesc::Mesh { .. } | ShapeDesc::Gen { .. }))
    {
        match s.surface(&ctx) {
            Ok(m) => println!("{}: surface {} triangles", s.kind_name(), m.triangles.len()),
            Err(e) => {
                assert!(matches!(s, ShapeDesc::Polyline { .. }), "{s:?}: {e}");
                continue;
            }
        }
        match s.volume(&ctx) {
            Ok(v) => {
                let q = v.quality();
                println!(
                    "{}: volume {} tets, dihedral {:.1}..{:.1} deg",
                    s.kind_name(),
                    q.tets,
                    q.min_dihedral_deg,
                    q.max_dihedral_deg
                );
                assert!(v.boundary_surface().is_closed(), "{s:?}");
            }
            Err(e) => assert!(
                matches!(
                    s,
                    ShapeDesc::Sphere { .. }
                        | ShapeDesc::Capsule { .. }
                        | ShapeDesc::Plane { .. }
                        | ShapeDesc::Grid { .. }
                ),
                "{s:?}: {e}"
            ),
        }
    }
}

#[test]
fn unknown_field_error_has_line_and_column() {
    let text = "Cylinder(\n    radius: 0.04,\n    hieght: 0.82,\n)";
    let err = ron::from_str::<ShapeDesc>(text).unwrap_err();
    println!("{err}");
    assert_eq!(err.span.start.line, 3, "{err}");
    assert!(err.to_string().contains("hieght"), "{err}");
    let nested = "Sweep(profile: Circle(radius: 0.1, segs: 3), path: Line(length: 1.0))";
    let err = ron::from_str::<ShapeDesc>(nested).unwrap_err();
    println!("{err}");
    assert!(err.to_string().contains("segs"));
    let float_count = "Cylinder(radius: 0.04, height: 0.82, layers: 40.0)";
    let err = ron::from_str::<ShapeDesc>(float_count).unwrap_err();
    println!("{err}");
    assert!(err.to_string().contains("integer count"), "{err}");
}

#[test]
fn validate_rejects_bad_numbers() {
    let cases: Vec<(ShapeDesc, &str)> = vec![
        (
            ShapeDesc::sphere(-0.1),
            "radius = -0.1: must be a finite number > 0",
        ),
        (ShapeDesc::sphere(f64::NAN), "radius = NaN"),
        (ShapeDesc::cylinder(0.1, f64::INFINITY, 16), "height = inf"),
        (ShapeDesc::cylinder(0.1, 1.0, 2), "segments = 2"),
        (ShapeDesc::cuboid([1.0, 0.0, 1.0]), "size.1 = 0.0"),
        (ShapeDesc::box_grid([1.0; 3], [40, 0, 2]), "divisions.1 = 0"),
        (ShapeDesc::grid([1.0, 1.0], [1, 31]), "resolution.0 = 1"),
        (
            ShapeDesc::belt(0.9, 0.05, -0.004, None, None),
            "profile.height = -0.004",
        ),
        (ShapeDesc::rod(0.9, 0.05, 16, Some(0)), "segments = 0"),
        (ShapeDesc::torus(0.01, 0.05, 32, 16), "radius = 0.01"),
        (
            ShapeDesc::extrude(vec![(0.0, 0.0), (1.0, 1.0), (1.0, 0.0), (0.0, 1.0)], 1.0),
            "intersect",
        ),
        (
            ShapeDesc::extrude(vec![(0.0, 0.0), (1.0, 1.0)], 1.0),
            "polygon.len() = 2",
        ),
        (
            ShapeDesc::Revolve {
                profile: Profile::Circle {
                    radius: 0.01,
                    segments: 8,
                    rings: None,
                },
                radius: 0.3,
                segments: None,
                angle: 7.0,
            },
            "angle = 7.0",
        ),
        (
            ShapeDesc::tube(
                SweepPath::Polyline {
                    points: vec![(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 0.0, 0.0)],
                    closed: false,
                },
                0.01,
                8,
            ),
            "path.points[2] = (1.0, 0.0, 0.0)",
        ),
        (
            ShapeDesc::tube(
                SweepPath::Helix {
                    radius: 0.1,
                    pitch: 0.0,
                    turns: 2.0,
                },
                0.01,
                8,
            ),
            "path.pitch = 0.0",
        ),
        (ShapeDesc::mesh_file("x.ply"), "file = \"x.ply\""),
        (ShapeDesc::mesh_file(""), "file"),
    ];
    for (shape, expected) in cases {
        let err = shape.validate().unwrap_err();
        println!("{err}");
        assert!(
            err.to_string().contains(expected),
            "{err} should contain {expected}"
        );
    }
    let err = ShapeDesc::sphere(-0.1)
        .validate()
        .unwrap_err()
        .prefixed("objects[3].shape.");
    assert_eq!(err.field(), Some("objects[3].shape.radius"));
    assert_eq!(
        err.to_string(),
        "objects[3].shape.radius = -0.1: must be a finite number > 0 (and <= 1e6)"
    );
    // RON accepts NaN; validate() is what stops it.
    let nan: ShapeDesc = ron::from_str("Sphere(radius: NaN)").unwrap();
    assert!(nan.validate().is_err());
}
