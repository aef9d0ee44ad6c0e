//! Triangle surface meshes and tetrahedral volume meshes, with the measures the rest of the engine needs
//! (normals, areas, volumes, boundary extraction, element quality and validity checks).

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::error::ShapeError;

/// A tetrahedron counts as degenerate when `|volume| <= DEGENERATE_RELATIVE_VOLUME * l_max^3`, where
/// `l_max` is its longest edge.
///
/// A regular tetrahedron has `volume = l^3 / (6 sqrt 2) ~ 0.118 l^3`, so the threshold flags elements
/// that are flat to about one part in 10^9 of their size: far above round-off (about 1e-16) and far
/// below anything a finite-element solver can use.
pub const DEGENERATE_RELATIVE_VOLUME: f64 = 1e-10;

/// A triangle surface mesh.
///
/// Closed surfaces are wound counter-clockwise seen from outside (right-hand normals point outward);
/// open sheets (`Grid`, `Plane`) are wound so their normals point to +z in the shape frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SurfaceMesh {
    /// Vertex positions, metres, shape frame. Shape: `[n_vertices]`.
    pub positions: Vec<Vector3<f64>>,
    /// Triangles as indices into `positions`, counter-clockwise seen from the side the normal points to.
    pub triangles: Vec<[u32; 3]>,
}

impl SurfaceMesh {
    /// The three corners of triangle `t`, or `None` if one of its indices is out of range.
    fn corners(&self, t: &[u32; 3]) -> Option<[Vector3<f64>; 3]> {
        Some([
            *self.positions.get(t[0] as usize)?,
            *self.positions.get(t[1] as usize)?,
            *self.positions.get(t[2] as usize)?,
        ])
    }

    /// Area-weighted vertex normals (unit length; zero for vertices no triangle uses).
    ///
    /// Triangles with out-of-range indices are skipped (see [`SurfaceMesh::check`]).
    pub fn vertex_normals(&self) -> Vec<Vector3<f64>> {
        let mut normals = vec![Vector3::zeros(); self.positions.len()];
        for t in &self.triangles {
            if let Some([a, b, c]) = self.corners(t) {
                // The cross product's length is twice the area: this weights by area.
                let n = (b - a).cross(&(c - a));
                for &i in t {
                    normals[i as usize] += n;
                }
            }
        }
        for n in &mut normals {
            let len = n.norm();
            if len > 0.0 {
                *n /= len;
            }
        }
        normals
    }

    /// Total area of all triangles, square metres.
    pub fn area(&self) -> f64 {
        self.triangles
            .iter()
            .filter_map(|t| self.corners(t))
            .map(|[a, b, c]| 0.5 * (b - a).cross(&(c - a)).norm())
            .sum()
    }

    /// Volume enclosed by a closed, outward-wound surface (divergence theorem), cubic metres.
    ///
    /// Meaningful only when [`SurfaceMesh::is_closed`] holds; negative if the surface is wound inward.
    pub fn enclosed_volume(&self) -> f64 {
        self.triangles
            .iter()
            .filter_map(|t| self.corners(t))
            .map(|[a, b, c]| a.dot(&b.cross(&c)) / 6.0)
            .sum()
    }

