//! Cloth self-collision: spatial hashing of particles (Teschner et al., "Optimized spatial
//! hashing for collision detection of deformable objects", 2003, with a dense counting-sort
//! table), point-triangle constraints with side memory and point-point separation.
//!
//! Once per step, pairs of particles that are close in space (within `R`) but far apart in the
//! rest shape (more than `R`) are found; the triangles around the other particle become
//! point-triangle candidates, each remembering on which side of the triangle the particle
//! started the step. During the substeps the particle is kept `thickness` away from the
//! triangle on that side while it lies over the triangle, so two layers cannot pass through each
//! other as long as they approach by less than `margin` per step. Edge-edge crossings are not
//! tested.

use crate::lanes::P4;
use nalgebra::Vector3;

/// Self-collision candidate data and scratch (rebuilt every step).
#[derive(Debug, Clone)]
pub(crate) struct SelfCollision {
    /// CSR particle -> incident triangles.
    vt_start: Vec<u32>,
    vt: Vec<u32>,
    /// Largest rest circumradius of a triangle (capped at its longest edge), m: every point over
    /// a triangle is at most this far from one of its vertices.
    max_reach: f64,
    /// Scratch: cell coordinates per particle.
    cells: Vec<(i64, i64, i64)>,
    /// Hash table: bucket starts (`size + 1`) and particle entries.
    bucket_start: Vec<u32>,
    entries: Vec<u32>,
    /// Point-triangle candidates: particle, triangle, side (+1 / -1).
    pt_particle: Vec<u32>,
    pt_tri: Vec<u32>,
    pt_side: Vec<f64>,
    /// Point-point candidates.
    pp: Vec<[u32; 2]>,
    /// Scratch: close particle pairs (spatially near, far apart at rest) and point-triangle
    /// candidates before the distance test.
    pairs: Vec<[u32; 2]>,
    cand: Vec<(u32, u32)>,
}

const BARY_TOL: f64 = 0.05;

fn hash_cell(x: i64, y: i64, z: i64, size: usize) -> usize {
    // Teschner et al.'s primes combined linearly, then Fibonacci hashing (the high bits of a
    // multiplication by 2^64 / golden ratio), which mixes well and costs two multiplications.
    let h = x
        .wrapping_mul(73_856_093)
        .wrapping_add(y.wrapping_mul(19_349_663))
        .wrapping_add(z.wrapping_mul(83_492_791)) as u64;
    let bits = size.trailing_zeros();
    (h.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> (64 - bits)) as usize
}

