//! Triangle-sheet generation and the topology derived from a triangle surface (edges, bending
//! hinges, constraint colouring).

use crate::error::PbdError;
use nalgebra::Vector3;

/// A rectangular grid sheet in a plane `z = const`, triangulated with alternating diagonals
/// (the same layout as the peer benchmark's `cloth_grid`).
#[derive(Debug, Clone, PartialEq)]
pub struct GridSheet {
    /// Particles along x.
    pub nx: usize,
    /// Particles along y.
    pub ny: usize,
    /// Particle positions, `nx * ny`, world frame, m; particle `(i, j)` (i along x, j along y) is
    /// `j * nx + i`.
    pub positions: Vec<Vector3<f64>>,
    /// Triangles, counter-clockwise seen from +z, `2 (nx-1)(ny-1)`.
    pub triangles: Vec<[u32; 3]>,
}

impl GridSheet {
    /// A `width` x `height` sheet (m, along x and y) with `nx` x `ny` particles whose corner of
    /// smallest x and y is at `origin`.
    pub fn new(
        width: f64,
        height: f64,
        nx: usize,
        ny: usize,
        origin: Vector3<f64>,
    ) -> Result<Self, PbdError> {
        crate::error::check_param("grid.width", width, 0.0, true, "a finite value > 0 m")?;
        crate::error::check_param("grid.height", height, 0.0, true, "a finite value > 0 m")?;
        if nx < 2 || ny < 2 || nx * ny > u32::MAX as usize / 2 {
            return Err(PbdError::InvalidParameter {
                field: "grid.nx/ny",
                value: format!("{nx} x {ny}"),
                expected: "at least 2 particles along each side",
            });
        }
        if !(origin.x.is_finite() && origin.y.is_finite() && origin.z.is_finite()) {
            return Err(PbdError::InvalidParameter {
                field: "grid.origin",
                value: format!("{origin:?}"),
                expected: "finite coordinates",
            });
        }
        let dx = width / (nx - 1) as f64;
        let dy = height / (ny - 1) as f64;
        let mut positions = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                positions.push(origin + Vector3::new(i as f64 * dx, j as f64 * dy, 0.0));
            }
        }
        let idx = |i: usize, j: usize| (j * nx + i) as u32;
        let mut triangles = Vec::with_capacity(2 * (nx - 1) * (ny - 1));
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i, j + 1), idx(i + 1, j + 1));
                if (i + j) % 2 == 0 {
                    triangles.push([a, b, d]);
                    triangles.push([a, d, c]);
                } else {
                    triangles.push([a, b, c]);
                    triangles.push([b, d, c]);
                }
            }
        }
        Ok(GridSheet {
            nx,
            ny,
            positions,
            triangles,
        })
    }

    /// Index of particle `(i, j)`, i along x, j along y.
    pub fn index(&self, i: usize, j: usize) -> u32 {
        (j * self.nx + i) as u32
    }

    /// A uniform `mu` x `mv` sub-grid of particle indices (corners included), row-major along x;
    /// for tracked-point observations.
    pub fn uniform_subset(&self, mu: usize, mv: usize) -> Vec<u32> {
        let pick = |k: usize, m: usize, n: usize| -> usize {
            if m <= 1 {
                0
            } else {
                ((k as f64) * ((n - 1) as f64) / ((m - 1) as f64)).round() as usize
            }
        };
        let mut out = Vec::with_capacity(mu * mv);
        for b in 0..mv {
            for a in 0..mu {
                out.push(self.index(pick(a, mu, self.nx), pick(b, mv, self.ny)));
            }
        }
        out
    }
}

/// Folds a flat sheet lying in a plane `z = const` onto itself about the line `x = at`: points
/// with `x <= at` stay, the next `pi * radius` of material (measured along x) wraps around a
/// half-cylinder of radius `radius` whose axis is parallel to y, and the rest lies on top, `2 *
/// radius` higher, running back towards -x. Lengths along the sheet are kept (an isometry), so the
/// folded shape is at rest for the stretch constraints. `radius` must be > 0.
pub fn fold_positions(positions: &[Vector3<f64>], at: f64, radius: f64) -> Vec<Vector3<f64>> {
    let arc = std::f64::consts::PI * radius;
    positions
        .iter()
        .map(|p| {
            let u = p.x - at;
            if u <= 0.0 {
                *p
            } else if u <= arc {
                let phi = u / radius;
                Vector3::new(
                    at + radius * phi.sin(),
                    p.y,
                    p.z + radius * (1.0 - phi.cos()),
                )
            } else {
                Vector3::new(at - (u - arc), p.y, p.z + 2.0 * radius)
            }
        })
        .collect()
}

