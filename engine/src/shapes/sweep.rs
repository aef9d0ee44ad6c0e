//! Volume meshing by sweeping a triangulated cross-section through a sequence of frames, and the frames
//! of the supported paths (line, polyline, arc, helix, revolution).

use nalgebra::{Rotation3, Unit, Vector2, Vector3};

use super::error::ShapeError;
use super::mesh::VolumeMesh;
use super::section::Section;

/// Where a cross-section is placed: profile point `(u, v)` goes to `origin + u * eu + v * ev`.
#[derive(Clone, Debug)]
pub(super) struct Frame {
    /// Position of the profile origin, metres.
    pub origin: Vector3<f64>,
    /// Unit direction of the profile's `u` axis.
    pub eu: Vector3<f64>,
    /// Unit direction of the profile's `v` axis.
    pub ev: Vector3<f64>,
}

impl Frame {
    fn place(&self, p: &Vector2<f64>) -> Vector3<f64> {
        self.origin + p.x * self.eu + p.y * self.ev
    }
}

/// Sweeps `section` through `frames` (one station per frame; `closed` joins the last station to the
/// first) and splits every triangular prism into three tetrahedra.
///
/// Node `k * n_points + i` is profile point `i` at station `k`. Each prism's quad faces are split along
/// the diagonal through the face's lowest-global-index vertex, so adjacent prisms (in the section and
/// along the path, including the seam of a closed sweep) share identical triangles. Tetrahedron
/// orientation is decided in the straight reference prism (profile coordinates and station parameter),
/// so a path that folds the real prisms inside out yields inverted tetrahedra, which the final
/// [`VolumeMesh::check`] reports instead of hiding.
pub(super) fn sweep_volume(
    shape: &str,
    section: &Section,
    frames: &[Frame],
    closed: bool,
) -> Result<VolumeMesh, ShapeError> {
    let np = section.points.len();
    let ns = frames.len();
    if ns < 2 || (closed && ns < 3) {
        return Err(ShapeError::Unsupported {
            shape: shape.to_string(),
            reason: format!(
                "a sweep needs at least {} stations, got {ns}",
                if closed { 3 } else { 2 }
            ),
        });
    }
    let n_prisms = if closed { ns } else { ns - 1 };
    super::error::check_count(
        &format!("{shape}: tetrahedra"),
        (n_prisms as u64)
            .saturating_mul(section.tris.len() as u64)
            .saturating_mul(3),
    )?;
    super::error::check_count(
        &format!("{shape}: nodes"),
        (ns as u64).saturating_mul(np as u64),
    )?;

    let mut nodes = Vec::with_capacity(ns * np);
    for f in frames {
        nodes.extend(section.points.iter().map(|p| f.place(p)));
    }
    // Handedness of the sweep: +1 if (eu x ev) points along the direction of travel.
    let c = section.centroid();
    let travel = frames[1].place(&c) - frames[0].place(&c);
    let sigma = frames[0].eu.cross(&frames[0].ev).dot(&travel);
    if sigma.is_nan() || sigma == 0.0 {
        return Err(ShapeError::Unsupported {
            shape: shape.to_string(),
            reason: "the path does not move the cross-section out of its plane".into(),
        });
    }
    let sigma = sigma.signum();

    let mut tets = Vec::with_capacity(n_prisms * section.tris.len() * 3);
    for s0 in 0..n_prisms {
        let s1 = (s0 + 1) % ns;
        let (lo, hi) = (s0.min(s1), s0.max(s1));
        // Reference coordinate along the path: 0 at s0, sigma at s1.
        let t_of = |station: usize| if station == s0 { 0.0 } else { sigma };
        for tri in &section.tris {
            let mut t = *tri;
            t.sort_unstable();
            let [x, y, z] = t.map(|i| i as usize);
            let node = |station: usize, i: usize| (station * np + i) as u32;
            let candidates = [
                [(lo, x), (lo, y), (lo, z), (hi, z)],
                [(lo, x), (lo, y), (hi, y), (hi, z)],
                [(lo, x), (hi, x), (hi, y), (hi, z)],
            ];
            for cand in candidates {
                let r = cand.map(|(st, i)| {
                    let p = section.points[i];
                    Vector3::new(p.x, p.y, t_of(st))
                });
                let det = (r[1] - r[0]).cross(&(r[2] - r[0])).dot(&(r[3] - r[0]));
                let mut tet = cand.map(|(st, i)| node(st, i));
                if det < 0.0 {
                    tet.swap(2, 3);
                }
                tets.push(tet);
            }
        }
    }
    let mesh = VolumeMesh { nodes, tets };
    mesh.check().map_err(|e| ShapeError::Unsupported {
        shape: shape.to_string(),
        reason: format!(
            "the swept mesh is invalid ({e}); the path bends too sharply for the profile's size, \
             or the sections are degenerate"
        ),
    })?;
    Ok(mesh)
}