impl SelfCollision {
    pub(crate) fn new(rest: &[Vector3<f64>], tris: &[[u32; 3]]) -> Self {
        let n = rest.len();
        let mut start = vec![0u32; n + 1];
        for t in tris {
            for &v in t {
                start[v as usize + 1] += 1;
            }
        }
        for i in 0..n {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut vt = vec![0u32; start[n] as usize];
        let mut max_reach: f64 = 0.0;
        for (k, t) in tris.iter().enumerate() {
            for &v in t {
                vt[fill[v as usize] as usize] = k as u32;
                fill[v as usize] += 1;
            }
            let [a, b, c] = t.map(|v| rest[v as usize]);
            let (la, lb, lc) = ((b - c).norm(), (c - a).norm(), (a - b).norm());
            let area2 = (b - a).cross(&(c - a)).norm();
            let circum = la * lb * lc / (2.0 * area2);
            max_reach = max_reach.max(circum.min(la.max(lb).max(lc)));
        }
        SelfCollision {
            vt_start: start,
            vt,
            max_reach,
            cells: Vec::new(),
            bucket_start: Vec::new(),
            entries: Vec::new(),
            pt_particle: Vec::new(),
            pt_tri: Vec::new(),
            pt_side: Vec::new(),
            pp: Vec::new(),
            pairs: Vec::new(),
            cand: Vec::new(),
        }
    }

    /// Gathers the candidates of this step from the positions at its start; returns their
    /// number.
    pub(crate) fn gather(
        &mut self,
        pos: &[Vector3<f64>],
        rest: &[Vector3<f64>],
        tris: &[[u32; 3]],
        thickness: f64,
        margin: f64,
    ) -> usize {
        let n = pos.len();
        self.pt_particle.clear();
        self.pt_tri.clear();
        self.pt_side.clear();
        self.pp.clear();
        let reach = thickness + margin;
        let r = self.max_reach + reach;
        let r2 = r * r;
        let inv = 1.0 / r;
        let size = (4 * n).next_power_of_two();
        self.bucket_start.clear();
        self.bucket_start.resize(size + 1, 0);
        let cell = |p: &Vector3<f64>| {
            (
                (p.x * inv).floor() as i64,
                (p.y * inv).floor() as i64,
                (p.z * inv).floor() as i64,
            )
        };
        self.cells.clear();
        self.cells.extend(pos.iter().map(cell));
        for &(x, y, z) in &self.cells {
            self.bucket_start[hash_cell(x, y, z, size) + 1] += 1;
        }
        for b in 0..size {
            self.bucket_start[b + 1] += self.bucket_start[b];
        }
        self.entries.clear();
        self.entries.resize(n, 0);
        let mut fill: Vec<u32> = self.bucket_start[..size].to_vec();
        for (i, &(x, y, z)) in self.cells.iter().enumerate() {
            let b = hash_cell(x, y, z, size);
            self.entries[fill[b] as usize] = i as u32;
            fill[b] += 1;
        }
        // Each close pair is found once: from the particle's own cell (higher index only) and its
        // 13 "forward" neighbour cells; hash collisions may report a pair twice (deduplicated).
        const FORWARD: [(i64, i64, i64); 13] = [
            (1, 0, 0),
            (-1, 1, 0),
            (0, 1, 0),
            (1, 1, 0),
            (-1, -1, 1),
            (0, -1, 1),
            (1, -1, 1),
            (-1, 0, 1),
            (0, 0, 1),
            (1, 0, 1),
            (-1, 1, 1),
            (0, 1, 1),
            (1, 1, 1),
        ];
        self.pairs.clear();
        for i in 0..n {
            let xi = pos[i];
            let ri = rest[i];
            let (cx, cy, cz) = self.cells[i];
            for k in 0..14 {
                let (b, own) = if k == 0 {
                    (hash_cell(cx, cy, cz, size), true)
                } else {
                    let (dx, dy, dz) = FORWARD[k - 1];
                    (hash_cell(cx + dx, cy + dy, cz + dz, size), false)
                };
                for e in self.bucket_start[b]..self.bucket_start[b + 1] {
                    let j = self.entries[e as usize] as usize;
                    if j == i || (own && j < i) {
                        continue;
                    }
                    if (pos[j] - xi).norm_squared() >= r2 || (rest[j] - ri).norm_squared() <= r2 {
                        continue;
                    }
                    self.pairs.push([i.min(j) as u32, i.max(j) as u32]);
                }
            }
        }
        self.pairs.sort_unstable();
        self.pairs.dedup();
        // point-triangle candidates from the close pairs, both directions
        self.cand.clear();
        for &[i, j] in &self.pairs {
            if (pos[i as usize] - pos[j as usize]).norm() < reach {
                self.pp.push([i, j]);
            }
            for (p, q) in [(i, j), (j, i)] {
                let (s0, s1) = (
                    self.vt_start[q as usize] as usize,
                    self.vt_start[q as usize + 1] as usize,
                );
                for &t in &self.vt[s0..s1] {
                    if !tris[t as usize].contains(&p) {
                        self.cand.push((p, t));
                    }
                }
            }
        }
        self.cand.sort_unstable();
        self.cand.dedup();
        for &(p, t) in &self.cand {
            let xi = pos[p as usize];
            let [a, b, c] = tris[t as usize].map(|v| pos[v as usize]);
            let q = closest_point_triangle(&xi, &a, &b, &c);
            if (xi - q).norm() >= reach {
                continue;
            }
            let nrm = (b - a).cross(&(c - a));
            let sd = nrm.dot(&(xi - a));
            self.pt_particle.push(p);
            self.pt_tri.push(t);
            self.pt_side.push(if sd >= 0.0 { 1.0 } else { -1.0 });
        }
        self.pp.sort_unstable();
        self.pp.dedup();
        self.pt_particle.len() + self.pp.len()
    }

    /// One projection sweep over the candidates.
    pub(crate) fn solve(&self, pos: &mut [P4], w: &[f64], tris: &[[u32; 3]], thickness: f64) {
        for k in 0..self.pt_particle.len() {
            let p = self.pt_particle[k] as usize;
            let [ia, ib, ic] = tris[self.pt_tri[k] as usize].map(|v| v as usize);
            let (a, b, c, x) = (pos[ia], pos[ib], pos[ic], pos[p]);
            let e1 = b - a;
            let e2 = c - a;
            let nrm = e1.cross(e2);
            let nl = nrm.norm();
            if nl < 1e-14 {
                continue;
            }
            let side = self.pt_side[k];
            let n = nrm * (side / nl);
            let d = n.dot(x - a);
            if d >= thickness {
                continue;
            }
            // barycentric coordinates of the projection
            let q = x - a;
            let d00 = e1.dot(e1);
            let d01 = e1.dot(e2);
            let d11 = e2.dot(e2);
            let d20 = q.dot(e1);
            let d21 = q.dot(e2);
            let den = d00 * d11 - d01 * d01;
            let v = (d11 * d20 - d01 * d21) / den;
            let ww = (d00 * d21 - d01 * d20) / den;
            let u = 1.0 - v - ww;
            if u < -BARY_TOL || v < -BARY_TOL || ww < -BARY_TOL {
                continue;
            }
            let (u, v, ww) = (u.max(0.0), v.max(0.0), ww.max(0.0));
            let s = u + v + ww;
            let (u, v, ww) = (u / s, v / s, ww / s);
            let (wp, wa, wb, wc) = (w[p], w[ia], w[ib], w[ic]);
            let denom = wp + wa * u * u + wb * v * v + wc * ww * ww;
            if denom == 0.0 {
                continue;
            }
            let lam = (thickness - d) / denom;
            pos[p] += n * (lam * wp);
            pos[ia] -= n * (lam * wa * u);
            pos[ib] -= n * (lam * wb * v);
            pos[ic] -= n * (lam * wc * ww);
        }
        for &[i, j] in &self.pp {
            let (i, j) = (i as usize, j as usize);
            let d = pos[i] - pos[j];
            let l = d.norm();
            if l >= thickness || l < 1e-14 {
                continue;
            }
            let ws = w[i] + w[j];
            if ws == 0.0 {
                continue;
            }
            let corr = d * ((thickness - l) / (l * ws));
            pos[i] += corr * w[i];
            pos[j] -= corr * w[j];
        }
    }
}

/// Closest point to `p` on triangle `abc` (the engine's, shared with deformable contact).
pub(crate) fn closest_point_triangle(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> Vector3<f64> {
    modesuite_engine::contact::closest_on_triangle(p, a, b, c).point
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_point_regions() {
        let a = Vector3::new(0.0, 0.0, 0.0);
        let b = Vector3::new(1.0, 0.0, 0.0);
        let c = Vector3::new(0.0, 1.0, 0.0);
        let q = closest_point_triangle(&Vector3::new(0.2, 0.2, 0.5), &a, &b, &c);
        assert!((q - Vector3::new(0.2, 0.2, 0.0)).norm() < 1e-15);
        let q = closest_point_triangle(&Vector3::new(-1.0, -1.0, 0.0), &a, &b, &c);
        assert_eq!(q, a);
        let q = closest_point_triangle(&Vector3::new(1.0, 1.0, 0.0), &a, &b, &c);
        assert!((q - Vector3::new(0.5, 0.5, 0.0)).norm() < 1e-15);
        let q = closest_point_triangle(&Vector3::new(0.5, -1.0, 0.3), &a, &b, &c);
        assert!((q - Vector3::new(0.5, 0.0, 0.0)).norm() < 1e-15);
    }
}
