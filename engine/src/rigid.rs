//! Rigid physics with rapier: static, dynamic and kinematic bodies, and the coupling API the
//! deformable plugins use (closest points against colliders, reactions back onto bodies).
//!
//! All rapier state lives in [`RigidContext`] (a resource, part of the env state: a snapshot is a
//! clone of every rapier set, so a restore reproduces the uninterrupted run bit for bit). The
//! rapier step runs once per substep in [`RigidSystems::Step`] inside `SubstepSystems::Solve`;
//! deformable solvers order themselves `.before(RigidSystems::Step)` and push their
//! [`Reaction`]s, which are applied as forces (F = J / dt) in that same step: rapier silently
//! ignores impulses on multibody links. After the step each touched body gets back exactly the
//! force and torque it carried before (controllers' forces survive; reaction forces are removed).

use std::any::Any;

use bevy_ecs::prelude::*;
use nalgebra::{Isometry3, Vector3};
use parry3d::bounding_volume::Aabb;
use parry3d::partitioning::{Bvh, BvhBuildStrategy};
use rapier3d::prelude::*;

use crate::app::{PhysicsSystems, Plugin, SimErrors, SubstepSystems};
use crate::codec::{Decoder, Encoder, Persist, StateError};
use crate::components::{Object, Pose, Velocity};
use crate::coupling::{ContactQuery, PointContact, Reaction};
use crate::math::{
    interpolate_pose, pose_from_rapier, pose_to_rapier, vec_from_rapier, vec_to_rapier,
};
use crate::scene::{MaterialDesc, RigidKind, RigidModel, RigidShape};
use crate::side::{body_resolves, rigid_resolves};
use crate::state::{mismatch, StateHasher, Stateful};
use crate::SimApp;

/// Sets of the rigid plugin.
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub enum RigidSystems {
    /// The rapier step (in `SubstepSystems::Solve`).
    Step,
    /// Rigid poses and velocities copied to the components (in `PhysicsSystems::Writeback`);
    /// plugins that also write `Pose` (robots' root entities) order themselves after it.
    Writeback,
}

/// The system set of one deformable solver, by name (`fem.solid`, `pbd.cloth`, a plugin's
/// own): [`add_deformable_systems`](crate::deformable::add_deformable_systems) creates one per
/// solver inside `SubstepSystems::Solve`, chained in registration order and all before
/// [`RigidSystems::Step`], so that their contact queries and reactions have a fixed order (no
/// ambiguity between two solvers that both push reactions). In `PhysicsStep` the same sets are
/// chained inside `PhysicsSystems::Writeback` for the systems that write `DeformableNodes`.
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub struct DeformableSystems(pub &'static str);

/// Handle of an object's rapier body.
#[derive(Component, Debug, Clone, Copy, PartialEq, Eq)]
pub struct RigidRef(pub RigidBodyHandle);

/// Adds rigid physics (rapier) to an app.
pub struct RigidPlugin;

impl Plugin for RigidPlugin {
    fn name(&self) -> &str {
        "modesuite.rigid"
    }

    fn build(&self, app: &mut SimApp) {
        app.insert_resource(RigidContext::new());
        app.register_stateful::<RigidContext>();
        app.register_stateful_component::<Pose>();
        app.register_stateful_component::<Velocity>();
        app.configure_sets(
            crate::Substep,
            RigidSystems::Step.in_set(SubstepSystems::Solve),
        );
        app.add_systems(crate::Substep, rigid_step.in_set(RigidSystems::Step));
        app.add_systems(
            crate::PhysicsStep,
            rigid_writeback
                .in_set(PhysicsSystems::Writeback)
                .in_set(RigidSystems::Writeback),
        );
    }
}

/// `user_data` of the colliders of dynamic scene bodies ([`crate::side`]).
pub use crate::side::SCENE_BODY_TAG;
/// `user_data` tag (bits 96..128) of a deformable surface's collider; bits 0..32 hold its scene
/// object's index and bits 32..96 the body's total mass (f64 bits): [`surface_user_data`].
pub const SURFACE_TAG: u128 = 0x5355_5246 << 96;
const TAG_MASK: u128 = 0xffff_ffff << 96;

/// The `user_data` of the collider of scene object `object`'s deformable surface, of total
/// mass `mass` kg.
pub fn surface_user_data(object: u32, mass: f64) -> u128 {
    SURFACE_TAG | (u128::from(mass.to_bits()) << 32) | u128::from(object)
}

/// The scene object index and total mass of a deformable surface's collider `user_data`.
pub fn surface_of(user_data: u128) -> Option<(u32, f64)> {
    (user_data & TAG_MASK == SURFACE_TAG).then(|| {
        let mass = f64::from_bits((user_data >> 32) as u64);
        (user_data as u32, mass)
    })
}

/// rapier's pair filter for deformable surfaces' colliders (they carry
/// `ActiveHooks::FILTER_CONTACT_PAIRS`; other pairs are never asked): a surface touches the
/// bodies that resolve their contact with it (`side::body_resolves`) and nothing else.
struct SurfaceFilter<'a>(&'a [(u32, RigidBodyHandle, bool)]);