/// A right-handed frame `(n, b)` perpendicular to the unit tangent `t` (`n x b = t`), with `b` as close
/// to +z as possible (or `n` along +x when `t` is nearly vertical).
pub(super) fn initial_frame(t: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    if t.z.abs() < 0.999 {
        let b = (Vector3::z() - t.z * t).normalize();
        (b.cross(t), b)
    } else {
        let n = (Vector3::x() - t.x * t).normalize();
        (n, t.cross(&n))
    }
}

/// Frames along sampled path points with unit tangents, by parallel transport (rotation-minimising),
/// starting from [`initial_frame`]. For a closed path the twist accumulated around the loop is spread
/// evenly over the stations so the seam matches. Profile `u` maps to the normal `n`, `v` to the
/// binormal `b`.
pub(super) fn transport_frames(
    shape: &str,
    points: &[Vector3<f64>],
    tangents: &[Vector3<f64>],
    closed: bool,
) -> Result<Vec<Frame>, ShapeError> {
    let reverses = || ShapeError::Unsupported {
        shape: shape.to_string(),
        reason: "the path turns back on itself (a 180 degree turn); the profile cannot follow it"
            .into(),
    };
    let rotate = |from: &Vector3<f64>, to: &Vector3<f64>| -> Result<Rotation3<f64>, ShapeError> {
        if from.dot(to) < -1.0 + 1e-9 {
            return Err(reverses());
        }
        Ok(Rotation3::rotation_between(from, to).unwrap_or_else(Rotation3::identity))
    };
    let Some(t0) = tangents.first() else {
        return Ok(Vec::new());
    };
    let (mut n, _) = initial_frame(t0);
    let mut normals = vec![n];
    for k in 1..tangents.len() {
        n = rotate(&tangents[k - 1], &tangents[k])? * n;
        // Re-orthogonalise against round-off drift.
        n = (n - n.dot(&tangents[k]) * tangents[k]).normalize();
        normals.push(n);
    }
    if closed && tangents.len() > 1 {
        let last = tangents.len() - 1;
        let end = rotate(&tangents[last], t0)? * normals[last];
        let n0 = normals[0];
        let twist = n0.cross(&end).dot(t0).atan2(n0.dot(&end));
        let count = tangents.len() as f64;
        for (k, (nk, tk)) in normals.iter_mut().zip(tangents).enumerate() {
            let axis = Unit::new_normalize(*tk);
            *nk = Rotation3::from_axis_angle(&axis, -twist * k as f64 / count) * *nk;
        }
    }
    Ok(points
        .iter()
        .zip(tangents)
        .zip(&normals)
        .map(|((p, t), n)| Frame {
            origin: *p,
            eu: *n,
            ev: t.cross(n),
        })
        .collect())
}

/// Points along a path and their unit tangents.
pub(super) type PathSamples = (Vec<Vector3<f64>>, Vec<Vector3<f64>>);

