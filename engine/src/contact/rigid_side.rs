//! The rigid side of contact between dynamic rigid bodies and deformables.
//!
//! The coupling scheme of [`crate::contact`] lets the lighter side of a touching pair resolve the
//! contact, because the other side answers a step late. A deformable resolves its contacts with
//! rigid colliders inside its own step, which is stable when the rigid body is the heavier (a
//! 20 kg box on a foam block) and not when it is the lighter: a 0.5 kg box dropped onto a 4.7 kg
//! torus was handed the momentum of the torus's surface nodes and thrown upwards. For such pairs
//! the rigid solver resolves the contact:
//!
//! - at spawn, every deformable (with a contact surface, `collide`, and node masses) that some
//!   dynamic scene body is lighter than ([`RigidContext::resolves_with_surface`]) gets a fixed
//!   rapier body with a triangle-mesh collider of its surface: its material's friction, its
//!   contact thickness as rapier's contact skin, and a pair filter that lets it touch exactly the
//!   lighter dynamic scene bodies (robots' links are never among them: grasps and finger
//!   contacts stay with the deformable solvers);
//! - before every rigid step the collider is rebuilt from the nodes where the deformable's step
//!   left them (`sync_surface_colliders`);
//! - the deformable leaves those bodies out of its own contacts ([`WithoutRigidSide`]);
//! - after the rigid step the impulses rapier's contacts applied (normal and friction) are
//!   spread, opposite, over the corners of the touched triangles in proportion to barycentric
//!   weight times node mass, as for two deformables, into [`ContactImpulses`], which the
//!   deformable takes, relaxed, from its next step on (`surface_reactions`).
//!
//! The collider follows the nodes but has no velocity in rapier: the rigid body sees the surface
//! at rest at its current place (a surface moving under a body does not carry it by friction).

use bevy_ecs::prelude::*;
use nalgebra::Vector3;
use rapier3d::parry::bounding_volume::BoundingVolume;
use rapier3d::parry::query::PointQueryWithLocation;
use rapier3d::prelude::*;

use super::{closest_on_triangle, spread_over_corners, ContactImpulses, ContactSurface, RigidPart};
use crate::components::Object;
use crate::coupling::{ContactQuery, PointContact};
use crate::deformable::solver::deformable_ref;
use crate::math::{vec_from_rapier, vec_to_rapier};
use crate::rigid::{surface_user_data, RigidContext};

/// The deformable surfaces that have a collider in the rigid world (a resource inserted at
/// spawn when there is one; it never changes, so it is not part of the env state: a state file
/// restores the colliders under the same handles).
#[derive(Resource, Debug, Clone, Default)]
pub struct RigidSurfaces(pub Vec<RigidSurface>);

/// One deformable surface with a collider in the rigid world.
#[derive(Debug, Clone, Copy)]
pub struct RigidSurface {
    /// The deformable's entity.
    pub entity: Entity,
    /// Its scene object's index (keys its [`ContactImpulses`]).
    pub object: u32,
    /// Its total mass, kg: bodies lighter than this resolve their contact with it.
    pub mass: f64,
    /// Its collider.
    pub collider: ColliderHandle,
}

impl RigidSurfaces {
    /// The entry of a deformable entity, if it has a surface collider.
    pub fn of(&self, entity: Entity) -> Option<&RigidSurface> {
        self.0.iter().find(|s| s.entity == entity)
    }
}

/// The surface `triangles` over `nodes` as a rapier shape (`None` for a surface rapier refuses:
/// no triangles, or all degenerate), with its internal edges fixed (contact normals on an edge
/// limited by the neighbouring triangles': a box sliding over a flat belt caught on the edges
/// between its facets). Only duplicate vertices are merged, so triangle indices are kept.
pub(crate) fn surface_shape(nodes: &[Vector3<f64>], triangles: &[[u32; 3]]) -> Option<SharedShape> {
    let v: Vec<_> = nodes.iter().map(vec_to_rapier).collect();
    SharedShape::trimesh_with_flags(v, triangles.to_vec(), TriMeshFlags::FIX_INTERNAL_EDGES).ok()
}