impl PhysicsHooks for SurfaceFilter<'_> {
    fn filter_contact_pair(&self, c: &PairFilterContext) -> Option<SolverFlags> {
        let (c1, c2) = (c.colliders.get(c.collider1)?, c.colliders.get(c.collider2)?);
        let ((object, mass), other, handle) =
            match (surface_of(c1.user_data), surface_of(c2.user_data)) {
                (Some(s), None) => (s, c2, c.rigid_body2?),
                (None, Some(s)) => (s, c1, c.rigid_body1?),
                _ => return None,
            };
        let body = c.bodies.get(handle)?;
        body_resolves(self.0, body, handle, other.user_data, object, mass)
            .then_some(SolverFlags::COMPUTE_RIGID_IMPULSES)
    }
}

/// All rapier state of one env, plus the entity <-> body map and pending reactions.
#[derive(Resource)]
pub struct RigidContext {
    /// Rigid bodies.
    pub bodies: RigidBodySet,
    /// Colliders.
    pub colliders: ColliderSet,
    /// Impulse joints.
    pub impulse_joints: ImpulseJointSet,
    /// Multibody joints (robots).
    pub multibody_joints: MultibodyJointSet,
    /// Islands (sleeping).
    pub islands: IslandManager,
    /// Broad phase.
    pub broad_phase: BroadPhaseBvh,
    /// Narrow phase (contact manifolds, warm-start impulses).
    pub narrow_phase: NarrowPhase,
    /// CCD solver.
    pub ccd: CCDSolver,
    soft_bodies: SoftBodySet,
    pipeline: PhysicsPipeline,
    /// Solver parameters (dt is set from the scene's substep each step).
    pub params: IntegrationParameters,
    gravity: Vector3<f64>,
    /// Body id (index) -> (handle, entity). Ids are what [`PointContact::body`] carries.
    body_ids: Vec<(RigidBodyHandle, Entity)>,
    /// Reactions pushed by deformables, applied as forces in the next rapier step.
    pending: Vec<Reaction>,
    /// Pose of every body id at the start of the last rapier step (empty after bodies were
    /// moved outside a step): what [`RigidContext::body_pose_between`] interpolates from.
    step_start: Vec<Isometry3<f64>>,
    /// `(surface object, body, the body resolves)`: the sides of the pairs in which a dynamic
    /// scene body presses a deformable onto a support in this physics step
    /// ([`crate::contact::support`]; other pairs go by mass); derived from the positions at
    /// each physics step's start, so not part of the state.
    sides: Vec<(u32, RigidBodyHandle, bool)>,
    /// Query acceleration: a BVH over the colliders' current AABBs, leaf -> collider.
    query_bvh: Bvh,
    query_leaves: Vec<QueryLeaf>,
    /// The colliders moved since `query_bvh` was built: rebuilt by
    /// [`RigidContext::refresh_queries`] before the next contact query (a robot-only scene
    /// never pays for it).
    queries_stale: bool,
}

/// The rigid world's state: rapier's sets as rapier serialises them (contact manifolds and
/// warm-start impulses included) and the coupling's pending reactions.
#[derive(Clone, serde::Serialize, serde::Deserialize)]
struct RigidState {
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    ccd: CCDSolver,
    soft_bodies: SoftBodySet,
    pending: Vec<Reaction>,
    step_start: Vec<Isometry3<f64>>,
}

impl Default for RigidContext {
    fn default() -> Self {
        Self::new()
    }
}

impl RigidContext {
    /// An empty rigid world with gravity -z.
    pub fn new() -> Self {
        Self {
            bodies: RigidBodySet::new(),
            colliders: ColliderSet::new(),
            impulse_joints: ImpulseJointSet::new(),
            multibody_joints: MultibodyJointSet::new(),
            islands: IslandManager::new(),
            broad_phase: BroadPhaseBvh::new(),
            narrow_phase: NarrowPhase::new(),
            ccd: CCDSolver::new(),
            soft_bodies: SoftBodySet::new(),
            pipeline: PhysicsPipeline::new(),
            params: IntegrationParameters::default(),
            gravity: Vector3::new(0.0, 0.0, -9.81),
            body_ids: Vec::new(),
            pending: Vec::new(),
            step_start: Vec::new(),
            sides: Vec::new(),
            query_bvh: Bvh::new(),
            query_leaves: Vec::new(),
            queries_stale: true,
        }
    }

    /// Sets gravity, m/s^2, world frame.
    pub fn set_gravity(&mut self, g: Vector3<f64>) {
        self.gravity = g;
    }

