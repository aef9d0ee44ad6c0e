//! Which side of a pair of a dynamic rigid body and a deformable resolves their contact: the
//! rules shared by the rigid world's pair filter ([`crate::rigid`]) and the deformables' contact
//! query ([`crate::contact::rigid_side`]); it depends on rapier only, so both can use it.

use rapier3d::prelude::*;

/// `user_data` of the colliders of dynamic scene bodies (robots' links carry none): the bodies
/// that may resolve their contact with a deformable themselves (`body_resolves`).
pub const SCENE_BODY_TAG: u128 = 0x5343_454e << 96;

/// Whether a rigid body whose collider carries `tag` resolves its contact with a deformable of
/// total mass `surface_mass` itself: a dynamic scene body lighter than the deformable. Then the
/// rigid solver treats the deformable's surface as a collider and the deformable is handed the
/// reaction; otherwise the deformable resolves the contact (the coupling scheme of
/// `crate::contact`: the lighter side resolves).
pub(crate) fn rigid_resolves(body: &RigidBody, tag: u128, surface_mass: f64) -> bool {
    tag == SCENE_BODY_TAG && body.is_dynamic() && f64::from(body.mass()) < surface_mass
}

/// Whether dynamic scene body `handle` (its collider's tag `tag`) resolves its contact with the
/// deformable of scene object `object` (total mass `surface_mass`) itself: as
/// [`crate::contact::support`] chose for this physics step where the deformable lies on a
/// support under the body (`sides`: `(object, body, the body resolves)`), else by mass
/// ([`rigid_resolves`]).
pub(crate) fn body_resolves(
    sides: &[(u32, RigidBodyHandle, bool)],
    body: &RigidBody,
    handle: RigidBodyHandle,
    tag: u128,
    object: u32,
    surface_mass: f64,
) -> bool {
    match sides.iter().find(|s| s.0 == object && s.1 == handle) {
        Some(s) => s.2 && tag == SCENE_BODY_TAG && body.is_dynamic(),
        None => rigid_resolves(body, tag, surface_mass),
    }
}