/// Samples a polyline: each edge is split into pieces about `total_len / segments` long (at least one
/// per edge). Returns points and unit tangents; a vertex's tangent bisects its two edges. `closed`
/// joins the last point to the first (the first point is not repeated at the end).
pub(super) fn sample_polyline(
    shape: &str,
    vertices: &[Vector3<f64>],
    closed: bool,
    segments: u32,
) -> Result<PathSamples, ShapeError> {
    let nv = vertices.len();
    let n_edges = if closed { nv } else { nv - 1 };
    let edge = |e: usize| vertices[(e + 1) % nv] - vertices[e];
    let total: f64 = (0..n_edges).map(|e| edge(e).norm()).sum();
    let mut pieces = Vec::with_capacity(n_edges);
    let mut count: u64 = 0;
    for e in 0..n_edges {
        let p = ((f64::from(segments) * edge(e).norm() / total).round() as u64).max(1);
        count += p;
        pieces.push(p);
    }
    super::error::check_count(&format!("{shape}: path stations"), count)?;
    let mut points = Vec::with_capacity(count as usize + 1);
    let mut tangents = Vec::with_capacity(count as usize + 1);
    for e in 0..n_edges {
        let d = edge(e);
        let dir = d.normalize();
        let at_vertex = if e == 0 && !closed {
            dir
        } else {
            let prev = edge((e + n_edges - 1) % n_edges).normalize();
            let bis = prev + dir;
            if bis.norm() < 1e-9 {
                return Err(ShapeError::Unsupported {
                    shape: shape.to_string(),
                    reason: format!("the path turns back on itself at point {e}"),
                });
            }
            bis.normalize()
        };
        points.push(vertices[e]);
        tangents.push(at_vertex);
        for k in 1..pieces[e] {
            points.push(vertices[e] + d * (k as f64 / pieces[e] as f64));
            tangents.push(dir);
        }
    }
    if !closed {
        points.push(vertices[nv - 1]);
        tangents.push(edge(n_edges - 1).normalize());
    }
    Ok((points, tangents))
}

#[cfg(test)]
mod tests {
    use super::super::section;
    use super::*;

    #[test]
    fn straight_prism_split_is_conforming_and_positive() {
        let s = section::circle(0.1, 12, 2);
        let frames: Vec<Frame> = (0..5)
            .map(|k| Frame {
                origin: Vector3::new(0.0, 0.0, 0.05 * k as f64),
                eu: Vector3::x(),
                ev: Vector3::y(),
            })
            .collect();
        let m = sweep_volume("test", &s, &frames, false).unwrap();
        let census = m.face_census();
        assert_eq!(census.overshared, 0);
        assert_eq!(census.boundary, m.boundary_faces().len());
        let surf = m.boundary_surface();
        assert!(surf.is_closed());
        assert!((surf.enclosed_volume() - m.volume()).abs() < 1e-12 * m.volume());
        assert!((m.volume() - s.area() * 0.2).abs() < 1e-12);
        // Left-handed frames (ev x eu along travel) must still give positive tetrahedra.
        let mirrored: Vec<Frame> = frames
            .iter()
            .map(|f| Frame {
                origin: f.origin,
                eu: f.ev,
                ev: f.eu,
            })
            .collect();
        let m2 = sweep_volume("test", &s, &mirrored, false).unwrap();
        assert_eq!(m2.quality().inverted, 0);
    }

    #[test]
    fn frames_are_right_handed() {
        for t in [
            Vector3::x(),
            Vector3::z(),
            -Vector3::z(),
            Vector3::new(1.0, 2.0, 3.0).normalize(),
        ] {
            let (n, b) = initial_frame(&t);
            assert!((n.cross(&b) - t).norm() < 1e-12, "{t:?}");
        }
        let (n, b) = initial_frame(&Vector3::x());
        assert!((n - Vector3::y()).norm() < 1e-12 && (b - Vector3::z()).norm() < 1e-12);
    }
}
