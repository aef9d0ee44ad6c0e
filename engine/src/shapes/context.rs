//! What shape generation needs from its caller ([`ShapeContext`]: where files resolve, which
//! generators exist) and what a registered generator returns ([`GeneratedMesh`]).

use super::mesh::{SurfaceMesh, VolumeMesh};

/// What a caller asks a generator for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshKind {
    /// A triangle surface (rigid colliders, cloth sheets, rendering).
    Surface,
    /// A tetrahedral volume (finite-element bodies).
    Volume,
}

/// The mesh a registered generator returns.
#[derive(Clone, Debug, PartialEq)]
pub enum GeneratedMesh {
    /// A triangle surface.
    Surface(SurfaceMesh),
    /// A tetrahedral volume; its boundary is used when a surface was asked for.
    Volume(VolumeMesh),
}

/// Shape generators registered by plugins, looked up by name for
/// [`ShapeDesc::Gen`](super::ShapeDesc::Gen).
pub trait ShapeGenerators {
    /// Runs generator `name` with its parameters as raw RON text (the plugin parses them into its own
    /// type, e.g. with `ron::from_str`). `want` says which kind of mesh the caller needs; returning a
    /// volume when a surface is wanted is fine (its boundary is used), the reverse is an error.
    /// Return `Err` with a message naming the parameter and value at fault.
    fn generate(
        &self,
        name: &str,
        params_ron: &str,
        want: MeshKind,
    ) -> Result<GeneratedMesh, String>;

    /// The names of all registered generators (used in "unknown generator" messages).
    fn names(&self) -> Vec<String>;
}

/// Where mesh files and generators are looked up while generating a shape.
#[derive(Clone, Copy)]
pub struct ShapeContext<'a> {
    /// Directory that relative mesh paths are resolved against (the scene file's folder).
    pub base_dir: &'a std::path::Path,
    /// Extra roots a mesh path may resolve into; a path escaping `base_dir` and all roots is an error.
    pub asset_roots: &'a [std::path::PathBuf],
    /// Resolver for `Gen` shapes (registered generators); `None` makes every `Gen` shape an
    /// "unknown generator" error.
    pub generators: Option<&'a dyn ShapeGenerators>,
}

impl<'a> ShapeContext<'a> {
    /// A context resolving files against `base_dir` only, without generators.
    pub fn new(base_dir: &'a std::path::Path) -> Self {
        ShapeContext {
            base_dir,
            asset_roots: &[],
            generators: None,
        }
    }
}

impl std::fmt::Debug for ShapeContext<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ShapeContext")
            .field("base_dir", &self.base_dir)
            .field("asset_roots", &self.asset_roots)
            .field("generators", &self.generators.map(|g| g.names()))
            .finish()
    }
}
