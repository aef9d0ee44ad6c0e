//! Analytic colliders implementing [`ContactQuery`] for tests and benchmarks (the engine answers
//! the same queries with parry against the rapier world).

use crate::coupling::{ContactQuery, PointContact};
use nalgebra::{Isometry3, Point3, Vector3};

/// Geometry of an analytic collider.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// Half-space `normal . (x - point) <= 0` (solid below the plane).
    Plane {
        /// A point on the plane, world frame, m.
        point: Vector3<f64>,
        /// Unit outward normal.
        normal: Vector3<f64>,
    },
    /// Oriented box.
    Box {
        /// Pose of the box centre.
        pose: Isometry3<f64>,
        /// Half extents, m.
        half_extents: Vector3<f64>,
    },
    /// Sphere.
    Sphere {
        /// Centre, world frame, m.
        center: Vector3<f64>,
        /// Radius, m.
        radius: f64,
    },
    /// Solid cylinder whose axis is the local z axis of `pose` (a disc when short).
    Cylinder {
        /// Pose of the cylinder centre.
        pose: Isometry3<f64>,
        /// Radius, m.
        radius: f64,
        /// Half height along the axis, m.
        half_height: f64,
    },
}

/// One analytic collider: shape, friction, body id and (uniform) surface velocity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnalyticCollider {
    /// Geometry.
    pub shape: Shape,
    /// Coulomb friction coefficient.
    pub friction: f64,
    /// Body id reported in contacts (`u32::MAX`: static, no reactions).
    pub body: u32,
    /// Surface velocity (translation only), m/s.
    pub velocity: Vector3<f64>,
}

impl AnalyticCollider {
    /// A static collider with friction `friction` and no body.
    pub fn fixed(shape: Shape, friction: f64) -> Self {
        AnalyticCollider {
            shape,
            friction,
            body: u32::MAX,
            velocity: Vector3::zeros(),
        }
    }

    /// Closest surface point, outward normal and signed distance of `p`.
    pub fn closest(&self, p: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>, f64) {
        match self.shape {
            Shape::Plane { point, normal } => {
                let d = normal.dot(&(p - point));
                (p - normal * d, normal, d)
            }
            Shape::Sphere { center, radius } => {
                let r = p - center;
                let l = r.norm();
                let n = if l > 0.0 { r / l } else { Vector3::z() };
                (center + n * radius, n, l - radius)
            }
            Shape::Box {
                pose,
                half_extents: h,
            } => {
                let l = pose.inverse_transform_point(&Point3::from(*p)).coords;
                let outside = l.x.abs() > h.x || l.y.abs() > h.y || l.z.abs() > h.z;
                let (q, n, d) = if outside {
                    let q = Vector3::new(
                        l.x.clamp(-h.x, h.x),
                        l.y.clamp(-h.y, h.y),
                        l.z.clamp(-h.z, h.z),
                    );
                    let r = l - q;
                    let d = r.norm();
                    (q, r / d, d)
                } else {
                    let gaps = [h.x - l.x.abs(), h.y - l.y.abs(), h.z - l.z.abs()];
                    let mut k = 0;
                    for j in 1..3 {
                        if gaps[j] < gaps[k] {
                            k = j;
                        }
                    }
                    let s = if l[k] >= 0.0 { 1.0 } else { -1.0 };
                    let mut q = l;
                    q[k] = s * h[k];
                    let mut n = Vector3::zeros();
                    n[k] = s;
                    (q, n, -gaps[k])
                };
                (
                    pose.transform_point(&Point3::from(q)).coords,
                    pose.rotation * n,
                    d,
                )
            }
            Shape::Cylinder {
                pose,
                radius,
                half_height,
            } => {
                let l = pose.inverse_transform_point(&Point3::from(*p)).coords;
                let r = (l.x * l.x + l.y * l.y).sqrt();
                let radial = if r > 0.0 {
                    Vector3::new(l.x / r, l.y / r, 0.0)
                } else {
                    Vector3::x()
                };
                let inside = r <= radius && l.z.abs() <= half_height;
                let (q, n, d) = if inside {
                    let side_gap = radius - r;
                    let cap_gap = half_height - l.z.abs();
                    if side_gap < cap_gap {
                        (
                            Vector3::new(radial.x * radius, radial.y * radius, l.z),
                            radial,
                            -side_gap,
                        )
                    } else {
                        let s = if l.z >= 0.0 { 1.0 } else { -1.0 };
                        (
                            Vector3::new(l.x, l.y, s * half_height),
                            Vector3::z() * s,
                            -cap_gap,
                        )
                    }
                } else {
                    let rq = r.min(radius);
                    let q = Vector3::new(
                        radial.x * rq,
                        radial.y * rq,
                        l.z.clamp(-half_height, half_height),
                    );
                    let v = l - q;
                    let d = v.norm();
                    (q, v / d, d)
                };
                (
                    pose.transform_point(&Point3::from(q)).coords,
                    pose.rotation * n,
                    d,
                )
            }
        }
    }

