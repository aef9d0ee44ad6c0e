//! Minimal mesh generators for tests and benchmarks (the engine provides the real ones).

use nalgebra::Vector3;

/// Kuhn (Freudenthal) split of an axis-aligned box `[origin, origin + size]` into
/// `cells[0] x cells[1] x cells[2]` hexahedra of 6 positively oriented tetrahedra each; all cells
/// share the diagonal direction, so the mesh is conforming. Returns `(nodes, tets)`; node
/// `(i, j, k)` has index `i + (nx + 1) (j + (ny + 1) k)`.
pub fn box_mesh(
    origin: Vector3<f64>,
    size: Vector3<f64>,
    cells: [usize; 3],
) -> (Vec<Vector3<f64>>, Vec<[u32; 4]>) {
    let [nx, ny, nz] = cells.map(|c| c.max(1));
    let idx = |i: usize, j: usize, k: usize| (i + (nx + 1) * (j + (ny + 1) * k)) as u32;
    let mut nodes = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                nodes.push(
                    origin
                        + Vector3::new(
                            size.x * i as f64 / nx as f64,
                            size.y * j as f64 / ny as f64,
                            size.z * k as f64 / nz as f64,
                        ),
                );
            }
        }
    }
    const PERMS: [[usize; 3]; 6] = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    let mut tets = Vec::with_capacity(6 * nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                for p in PERMS {
                    let mut c = [i, j, k];
                    let mut t = [idx(c[0], c[1], c[2]); 4];
                    for (s, &axis) in p.iter().enumerate() {
                        c[axis] += 1;
                        t[s + 1] = idx(c[0], c[1], c[2]);
                    }
                    let x = t.map(|v| nodes[v as usize]);
                    let vol = (x[1] - x[0]).cross(&(x[2] - x[0])).dot(&(x[3] - x[0]));
                    if vol < 0.0 {
                        t.swap(2, 3);
                    }
                    tets.push(t);
                }
            }
        }
    }
    (nodes, tets)
}

/// Applies `f` to every node (e.g. to distort a mesh for the patch test).
pub fn map_nodes(nodes: &mut [Vector3<f64>], f: impl Fn(&Vector3<f64>) -> Vector3<f64>) {
    for p in nodes.iter_mut() {
        *p = f(p);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_mesh_volume_and_orientation() {
        let (n, t) = box_mesh(Vector3::zeros(), Vector3::new(2.0, 1.0, 0.5), [3, 2, 2]);
        let mut vol = 0.0;
        for tet in &t {
            let x = tet.map(|v| n[v as usize]);
            let v = (x[1] - x[0]).cross(&(x[2] - x[0])).dot(&(x[3] - x[0])) / 6.0;
            assert!(v > 0.0);
            vol += v;
        }
        assert!((vol - 1.0).abs() < 1e-12);
        assert_eq!(t.len(), 6 * 12);
    }
}
