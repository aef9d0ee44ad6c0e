//! Geometry of deformable-deformable contact: the closest point of a triangle and a bounding
//! volume hierarchy over a body's surface triangles (f64, deterministic, rebuilt every substep).

use nalgebra::Vector3;

/// The closest point of a triangle to a point ([`closest_on_triangle`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClosestPoint {
    /// The point, m.
    pub point: Vector3<f64>,
    /// Its barycentric weights on the corners `(a, b, c)`.
    pub weights: [f64; 3],
    /// Whether it lies inside the face (not on an edge or a corner).
    pub inside: bool,
}

/// The closest point of triangle `(a, b, c)` to `p` (the Voronoi regions of the corners, the
/// edges and the face: Ericson, Real-Time Collision Detection, 5.1.5). A degenerate (zero-area)
/// triangle whose face region is reached gives its first corner.
pub fn closest_on_triangle(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> ClosestPoint {
    let corner = |point: &Vector3<f64>, k: usize| {
        let mut weights = [0.0; 3];
        weights[k] = 1.0;
        ClosestPoint {
            point: *point,
            weights,
            inside: false,
        }
    };
    let edge = |point: Vector3<f64>, weights: [f64; 3]| ClosestPoint {
        point,
        weights,
        inside: false,
    };
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return corner(a, 0);
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return corner(b, 1);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return edge(a + ab * v, [1.0 - v, v, 0.0]);
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return corner(c, 2);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return edge(a + ac * w, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return edge(b + (c - b) * w, [0.0, 1.0 - w, w]);
    }
    let sum = va + vb + vc;
    if !(sum.is_finite() && sum > 0.0) {
        return corner(a, 0);
    }
    let den = 1.0 / sum;
    let v = vb * den;
    let w = vc * den;
    ClosestPoint {
        point: a + ab * v + ac * w,
        weights: [1.0 - v - w, v, w],
        inside: true,
    }
}

/// An axis-aligned box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Aabb {
    pub lo: Vector3<f64>,
    pub hi: Vector3<f64>,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        lo: Vector3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY),
        hi: Vector3::new(f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY),
    };

    fn grow(&mut self, p: &Vector3<f64>) {
        self.lo = self.lo.inf(p);
        self.hi = self.hi.sup(p);
    }

    fn merge(&mut self, o: &Aabb) {
        self.lo = self.lo.inf(&o.lo);
        self.hi = self.hi.sup(&o.hi);
    }

    /// Whether the box meets the cube `p +- r`.
    pub fn near(&self, p: &Vector3<f64>, r: f64) -> bool {
        (0..3).all(|k| p[k] + r >= self.lo[k] && p[k] - r <= self.hi[k])
    }
}

/// One node of a [`TriangleBvh`]: a box and either two children or a range of leaves.
#[derive(Debug, Clone, Copy)]
struct Node {
    aabb: Aabb,
    /// Leaf: first index into `order`; inner: index of the left child (right = left + 1).
    start: u32,
    /// Leaf: number of triangles (> 0); inner: 0.
    count: u32,
}

const LEAF_SIZE: usize = 4;

/// A bounding volume hierarchy over triangles (median split on the longest axis of the
/// centroids), built from scratch from the current node positions: the result depends only on
/// the positions, so queries are deterministic.
#[derive(Debug, Clone, Default)]
pub(crate) struct TriangleBvh {
    nodes: Vec<Node>,
    /// Triangle indices, grouped by leaf.
    order: Vec<u32>,
    boxes: Vec<Aabb>,
    centroids: Vec<Vector3<f64>>,
}

impl TriangleBvh {
    /// Rebuilds over `triangles` of the nodes `pos`, each box padded by `pad` (m).
    pub fn rebuild(&mut self, triangles: &[[u32; 3]], pos: &[Vector3<f64>], pad: f64) {
        self.nodes.clear();
        self.order.clear();
        self.boxes.clear();
        self.centroids.clear();
        let padv = Vector3::repeat(pad);
        for t in triangles {
            let mut b = Aabb::EMPTY;
            for &i in t {
                b.grow(&pos[i as usize]);
            }
            b.lo -= padv;
            b.hi += padv;
            self.centroids.push((b.lo + b.hi) * 0.5);
            self.boxes.push(b);
        }
        self.order.extend(0..triangles.len() as u32);
        if triangles.is_empty() {
            return;
        }
        self.nodes.push(Node {
            aabb: Aabb::EMPTY,
            start: 0,
            count: 0,
        });
        self.build(0, 0, triangles.len());
    }

