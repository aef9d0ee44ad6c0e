//! Direct tessellations: hexahedral box grids split into tetrahedra, spheres, capsules, planes and
//! cloth grids.

use nalgebra::Vector3;

use super::mesh::{SurfaceMesh, VolumeMesh};

/// A box of `size` centred at the origin, meshed as an `n[0] x n[1] x n[2]` grid of hexahedra, each
/// split into six tetrahedra around its main diagonal (Kuhn/Freudenthal split). Every hexahedron uses
/// the same split, so shared faces are cut along the same diagonal (conforming).
///
/// Node `(i, j, k)` has index `i + (n0 + 1) * (j + (n1 + 1) * k)` (x fastest). Callers validate sizes and
/// counts.
pub(super) fn box_grid(size: Vector3<f64>, n: [u32; 3]) -> VolumeMesh {
    let [nx, ny, nz] = n.map(|v| v as usize);
    let mut nodes = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                nodes.push(Vector3::new(
                    size.x * (i as f64 / nx as f64 - 0.5),
                    size.y * (j as f64 / ny as f64 - 0.5),
                    size.z * (k as f64 / nz as f64 - 0.5),
                ));
            }
        }
    }
    let id = |i: usize, j: usize, k: usize| (i + (nx + 1) * (j + (ny + 1) * k)) as u32;
    // Axis permutations: the path 0 -> e_p0 -> e_p0 + e_p1 -> (1, 1, 1) through the unit cube; the
    // tetrahedron's orientation is the permutation's sign, fixed by swapping the last two corners.
    const PERMS: [([usize; 3], bool); 6] = [
        ([0, 1, 2], true),
        ([1, 2, 0], true),
        ([2, 0, 1], true),
        ([0, 2, 1], false),
        ([1, 0, 2], false),
        ([2, 1, 0], false),
    ];
    let mut tets = Vec::with_capacity(6 * nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                for (perm, even) in PERMS {
                    let mut corner = [0usize; 3];
                    let mut tet = [id(i, j, k); 4];
                    for (step, &axis) in perm.iter().enumerate() {
                        corner[axis] = 1;
                        tet[step + 1] = id(i + corner[0], j + corner[1], k + corner[2]);
                    }
                    if !even {
                        tet.swap(2, 3);
                    }
                    tets.push(tet);
                }
            }
        }
    }
    VolumeMesh { nodes, tets }
}

/// A closed surface of revolution about z through the given latitude circles, from a top pole to a
/// bottom pole: `rings` lists `(z, radius)` from top to bottom; each circle has `segments` vertices.
fn lathe(top: f64, bottom: f64, rings: &[(f64, f64)], segments: u32) -> SurfaceMesh {
    let s = segments;
    let mut positions = vec![Vector3::new(0.0, 0.0, top)];
    for &(z, r) in rings {
        for j in 0..s {
            let a = std::f64::consts::TAU * f64::from(j) / f64::from(s);
            positions.push(Vector3::new(r * a.cos(), r * a.sin(), z));
        }
    }
    let bottom_pole = positions.len() as u32;
    positions.push(Vector3::new(0.0, 0.0, bottom));
    let ring = |k: usize, j: u32| 1 + k as u32 * s + j % s;
    let mut triangles = Vec::with_capacity(2 * s as usize * rings.len());
    for j in 0..s {
        triangles.push([0, ring(0, j), ring(0, j + 1)]);
    }
    for k in 0..rings.len().saturating_sub(1) {
        for j in 0..s {
            triangles.push([ring(k, j), ring(k + 1, j), ring(k + 1, j + 1)]);
            triangles.push([ring(k, j), ring(k + 1, j + 1), ring(k, j + 1)]);
        }
    }
    let last = rings.len() - 1;
    for j in 0..s {
        triangles.push([bottom_pole, ring(last, j + 1), ring(last, j)]);
    }
    SurfaceMesh {
        positions,
        triangles,
    }
}

/// A latitude-longitude sphere centred at the origin: `segments` vertices around z, `rings` bands from
/// pole to pole (callers validate `segments >= 3`, `rings >= 2`).
pub(super) fn sphere(radius: f64, segments: u32, rings: u32) -> SurfaceMesh {
    let lats: Vec<(f64, f64)> = (1..rings)
        .map(|k| {
            let phi = std::f64::consts::PI * f64::from(k) / f64::from(rings);
            (radius * phi.cos(), radius * phi.sin())
        })
        .collect();
    lathe(radius, -radius, &lats, segments)
}

/// A capsule along z centred at the origin: a cylinder of `height` (between the hemisphere centres)
/// capped by hemispheres of `radius`, each with `rings` bands from pole to equator.
pub(super) fn capsule(radius: f64, height: f64, segments: u32, rings: u32) -> SurfaceMesh {
    let half = 0.5 * height;
    let mut lats = Vec::with_capacity(2 * rings as usize);
    for k in 1..=rings {
        let phi = std::f64::consts::FRAC_PI_2 * f64::from(k) / f64::from(rings);
        lats.push((half + radius * phi.cos(), radius * phi.sin()));
    }
    // With zero height the two equators coincide: keep one.
    let start = if height > 0.0 { 0 } else { 1 };
    for k in start..rings {
        let phi = std::f64::consts::FRAC_PI_2 * f64::from(k) / f64::from(rings);
        lats.push((-half - radius * phi.sin(), radius * phi.cos()));
    }
    lathe(half + radius, -half - radius, &lats, segments)
}

/// A `size.0` x `size.1` rectangle in the xy-plane centred at the origin, two triangles, normal +z.
pub(super) fn plane(size: (f64, f64)) -> SurfaceMesh {
    let (hx, hy) = (0.5 * size.0, 0.5 * size.1);
    SurfaceMesh {
        positions: vec![
            Vector3::new(-hx, -hy, 0.0),
            Vector3::new(hx, -hy, 0.0),
            Vector3::new(hx, hy, 0.0),
            Vector3::new(-hx, hy, 0.0),
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// A cloth sheet: `res.0 x res.1` vertices on a `size` rectangle in the xy-plane centred at the origin,
/// vertex `(i, j)` at index `j * res.0 + i` (x fastest), normal +z. Cell diagonals alternate in a
/// checkerboard pattern so the sheet has no preferred shear direction.
pub(super) fn grid(size: (f64, f64), res: (u32, u32)) -> SurfaceMesh {
    let (nx, ny) = res;
    let mut positions = Vec::with_capacity((nx * ny) as usize);
    for j in 0..ny {
        for i in 0..nx {
            positions.push(Vector3::new(
                size.0 * (f64::from(i) / f64::from(nx - 1) - 0.5),
                size.1 * (f64::from(j) / f64::from(ny - 1) - 0.5),
                0.0,
            ));
        }
    }
    let id = |i: u32, j: u32| j * nx + i;
    let mut triangles = Vec::with_capacity(2 * ((nx - 1) * (ny - 1)) as usize);
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if (i + j) % 2 == 0 {
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            } else {
                triangles.push([a, b, d]);
                triangles.push([b, c, d]);
            }
        }
    }
    SurfaceMesh {
        positions,
        triangles,
    }
}
