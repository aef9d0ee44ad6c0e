//! How a dynamic rigid body pressing a deformable onto a support is coupled to it.
//!
//! [`crate::contact::rigid_side`] lets the lighter of a dynamic scene body and a deformable
//! resolve their contact, as for two deformables: the side that answers a step late must be the
//! heavier. For a deformable lying on a support that rule has a blind spot. A 2 kg box on a
//! 0.79 kg belt lying on the ground is the heavier, so the belt resolves it and the box gets the
//! reaction after the belt's step; but the belt squeezed between the box and the ground is a
//! spring of stiffness about `E A / h` (modulus, footprint, the 4 mm thickness) on the box, with
//! `k dt^2 / m` about 94: an explicit spring step that overshoots many times over, and the belt's
//! solve failed in the 3rd step. Seen from the box the belt is not light: the ground holds it up.
//! So where a deformable lies on a support under a body, the engine weighs the body against the
//! layer's stiffness between it and the support instead of against the layer's mass:
//!
//! - at the start of every physics step, for each deformable with a surface collider and a
//!   [`DeformableSolver::compression_modulus`](crate::deformable::solver::DeformableSolver::compression_modulus)
//!   and each dynamic scene body, the surface nodes within the body's reach (the surface's
//!   contact thickness, [`SUPPORT_GAP`], and the distance the body travels in a physics step)
//!   are taken one by one (a node on the body's surface too, along the body's outward normal
//!   there where its shape gives one: boxes, balls, convex hulls; not meshes or compounds): a ray from the node away from the body, through the deformable's own
//!   surface, finds the layer's far side (column height `h`), and the node counts if a fixed
//!   rigid collider is within the contact thickness plus [`SUPPORT_GAP`] of that point;
//! - they add up to `k = E sum(a / h)` (a: the node's share of the surface area), and
//!   `ratio = k dt^2 / m` over a scene substep ([`stiffness_ratios`]); a pair with no such node
//!   keeps the mass rule;
//! - above [`RIGID_SIDE_RATIO`] the body resolves the contact itself against the surface
//!   collider, as a lighter body does by the mass rule (the pair filter and
//!   [`crate::contact::rigid_side::WithoutRigidSide`] read the same list,
//!   [`RigidContext::set_sides`]), and the support takes the reactions the layer is handed;
//! - at or below it the layer resolves, whichever is heavier, and the engine splits each
//!   substep of this physics step into [`coupling_substeps`], so that the ratio over a substep
//!   falls below [`STABLE_RATIO`] (the step's cost grows by that factor).
//!
//! Measured (`tests/contact_scenes.rs`): the 2 kg box on the belt on the ground, ratio about 94,
//! rigid side; the 20 kg box on a 10 cm foam block (E 1e5 Pa) 1.04, two substeps; a 5 kg box
//! on it 4.4, three (with one it bounced off the block at 0.85 m/s in its 2nd step, and resolved
//! by the rigid solver it was thrown off too: the block's top is light and not held by the
//! ground within one step); a belt hanging free between clamps has no supported node. The
//! choice depends on the positions at the physics step's start only, so it is the same on any
//! thread count and after a state file is loaded (it is not part of the state).

use bevy_ecs::prelude::*;
use nalgebra::Vector3;
use rapier3d::parry::bounding_volume::BoundingVolume;
use rapier3d::prelude::*;

use super::rigid_side::{solver_and_surface, surface_shape, RigidSurfaces};
use super::ContactSurface;
use crate::math::{vec_from_rapier, vec_to_rapier};
use crate::rigid::{surface_of, RigidContext};

/// A body resolves its contact with a deformable on a support itself when the layer's stiffness
/// under it over a scene substep, `k dt^2`, exceeds this multiple of its mass.
pub const RIGID_SIDE_RATIO: f64 = 16.0;

/// Below this `k dt^2 / m` a deformable on a support resolves a body's contact in the scene's
/// substeps; between it and [`RIGID_SIDE_RATIO`] the engine splits each substep into
/// `ceil(sqrt(ratio / STABLE_RATIO))` (at most [`MAX_COUPLING_SUBSTEPS`]), so that the ratio
/// over a substep falls below it.
pub const STABLE_RATIO: f64 = 0.5;

/// The most substeps the engine splits a scene substep into (`ceil(sqrt(RIGID_SIDE_RATIO /
/// STABLE_RATIO))`).
pub const MAX_COUPLING_SUBSTEPS: u32 = 6;

pub use super::SUPPORT_GAP;

/// A ray through the layer starts this far (m) inside it, clear of the node's own triangles.
const RAY_START: f64 = 1e-5;

