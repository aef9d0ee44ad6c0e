//! Contact between deformable bodies, whatever their solvers (FEM solid against FEM solid, cloth
//! against a solid, cloth against another cloth).
//!
//! Every deformable body whose kind gives surface triangles
//! ([`BodyKind::surface_triangles`](crate::registry::BodyKind::surface_triangles)) gets a
//! [`ContactSurface`] at spawn. At the start of every substep the engine copies the surfaces'
//! nodes and velocities into [`DeformableContacts`] and builds a bounding volume hierarchy over
//! each surface's triangles. A solver then sees the other bodies' surfaces through the same
//! [`ContactQuery`] it uses for rigid colliders: the closest point of another body's surface
//! (offset by that surface's contact thickness), its outward normal, its velocity (interpolated
//! from its nodes) and its friction. No solver needs to know another's types.
//!
//! **Coupling scheme.** Of each pair of touching bodies one resolves the contact: the body with
//! the lighter nodes treats the other's surface as a moving collider within its own (implicit or
//! constraint-based) step, exactly as it treats a rigid collider, and reports the impulses it
//! applied, as for a rigid body. The engine spreads each impulse over the corners of the touched
//! triangle (by the contact point's barycentric weights) and hands the opposite impulse to the
//! other body ([`DeformableSolver::add_node_impulses`]): before its next step when it has yet
//! to step in this substep, at the end of the substep otherwise. Momentum is conserved exactly.
//! The lighter side is the one that resolves because the scheme is a partitioned
//! (Dirichlet-Neumann) coupling: the body receiving impulses lags by one step, and that lag is
//! stable only while the resolving side's inertia is the smaller (the "added mass" ratio below
//! one); resolving from the heavy side makes a light body's weight bounce the heavy one. Node
//! masses decide, ties go to the later body. Only the resolving side's nodes are tested against
//! the other side's triangles, so a coarse resolving surface may let the other side's corners
//! dip into it by up to its triangles' sagitta.
//!
//! Bodies of a solver that does not report node masses or take impulses
//! ([`DeformableSolver::node_masses`]) only resolve contacts one way: they are moving colliders
//! for the others and are not pushed back.
//!
//! Scenes control it per object (`collide: false`, `collision_group`) and per material
//! (`contact_thickness`); see [`validate_object`].

mod geometry;
pub mod rigid_side;
pub mod support;

use std::sync::Arc;

use bevy_ecs::prelude::*;
use nalgebra::Vector3;

use crate::codec::StateError;
use crate::components::Object;
use crate::coupling::{ContactQuery, PointContact, Reaction};
use crate::deformable::solver::{deformable_ref, DeformableSolver};
use crate::scene::{MaterialDesc, ObjectDesc, SceneError};
use crate::state::{restore_clone, StateHasher, Stateful};
use geometry::TriangleBvh;
pub use geometry::{closest_on_triangle, ClosestPoint};

/// Body ids from here up in [`PointContact::body`] and [`Reaction::body`] name a deformable
/// surface (the id minus this base: its index among the env's surfaces, in spawn order), not a
/// rigid body.
pub const DEFORMABLE_CONTACT_BASE: u32 = 0xC000_0000;

/// Whether a contact or reaction body id names a deformable surface's triangle.
pub fn is_deformable_contact(body: u32) -> bool {
    (DEFORMABLE_CONTACT_BASE..u32::MAX).contains(&body)
}

/// The contact settings of one deformable body (a component, added at spawn from its scene
/// object and material; not part of the env state: it never changes).
#[derive(Component, Debug, Clone)]
pub struct ContactSurface {
    /// Surface triangles, outward-facing, as indices into the body's nodes.
    pub triangles: Arc<[[u32; 3]]>,
    /// Whether the surface is closed (every edge shared by two triangles): a solid's boundary,
    /// with an inside; an open surface (a cloth) is two-sided.
    pub closed: bool,
    /// Contact thickness, m: the surface others touch lies this far out of the triangles (on
    /// both sides of an open surface).
    pub thickness: f64,
    /// Coulomb friction coefficient of the body's material.
    pub friction: f64,
    /// Whether the body touches other deformables at all (`collide`).
    pub collide: bool,
    /// Bodies sharing a group do not touch each other (`collision_group`).
    pub group: Option<String>,
}