    /// Gravity, m/s^2.
    pub fn gravity(&self) -> Vector3<f64> {
        self.gravity
    }

    /// Adds a body for a compiled rigid object and returns its handle.
    pub fn add_body(
        &mut self,
        entity: Entity,
        pose: &Isometry3<f64>,
        model: &RigidModel,
        material: &MaterialDesc,
    ) -> RigidBodyHandle {
        let builder = match model.kind {
            RigidKind::Static => RigidBodyBuilder::fixed(),
            RigidKind::Dynamic => RigidBodyBuilder::dynamic()
                .linvel(vec_to_rapier(&model.linear_velocity))
                .angvel(vec_to_rapier(&model.angular_velocity)),
            RigidKind::Kinematic => RigidBodyBuilder::kinematic_position_based(),
        };
        let body = builder.pose(pose_to_rapier(pose)).build();
        let handle = self.bodies.insert(body);
        let collider = collider_builder(&model.shape)
            .friction(material.friction as f32)
            .restitution(material.restitution as f32);
        let collider = match model.mass {
            Some(m) => collider.mass(m as f32),
            None => collider.density(material.density as f32),
        };
        let collider = match model.kind {
            RigidKind::Dynamic => collider.user_data(SCENE_BODY_TAG),
            _ => collider,
        };
        self.colliders
            .insert_with_parent(collider.build(), handle, &mut self.bodies);
        self.body_ids.push((handle, entity));
        self.queries_stale = true;
        handle
    }

    /// Registers a body created elsewhere (robots) so deformable contacts can name it.
    pub fn register_body(&mut self, handle: RigidBodyHandle, entity: Entity) -> u32 {
        self.body_ids.push((handle, entity));
        (self.body_ids.len() - 1) as u32
    }

    /// The body id ([`PointContact::body`]) of a handle.
    pub fn body_id(&self, handle: RigidBodyHandle) -> Option<u32> {
        self.body_ids
            .iter()
            .position(|(h, _)| *h == handle)
            .map(|i| i as u32)
    }

    /// Handle and entity of a body id.
    pub fn body_of_id(&self, id: u32) -> Option<(RigidBodyHandle, Entity)> {
        self.body_ids.get(id as usize).copied()
    }

    /// Whether `b` is a scene body (its colliders carry [`SCENE_BODY_TAG`]; robots' links do not).
    pub fn is_scene_body(&self, b: &RigidBody) -> bool {
        self.tag_of(b) == SCENE_BODY_TAG
    }

    /// The `user_data` of a body's first collider (robots' links: 0; [`SCENE_BODY_TAG`]).
    fn tag_of(&self, b: &RigidBody) -> u128 {
        b.colliders()
            .first()
            .and_then(|c| self.colliders.get(*c))
            .map_or(0, |c| c.user_data)
    }

    /// Whether body id `body` resolves its contact with the deformable of scene object `object`
    /// (total mass `surface_mass` kg) itself (by mass, or as chosen for a deformable on a
    /// support; then the deformable leaves that body out of its own contacts;
    /// [`crate::contact::rigid_side`], [`crate::contact::support`]).
    pub fn resolves_with_surface(&self, body: u32, object: u32, surface_mass: f64) -> bool {
        let Some((h, b)) = self
            .body_of_id(body)
            .and_then(|(h, _)| Some((h, self.bodies.get(h)?)))
        else {
            return false;
        };
        body_resolves(&self.sides, b, h, self.tag_of(b), object, surface_mass)
    }

    /// Whether any dynamic scene body is lighter than `surface_mass` kg (such a body always
    /// resolves its contact with a deformable of that mass).
    pub fn any_resolves_with_surface(&self, surface_mass: f64) -> bool {
        self.body_ids.iter().any(|(h, _)| {
            self.bodies
                .get(*h)
                .is_some_and(|b| rigid_resolves(b, self.tag_of(b), surface_mass))
        })
    }

    /// The dynamic scene bodies (not robots' links) of at least `mass` kg, in body-id order:
    /// handle and mass.
    pub fn scene_bodies_from(&self, mass: f64) -> Vec<(RigidBodyHandle, f64)> {
        self.body_ids
            .iter()
            .filter_map(|(h, _)| {
                let b = self.bodies.get(*h)?;
                let m = f64::from(b.mass());
                (b.is_dynamic() && self.is_scene_body(b) && m >= mass).then_some((*h, m))
            })
            .collect()
    }

    /// Sets the sides `(surface object, body, the body resolves)` of the pairs on a support in
    /// this physics step ([`crate::contact::support`]).
    pub fn set_sides(&mut self, sides: Vec<(u32, RigidBodyHandle, bool)>) {
        self.sides = sides;
    }

    /// Whether any pair on a support has its side chosen in this physics step.
    pub fn has_sides(&self) -> bool {
        !self.sides.is_empty()
    }

