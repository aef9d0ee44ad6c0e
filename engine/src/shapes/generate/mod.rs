//! Mesh generation for every [`ShapeDesc`] variant: [`ShapeDesc::surface`] and [`ShapeDesc::volume`].
//!
//! The tests are in `tests`.

#[cfg(test)]
mod tests;

use std::f64::consts::TAU;

use nalgebra::Vector3;

use super::context::{GeneratedMesh, MeshKind, ShapeContext};
use super::desc::{is_full_turn, to_vec2, to_vec3, Profile, ShapeDesc, SweepPath};
use super::error::{check_count, ShapeError};
use super::files;
use super::mesh::{SurfaceMesh, VolumeMesh};
use super::section::{self, Section};
use super::sweep::{sample_polyline, sweep_volume, transport_frames, Frame};
use super::tess;

/// The shapes [`ShapeDesc::volume`] can mesh, for error messages.
const VOLUME_SHAPES: &str =
    "Box, Cylinder, Sweep, Revolve, Extrude, Mesh with a .msh or .mesh file, \
                             and Gen generators that return volumes";

impl ShapeDesc {
    /// A triangle surface of the shape, in the shape frame (closed and outward-wound for solids; normal
    /// +z for `Plane` and `Grid`; as stored for `.obj`/`.stl` files). Volumetric shapes return the
    /// boundary of their volume mesh (so the surface matches the tetrahedra exactly), compacted to the
    /// boundary nodes. `Polyline` has no surface and returns [`ShapeError::Unsupported`].
    pub fn surface(&self, ctx: &ShapeContext) -> Result<SurfaceMesh, ShapeError> {
        self.validate()?;
        let mesh =
            match self {
                ShapeDesc::Sphere {
                    radius,
                    segments,
                    rings,
                } => tess::sphere(*radius, *segments, *rings),
                ShapeDesc::Capsule {
                    radius,
                    height,
                    segments,
                    rings,
                } => tess::capsule(*radius, *height, *segments, *rings),
                ShapeDesc::Plane { size } => tess::plane(*size),
                ShapeDesc::Grid { size, resolution } => tess::grid(*size, *resolution),
                ShapeDesc::Polyline { .. } => return Err(ShapeError::Unsupported {
                    shape: "Polyline".into(),
                    reason:
                        "a polyline is a path and has no surface; sweep a profile along it with \
                             Sweep(profile: ..., path: Polyline(points: ...))"
                            .into(),
                }),
                ShapeDesc::Mesh { file } => {
                    let path = files::resolve_mesh_path(ctx, file)?;
                    files::load_any_surface(&path)?
                }
                ShapeDesc::Gen { name, params } => {
                    match run_generator(ctx, name, params.get_ron(), MeshKind::Surface)? {
                        GeneratedMesh::Surface(s) => s,
                        GeneratedMesh::Volume(v) => {
                            v.check().map_err(|e| generator_error(name, e))?;
                            v.boundary_surface_compact().0
                        }
                    }
                }
                ShapeDesc::Box { .. }
                | ShapeDesc::Cylinder { .. }
                | ShapeDesc::Revolve { .. }
                | ShapeDesc::Sweep { .. }
                | ShapeDesc::Extrude { .. } => self.volume(ctx)?.boundary_surface_compact().0,
            };
        mesh.check().map_err(|e| match self {
            ShapeDesc::Gen { name, .. } => generator_error(name, e),
            _ => e,
        })?;
        Ok(mesh)
    }

    /// A tetrahedral volume mesh of the shape, in the shape frame: positively oriented, conforming, no
    /// degenerate elements (checked with [`VolumeMesh::check`] before it is returned).
    ///
    /// Available for `Box`, `Cylinder`, `Sweep`, `Revolve`, `Extrude`, `.msh`/`.mesh` files and
    /// volume-producing generators; the other shapes return [`ShapeError::Unsupported`] naming these.
    pub fn volume(&self, ctx: &ShapeContext) -> Result<VolumeMesh, ShapeError> {
        self.volume_with_layout(ctx).map(|(mesh, _)| mesh)
    }

