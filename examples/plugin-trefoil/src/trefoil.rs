//! The trefoil-knot tube: a closed tube of tetrahedra along the curve
//! `scale * (sin t + 2 sin 2t, cos t - 2 cos 2t, -sin 3t)`, `t` in `[0, 2 pi)`.
//!
//! Each of `stations` cross-sections is a regular polygon of `segments` rim points around a centre
//! point, placed in a rotation-minimising frame (parallel transport, with the closing twist spread
//! evenly so the tube closes on itself). Neighbouring cross-sections bound triangular prisms (one
//! per fan triangle); each prism is split into three tetrahedra by the rule "every quadrilateral
//! face is cut by the diagonal through its lowest-numbered node", which makes neighbouring prisms
//! agree on shared faces (a conforming mesh). Tetrahedra are oriented positively.
//!
//! Volume: the mesh volume is close to `A * L` (polygon area times curve length; Pappus).

use std::f64::consts::TAU;

use serde::Deserialize;

type V3 = [f64; 3];

fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}
fn unit(a: V3) -> V3 {
    scale(a, 1.0 / norm(a))
}

/// Parameters of `Gen(name: "acme.trefoil", params: (...))`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrefoilParams {
    /// Size of the knot, m (the curve spans about `6 * scale`).
    pub scale: f64,
    /// Tube radius, m.
    pub radius: f64,
    /// Rim points of the cross-section polygon (default 8).
    #[serde(default = "default_segments")]
    pub segments: u32,
    /// Cross-sections along the curve (default 96).
    #[serde(default = "default_stations")]
    pub stations: u32,
}

fn default_segments() -> u32 {
    8
}
fn default_stations() -> u32 {
    96
}

/// A point of the centre curve, m.
pub fn curve(p: &TrefoilParams, t: f64) -> V3 {
    scale(
        [
            t.sin() + 2.0 * (2.0 * t).sin(),
            t.cos() - 2.0 * (2.0 * t).cos(),
            -(3.0 * t).sin(),
        ],
        p.scale,
    )
}

/// First derivative of the centre curve, m per unit t.
fn curve_d1(p: &TrefoilParams, t: f64) -> V3 {
    scale(
        [
            t.cos() + 4.0 * (2.0 * t).cos(),
            -t.sin() + 4.0 * (2.0 * t).sin(),
            -3.0 * (3.0 * t).cos(),
        ],
        p.scale,
    )
}

/// Second derivative of the centre curve.
fn curve_d2(p: &TrefoilParams, t: f64) -> V3 {
    scale(
        [
            -t.sin() - 8.0 * (2.0 * t).sin(),
            -t.cos() + 8.0 * (2.0 * t).cos(),
            9.0 * (3.0 * t).sin(),
        ],
        p.scale,
    )
}

/// Length of the centre curve, m (composite Simpson rule, 4096 intervals).
pub fn curve_length(p: &TrefoilParams) -> f64 {
    let n = 4096;
    let h = TAU / n as f64;
    let f = |i: usize| norm(curve_d1(p, i as f64 * h));
    let mut s = f(0) + f(n);
    for i in 1..n {
        s += if i % 2 == 1 { 4.0 } else { 2.0 } * f(i);
    }
    s * h / 3.0
}

/// Area of the cross-section polygon, m^2.
pub fn section_area(p: &TrefoilParams) -> f64 {
    let m = f64::from(p.segments);
    0.5 * m * (TAU / m).sin() * p.radius * p.radius
}