    /// Whether some body resolves its contact with surface object `object` in this physics step
    /// because it presses it onto a support.
    pub fn is_supported(&self, object: u32) -> bool {
        self.sides.iter().any(|s| s.0 == object && s.2)
    }

    /// Current pose (`world_from_body`) of a body id.
    pub fn body_pose(&self, id: u32) -> Option<Isometry3<f64>> {
        let (h, _) = self.body_of_id(id)?;
        self.bodies.get(h).map(|b| pose_from_rapier(b.position()))
    }

    /// Pose of a body id a fraction `s` (0..=1) of the way through the last rapier step: its
    /// pose at that step's start interpolated towards its current pose (translation linearly,
    /// rotation by slerp, [`interpolate_pose`]); `s >= 1`, a body that did not exist then, or any body after
    /// [`RigidContext::bodies_moved`] gives [`RigidContext::body_pose`] exactly. What
    /// deformables stepping several times per rigid substep follow
    /// (`physics.deformable_substeps`): the last rigid substep's motion, subdivided, one substep
    /// behind as a single deformable step per substep is.
    pub fn body_pose_between(&self, id: u32, s: f64) -> Option<Isometry3<f64>> {
        let now = self.body_pose(id)?;
        Some(match self.step_start.get(id as usize) {
            Some(start) => interpolate_pose(start, &now, s.max(0.0)),
            None => now,
        })
    }

    /// Appends the world positions (m) of the rigid contact points whose separation was at most
    /// `max_distance` m (negative: penetration) after the last rapier step: the midpoint of the
    /// two surface points of every tracked point of every contact manifold, in the narrow
    /// phase's pair order.
    pub fn contact_points(&self, max_distance: f64, out: &mut Vec<Vector3<f64>>) {
        for pair in self.narrow_phase.contact_pairs() {
            let (Some(c1), Some(c2)) = (
                self.colliders.get(pair.collider1),
                self.colliders.get(pair.collider2),
            ) else {
                continue;
            };
            let (p1, p2) = (
                pose_from_rapier(c1.position()),
                pose_from_rapier(c2.position()),
            );
            for m in pair.manifolds() {
                for c in m
                    .points
                    .iter()
                    .filter(|c| f64::from(c.dist) <= max_distance)
                {
                    let a = p1 * nalgebra::Point3::from(vec_from_rapier(c.local_p1));
                    let b = p2 * nalgebra::Point3::from(vec_from_rapier(c.local_p2));
                    out.push((a.coords + b.coords) * 0.5);
                }
            }
        }
    }

    /// Queues an impulse a deformable applied to a body; it is applied as a force in the next
    /// rapier step.
    pub fn push_reaction(&mut self, r: Reaction) {
        self.pending.push(r);
    }

    /// After bodies were moved outside a step (spawning a robot in its start configuration, a
    /// reset event's start pose): puts the colliders attached to them back on their bodies and
    /// marks the query structure stale. Rapier itself moves them only at its next step; until
    /// then queries and cameras would see the old place.
    pub fn bodies_moved(&mut self) {
        for (_, co) in self.colliders.iter_mut() {
            let Some(body) = co.parent().and_then(|b| self.bodies.get(b)) else {
                continue;
            };
            let Some(local) = co.position_wrt_parent() else {
                continue;
            };
            let pos = *body.position() * *local;
            if pos != *co.position() {
                co.set_position(pos);
            }
        }
        // Moved, not stepped: nothing to interpolate from.
        self.step_start.clear();
        self.queries_stale = true;
    }

    /// Rebuilds the collision query structure from the colliders' current poses if they moved
    /// since it was built (rapier steps and [`RigidContext::bodies_moved`] mark it stale). The
    /// deformable step calls it before its contact queries; a query on a stale structure builds
    /// the same structure for itself (slower), so results never depend on who called this.
    pub fn refresh_queries(&mut self) {
        if !self.queries_stale {
            return;
        }
        self.queries_stale = false;
        (self.query_bvh, self.query_leaves) = self.build_query_bvh();
    }

    /// A BVH over the colliders' current AABBs and its leaf -> collider table.
    fn build_query_bvh(&self) -> (Bvh, Vec<QueryLeaf>) {
        let mut leaves = Vec::with_capacity(self.colliders.len());
        let mut aabbs = Vec::with_capacity(self.colliders.len());
        // deformable surfaces' colliders are for the rigid solver only: deformables see each
        // other through `crate::contact`
        for (h, co) in self
            .colliders
            .iter()
            .filter(|(_, c)| surface_of(c.user_data).is_none())
        {
            let pose = co.position();
            let plane = co
                .shape()
                .as_halfspace()
                .map(|hs| (pose.rotation * hs.normal, pose.translation));
            let aabb = co.compute_aabb();
            leaves.push(QueryLeaf {
                collider: h,
                aabb,
                plane,
            });
            aabbs.push(aabb);
        }
        (Bvh::from_leaves(BvhBuildStrategy::Binned, &aabbs), leaves)
    }

