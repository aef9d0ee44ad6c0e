//! The serde shape description ([`ShapeDesc`]) with its cross-section profiles ([`Profile`]) and sweep
//! paths ([`SweepPath`]), parameter validation and the Rust convenience constructors.

use nalgebra::{Vector2, Vector3};
use ron::value::RawValue;
use serde::{Deserialize, Deserializer, Serialize};

use super::error::{check_count, count_in, finite, in_range, positive, ShapeError};
use super::section;

/// Largest value accepted for any single resolution count (segments, rings, layers, divisions).
const MAX_COUNT: u32 = 1_000_000;

/// Geometry of an object, as written in a scene file (RON) or built in Rust.
///
/// Every shape lives in its own frame (metres, z up) as each variant documents; the scene gives the
/// pose. Optional resolution fields marked "auto" may be left out; they then follow the cross-section's
/// spacing so elements stay close to equilateral. Such a field may be written as a bare integer
/// (`layers: 40`), as `Some(40)` or as `None`.
///
/// RON examples:
/// ```text
/// Box(size: (1.0, 0.5, 0.2))                          // surface; volume = 6 tetrahedra
/// Box(size: (0.82, 0.04, 0.04), divisions: Some((40, 2, 2)))
/// Sphere(radius: 0.1)
/// Cylinder(radius: 0.04, height: 0.82)
/// Capsule(radius: 0.05, height: 0.3)
/// Plane(size: (10.0, 10.0))
/// Grid(size: (1.6, 1.2), resolution: (41, 31))
/// Polyline(points: [(0, 0, 0), (1, 0, 0)], closed: false)
/// Revolve(profile: Circle(radius: 0.02), radius: 0.3)                       // torus
/// Revolve(profile: Rect(width: 0.02, height: 0.01), radius: 0.3, segments: 64)  // ring
/// Sweep(profile: Rect(width: 0.05, height: 0.004), path: Line(length: 0.9))     // belt along x
/// Sweep(profile: Circle(radius: 0.01), path: Helix(radius: 0.1, pitch: 0.05, turns: 3.0))
/// Extrude(polygon: [(0, 0), (1, 0), (0, 1)], height: 0.1)
/// Mesh(file: "meshes/bunny.obj")
/// Gen(name: "acme.trefoil", params: (turns: 3, radius: 0.2))
/// ```
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub enum ShapeDesc {
    /// A box centred at the origin with edge lengths `size` along x, y, z.
    ///
    /// Volume: an `nx x ny x nz` hexahedral grid (`divisions`, default `(1, 1, 1)`), each hexahedron
    /// split into 6 tetrahedra (Kuhn split), `(nx+1)(ny+1)(nz+1)` nodes, x fastest.
    Box {
        /// Edge lengths along x, y, z, metres (> 0).
        size: (f64, f64, f64),
        /// Hexahedra along x, y, z (each >= 1); `None` means one hexahedron.
        #[serde(default)]
        divisions: Option<(u32, u32, u32)>,
    },
    /// A sphere centred at the origin (surface only), latitude-longitude tessellation.
    Sphere {
        /// Radius, metres (> 0).
        radius: f64,
        /// Vertices around z (>= 3, default 24).
        #[serde(default = "default_sphere_segments")]
        segments: u32,
        /// Bands from pole to pole (>= 2, default 12).
        #[serde(default = "default_sphere_rings")]
        rings: u32,
    },
    /// A solid cylinder along z centred at the origin (z from `-height/2` to `height/2`).
    ///
    /// Volume: a disk of concentric rings swept along z.
    Cylinder {
        /// Radius, metres (> 0).
        radius: f64,
        /// Length along z, metres (> 0).
        height: f64,
        /// Vertices on the rim (>= 3, default 16).
        #[serde(default = "default_circle_segments")]
        segments: u32,
        /// Concentric rings of the cross-section (1..=segments, auto: `segments / 2 pi`).
        #[serde(default, deserialize_with = "count_or_auto")]
        rings: Option<u32>,
        /// Layers along z (>= 1, auto: about the cross-section's edge length).
        #[serde(default, deserialize_with = "count_or_auto")]
        layers: Option<u32>,
    },
    /// A capsule along z centred at the origin (surface only): a cylinder of `height` between the
    /// hemisphere centres, total length `height + 2 radius`.
    Capsule {
        /// Radius, metres (> 0).
        radius: f64,
        /// Length of the cylindrical part, metres (>= 0).
        height: f64,
        /// Vertices around z (>= 3, default 24).
        #[serde(default = "default_sphere_segments")]
        segments: u32,
        /// Bands per hemisphere, pole to equator (>= 1, default 6).
        #[serde(default = "default_capsule_rings")]
        rings: u32,
    },
    /// A rectangle in the xy-plane centred at the origin, normal +z (surface only; two triangles).
    Plane {
        /// Edge lengths along x and y, metres (> 0).
        size: (f64, f64),
    },
    /// A cloth sheet in the xy-plane centred at the origin, normal +z (surface only).
    ///
    /// Vertex `(i, j)` has index `j * resolution.0 + i` (x fastest); cell diagonals alternate.
    Grid {
        /// Edge lengths along x and y, metres (> 0).
        size: (f64, f64),
        /// Vertex counts along x and y (each >= 2), e.g. `(41, 31)`.
        resolution: (u32, u32),
    },
    /// A 3-D path (points in metres). It has no surface or volume of its own: use it as the path of a
    /// `Sweep` (`path: Polyline(...)`) or read its points for a rod's centre line.
    Polyline {
        /// Points (>= 2; >= 3 when closed), consecutive points distinct.
        points: Vec<(f64, f64, f64)>,
        /// Join the last point to the first (do not repeat the first point).
        #[serde(default)]
        closed: bool,
    },
    /// A profile revolved about the z axis: profile `u` is added to `radius` (distance from the axis),
    /// profile `v` is height along z. A circle profile gives a torus, a rectangle a ring. The
    /// revolution starts on the +x axis and turns counter-clockwise about z by `angle`; a full turn
    /// (`angle` = 2 pi, the default) is closed with a single seam.
    Revolve {
        /// The cross-section.
        profile: Profile,
        /// Distance of the profile origin from the z axis, metres (>= 0; the profile must stay at a
        /// positive distance from the axis).
        radius: f64,
        /// Steps around the axis (>= 1, >= 3 for a full turn; auto: about the cross-section's edge length
        /// at the profile's centroid).
        #[serde(default, deserialize_with = "count_or_auto")]
        segments: Option<u32>,
        /// Revolution angle, radians, in (0, 2 pi]; within 0.36 degrees of 2 pi counts as a full turn.
        #[serde(default = "default_full_turn")]
        angle: f64,
    },
    /// A profile swept along a path (belt: rectangle along a line; tube: circle along a polyline, arc or
    /// helix). The profile's `u` axis follows the path's normal and `v` its binormal, transported along
    /// the path without twist (see [`SweepPath`]).
    Sweep {
        /// The cross-section.
        profile: Profile,
        /// The path of the profile's origin.
        path: SweepPath,
        /// Steps along the path (>= 1; auto: about the cross-section's edge length). For polylines it is
        /// distributed over the edges by length, at least one step per edge.
        #[serde(default, deserialize_with = "count_or_auto")]
        segments: Option<u32>,
    },
    /// A simple polygon in the xy-plane extruded along +z from `z = 0` to `z = height`.
    Extrude {
        /// Polygon corners `(x, y)`, metres; either winding; simple (no self-intersections), >= 3 points.
        polygon: Vec<(f64, f64)>,
        /// Extrusion height, metres (> 0).
        height: f64,
        /// Layers along z (>= 1; auto: about the cross-section's edge length).
        #[serde(default, deserialize_with = "count_or_auto")]
        layers: Option<u32>,
    },
    /// A mesh file, resolved against the scene folder (see [`super::resolve_mesh_path`]): surfaces from
    /// `.obj` and `.stl` (ASCII or binary), tetrahedral volumes from gmsh `.msh` (v4.1 ASCII) and medit
    /// `.mesh`.
    Mesh {
        /// Path of the file, relative to the scene file's folder (or absolute inside an asset root).
        file: String,
    },
    /// A shape made by a registered generator (a plugin), e.g. `Gen(name: "acme.trefoil", params: (...))`.
    /// `params` is any RON value, kept verbatim and handed to the generator as text.
    Gen {
        /// Registered generator name.
        name: String,
        /// The generator's parameters, raw RON (parse with `params.into_rust::<T>()`).
        params: Box<RawValue>,
    },
}