impl ContactSurface {
    /// The settings of a body with surface `triangles`, its scene object and its material.
    pub fn new(
        triangles: Vec<[u32; 3]>,
        material: &MaterialDesc,
        collide: bool,
        group: Option<String>,
    ) -> Self {
        let closed = is_closed(&triangles);
        Self {
            triangles: triangles.into(),
            closed,
            thickness: material.contact_thickness,
            friction: material.friction,
            collide,
            group,
        }
    }
}

/// Every edge of the triangles belongs to exactly two of them.
fn is_closed(triangles: &[[u32; 3]]) -> bool {
    let mut edges: Vec<(u32, u32)> = triangles
        .iter()
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    edges.sort_unstable();
    !edges.is_empty() && edges.chunk_by(|a, b| a == b).all(|run| run.len() == 2)
}

/// Checks an object's contact fields: `collide` and `collision_group` apply to deformable
/// bodies only (rigid colliders always collide); a group name is not empty.
pub fn validate_object(path: &str, obj: &ObjectDesc, deformable: bool) -> Result<(), SceneError> {
    if !deformable && !obj.collide {
        return Err(SceneError::semantic(
            format!("{path}.collide"),
            "false",
            "true (the default); `collide: false` applies to deformable bodies (Kind(...)) only: rigid colliders always collide",
        ));
    }
    if let Some(g) = &obj.collision_group {
        if !deformable {
            return Err(SceneError::semantic(
                format!("{path}.collision_group"),
                format!("{g:?}"),
                "no group: collision groups apply to deformable bodies (Kind(...)) only",
            ));
        }
        if g.trim().is_empty() {
            return Err(SceneError::semantic(
                format!("{path}.collision_group"),
                format!("{g:?}"),
                "a non-empty name (deformables sharing it do not touch each other)",
            ));
        }
    }
    Ok(())
}

/// Checks a material's contact thickness: finite, >= 0 and at most 0.05 m.
pub fn validate_material(path: &str, m: &MaterialDesc) -> Result<(), SceneError> {
    let t = m.contact_thickness;
    if !(t.is_finite() && (0.0..=0.05).contains(&t)) {
        return Err(SceneError::semantic(
            format!("{path}.contact_thickness"),
            t.to_string(),
            "a thickness in [0, 0.05] m (the distance out of a deformable's surface where others touch it)",
        ));
    }
    Ok(())
}

/// One deformable surface as the contact step sees it.
struct Entry {
    entity: Entity,
    surface: ContactSurface,
    /// Index in [`DeformableContacts`] (contacts name the surface by it).
    index: u32,
    /// Mean node mass, kg (infinite when the solver reports none).
    node_mass: f64,
    /// Node masses (empty when the solver reports none: the body takes no impulses).
    masses: Vec<f64>,
    pos: Vec<Vector3<f64>>,
    vel: Vec<Vector3<f64>>,
    bvh: TriangleBvh,
    /// Whether another body resolves contacts against this one (its hierarchy is kept).
    is_target: bool,
    /// The surfaces this body resolves contacts against.
    targets: Vec<Target>,
    /// The scene object's index (keys its [`ContactImpulses`]).
    object: u32,
}

impl Entry {
    fn refresh(&mut self, solver: &dyn DeformableSolver) {
        // the hierarchy depends on the positions only: a body that has not moved since its last
        // refresh (the substep's start after its own step) keeps it
        let moved = self.pos.as_slice() != solver.node_positions() || self.bvh.is_empty();
        self.pos.clear();
        self.pos.extend_from_slice(solver.node_positions());
        self.vel.clear();
        match solver.node_velocities() {
            Some(v) if v.len() == self.pos.len() => self.vel.extend_from_slice(v),
            _ => self.vel.resize(self.pos.len(), Vector3::zeros()),
        }
        if self.is_target && moved {
            let pad = self.surface.thickness;
            self.bvh.rebuild(&self.surface.triangles, &self.pos, pad);
        }
    }