/// Edge of the triangle mesh with its adjacent data.
#[derive(Debug, Clone)]
pub(crate) struct MeshEdge {
    /// Endpoints, `v[0] < v[1]`.
    pub v: [u32; 2],
    /// Opposite vertices of the (up to two) adjacent triangles; `u32::MAX` when absent.
    pub opp: [u32; 2],
    /// Sum of the adjacent triangles' rest areas, m^2.
    pub area: f64,
    /// Largest rest angle opposite this edge in an adjacent triangle, rad.
    pub max_opposite_angle: f64,
}

/// Unique edges of a triangle list, sorted by endpoints (deterministic).
pub(crate) fn mesh_edges(rest: &[Vector3<f64>], tris: &[[u32; 3]]) -> Vec<MeshEdge> {
    let mut half: Vec<(u32, u32, u32, usize)> = Vec::with_capacity(tris.len() * 3);
    for (t, tri) in tris.iter().enumerate() {
        for k in 0..3 {
            let a = tri[k];
            let b = tri[(k + 1) % 3];
            let c = tri[(k + 2) % 3];
            half.push((a.min(b), a.max(b), c, t));
        }
    }
    half.sort_unstable();
    let mut edges: Vec<MeshEdge> = Vec::new();
    for (a, b, c, t) in half {
        let tri = tris[t];
        let area = triangle_area(rest, tri);
        let (pa, pb, pc) = (rest[a as usize], rest[b as usize], rest[c as usize]);
        let ang = angle(pa - pc, pb - pc);
        match edges.last_mut() {
            Some(e) if e.v == [a, b] => {
                if e.opp[1] == u32::MAX {
                    e.opp[1] = c;
                }
                e.area += area;
                e.max_opposite_angle = e.max_opposite_angle.max(ang);
            }
            _ => edges.push(MeshEdge {
                v: [a, b],
                opp: [c, u32::MAX],
                area,
                max_opposite_angle: ang,
            }),
        }
    }
    edges
}

/// Rest area of a triangle, m^2.
pub(crate) fn triangle_area(p: &[Vector3<f64>], t: [u32; 3]) -> f64 {
    let (a, b, c) = (p[t[0] as usize], p[t[1] as usize], p[t[2] as usize]);
    0.5 * (b - a).cross(&(c - a)).norm()
}

fn angle(u: Vector3<f64>, v: Vector3<f64>) -> f64 {
    u.cross(&v).norm().atan2(u.dot(&v))
}

fn cot(u: Vector3<f64>, v: Vector3<f64>) -> f64 {
    u.dot(&v) / u.cross(&v).norm()
}

/// Coefficients `K` of the isometric bending model (Bergou, Wardetzky, Harmon, Zorin, Grinspun,
/// "A quadratic bending model for inextensible surfaces", SGP 2006) for the hinge with edge
/// `x0 x1` and opposite vertices `x2` (triangle x0 x1 x2) and `x3` (triangle x0 x1 x3):
/// `sum_i K_i x_i` is the discrete mean-curvature vector of the hinge; it vanishes for any flat
/// (rigidly moved) configuration and the bending energy is `(3 / (2 A)) k_b |sum_i K_i x_i|^2`.
pub(crate) fn isometric_bending_coefficients(x: [Vector3<f64>; 4]) -> [f64; 4] {
    let e0 = x[1] - x[0];
    let e1 = x[2] - x[0];
    let e2 = x[3] - x[0];
    let e3 = x[2] - x[1];
    let e4 = x[3] - x[1];
    let c01 = cot(e0, e1);
    let c02 = cot(e0, e2);
    let c03 = cot(-e0, e3);
    let c04 = cot(-e0, e4);
    [c03 + c04, c01 + c02, -c01 - c03, -c02 - c04]
}

/// Greedy colouring of constraints given by their particle lists: no two constraints of one
/// colour share a particle. Returns the colour per constraint (deterministic: input order).
pub(crate) fn greedy_colouring(n_particles: usize, constraints: &[&[u32]]) -> Vec<u32> {
    // used[p] = bitmask of colours touching particle p (spills to a slow path beyond 64 colours)
    let mut used: Vec<u64> = vec![0; n_particles];
    let mut extra: Vec<Vec<u32>> = vec![Vec::new(); n_particles];
    let mut colour = Vec::with_capacity(constraints.len());
    for c in constraints {
        let mut mask = 0u64;
        for &p in c.iter() {
            mask |= used[p as usize];
        }
        let col = if mask != u64::MAX {
            (!mask).trailing_zeros()
        } else {
            let mut k = 64u32;
            while c.iter().any(|&p| extra[p as usize].contains(&k)) {
                k += 1;
            }
            k
        };
        for &p in c.iter() {
            if col < 64 {
                used[p as usize] |= 1u64 << col;
            } else {
                extra[p as usize].push(col);
            }
        }
        colour.push(col);
    }
    colour
}