/// At the start of every physics step: sets the sides of the pairs in which a dynamic scene body
/// presses a deformable onto a support ([`RigidContext::set_sides`]) and returns the coupling substeps of the step (1 in worlds
/// without such pairs, and in scenes that step deformables at their own rate,
/// `physics.deformable_substeps`).
pub fn plan_physics_step(world: &mut World) -> u32 {
    let pressed = stiffness_ratios(world);
    let Some(mut rigid) = world.get_resource_mut::<RigidContext>() else {
        return 1;
    };
    let mut sides = Vec::new();
    let mut worst: f64 = 0.0;
    for p in pressed.iter().filter(|p| p.ratio > 0.0) {
        let body_resolves = p.ratio > RIGID_SIDE_RATIO;
        if !body_resolves {
            worst = worst.max(p.ratio);
        }
        sides.push((p.object, p.body, body_resolves));
    }
    if !sides.is_empty() || rigid.has_sides() {
        rigid.set_sides(sides);
    }
    let own_rate = world
        .get_resource::<crate::SimSettings>()
        .is_none_or(|s| s.deformable_stride > 1 || s.deformable_inner > 1);
    if own_rate {
        return 1;
    }
    coupling_substeps(worst)
}

/// Before the substeps of every physics step: the sides and coupling substeps of the pairs on a
/// support ([`plan_physics_step`]).
fn plan_coupling(world: &mut World) {
    let coupling = plan_physics_step(world);
    world.resource_mut::<crate::SimSettings>().coupling_substeps = coupling;
}

/// Adds the coupling plan between [`crate::app::PhysicsSystems::ApplyActions`] and the substeps
/// (`StepSimulation`); it runs only in worlds with [`RigidSurfaces`].
pub(crate) fn add_coupling_plan(app: &mut crate::SimApp) {
    use crate::app::PhysicsSystems;
    app.add_systems(
        crate::PhysicsStep,
        plan_coupling
            .run_if(resource_exists::<RigidSurfaces>)
            .after(PhysicsSystems::ApplyActions)
            .before(PhysicsSystems::StepSimulation),
    );
}

/// The coupling substeps for a deformable-resolved pair of ratio `ratio` ([`STABLE_RATIO`]).
pub fn coupling_substeps(ratio: f64) -> u32 {
    if ratio <= STABLE_RATIO {
        return 1;
    }
    ((ratio / STABLE_RATIO).sqrt().ceil() as u32).clamp(1, MAX_COUPLING_SUBSTEPS)
}

/// A deformable and a dynamic scene body, weighed against each other.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PressedPair {
    /// The deformable's scene object index.
    pub object: u32,
    /// The body.
    pub body: RigidBodyHandle,
    /// `k dt^2 / m`: the layer's supported stiffness under the body over a scene substep,
    /// against the body's mass (0 where nothing is supported); the body resolves the contact
    /// itself above [`RIGID_SIDE_RATIO`].
    pub ratio: f64,
}

/// Every deformable with a surface collider and a compression modulus, paired with every
/// dynamic scene body, in the current positions; see the module's
/// documentation. Empty in worlds without such pairs.
pub fn stiffness_ratios(world: &World) -> Vec<PressedPair> {
    let (Some(surfaces), Some(rigid), Some(settings)) = (
        world.get_resource::<RigidSurfaces>(),
        world.get_resource::<RigidContext>(),
        world.get_resource::<crate::SimSettings>(),
    ) else {
        return Vec::new();
    };
    let (dt, step) = (settings.scene_substep_dt(), settings.dt);
    let mut out = Vec::new();
    let mut fixed = None;
    for s in &surfaces.0 {
        let bodies = rigid.scene_bodies_from(0.0);
        if bodies.is_empty() {
            continue;
        }
        let Some((solver, surface)) = solver_and_surface(world, s.entity) else {
            continue;
        };
        let Some(modulus) = solver.compression_modulus() else {
            continue;
        };
        // rebuilt after the last deformable step only while some pair used it
        let current = (rigid.any_resolves_with_surface(s.mass) || rigid.is_supported(s.object))
            .then(|| rigid.colliders.get(s.collider).map(|c| c.shared_shape()))
            .flatten();
        let mut layer = None;
        let fixed = fixed.get_or_insert_with(|| fixed_colliders(rigid));
        for (h, mass) in bodies {
            let under = Under {
                rigid,
                nodes: solver.node_positions(),
                surface,
                travel_time: step,
                current,
                fixed,
            };
            out.push(PressedPair {
                object: s.object,
                body: h,
                ratio: modulus * under.area_over_height(h, &mut layer) * dt * dt / mass,
            });
        }
    }
    out
}

/// The outward unit normal of collider `co`'s shape at its boundary point nearest `p` (world
/// frame), where the shape defines one; `None` for composite shapes (meshes, compounds: the
/// feature alone does not name the part) and shapes without feature normals.
fn outward_normal(co: &Collider, p: &Vector3<f64>) -> Option<Vector3<f64>> {
    if co.shape().as_composite_shape().is_some() {
        return None;
    }
    let pose = co.position();
    let (proj, feature) = co
        .shape()
        .project_point_and_get_feature(pose, vec_to_rapier(p));
    let local = pose.inverse_transform_point(proj.point);
    let n = co.shape().feature_normal_at_point(0, feature, local)?;
    vec_from_rapier(pose.rotation * n).try_normalize(1e-12)
}

