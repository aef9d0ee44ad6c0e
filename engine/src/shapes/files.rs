//! Mesh files: safe path resolution and loaders for OBJ and STL surfaces and gmsh `.msh` (4.1 ASCII) and
//! medit `.mesh` tetrahedral volumes.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use super::error::{check_count, ShapeError, MAX_ELEMENTS};
use super::mesh::{SurfaceMesh, VolumeMesh};
use super::ShapeContext;

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

fn read_text(path: &Path) -> Result<String, ShapeError> {
    String::from_utf8(read_bytes(path)?).map_err(|e| ShapeError::Parse {
        path: path.to_path_buf(),
        line: 0,
        message: format!("not UTF-8 text: {e}"),
    })
}

fn parse_error(path: &Path, line: usize, message: impl Into<String>) -> ShapeError {
    ShapeError::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// Loads a surface file: `.obj` (vertices `v x y z`, faces `f` with any number of corners, fan
/// triangulated; `i`, `i/t`, `i//n`, `i/t/n` forms and negative (relative) indices; other statements are
/// ignored) or `.stl` (binary when the size matches the triangle count in the header, ASCII otherwise;
/// exactly equal vertices are welded and triangles that collapse to a line or point are dropped).
/// Windings are kept as stored. The mesh is checked ([`SurfaceMesh::check`]).
pub fn load_surface_file(path: &Path) -> Result<SurfaceMesh, ShapeError> {
    let mesh =
        match MeshFormat::from_path(path) {
            Some(MeshFormat::Obj) => parse_obj(path, &read_text(path)?)?,
            Some(MeshFormat::Stl) => parse_stl(path, &read_bytes(path)?)?,
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
    let (nodes, tets, quadratic_reduced) = match MeshFormat::from_path(path) {
        Some(MeshFormat::Msh) => parse_msh(path, &read_text(path)?)?,
        Some(MeshFormat::Medit) => parse_medit(path, &read_text(path)?)?,
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

/// Parses `n` whitespace-separated floats from `tokens`, naming `what` in errors.
fn floats<'a>(
    path: &Path,
    line: usize,
    tokens: &mut impl Iterator<Item = &'a str>,
    what: &str,
) -> Result<Vector3<f64>, ShapeError> {
    let mut v = Vector3::zeros();
    for k in 0..3 {
        let tok = tokens.next().ok_or_else(|| {
            parse_error(
                path,
                line,
                format!("{what}: expected 3 coordinates, found {k}"),
            )
        })?;
        let x: f64 = tok
            .parse()
            .map_err(|_| parse_error(path, line, format!("{what}: '{tok}' is not a number")))?;
        if !x.is_finite() {
            return Err(parse_error(
                path,
                line,
                format!("{what}: coordinate {tok} is not finite"),
            ));
        }
        v[k] = x;
    }
    Ok(v)
}

fn parse_obj(path: &Path, text: &str) -> Result<SurfaceMesh, ShapeError> {
    let mut positions = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    let mut face_lines: Vec<usize> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let content = raw.split('#').next().unwrap_or("");
        let mut tokens = content.split_whitespace();
        match tokens.next() {
            Some("v") => {
                positions.push(floats(path, line, &mut tokens, "vertex")?);
                check_count("OBJ vertices", positions.len() as u64)?;
            }
            Some("f") => {
                let mut corners = Vec::new();
                for tok in tokens {
                    let index_text = tok.split('/').next().unwrap_or("");
                    let index: i64 = index_text.parse().map_err(|_| {
                        parse_error(
                            path,
                            line,
                            format!("face corner '{tok}': '{index_text}' is not a vertex index"),
                        )
                    })?;
                    let resolved = match index {
                        0 => {
                            return Err(parse_error(
                                path,
                                line,
                                "face corner index 0: OBJ indices start at 1",
                            ))
                        }
                        i if i > 0 => i - 1,
                        i => positions.len() as i64 + i,
                    };
                    if resolved < 0 || resolved >= i64::from(u32::MAX) {
                        return Err(parse_error(
                            path,
                            line,
                            format!(
                                "face corner '{tok}' refers before the first vertex ({} vertices so far)",
                                positions.len()
                            ),
                        ));
                    }
                    corners.push(resolved as u32);
                }
                if corners.len() < 3 {
                    return Err(parse_error(
                        path,
                        line,
                        format!("a face needs at least 3 corners, found {}", corners.len()),
                    ));
                }
                for k in 1..corners.len() - 1 {
                    triangles.push([corners[0], corners[k], corners[k + 1]]);
                    face_lines.push(line);
                }
                check_count("OBJ triangles", triangles.len() as u64)?;
            }
            _ => {}
        }
    }
    if triangles.is_empty() {
        return Err(parse_error(path, 0, "no faces ('f' lines) found"));
    }
    let n = positions.len();
    for (t, &line) in triangles.iter().zip(&face_lines) {
        if let Some(bad) = t.iter().find(|&&v| v as usize >= n) {
            return Err(parse_error(
                path,
                line,
                format!(
                    "face refers to vertex {} but the file has {n} vertices",
                    bad + 1
                ),
            ));
        }
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            return Err(parse_error(path, line, "face repeats a vertex"));
        }
    }
    Ok(SurfaceMesh {
        positions,
        triangles,
    })
}

/// Welds exactly equal points (with -0.0 and 0.0 treated as equal).
struct Welder {
    index: HashMap<[u64; 3], u32>,
    positions: Vec<Vector3<f64>>,
}

impl Welder {
    fn new() -> Self {
        Welder {
            index: HashMap::new(),
            positions: Vec::new(),
        }
    }

    fn add(&mut self, p: Vector3<f64>) -> u32 {
        let key = [p.x, p.y, p.z].map(|x| (x + 0.0).to_bits());
        let next = self.positions.len() as u32;
        let id = *self.index.entry(key).or_insert(next);
        if id == next {
            self.positions.push(p);
        }
        id
    }
}

fn parse_stl(path: &Path, bytes: &[u8]) -> Result<SurfaceMesh, ShapeError> {
    let declared = bytes
        .get(80..84)
        .map(|b| u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])));
    let is_binary = declared.is_some_and(|n| 84 + 50 * n == bytes.len() as u64);
    let mut welder = Welder::new();
    let mut triangles = Vec::new();
    let mut push = |corners: [Vector3<f64>; 3], triangles: &mut Vec<[u32; 3]>| {
        let t = corners.map(|p| welder.add(p));
        if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] {
            triangles.push(t);
        }
    };
    if is_binary {
        let n = declared.unwrap_or(0);
        check_count("STL triangles", n)?;
        for i in 0..n as usize {
            let rec = &bytes[84 + 50 * i..84 + 50 * (i + 1)];
            let mut corners = [Vector3::zeros(); 3];
            for (k, c) in corners.iter_mut().enumerate() {
                for d in 0..3 {
                    let o = 12 + 12 * k + 4 * d;
                    let x = f64::from(f32::from_le_bytes([
                        rec[o],
                        rec[o + 1],
                        rec[o + 2],
                        rec[o + 3],
                    ]));
                    if !x.is_finite() {
                        return Err(parse_error(
                            path,
                            0,
                            format!("binary STL triangle {i}: non-finite coordinate"),
                        ));
                    }
                    c[d] = x;
                }
            }
            push(corners, &mut triangles);
        }
    } else {
        let text = std::str::from_utf8(bytes).map_err(|_| {
            parse_error(
                path,
                0,
                format!(
                    "neither binary STL (size {} does not match 84 + 50 x the {} triangles in the header) nor ASCII STL",
                    bytes.len(),
                    declared.map_or("(missing)".to_string(), |n| n.to_string())
                ),
            )
        })?;
        if !text.trim_start().starts_with("solid") {
            return Err(parse_error(path, 1, "ASCII STL must start with 'solid'"));
        }
        let mut corners: Vec<Vector3<f64>> = Vec::with_capacity(3);
        let mut facet_line = 0;
        for (i, raw) in text.lines().enumerate() {
            let line = i + 1;
            let mut tokens = raw.split_whitespace();
            match tokens.next() {
                Some("facet") => {
                    corners.clear();
                    facet_line = line;
                }
                Some("vertex") => {
                    if corners.len() == 3 {
                        return Err(parse_error(path, line, "a facet has more than 3 vertices"));
                    }
                    corners.push(floats(path, line, &mut tokens, "vertex")?);
                }
                Some("endfacet") => {
                    let [a, b, c] = corners[..] else {
                        return Err(parse_error(
                            path,
                            line,
                            format!(
                                "the facet opened on line {facet_line} has {} vertices, expected 3",
                                corners.len()
                            ),
                        ));
                    };
                    push([a, b, c], &mut triangles);
                    corners.clear();
                    check_count("STL triangles", triangles.len() as u64)?;
                }
                Some("solid" | "outer" | "endloop" | "endsolid") | None => {}
                Some(other) => {
                    return Err(parse_error(
                        path,
                        line,
                        format!("unexpected '{other}' (expected facet, outer loop, vertex, endloop, endfacet)"),
                    ))
                }
            }
        }
    }
    if triangles.is_empty() {
        return Err(parse_error(path, 0, "no (non-degenerate) triangles found"));
    }
    Ok(SurfaceMesh {
        positions: welder.positions,
        triangles,
    })
}