    /// The fastest body whose speed is above `max` (m/s), with its speed: the larger of its
    /// linear velocity and its displacement over the last step of `dt` seconds divided by `dt`
    /// (a blown-up articulation can end a step far away with a moderate velocity: a Spot body
    /// 2 km from where the step began, its velocity under 100 m/s).
    pub fn fastest_body_above(&self, max: f64, dt: f64) -> Option<(RigidBodyHandle, f64)> {
        let by_velocity = self
            .bodies
            .iter()
            .map(|(h, b)| (h, f64::from(b.linvel().length())));
        let by_displacement = self
            .body_ids
            .iter()
            .zip(&self.step_start)
            .filter(|_| dt > 0.0)
            .filter_map(|(&(h, _), start)| {
                let now = pose_from_rapier(self.bodies.get(h)?.position());
                Some((
                    h,
                    (now.translation.vector - start.translation.vector).norm() / dt,
                ))
            });
        by_velocity
            .chain(by_displacement)
            .filter(|&(_, v)| v > max)
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// Advances the rigid world by `dt` seconds, applying pending reactions as forces.
    pub fn step(&mut self, dt: f64) -> Result<(), String> {
        self.params.dt = dt as f32;
        let inv_dt = 1.0 / dt;
        // Bodies touched by reactions, with the force and torque they carried before (set by
        // controllers, e.g. gravity compensation): restored after the step, so only the
        // reaction forces are removed.
        let mut touched: Vec<(
            RigidBodyHandle,
            rapier3d::math::Vector,
            rapier3d::math::Vector,
        )> = Vec::new();
        for r in self.pending.drain(..) {
            if let Some((h, _)) = self.body_ids.get(r.body as usize) {
                if let Some(b) = self.bodies.get_mut(*h) {
                    if b.is_dynamic() {
                        if !touched.iter().any(|(t, _, _)| t == h) {
                            touched.push((*h, b.user_force(), b.user_torque()));
                        }
                        b.add_force_at_point(
                            vec_to_rapier(&(r.impulse * inv_dt)),
                            vec_to_rapier(&r.point),
                            true,
                        );
                    }
                }
            }
        }
        self.step_start.clear();
        for (h, _) in &self.body_ids {
            let pose = self
                .bodies
                .get(*h)
                .map_or_else(Isometry3::identity, |b| pose_from_rapier(b.position()));
            self.step_start.push(pose);
        }
        // rapier asserts its sets' internal consistency; sets that are not consistent (a state
        // file edited by hand and re-sealed) must end the episode with a reason, not the process.
        let stepped = crate::catch_panic(|| {
            self.pipeline.step(
                vec_to_rapier(&self.gravity),
                &self.params,
                &mut self.islands,
                &mut self.broad_phase,
                &mut self.narrow_phase,
                &mut self.bodies,
                &mut self.colliders,
                &mut self.impulse_joints,
                &mut self.multibody_joints,
                &mut self.soft_bodies,
                &mut self.ccd,
                &SurfaceFilter(&self.sides),
                &(),
            )
        });
        if let Err(why) = stepped {
            // Fresh derived structures, so what reads contacts before the reset does not meet
            // the inconsistent ones.
            self.pipeline = PhysicsPipeline::new();
            self.broad_phase = BroadPhaseBvh::new();
            self.narrow_phase = NarrowPhase::new();
            self.queries_stale = true;
            return Err(format!(
                "rigid physics failed: the rigid solver stopped on an inconsistent world ({why}); was the state loaded from a damaged file?"
            ));
        }
        for (h, force, torque) in touched {
            if let Some(b) = self.bodies.get_mut(h) {
                b.reset_forces(false);
                b.reset_torques(false);
                b.add_force(force, false);
                b.add_torque(torque, false);
            }
        }
        self.queries_stale = true;
        let q = self.pipeline.quarantine();
        if !q.is_empty() {
            return Err(format!(
                "rigid physics blew up: {} bodies had non-finite state and were disabled",
                q.bodies().len()
            ));
        }
        for (h, b) in self.bodies.iter() {
            let t = b.translation();
            let v = b.linvel();
            if !(t.is_finite() && v.is_finite()) {
                return Err(format!(
                    "rigid body {h:?} has non-finite position or velocity"
                ));
            }
        }
        Ok(())
    }

    fn signed_distance(co: &Collider, p: rapier3d::math::Vector) -> Option<f32> {
        let proj = co.shape().project_point(co.position(), p, false);
        let d = (p - proj.point).length();
        Some(if proj.is_inside { -d } else { d })
    }
}

/// A leaf of the query BVH: its collider, the AABB it was built with and, for a half-space, the
/// world normal and a point of its boundary plane.
#[derive(Clone, Copy, Debug)]
struct QueryLeaf {
    collider: ColliderHandle,
    aabb: Aabb,
    plane: Option<(rapier3d::math::Vector, rapier3d::math::Vector)>,
}

/// [`RigidContext`]'s queries inside a region: the leaves whose AABB meets the region, in the
/// BVH's traversal order, so that filtering them by a query's box visits exactly the leaves, in
/// the order, that the traversal of the whole BVH for that box would.
struct RegionQuery<'a> {
    ctx: &'a RigidContext,
    leaves: Vec<QueryLeaf>,
}