/// A 2-D cross-section for `Revolve` and `Sweep`, in profile coordinates `(u, v)`, centred on the
/// profile origin.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub enum Profile {
    /// A disk meshed as concentric rings (not a fan), so tetrahedra keep reasonable angles.
    Circle {
        /// Radius, metres (> 0).
        radius: f64,
        /// Vertices on the rim (>= 3, default 16).
        #[serde(default = "default_circle_segments")]
        segments: u32,
        /// Concentric rings (1..=segments; auto: `segments / 2 pi`).
        #[serde(default, deserialize_with = "count_or_auto")]
        rings: Option<u32>,
    },
    /// A rectangle, `width` along `u` and `height` along `v`, as a grid of cells.
    Rect {
        /// Extent along `u`, metres (> 0).
        width: f64,
        /// Extent along `v`, metres (> 0).
        height: f64,
        /// Cells along `u` and `v` (each >= 1); `None`: square-ish cells the size of the shorter side
        /// (at most 64 per side).
        #[serde(default)]
        divisions: Option<(u32, u32)>,
    },
    /// A simple polygon (either winding), triangulated by ear clipping without extra points.
    Polygon {
        /// Corners `(u, v)`, metres (>= 3, simple).
        points: Vec<(f64, f64)>,
    },
}

/// The path a `Sweep` moves its profile along.
///
/// The profile frame starts with `v` (binormal) as close to +z as possible (for a path starting along
/// z: `u` along +x) and is carried along without twist (parallel transport); on closed paths any twist
/// left at the seam is spread evenly over the stations. At polyline corners the cross-section lies in
/// the bisecting plane and is not widened, so sharp corners pinch the tube: subdivide them.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub enum SweepPath {
    /// A straight segment of `length` along `axis`, centred at the origin.
    Line {
        /// Length, metres (> 0).
        length: f64,
        /// Direction (normalised; not zero), default +x.
        #[serde(default = "default_axis")]
        axis: (f64, f64, f64),
    },
    /// A polyline through `points` (metres).
    Polyline {
        /// Points (>= 2; >= 3 when closed), consecutive points distinct, no 180 degree turns.
        points: Vec<(f64, f64, f64)>,
        /// Join the last point to the first (do not repeat the first point).
        #[serde(default)]
        closed: bool,
    },
    /// A circular arc in the xy-plane about the origin, starting at `(radius, 0, 0)` and turning
    /// counter-clockwise by `angle`; a full turn (2 pi) is a closed loop.
    Arc {
        /// Radius, metres (> 0).
        radius: f64,
        /// Angle, radians, in (0, 2 pi]; within 0.36 degrees of 2 pi counts as a full turn.
        angle: f64,
    },
    /// A helix about z starting at `(radius, 0, 0)`, turning counter-clockwise and rising `pitch` per
    /// turn (a negative pitch descends). Overlap of neighbouring turns is not checked: keep
    /// `|pitch|` larger than the profile.
    Helix {
        /// Radius, metres (> 0).
        radius: f64,
        /// Rise per turn, metres (finite, not zero).
        pitch: f64,
        /// Number of turns (> 0).
        turns: f64,
    },
}

