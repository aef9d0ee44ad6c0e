//! Quadratic (10-node) tetrahedra built from a linear tet mesh.
//!
//! Node numbering of an element: the 4 corners (as in the input tet), then the 6 edge midpoints
//! in the order of [`TET10_EDGES`]. Shape functions in barycentric coordinates `L0..L3`:
//! corner `N_i = L_i (2 L_i - 1)`, edge `(i, j)`: `N = 4 L_i L_j` (Zienkiewicz & Taylor, The Finite
//! Element Method, vol. 1, sec. 8.8). Rest edges are straight, so the isoparametric map is affine
//! and the shape-function gradients are exact polynomials of degree 1.

use crate::error::FemError;
use nalgebra::{Matrix3, Vector3};

/// Local corner pairs of the 6 edge nodes of a 10-node tetrahedron.
pub const TET10_EDGES: [(usize, usize); 6] = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];

/// Barycentric coordinates of the 4-point, degree-2 Gauss rule on a tetrahedron (weights 1/4).
pub const QUAD_POINTS: [[f64; 4]; 4] = {
    const A: f64 = 0.585_410_196_624_968_5;
    const B: f64 = 0.138_196_601_125_010_5;
    [[A, B, B, B], [B, A, B, B], [B, B, A, B], [B, B, B, A]]
};

/// Number of quadrature points per element.
pub const NQ: usize = 4;

/// Values of the 10 shape functions at barycentric coordinates `l`.
#[inline]
pub fn shape_values(l: &[f64; 4]) -> [f64; 10] {
    let mut n = [0.0; 10];
    for i in 0..4 {
        n[i] = l[i] * (2.0 * l[i] - 1.0);
    }
    for (k, &(i, j)) in TET10_EDGES.iter().enumerate() {
        n[4 + k] = 4.0 * l[i] * l[j];
    }
    n
}

/// Rest-frame gradients of the 10 shape functions at barycentric coordinates `l`, given the
/// gradients of the barycentric coordinates `gl` (1/m).
#[inline]
pub fn shape_gradients(l: &[f64; 4], gl: &[Vector3<f64>; 4]) -> [Vector3<f64>; 10] {
    let mut g = [Vector3::zeros(); 10];
    for i in 0..4 {
        g[i] = gl[i] * (4.0 * l[i] - 1.0);
    }
    for (k, &(i, j)) in TET10_EDGES.iter().enumerate() {
        g[4 + k] = (gl[j] * l[i] + gl[i] * l[j]) * 4.0;
    }
    g
}

/// Gradients of the barycentric coordinates of a linear tet and its signed volume.
pub fn barycentric_gradients(x: &[Vector3<f64>; 4]) -> Option<([Vector3<f64>; 4], f64)> {
    let dm = Matrix3::from_columns(&[x[1] - x[0], x[2] - x[0], x[3] - x[0]]);
    let vol = dm.determinant() / 6.0;
    let inv = dm.try_inverse()?;
    let g1 = inv.row(0).transpose();
    let g2 = inv.row(1).transpose();
    let g3 = inv.row(2).transpose();
    Some(([-(g1 + g2 + g3), g1, g2, g3], vol))
}

/// A quadratic tetrahedral mesh: the input corners followed by one node per unique edge.
#[derive(Clone, Debug)]
pub struct QuadraticMesh {
    /// Rest positions of all nodes (corners first, then edge nodes), world frame (m). Length `n_nodes`.
    pub rest: Vec<Vector3<f64>>,
    /// Number of corner (input) nodes; corner `i` keeps index `i`.
    pub n_corners: usize,
    /// Node indices of each element, 4 corners then 6 edge nodes (see [`TET10_EDGES`]).
    pub elements: Vec<[u32; 10]>,
    /// Unique edges `(a, b)`, `a < b`, sorted; edge `k` has node index `n_corners + k`.
    pub edges: Vec<[u32; 2]>,
    /// Boundary faces of the corner mesh (each 3 corners, outward orientation).
    pub boundary_faces: Vec<[u32; 3]>,
}