    /// True if every edge is shared by exactly two triangles that traverse it in opposite directions
    /// (a closed, consistently oriented surface). An empty mesh is not closed.
    pub fn is_closed(&self) -> bool {
        if self.triangles.is_empty() {
            return false;
        }
        // Count each directed edge; a closed oriented manifold uses each directed edge once and its
        // reverse once.
        let mut directed: HashMap<(u32, u32), u32> =
            HashMap::with_capacity(self.triangles.len() * 3);
        for t in &self.triangles {
            for k in 0..3 {
                *directed.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        directed
            .iter()
            .all(|(&(a, b), &count)| count == 1 && directed.get(&(b, a)) == Some(&1))
    }

    /// Axis-aligned bounds `(min, max)` of the vertices, or `None` for a mesh without vertices.
    pub fn bounds(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        bounds_of(&self.positions)
    }

    /// A copy with every vertex mapped through `pose` (a rigid motion keeps the winding valid).
    pub fn transformed(&self, pose: &Isometry3<f64>) -> SurfaceMesh {
        SurfaceMesh {
            positions: transform_all(&self.positions, pose),
            triangles: self.triangles.clone(),
        }
    }

    /// Checks that every position is finite and every triangle has three distinct in-range indices.
    pub fn check(&self) -> Result<(), ShapeError> {
        check_points("surface mesh", &self.positions)?;
        let n = self.positions.len();
        for (i, t) in self.triangles.iter().enumerate() {
            if let Some(bad) = t.iter().find(|&&v| v as usize >= n) {
                return Err(bad_element(
                    "surface mesh",
                    i,
                    format!("referencing vertex {bad}, but the mesh has {n} vertices"),
                ));
            }
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                return Err(bad_element(
                    "surface mesh",
                    i,
                    format!("repeating a vertex: {t:?}"),
                ));
            }
        }
        Ok(())
    }

    /// A copy without vertices that no triangle uses, and the map from new vertex index to old.
    /// Out-of-range indices become `u32::MAX` (which [`SurfaceMesh::check`] reports).
    pub fn compacted(&self) -> (SurfaceMesh, Vec<u32>) {
        let (positions, new_to_old, old_to_new) =
            compact(&self.positions, self.triangles.iter().flatten());
        let triangles = self
            .triangles
            .iter()
            .map(|t| t.map(|v| remap(&old_to_new, v)))
            .collect();
        (
            SurfaceMesh {
                positions,
                triangles,
            },
            new_to_old,
        )
    }
}

/// A tetrahedral volume mesh.
///
/// Tetrahedra are positively oriented: `det[x1 - x0, x2 - x0, x3 - x0] > 0`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct VolumeMesh {
    /// Node positions, metres, shape frame. Shape: `[n_nodes]`.
    pub nodes: Vec<Vector3<f64>>,
    /// Tetrahedra as indices into `nodes`, positively oriented.
    pub tets: Vec<[u32; 4]>,
}

/// Element-quality figures of a [`VolumeMesh`], from [`VolumeMesh::quality`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeshQuality {
    /// Smallest dihedral angle over all non-degenerate tetrahedra, degrees (0 when there are none).
    pub min_dihedral_deg: f64,
    /// Largest dihedral angle over all non-degenerate tetrahedra, degrees (0 when there are none).
    pub max_dihedral_deg: f64,
    /// Smallest signed tetrahedron volume, cubic metres (0 when there are no tetrahedra).
    pub min_tet_volume: f64,
    /// Number of tetrahedra with negative volume that are not degenerate.
    pub inverted: usize,
    /// Number of degenerate tetrahedra: `|volume| <= DEGENERATE_RELATIVE_VOLUME * l_max^3`
    /// (see [`DEGENERATE_RELATIVE_VOLUME`]), or with an out-of-range or repeated node index.
    pub degenerate: usize,
    /// Number of tetrahedra.
    pub tets: usize,
    /// Number of nodes.
    pub nodes: usize,
}

/// How the triangular faces of a [`VolumeMesh`] are shared, from [`VolumeMesh::face_census`].
///
/// A conforming tetrahedral mesh has `overshared == 0`: every face is a boundary face (one tetrahedron)
/// or an interior face (two). A non-conforming mesh (hanging faces, mismatched quad diagonals) shows up
/// as extra boundary faces whose surface is not closed.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FaceCensus {
    /// Faces used by exactly one tetrahedron.
    pub boundary: usize,
    /// Faces used by exactly two tetrahedra.
    pub interior: usize,
    /// Faces used by three or more tetrahedra (always an error).
    pub overshared: usize,
}

/// The faces of a positively oriented tetrahedron `[0, 1, 2, 3]`, wound outward, each listed opposite
/// the vertex with the same position in this array.
const TET_FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

/// Signed volume of the tetrahedron `(a, b, c, d)`: `det[b - a, c - a, d - a] / 6`.
pub fn signed_tet_volume(
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
    d: &Vector3<f64>,
) -> f64 {
    (b - a).cross(&(c - a)).dot(&(d - a)) / 6.0
}

