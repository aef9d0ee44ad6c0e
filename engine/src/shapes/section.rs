//! Triangulated 2-D cross-sections (profiles) for sweeps, revolutions and extrusions.

use nalgebra::Vector2;

use super::error::{in_range, ShapeError};

/// A triangulated planar region in profile coordinates `(u, v)`, triangles counter-clockwise.
#[derive(Clone, Debug)]
pub(super) struct Section {
    /// Points, metres.
    pub points: Vec<Vector2<f64>>,
    /// Counter-clockwise triangles.
    pub tris: Vec<[u32; 3]>,
}

impl Section {
    /// Total area.
    #[cfg(test)]
    pub fn area(&self) -> f64 {
        self.tris
            .iter()
            .map(|t| {
                tri_area(
                    &self.points[t[0] as usize],
                    &self.points[t[1] as usize],
                    &self.points[t[2] as usize],
                )
            })
            .sum()
    }

    /// Area centroid.
    pub fn centroid(&self) -> Vector2<f64> {
        let mut sum = Vector2::zeros();
        let mut area = 0.0;
        for t in &self.tris {
            let [a, b, c] = t.map(|i| self.points[i as usize]);
            let w = tri_area(&a, &b, &c);
            sum += w * (a + b + c) / 3.0;
            area += w;
        }
        if area > 0.0 {
            sum / area
        } else {
            Vector2::zeros()
        }
    }
}

/// Signed area of the triangle `(a, b, c)` (positive when counter-clockwise).
pub(super) fn tri_area(a: &Vector2<f64>, b: &Vector2<f64>, c: &Vector2<f64>) -> f64 {
    0.5 * cross2(&(b - a), &(c - a))
}

fn cross2(a: &Vector2<f64>, b: &Vector2<f64>) -> f64 {
    a.x * b.y - a.y * b.x
}

/// Number of nodes on ring `k` (1-based, `k <= rings`) of a disk with `segments` nodes on its rim:
/// proportional to the ring radius, at least 3, so triangles stay close to equilateral.
pub(super) fn ring_nodes(segments: u32, rings: u32, k: u32) -> u32 {
    let n = (f64::from(segments) * f64::from(k) / f64::from(rings)).round() as u32;
    n.max(3)
}

/// Default number of rings for a disk with `segments` rim nodes: radial spacing about equal to the
/// rim spacing (`segments / 2 pi`, at least 1).
pub(super) fn default_rings(segments: u32) -> u32 {
    ((f64::from(segments) / std::f64::consts::TAU).round() as u32).max(1)
}

/// A disk of `radius` centred at the origin: a centre node (point 0) and `rings` concentric rings, ring
/// `k` at radius `k * radius / rings` with [`ring_nodes`] nodes, the outermost with `segments` nodes
/// (the first of them on the +u axis). Adjacent rings are zipped together by angle; each inner ring is
/// rotated by the fraction of its node spacing (eighths) that maximises the smallest triangle angle
/// against the next ring out. Callers validate `segments >= 3` and `rings >= 1`.
pub(super) fn circle(radius: f64, segments: u32, rings: u32) -> Section {
    // Offsets (in units of each ring's node spacing), chosen from the rim inward.
    let mut offsets = vec![0.0; rings as usize + 1];
    for k in (1..rings).rev() {
        let (n_in, n_out) = (
            ring_nodes(segments, rings, k),
            ring_nodes(segments, rings, k + 1),
        );
        let (r_in, r_out) = (f64::from(k), f64::from(k + 1));
        let outer_offset = offsets[k as usize + 1];
        let mut best = (f64::NEG_INFINITY, 0.0);
        for eighth in 0..8 {
            let offset = f64::from(eighth) / 8.0;
            let mut pts = ring_points(r_in, n_in, offset);
            pts.extend(ring_points(r_out, n_out, outer_offset));
            let mut tris = Vec::new();
            zip_rings(&mut tris, (0, n_in, offset), (n_in, n_out, outer_offset));
            let worst = tris
                .iter()
                .map(|t| min_angle(&t.map(|i| pts[i as usize])))
                .fold(f64::INFINITY, f64::min);
            if worst > best.0 + 1e-12 {
                best = (worst, offset);
            }
        }
        offsets[k as usize] = best.1;
    }
    let mut points = vec![Vector2::zeros()];
    let mut tris = Vec::new();
    let mut prev: Option<(u32, u32, f64)> = None;
    for k in 1..=rings {
        let n = ring_nodes(segments, rings, k);
        let offset = offsets[k as usize];
        let start = points.len() as u32;
        points.extend(ring_points(
            radius * f64::from(k) / f64::from(rings),
            n,
            offset,
        ));
        match prev {
            None => {
                for j in 0..n {
                    tris.push([0, start + j, start + (j + 1) % n]);
                }
            }
            Some(inner) => zip_rings(&mut tris, inner, (start, n, offset)),
        }
        prev = Some((start, n, offset));
    }
    Section { points, tris }
}

