//! Shape descriptions, shape generators and tetrahedral meshing.
//!
//! A scene names its geometry with a [`ShapeDesc`] (written in RON or built in Rust with the
//! convenience constructors such as [`ShapeDesc::rod`], [`ShapeDesc::belt`], [`ShapeDesc::torus`]).
//! [`ShapeDesc::validate`] checks every parameter; [`ShapeDesc::surface`] produces a triangle
//! [`SurfaceMesh`] (every variant but `Polyline`, which is a path), and [`ShapeDesc::volume`] a
//! tetrahedral [`VolumeMesh`] for the shapes a finite-element body can be made of (`Box`, `Cylinder`,
//! `Sweep`, `Revolve`, `Extrude`, volume mesh files, and `Gen` generators that return volumes).
//!
//! Conventions: SI units (metres, radians), z up; every shape is built in its own frame, centred as its
//! variant documents; the scene places it with a pose. Meshes from this module are validated: volume
//! meshes have no inverted and no degenerate tetrahedra ([`VolumeMesh::check`]) and are conforming.
//!
//! Meshing method (volumes): every sweepable shape is a 2-D cross-section (structured concentric rings
//! for circles, a grid for rectangles, ear clipping for polygons) placed at stations along a path; each
//! triangular prism between two stations is split into three tetrahedra with the rule "each quad face's
//! diagonal starts at its lowest-global-index vertex", which makes neighbouring prisms agree on shared
//! faces. Boxes are hexahedral grids split into six tetrahedra per hexahedron (Kuhn/Freudenthal split
//! along the main diagonal), conforming because every hexahedron uses the same split.
//!
//! Node numbering of generated volumes is structured and documented by [`VolumeLayout`]
//! ([`ShapeDesc::volume_with_layout`]): end faces of rods and belts are the first and last stations,
//! and a circle profile's point 0 is its centre, so station `k`'s centre-line node is
//! `k * section_points`.
//!
//! Element quality depends on the prism aspect ratio: the automatic resolutions (`None` counts) keep
//! steps along the path about one cross-section edge long, which gives minimum dihedral angles of about
//! 28-35 degrees for circles and 40 degrees for rectangles; very long or very flat prisms chosen by
//! hand lower it (see the tests' printed figures). The circle cross-section is an inscribed polygon, so
//! its area is `n/2 sin(2 pi / n) r^2` (2.6 % below `pi r^2` for 16 rim points): compute masses from the
//! mesh volume.
//!
//! Counts that can be automatic are `Option<u32>` and accept `40`, `Some(40)` or `None` in RON. The
//! sweep path type is called [`SweepPath`] in Rust (not `Path`, to avoid clashing with
//! `std::path::Path`); RON does not name it.
//!
//! The module depends only on `nalgebra`, `serde`, `ron`, `thiserror` and `std`, and refers to its own
//! items by relative paths, so it can be included at any crate root.

mod context;
mod desc;
mod error;
mod files;
mod generate;
mod mesh;
mod section;
mod sweep;
mod tess;

pub use context::{GeneratedMesh, MeshKind, ShapeContext, ShapeGenerators};
pub use desc::{Profile, ShapeDesc, SweepPath};
pub use error::{ShapeError, MAX_ELEMENTS, MAX_MAGNITUDE};
pub use files::{
    load_surface_bytes, load_surface_file, load_volume_bytes, load_volume_file, resolve_mesh_path,
    LoadedVolume,
};
pub use generate::VolumeLayout;
pub use mesh::{
    dihedral_range_deg, signed_tet_volume, FaceCensus, MeshQuality, SurfaceMesh, VolumeMesh,
    DEGENERATE_RELATIVE_VOLUME,
};