/// Non-empty lines of a text with 1-based line numbers, for the line-structured gmsh format.
struct Lines<'a> {
    path: &'a Path,
    inner: std::iter::Enumerate<std::str::Lines<'a>>,
}

impl<'a> Lines<'a> {
    fn next_line(&mut self, what: &str) -> Result<(usize, &'a str), ShapeError> {
        for (i, l) in self.inner.by_ref() {
            let t = l.trim();
            if !t.is_empty() {
                return Ok((i + 1, t));
            }
        }
        Err(parse_error(
            self.path,
            0,
            format!("unexpected end of file while reading {what}"),
        ))
    }

    /// Reads a line of integers (at least `min` of them).
    fn ints(&mut self, what: &str, min: usize) -> Result<(usize, Vec<u64>), ShapeError> {
        let (line, text) = self.next_line(what)?;
        let values: Result<Vec<u64>, _> = text.split_whitespace().map(str::parse::<u64>).collect();
        match values {
            Ok(v) if v.len() >= min => Ok((line, v)),
            _ => Err(parse_error(
                self.path,
                line,
                format!("{what}: expected at least {min} non-negative integers, found '{text}'"),
            )),
        }
    }
}

type RawVolume = (Vec<Vector3<f64>>, Vec<[u32; 4]>, bool);