/// The fixed rigid colliders (on fixed bodies or none; not deformables' surface colliders): what
/// can hold a layer up. Gathered at most once per physics step, for the first deformable with
/// bodies to weigh.
fn fixed_colliders(rigid: &RigidContext) -> Vec<&Collider> {
    rigid
        .colliders
        .iter()
        .map(|(_, co)| co)
        .filter(|co| {
            co.parent()
                .and_then(|b| rigid.bodies.get(b))
                .is_none_or(|b| b.is_fixed())
                && surface_of(co.user_data).is_none()
        })
        .collect()
}

/// A deformable's surface for rays and each node's share of its area (0 for inner nodes), built
/// once per surface and substep, when a body comes near.
struct Layer {
    mesh: SharedShape,
    areas: Vec<f64>,
}

impl Layer {
    /// The layer of `triangles` over `nodes`; its ray mesh is `current` (the surface collider's
    /// shape, when the rigid side kept it within `SURFACE_REBUILD_DISTANCE` of the nodes) or
    /// built afresh.
    fn new(
        nodes: &[Vector3<f64>],
        triangles: &[[u32; 3]],
        current: Option<&SharedShape>,
    ) -> Option<Self> {
        let mut areas = vec![0.0; nodes.len()];
        for t in triangles {
            let [a, b, c] = t.map(|i| nodes[i as usize]);
            let third = (b - a).cross(&(c - a)).norm() / 6.0;
            for i in t {
                areas[*i as usize] += third;
            }
        }
        Some(Self {
            mesh: match current {
                Some(shape) => shape.clone(),
                None => surface_shape(nodes, triangles)?,
            },
            areas,
        })
    }
}

/// One deformable's nodes and surface in the rigid world of one substep.
struct Under<'a> {
    rigid: &'a RigidContext,
    nodes: &'a [Vector3<f64>],
    surface: &'a ContactSurface,
    /// How long the body travels before the next look (s): a physics step.
    travel_time: f64,
    /// The fixed rigid colliders that can support a layer ([`fixed_colliders`]).
    fixed: &'a [&'a Collider],
    /// The surface collider's shape, if the rigid side rebuilt it after the last deformable step
    /// (it had a pair then): the nodes are within `SURFACE_REBUILD_DISTANCE` of it.
    current: Option<&'a SharedShape>,
}

impl Under<'_> {
    /// `sum(a / h)` (m) over the surface nodes touching body `body` whose column through the
    /// layer, away from the body, ends on a fixed collider.
    fn area_over_height(&self, body: RigidBodyHandle, layer: &mut Option<Layer>) -> f64 {
        let Some(b) = self.rigid.bodies.get(body) else {
            return 0.0;
        };
        let reach = self.surface.thickness
            + SUPPORT_GAP
            + vec_from_rapier(b.linvel()).norm() * self.travel_time;
        let mut sum = 0.0;
        for co in b
            .colliders()
            .iter()
            .filter_map(|c| self.rigid.colliders.get(*c))
        {
            let aabb = co.compute_aabb().loosened(reach as f32);
            for (i, p) in self.nodes.iter().enumerate() {
                if !aabb.contains_local_point(vec_to_rapier(p)) {
                    continue;
                }
                if layer.is_none() {
                    *layer = Layer::new(self.nodes, &self.surface.triangles, self.current);
                }
                let Some(l) = layer.as_ref() else {
                    return 0.0;
                };
                if l.areas[i] == 0.0 {
                    continue;
                }
                let proj = co
                    .shape()
                    .project_point(co.position(), vec_to_rapier(p), false);
                let to = p - vec_from_rapier(proj.point);
                let dist = to.norm();
                if !proj.is_inside && dist > reach {
                    continue;
                }
                // away from the body: into the layer; a node on the body's surface (a contact
                // holds it there at rest) along the body's outward normal at that point (it
                // was skipped, and whether a resting node sat 1e-9 m off the surface or not
                // decided the coupling substeps)
                let inward = if dist >= 1e-9 {
                    if proj.is_inside {
                        -to / dist
                    } else {
                        to / dist
                    }
                } else {
                    match outward_normal(co, p) {
                        Some(n) => n,
                        None => continue,
                    }
                };
                if let Some(h) = self.supported_column(l, p, &inward) {
                    sum += l.areas[i] / h;
                }
            }
        }
        sum
    }

    /// The height (m) of the layer's column from surface node `p` along `inward`, if its far end
    /// rests on a fixed collider.
    fn supported_column(
        &self,
        layer: &Layer,
        p: &Vector3<f64>,
        inward: &Vector3<f64>,
    ) -> Option<f64> {
        let start = p + inward * RAY_START;
        let ray = Ray::new(vec_to_rapier(&start), vec_to_rapier(inward));
        let toi = layer.mesh.cast_local_ray(&ray, 10.0, false)?;
        let h = RAY_START + f64::from(toi);
        let end = vec_to_rapier(&(p + inward * h));
        let gap = (self.surface.thickness + SUPPORT_GAP) as f32;
        let on_fixed = self
            .fixed
            .iter()
            .any(|co| co.shape().distance_to_point(co.position(), end, true) <= gap);
        on_fixed.then_some(h)
    }
}