    /// The closest point of the triangles to `p` among those whose padded boxes meet the cube
    /// `p +- r`: squared distance, triangle, point. Ties go to the lower triangle index,
    /// whatever the hierarchy's order.
    fn closest(&self, p: &Vector3<f64>, r: f64) -> Option<(f64, u32, ClosestPoint)> {
        let mut best: Option<(f64, u32, ClosestPoint)> = None;
        self.bvh.visit(p, r, |t| {
            let [a, b, c] = self.surface.triangles[t as usize].map(|i| self.pos[i as usize]);
            let cp = closest_on_triangle(p, &a, &b, &c);
            let d2 = (p - cp.point).norm_squared();
            if best.is_none_or(|(bd, bt, _)| d2 < bd || (d2 == bd && t < bt)) {
                best = Some((d2, t, cp));
            }
        });
        best
    }

    /// The closest point of this surface to `p` within `max_distance` (of the surface offset by
    /// its thickness less `inset`), as a contact.
    fn contact(&self, p: &Vector3<f64>, max_distance: f64, inset: f64) -> Option<PointContact> {
        let thick = self.surface.thickness - inset;
        let (d2, t, cp) = self.closest(p, max_distance)?;
        let (q, w, inside) = (cp.point, cp.weights, cp.inside);
        let tri = self.surface.triangles[t as usize].map(|i| i as usize);
        let [a, b, c] = tri.map(|i| self.pos[i]);
        let face = (b - a).cross(&(c - a)).try_normalize(1e-300)?;
        let d = d2.sqrt();
        let delta = p - q;
        let (normal, distance) = if self.surface.closed {
            let side = delta.dot(&face);
            if inside || side < 0.0 || d < 1e-12 {
                (face, side)
            } else {
                (delta / d, d)
            }
        } else if d >= 1e-12 {
            (delta / d, d)
        } else {
            (face, 0.0)
        };
        let distance = distance - thick;
        if distance > max_distance {
            return None;
        }
        let v = self.vel[tri[0]] * w[0] + self.vel[tri[1]] * w[1] + self.vel[tri[2]] * w[2];
        // tangential only: friction sees the sliding, but the resolver does not chase the
        // surface's normal motion, which lags a step (see the module's coupling scheme)
        let velocity = v - normal * v.dot(&normal);
        Some(PointContact {
            point: q + normal * thick,
            normal,
            distance,
            friction: self.surface.friction,
            body: DEFORMABLE_CONTACT_BASE + self.index,
            velocity,
        })
    }

    /// Spreads an impulse on this surface at `point` (near triangle `t`) over the triangle's
    /// corners, in proportion to their barycentric weights times their masses (every corner
    /// gets the same velocity change; the momentum is the impulse's), into `impulses`.
    fn receive(
        &self,
        point: &Vector3<f64>,
        impulse: &Vector3<f64>,
        impulses: &mut ContactImpulses,
    ) {
        if self.masses.is_empty() {
            return;
        }
        // the triangle under the contact point (near it: the point is on the offset surface)
        let b = self.bvh.bounds();
        let near = self.surface.thickness + 1e-3;
        let Some((_, t, cp)) = self
            .closest(point, near)
            .or_else(|| self.closest(point, (b.hi - b.lo).norm() + (point - b.lo).norm()))
        else {
            return;
        };
        let tri = &self.surface.triangles[t as usize];
        let nodes = impulses.of(self.object, self.pos.len());
        spread_over_corners(nodes, tri, cp.weights, &self.masses, impulse);
    }
}