/// After a scene spawned (its rigid bodies and deformables): gives a surface collider to every
/// deformable that some dynamic scene body is lighter than, and inserts [`RigidSurfaces`] when
/// there is one. Deformables are taken in scene order, so every env of a scene gets the same
/// handles.
pub(crate) fn add_surface_colliders(world: &mut World) {
    let mut q = world.query::<(Entity, &Object, &ContactSurface)>();
    let Some(rigid) = world.get_resource::<RigidContext>() else {
        return;
    };
    let mut wanted = Vec::new();
    for (entity, object, surface) in q.iter(world) {
        if !surface.collide {
            continue;
        }
        let Some(solver) = deformable_ref(world, entity) else {
            continue;
        };
        let Some(masses) = solver.node_masses().filter(|m| !m.is_empty()) else {
            continue;
        };
        let mass: f64 = masses.iter().sum();
        let pressed =
            solver.compression_modulus().is_some() && !rigid.scene_bodies_from(mass).is_empty();
        if !rigid.any_resolves_with_surface(mass) && !pressed {
            continue;
        }
        let Some(shape) = surface_shape(solver.node_positions(), &surface.triangles) else {
            continue;
        };
        let collider = ColliderBuilder::new(shape)
            .user_data(surface_user_data(object.index, mass))
            .friction(surface.friction as f32)
            .contact_skin(surface.thickness as f32)
            .active_hooks(ActiveHooks::FILTER_CONTACT_PAIRS)
            .build();
        wanted.push((object.index, entity, mass, collider));
    }
    if wanted.is_empty() {
        return;
    }
    wanted.sort_by_key(|w| w.0);
    let mut rigid = world.resource_mut::<RigidContext>();
    let rigid = &mut *rigid;
    let mut surfaces = Vec::with_capacity(wanted.len());
    for (object, entity, mass, collider) in wanted {
        let body = rigid.bodies.insert(RigidBodyBuilder::fixed().build());
        let collider = rigid
            .colliders
            .insert_with_parent(collider, body, &mut rigid.bodies);
        surfaces.push(RigidSurface {
            entity,
            object,
            mass,
            collider,
        });
    }
    world.insert_resource(RigidSurfaces(surfaces));
}

/// The solver and contact surface of a deformable entity.
pub(crate) fn solver_and_surface(
    world: &World,
    entity: Entity,
) -> Option<(
    &dyn crate::deformable::solver::DeformableSolver,
    &ContactSurface,
)> {
    Some((
        deformable_ref(world, entity)?,
        world.get::<ContactSurface>(entity)?,
    ))
}

/// A surface collider is rebuilt only when some node of its deformable is farther than this (m)
/// from where the collider has it. A new shape makes rapier start the pair's contacts afresh
/// (no warm start), and a body resting on a surface that trembles by less than this would
/// otherwise never keep its friction from one step to the next.
pub const SURFACE_REBUILD_DISTANCE: f64 = 1e-4;

/// Before every rigid step (after the deformables stepped): rebuilds each surface collider from
/// its deformable's nodes where they moved by more than [`SURFACE_REBUILD_DISTANCE`].
pub(crate) fn sync_surface_colliders(world: &mut World) {
    let (Some(surfaces), Some(rigid)) = (
        world.get_resource::<RigidSurfaces>(),
        world.get_resource::<RigidContext>(),
    ) else {
        return;
    };
    let mut shapes = Vec::with_capacity(surfaces.0.len());
    for s in &surfaces.0 {
        // a surface no body touches in this substep keeps its old shape
        if !rigid.any_resolves_with_surface(s.mass) && !rigid.is_supported(s.object) {
            continue;
        }
        let Some((solver, surface)) = solver_and_surface(world, s.entity) else {
            continue;
        };
        let nodes = solver.node_positions();
        let tol = SURFACE_REBUILD_DISTANCE * SURFACE_REBUILD_DISTANCE;
        let current = rigid
            .colliders
            .get(s.collider)
            .and_then(|c| c.shape().as_trimesh());
        let moved = current.is_none_or(|m| {
            m.vertices().len() != nodes.len()
                || m.vertices()
                    .iter()
                    .zip(nodes)
                    .any(|(v, p)| (vec_from_rapier(*v) - p).norm_squared() > tol)
        });
        if !moved {
            continue;
        }
        if let Some(shape) = surface_shape(nodes, &surface.triangles) {
            shapes.push((s.collider, shape));
        }
    }
    let mut rigid = world.resource_mut::<RigidContext>();
    for (h, shape) in shapes {
        if let Some(co) = rigid.colliders.get_mut(h) {
            co.set_shape(shape);
        }
    }
}

