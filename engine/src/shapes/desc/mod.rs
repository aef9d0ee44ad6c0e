//! The serde shape description ([`ShapeDesc`]) with its cross-section profiles ([`Profile`]) and sweep
//! paths ([`SweepPath`]), parameter validation and the Rust convenience constructors.
//!
//! Files: the types here; `validate` (parameter checks), `build` (the convenience
//! constructors), `tests`.

mod build;
#[cfg(test)]
mod tests;
mod validate;

use nalgebra::{Vector2, Vector3};
use ron::value::RawValue;
use serde::{Deserialize, Deserializer, Serialize};

use super::error::ShapeError;
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

/// Angles within this distance of 2 pi (radians; 0.36 degrees) count as a full turn, so a rounded
/// `6.283` closes the loop instead of leaving a sliver-thin gap.
pub(super) const FULL_TURN_TOLERANCE: f64 = 2e-3 * std::f64::consts::PI;

pub(super) fn is_full_turn(angle: f64) -> bool {
    (angle - std::f64::consts::TAU).abs() <= FULL_TURN_TOLERANCE
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

/// Smallest `u` a profile reaches (after validation).
pub(super) fn profile_min_u(profile: &Profile) -> f64 {
    match profile {
        Profile::Circle { radius, .. } => -radius,
        Profile::Rect { width, .. } => -0.5 * width,
        Profile::Polygon { points } => points.iter().map(|p| p.0).fold(f64::INFINITY, f64::min),
    }
}