/// Checks the parameters, naming the one at fault.
pub fn validate(p: &TrefoilParams) -> Result<(), String> {
    if !(p.scale.is_finite() && p.scale > 0.0 && p.scale <= 100.0) {
        return Err(format!("scale = {}: a length in (0, 100] m", p.scale));
    }
    if !(p.radius.is_finite() && p.radius > 0.0) {
        return Err(format!("radius = {}: a radius > 0 m", p.radius));
    }
    if !(3..=64).contains(&p.segments) {
        return Err(format!("segments = {}: an integer in 3..=64", p.segments));
    }
    if !(12..=4096).contains(&p.stations) {
        return Err(format!(
            "stations = {}: an integer in 12..=4096",
            p.stations
        ));
    }
    // The tube must not fold on itself: radius below the smallest radius of curvature...
    let samples = 4 * p.stations as usize;
    let ts: Vec<f64> = (0..samples)
        .map(|i| TAU * i as f64 / samples as f64)
        .collect();
    let min_bend = ts
        .iter()
        .map(|&t| {
            let (d1, d2) = (curve_d1(p, t), curve_d2(p, t));
            norm(d1).powi(3) / norm(cross(d1, d2))
        })
        .fold(f64::INFINITY, f64::min);
    if p.radius >= 0.9 * min_bend {
        return Err(format!(
            "radius = {}: the tube folds on itself; the smallest radius of curvature is {:.4} m (use radius < {:.4})",
            p.radius,
            min_bend,
            0.9 * min_bend
        ));
    }
    // ...and strands that pass each other must stay apart.
    let points: Vec<V3> = ts.iter().map(|&t| curve(p, t)).collect();
    let arc: Vec<f64> = ts
        .iter()
        .map(|&t| norm(curve_d1(p, t)) * TAU / samples as f64)
        .collect();
    let total: f64 = arc.iter().sum();
    let mut cum = vec![0.0; samples];
    for i in 1..samples {
        cum[i] = cum[i - 1] + arc[i - 1];
    }
    let mut clearance = f64::INFINITY;
    for i in 0..samples {
        for j in i + 1..samples {
            let along = (cum[j] - cum[i]).min(total - (cum[j] - cum[i]));
            if along > 4.0 * p.radius {
                clearance = clearance.min(norm(sub(points[i], points[j])));
            }
        }
    }
    if clearance <= 2.2 * p.radius {
        return Err(format!(
            "radius = {}: strands of the knot pass {:.4} m apart, so the tube intersects itself (use radius < {:.4}, or a larger scale)",
            p.radius,
            clearance,
            clearance / 2.2
        ));
    }
    Ok(())
}

/// Rotates `v` about the unit axis `k` by `angle` (Rodrigues).
fn rotate(v: V3, k: V3, angle: f64) -> V3 {
    let (s, c) = angle.sin_cos();
    add(
        add(scale(v, c), scale(cross(k, v), s)),
        scale(k, dot(k, v) * (1.0 - c)),
    )
}