/// After every rigid step: hands each deformable the impulses the rigid bodies' contacts with its
/// surface collider applied, opposite, spread over the touched triangles' corners (barycentric
/// weight times node mass: every corner gets the same velocity change).
pub(crate) fn surface_reactions(world: &mut World) {
    let Some(surfaces) = world.get_resource::<RigidSurfaces>() else {
        return;
    };
    let rigid = world.resource::<RigidContext>();
    let mut owed: Vec<(u32, Vec<Vector3<f64>>)> = Vec::new();
    for s in &surfaces.0 {
        let Some((solver, surface)) = solver_and_surface(world, s.entity) else {
            continue;
        };
        let (Some(masses), nodes) = (solver.node_masses(), solver.node_positions()) else {
            continue;
        };
        let Some(mesh) = rigid
            .colliders
            .get(s.collider)
            .and_then(|c| c.shape().as_trimesh())
        else {
            continue;
        };
        let mut impulses: Option<Vec<Vector3<f64>>> = None;
        for (at, j) in impulses_on(rigid, s.collider) {
            // the surface collider sits at the world origin: its local points are world points
            let (_, (t, _)) = mesh.project_local_point_and_get_location(at, false);
            let Some(tri) = surface.triangles.get(t as usize) else {
                continue;
            };
            let [a, b, c] = tri.map(|i| nodes[i as usize]);
            let w = closest_on_triangle(&vec_from_rapier(at), &a, &b, &c).weights;
            let out = impulses.get_or_insert_with(|| vec![Vector3::zeros(); nodes.len()]);
            spread_over_corners(out, tri, w, masses, &j);
        }
        if let Some(j) = impulses {
            owed.push((s.object, j));
        }
    }
    if owed.is_empty() {
        return;
    }
    let mut impulses = world.resource_mut::<ContactImpulses>();
    for (object, j) in owed {
        let nodes = impulses.of(object, j.len());
        for (a, b) in nodes.iter_mut().zip(&j) {
            *a += b;
        }
    }
}

/// The impulses (N s, world frame) rapier's last step applied to surface collider `collider`,
/// non-zero ones only, each with its contact point on the surface (in the collider's frame).
fn impulses_on(
    rigid: &RigidContext,
    collider: ColliderHandle,
) -> impl Iterator<Item = (rapier3d::math::Vector, Vector3<f64>)> + '_ {
    rigid
        .narrow_phase
        .contact_pairs_with(collider)
        .flat_map(move |pair| {
            let first = pair.collider1 == collider;
            // what the solver solved: a composite shape's manifolds merged by normal (so the
            // touched triangle is found again from the contact point)
            pair.solver_manifolds().iter().flat_map(move |m| {
                let n = vec_from_rapier(m.data.normal);
                // the points the solver used (the others carry copied warm-start data only)
                m.data.solver_contacts.iter().filter_map(move |sc| {
                    let id = sc.contact_id[0] & !rapier3d::geometry::NEW_CONTACT_BIT;
                    let p = m.points.get(id as usize)?;
                    // rapier pushes the first collider's body by -normal x impulse plus the
                    // friction impulse `warmstart_tangent_world`; the second by the opposite
                    let on_first = -n * f64::from(p.data.impulse)
                        + vec_from_rapier(p.data.warmstart_tangent_world);
                    let (j, at) = if first {
                        (on_first, p.local_p1)
                    } else {
                        (-on_first, p.local_p2)
                    };
                    (j != Vector3::zeros()).then_some((at, j))
                })
            })
        })
}

