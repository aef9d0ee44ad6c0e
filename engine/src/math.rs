//! Conversions between our nalgebra (f64) types and rapier/parry's glam (f32) types.
//!
//! This is the only module that touches both; everything else uses nalgebra `f64` in SI units.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use rapier3d::math::{Pose, Rotation, Vector};

/// nalgebra f64 vector -> rapier vector.
pub fn vec_to_rapier(v: &Vector3<f64>) -> Vector {
    Vector::new(v.x as f32, v.y as f32, v.z as f32)
}

/// rapier vector -> nalgebra f64 vector.
pub fn vec_from_rapier(v: Vector) -> Vector3<f64> {
    Vector3::new(f64::from(v.x), f64::from(v.y), f64::from(v.z))
}

/// nalgebra unit quaternion -> rapier rotation.
pub fn rot_to_rapier(q: &UnitQuaternion<f64>) -> Rotation {
    let q = q.quaternion();
    Rotation::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32).normalize()
}

/// rapier rotation -> nalgebra unit quaternion.
pub fn rot_from_rapier(q: Rotation) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(
        f64::from(q.w),
        f64::from(q.x),
        f64::from(q.y),
        f64::from(q.z),
    ))
}

/// nalgebra isometry -> rapier pose.
pub fn pose_to_rapier(p: &Isometry3<f64>) -> Pose {
    Pose::from_parts(
        vec_to_rapier(&p.translation.vector),
        rot_to_rapier(&p.rotation),
    )
}

/// rapier pose -> nalgebra isometry.
pub fn pose_from_rapier(p: &Pose) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(vec_from_rapier(p.translation)),
        rot_from_rapier(p.rotation),
    )
}

/// The pose a fraction `t` of the way from `a` to `b`: translation linearly, rotation by slerp
/// (`t >= 1` gives `b` exactly; for rotations half a turn apart, where slerp has no unique
/// path, the nearer end).
pub fn interpolate_pose(a: &Isometry3<f64>, b: &Isometry3<f64>, t: f64) -> Isometry3<f64> {
    if t >= 1.0 {
        return *b;
    }
    let tr = a.translation.vector.lerp(&b.translation.vector, t);
    let rot = a
        .rotation
        .try_slerp(&b.rotation, t, 1e-12)
        .unwrap_or(if t < 0.5 { a.rotation } else { b.rotation });
    Isometry3::from_parts(Translation3::from(tr), rot)
}

/// Roll-pitch-yaw (extrinsic x, then y, then z; radians) -> rotation.
pub fn rpy(roll: f64, pitch: f64, yaw: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(roll, pitch, yaw)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_round_trip_within_f32() {
        let p = Isometry3::from_parts(Translation3::new(1.0, -2.0, 0.5), rpy(0.3, -0.2, 1.4));
        let back = pose_from_rapier(&pose_to_rapier(&p));
        let dt = (back.translation.vector - p.translation.vector).norm();
        let dr = back.rotation.angle_to(&p.rotation);
        println!(
            "pose round trip: translation error {dt:.2e} m, rotation error {dr:.2e} rad (tol 1e-6)"
        );
        assert!(dt < 1e-6 && dr < 1e-6);
    }
}