impl ContactQuery for RegionQuery<'_> {
    fn contacts_near(&self, p: &Vector3<f64>, max_distance: f64, out: &mut Vec<PointContact>) {
        let (pr, m, q) = query_box(p, max_distance);
        for ql in self.leaves.iter().filter(|l| l.aabb.intersects(&q)) {
            self.ctx.leaf_contact(ql, pr, m, out);
        }
    }
}

/// A point query's point, distance and box, in rapier's types.
fn query_box(p: &Vector3<f64>, max_distance: f64) -> (rapier3d::math::Vector, f32, Aabb) {
    let pr = vec_to_rapier(p);
    let m = max_distance as f32;
    let half = rapier3d::math::Vector::new(m, m, m);
    (pr, m, Aabb::new(pr - half, pr + half))
}

impl RigidContext {
    /// The contact of one query leaf's collider with the point `pr` within `m`, if any.
    fn leaf_contact(
        &self,
        ql: &QueryLeaf,
        pr: rapier3d::math::Vector,
        m: f32,
        out: &mut Vec<PointContact>,
    ) {
        // A half-space's AABB is infinite, so every query meets the ground plane: its
        // distance is one dot product. Only points clearly farther than the query distance
        // are skipped here (with a margin over rounding), so the contacts are exactly those
        // of the general path below.
        if let Some((n, o)) = ql.plane {
            if n.dot(pr - o).abs() > m * 1.001 + 1e-6 {
                return;
            }
        }
        let Some(co) = self.colliders.get(ql.collider) else {
            return;
        };
        let proj = co.shape().project_point(co.position(), pr, false);
        let delta = pr - proj.point;
        let dist = delta.length();
        if dist > m {
            return;
        }
        let normal = if dist > 1e-7 {
            let n = delta / dist;
            if proj.is_inside {
                -n
            } else {
                n
            }
        } else {
            // Exactly on the surface: the gradient of the signed distance.
            let e = 1e-4f32;
            let mut g = rapier3d::math::Vector::ZERO;
            for axis in 0..3 {
                let mut dp = rapier3d::math::Vector::ZERO;
                dp[axis] = e;
                let a = Self::signed_distance(co, pr + dp).unwrap_or(0.0);
                let b = Self::signed_distance(co, pr - dp).unwrap_or(0.0);
                g[axis] = (a - b) / (2.0 * e);
            }
            g.normalize_or(rapier3d::math::Vector::Z)
        };
        let signed = if proj.is_inside { -dist } else { dist };
        let (body, velocity) = match co.parent() {
            Some(bh) => {
                let id = self.body_id(bh).unwrap_or(u32::MAX);
                let v = self
                    .bodies
                    .get(bh)
                    .map(|b| b.velocity_at_point(proj.point))
                    .unwrap_or(rapier3d::math::Vector::ZERO);
                (id, v)
            }
            None => (u32::MAX, rapier3d::math::Vector::ZERO),
        };
        out.push(PointContact {
            point: vec_from_rapier(proj.point),
            normal: vec_from_rapier(normal),
            distance: f64::from(signed),
            friction: f64::from(co.friction()),
            body,
            velocity: vec_from_rapier(velocity),
        });
    }
}

impl ContactQuery for RigidContext {
    fn contacts_near(&self, p: &Vector3<f64>, max_distance: f64, out: &mut Vec<PointContact>) {
        let (pr, m, q) = query_box(p, max_distance);
        // A stale structure (a caller that did not refresh it) is built afresh for this query
        // the same way, so the contacts and their order are the same either way.
        let fresh;
        let (bvh, leaves) = if self.queries_stale {
            fresh = self.build_query_bvh();
            (&fresh.0, &fresh.1)
        } else {
            (&self.query_bvh, &self.query_leaves)
        };
        for leaf in bvh.leaves(|node| node.aabb().intersects(&q)) {
            if let Some(ql) = leaves.get(leaf as usize) {
                self.leaf_contact(ql, pr, m, out);
            }
        }
    }

    fn region(&self, lo: &Vector3<f64>, hi: &Vector3<f64>) -> Option<Box<dyn ContactQuery + '_>> {
        if self.queries_stale {
            return None;
        }
        let r = Aabb::new(vec_to_rapier(lo), vec_to_rapier(hi));
        let leaves = self
            .query_bvh
            .leaves(|node| node.aabb().intersects(&r))
            .filter_map(|leaf| self.query_leaves.get(leaf as usize).copied())
            .collect();
        Some(Box::new(RegionQuery { ctx: self, leaves }))
    }
}