/// Rotation-minimising normals along the closed curve, closing twist spread evenly.
fn frames(tangents: &[V3]) -> Vec<V3> {
    let t0 = tangents[0];
    let helper = if t0[2].abs() < 0.9 {
        [0.0, 0.0, 1.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let mut normals = vec![unit(cross(t0, helper))];
    let transport = |n: V3, t: V3| unit(sub(n, scale(t, dot(n, t))));
    for t in &tangents[1..] {
        let prev = normals[normals.len() - 1];
        normals.push(transport(prev, *t));
    }
    // Back at the start, the transported normal is the first one turned by `twist` about t0.
    let back = transport(normals[normals.len() - 1], t0);
    let twist = dot(cross(normals[0], back), t0).atan2(dot(normals[0], back));
    let n = tangents.len() as f64;
    normals
        .iter()
        .zip(tangents)
        .enumerate()
        .map(|(k, (nk, tk))| rotate(*nk, *tk, -twist * k as f64 / n))
        .collect()
}

/// The prism's vertices reordered so that the lowest global index comes first (Dompierre et al.).
const PRISM_ROTATIONS: [[usize; 6]; 6] = [
    [0, 1, 2, 3, 4, 5],
    [1, 2, 0, 4, 5, 3],
    [2, 0, 1, 5, 3, 4],
    [3, 5, 4, 0, 2, 1],
    [4, 3, 5, 1, 0, 2],
    [5, 4, 3, 2, 1, 0],
];

/// Splits prism `v` (bottom triangle 0 1 2, top 3 4 5 above them) into three tetrahedra whose
/// quadrilateral faces are cut through their lowest-numbered node.
fn split_prism(v: [u32; 6]) -> [[u32; 4]; 3] {
    let first = (0..6).min_by_key(|&i| v[i]).unwrap_or(0);
    let r = PRISM_ROTATIONS[first].map(|i| v[i]);
    if r[1].min(r[5]) < r[2].min(r[4]) {
        [
            [r[0], r[1], r[2], r[5]],
            [r[0], r[1], r[5], r[4]],
            [r[0], r[4], r[5], r[3]],
        ]
    } else {
        [
            [r[0], r[1], r[2], r[4]],
            [r[0], r[4], r[2], r[5]],
            [r[0], r[4], r[5], r[3]],
        ]
    }
}

fn signed_volume(n: &[V3], t: [u32; 4]) -> f64 {
    let [a, b, c, d] = t.map(|i| n[i as usize]);
    dot(cross(sub(b, a), sub(c, a)), sub(d, a)) / 6.0
}

/// The tetrahedral tube: `(nodes, tets)`. Node `k * (segments + 1)` is the centre of station `k`,
/// the next `segments` nodes its rim.
pub fn mesh(p: &TrefoilParams) -> (Vec<V3>, Vec<[u32; 4]>) {
    let s = p.stations as usize;
    let m = p.segments as usize;
    let ts: Vec<f64> = (0..s).map(|k| TAU * k as f64 / s as f64).collect();
    let tangents: Vec<V3> = ts.iter().map(|&t| unit(curve_d1(p, t))).collect();
    let normals = frames(&tangents);
    let mut nodes = Vec::with_capacity(s * (m + 1));
    for k in 0..s {
        let c = curve(p, ts[k]);
        let (n, b) = (normals[k], cross(tangents[k], normals[k]));
        nodes.push(c);
        for j in 0..m {
            let phi = TAU * j as f64 / m as f64;
            let offset = add(
                scale(n, p.radius * phi.cos()),
                scale(b, p.radius * phi.sin()),
            );
            nodes.push(add(c, offset));
        }
    }
    let id = |k: usize, j: usize| ((k % s) * (m + 1) + j) as u32;
    let mut tets = Vec::with_capacity(3 * s * m);
    for k in 0..s {
        for j in 1..=m {
            let j2 = j % m + 1;
            let prism = [
                id(k, 0),
                id(k, j),
                id(k, j2),
                id(k + 1, 0),
                id(k + 1, j),
                id(k + 1, j2),
            ];
            for mut t in split_prism(prism) {
                if signed_volume(&nodes, t) < 0.0 {
                    t.swap(2, 3);
                }
                tets.push(t);
            }
        }
    }
    (nodes, tets)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> TrefoilParams {
        TrefoilParams {
            scale: 0.1,
            radius: 0.02,
            segments: 8,
            stations: 96,
        }
    }

    #[test]
    fn tube_volume_is_section_area_times_length_and_tets_are_positive() {
        let p = params();
        validate(&p).unwrap();
        let (nodes, tets) = mesh(&p);
        let volumes: Vec<f64> = tets.iter().map(|t| signed_volume(&nodes, *t)).collect();
        let min = volumes.iter().cloned().fold(f64::INFINITY, f64::min);
        let total: f64 = volumes.iter().sum();
        let expected = section_area(&p) * curve_length(&p);
        println!(
            "{} nodes, {} tets, volume {total:.6e} m^3, A*L {expected:.6e}, ratio {:.5}, smallest tet {min:.3e}",
            nodes.len(),
            tets.len(),
            total / expected
        );
        assert!(min > 0.0);
        assert!((total / expected - 1.0).abs() < 0.02);
    }

    #[test]
    fn a_tube_too_thick_for_the_knot_is_refused_with_the_limit() {
        let mut p = params();
        p.radius = 0.2;
        let e = validate(&p).unwrap_err();
        assert!(e.starts_with("radius = 0.2"), "{e}");
    }
}