/// A deformable's rigid query without the bodies that resolve their contact with it themselves
/// (their colliders still answer; their contacts are dropped).
pub struct WithoutRigidSide<'a> {
    inner: RigidPart<'a>,
    rigid: &'a RigidContext,
    surface: &'a RigidSurface,
    /// The dynamic scene bodies this deformable resolves, seen moving with the common motion
    /// of the body and the nodes touching it ([`inelastic_shifts`]).
    shifts: Vec<Shift>,
}

impl<'a> WithoutRigidSide<'a> {
    /// The rigid world's query for the deformable of `surface`.
    pub fn new(rigid: &'a RigidContext, surface: &'a RigidSurface) -> Self {
        Self {
            inner: RigidPart::Borrowed(rigid),
            rigid,
            surface,
            shifts: Vec::new(),
        }
    }

    /// [`WithoutRigidSide::new`], with the dynamic scene bodies the deformable resolves seen at
    /// their common velocity with the nodes touching them ([`inelastic_shifts`]).
    pub fn with_touching(
        rigid: &'a RigidContext,
        surface: &'a RigidSurface,
        solver: &dyn crate::deformable::DeformableSolver,
        thickness: f64,
    ) -> Self {
        let mut q = Self::new(rigid, surface);
        q.shifts = inelastic_shifts(rigid, surface, solver, thickness);
        q
    }
}

/// A body's motion as a deformable sees it, changed: `velocity(p) + dv + dw x (p - com)`.
#[derive(Clone, Copy, Debug)]
pub struct Shift {
    /// Body id.
    pub body: u32,
    /// Centre of mass, m.
    pub com: Vector3<f64>,
    /// Change of linear velocity, m/s.
    pub dv: Vector3<f64>,
    /// Change of angular velocity, rad/s.
    pub dw: Vector3<f64>,
}

/// For each dynamic scene body the deformable of `surface` resolves (a body on a layer it
/// presses onto a support, or one heavier than the deformable): the change from the body's
/// motion to the common rigid motion of the body (mass M, velocity v, inertia I, angular
/// velocity w) and the deformable's nodes within `thickness` + 2 mm of its colliders (masses
/// m_i at r_i from the centre of mass, velocities u_i): linear `(M v + sum m_i u_i) / (M + sum
/// m_i)`, angular `(I + sum m_i [r_i]^T [r_i])^-1 (I w + sum m_i r_i x (u_i - v'))` with v' that
/// linear velocity (momentum and angular momentum about the centre of mass kept).
///
/// Why: the deformable moves its touching nodes with the body it treats as a moving collider and
/// hands the body the impulse back after its step; seen at the body's own velocity, the nodes'
/// momentum change `m (v - u)` overshoots the body by `m / M` of their relative velocity, a mode
/// that flips sign every substep (a 2 kg box on the 2.7 kg foam block trembled at 1.55 cm/s,
/// ARCHITECTURE.md). Seen at the common velocity, the impulse the nodes take is exactly what
/// brings the body to that velocity, as an inelastic collision does.
pub fn inelastic_shifts(
    rigid: &RigidContext,
    surface: &RigidSurface,
    solver: &dyn crate::deformable::DeformableSolver,
    thickness: f64,
) -> Vec<Shift> {
    let (Some(v), Some(m)) = (solver.node_velocities(), solver.node_masses()) else {
        return Vec::new();
    };
    let x = solver.node_positions();
    let reach = thickness + super::SUPPORT_GAP;
    let mut out = Vec::new();
    for id in 0u32.. {
        let Some((h, _)) = rigid.body_of_id(id) else {
            break;
        };
        let Some(b) = rigid.bodies.get(h) else {
            continue;
        };
        if !b.is_dynamic()
            || !rigid.is_scene_body(b)
            || rigid.resolves_with_surface(id, surface.object, surface.mass)
        {
            continue;
        }
        // each collider with its box loosened by the reach: a cheap test before the distance
        let colliders: Vec<(&Collider, Aabb)> = b
            .colliders()
            .iter()
            .filter_map(|c| rigid.colliders.get(*c))
            .map(|co| (co, co.compute_aabb().loosened(reach as f32)))
            .collect();
        let com = vec_from_rapier(b.center_of_mass());
        let (mut mass, mut momentum) = (0.0, Vector3::zeros());
        let (mut inertia, mut angular) = (nalgebra::Matrix3::zeros(), Vector3::zeros());
        let mut first = Vector3::zeros();
        for (i, p) in x.iter().enumerate() {
            let q = vec_to_rapier(p);
            let touching = colliders.iter().any(|(co, aabb)| {
                aabb.contains_local_point(q)
                    && f64::from(co.shape().distance_to_point(co.position(), q, true)) <= reach
            });
            if touching {
                let mi = m.get(i).copied().unwrap_or(0.0);
                let ui = v.get(i).copied().unwrap_or_default();
                let r = p - com;
                mass += mi;
                momentum += ui * mi;
                inertia +=
                    (nalgebra::Matrix3::identity() * r.norm_squared() - r * r.transpose()) * mi;
                angular += r.cross(&ui) * mi;
                first += r * mi;
            }
        }
        let body_mass = f64::from(b.mass());
        let inv = b.mass_properties().effective_world_inv_inertia;
        let inv = nalgebra::Matrix3::new(
            inv.m11, inv.m12, inv.m13, inv.m12, inv.m22, inv.m23, inv.m13, inv.m23, inv.m33,
        )
        .cast::<f64>();
        let (Some(body_inertia), true) = (inv.try_inverse(), mass > 0.0 && body_mass > 0.0) else {
            continue;
        };
        let vb = vec_from_rapier(b.linvel());
        let wb = vec_from_rapier(b.angvel());
        let common = (vb * body_mass + momentum) / (body_mass + mass);
        let spin = (body_inertia + inertia).try_inverse().map_or(wb, |k| {
            k * (body_inertia * wb + angular - first.cross(&common))
        });
        out.push(Shift {
            body: id,
            com,
            dv: common - vb,
            dw: spin - wb,
        });
    }
    out
}