impl QuadraticMesh {
    /// Builds the 10-node mesh from a positively oriented linear tet mesh. Validates indices,
    /// finiteness and volumes.
    pub fn from_linear(nodes: &[Vector3<f64>], tets: &[[u32; 4]]) -> Result<Self, FemError> {
        if nodes.is_empty() || tets.is_empty() {
            return Err(FemError::InvalidMesh(format!(
                "needs nodes and tets, got {} nodes and {} tets",
                nodes.len(),
                tets.len()
            )));
        }
        if let Some(i) = nodes.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(FemError::InvalidMesh(format!(
                "node {i} has a non-finite coordinate"
            )));
        }
        let mut max_edge: f64 = 0.0;
        for (t, tet) in tets.iter().enumerate() {
            for &v in tet {
                if v as usize >= nodes.len() {
                    return Err(FemError::InvalidMesh(format!(
                        "tet {t} references node {v}, but there are {} nodes",
                        nodes.len()
                    )));
                }
            }
            let x = tet.map(|v| nodes[v as usize]);
            for &(i, j) in TET10_EDGES.iter() {
                max_edge = max_edge.max((x[i] - x[j]).norm());
            }
        }
        for (t, tet) in tets.iter().enumerate() {
            let x = tet.map(|v| nodes[v as usize]);
            let vol = (x[1] - x[0]).cross(&(x[2] - x[0])).dot(&(x[3] - x[0])) / 6.0;
            // relative degeneracy threshold against the largest edge
            if vol.is_nan() || vol <= 1e-12 * max_edge.powi(3) {
                return Err(FemError::DegenerateElement {
                    tet: t,
                    volume: vol,
                });
            }
        }
        let mut edges: Vec<[u32; 2]> = Vec::with_capacity(tets.len() * 6);
        for tet in tets {
            for &(i, j) in TET10_EDGES.iter() {
                let (a, b) = (tet[i].min(tet[j]), tet[i].max(tet[j]));
                edges.push([a, b]);
            }
        }
        edges.sort_unstable();
        edges.dedup();
        let nc = nodes.len();
        let mut rest = nodes.to_vec();
        rest.extend(
            edges
                .iter()
                .map(|e| (nodes[e[0] as usize] + nodes[e[1] as usize]) * 0.5),
        );
        let elements = tets
            .iter()
            .map(|tet| {
                let mut el = [0u32; 10];
                el[..4].copy_from_slice(tet);
                for (k, &(i, j)) in TET10_EDGES.iter().enumerate() {
                    let key = [tet[i].min(tet[j]), tet[i].max(tet[j])];
                    let idx = edges.binary_search(&key).expect("edge was inserted above");
                    el[4 + k] = (nc + idx) as u32;
                }
                el
            })
            .collect();
        // boundary faces: faces that occur once (sorted keys, deterministic)
        let mut faces: Vec<([u32; 3], [u32; 3])> = Vec::with_capacity(tets.len() * 4);
        for tet in tets {
            // outward-oriented faces of a positively oriented tet
            for f in [
                [tet[1], tet[2], tet[3]],
                [tet[0], tet[3], tet[2]],
                [tet[0], tet[1], tet[3]],
                [tet[0], tet[2], tet[1]],
            ] {
                let mut key = f;
                key.sort_unstable();
                faces.push((key, f));
            }
        }
        faces.sort_unstable_by_key(|a| a.0);
        let mut boundary_faces = Vec::new();
        let mut i = 0;
        while i < faces.len() {
            let mut j = i + 1;
            while j < faces.len() && faces[j].0 == faces[i].0 {
                j += 1;
            }
            if j - i == 1 {
                boundary_faces.push(faces[i].1);
            }
            i = j;
        }
        Ok(QuadraticMesh {
            rest,
            n_corners: nc,
            elements,
            edges,
            boundary_faces,
        })
    }

    /// Node index of the edge node between corners `a` and `b`, if that edge exists.
    pub fn edge_node(&self, a: u32, b: u32) -> Option<u32> {
        let key = [a.min(b), a.max(b)];
        self.edges
            .binary_search(&key)
            .ok()
            .map(|k| (self.n_corners + k) as u32)
    }

    /// Sorted, unique indices of all nodes on the boundary (corners and edge nodes of boundary faces).
    pub fn boundary_nodes(&self) -> Vec<u32> {
        let mut out = Vec::new();
        for f in &self.boundary_faces {
            for k in 0..3 {
                out.push(f[k]);
                if let Some(e) = self.edge_node(f[k], f[(k + 1) % 3]) {
                    out.push(e);
                }
            }
        }
        out.sort_unstable();
        out.dedup();
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partition_of_unity_and_gradients() {
        let x = [
            Vector3::new(0.1, 0.0, 0.0),
            Vector3::new(1.0, 0.2, 0.0),
            Vector3::new(0.0, 1.0, 0.3),
            Vector3::new(0.2, 0.1, 1.0),
        ];
        let (gl, vol) = barycentric_gradients(&x).unwrap();
        assert!(vol > 0.0);
        for q in QUAD_POINTS.iter() {
            let n = shape_values(q);
            let g = shape_gradients(q, &gl);
            let s: f64 = n.iter().sum();
            let gs: Vector3<f64> = g.iter().sum();
            assert!((s - 1.0).abs() < 1e-14 && gs.norm() < 1e-12);
        }
    }
}