fn default_sphere_segments() -> u32 {
    24
}
fn default_sphere_rings() -> u32 {
    12
}
fn default_capsule_rings() -> u32 {
    6
}
fn default_circle_segments() -> u32 {
    16
}
fn default_full_turn() -> f64 {
    std::f64::consts::TAU
}
fn default_axis() -> (f64, f64, f64) {
    (1.0, 0.0, 0.0)
}

/// Deserializes an optional count written as `40`, `Some(40)` or `None`.
fn count_or_auto<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u32>, D::Error> {
    struct V;
    impl<'de> serde::de::Visitor<'de> for V {
        type Value = Option<u32>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a non-negative integer count (e.g. 40), Some(40), or None for automatic")
        }
        fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Self::Value, E> {
            u32::try_from(v)
                .map(Some)
                .map_err(|_| E::invalid_value(serde::de::Unexpected::Unsigned(v), &self))
        }
        fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Self::Value, E> {
            u32::try_from(v)
                .map(Some)
                .map_err(|_| E::invalid_value(serde::de::Unexpected::Signed(v), &self))
        }
        fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Self::Value, E> {
            Err(E::invalid_type(serde::de::Unexpected::Float(v), &self))
        }
        fn visit_none<E: serde::de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_unit<E: serde::de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_some<D2: Deserializer<'de>>(self, d: D2) -> Result<Self::Value, D2::Error> {
            u32::deserialize(d).map(Some)
        }
    }
    d.deserialize_any(V)
}