impl ContactQuery for WithoutRigidSide<'_> {
    fn contacts_near(&self, p: &Vector3<f64>, max_distance: f64, out: &mut Vec<PointContact>) {
        let from = out.len();
        self.inner.get().contacts_near(p, max_distance, out);
        let mut kept = from;
        for k in from..out.len() {
            let s = self.surface;
            if !self
                .rigid
                .resolves_with_surface(out[k].body, s.object, s.mass)
            {
                out[kept] = out[k];
                if let Some(sh) = self.shifts.iter().find(|sh| sh.body == out[k].body) {
                    let c = &mut out[kept];
                    c.velocity += sh.dv + sh.dw.cross(&(c.point - sh.com));
                }
                kept += 1;
            }
        }
        out.truncate(kept);
    }

    fn region(&self, lo: &Vector3<f64>, hi: &Vector3<f64>) -> Option<Box<dyn ContactQuery + '_>> {
        let inner = match self.inner.get().region(lo, hi) {
            Some(owned) => RigidPart::Owned(owned),
            None => RigidPart::Borrowed(self.inner.get()),
        };
        Some(Box::new(WithoutRigidSide {
            inner,
            rigid: self.rigid,
            surface: self.surface,
            shifts: self.shifts.clone(),
        }))
    }
}

/// The system set that rebuilds the surface colliders: after every deformable solver's set,
/// before the rigid step.
#[derive(bevy_ecs::schedule::SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub struct SurfaceSync;

/// Adds the collider rebuild (before the rigid step) and the reactions (after it); both run only
/// in worlds with [`RigidSurfaces`].
pub(crate) fn add_rigid_side_systems(app: &mut crate::SimApp) {
    use crate::app::SubstepSystems;
    use crate::rigid::RigidSystems;
    app.configure_sets(
        crate::Substep,
        SurfaceSync
            .in_set(SubstepSystems::Solve)
            .before(RigidSystems::Step),
    );
    app.add_systems(
        crate::Substep,
        sync_surface_colliders
            .run_if(resource_exists::<RigidSurfaces>)
            .in_set(SurfaceSync),
    );
    app.add_systems(
        crate::Substep,
        surface_reactions
            .run_if(resource_exists::<RigidSurfaces>)
            .in_set(SubstepSystems::Solve)
            .after(RigidSystems::Step),
    );
}