impl VolumeMesh {
    /// The four corners of tetrahedron `t`, or `None` if one of its indices is out of range.
    fn corners(&self, t: &[u32; 4]) -> Option<[Vector3<f64>; 4]> {
        Some([
            *self.nodes.get(t[0] as usize)?,
            *self.nodes.get(t[1] as usize)?,
            *self.nodes.get(t[2] as usize)?,
            *self.nodes.get(t[3] as usize)?,
        ])
    }

    /// Sum of the signed tetrahedron volumes, cubic metres (tetrahedra with bad indices count 0).
    pub fn volume(&self) -> f64 {
        self.tets
            .iter()
            .filter_map(|t| self.corners(t))
            .map(|[a, b, c, d]| signed_tet_volume(&a, &b, &c, &d))
            .sum()
    }

    /// Signed volume of tetrahedron `i`, cubic metres; `None` if `i` or one of its node indices is out of
    /// range.
    pub fn tet_volume(&self, i: usize) -> Option<f64> {
        let [a, b, c, d] = self.corners(self.tets.get(i)?)?;
        Some(signed_tet_volume(&a, &b, &c, &d))
    }

    /// Outward-wound boundary faces: the faces used by exactly one tetrahedron.
    ///
    /// Tetrahedra with out-of-range indices are skipped. The order is deterministic (tetrahedron order,
    /// then local face order).
    pub fn boundary_faces(&self) -> Vec<[u32; 3]> {
        let mut count: HashMap<[u32; 3], u32> = HashMap::with_capacity(self.tets.len() * 4);
        let n = self.nodes.len();
        let valid = |t: &&[u32; 4]| t.iter().all(|&v| (v as usize) < n);
        for t in self.tets.iter().filter(valid) {
            for f in TET_FACES {
                *count
                    .entry(sorted3([t[f[0]], t[f[1]], t[f[2]]]))
                    .or_insert(0) += 1;
            }
        }
        let mut faces = Vec::new();
        for t in self.tets.iter().filter(valid) {
            for f in TET_FACES {
                let face = [t[f[0]], t[f[1]], t[f[2]]];
                if count.get(&sorted3(face)) == Some(&1) {
                    faces.push(face);
                }
            }
        }
        faces
    }

    /// The boundary surface, wound outward, keeping node indexing: `positions` is a copy of `nodes`
    /// (interior nodes are present but unused). See [`VolumeMesh::boundary_surface_compact`] for a
    /// surface holding only the boundary nodes.
    pub fn boundary_surface(&self) -> SurfaceMesh {
        SurfaceMesh {
            positions: self.nodes.clone(),
            triangles: self.boundary_faces(),
        }
    }

    /// The boundary surface holding only boundary nodes, and the map from surface vertex index to node
    /// index (`map[surface_vertex] = node`).
    pub fn boundary_surface_compact(&self) -> (SurfaceMesh, Vec<u32>) {
        self.boundary_surface().compacted()
    }

    /// Counts boundary, interior and over-shared faces (see [`FaceCensus`]).
    pub fn face_census(&self) -> FaceCensus {
        let mut count: HashMap<[u32; 3], u32> = HashMap::with_capacity(self.tets.len() * 4);
        for t in &self.tets {
            for f in TET_FACES {
                *count
                    .entry(sorted3([t[f[0]], t[f[1]], t[f[2]]]))
                    .or_insert(0) += 1;
            }
        }
        let mut census = FaceCensus {
            boundary: 0,
            interior: 0,
            overshared: 0,
        };
        for c in count.values() {
            match c {
                1 => census.boundary += 1,
                2 => census.interior += 1,
                _ => census.overshared += 1,
            }
        }
        census
    }