impl Profile {
    /// Checks the profile's parameters; `field` is the path of the profile in errors (e.g. `profile`).
    pub fn validate(&self, field: &str) -> Result<(), ShapeError> {
        match self {
            Profile::Circle {
                radius,
                segments,
                rings,
            } => {
                positive(&format!("{field}.radius"), *radius)?;
                check_circle(field, *segments, *rings)
            }
            Profile::Rect {
                width,
                height,
                divisions,
            } => {
                positive(&format!("{field}.width"), *width)?;
                positive(&format!("{field}.height"), *height)?;
                if let Some((a, b)) = divisions {
                    count_in(&format!("{field}.divisions.0"), *a, 1, MAX_COUNT)?;
                    count_in(&format!("{field}.divisions.1"), *b, 1, MAX_COUNT)?;
                    check_count(
                        &format!("{field}.divisions: triangles"),
                        2 * u64::from(*a) * u64::from(*b),
                    )?;
                }
                Ok(())
            }
            Profile::Polygon { points } => {
                section::check_polygon(&format!("{field}.points"), &to_vec2(points))
            }
        }
    }

    /// Builds the triangulated cross-section (after validation).
    pub(super) fn section(&self, field: &str) -> Result<section::Section, ShapeError> {
        self.validate(field)?;
        Ok(match self {
            Profile::Circle {
                radius,
                segments,
                rings,
            } => section::circle(
                *radius,
                *segments,
                rings.unwrap_or_else(|| section::default_rings(*segments)),
            ),
            Profile::Rect {
                width,
                height,
                divisions,
            } => {
                let (a, b) =
                    divisions.unwrap_or_else(|| section::default_rect_divisions(*width, *height));
                section::rect(*width, *height, a, b)
            }
            Profile::Polygon { points } => {
                section::polygon(&format!("{field}.points"), &to_vec2(points))?
            }
        })
    }
}

/// Checks a circle's rim segment and ring counts and the size of its triangulation.
fn check_circle(field: &str, segments: u32, rings: Option<u32>) -> Result<(), ShapeError> {
    let prefix = if field.is_empty() {
        String::new()
    } else {
        format!("{field}.")
    };
    count_in(&format!("{prefix}segments"), segments, 3, MAX_COUNT)?;
    let rings = match rings {
        Some(r) => {
            count_in(&format!("{prefix}rings"), r, 1, segments)?;
            r
        }
        None => section::default_rings(segments),
    };
    // Triangles: the centre fan plus, between rings, the sum of both rings' node counts.
    let mut tris = u64::from(section::ring_nodes(segments, rings, 1));
    for k in 2..=rings {
        tris += u64::from(section::ring_nodes(segments, rings, k - 1))
            + u64::from(section::ring_nodes(segments, rings, k));
        if tris > super::error::MAX_ELEMENTS {
            break;
        }
    }
    check_count(
        &format!("{prefix}segments/rings: cross-section triangles"),
        tris,
    )
}

impl SweepPath {
    /// Checks the path's parameters; `field` is the path of the path in errors (e.g. `path`).
    pub fn validate(&self, field: &str) -> Result<(), ShapeError> {
        match self {
            SweepPath::Line { length, axis } => {
                positive(&format!("{field}.length"), *length)?;
                check_direction(&format!("{field}.axis"), *axis)
            }
            SweepPath::Polyline { points, closed } => {
                check_polyline(&format!("{field}.points"), points, *closed)
            }
            SweepPath::Arc { radius, angle } => {
                positive(&format!("{field}.radius"), *radius)?;
                check_angle(&format!("{field}.angle"), *angle)
            }
            SweepPath::Helix {
                radius,
                pitch,
                turns,
            } => {
                positive(&format!("{field}.radius"), *radius)?;
                finite(&format!("{field}.pitch"), *pitch)?;
                if *pitch == 0.0 {
                    return Err(ShapeError::invalid(
                        format!("{field}.pitch"),
                        pitch,
                        "must not be zero (use Arc for a flat loop)",
                    ));
                }
                positive(&format!("{field}.turns"), *turns)?;
                if *turns > f64::from(MAX_COUNT) {
                    return Err(ShapeError::invalid(
                        format!("{field}.turns"),
                        turns,
                        format!("must be at most {MAX_COUNT}"),
                    ));
                }
                Ok(())
            }
        }
    }