/// Adds `impulse` (N s) to the corners `tri` of a surface's nodes, shared in proportion to the
/// contact point's barycentric weights `w` times the corners' masses: every corner gets the same
/// velocity change and the momentum is the impulse's (by weight alone when the masses are zero).
fn spread_over_corners(
    nodes: &mut [Vector3<f64>],
    tri: &[u32; 3],
    w: [f64; 3],
    masses: &[f64],
    impulse: &Vector3<f64>,
) {
    let wm: [f64; 3] = std::array::from_fn(|k| w[k] * masses[tri[k] as usize].max(0.0));
    let total: f64 = wm.iter().sum();
    let share = if total > 0.0 {
        wm.map(|x| x / total)
    } else {
        w
    };
    for (k, &i) in tri.iter().enumerate() {
        nodes[i as usize] += impulse * share[k];
    }
}

/// The share of the impulses received in a step that a body gets at its next step; the rest
/// follows in later steps (each step hands on `RELAXATION` of what is owed). See the module's
/// coupling scheme.
pub const RELAXATION: f64 = 0.5;

/// Gap, m, beyond a surface's contact thickness within which a node counts as touching a body
/// (`rigid_side::inelastic_shifts`) and a layer's far side as resting on a fixed collider
/// (`support`); here, where both read it.
pub const SUPPORT_GAP: f64 = 2e-3;

/// Impulses (N s per node, world frame) other bodies' contacts owe one deformable body.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OwedImpulses {
    /// The scene object's index.
    pub object: u32,
    /// Received since the body's last step.
    pub received: Vec<Vector3<f64>>,
    /// Handed to the body at its last step.
    pub applied: Vec<Vector3<f64>>,
}

/// What contacts resolved by other bodies owe each deformable body, by scene object index: part
/// of the env state (impulses reach a body over its next steps, relaxed).
#[derive(Resource, Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ContactImpulses(pub Vec<OwedImpulses>);

impl ContactImpulses {
    fn of(&mut self, object: u32, n: usize) -> &mut Vec<Vector3<f64>> {
        let k = match self.0.binary_search_by_key(&object, |e| e.object) {
            Ok(k) => k,
            Err(k) => {
                let zero = vec![Vector3::zeros(); n];
                let owed = OwedImpulses {
                    object,
                    received: zero.clone(),
                    applied: zero,
                };
                self.0.insert(k, owed);
                k
            }
        };
        &mut self.0[k].received
    }

    /// The impulses a body gets at this step: `RELAXATION` of what it received plus the rest of
    /// what it got last time (a geometric series: over the steps it gets exactly what it
    /// received). A body owed less than 1e-12 N s per node is forgiven (and forgotten).
    fn take(&mut self, object: u32) -> Option<Vec<Vector3<f64>>> {
        let k = self.0.binary_search_by_key(&object, |e| e.object).ok()?;
        let owed = &mut self.0[k];
        for (a, r) in owed.applied.iter_mut().zip(owed.received.iter_mut()) {
            *a = *a * (1.0 - RELAXATION) + *r * RELAXATION;
            *r = Vector3::zeros();
        }
        let now = owed.applied.clone();
        if now.iter().all(|j| j.norm() < 1e-12) {
            self.0.remove(k);
        }
        Some(now)
    }
}

crate::persist_by_serde!(ContactImpulses);

impl Stateful for ContactImpulses {
    fn save_state(&self) -> Box<dyn std::any::Any + Send + Sync> {
        Box::new(self.clone())
    }
    fn load_state(&mut self, state: &(dyn std::any::Any + Send + Sync)) -> Result<(), StateError> {
        restore_clone(self, state)
    }
    /// Nothing pending hashes to nothing (scenes without deformable contact keep their hashes).
    fn hash_state(&self, h: &mut StateHasher) {
        for owed in &self.0 {
            h.write_u64(u64::from(owed.object));
            for j in owed.received.iter().chain(&owed.applied) {
                h.write_f64(j.x);
                h.write_f64(j.y);
                h.write_f64(j.z);
            }
        }
    }
}