fn collider_builder(shape: &RigidShape) -> ColliderBuilder {
    match shape {
        RigidShape::Cuboid(h) => ColliderBuilder::cuboid(h.x as f32, h.y as f32, h.z as f32),
        RigidShape::Ball(r) => ColliderBuilder::ball(*r as f32),
        RigidShape::CylinderZ {
            radius,
            half_height,
        } => ColliderBuilder::cylinder(*half_height as f32, *radius as f32)
            // parry's cylinder is along y; ours along z.
            .rotation(rapier3d::math::Vector::new(
                std::f32::consts::FRAC_PI_2,
                0.0,
                0.0,
            )),
        RigidShape::CapsuleZ {
            radius,
            half_height,
        } => ColliderBuilder::capsule_z(*half_height as f32, *radius as f32),
        RigidShape::HalfSpace => {
            ColliderBuilder::halfspace(nalgebra::Unit::new_unchecked(rapier3d::math::Vector::Z))
        }
        RigidShape::TriMesh(mesh) => {
            let (v, i) = mesh_to_rapier(mesh);
            ColliderBuilder::trimesh(v, i).unwrap_or_else(|_| ColliderBuilder::ball(1e-3))
        }
        RigidShape::ConvexDecomposition { parts, .. } => ColliderBuilder::new(parts.clone()),
    }
}

/// The convex decomposition (parry's VHACD) a dynamic or kinematic mesh body collides with,
/// computed once when the scene compiles and shared by every env's collider. parry panics on
/// some meshes (a degenerate convex hull), which must be a scene error, not a crash.
pub(crate) fn convex_decomposition(
    mesh: &crate::shapes::SurfaceMesh,
) -> Result<SharedShape, String> {
    let (v, i) = mesh_to_rapier(mesh);
    crate::catch_panic(|| SharedShape::convex_decomposition(&v, &i))
}

fn mesh_to_rapier(
    mesh: &crate::shapes::SurfaceMesh,
) -> (Vec<rapier3d::math::Vector>, Vec<[u32; 3]>) {
    (
        mesh.positions.iter().map(vec_to_rapier).collect(),
        mesh.triangles.clone(),
    )
}

fn rigid_step(
    mut ctx: ResMut<RigidContext>,
    settings: Res<crate::SimSettings>,
    mut errors: ResMut<SimErrors>,
    names: Query<(&RigidRef, &Object)>,
) {
    if let Err(e) = ctx.step(settings.substep_dt()) {
        errors.raise(e);
        return;
    }
    if let Some((h, speed)) = ctx.fastest_body_above(settings.max_body_speed, settings.substep_dt())
    {
        let name = names
            .iter()
            .find(|(r, _)| r.0 == h)
            .map_or_else(|| format!("{h:?}"), |(_, o)| format!("\"{}\"", o.name));
        errors.raise(format!(
            "rigid physics blew up: body {name} moves at {speed:.3e} m/s, above physics.max_body_speed = {} m/s",
            settings.max_body_speed
        ));
    }
}

fn rigid_writeback(ctx: Res<RigidContext>, mut q: Query<(&RigidRef, &mut Pose, &mut Velocity)>) {
    for (r, mut pose, mut vel) in &mut q {
        if let Some(b) = ctx.bodies.get(r.0) {
            pose.0 = pose_from_rapier(b.position());
            vel.linear = vec_from_rapier(b.linvel());
            vel.angular = vec_from_rapier(b.angvel());
        }
    }
}

impl RigidContext {
    fn rigid_state(&self) -> RigidState {
        RigidState {
            bodies: self.bodies.clone(),
            colliders: self.colliders.clone(),
            impulse_joints: self.impulse_joints.clone(),
            multibody_joints: self.multibody_joints.clone(),
            islands: self.islands.clone(),
            broad_phase: self.broad_phase.clone(),
            narrow_phase: self.narrow_phase.clone(),
            ccd: self.ccd.clone(),
            soft_bodies: self.soft_bodies.clone(),
            pending: self.pending.clone(),
            step_start: self.step_start.clone(),
        }
    }

    fn set_rigid_state(&mut self, s: RigidState) {
        self.sides.clear();
        self.bodies = s.bodies;
        self.colliders = s.colliders;
        self.impulse_joints = s.impulse_joints;
        self.multibody_joints = s.multibody_joints;
        self.islands = s.islands;
        self.broad_phase = s.broad_phase;
        self.narrow_phase = s.narrow_phase;
        self.ccd = s.ccd;
        self.soft_bodies = s.soft_bodies;
        self.pending = s.pending;
        self.step_start = s.step_start;
        // The pipeline holds only workspace, but a fresh one also drops memos tied to the
        // replaced sets.
        self.pipeline = PhysicsPipeline::new();
        self.queries_stale = true;
    }
}