    /// True if the path is a closed loop (closed polyline, full-turn arc).
    pub fn is_closed(&self) -> bool {
        match self {
            SweepPath::Polyline { closed, .. } => *closed,
            SweepPath::Arc { angle, .. } => is_full_turn(*angle),
            SweepPath::Line { .. } | SweepPath::Helix { .. } => false,
        }
    }

    /// Length of the path, metres (after validation).
    pub fn length(&self) -> f64 {
        match self {
            SweepPath::Line { length, .. } => *length,
            SweepPath::Polyline { points, closed } => {
                let p = to_vec3(points);
                let n = p.len();
                let edges = if *closed { n } else { n.saturating_sub(1) };
                (0..edges).map(|e| (p[(e + 1) % n] - p[e]).norm()).sum()
            }
            SweepPath::Arc { radius, angle } => radius * angle,
            SweepPath::Helix {
                radius,
                pitch,
                turns,
            } => turns * (std::f64::consts::TAU * radius).hypot(*pitch),
        }
    }
}

/// Angles within this distance of 2 pi (radians; 0.36 degrees) count as a full turn, so a rounded
/// `6.283` closes the loop instead of leaving a sliver-thin gap.
pub(super) const FULL_TURN_TOLERANCE: f64 = 2e-3 * std::f64::consts::PI;

pub(super) fn is_full_turn(angle: f64) -> bool {
    (angle - std::f64::consts::TAU).abs() <= FULL_TURN_TOLERANCE
}

fn check_angle(field: &str, angle: f64) -> Result<(), ShapeError> {
    if angle.is_finite() && angle > 0.0 && angle <= std::f64::consts::TAU + FULL_TURN_TOLERANCE {
        Ok(())
    } else {
        Err(ShapeError::invalid(
            field,
            angle,
            "must be an angle in radians in (0, 2 pi] (6.283185307179586 for a full turn; values within \
             0.006 of it count as a full turn)",
        ))
    }
}

fn check_direction(field: &str, axis: (f64, f64, f64)) -> Result<(), ShapeError> {
    let v = Vector3::new(axis.0, axis.1, axis.2);
    if v.iter().all(|&x| in_range(x)) && v.norm() > 0.0 {
        Ok(())
    } else {
        Err(ShapeError::invalid(
            field,
            axis,
            "must be a finite, non-zero direction",
        ))
    }
}

fn check_polyline(field: &str, points: &[(f64, f64, f64)], closed: bool) -> Result<(), ShapeError> {
    let min = if closed { 3 } else { 2 };
    if points.len() < min || points.len() > MAX_COUNT as usize {
        return Err(ShapeError::invalid(
            format!("{field}.len()"),
            points.len(),
            format!(
                "a {} polyline needs between {min} and {MAX_COUNT} points",
                if closed { "closed" } else { "open" }
            ),
        ));
    }
    let p = to_vec3(points);
    for (i, q) in p.iter().enumerate() {
        if !q.iter().all(|&x| in_range(x)) {
            return Err(ShapeError::invalid(
                format!("{field}[{i}]"),
                points[i],
                "must be finite, each coordinate with magnitude <= 1e6",
            ));
        }
    }
    let n = p.len();
    let edges = if closed { n } else { n - 1 };
    for e in 0..edges {
        let j = (e + 1) % n;
        if (p[j] - p[e]).norm() == 0.0 {
            let hint = if closed && j == 0 {
                "repeats the first point; a closed polyline joins its ends itself, do not repeat the first point"
            } else {
                "repeats the previous point; consecutive points must differ"
            };
            let index = if closed && j == 0 { e } else { j };
            return Err(ShapeError::invalid(
                format!("{field}[{index}]"),
                points[index],
                hint,
            ));
        }
    }
    Ok(())
}

pub(super) fn to_vec2(points: &[(f64, f64)]) -> Vec<Vector2<f64>> {
    points.iter().map(|&(x, y)| Vector2::new(x, y)).collect()
}

