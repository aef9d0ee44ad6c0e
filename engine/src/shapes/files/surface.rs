//! Surface mesh parsers: Wavefront OBJ and STL (binary and ASCII, vertices welded).

use std::collections::HashMap;
use std::path::Path;

use nalgebra::Vector3;

use super::super::error::{check_count, ShapeError};
use super::super::mesh::SurfaceMesh;

use super::text::{floats, parse_error};

pub(super) fn parse_obj(path: &Path, text: &str) -> Result<SurfaceMesh, ShapeError> {
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

pub(super) fn parse_stl(path: &Path, bytes: &[u8]) -> Result<SurfaceMesh, ShapeError> {
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