fn parse_msh(path: &Path, text: &str) -> Result<RawVolume, ShapeError> {
    let mut lines = Lines {
        path,
        inner: text.lines().enumerate(),
    };
    let mut nodes: Vec<Vector3<f64>> = Vec::new();
    let mut tag_to_index: HashMap<u64, u32> = HashMap::new();
    let mut raw_tets: Vec<([u64; 4], usize)> = Vec::new();
    let mut quadratic = false;
    let mut saw_format = false;
    while let Ok((line, header)) = lines.next_line("a section") {
        let Some(section) = header.strip_prefix('$') else {
            return Err(parse_error(
                path,
                line,
                format!("expected a section header like $Nodes, found '{header}'"),
            ));
        };
        match section {
            "MeshFormat" => {
                let (l, fmt) = lines.next_line("$MeshFormat")?;
                let parts: Vec<&str> = fmt.split_whitespace().collect();
                if parts.len() < 3 {
                    return Err(parse_error(
                        path,
                        l,
                        "expected 'version file-type data-size', e.g. '4.1 0 8'",
                    ));
                }
                if parts[0] != "4.1" {
                    return Err(ShapeError::NotImplemented {
                        what: format!(
                            "{}:{l}: gmsh MSH version {}; only 4.1 is read (export with `gmsh -format msh41`)",
                            path.display(),
                            parts[0]
                        ),
                    });
                }
                if parts[1] != "0" {
                    return Err(ShapeError::NotImplemented {
                        what: format!(
                            "{}:{l}: binary gmsh MSH; only ASCII is read (export with `-bin 0`)",
                            path.display()
                        ),
                    });
                }
                saw_format = true;
                expect_end(&mut lines, "MeshFormat")?;
            }
            "Nodes" => {
                let (l, head) = lines.ints("$Nodes header", 4)?;
                let (blocks, total) = (head[0], head[1]);
                check_count("gmsh nodes", total)
                    .map_err(|e| parse_error(path, l, e.to_string()))?;
                nodes.reserve(total as usize);
                for _ in 0..blocks {
                    let (l, b) = lines.ints("a $Nodes entity block header", 4)?;
                    let (parametric, count) = (b[2], b[3]);
                    if nodes.len() as u64 + count > total {
                        return Err(parse_error(
                            path,
                            l,
                            format!("blocks hold more nodes than the {total} declared"),
                        ));
                    }
                    let mut tags = Vec::with_capacity(count as usize);
                    for _ in 0..count {
                        let (l, t) = lines.ints("a node tag", 1)?;
                        if t.len() != 1 {
                            return Err(parse_error(path, l, "expected one node tag per line"));
                        }
                        tags.push((t[0], l));
                    }
                    for (tag, tag_line) in tags {
                        let (l, coords) = lines.next_line("node coordinates")?;
                        let mut tokens = coords.split_whitespace();
                        let p = floats(path, l, &mut tokens, "node")?;
                        if parametric != 0 && tokens.next().is_none() {
                            return Err(parse_error(
                                path,
                                l,
                                "parametric node without parametric coordinates",
                            ));
                        }
                        if tag_to_index.insert(tag, nodes.len() as u32).is_some() {
                            return Err(parse_error(
                                path,
                                tag_line,
                                format!("node tag {tag} is used twice"),
                            ));
                        }
                        nodes.push(p);
                    }
                }
                expect_end(&mut lines, "Nodes")?;
            }
            "Elements" => {
                let (l, head) = lines.ints("$Elements header", 4)?;
                let (blocks, total) = (head[0], head[1]);
                check_count("gmsh elements", total)
                    .map_err(|e| parse_error(path, l, e.to_string()))?;
                for _ in 0..blocks {
                    let (l, b) = lines.ints("an $Elements entity block header", 4)?;
                    let (kind, count) = (b[2], b[3]);
                    if count > total {
                        return Err(parse_error(
                            path,
                            l,
                            format!("block holds more than the {total} declared elements"),
                        ));
                    }
                    let per = match kind {
                        4 => Some(4),
                        11 => {
                            quadratic = true;
                            Some(10)
                        }
                        _ => None,
                    };
                    for _ in 0..count {
                        let (l, e) = lines.ints("an element", 1)?;
                        if let Some(per) = per {
                            if e.len() != per + 1 {
                                return Err(parse_error(
                                    path,
                                    l,
                                    format!(
                                        "element type {kind} needs a tag and {per} node tags, found {} numbers",
                                        e.len()
                                    ),
                                ));
                            }
                            raw_tets.push(([e[1], e[2], e[3], e[4]], l));
                        }
                    }
                }
                expect_end(&mut lines, "Elements")?;
            }
            other => {
                // Skip sections we do not need ($PhysicalNames, $Entities, $NodeData, ...).
                let end = format!("$End{other}");
                loop {
                    let (_, l) = lines.next_line(&end)?;
                    if l == end {
                        break;
                    }
                }
            }
        }
    }
    if !saw_format {
        return Err(parse_error(
            path,
            1,
            "missing $MeshFormat section: not a gmsh .msh file",
        ));
    }
    let mut tets = Vec::with_capacity(raw_tets.len());
    for (tags, line) in raw_tets {
        let mut t = [0u32; 4];
        for (k, tag) in tags.iter().enumerate() {
            t[k] = *tag_to_index.get(tag).ok_or_else(|| {
                parse_error(
                    path,
                    line,
                    format!("element refers to unknown node tag {tag}"),
                )
            })?;
        }
        tets.push(t);
    }
    Ok((nodes, tets, quadratic))
}

