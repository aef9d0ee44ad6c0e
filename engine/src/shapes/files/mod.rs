//! Mesh files: safe path resolution and loaders for OBJ and STL surfaces and gmsh `.msh` (4.1 ASCII) and
//! medit `.mesh` tetrahedral volumes.
//!
//! Files: path resolution, reading and the loaders here; `surface` (OBJ, STL), `volume` (gmsh,
//! medit), `tests`.

mod surface;
#[cfg(test)]
mod tests;
mod text;
mod volume;

use std::path::{Path, PathBuf};

use super::context::ShapeContext;
use super::error::ShapeError;
use super::mesh::{SurfaceMesh, VolumeMesh};
use surface::{parse_obj, parse_stl};
use text::parse_error;
use volume::{parse_medit, parse_msh};

/// Largest mesh file read, bytes (1 GiB).
const MAX_FILE_BYTES: u64 = 1 << 30;

/// The mesh file formats, recognised by extension (case-insensitive).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum MeshFormat {
    /// Wavefront OBJ surface.
    Obj,
    /// STL surface (ASCII or binary).
    Stl,
    /// gmsh MSH 4.1 ASCII volume.
    Msh,
    /// medit (INRIA) `.mesh` volume.
    Medit,
}

impl MeshFormat {
    /// The format of a file, from its extension.
    pub fn from_path(path: &Path) -> Option<MeshFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "obj" => Some(MeshFormat::Obj),
            "stl" => Some(MeshFormat::Stl),
            "msh" => Some(MeshFormat::Msh),
            "mesh" => Some(MeshFormat::Medit),
            _ => None,
        }
    }
}

/// Resolves a mesh path from a scene: relative paths are tried against `ctx.base_dir`, then against each
/// of `ctx.asset_roots`; the first existing candidate is canonicalized (symbolic links and `..`
/// resolved) and must lie inside the canonical `base_dir` or one of the canonical asset roots.
///
/// Errors: [`ShapeError::NotFound`] listing every path tried; [`ShapeError::PathEscape`] for a file
/// outside all roots (e.g. `../../etc/passwd`); [`ShapeError::Io`] if it is not a regular file.
pub fn resolve_mesh_path(ctx: &ShapeContext, file: &str) -> Result<PathBuf, ShapeError> {
    let written = Path::new(file);
    let candidates: Vec<PathBuf> = if written.is_absolute() {
        vec![written.to_path_buf()]
    } else {
        std::iter::once(ctx.base_dir.join(written))
            .chain(ctx.asset_roots.iter().map(|r| r.join(written)))
            .collect()
    };
    let Some(canonical) = candidates.iter().find_map(|c| c.canonicalize().ok()) else {
        return Err(ShapeError::NotFound {
            file: file.to_string(),
            tried: candidates,
        });
    };
    let inside = std::iter::once(ctx.base_dir)
        .chain(ctx.asset_roots.iter().map(PathBuf::as_path))
        .filter_map(|root| root.canonicalize().ok())
        .any(|root| canonical.starts_with(&root));
    if !inside {
        return Err(ShapeError::PathEscape {
            file: file.to_string(),
            resolved: canonical,
            base: ctx.base_dir.to_path_buf(),
        });
    }
    if !canonical.is_file() {
        return Err(ShapeError::Io {
            path: canonical,
            message: "is not a regular file".into(),
        });
    }
    Ok(canonical)
}

fn read_bytes(path: &Path) -> Result<Vec<u8>, ShapeError> {
    let io = |e: std::io::Error| ShapeError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let len = std::fs::metadata(path).map_err(io)?.len();
    if len > MAX_FILE_BYTES {
        return Err(ShapeError::TooLarge {
            what: format!("mesh file '{}': bytes", path.display()),
            count: len,
            limit: MAX_FILE_BYTES,
        });
    }
    std::fs::read(path).map_err(io)
}

fn text_of<'a>(path: &Path, bytes: &'a [u8]) -> Result<&'a str, ShapeError> {
    std::str::from_utf8(bytes).map_err(|e| ShapeError::Parse {
        path: path.to_path_buf(),
        line: 0,
        message: format!("not UTF-8 text: {e}"),
    })
}

/// Loads a surface file: `.obj` (vertices `v x y z`, faces `f` with any number of corners, fan
/// triangulated; `i`, `i/t`, `i//n`, `i/t/n` forms and negative (relative) indices; other statements are
/// ignored) or `.stl` (binary when the size matches the triangle count in the header, ASCII otherwise;
/// exactly equal vertices are welded and triangles that collapse to a line or point are dropped).
/// Windings are kept as stored. The mesh is checked ([`SurfaceMesh::check`]).
pub fn load_surface_file(path: &Path) -> Result<SurfaceMesh, ShapeError> {
    if MeshFormat::from_path(path).is_none() {
        return Err(unknown_extension(path));
    }
    load_surface_bytes(path, &read_bytes(path)?)
}