pub(super) fn to_vec3(points: &[(f64, f64, f64)]) -> Vec<Vector3<f64>> {
    points
        .iter()
        .map(|&(x, y, z)| Vector3::new(x, y, z))
        .collect()
}

fn check_size(field: &str, values: &[f64]) -> Result<(), ShapeError> {
    for (i, v) in values.iter().enumerate() {
        positive(&format!("{field}.{i}"), *v)?;
    }
    Ok(())
}

fn check_optional_count(field: &str, value: Option<u32>, min: u32) -> Result<(), ShapeError> {
    match value {
        Some(v) => count_in(field, v, min, MAX_COUNT),
        None => Ok(()),
    }
}

impl ShapeDesc {
    /// The variant's name as written in RON (`"Box"`, `"Sweep"`, ...).
    pub fn kind_name(&self) -> &'static str {
        match self {
            ShapeDesc::Box { .. } => "Box",
            ShapeDesc::Sphere { .. } => "Sphere",
            ShapeDesc::Cylinder { .. } => "Cylinder",
            ShapeDesc::Capsule { .. } => "Capsule",
            ShapeDesc::Plane { .. } => "Plane",
            ShapeDesc::Grid { .. } => "Grid",
            ShapeDesc::Polyline { .. } => "Polyline",
            ShapeDesc::Revolve { .. } => "Revolve",
            ShapeDesc::Sweep { .. } => "Sweep",
            ShapeDesc::Extrude { .. } => "Extrude",
            ShapeDesc::Mesh { .. } => "Mesh",
            ShapeDesc::Gen { .. } => "Gen",
        }
    }

    /// Checks every parameter: finite numbers, positive sizes, resolutions in range, element counts
    /// within [`super::MAX_ELEMENTS`], simple polygons, known mesh file extensions. Errors name the
    /// field relative to the shape (prefix them with [`ShapeError::prefixed`]).
    ///
    /// `Gen` parameters are checked by the generator; mesh files by the loader.
    pub fn validate(&self) -> Result<(), ShapeError> {
        match self {
            ShapeDesc::Box { size, divisions } => {
                check_size("size", &[size.0, size.1, size.2])?;
                if let Some((a, b, c)) = divisions {
                    count_in("divisions.0", *a, 1, MAX_COUNT)?;
                    count_in("divisions.1", *b, 1, MAX_COUNT)?;
                    count_in("divisions.2", *c, 1, MAX_COUNT)?;
                    let hexes = u64::from(*a) * u64::from(*b) * u64::from(*c);
                    check_count(
                        "divisions: tetrahedra (6 per hexahedron)",
                        hexes.saturating_mul(6),
                    )?;
                }
                Ok(())
            }
            ShapeDesc::Sphere {
                radius,
                segments,
                rings,
            } => {
                positive("radius", *radius)?;
                count_in("segments", *segments, 3, MAX_COUNT)?;
                count_in("rings", *rings, 2, MAX_COUNT)?;
                check_count(
                    "segments x rings: triangles",
                    2 * u64::from(*segments) * u64::from(*rings),
                )
            }
            ShapeDesc::Cylinder {
                radius,
                height,
                segments,
                rings,
                layers,
            } => {
                positive("radius", *radius)?;
                positive("height", *height)?;
                check_circle("", *segments, *rings)?;
                check_optional_count("layers", *layers, 1)
            }
            ShapeDesc::Capsule {
                radius,
                height,
                segments,
                rings,
            } => {
                positive("radius", *radius)?;
                if !(in_range(*height) && *height >= 0.0) {
                    return Err(ShapeError::invalid(
                        "height",
                        height,
                        "must be a finite number >= 0 (and <= 1e6)",
                    ));
                }
                count_in("segments", *segments, 3, MAX_COUNT)?;
                count_in("rings", *rings, 1, MAX_COUNT)?;
                check_count(
                    "segments x rings: triangles",
                    4 * u64::from(*segments) * (u64::from(*rings) + 1),
                )
            }
            ShapeDesc::Plane { size } => check_size("size", &[size.0, size.1]),
            ShapeDesc::Grid { size, resolution } => {
                check_size("size", &[size.0, size.1])?;
                count_in("resolution.0", resolution.0, 2, MAX_COUNT)?;
                count_in("resolution.1", resolution.1, 2, MAX_COUNT)?;
                check_count(
                    "resolution: triangles",
                    2 * u64::from(resolution.0 - 1) * u64::from(resolution.1 - 1),
                )
            }
            ShapeDesc::Polyline { points, closed } => check_polyline("points", points, *closed),
            ShapeDesc::Revolve {
                profile,
                radius,
                segments,
                angle,
            } => {
                profile.validate("profile")?;
                if !(in_range(*radius) && *radius >= 0.0) {
                    return Err(ShapeError::invalid(
                        "radius",
                        radius,
                        "must be a finite number >= 0 (and <= 1e6)",
                    ));
                }
                check_angle("angle", *angle)?;
                let min_segments = if is_full_turn(*angle) { 3 } else { 1 };
                check_optional_count("segments", *segments, min_segments)?;
                let inner = radius + profile_min_u(profile);
                if inner.is_nan() || inner <= 0.0 {
                    return Err(ShapeError::invalid(
                        "radius",
                        radius,
                        format!(
                            "the profile reaches {inner} m from the axis; radius must exceed the profile's extent \
                             towards the axis ({})",
                            -profile_min_u(profile)
                        ),
                    ));
                }
                Ok(())
            }
            ShapeDesc::Sweep {
                profile,
                path,
                segments,
            } => {
                profile.validate("profile")?;
                path.validate("path")?;
                let min_segments = if path.is_closed() { 3 } else { 1 };
                check_optional_count("segments", *segments, min_segments)
            }
            ShapeDesc::Extrude {
                polygon,
                height,
                layers,
            } => {
                section::check_polygon("polygon", &to_vec2(polygon))?;
                positive("height", *height)?;
                check_optional_count("layers", *layers, 1)
            }
            ShapeDesc::Mesh { file } => {
                if file.trim().is_empty() {
                    return Err(ShapeError::invalid("file", file, "must name a mesh file"));
                }
                super::files::MeshFormat::from_path(std::path::Path::new(file))
                    .map(|_| ())
                    .ok_or_else(|| {
                        ShapeError::invalid(
                            "file",
                            file,
                            "must end in .obj or .stl (surfaces), .msh (gmsh 4.1 ASCII) or .mesh (medit volumes)",
                        )
                    })
            }
            ShapeDesc::Gen { name, .. } => {
                if name.trim().is_empty() {
                    Err(ShapeError::invalid(
                        "name",
                        name,
                        "must name a registered shape generator",
                    ))
                } else {
                    Ok(())
                }
            }
        }
    }

    // ----- convenience constructors -----

    /// A box of edge lengths `size` (surface or a single-hexahedron volume).
    pub fn cuboid(size: [f64; 3]) -> Self {
        ShapeDesc::Box {
            size: (size[0], size[1], size[2]),
            divisions: None,
        }
    }

    /// A box meshed as a `divisions` hexahedral grid, 6 tetrahedra per hexahedron
    /// (e.g. `box_grid([0.82, 0.04, 0.04], [40, 2, 2])`: 960 tetrahedra, 369 nodes).
    pub fn box_grid(size: [f64; 3], divisions: [u32; 3]) -> Self {
        ShapeDesc::Box {
            size: (size[0], size[1], size[2]),
            divisions: Some((divisions[0], divisions[1], divisions[2])),
        }
    }

    /// A sphere of `radius` with the default tessellation.
    pub fn sphere(radius: f64) -> Self {
        ShapeDesc::Sphere {
            radius,
            segments: default_sphere_segments(),
            rings: default_sphere_rings(),
        }
    }

    /// A cylinder along z with automatic rings and layers and `segments` rim vertices.
    pub fn cylinder(radius: f64, height: f64, segments: u32) -> Self {
        ShapeDesc::Cylinder {
            radius,
            height,
            segments,
            rings: None,
            layers: None,
        }
    }

    /// A capsule along z (`height` between the hemisphere centres) with the default tessellation.
    pub fn capsule(radius: f64, height: f64) -> Self {
        ShapeDesc::Capsule {
            radius,
            height,
            segments: default_sphere_segments(),
            rings: default_capsule_rings(),
        }
    }

    /// A rectangle of `size` in the xy-plane (two triangles).
    pub fn plane(size: [f64; 2]) -> Self {
        ShapeDesc::Plane {
            size: (size[0], size[1]),
        }
    }

    /// A cloth sheet of `size` with `resolution` vertices along x and y (e.g. `([1.6, 1.2], [41, 31])`).
    pub fn grid(size: [f64; 2], resolution: [u32; 2]) -> Self {
        ShapeDesc::Grid {
            size: (size[0], size[1]),
            resolution: (resolution[0], resolution[1]),
        }
    }

    /// An elastic rod along x centred at the origin: a circle of `radius` with `circle_segments` rim
    /// vertices (automatic rings) swept along a line of `length`, `length_segments` steps (`None`:
    /// automatic, about the cross-section's edge length).
    pub fn rod(
        length: f64,
        radius: f64,
        circle_segments: u32,
        length_segments: Option<u32>,
    ) -> Self {
        ShapeDesc::Sweep {
            profile: Profile::Circle {
                radius,
                segments: circle_segments,
                rings: None,
            },
            path: SweepPath::Line {
                length,
                axis: default_axis(),
            },
            segments: length_segments,
        }
    }

    /// A belt along x centred at the origin: `width` along y, `thickness` along z, cross-section cells
    /// `divisions` (`None`: square-ish cells the size of the thickness), `length_segments` steps along x
    /// (`None`: automatic).
    pub fn belt(
        length: f64,
        width: f64,
        thickness: f64,
        divisions: Option<(u32, u32)>,
        length_segments: Option<u32>,
    ) -> Self {
        ShapeDesc::Sweep {
            profile: Profile::Rect {
                width,
                height: thickness,
                divisions,
            },
            path: SweepPath::Line {
                length,
                axis: default_axis(),
            },
            segments: length_segments,
        }
    }

    /// A torus about z: tube of radius `minor` (with `segments_minor` rim vertices) around a circle of
    /// radius `major` (`segments_major` steps). Exact volume of the smooth torus: `2 pi^2 major minor^2`.
    pub fn torus(major: f64, minor: f64, segments_major: u32, segments_minor: u32) -> Self {
        ShapeDesc::Revolve {
            profile: Profile::Circle {
                radius: minor,
                segments: segments_minor,
                rings: None,
            },
            radius: major,
            segments: Some(segments_major),
            angle: default_full_turn(),
        }
    }

    /// A flat ring (washer) about z: rectangular cross-section `width` (radial) x `height` (along z)
    /// centred at `radius`, `segments` steps around.
    pub fn ring(radius: f64, width: f64, height: f64, segments: u32) -> Self {
        ShapeDesc::Revolve {
            profile: Profile::Rect {
                width,
                height,
                divisions: None,
            },
            radius,
            segments: Some(segments),
            angle: default_full_turn(),
        }
    }

    /// A tube of `radius` (with `circle_segments` rim vertices) along `path`, automatic steps.
    pub fn tube(path: SweepPath, radius: f64, circle_segments: u32) -> Self {
        ShapeDesc::Sweep {
            profile: Profile::Circle {
                radius,
                segments: circle_segments,
                rings: None,
            },
            path,
            segments: None,
        }
    }

    /// A polygon in the xy-plane extruded to `height` along +z, automatic layers.
    pub fn extrude(polygon: Vec<(f64, f64)>, height: f64) -> Self {
        ShapeDesc::Extrude {
            polygon,
            height,
            layers: None,
        }
    }

    /// A mesh file (see [`ShapeDesc::Mesh`]).
    pub fn mesh_file(file: impl Into<String>) -> Self {
        ShapeDesc::Mesh { file: file.into() }
    }

    /// A registered generator's shape with parameters given as any serializable Rust value (stored as
    /// RON text).
    pub fn generated(name: impl Into<String>, params: &impl Serialize) -> Result<Self, ShapeError> {
        let name = name.into();
        let params = RawValue::from_rust(params).map_err(|e| ShapeError::Generator {
            name: name.clone(),
            message: format!("parameters cannot be written as RON: {e}"),
        })?;
        Ok(ShapeDesc::Gen { name, params })
    }
}

/// Smallest `u` a profile reaches (after validation).
pub(super) fn profile_min_u(profile: &Profile) -> f64 {
    match profile {
        Profile::Circle { radius, .. } => -radius,
        Profile::Rect { width, .. } => -0.5 * width,
        Profile::Polygon { points } => points.iter().map(|p| p.0).fold(f64::INFINITY, f64::min),
    }
}

#[cfg(test)]
mod tests {
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
        let source = include_str!("desc.rs");
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
}