    /// Like [`ShapeDesc::volume`], and also says how the nodes are numbered ([`VolumeLayout`]), so a
    /// finite-element plugin can find end faces (to fix or grasp) and centre-line nodes (to track).
    pub fn volume_with_layout(
        &self,
        ctx: &ShapeContext,
    ) -> Result<(VolumeMesh, VolumeLayout), ShapeError> {
        self.validate()?;
        let (mesh, layout) = match self {
            ShapeDesc::Box { size, divisions } => {
                let (a, b, c) = divisions.unwrap_or((1, 1, 1));
                (
                    tess::box_grid(Vector3::new(size.0, size.1, size.2), [a, b, c]),
                    VolumeLayout::HexGrid {
                        divisions: [a, b, c],
                    },
                )
            }
            ShapeDesc::Cylinder {
                radius,
                height,
                segments,
                rings,
                layers,
            } => {
                let s = section::circle(
                    *radius,
                    *segments,
                    rings.unwrap_or_else(|| section::default_rings(*segments)),
                );
                let n = stations("Cylinder", &s, *height, *layers, false)?;
                let frames: Vec<Frame> = (0..=n)
                    .map(|k| Frame {
                        origin: Vector3::new(
                            0.0,
                            0.0,
                            height * (f64::from(k) / f64::from(n) - 0.5),
                        ),
                        eu: Vector3::x(),
                        ev: Vector3::y(),
                    })
                    .collect();
                swept("Cylinder", &s, &frames, false)?
            }
            ShapeDesc::Extrude {
                polygon,
                height,
                layers,
            } => {
                let s = section::polygon("polygon", &to_vec2(polygon))?;
                let n = stations("Extrude", &s, *height, *layers, false)?;
                let frames: Vec<Frame> = (0..=n)
                    .map(|k| Frame {
                        origin: Vector3::new(0.0, 0.0, height * f64::from(k) / f64::from(n)),
                        eu: Vector3::x(),
                        ev: Vector3::y(),
                    })
                    .collect();
                swept("Extrude", &s, &frames, false)?
            }
            ShapeDesc::Revolve {
                profile,
                radius,
                segments,
                angle,
            } => {
                let s = profile.section("profile")?;
                let closed = is_full_turn(*angle);
                // A full turn is exactly 2 pi, whatever rounding the scene used.
                let angle = if closed { &TAU } else { angle };
                let arc = (radius + s.centroid().x) * angle;
                let n = stations("Revolve", &s, arc, *segments, closed)?;
                let count = if closed { n } else { n + 1 };
                let frames: Vec<Frame> = (0..count)
                    .map(|k| {
                        let theta = angle * f64::from(k) / f64::from(n);
                        let radial = Vector3::new(theta.cos(), theta.sin(), 0.0);
                        Frame {
                            origin: *radius * radial,
                            eu: radial,
                            ev: Vector3::z(),
                        }
                    })
                    .collect();
                swept("Revolve", &s, &frames, closed)?
            }
            ShapeDesc::Sweep {
                profile,
                path,
                segments,
            } => {
                let s = profile.section("profile")?;
                let frames = path_frames(path, &s, *segments)?;
                swept("Sweep", &s, &frames, path.is_closed())?
            }
            ShapeDesc::Mesh { file } => {
                let path = files::resolve_mesh_path(ctx, file)?;
                (
                    files::load_volume_file(&path)?.mesh,
                    VolumeLayout::Unstructured,
                )
            }
            ShapeDesc::Gen { name, params } => {
                match run_generator(ctx, name, params.get_ron(), MeshKind::Volume)? {
                    GeneratedMesh::Volume(v) => {
                        v.check().map_err(|e| generator_error(name, e))?;
                        (v, VolumeLayout::Unstructured)
                    }
                    GeneratedMesh::Surface(_) => return Err(ShapeError::Generator {
                        name: name.clone(),
                        message:
                            "returned a surface mesh, but a tetrahedral volume mesh was asked for"
                                .into(),
                    }),
                }
            }
            ShapeDesc::Sphere { .. }
            | ShapeDesc::Capsule { .. }
            | ShapeDesc::Plane { .. }
            | ShapeDesc::Grid { .. }
            | ShapeDesc::Polyline { .. } => {
                return Err(ShapeError::Unsupported {
                    shape: self.kind_name().into(),
                    reason: format!(
                        "cannot be volume-meshed; shapes with volume meshes: {VOLUME_SHAPES}"
                    ),
                })
            }
        };
        mesh.check()?;
        Ok((mesh, layout))
    }
}