    /// Element-quality figures: dihedral angle range, smallest volume, inverted and degenerate counts.
    pub fn quality(&self) -> MeshQuality {
        let mut q = MeshQuality {
            min_dihedral_deg: f64::INFINITY,
            max_dihedral_deg: f64::NEG_INFINITY,
            min_tet_volume: f64::INFINITY,
            inverted: 0,
            degenerate: 0,
            tets: self.tets.len(),
            nodes: self.nodes.len(),
        };
        for t in &self.tets {
            match classify(self, t) {
                TetClass::Bad(_) => q.degenerate += 1,
                TetClass::Degenerate { volume, .. } => {
                    q.degenerate += 1;
                    q.min_tet_volume = q.min_tet_volume.min(volume);
                }
                TetClass::Valid { volume, corners } => {
                    if volume < 0.0 {
                        q.inverted += 1;
                    }
                    q.min_tet_volume = q.min_tet_volume.min(volume);
                    let (lo, hi) = dihedral_range_deg(&corners);
                    q.min_dihedral_deg = q.min_dihedral_deg.min(lo);
                    q.max_dihedral_deg = q.max_dihedral_deg.max(hi);
                }
            }
        }
        if !q.min_dihedral_deg.is_finite() {
            q.min_dihedral_deg = 0.0;
            q.max_dihedral_deg = 0.0;
        }
        if !q.min_tet_volume.is_finite() {
            q.min_tet_volume = 0.0;
        }
        q
    }

    /// Checks the mesh is usable by a finite-element solver: at least one tetrahedron, finite nodes,
    /// in-range distinct indices, no inverted and no degenerate tetrahedron. The error names the first
    /// bad tetrahedron and its measured volume.
    pub fn check(&self) -> Result<(), ShapeError> {
        const WHAT: &str = "volume mesh";
        if self.tets.is_empty() {
            return Err(ShapeError::BadElement {
                mesh: WHAT.into(),
                index: 0,
                problem: "missing: the mesh has no tetrahedra".into(),
            });
        }
        check_points(WHAT, &self.nodes)?;
        for (i, t) in self.tets.iter().enumerate() {
            match classify(self, t) {
                TetClass::Bad(why) => return Err(bad_element(WHAT, i, why)),
                TetClass::Degenerate { volume, l_max } => {
                    return Err(bad_element(
                        WHAT,
                        i,
                        format!(
                            "degenerate: nodes {t:?}, volume {volume:e} m^3 <= {DEGENERATE_RELATIVE_VOLUME:e} * \
                             longest edge^3 ({l_max:e} m)"
                        ),
                    ))
                }
                TetClass::Valid { volume, .. } if volume < 0.0 => {
                    return Err(bad_element(
                        WHAT,
                        i,
                        format!("inverted: nodes {t:?}, volume {volume:e} m^3 < 0"),
                    ))
                }
                TetClass::Valid { .. } => {}
            }
        }
        Ok(())
    }

    /// Flips every inverted (negative-volume, non-degenerate) tetrahedron by swapping its last two nodes,
    /// and returns how many were flipped.
    pub fn orient_positive(&mut self) -> usize {
        let mut flipped = 0;
        for i in 0..self.tets.len() {
            if let TetClass::Valid { volume, .. } = classify(self, &self.tets[i]) {
                if volume < 0.0 {
                    self.tets[i].swap(2, 3);
                    flipped += 1;
                }
            }
        }
        flipped
    }

    /// A copy without nodes that no tetrahedron uses, and the map from new node index to old.
    /// Out-of-range indices become `u32::MAX` (which [`VolumeMesh::check`] reports).
    pub fn compacted(&self) -> (VolumeMesh, Vec<u32>) {
        let (nodes, new_to_old, old_to_new) = compact(&self.nodes, self.tets.iter().flatten());
        let tets = self
            .tets
            .iter()
            .map(|t| t.map(|v| remap(&old_to_new, v)))
            .collect();
        (VolumeMesh { nodes, tets }, new_to_old)
    }

    /// Axis-aligned bounds `(min, max)` of the nodes, or `None` for a mesh without nodes.
    pub fn bounds(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        bounds_of(&self.nodes)
    }

    /// A copy with every node mapped through `pose` (a rigid motion keeps orientations positive).
    pub fn transformed(&self, pose: &Isometry3<f64>) -> VolumeMesh {
        VolumeMesh {
            nodes: transform_all(&self.nodes, pose),
            tets: self.tets.clone(),
        }
    }
}

/// What [`classify`] found out about one tetrahedron.
enum TetClass {
    /// Out-of-range or repeated index (reason).
    Bad(String),
    /// Volume below the relative threshold.
    Degenerate { volume: f64, l_max: f64 },
    /// Usable geometry (volume may be negative: inverted).
    Valid {
        volume: f64,
        corners: [Vector3<f64>; 4],
    },
}