/// The deformable surfaces of an env during a substep (a resource; a cache rebuilt from the
/// solvers at the start of every substep and emptied of impulses at its end, so not part of the
/// env state).
#[derive(Resource, Default)]
pub struct DeformableContacts {
    entries: Vec<Entry>,
    /// Contact surfaces spawned into this world (an upper bound of those alive): below two the
    /// refresh does not run at all.
    spawned: usize,
}

/// Gives a spawned deformable its [`ContactSurface`] (the scene spawner calls it).
pub(crate) fn attach_surface(world: &mut World, entity: Entity, surface: ContactSurface) {
    world.entity_mut(entity).insert(surface);
    if let Some(mut c) = world.get_resource_mut::<DeformableContacts>() {
        c.spawned += 1;
    }
}

fn two_or_more(contacts: Option<Res<DeformableContacts>>) -> bool {
    contacts.is_some_and(|c| c.spawned >= 2)
}

impl DeformableContacts {
    fn find(&self, entity: Entity) -> Option<usize> {
        self.entries.iter().position(|e| e.entity == entity)
    }

    /// The query a body of `entity` steps against: the rigid world (`rigid`) and the surfaces it
    /// resolves contacts with; `None` when it resolves none (then the rigid world alone).
    pub fn query_for<'a>(
        &'a self,
        entity: Entity,
        rigid: Option<&'a dyn ContactQuery>,
    ) -> Option<SurfaceQuery<'a>> {
        let e = &self.entries[self.find(entity)?];
        if e.targets.is_empty() {
            return None;
        }
        Some(SurfaceQuery {
            rigid: rigid.map(RigidPart::Borrowed),
            contacts: self,
            targets: &e.targets,
        })
    }

    /// After `entity` stepped: takes the reactions on other deformables out of `reactions`
    /// (from index `from` on) as impulses for those bodies (into `impulses`), and refreshes this
    /// body's surface.
    pub fn after_step(
        &mut self,
        entity: Entity,
        solver: &dyn DeformableSolver,
        reactions: &mut Vec<Reaction>,
        from: usize,
        impulses: &mut ContactImpulses,
    ) {
        let mut kept = from;
        for k in from..reactions.len() {
            let r = reactions[k];
            if !is_deformable_contact(r.body) {
                reactions[kept] = r;
                kept += 1;
                continue;
            }
            let id = (r.body - DEFORMABLE_CONTACT_BASE) as usize;
            if let Some(e) = self.entries.get(id) {
                e.receive(&r.point, &r.impulse, impulses);
            }
        }
        reactions.truncate(kept);
        if let Some(k) = self.find(entity) {
            self.entries[k].refresh(solver);
        }
    }
}

/// Before a body steps: hands the impulses other bodies' contacts left for scene object
/// `object` to its solver (and forgets them).
pub fn deliver(
    impulses: &mut ContactImpulses,
    object: u32,
    solver: &mut dyn DeformableSolver,
) -> Result<(), String> {
    match impulses.take(object) {
        Some(j) => solver.add_node_impulses(&j),
        None => Ok(()),
    }
}

/// The rigid part of a [`SurfaceQuery`].
enum RigidPart<'a> {
    Borrowed(&'a dyn ContactQuery),
    Owned(Box<dyn ContactQuery + 'a>),
}

impl RigidPart<'_> {
    fn get(&self) -> &dyn ContactQuery {
        match self {
            RigidPart::Borrowed(q) => *q,
            RigidPart::Owned(q) => q.as_ref(),
        }
    }
}

/// The rigid world plus the deformable surfaces one body resolves contacts against.
pub struct SurfaceQuery<'a> {
    rigid: Option<RigidPart<'a>>,
    contacts: &'a DeformableContacts,
    targets: &'a [Target],
}

/// A surface a body resolves contacts against.
#[derive(Debug, Clone, Copy)]
struct Target {
    /// Its index in [`DeformableContacts`].
    index: usize,
    /// How far into the surface the contacts lie, m: 0 for the pair's primary resolver; for the
    /// secondary one of a mutual pair, its thickness or 1 mm, whichever is more, so that it only
    /// stops the partner's corners from passing through and does not push on resting contacts
    /// the primary already holds.
    inset: f64,
}