    /// Whether `p` is strictly inside the collider deeper than `tolerance` (m).
    pub fn contains(&self, p: &Vector3<f64>, tolerance: f64) -> bool {
        self.closest(p).2 < -tolerance
    }
}

/// A set of analytic colliders.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AnalyticColliders {
    /// The colliders, queried in order.
    pub colliders: Vec<AnalyticCollider>,
}

impl AnalyticColliders {
    /// A set from a list.
    pub fn new(colliders: Vec<AnalyticCollider>) -> Self {
        AnalyticColliders { colliders }
    }

    /// Number of points of `points` inside any collider deeper than `tolerance` (m).
    pub fn count_inside(&self, points: &[Vector3<f64>], tolerance: f64) -> usize {
        points
            .iter()
            .filter(|p| self.colliders.iter().any(|c| c.contains(p, tolerance)))
            .count()
    }
}

impl ContactQuery for AnalyticColliders {
    fn contacts_near(&self, p: &Vector3<f64>, max_distance: f64, out: &mut Vec<PointContact>) {
        for c in &self.colliders {
            let (point, normal, distance) = c.closest(p);
            if distance <= max_distance {
                out.push(PointContact {
                    point,
                    normal,
                    distance,
                    friction: c.friction,
                    body: c.body,
                    velocity: c.velocity,
                });
            }
        }
    }
}

/// Layer crossings of a cloth folded onto itself (layers roughly horizontal, `bottom` below):
/// the number of `top` particles whose xy projection falls inside a `bottom` triangle and that lie
/// below that triangle's plane there. 0 while the layers never pass through each other.
pub fn layer_crossings(positions: &[Vector3<f64>], top: &[u32], bottom: &[[u32; 3]]) -> usize {
    let mut cross = 0;
    for &i in top {
        let q = positions[i as usize];
        for tri in bottom {
            let [x, y, z] = tri.map(|v| positions[v as usize]);
            let det = (y.x - x.x) * (z.y - x.y) - (z.x - x.x) * (y.y - x.y);
            if det.abs() < 1e-14 {
                continue;
            }
            let u = ((y.x - q.x) * (z.y - q.y) - (z.x - q.x) * (y.y - q.y)) / det;
            let v = ((z.x - q.x) * (x.y - q.y) - (x.x - q.x) * (z.y - q.y)) / det;
            let w = 1.0 - u - v;
            if u >= 0.0 && v >= 0.0 && w >= 0.0 {
                if q.z < u * x.z + v * y.z + w * z.z {
                    cross += 1;
                }
                break;
            }
        }
    }
    cross
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_closest_points() {
        let b = AnalyticCollider::fixed(
            Shape::Box {
                pose: Isometry3::translation(0.0, 0.0, 0.25),
                half_extents: Vector3::repeat(0.25),
            },
            0.5,
        );
        let (q, n, d) = b.closest(&Vector3::new(0.0, 0.0, 0.6));
        assert!(
            (q - Vector3::new(0.0, 0.0, 0.5)).norm() < 1e-15 && (n - Vector3::z()).norm() < 1e-15
        );
        assert!((d - 0.1).abs() < 1e-15);
        let (_, n, d) = b.closest(&Vector3::new(0.2, 0.0, 0.25));
        assert!((n - Vector3::x()).norm() < 1e-15 && (d + 0.05).abs() < 1e-15);
        let (_, _, d) = b.closest(&Vector3::new(0.35, 0.0, 0.6));
        assert!((d - (0.01f64 + 0.01).sqrt()).abs() < 1e-15);
    }

    #[test]
    fn cylinder_and_sphere() {
        let c = AnalyticCollider::fixed(
            Shape::Cylinder {
                pose: Isometry3::identity(),
                radius: 0.1,
                half_height: 0.01,
            },
            0.5,
        );
        let (_, n, d) = c.closest(&Vector3::new(0.0, 0.05, 0.11));
        assert!((d - 0.1).abs() < 1e-15 && (n - Vector3::z()).norm() < 1e-15);
        let (_, n, d) = c.closest(&Vector3::new(0.3, 0.0, 0.0));
        assert!((d - 0.2).abs() < 1e-15 && (n - Vector3::x()).norm() < 1e-15);
        let s = AnalyticCollider::fixed(
            Shape::Sphere {
                center: Vector3::zeros(),
                radius: 1.0,
            },
            0.0,
        );
        assert!((s.closest(&Vector3::new(0.0, 2.0, 0.0)).2 - 1.0).abs() < 1e-15);
        assert!(s.contains(&Vector3::new(0.0, 0.5, 0.0), 0.0));
    }
}