fn classify(mesh: &VolumeMesh, t: &[u32; 4]) -> TetClass {
    let n = mesh.nodes.len();
    if let Some(bad) = t.iter().find(|&&v| v as usize >= n) {
        return TetClass::Bad(format!(
            "referencing node {bad}, but the mesh has {n} nodes"
        ));
    }
    for a in 0..4 {
        for b in a + 1..4 {
            if t[a] == t[b] {
                return TetClass::Bad(format!("degenerate: it repeats a node: {t:?}"));
            }
        }
    }
    let Some(c) = mesh.corners(t) else {
        return TetClass::Bad(format!("referencing a node outside the {n} nodes"));
    };
    let volume = signed_tet_volume(&c[0], &c[1], &c[2], &c[3]);
    let mut l_max: f64 = 0.0;
    for a in 0..4 {
        for b in a + 1..4 {
            l_max = l_max.max((c[a] - c[b]).norm());
        }
    }
    if volume.is_nan() || volume.abs() <= DEGENERATE_RELATIVE_VOLUME * l_max.powi(3) {
        return TetClass::Degenerate { volume, l_max };
    }
    TetClass::Valid { volume, corners: c }
}

/// Smallest and largest of the six dihedral angles of a tetrahedron, degrees.
pub fn dihedral_range_deg(c: &[Vector3<f64>; 4]) -> (f64, f64) {
    // Face normals (outward for a positive tet; the angles do not depend on the sign).
    let normals: Vec<Vector3<f64>> = TET_FACES
        .iter()
        .map(|f| (c[f[1]] - c[f[0]]).cross(&(c[f[2]] - c[f[0]])))
        .collect();
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for k in 0..4 {
        for l in k + 1..4 {
            // The edge shared by the faces opposite k and l; its dihedral angle is pi minus the angle
            // between the outward normals.
            let denom = normals[k].norm() * normals[l].norm();
            if denom <= 0.0 {
                continue;
            }
            let cos = (normals[k].dot(&normals[l]) / denom).clamp(-1.0, 1.0);
            let angle = 180.0 - cos.acos().to_degrees();
            lo = lo.min(angle);
            hi = hi.max(angle);
        }
    }
    (lo, hi)
}

fn sorted3(mut f: [u32; 3]) -> [u32; 3] {
    f.sort_unstable();
    f
}

fn bad_element(mesh: &str, index: usize, problem: String) -> ShapeError {
    ShapeError::BadElement {
        mesh: mesh.to_string(),
        index,
        problem,
    }
}

fn check_points(what: &str, points: &[Vector3<f64>]) -> Result<(), ShapeError> {
    match points.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
        Some(i) => Err(ShapeError::invalid(
            format!("{what}: position[{i}]"),
            points[i],
            "must have finite coordinates",
        )),
        None => Ok(()),
    }
}

fn bounds_of(points: &[Vector3<f64>]) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let first = *points.first()?;
    Some(
        points
            .iter()
            .fold((first, first), |(lo, hi), p| (lo.inf(p), hi.sup(p))),
    )
}

fn transform_all(points: &[Vector3<f64>], pose: &Isometry3<f64>) -> Vec<Vector3<f64>> {
    points
        .iter()
        .map(|p| pose.transform_point(&Point3::from(*p)).coords)
        .collect()
}

/// The new index of old index `v`; out-of-range indices become `u32::MAX` (still invalid, so
/// `check` reports them instead of this function panicking).
fn remap(old_to_new: &[u32], v: u32) -> u32 {
    old_to_new.get(v as usize).copied().unwrap_or(u32::MAX)
}