/// How the nodes of a generated volume mesh are numbered.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum VolumeLayout {
    /// A `Box` hexahedral grid: node `(i, j, k)` (`i <= nx`, `j <= ny`, `k <= nz`) has index
    /// `i + (nx + 1) * (j + (ny + 1) * k)`, x fastest, from the `-x, -y, -z` corner.
    HexGrid {
        /// Hexahedra along x, y, z.
        divisions: [u32; 3],
    },
    /// A swept shape (`Cylinder`, `Sweep`, `Revolve`, `Extrude`): node `station * section_points + p`
    /// is cross-section point `p` at station `station`; stations follow the path (for a `Cylinder` from
    /// `z = -height/2` up, for an `Extrude` from `z = 0` up, for a `Revolve` counter-clockwise from +x).
    Swept {
        /// Number of stations (cross-sections) along the path.
        stations: u32,
        /// Points per cross-section.
        section_points: u32,
        /// True if the last station connects back to the first (no end faces).
        closed: bool,
        /// The cross-section point at the profile origin (the centre line), if there is one: point 0 of
        /// a circle; the middle point of a rectangle with even divisions on both sides.
        centre_point: Option<u32>,
    },
    /// No known structure (mesh files, generators).
    Unstructured,
}

impl VolumeLayout {
    /// For a swept mesh, the node indices of station `station` (its cross-section); `None` otherwise or
    /// out of range. The first and last stations of an open sweep are its end faces.
    pub fn station_nodes(&self, station: u32) -> Option<std::ops::Range<u32>> {
        match self {
            VolumeLayout::Swept {
                stations,
                section_points,
                ..
            } if station < *stations => {
                Some(station * section_points..(station + 1) * section_points)
            }
            _ => None,
        }
    }

    /// For a swept mesh with a centre point, the centre-line node of every station, in path order.
    pub fn centre_line(&self) -> Option<Vec<u32>> {
        match self {
            VolumeLayout::Swept {
                stations,
                section_points,
                centre_point: Some(c),
                ..
            } => Some((0..*stations).map(|k| k * section_points + c).collect()),
            _ => None,
        }
    }
}

/// Sweeps and records the layout.
fn swept(
    shape: &str,
    s: &Section,
    frames: &[Frame],
    closed: bool,
) -> Result<(VolumeMesh, VolumeLayout), ShapeError> {
    let mesh = sweep_volume(shape, s, frames, closed)?;
    let scale = s.points.iter().map(|p| p.norm()).fold(0.0, f64::max);
    let centre_point = s
        .points
        .iter()
        .position(|p| p.norm() <= 1e-9 * scale)
        .map(|i| i as u32);
    let layout = VolumeLayout::Swept {
        stations: frames.len() as u32,
        section_points: s.points.len() as u32,
        closed,
        centre_point,
    };
    Ok((mesh, layout))
}

/// Mean edge length of a cross-section's triangles.
fn mean_edge(s: &Section) -> f64 {
    let mut sum = 0.0;
    for t in &s.tris {
        for k in 0..3 {
            sum += (s.points[t[k] as usize] - s.points[t[(k + 1) % 3] as usize]).norm();
        }
    }
    sum / (3 * s.tris.len().max(1)) as f64
}

