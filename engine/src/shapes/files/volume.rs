//! Tetrahedral volume parsers: gmsh `.msh` (4.1 ASCII) and medit `.mesh`.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::Vector3;

use super::super::error::{check_count, ShapeError, MAX_ELEMENTS};

use super::text::{floats, parse_error};

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

pub(super) fn parse_msh(path: &Path, text: &str) -> Result<RawVolume, ShapeError> {
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

pub(super) fn parse_medit(path: &Path, text: &str) -> Result<RawVolume, ShapeError> {
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