impl Persist for RigidContext {
    fn encode(&self, e: &mut Encoder) {
        e.put(&self.rigid_state());
    }

    fn decode(&mut self, d: &mut Decoder<'_>) -> Result<(), StateError> {
        let s: RigidState = d.take()?;
        if s.bodies.len() != self.bodies.len() || s.colliders.len() != self.colliders.len() {
            return Err(StateError::part(
                d.part(),
                format!(
                    "{} bodies and {} colliders in the file, {} and {} in this env",
                    s.bodies.len(),
                    s.colliders.len(),
                    self.bodies.len(),
                    self.colliders.len()
                ),
            ));
        }
        self.check_consistent(&s)
            .map_err(|m| StateError::part(d.part(), m))?;
        self.set_rigid_state(s);
        Ok(())
    }
}

impl RigidContext {
    /// A trial step of a decoded rigid state, on a copy: rapier's sets in a state file are
    /// trusted only if rapier can step them and read their contacts without panicking (a file
    /// edited by hand and re-sealed can hold sets rapier asserts on).
    fn check_consistent(&self, s: &RigidState) -> Result<(), String> {
        let mut trial = RigidContext::new();
        trial.set_rigid_state(s.clone());
        trial.params = self.params;
        trial.gravity = self.gravity;
        trial.body_ids = self.body_ids.clone();
        let dt = f64::from(self.params.dt).max(1e-4);
        trial.step(dt)?;
        let read = crate::catch_panic(|| {
            let mut n = trial.narrow_phase.contact_pairs().count();
            for (h, _) in trial.colliders.iter() {
                n += trial.narrow_phase.contact_pairs_with(h).count();
                n += trial.narrow_phase.intersection_pairs_with(h).count();
            }
            n
        });
        read.map(|_| ()).map_err(|_| {
            "the rigid world's contact graph is inconsistent (a damaged file?)".to_string()
        })
    }
}

impl Stateful for RigidContext {
    fn save_state(&self) -> Box<dyn Any + Send + Sync> {
        Box::new(self.rigid_state())
    }

    fn load_state(&mut self, state: &(dyn Any + Send + Sync)) -> Result<(), StateError> {
        let s = state
            .downcast_ref::<RigidState>()
            .ok_or_else(mismatch::<Self>)?;
        self.set_rigid_state(s.clone());
        Ok(())
    }

    fn hash_state(&self, h: &mut StateHasher) {
        for (_, b) in self.bodies.iter() {
            let p = b.position();
            for x in [
                p.translation.x,
                p.translation.y,
                p.translation.z,
                p.rotation.x,
                p.rotation.y,
                p.rotation.z,
                p.rotation.w,
            ] {
                h.write_f32(x);
            }
            let v = b.linvel();
            let w = b.angvel();
            for x in [v.x, v.y, v.z, w.x, w.y, w.z] {
                h.write_f32(x);
            }
        }
        h.write_u64(self.pending.len() as u64);
        h.write_u64(self.step_start.len() as u64);
        for p in &self.step_start {
            for x in p.translation.vector.iter().chain(p.rotation.coords.iter()) {
                h.write_f64(*x);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rapier3d::prelude::{ColliderBuilder, RigidBodyBuilder};

    #[test]
    fn a_body_displaced_far_in_a_step_counts_as_fast_whatever_its_velocity() {
        let mut ctx = RigidContext::new();
        let body = ctx.bodies.insert(RigidBodyBuilder::dynamic().build());
        let collider = ColliderBuilder::ball(0.1).build();
        ctx.colliders
            .insert_with_parent(collider, body, &mut ctx.bodies);
        ctx.register_body(body, Entity::PLACEHOLDER);
        let dt = 1.0 / 60.0;
        ctx.step(dt).unwrap();
        // a free fall for one step: far below 100 m/s either way
        assert_eq!(ctx.fastest_body_above(100.0, dt), None);
        // the body ends the step 2 km away (as a blown-up articulation did), at rest
        let far = rapier3d::math::Pose::translation(2000.0, 0.0, 0.0);
        let b = ctx.bodies.get_mut(body).unwrap();
        b.set_position(far, false);
        b.set_linvel(rapier3d::math::Vector::ZERO, false);
        let (h, speed) = ctx.fastest_body_above(100.0, dt).expect("caught");
        println!("displaced 2 km in 1/60 s at rest: {speed:.3e} m/s (limit 100)");
        assert_eq!(h, body);
        assert!((speed - 2000.0 / dt).abs() < 1.0, "{speed}");
        // without a step length only the velocity counts
        assert_eq!(ctx.fastest_body_above(100.0, 0.0), None);
    }
}