/// Checks a triangle list against `n` particles: indices in range, no repeated vertex, no
/// zero-area triangle.
pub(crate) fn validate_triangles(rest: &[Vector3<f64>], tris: &[[u32; 3]]) -> Result<(), PbdError> {
    for (t, tri) in tris.iter().enumerate() {
        for &v in tri {
            if v as usize >= rest.len() {
                return Err(PbdError::InvalidMesh(format!(
                    "triangle {t} = {tri:?} refers to particle {v}, but there are only {} particles",
                    rest.len()
                )));
            }
        }
        if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
            return Err(PbdError::InvalidMesh(format!(
                "triangle {t} = {tri:?} repeats a vertex"
            )));
        }
        let a = triangle_area(rest, *tri);
        let scale = (rest[tri[1] as usize] - rest[tri[0] as usize]).norm_squared()
            + (rest[tri[2] as usize] - rest[tri[0] as usize]).norm_squared();
        if !a.is_finite() || a <= 1e-12 * scale {
            return Err(PbdError::InvalidMesh(format!(
                "triangle {t} = {tri:?} is degenerate (rest area {a:e} m^2)"
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_counts_and_edges() {
        let g = GridSheet::new(1.0, 1.0, 40, 40, Vector3::zeros()).unwrap();
        assert_eq!(g.positions.len(), 1600);
        assert_eq!(g.triangles.len(), 2 * 39 * 39);
        let e = mesh_edges(&g.positions, &g.triangles);
        // 2 * 39 * 40 axis edges + 39 * 39 diagonals
        assert_eq!(e.len(), 2 * 39 * 40 + 39 * 39);
        let total: f64 = e.iter().map(|e| e.area).sum();
        assert!(
            (total - 3.0).abs() < 1e-9,
            "each triangle counted by its 3 edges: {total}"
        );
        let sub = g.uniform_subset(3, 2);
        assert_eq!(sub, vec![0, 20, 39, 1560, 1580, 1599]);
    }

    #[test]
    fn bending_coefficients_vanish_when_flat_and_not_when_bent() {
        let x = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.3, 0.8, 0.0),
            Vector3::new(0.6, -0.7, 0.0),
        ];
        let k = isometric_bending_coefficients(x);
        let sum: f64 = k.iter().sum();
        assert!(sum.abs() < 1e-12, "translation invariance: {sum}");
        let c: Vector3<f64> = (0..4).map(|i| x[i] * k[i]).sum();
        assert!(
            c.norm() < 1e-12,
            "flat hinge has zero curvature vector: {c:?}"
        );
        let mut bent = x;
        bent[3].z = 0.3;
        let c: Vector3<f64> = (0..4).map(|i| bent[i] * k[i]).sum();
        assert!(c.norm() > 0.1, "bent hinge has curvature: {c:?}");
    }

    #[test]
    fn colouring_is_proper() {
        let g = GridSheet::new(1.0, 1.0, 10, 10, Vector3::zeros()).unwrap();
        let e = mesh_edges(&g.positions, &g.triangles);
        let lists: Vec<&[u32]> = e.iter().map(|e| &e.v[..]).collect();
        let col = greedy_colouring(100, &lists);
        for (i, a) in e.iter().enumerate() {
            for (j, b) in e.iter().enumerate() {
                if i < j && col[i] == col[j] {
                    assert!(a.v.iter().all(|p| !b.v.contains(p)));
                }
            }
        }
    }

    #[test]
    fn bad_triangles_are_reported() {
        let p = vec![Vector3::zeros(), Vector3::x(), Vector3::y()];
        assert!(validate_triangles(&p, &[[0, 1, 3]]).is_err());
        assert!(validate_triangles(&p, &[[0, 1, 1]]).is_err());
        let q = vec![Vector3::zeros(), Vector3::x(), 2.0 * Vector3::x()];
        assert!(validate_triangles(&q, &[[0, 1, 2]]).is_err());
        assert!(validate_triangles(&p, &[[0, 1, 2]]).is_ok());
    }
}
