//! The Rust convenience constructors of [`ShapeDesc`] ([`ShapeDesc::rod`], [`ShapeDesc::belt`],
//! [`ShapeDesc::torus`], ...).

use ron::value::RawValue;
use serde::Serialize;

use super::super::error::ShapeError;

use super::{
    default_axis, default_capsule_rings, default_full_turn, default_sphere_rings,
    default_sphere_segments, Profile, ShapeDesc, SweepPath,
};

impl ShapeDesc {
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