fn expect_end(lines: &mut Lines, section: &str) -> Result<(), ShapeError> {
    let end = format!("$End{section}");
    let (l, text) = lines.next_line(&end)?;
    if text == end {
        Ok(())
    } else {
        Err(parse_error(
            lines.path,
            l,
            format!("expected {end}, found '{text}'"),
        ))
    }
}

fn parse_medit(path: &Path, text: &str) -> Result<RawVolume, ShapeError> {
    // Tokens with line numbers; '#' starts a comment.
    let mut tokens = text.lines().enumerate().flat_map(|(i, l)| {
        l.split('#')
            .next()
            .unwrap_or("")
            .split_whitespace()
            .map(move |t| (i + 1, t))
    });
    let mut last_line = 1;
    let mut next = |what: &str| -> Result<(usize, &str), ShapeError> {
        match tokens.next() {
            Some((l, t)) => {
                last_line = l;
                Ok((l, t))
            }
            None => Err(parse_error(
                path,
                last_line,
                format!("unexpected end of file while reading {what}"),
            )),
        }
    };
    fn number<T: std::str::FromStr>(
        path: &Path,
        (l, t): (usize, &str),
        what: &str,
    ) -> Result<T, ShapeError> {
        t.parse()
            .map_err(|_| parse_error(path, l, format!("{what}: '{t}' is not a valid number")))
    }
    let mut nodes: Vec<Vector3<f64>> = Vec::new();
    let mut raw_tets: Vec<([u64; 4], usize)> = Vec::new();
    // End of input without `End` is accepted.
    while let Ok((line, keyword)) = next("a keyword") {
        match keyword {
            "End" => break,
            "MeshVersionFormatted" => {
                let _: u32 = number(path, next("the version")?, "MeshVersionFormatted")?;
            }
            "Dimension" => {
                let d: u32 = number(path, next("the dimension")?, "Dimension")?;
                if d != 3 {
                    return Err(parse_error(
                        path,
                        line,
                        format!("Dimension {d}: only 3-D meshes are supported"),
                    ));
                }
            }
            "Vertices" => {
                let n: u64 = number(path, next("the vertex count")?, "Vertices count")?;
                check_count("medit vertices", n)
                    .map_err(|e| parse_error(path, line, e.to_string()))?;
                for _ in 0..n {
                    let mut p = Vector3::zeros();
                    for k in 0..3 {
                        let tok = next("vertex coordinates")?;
                        let x: f64 = number(path, tok, "vertex coordinate")?;
                        if !x.is_finite() {
                            return Err(parse_error(
                                path,
                                tok.0,
                                format!("vertex coordinate {} is not finite", tok.1),
                            ));
                        }
                        p[k] = x;
                    }
                    let _: i64 = number(path, next("a vertex reference")?, "vertex reference")?;
                    nodes.push(p);
                }
            }
            "Tetrahedra" => {
                let n: u64 = number(path, next("the tetrahedron count")?, "Tetrahedra count")?;
                check_count("medit tetrahedra", n)
                    .map_err(|e| parse_error(path, line, e.to_string()))?;
                for _ in 0..n {
                    let mut t = [0u64; 4];
                    let mut first_line = 0;
                    for (k, slot) in t.iter_mut().enumerate() {
                        let tok = next("tetrahedron vertices")?;
                        if k == 0 {
                            first_line = tok.0;
                        }
                        *slot = number(path, tok, "tetrahedron vertex index")?;
                    }
                    let _: i64 = number(
                        path,
                        next("a tetrahedron reference")?,
                        "tetrahedron reference",
                    )?;
                    raw_tets.push((t, first_line));
                }
            }
            other => {
                let Some(per) = medit_entry_size(other) else {
                    return Err(parse_error(
                        path,
                        line,
                        format!("unknown medit keyword '{other}' (expected Vertices, Tetrahedra, Triangles, ..., End)"),
                    ));
                };
                let n: u64 = number(path, next("an entry count")?, other)?;
                let tokens_to_skip = n.saturating_mul(per);
                if tokens_to_skip > MAX_ELEMENTS.saturating_mul(10) {
                    return Err(parse_error(
                        path,
                        line,
                        format!("{other}: {n} entries is too many"),
                    ));
                }
                for _ in 0..tokens_to_skip {
                    next(other)?;
                }
            }
        }
    }
    let n = nodes.len() as u64;
    let mut tets = Vec::with_capacity(raw_tets.len());
    for (t, line) in raw_tets {
        if let Some(bad) = t.iter().find(|&&v| v == 0 || v > n) {
            return Err(parse_error(
                path,
                line,
                format!("tetrahedron refers to vertex {bad}; valid indices are 1..={n}"),
            ));
        }
        tets.push(t.map(|v| (v - 1) as u32));
    }
    Ok((nodes, tets, false))
}