impl ContactQuery for SurfaceQuery<'_> {
    fn contacts_near(&self, p: &Vector3<f64>, max_distance: f64, out: &mut Vec<PointContact>) {
        if let Some(r) = &self.rigid {
            r.get().contacts_near(p, max_distance, out);
        }
        for t in self.targets {
            let e = &self.contacts.entries[t.index];
            if e.bvh.bounds().near(p, max_distance + t.inset) {
                // a guard's contacts name no body: its impulses are not handed on
                let guard = |mut c: PointContact| {
                    if t.inset > 0.0 {
                        c.body = u32::MAX;
                    }
                    c
                };
                out.extend(e.contact(p, max_distance, t.inset).map(guard));
            }
        }
    }

    fn region(&self, lo: &Vector3<f64>, hi: &Vector3<f64>) -> Option<Box<dyn ContactQuery + '_>> {
        let rigid = self.rigid.as_ref().map(|r| match r.get().region(lo, hi) {
            Some(owned) => RigidPart::Owned(owned),
            None => RigidPart::Borrowed(r.get()),
        });
        Some(Box::new(SurfaceQuery {
            rigid,
            contacts: self.contacts,
            targets: self.targets,
        }))
    }
}

/// Whether `a` is the lighter of the pair by mean node mass (ties, masses equal up to rounding:
/// the same body spawned at another pose, go to `a` when `a_later`).
fn lighter(a: &Entry, b: &Entry, a_later: bool) -> bool {
    let (ma, mb) = (a.node_mass, b.node_mass);
    let tie = (ma - mb).abs() <= 1e-9 * ma.max(mb);
    if tie {
        a_later
    } else {
        ma < mb
    }
}

/// Bodies whose mean node masses are within this ratio of each other resolve contacts both
/// ways (each body's nodes against the other's triangles); see the module's coupling scheme.
pub const MUTUAL_MASS_RATIO: f64 = 2.0;

/// How a pair resolves its contact: `(a is the primary resolver, the other guards too)`. The
/// primary is the lighter body, unless only the other takes impulses (the one resolving leaves
/// the impulses to a body that takes them); the other guards when both take impulses and their
/// node masses are comparable.
fn roles(a: &Entry, b: &Entry, a_later: bool) -> (bool, bool) {
    let takes = |e: &Entry| !e.masses.is_empty();
    let (ma, mb) = (a.node_mass, b.node_mass);
    match (takes(a), takes(b)) {
        (true, false) => (false, false),
        (false, true) => (true, false),
        (true, true) => (
            lighter(a, b, a_later),
            ma.max(mb) <= MUTUAL_MASS_RATIO * ma.min(mb),
        ),
        (false, false) => (lighter(a, b, a_later), false),
    }
}

fn may_touch(a: &ContactSurface, b: &ContactSurface) -> bool {
    a.collide && b.collide && (a.group.is_none() || a.group != b.group)
}