/// `n` points evenly spaced on a circle of radius `r`, the first at angle `offset * 2 pi / n`.
fn ring_points(r: f64, n: u32, offset: f64) -> Vec<Vector2<f64>> {
    (0..n)
        .map(|j| {
            let a = std::f64::consts::TAU * (f64::from(j) + offset) / f64::from(n);
            Vector2::new(r * a.cos(), r * a.sin())
        })
        .collect()
}

/// Smallest interior angle of a triangle, radians.
fn min_angle(p: &[Vector2<f64>; 3]) -> f64 {
    (0..3)
        .map(|k| {
            let a = p[(k + 1) % 3] - p[k];
            let b = p[(k + 2) % 3] - p[k];
            (a.dot(&b) / (a.norm() * b.norm())).clamp(-1.0, 1.0).acos()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Triangulates the annulus between an inner ring and an outer ring, each `(first index, count,
/// offset)` with nodes evenly spaced by angle from `offset` node spacings, always advancing on the ring
/// whose next node comes first.
fn zip_rings(tris: &mut Vec<[u32; 3]>, inner: (u32, u32, f64), outer: (u32, u32, f64)) {
    let (ia, na, oa) = inner;
    let (ib, nb, ob) = outer;
    let (mut i, mut j) = (0u32, 0u32);
    while i < na || j < nb {
        let next_a = (f64::from(i + 1) + oa) / f64::from(na);
        let next_b = (f64::from(j + 1) + ob) / f64::from(nb);
        let a = ia + i % na;
        let b = ib + j % nb;
        if j < nb && (i >= na || next_b <= next_a) {
            tris.push([a, b, ib + (j + 1) % nb]);
            j += 1;
        } else {
            tris.push([a, b, ia + (i + 1) % na]);
            i += 1;
        }
    }
}

/// A `width` x `height` rectangle centred at the origin (`u` across the width, `v` across the height),
/// as a grid of `du` x `dv` cells, each split into two triangles. Callers validate the counts.
pub(super) fn rect(width: f64, height: f64, du: u32, dv: u32) -> Section {
    let mut points = Vec::with_capacity(((du + 1) * (dv + 1)) as usize);
    for j in 0..=dv {
        for i in 0..=du {
            points.push(Vector2::new(
                -0.5 * width + width * f64::from(i) / f64::from(du),
                -0.5 * height + height * f64::from(j) / f64::from(dv),
            ));
        }
    }
    let id = |i: u32, j: u32| j * (du + 1) + i;
    let mut tris = Vec::with_capacity((2 * du * dv) as usize);
    for j in 0..dv {
        for i in 0..du {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    Section { points, tris }
}

/// Default rectangle divisions: square-ish cells whose edge is the shorter side (at most 64 per side).
pub(super) fn default_rect_divisions(width: f64, height: f64) -> (u32, u32) {
    let cell = width.min(height);
    let n = |len: f64| ((len / cell).round() as u32).clamp(1, 64);
    (n(width), n(height))
}

/// Signed area of a closed polygon (positive when counter-clockwise).
pub(super) fn polygon_area(points: &[Vector2<f64>]) -> f64 {
    let n = points.len();
    (0..n)
        .map(|i| cross2(&points[i], &points[(i + 1) % n]))
        .sum::<f64>()
        * 0.5
}

/// Checks that `points` form a simple polygon: at least 3 finite points, no repeated consecutive points,
/// no two non-adjacent edges touching, non-zero area. `field` names the list in errors.
pub(super) fn check_polygon(field: &str, points: &[Vector2<f64>]) -> Result<(), ShapeError> {
    const MAX_POINTS: usize = 4096;
    let n = points.len();
    if !(3..=MAX_POINTS).contains(&n) {
        return Err(ShapeError::invalid(
            format!("{field}.len()"),
            n,
            format!("a polygon needs between 3 and {MAX_POINTS} points"),
        ));
    }
    for (i, p) in points.iter().enumerate() {
        if !(in_range(p.x) && in_range(p.y)) {
            return Err(ShapeError::invalid(
                format!("{field}[{i}]"),
                (p.x, p.y),
                "must be finite, each coordinate with magnitude <= 1e6",
            ));
        }
    }
    let scale = points
        .iter()
        .map(|p| p.norm())
        .fold(0.0, f64::max)
        .max(f64::MIN_POSITIVE);
    for i in 0..n {
        let j = (i + 1) % n;
        if (points[i] - points[j]).norm() <= 1e-12 * scale {
            return Err(ShapeError::invalid(
                format!("{field}[{j}]"),
                (points[j].x, points[j].y),
                format!("repeats point {i}; consecutive polygon points must differ"),
            ));
        }
    }
    for i in 0..n {
        for j in i + 2..n {
            if i == 0 && j == n - 1 {
                continue; // adjacent through the closing edge
            }
            let (a, b) = (points[i], points[(i + 1) % n]);
            let (c, d) = (points[j], points[(j + 1) % n]);
            if segments_touch(&a, &b, &c, &d) {
                return Err(ShapeError::invalid(
                    field,
                    format!("edges {i}-{} and {j}-{}", (i + 1) % n, (j + 1) % n),
                    "the polygon must be simple: these edges intersect",
                ));
            }
        }
    }
    let area = polygon_area(points);
    if area.abs() <= 1e-12 * scale * scale {
        return Err(ShapeError::invalid(
            format!("{field} (area)"),
            area,
            "the polygon must enclose a non-zero area",
        ));
    }
    Ok(())
}

/// True if closed segments `ab` and `cd` share a point.
fn segments_touch(a: &Vector2<f64>, b: &Vector2<f64>, c: &Vector2<f64>, d: &Vector2<f64>) -> bool {
    let o1 = cross2(&(b - a), &(c - a));
    let o2 = cross2(&(b - a), &(d - a));
    let o3 = cross2(&(d - c), &(a - c));
    let o4 = cross2(&(d - c), &(b - c));
    let on = |p: &Vector2<f64>, q: &Vector2<f64>, r: &Vector2<f64>| {
        // r collinear with pq and within its bounding box
        r.x >= p.x.min(q.x) && r.x <= p.x.max(q.x) && r.y >= p.y.min(q.y) && r.y <= p.y.max(q.y)
    };
    if ((o1 > 0.0 && o2 < 0.0) || (o1 < 0.0 && o2 > 0.0))
        && ((o3 > 0.0 && o4 < 0.0) || (o3 < 0.0 && o4 > 0.0))
    {
        return true;
    }
    (o1 == 0.0 && on(a, b, c))
        || (o2 == 0.0 && on(a, b, d))
        || (o3 == 0.0 && on(c, d, a))
        || (o4 == 0.0 && on(c, d, b))
}

/// Triangulates a simple polygon (checked with [`check_polygon`]) by ear clipping, without adding
/// points. Clockwise input is accepted; the triangles are always counter-clockwise.
pub(super) fn polygon(field: &str, points: &[Vector2<f64>]) -> Result<Section, ShapeError> {
    check_polygon(field, points)?;
    let mut ring: Vec<u32> = (0..points.len() as u32).collect();
    if polygon_area(points) < 0.0 {
        ring.reverse();
    }
    let p = |i: u32| points[i as usize];
    let mut tris = Vec::with_capacity(points.len() - 2);
    while ring.len() > 3 {
        let m = ring.len();
        let ear = (0..m).find(|&k| {
            let (a, b, c) = (ring[(k + m - 1) % m], ring[k], ring[(k + 1) % m]);
            if tri_area(&p(a), &p(b), &p(c)) <= 0.0 {
                return false;
            }
            // No other remaining vertex may lie inside or on the candidate ear.
            ring.iter()
                .filter(|&&v| v != a && v != b && v != c)
                .all(|&v| !point_in_triangle(&p(v), &p(a), &p(b), &p(c)))
        });
        let Some(k) = ear else {
            return Err(ShapeError::invalid(
                field,
                format!("{} points", points.len()),
                "could not be triangulated (nearly self-touching polygon?)",
            ));
        };
        let m = ring.len();
        tris.push([ring[(k + m - 1) % m], ring[k], ring[(k + 1) % m]]);
        ring.remove(k);
    }
    tris.push([ring[0], ring[1], ring[2]]);
    Ok(Section {
        points: points.to_vec(),
        tris,
    })
}

/// True if `p` lies inside or on the boundary of the counter-clockwise triangle `(a, b, c)`.
fn point_in_triangle(
    p: &Vector2<f64>,
    a: &Vector2<f64>,
    b: &Vector2<f64>,
    c: &Vector2<f64>,
) -> bool {
    cross2(&(b - a), &(p - a)) >= 0.0
        && cross2(&(c - b), &(p - b)) >= 0.0
        && cross2(&(a - c), &(p - c)) >= 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn circle_section_area_and_orientation() {
        for (segments, rings) in [(8, 1), (16, 3), (24, 4), (40, 6)] {
            let s = circle(0.5, segments, rings);
            let exact_polygon = 0.5
                * f64::from(segments)
                * 0.25
                * (std::f64::consts::TAU / f64::from(segments)).sin();
            assert!(
                (s.area() - exact_polygon).abs() < 1e-12,
                "{segments}/{rings}"
            );
            assert!(s.tris.iter().all(|t| tri_area(
                &s.points[t[0] as usize],
                &s.points[t[1] as usize],
                &s.points[t[2] as usize]
            ) > 0.0));
            // Euler: a triangulated disk has T = 2V - B - 2 triangles (B boundary points).
            let v = s.points.len() as i64;
            assert_eq!(s.tris.len() as i64, 2 * v - i64::from(segments) - 2);
        }
    }

    #[test]
    fn circle_sections_have_no_slivers() {
        for segments in [8u32, 12, 16, 24, 32, 64] {
            let rings = default_rings(segments);
            let s = circle(1.0, segments, rings);
            let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
            for t in &s.tris {
                let p = t.map(|i| s.points[i as usize]);
                lo = lo.min(min_angle(&p).to_degrees());
                for k in 0..3 {
                    let a = p[(k + 1) % 3] - p[k];
                    let b = p[(k + 2) % 3] - p[k];
                    hi = hi.max((a.dot(&b) / (a.norm() * b.norm())).acos().to_degrees());
                }
            }
            println!("circle {segments} segments, {rings} rings: triangle angles {lo:.1}..{hi:.1} deg (tol >= 30)");
            assert!(lo >= 30.0);
        }
    }

    #[test]
    fn polygon_ear_clipping_and_checks() {
        // An L shape, clockwise.
        let l: Vec<Vector2<f64>> = [
            (0.0, 0.0),
            (0.0, 2.0),
            (1.0, 2.0),
            (1.0, 1.0),
            (2.0, 1.0),
            (2.0, 0.0),
        ]
        .iter()
        .map(|&(x, y)| Vector2::new(x, y))
        .collect();
        let s = polygon("polygon", &l).unwrap();
        assert_eq!(s.tris.len(), 4);
        assert!((s.area() - 3.0).abs() < 1e-12);
        let bow: Vec<Vector2<f64>> = [(0.0, 0.0), (1.0, 1.0), (1.0, 0.0), (0.0, 1.0)]
            .iter()
            .map(|&(x, y)| Vector2::new(x, y))
            .collect();
        let err = polygon("polygon", &bow).unwrap_err().to_string();
        println!("{err}");
        assert!(err.contains("intersect"), "{err}");
        let two = [Vector2::new(0.0, 0.0), Vector2::new(1.0, 0.0)];
        assert!(polygon("polygon", &two).is_err());
        let rect = rect(2.0, 1.0, 4, 2);
        assert!((rect.area() - 2.0).abs() < 1e-12);
        assert_eq!(default_rect_divisions(0.05, 0.004), (13, 1));
    }
}