/// Numbers per entry of the medit sections this loader skips.
fn medit_entry_size(keyword: &str) -> Option<u64> {
    Some(match keyword {
        "Corners" | "RequiredVertices" | "Ridges" | "RequiredEdges" | "RequiredTriangles" => 1,
        "NormalAtVertices" | "TangentAtVertices" => 2,
        "Edges" | "Normals" | "Tangents" => 3,
        "Triangles" => 4,
        "Quadrilaterals" => 5,
        "Prisms" => 7,
        "Hexahedra" => 9,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::super::ShapeDesc;
    use super::*;

    /// A fresh scratch directory under the system temp dir.
    fn temp_dir(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("modesuite-shapes-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// A unit cube as quads, the faces written with negative (relative) indices and `v/vt/vn` forms.
    const CUBE_OBJ: &str = "# unit cube\no cube\n\
        v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
        vt 0 0\nvn 0 0 1\n\
        f -8/1/1 -5/1/1 -6/1/1 -7/1/1\n\
        f 5//1 6//1 7//1 8//1\n\
        f 1 2 6 5\n\
        f 2/1 3/1 7/1 6/1\n\
        f 3 4 8 7\n\
        f 4 1 5 8\n";

    #[test]
    fn obj_quads_and_negative_indices() {
        let dir = temp_dir("obj");
        std::fs::write(dir.join("cube.obj"), CUBE_OBJ).unwrap();
        let ctx = ShapeContext::new(&dir);
        let s = ShapeDesc::mesh_file("cube.obj").surface(&ctx).unwrap();
        assert_eq!((s.positions.len(), s.triangles.len()), (8, 12));
        assert!(s.is_closed());
        println!(
            "OBJ cube: enclosed volume {} (expected 1, tol 1e-12)",
            s.enclosed_volume()
        );
        assert!((s.enclosed_volume() - 1.0).abs() < 1e-12);
        let err = ShapeDesc::mesh_file("cube.obj")
            .volume(&ctx)
            .unwrap_err()
            .to_string();
        println!("{err}");
        assert!(err.contains("not implemented"), "{err}");

        std::fs::write(dir.join("bad.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n").unwrap();
        let err = load_surface_file(&dir.join("bad.obj"))
            .unwrap_err()
            .to_string();
        println!("{err}");
        assert!(err.contains("bad.obj:4:"), "{err}");
        std::fs::write(
            dir.join("range.obj"),
            "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 9\n",
        )
        .unwrap();
        let err = load_surface_file(&dir.join("range.obj"))
            .unwrap_err()
            .to_string();
        println!("{err}");
        assert!(
            err.contains("range.obj:5:") && err.contains("vertex 9"),
            "{err}"
        );
        std::fs::write(dir.join("nan.obj"), "v 0 nan 0\n").unwrap();
        assert!(load_surface_file(&dir.join("nan.obj"))
            .unwrap_err()
            .to_string()
            .contains("nan.obj:1:"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    fn tet_corners() -> [[f32; 3]; 4] {
        [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ]
    }
    /// Outward faces of the corner tetrahedron.
    const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

    #[test]
    fn stl_binary_and_ascii_weld_vertices() {
        let dir = temp_dir("stl");
        let p = tet_corners();
        let mut bin = vec![0u8; 80];
        bin.extend_from_slice(&(FACES.len() as u32).to_le_bytes());
        for f in FACES {
            bin.extend_from_slice(&[0u8; 12]);
            for &v in &f {
                for x in p[v] {
                    bin.extend_from_slice(&x.to_le_bytes());
                }
            }
            bin.extend_from_slice(&[0u8; 2]);
        }
        // A binary file whose header starts with "solid" must still be read as binary.
        bin[..5].copy_from_slice(b"solid");
        std::fs::write(dir.join("tet.stl"), &bin).unwrap();
        let mut ascii = String::from("solid tet\n");
        for f in FACES {
            ascii.push_str("  facet normal 0 0 0\n    outer loop\n");
            for &v in &f {
                ascii.push_str(&format!(
                    "      vertex {} {} {}\n",
                    p[v][0], p[v][1], p[v][2]
                ));
            }
            ascii.push_str("    endloop\n  endfacet\n");
        }
        ascii.push_str("endsolid tet\n");
        std::fs::write(dir.join("tet_ascii.STL"), &ascii).unwrap();
        for file in ["tet.stl", "tet_ascii.STL"] {
            let s = load_surface_file(&dir.join(file)).unwrap();
            assert_eq!(
                (s.positions.len(), s.triangles.len()),
                (4, 4),
                "{file}: welded"
            );
            assert!(s.is_closed());
            assert!((s.enclosed_volume() - 1.0 / 6.0).abs() < 1e-12);
        }
        std::fs::write(
            dir.join("broken.stl"),
            "solid x\n facet normal 0 0 1\n outer loop\n vertex 0 0\n",
        )
        .unwrap();
        let err = load_surface_file(&dir.join("broken.stl"))
            .unwrap_err()
            .to_string();
        println!("{err}");
        assert!(err.contains("broken.stl:4:"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Two tetrahedra sharing a face (the second stored inverted), a boundary triangle element and an
    /// unused node.
    const MSH: &str = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n\
        $PhysicalNames\n1\n3 1 \"body\"\n$EndPhysicalNames\n\
        $Nodes\n2 6 1 6\n\
        0 1 0 1\n6\n0 0 0\n\
        3 1 0 5\n1\n2\n3\n4\n5\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n0 0 0\n\
        $EndNodes\n\
        $Elements\n2 3 1 3\n\
        2 1 2 1\n1 1 2 3\n\
        3 1 4 2\n2 5 1 2 3\n3 4 1 2 3\n\
        $EndElements\n";

    #[test]
    fn gmsh_msh41_tets_and_reorientation() {
        let dir = temp_dir("msh");
        std::fs::write(dir.join("two.msh"), MSH).unwrap();
        let loaded = load_volume_file(&dir.join("two.msh")).unwrap();
        println!(
            "msh: {} tets, {} nodes, reoriented {}, dropped {}",
            loaded.mesh.tets.len(),
            loaded.mesh.nodes.len(),
            loaded.reoriented,
            loaded.dropped_nodes
        );
        assert_eq!(loaded.mesh.tets.len(), 2);
        assert_eq!(loaded.mesh.nodes.len(), 5);
        assert_eq!((loaded.reoriented, loaded.dropped_nodes), (1, 1));
        assert!(!loaded.quadratic_reduced);
        assert_eq!(loaded.mesh.quality().inverted, 0);
        let s = ShapeDesc::mesh_file("two.msh")
            .surface(&ShapeContext::new(&dir))
            .unwrap();
        assert!(s.is_closed());
        assert_eq!(s.triangles.len(), 6);
        assert!((s.enclosed_volume() - loaded.mesh.volume()).abs() < 1e-12);

        // 10-node tetrahedra keep their corners.
        let tet10 = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 10 1 10\n3 1 0 10\n\
            1\n2\n3\n4\n5\n6\n7\n8\n9\n10\n\
            0 0 0\n1 0 0\n0 1 0\n0 0 1\n0.5 0 0\n0.5 0.5 0\n0 0.5 0\n0 0 0.5\n0 0.5 0.5\n0.5 0 0.5\n\
            $EndNodes\n$Elements\n1 1 1 1\n3 1 11 1\n1 1 2 3 4 5 6 7 8 10 9\n$EndElements\n";
        std::fs::write(dir.join("quad.msh"), tet10).unwrap();
        let loaded = load_volume_file(&dir.join("quad.msh")).unwrap();
        assert!(loaded.quadratic_reduced);
        assert_eq!(
            (
                loaded.mesh.nodes.len(),
                loaded.mesh.tets.len(),
                loaded.dropped_nodes
            ),
            (4, 1, 6)
        );

        std::fs::write(
            dir.join("old.msh"),
            "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n",
        )
        .unwrap();
        let err = load_volume_file(&dir.join("old.msh"))
            .unwrap_err()
            .to_string();
        println!("{err}");
        assert!(err.contains("2.2") && err.contains("4.1"), "{err}");
        let bad = MSH.replace("2 5 1 2 3", "2 5 1 2 77");
        std::fs::write(dir.join("bad.msh"), bad).unwrap();
        let err = load_volume_file(&dir.join("bad.msh"))
            .unwrap_err()
            .to_string();
        println!("{err}");
        assert!(err.contains("bad.msh:30:") && err.contains("77"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn medit_vertices_and_tetrahedra() {
        let dir = temp_dir("medit");
        let text = "MeshVersionFormatted 2\nDimension\n3\n# a comment\nVertices\n4\n\
            0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n\
            Triangles\n1\n1 2 3 7\n\
            Tetrahedra\n1\n1 2 3 4 0\nEnd\n";
        std::fs::write(dir.join("tet.mesh"), text).unwrap();
        let loaded = load_volume_file(&dir.join("tet.mesh")).unwrap();
        assert_eq!(
            (
                loaded.mesh.nodes.len(),
                loaded.mesh.tets.len(),
                loaded.reoriented
            ),
            (4, 1, 0)
        );
        assert!((loaded.mesh.volume() - 1.0 / 6.0).abs() < 1e-15);
        let v = ShapeDesc::mesh_file("tet.mesh")
            .volume(&ShapeContext::new(&dir))
            .unwrap();
        assert_eq!(v, loaded.mesh);
        let bad = text.replace("1 2 3 4 0", "1 2 3 5 0");
        std::fs::write(dir.join("bad.mesh"), bad).unwrap();
        let err = load_volume_file(&dir.join("bad.mesh"))
            .unwrap_err()
            .to_string();
        println!("{err}");
        assert!(
            err.contains("bad.mesh:16:") && err.contains("vertex 5"),
            "{err}"
        );
        let flat = text.replace("0 0 1 1\n", "0.5 0.5 0 1\n");
        std::fs::write(dir.join("flat.mesh"), flat).unwrap();
        let err = load_volume_file(&dir.join("flat.mesh"))
            .unwrap_err()
            .to_string();
        println!("{err}");
        assert!(err.contains("degenerate"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn truncated_and_corrupted_files_never_panic() {
        let dir = temp_dir("fuzz");
        let medit = "MeshVersionFormatted 2\nDimension 3\nVertices\n4\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n\
            Tetrahedra\n1\n1 2 3 4 0\nEnd\n";
        let mut stl = String::from("solid t\n");
        for f in FACES {
            stl.push_str("facet normal 0 0 0\nouter loop\n");
            for &v in &f {
                let p = tet_corners()[v];
                stl.push_str(&format!("vertex {} {} {}\n", p[0], p[1], p[2]));
            }
            stl.push_str("endloop\nendfacet\n");
        }
        let mut outcomes = [0usize; 2];
        for (name, text) in [
            ("f.obj", CUBE_OBJ),
            ("f.msh", MSH),
            ("f.mesh", medit),
            ("f.stl", stl.as_str()),
        ] {
            let path = dir.join(name);
            let bytes = text.as_bytes();
            for cut in (0..bytes.len()).step_by(3) {
                std::fs::write(&path, &bytes[..cut]).unwrap();
                let ok = if name.ends_with(".obj") || name.ends_with(".stl") {
                    load_surface_file(&path).is_ok()
                } else {
                    load_volume_file(&path).is_ok()
                };
                outcomes[usize::from(ok)] += 1;
                // Flip one byte too.
                let mut corrupt = bytes.to_vec();
                corrupt[cut] = corrupt[cut].wrapping_add(7);
                std::fs::write(&path, &corrupt).unwrap();
                let _ = load_any_surface(&path);
            }
        }
        println!(
            "truncated files: {} rejected, {} still valid",
            outcomes[0], outcomes[1]
        );
        assert!(outcomes[0] > 0);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn paths_are_confined_and_missing_files_named() {
        let root = temp_dir("paths");
        let scene = root.join("scenes").join("place");
        let assets = root.join("assets");
        std::fs::create_dir_all(&scene).unwrap();
        std::fs::create_dir_all(assets.join("meshes")).unwrap();
        std::fs::write(root.join("secret.obj"), CUBE_OBJ).unwrap();
        std::fs::write(assets.join("meshes").join("cube.obj"), CUBE_OBJ).unwrap();
        std::fs::write(scene.join("local.obj"), CUBE_OBJ).unwrap();
        let roots = [assets.clone()];
        let ctx = ShapeContext {
            base_dir: &scene,
            asset_roots: &roots,
            generators: None,
        };
        assert!(resolve_mesh_path(&ctx, "local.obj").is_ok());
        // Reaching an asset root through `..` is allowed, and so is a path relative to an asset root.
        assert!(resolve_mesh_path(&ctx, "../../assets/meshes/cube.obj").is_ok());
        assert!(resolve_mesh_path(&ctx, "meshes/cube.obj").is_ok());
        let err = resolve_mesh_path(&ctx, "../../secret.obj").unwrap_err();
        println!("{err}");
        assert!(matches!(err, ShapeError::PathEscape { .. }), "{err:?}");
        let abs = root.join("secret.obj");
        assert!(matches!(
            resolve_mesh_path(&ctx, abs.to_str().unwrap()),
            Err(ShapeError::PathEscape { .. })
        ));
        let err = ShapeDesc::mesh_file("../../../../../../../../etc/passwd.obj")
            .surface(&ctx)
            .unwrap_err();
        println!("{err}");
        let err = ShapeDesc::mesh_file("meshes/missing.obj")
            .surface(&ctx)
            .unwrap_err();
        println!("{err}");
        let text = err.to_string();
        assert!(
            text.contains("missing.obj") && text.contains(&scene.display().to_string()),
            "{text}"
        );
        assert!(text.contains(&assets.display().to_string()), "{text}");
        let _ = std::fs::remove_dir_all(&root);
    }
}