/// [`load_surface_file`] on a file's bytes already in memory; `path` names the file in errors
/// and its extension gives the format.
pub fn load_surface_bytes(path: &Path, bytes: &[u8]) -> Result<SurfaceMesh, ShapeError> {
    let mesh =
        match MeshFormat::from_path(path) {
            Some(MeshFormat::Obj) => parse_obj(path, text_of(path, bytes)?)?,
            Some(MeshFormat::Stl) => parse_stl(path, bytes)?,
            Some(MeshFormat::Msh | MeshFormat::Medit) => return Err(ShapeError::Unsupported {
                shape: format!("mesh file '{}'", path.display()),
                reason:
                    "is a volume mesh; load it with load_volume_file (its boundary is its surface)"
                        .into(),
            }),
            None => return Err(unknown_extension(path)),
        };
    mesh.check()
        .map_err(|e| parse_error(path, 0, e.to_string()))?;
    Ok(mesh)
}

/// The surface of any supported mesh file: surface files as loaded, volume files as the compacted
/// boundary of their tetrahedra.
pub(super) fn load_any_surface(path: &Path) -> Result<SurfaceMesh, ShapeError> {
    match MeshFormat::from_path(path) {
        Some(MeshFormat::Msh | MeshFormat::Medit) => {
            Ok(load_volume_file(path)?.mesh.boundary_surface_compact().0)
        }
        _ => load_surface_file(path),
    }
}

fn unknown_extension(path: &Path) -> ShapeError {
    ShapeError::invalid(
        "file",
        path.display().to_string(),
        "must end in .obj or .stl (surfaces), .msh (gmsh 4.1 ASCII) or .mesh (medit volumes)",
    )
}

/// A tetrahedral mesh loaded from a file, with what the loader changed.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadedVolume {
    /// The mesh: only nodes used by tetrahedra (in file order), every tetrahedron positively oriented.
    pub mesh: VolumeMesh,
    /// Tetrahedra that were stored with negative orientation and were flipped.
    pub reoriented: usize,
    /// Nodes dropped because no tetrahedron uses them (e.g. mid-edge nodes of 10-node tetrahedra,
    /// surface-only nodes).
    pub dropped_nodes: usize,
    /// True if the file held 10-node (quadratic) tetrahedra, of which only the 4 corners were kept.
    pub quadratic_reduced: bool,
}

/// Loads a tetrahedral volume file: gmsh `.msh` version 4.1 ASCII (`$Nodes`; `$Elements` of type 4,
/// 4-node tetrahedra, or type 11, 10-node tetrahedra reduced to their corner nodes; other element types
/// such as boundary triangles are skipped) or medit `.mesh` (`Vertices`, `Tetrahedra`; other sections
/// skipped). Unused nodes are dropped and negatively oriented tetrahedra flipped (both reported in
/// [`LoadedVolume`]); degenerate tetrahedra are an error ([`VolumeMesh::check`]).
pub fn load_volume_file(path: &Path) -> Result<LoadedVolume, ShapeError> {
    match MeshFormat::from_path(path) {
        Some(MeshFormat::Msh | MeshFormat::Medit) => load_volume_bytes(path, &read_bytes(path)?),
        _ => load_volume_bytes(path, &[]),
    }
}

/// [`load_volume_file`] on a file's bytes already in memory; `path` names the file in errors
/// and its extension gives the format.
pub fn load_volume_bytes(path: &Path, bytes: &[u8]) -> Result<LoadedVolume, ShapeError> {
    let (nodes, tets, quadratic_reduced) = match MeshFormat::from_path(path) {
        Some(MeshFormat::Msh) => parse_msh(path, text_of(path, bytes)?)?,
        Some(MeshFormat::Medit) => parse_medit(path, text_of(path, bytes)?)?,
        Some(MeshFormat::Obj | MeshFormat::Stl) => {
            return Err(ShapeError::NotImplemented {
                what: format!(
                    "tetrahedral meshing of surface file '{}'; mesh it with gmsh or TetGen and load the .msh or \
                     .mesh file, or use the shape as a surface",
                    path.display()
                ),
            })
        }
        None => return Err(unknown_extension(path)),
    };
    if tets.is_empty() {
        return Err(parse_error(path, 0, "the file contains no tetrahedra"));
    }
    let total = nodes.len();
    let (mut mesh, _) = VolumeMesh { nodes, tets }.compacted();
    let reoriented = mesh.orient_positive();
    mesh.check()
        .map_err(|e| parse_error(path, 0, e.to_string()))?;
    Ok(LoadedVolume {
        dropped_nodes: total - mesh.nodes.len(),
        mesh,
        reoriented,
        quadratic_reduced,
    })
}