    fn build(&mut self, node: usize, start: usize, end: usize) {
        let mut aabb = Aabb::EMPTY;
        let mut cbox = Aabb::EMPTY;
        for &t in &self.order[start..end] {
            aabb.merge(&self.boxes[t as usize]);
            cbox.grow(&self.centroids[t as usize]);
        }
        self.nodes[node].aabb = aabb;
        let extent = cbox.hi - cbox.lo;
        if end - start <= LEAF_SIZE || extent.max() <= 0.0 {
            self.nodes[node].start = start as u32;
            self.nodes[node].count = (end - start) as u32;
            return;
        }
        let axis = extent.imax();
        let mid = start + (end - start) / 2;
        let centroids = &self.centroids;
        self.order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
            let (ca, cb) = (centroids[a as usize][axis], centroids[b as usize][axis]);
            ca.total_cmp(&cb).then(a.cmp(&b))
        });
        let left = self.nodes.len();
        let blank = Node {
            aabb: Aabb::EMPTY,
            start: 0,
            count: 0,
        };
        self.nodes.push(blank);
        self.nodes.push(blank);
        self.nodes[node].start = left as u32;
        self.nodes[node].count = 0;
        self.build(left, start, mid);
        self.build(left + 1, mid, end);
    }

    /// Whether nothing is built yet (or there are no triangles).
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The box of every triangle.
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, |n| n.aabb)
    }

    /// Calls `f` with every triangle whose padded box meets the cube `p +- r`, in a fixed order.
    pub fn visit(&self, p: &Vector3<f64>, r: f64, mut f: impl FnMut(u32)) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack: [u32; 64] = [0; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let n = self.nodes[stack[top] as usize];
            if !n.aabb.near(p, r) {
                continue;
            }
            if n.count > 0 {
                let s = n.start as usize;
                for &t in &self.order[s..s + n.count as usize] {
                    if self.boxes[t as usize].near(p, r) {
                        f(t);
                    }
                }
            } else if top + 2 <= stack.len() {
                stack[top] = n.start + 1;
                stack[top + 1] = n.start;
                top += 2;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
        Vector3::new(x, y, z)
    }

    #[test]
    fn closest_point_regions_match_brute_force() {
        let (a, b, c) = (v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0), v(0.2, 0.9, 0.0));
        let mut worst: f64 = 0.0;
        for i in 0..21 {
            for j in 0..21 {
                let p = v(-0.5 + 0.1 * i as f64, -0.5 + 0.1 * j as f64, 0.3);
                let q = closest_on_triangle(&p, &a, &b, &c).point;
                // brute force over a fine grid of the triangle
                let mut best = f64::INFINITY;
                for s in 0..=200 {
                    for t in 0..=(200 - s) {
                        let (s, t) = (s as f64 / 200.0, t as f64 / 200.0);
                        let r = a + (b - a) * s + (c - a) * t;
                        best = best.min((p - r).norm());
                    }
                }
                worst = worst.max((p - q).norm() - best);
            }
        }
        // the grid's spacing bounds how much closer the exact point may be
        assert!(
            worst <= 1e-12,
            "closest point farther than the grid's: {worst}"
        );
    }

    #[test]
    fn bvh_visits_exactly_the_boxes_near_the_point() {
        let mut pos = Vec::new();
        let mut tris = Vec::new();
        for i in 0..20u32 {
            for j in 0..20u32 {
                pos.push(v(f64::from(i) * 0.1, f64::from(j) * 0.1, 0.0));
                if i > 0 && j > 0 {
                    let k = i * 20 + j;
                    tris.push([k - 21, k - 20, k]);
                }
            }
        }
        let mut bvh = TriangleBvh::default();
        bvh.rebuild(&tris, &pos, 0.01);
        for (p, r) in [
            (v(0.55, 0.55, 0.0), 0.07),
            (v(3.0, 3.0, 0.0), 0.1),
            (v(1.0, 0.2, 0.05), 0.3),
        ] {
            let mut got = Vec::new();
            bvh.visit(&p, r, |t| got.push(t));
            got.sort_unstable();
            let want: Vec<u32> = (0..tris.len() as u32)
                .filter(|&t| bvh.boxes[t as usize].near(&p, r))
                .collect();
            assert_eq!(got, want);
        }
    }
}