/// Number of steps along a path of `length`: the given count, or automatically about one cross-section
/// edge length per step; checked against the element limit before anything is allocated.
fn stations(
    shape: &str,
    s: &Section,
    length: f64,
    given: Option<u32>,
    closed: bool,
) -> Result<u32, ShapeError> {
    let min = if closed { 3 } else { 1 };
    let n = match given {
        Some(n) => u64::from(n),
        None => {
            let h = mean_edge(s);
            let raw = (length / h).ceil();
            if raw.is_finite() && raw < 1e18 {
                (raw as u64).max(min)
            } else {
                u64::MAX
            }
        }
    };
    check_count(&format!("{shape}: steps along the path"), n)?;
    check_count(
        &format!("{shape}: tetrahedra (3 per prism)"),
        n.saturating_mul(s.tris.len() as u64).saturating_mul(3),
    )?;
    check_count(
        &format!("{shape}: nodes"),
        (n + 1).saturating_mul(s.points.len() as u64),
    )?;
    // n <= MAX_ELEMENTS < u32::MAX here.
    Ok(n as u32)
}

/// Frames of a sweep path, one per station.
fn path_frames(
    path: &SweepPath,
    s: &Section,
    segments: Option<u32>,
) -> Result<Vec<Frame>, ShapeError> {
    const SHAPE: &str = "Sweep";
    let closed = path.is_closed();
    let n = stations(SHAPE, s, path.length(), segments, closed)?;
    let (points, tangents) = match path {
        SweepPath::Line { length, axis } => {
            let dir = Vector3::new(axis.0, axis.1, axis.2).normalize();
            let points = (0..=n)
                .map(|k| dir * (length * (f64::from(k) / f64::from(n) - 0.5)))
                .collect();
            (points, vec![dir; n as usize + 1])
        }
        SweepPath::Polyline { points, closed } => {
            sample_polyline(SHAPE, &to_vec3(points), *closed, n)?
        }
        SweepPath::Arc { radius, angle } => {
            let angle = if closed { TAU } else { *angle };
            let count = if closed { n } else { n + 1 };
            (0..count)
                .map(|k| {
                    let theta = angle * f64::from(k) / f64::from(n);
                    let (sin, cos) = theta.sin_cos();
                    (
                        Vector3::new(radius * cos, radius * sin, 0.0),
                        Vector3::new(-sin, cos, 0.0),
                    )
                })
                .unzip()
        }
        SweepPath::Helix {
            radius,
            pitch,
            turns,
        } => (0..=n)
            .map(|k| {
                let theta = TAU * turns * f64::from(k) / f64::from(n);
                let (sin, cos) = theta.sin_cos();
                let rise = pitch / TAU;
                (
                    Vector3::new(radius * cos, radius * sin, rise * theta),
                    Vector3::new(-radius * sin, radius * cos, rise).normalize(),
                )
            })
            .unzip(),
    };
    transport_frames(SHAPE, &points, &tangents, closed)
}

fn run_generator(
    ctx: &ShapeContext,
    name: &str,
    params: &str,
    want: MeshKind,
) -> Result<GeneratedMesh, ShapeError> {
    let Some(generators) = ctx.generators else {
        return Err(ShapeError::UnknownGenerator {
            name: name.to_string(),
            known: Vec::new(),
        });
    };
    let known = generators.names();
    if !known.iter().any(|k| k == name) {
        return Err(ShapeError::UnknownGenerator {
            name: name.to_string(),
            known,
        });
    }
    generators
        .generate(name, params, want)
        .map_err(|message| ShapeError::Generator {
            name: name.to_string(),
            message,
        })
}

fn generator_error(name: &str, e: ShapeError) -> ShapeError {
    ShapeError::Generator {
        name: name.to_string(),
        message: format!("returned an invalid mesh: {e}"),
    }
}

impl ShapeDesc {
    /// The cross-section profile of a `Revolve` or `Sweep`, if this is one.
    pub fn profile(&self) -> Option<&Profile> {
        match self {
            ShapeDesc::Revolve { profile, .. } | ShapeDesc::Sweep { profile, .. } => Some(profile),
            _ => None,
        }
    }
}
