//! Parameter validation of shape descriptions: [`Profile::validate`], [`SweepPath::validate`]
//! (with the path's length and closedness), [`ShapeDesc::validate`] and their checks.

use nalgebra::Vector3;

use super::super::error::{check_count, count_in, finite, in_range, positive, ShapeError};
use super::super::section;

use super::{
    is_full_turn, profile_min_u, to_vec2, to_vec3, Profile, ShapeDesc, SweepPath,
    FULL_TURN_TOLERANCE, MAX_COUNT,
};

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
        if tris > super::super::error::MAX_ELEMENTS {
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
    ///
    /// [`super::MAX_ELEMENTS`]: super::super::MAX_ELEMENTS
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
                super::super::files::MeshFormat::from_path(std::path::Path::new(file))
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
}