/// Keeps the points referenced by `used` (in first-use order of index value), returning the kept points,
/// the new-to-old map and an old-to-new map (`u32::MAX` for dropped points).
fn compact<'a>(
    points: &[Vector3<f64>],
    used: impl Iterator<Item = &'a u32>,
) -> (Vec<Vector3<f64>>, Vec<u32>, Vec<u32>) {
    let mut keep = vec![false; points.len()];
    for &v in used {
        if let Some(k) = keep.get_mut(v as usize) {
            *k = true;
        }
    }
    let mut old_to_new = vec![u32::MAX; points.len()];
    let mut new_to_old = Vec::new();
    let mut kept = Vec::new();
    for (i, p) in points.iter().enumerate() {
        if keep[i] {
            old_to_new[i] = new_to_old.len() as u32;
            new_to_old.push(i as u32);
            kept.push(*p);
        }
    }
    (kept, new_to_old, old_to_new)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_tet() -> VolumeMesh {
        VolumeMesh {
            nodes: vec![
                Vector3::new(0.0, 0.0, 0.0),
                Vector3::new(1.0, 0.0, 0.0),
                Vector3::new(0.0, 1.0, 0.0),
                Vector3::new(0.0, 0.0, 1.0),
            ],
            tets: vec![[0, 1, 2, 3]],
        }
    }

    #[test]
    fn unit_tet_measures() {
        let m = unit_tet();
        assert!((m.volume() - 1.0 / 6.0).abs() < 1e-15);
        let s = m.boundary_surface();
        assert_eq!(s.triangles.len(), 4);
        assert!(s.is_closed());
        assert!((s.enclosed_volume() - m.volume()).abs() < 1e-15);
        let q = m.quality();
        // Corner tet: three 90 degree dihedral angles at the origin, 54.7356 at the slanted face.
        println!(
            "unit tet dihedral range {:.4}..{:.4} deg",
            q.min_dihedral_deg, q.max_dihedral_deg
        );
        assert!((q.max_dihedral_deg - 90.0).abs() < 1e-9);
        assert!((q.min_dihedral_deg - (1.0f64 / 3.0f64.sqrt()).acos().to_degrees()).abs() < 1e-9);
        m.check().unwrap();
        let census = m.face_census();
        assert_eq!(
            census,
            FaceCensus {
                boundary: 4,
                interior: 0,
                overshared: 0
            }
        );
    }

    #[test]
    fn inverted_and_degenerate_are_reported() {
        let mut m = unit_tet();
        m.tets[0].swap(0, 1);
        let err = m.check().unwrap_err().to_string();
        println!("{err}");
        assert!(err.contains("element 0 is inverted"), "{err}");
        assert_eq!(m.quality().inverted, 1);
        assert_eq!(m.orient_positive(), 1);
        m.check().unwrap();

        let mut flat = unit_tet();
        flat.nodes[3] = Vector3::new(0.3, 0.3, 0.0);
        let err = flat.check().unwrap_err().to_string();
        println!("{err}");
        assert!(err.contains("degenerate"), "{err}");
        assert_eq!(flat.quality().degenerate, 1);

        let mut bad_index = unit_tet();
        bad_index.tets[0][2] = 9;
        assert!(bad_index
            .check()
            .unwrap_err()
            .to_string()
            .contains("node 9"));
        assert_eq!(bad_index.volume(), 0.0);
        assert_eq!(bad_index.tet_volume(0), None);
        assert!(VolumeMesh::default().check().is_err());
    }

    #[test]
    fn transform_keeps_volume_and_compaction_maps() {
        let m = unit_tet();
        let pose = Isometry3::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(0.3, -0.2, 1.1));
        let t = m.transformed(&pose);
        assert!((t.volume() - m.volume()).abs() < 1e-14);
        let (lo, hi) = t.bounds().unwrap();
        assert!(lo.iter().zip(hi.iter()).all(|(a, b)| a < b));
        let mut with_orphan = m.clone();
        with_orphan.nodes.insert(0, Vector3::new(5.0, 5.0, 5.0));
        for t in &mut with_orphan.tets {
            for v in t.iter_mut() {
                *v += 1;
            }
        }
        let (c, map) = with_orphan.compacted();
        assert_eq!(map, vec![1, 2, 3, 4]);
        assert_eq!(c, m);
        let (s, smap) = with_orphan.boundary_surface_compact();
        assert_eq!(s.positions.len(), 4);
        assert_eq!(smap, vec![1, 2, 3, 4]);
        assert!(s.is_closed());
        let normals = s.vertex_normals();
        assert!(normals.iter().all(|n| (n.norm() - 1.0).abs() < 1e-12));
        assert!((s.area() - (1.5 + 3f64.sqrt() / 2.0)).abs() < 1e-12);
    }
}
