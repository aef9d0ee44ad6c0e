//! Measures of a deformable body's surface from its nodes and triangles, whatever its solver:
//! what tasks score (the fraction of a cloth over a region, the area it covers). A solver's
//! body kind gives the triangles ([`BodyKind::surface_triangles`]); the nodes are the body's
//! [`DeformableNodes`](crate::components::DeformableNodes).
//!
//! [`BodyKind::surface_triangles`]: crate::registry::BodyKind::surface_triangles

use nalgebra::Vector3;

/// An axis-aligned rectangle in the xy plane (a table top, a gap), m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Region {
    /// Smallest x and y, m.
    pub min: [f64; 2],
    /// Largest x and y, m.
    pub max: [f64; 2],
}

impl Region {
    /// Area of the rectangle, m^2.
    pub fn area(&self) -> f64 {
        (self.max[0] - self.min[0]).max(0.0) * (self.max[1] - self.min[1]).max(0.0)
    }
    /// Whether the xy projection of `p` lies inside.
    pub fn contains_xy(&self, p: &Vector3<f64>) -> bool {
        p.x >= self.min[0] && p.x <= self.max[0] && p.y >= self.min[1] && p.y <= self.max[1]
    }
}

/// A deformable body's surface: its nodes (m, world frame) and the triangles over them.
#[derive(Debug, Clone, Copy)]
pub struct Surface<'a> {
    /// Node positions.
    pub nodes: &'a [Vector3<f64>],
    /// Triangles, indices into `nodes`.
    pub triangles: &'a [[u32; 3]],
}

impl Surface<'_> {
    /// Fraction of nodes whose xy projection lies inside `region` (Uncover: what is still
    /// covered); 0 for a body without nodes.
    pub fn fraction_inside_xy(&self, region: &Region) -> f64 {
        if self.nodes.is_empty() {
            return 0.0;
        }
        let k = self.nodes.iter().filter(|p| region.contains_xy(p)).count();
        k as f64 / self.nodes.len() as f64
    }

    /// Area of `region` covered by the xy projection of the triangles whose three nodes are
    /// higher than `above` (m), estimated on a `resolution` x `resolution` grid of sample points
    /// (cell centres): the error is at most the region's boundary cells. Cover's gap is covered
    /// by cloth spanning it, not by cloth lying on the floor under it.
    pub fn covered_area_above(&self, region: &Region, resolution: usize, above: f64) -> f64 {
        let r = resolution.max(1);
        let (x0, y0) = (region.min[0], region.min[1]);
        let dx = (region.max[0] - x0) / r as f64;
        let dy = (region.max[1] - y0) / r as f64;
        if !(dx > 0.0 && dy > 0.0) {
            return 0.0;
        }
        let mut covered = vec![false; r * r];
        for t in self.triangles {
            let [a, b, c] = t.map(|i| self.nodes[i as usize]);
            if !(a.z > above && b.z > above && c.z > above) {
                continue;
            }
            let lo_x = a.x.min(b.x).min(c.x);
            let hi_x = a.x.max(b.x).max(c.x);
            let lo_y = a.y.min(b.y).min(c.y);
            let hi_y = a.y.max(b.y).max(c.y);
            let i0 = (((lo_x - x0) / dx - 0.5).ceil().max(0.0)) as usize;
            let i1 = (((hi_x - x0) / dx - 0.5).floor()).min(r as f64 - 1.0);
            let j0 = (((lo_y - y0) / dy - 0.5).ceil().max(0.0)) as usize;
            let j1 = (((hi_y - y0) / dy - 0.5).floor()).min(r as f64 - 1.0);
            if i1 < 0.0 || j1 < 0.0 {
                continue;
            }
            let det = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
            if det == 0.0 {
                continue;
            }
            for j in j0..=(j1 as usize) {
                let py = y0 + (j as f64 + 0.5) * dy;
                for i in i0..=(i1 as usize) {
                    let px = x0 + (i as f64 + 0.5) * dx;
                    let u = ((b.x - px) * (c.y - py) - (c.x - px) * (b.y - py)) / det;
                    let v = ((c.x - px) * (a.y - py) - (a.x - px) * (c.y - py)) / det;
                    let w = 1.0 - u - v;
                    if u >= 0.0 && v >= 0.0 && w >= 0.0 {
                        covered[j * r + i] = true;
                    }
                }
            }
        }
        covered.iter().filter(|&&c| c).count() as f64 * dx * dy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_unit_square_of_two_triangles_covers_its_area_and_counts_its_nodes() {
        let nodes = [
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::new(1.0, 0.0, 1.0),
            Vector3::new(1.0, 1.0, 1.0),
            Vector3::new(0.0, 1.0, 1.0),
        ];
        let triangles = [[0, 1, 2], [0, 2, 3]];
        let s = Surface {
            nodes: &nodes,
            triangles: &triangles,
        };
        let big = Region {
            min: [-1.0, -1.0],
            max: [2.0, 2.0],
        };
        let half = Region {
            min: [0.5, -1.0],
            max: [2.0, 2.0],
        };
        let area = s.covered_area_above(&big, 300, f64::NEG_INFINITY);
        println!("covered area {area:.4} m^2 (want 1 within a boundary row of cells, 0.04)");
        assert!((area - 1.0).abs() < 0.04, "{area}");
        assert_eq!(s.covered_area_above(&big, 300, 1.0), 0.0); // not above z = 1
        assert_eq!(s.fraction_inside_xy(&half), 0.5);
        assert_eq!(big.area(), 9.0);
    }
}