/// Start of every substep's solve: copies every deformable surface into [`DeformableContacts`]
/// (rebuilding its list when bodies came or went).
pub(crate) fn refresh_contacts(world: &mut World) {
    let mut q = world.query::<(Entity, &Object, &ContactSurface)>();
    let mut bodies: Vec<(u32, Entity)> = q
        .iter(world)
        .filter(|(_, _, s)| s.collide)
        .map(|(e, o, _)| (o.index, e))
        .collect();
    if bodies.len() < 2 {
        if let Some(mut c) = world.get_resource_mut::<DeformableContacts>() {
            c.entries.clear();
        }
        return;
    }
    bodies.sort_by_key(|b| b.0);
    let mut contacts = world
        .remove_resource::<DeformableContacts>()
        .unwrap_or_default();
    let same = contacts.entries.len() == bodies.len()
        && contacts
            .entries
            .iter()
            .zip(&bodies)
            .all(|(e, b)| e.entity == b.1);
    if !same {
        contacts.entries.clear();
        for (object, entity) in bodies {
            let (Some(solver), Some(surface)) = (
                deformable_ref(world, entity),
                world.get::<ContactSurface>(entity).cloned(),
            ) else {
                continue;
            };
            let masses = solver
                .node_masses()
                .map(<[f64]>::to_vec)
                .unwrap_or_default();
            let node_mass = if masses.is_empty() {
                f64::INFINITY
            } else {
                masses.iter().sum::<f64>() / masses.len() as f64
            };
            let index = contacts.entries.len() as u32;
            contacts.entries.push(Entry {
                entity,
                surface,
                index,
                node_mass,
                masses,
                pos: Vec::new(),
                vel: Vec::new(),
                bvh: TriangleBvh::default(),
                is_target: false,
                targets: Vec::new(),
                object,
            });
        }
        let n = contacts.entries.len();
        for j in 0..n {
            for i in 0..j {
                let (a, b) = (&contacts.entries[i], &contacts.entries[j]);
                if !may_touch(&a.surface, &b.surface) {
                    continue;
                }
                let (j_primary, mutual) = roles(b, a, true);
                let (p, o) = if j_primary { (j, i) } else { (i, j) };
                let guard_inset = contacts.entries[p].surface.thickness.max(1e-3);
                let mut resolve = |r: usize, t: usize, inset: f64| {
                    contacts.entries[r].targets.push(Target { index: t, inset });
                    contacts.entries[t].is_target = true;
                };
                resolve(p, o, 0.0);
                if mutual {
                    resolve(o, p, guard_inset);
                }
            }
        }
    }
    for e in &mut contacts.entries {
        if let Some(solver) = deformable_ref(world, e.entity) {
            e.refresh(solver);
        }
    }
    world.insert_resource(contacts);
}

/// The system set before the solvers' sets in `SubstepSystems::Solve`: copies the surfaces.
#[derive(bevy_ecs::schedule::SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub struct ContactRefresh;

/// Adds the refresh system before the solvers and the pending impulses to the env state (once,
/// with the first solver).
pub(crate) fn add_contact_systems(app: &mut crate::SimApp) {
    app.insert_resource(DeformableContacts::default());
    app.insert_resource(ContactImpulses::default());
    app.register_stateful::<ContactImpulses>();
    app.configure_sets(
        crate::Substep,
        ContactRefresh.in_set(crate::app::SubstepSystems::Solve),
    );
    app.add_systems(
        crate::Substep,
        refresh_contacts.run_if(two_or_more).in_set(ContactRefresh),
    );
}

/// A deformable surface frozen for measurements: signed distances of points from it, m,
/// measured the way contact sees them (negative inside a closed surface, the unsigned distance
/// from an open one). Meant for tests and analysis.
pub struct SurfaceProbe(Entry);

impl SurfaceProbe {
    /// The surface of `triangles` over `nodes`.
    pub fn new(nodes: &[Vector3<f64>], triangles: &[[u32; 3]]) -> Self {
        let surface = ContactSurface::new(triangles.to_vec(), &MaterialDesc::default(), true, None);
        let mut e = Entry {
            entity: Entity::PLACEHOLDER,
            surface,
            index: 0,
            node_mass: 0.0,
            masses: Vec::new(),
            pos: nodes.to_vec(),
            vel: vec![Vector3::zeros(); nodes.len()],
            bvh: TriangleBvh::default(),
            is_target: true,
            targets: Vec::new(),
            object: 0,
        };
        e.bvh.rebuild(&e.surface.triangles, &e.pos, 0.0);
        Self(e)
    }

    /// The signed distance of `p`; `None` without triangles.
    pub fn distance(&self, p: &Vector3<f64>) -> Option<f64> {
        let b = self.0.bvh.bounds();
        let reach = (b.hi - b.lo).norm() + (p - b.lo).norm();
        self.0.contact(p, reach, 0.0).map(|c| c.distance)
    }
}
