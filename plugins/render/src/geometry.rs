//! Scene extraction: the world's rigid colliders, deformable surfaces and target markers as one
//! list of world-space triangles per frame (CPU side; the GPU draws it in one call per pass).
//!
//! - Rigid bodies are drawn as the rapier colliders they are, so anything with a collider
//!   appears (scene objects, robot links). Scene objects keep their visual mesh where the
//!   collider is an approximation (convex decompositions) and their plane's size for half
//!   spaces. Meshes are tessellated once per collider and cached; vertices are split where the
//!   surface creases, so boxes stay sharp and spheres smooth.
//! - Deformables: FEM solids draw their boundary faces, each split into four triangles through
//!   the 10-node tets' edge nodes (so bending shows); cloth draws its triangles. Normals are
//!   recomputed every frame; the shader lights both sides.
//! - Target markers: translucent spheres at the scene's named frames.

use std::collections::HashMap;
use std::sync::Arc;

use bevy_ecs::prelude::*;
use modesuite_engine::components::{DeformableNodes, Object};
use modesuite_engine::deformable::DeformableMarkers;
use modesuite_engine::math::pose_from_rapier;
use modesuite_engine::scene::{BodyModel, NamedFrames, RigidShape, SceneModel};
use modesuite_engine::shapes::ShapeDesc;
use modesuite_engine::RigidContext;
use nalgebra::{Isometry3, Point3, Vector3};
use rapier3d::geometry::{ColliderHandle, TypedShape};

/// Vertex flag: draw a checker pattern (ground planes).
pub const FLAG_CHECKER: u32 = 1;

/// One vertex as the GPU reads it.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Vertex {
    /// World position, m.
    pub pos: [f32; 3],
    /// World normal (unit).
    pub normal: [f32; 3],
    /// Linear RGBA colour.
    pub color: [u8; 4],
    /// Segmentation id (object index + 1; 0 = background).
    pub id: u32,
    /// `FLAG_*` bits.
    pub flags: u32,
}

/// The triangles of one frame, world frame: opaque geometry first, then translucent target
/// markers, then the contact and grasp markers.
#[derive(Debug, Clone, Default)]
pub struct FrameGeometry {
    /// All vertices.
    pub vertices: Vec<Vertex>,
    /// Triangle indices; `0..opaque_indices` are opaque, `opaque_indices..target_indices` target
    /// markers, the rest contact and grasp markers.
    pub indices: Vec<u32>,
    /// Number of opaque indices.
    pub opaque_indices: u32,
    /// End of the target markers' indices.
    pub target_indices: u32,
    /// Bounds of the finite geometry (everything but ground planes), for shadows and framing.
    pub focus: Option<(Vector3<f64>, Vector3<f64>)>,
}

impl FrameGeometry {
    fn clear(&mut self) {
        self.vertices.clear();
        self.indices.clear();
        self.opaque_indices = 0;
        self.target_indices = 0;
        self.focus = None;
    }

    fn grow_focus(&mut self, p: &Vector3<f64>) {
        self.focus = Some(match self.focus {
            None => (*p, *p),
            Some((lo, hi)) => (lo.inf(p), hi.sup(p)),
        });
    }

    /// Appends a mesh placed at `world_from_local`.
    fn push_mesh(&mut self, mesh: &LocalMesh, pose: &Isometry3<f64>, style: Style) {
        let base = self.vertices.len() as u32;
        for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
            let w = pose * Point3::from(*p);
            let wn = pose.rotation * n;
            if style.flags & FLAG_CHECKER == 0 {
                self.grow_focus(&w.coords);
            }
            self.vertices.push(Vertex {
                pos: [w.x as f32, w.y as f32, w.z as f32],
                normal: [wn.x as f32, wn.y as f32, wn.z as f32],
                color: style.color,
                id: style.id,
                flags: style.flags,
            });
        }
        self.indices
            .extend(mesh.triangles.iter().flatten().map(|i| base + i));
    }
}

/// How a mesh is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Style {
    color: [u8; 4],
    id: u32,
    flags: u32,
}

/// A triangle mesh in its own frame with per-vertex normals.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LocalMesh {
    /// Vertex positions, m.
    pub positions: Vec<Vector3<f64>>,
    /// Unit normals, one per vertex.
    pub normals: Vec<Vector3<f64>>,
    /// Triangles (counter-clockwise seen from outside).
    pub triangles: Vec<[u32; 3]>,
}

/// Area-weighted vertex normals of a welded mesh (zero-area neighbourhoods get +z).
pub fn smooth_normals(
    positions: &[Vector3<f64>],
    triangles: &[[u32; 3]],
    out: &mut Vec<Vector3<f64>>,
) {
    out.clear();
    out.resize(positions.len(), Vector3::zeros());
    for t in triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let n = (b - a).cross(&(c - a));
        for i in t {
            out[*i as usize] += n;
        }
    }
    for n in out.iter_mut() {
        *n = n.try_normalize(1e-30).unwrap_or_else(Vector3::z);
    }
}

impl LocalMesh {
    /// Builds a mesh with sharp edges where neighbouring faces meet at more than `crease_deg`
    /// degrees: each triangle corner averages only the faces around its vertex within the
    /// crease angle of its own face.
    pub fn with_creases(
        positions: &[Vector3<f64>],
        triangles: &[[u32; 3]],
        crease_deg: f64,
    ) -> Self {
        let cos_crease = crease_deg.to_radians().cos();
        let valid: Vec<[u32; 3]> = triangles
            .iter()
            .copied()
            .filter(|t| t.iter().all(|&i| (i as usize) < positions.len()))
            .collect();
        let face_n: Vec<Vector3<f64>> = valid
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| positions[i as usize]);
                (b - a).cross(&(c - a))
            })
            .collect();
        let mut around: Vec<Vec<usize>> = vec![Vec::new(); positions.len()];
        for (f, t) in valid.iter().enumerate() {
            for &i in t {
                around[i as usize].push(f);
            }
        }
        let mut mesh = LocalMesh::default();
        // (position index, rounded normal) -> new vertex, so equal corners are shared.
        let mut shared: HashMap<(u32, [i64; 3]), u32> = HashMap::new();
        for (f, t) in valid.iter().enumerate() {
            let own = face_n[f].try_normalize(1e-30).unwrap_or_else(Vector3::z);
            let mut tri = [0u32; 3];
            for (k, &i) in t.iter().enumerate() {
                let mut n = Vector3::zeros();
                for &g in &around[i as usize] {
                    let gn = face_n[g].try_normalize(1e-30).unwrap_or_else(Vector3::z);
                    if gn.dot(&own) >= cos_crease {
                        n += face_n[g];
                    }
                }
                let n = n.try_normalize(1e-30).unwrap_or(own);
                let key = (i, [0, 1, 2].map(|c| (n[c] * 1e4).round() as i64));
                tri[k] = *shared.entry(key).or_insert_with(|| {
                    mesh.positions.push(positions[i as usize]);
                    mesh.normals.push(n);
                    (mesh.positions.len() - 1) as u32
                });
            }
            mesh.triangles.push(tri);
        }
        mesh
    }

    /// A UV sphere of radius `r` (smooth).
    pub fn sphere(r: f64) -> Self {
        let (v, t) = rapier3d::geometry::Ball::new(r as f32).to_trimesh(24, 12);
        Self::from_parry(&v, &t, 60.0)
    }

    /// A quad of `size` in the xy plane, normal +z, centred at the origin.
    pub fn quad(size: (f64, f64)) -> Self {
        let (hx, hy) = (size.0 * 0.5, size.1 * 0.5);
        Self {
            positions: vec![
                Vector3::new(-hx, -hy, 0.0),
                Vector3::new(hx, -hy, 0.0),
                Vector3::new(hx, hy, 0.0),
                Vector3::new(-hx, hy, 0.0),
            ],
            normals: vec![Vector3::z(); 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    fn from_parry(v: &[rapier3d::math::Vector], t: &[[u32; 3]], crease: f64) -> Self {
        let pos: Vec<_> = v
            .iter()
            .map(|p| Vector3::new(p.x as f64, p.y as f64, p.z as f64))
            .collect();
        Self::with_creases(&pos, t, crease)
    }

    fn append(&mut self, other: &LocalMesh, pose: &Isometry3<f64>) {
        let base = self.positions.len() as u32;
        self.positions.extend(
            other
                .positions
                .iter()
                .map(|p| (pose * Point3::from(*p)).coords),
        );
        self.normals
            .extend(other.normals.iter().map(|n| pose.rotation * n));
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|i| i + base)));
    }
}

/// Tessellates a collider shape in its own frame (`None` for shapes without a surface to draw).
pub fn tessellate(shape: TypedShape, plane_size: (f64, f64)) -> Option<LocalMesh> {
    Some(match shape {
        TypedShape::Ball(b) => {
            let (v, t) = b.to_trimesh(24, 12);
            LocalMesh::from_parry(&v, &t, 60.0)
        }
        TypedShape::Cuboid(c) => {
            let (v, t) = c.to_trimesh();
            LocalMesh::from_parry(&v, &t, 30.0)
        }
        TypedShape::Cylinder(c) => {
            let (v, t) = c.to_trimesh(32);
            LocalMesh::from_parry(&v, &t, 40.0)
        }
        TypedShape::Cone(c) => {
            let (v, t) = c.to_trimesh(32);
            LocalMesh::from_parry(&v, &t, 40.0)
        }
        TypedShape::Capsule(c) => {
            let (v, t) = c.to_trimesh(24, 8);
            LocalMesh::from_parry(&v, &t, 60.0)
        }
        TypedShape::ConvexPolyhedron(c) => {
            let (v, t) = c.to_trimesh();
            LocalMesh::from_parry(&v, &t, 30.0)
        }
        TypedShape::TriMesh(m) => LocalMesh::from_parry(m.vertices(), m.indices(), 30.0),
        TypedShape::HalfSpace(h) => {
            // The quad lies in the plane through the origin with the half space's normal.
            let n = Vector3::new(h.normal.x as f64, h.normal.y as f64, h.normal.z as f64);
            let rot = nalgebra::UnitQuaternion::rotation_between(&Vector3::z(), &n).unwrap_or_else(
                || {
                    nalgebra::UnitQuaternion::from_axis_angle(
                        &Vector3::x_axis(),
                        std::f64::consts::PI,
                    )
                },
            );
            let mut m = LocalMesh::default();
            m.append(
                &LocalMesh::quad(plane_size),
                &Isometry3::from_parts(nalgebra::Translation3::identity(), rot),
            );
            m
        }
        TypedShape::Compound(c) => {
            let mut m = LocalMesh::default();
            for (pose, s) in c.shapes() {
                if let Some(part) = tessellate(s.as_typed_shape(), plane_size) {
                    m.append(&part, &pose_from_rapier(pose));
                }
            }
            m
        }
        _ => return None,
    })
}

/// Default colours by object index (linear RGB).
const PALETTE: [[f32; 3]; 8] = [
    [0.80, 0.35, 0.20],
    [0.20, 0.45, 0.80],
    [0.30, 0.65, 0.30],
    [0.85, 0.70, 0.20],
    [0.60, 0.35, 0.70],
    [0.20, 0.70, 0.70],
    [0.75, 0.30, 0.45],
    [0.55, 0.55, 0.55],
];

fn rgba(c: [f32; 3], a: f32) -> [u8; 4] {
    let q = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
    [q(c[0]), q(c[1]), q(c[2]), q(a)]
}

/// What is cached per collider.
struct ColliderVisual {
    mesh: Arc<LocalMesh>,
    style: Style,
    /// Place the mesh with the parent body's pose (visual meshes in the body frame) instead of
    /// the collider's.
    body_frame: bool,
}

/// A deformable object's surface topology (positions come from its `DeformableNodes`).
struct DeformableVisual {
    entity: Entity,
    triangles: Arc<Vec<[u32; 3]>>,
    style: Style,
}

/// The surface triangles of a deformable body, as its body kind gives them
/// ([`BodyKind::surface_triangles`](modesuite_engine::registry::BodyKind::surface_triangles));
/// `None` for rigid bodies and kinds without nodes.
pub fn deformable_triangles(body: &BodyModel) -> Option<Vec<[u32; 3]>> {
    match body {
        BodyModel::Plugin { kind, compiled } => kind.surface_triangles(compiled),
        _ => None,
    }
}

/// Which markers [`SceneExtractor::extract`] adds after the opaque geometry.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Markers {
    /// Translucent spheres at the scene's named frames (task targets).
    pub targets: bool,
    /// Contact markers (red: rigid contact points and deformable nodes touching colliders) and
    /// grasp markers (yellow: deformable nodes held by grippers).
    pub overlays: bool,
}

/// Colour of contact markers.
pub const CONTACT_MARKER_RGB: [f32; 3] = [0.95, 0.1, 0.1];
/// Colour of grasp markers.
pub const GRASP_MARKER_RGB: [f32; 3] = [1.0, 0.85, 0.0];
/// Radius of contact and grasp markers, m.
pub const OVERLAY_MARKER_RADIUS: f64 = 0.012;
/// Rigid contact points at most this far apart (m) count as touching for the markers.
const CONTACT_MARKER_DISTANCE: f64 = 2e-3;

/// Extracts the drawable geometry of one env's world; caches tessellations.
pub struct SceneExtractor {
    model: Arc<SceneModel>,
    colliders: HashMap<ColliderHandle, Option<ColliderVisual>>,
    deformables: Option<Vec<DeformableVisual>>,
    marker: LocalMesh,
    dot: LocalMesh,
    marker_radius: f64,
    points: Vec<Vector3<f64>>,
    normals: Vec<Vector3<f64>>,
    positions: Vec<Vector3<f64>>,
}

impl SceneExtractor {
    /// An extractor for worlds spawned from `model`.
    pub fn new(model: Arc<SceneModel>, marker_radius: f64) -> Self {
        Self {
            model,
            colliders: HashMap::new(),
            deformables: None,
            marker: LocalMesh::sphere(marker_radius),
            dot: {
                let (v, t) =
                    rapier3d::geometry::Ball::new(OVERLAY_MARKER_RADIUS as f32).to_trimesh(8, 4);
                LocalMesh::from_parry(&v, &t, 60.0)
            },
            marker_radius,
            points: Vec::new(),
            normals: Vec::new(),
            positions: Vec::new(),
        }
    }

    /// The scene this extractor draws.
    pub fn model(&self) -> &Arc<SceneModel> {
        &self.model
    }

    fn style_of(&self, index: Option<u32>) -> Style {
        match index.and_then(|i| self.model.objects.get(i as usize).map(|o| (i, o))) {
            Some((i, o)) => {
                let plane = matches!(o.shape, ShapeDesc::Plane { .. });
                let c = o.color.unwrap_or(if plane {
                    [0.75, 0.75, 0.72]
                } else {
                    PALETTE[i as usize % PALETTE.len()]
                });
                Style {
                    color: rgba(c, 1.0),
                    id: i + 1,
                    flags: if plane { FLAG_CHECKER } else { 0 },
                }
            }
            // Colliders of no scene object (e.g. robot links not registered as objects).
            None => Style {
                color: rgba([0.7, 0.7, 0.72], 1.0),
                id: 0,
                flags: 0,
            },
        }
    }

    fn collider_visual(
        &self,
        world: &World,
        rigid: &RigidContext,
        handle: ColliderHandle,
    ) -> Option<ColliderVisual> {
        let co = rigid.colliders.get(handle)?;
        // a deformable's surface collider (for the rigid solver) is drawn as the deformable
        if modesuite_engine::rigid::surface_of(co.user_data).is_some() {
            return None;
        }
        let entity = co
            .parent()
            .and_then(|b| rigid.body_id(b))
            .and_then(|id| rigid.body_of_id(id))
            .map(|(_, e)| e);
        let object = entity.and_then(|e| world.get::<Object>(e));
        let index = object.map(|o| o.index);
        let style = self.style_of(index);
        let om = index.and_then(|i| self.model.objects.get(i as usize));
        // Scene objects whose collider approximates a visual mesh draw the mesh.
        if let Some(BodyModel::Rigid(r)) = om.map(|o| &o.body) {
            if let RigidShape::ConvexDecomposition { mesh: m, .. } = &r.shape {
                return Some(ColliderVisual {
                    mesh: Arc::new(LocalMesh::with_creases(&m.positions, &m.triangles, 30.0)),
                    style,
                    body_frame: true,
                });
            }
        }
        let plane_size = match om.map(|o| &o.shape) {
            Some(ShapeDesc::Plane { size }) => *size,
            _ => (20.0, 20.0),
        };
        let mesh = tessellate(co.shape().as_typed_shape(), plane_size)?;
        Some(ColliderVisual {
            mesh: Arc::new(mesh),
            style,
            body_frame: false,
        })
    }

    fn init_deformables(&mut self, world: &World) -> Vec<DeformableVisual> {
        let mut out = Vec::new();
        let Some(mut q) = world.try_query::<(Entity, &Object, &DeformableNodes)>() else {
            return out;
        };
        let mut found: Vec<(u32, Entity)> = q.iter(world).map(|(e, o, _)| (o.index, e)).collect();
        found.sort_unstable_by_key(|(i, _)| *i);
        for (i, entity) in found {
            let Some(om) = self.model.objects.get(i as usize) else {
                continue;
            };
            if let Some(tris) = deformable_triangles(&om.body) {
                out.push(DeformableVisual {
                    entity,
                    triangles: Arc::new(tris),
                    style: self.style_of(Some(i)),
                });
            }
        }
        out
    }

    /// Fills `out` with the world's current geometry and the markers asked for.
    pub fn extract(&mut self, world: &World, markers: Markers, out: &mut FrameGeometry) {
        out.clear();
        if let Some(rigid) = world.get_resource::<RigidContext>() {
            let handles: Vec<ColliderHandle> = rigid.colliders.iter().map(|(h, _)| h).collect();
            for h in handles {
                if !self.colliders.contains_key(&h) {
                    let v = self.collider_visual(world, rigid, h);
                    self.colliders.insert(h, v);
                }
                let (Some(Some(v)), Some(co)) = (self.colliders.get(&h), rigid.colliders.get(h))
                else {
                    continue;
                };
                let pose = if v.body_frame {
                    co.parent()
                        .and_then(|b| rigid.bodies.get(b))
                        .map(|b| pose_from_rapier(b.position()))
                } else {
                    Some(pose_from_rapier(co.position()))
                };
                if let Some(pose) = pose {
                    out.push_mesh(&v.mesh, &pose, v.style);
                }
            }
        }
        if self.deformables.is_none() {
            self.deformables = Some(self.init_deformables(world));
        }
        let mut positions = std::mem::take(&mut self.positions);
        let mut normals = std::mem::take(&mut self.normals);
        for d in self.deformables.iter().flatten() {
            let Some(nodes) = world.get::<DeformableNodes>(d.entity) else {
                continue;
            };
            if d.triangles
                .iter()
                .any(|t| t.iter().any(|&i| i as usize >= nodes.0.len()))
            {
                continue;
            }
            positions.clear();
            positions.extend_from_slice(&nodes.0);
            smooth_normals(&positions, &d.triangles, &mut normals);
            let mesh = LocalMesh {
                positions: std::mem::take(&mut positions),
                normals: std::mem::take(&mut normals),
                triangles: Vec::new(),
            };
            let base = out.vertices.len() as u32;
            out.push_mesh(&mesh, &Isometry3::identity(), d.style);
            out.indices
                .extend(d.triangles.iter().flatten().map(|i| base + i));
            positions = mesh.positions;
            normals = mesh.normals;
        }
        self.positions = positions;
        self.normals = normals;
        out.opaque_indices = out.indices.len() as u32;
        // Markers do not cast shadows or change the framing.
        let focus = out.focus;
        if markers.targets {
            if let Some(frames) = world.get_resource::<NamedFrames>() {
                let style = Style {
                    color: rgba([0.1, 0.9, 0.3], 0.35),
                    id: 0,
                    flags: 0,
                };
                for pose in frames.0.values() {
                    let at = Isometry3::from_parts(
                        pose.translation,
                        nalgebra::UnitQuaternion::identity(),
                    );
                    out.push_mesh(&self.marker, &at, style);
                }
            }
        }
        out.target_indices = out.indices.len() as u32;
        if markers.overlays {
            self.push_overlays(world, out);
        }
        out.focus = focus;
    }

    /// Contact and grasp markers: small spheres at rigid contact points and at the deformable
    /// nodes that touch colliders or are grasped (grasp colour wins).
    fn push_overlays(&mut self, world: &World, out: &mut FrameGeometry) {
        let style = |rgb: [f32; 3]| Style {
            color: rgba(rgb, 0.9),
            id: 0,
            flags: 0,
        };
        let mut points = std::mem::take(&mut self.points);
        points.clear();
        if let Some(rigid) = world.get_resource::<RigidContext>() {
            rigid.contact_points(CONTACT_MARKER_DISTANCE, &mut points);
        }
        let mut grasped = Vec::new();
        for d in self.deformables.iter().flatten() {
            let (Some(nodes), Some(m)) = (
                world.get::<DeformableNodes>(d.entity),
                world.get::<DeformableMarkers>(d.entity),
            ) else {
                continue;
            };
            let at = |i: &u32| nodes.0.get(*i as usize).copied();
            points.extend(
                m.contacts
                    .iter()
                    .filter(|i| m.grasped.binary_search(i).is_err())
                    .filter_map(at),
            );
            grasped.extend(m.grasped.iter().filter_map(at));
        }
        for (list, rgb) in [(&points, CONTACT_MARKER_RGB), (&grasped, GRASP_MARKER_RGB)] {
            for p in list.iter().filter(|p| p.iter().all(|x| x.is_finite())) {
                let at = Isometry3::translation(p.x, p.y, p.z);
                out.push_mesh(&self.dot, &at, style(rgb));
            }
        }
        self.points = points;
    }

    /// Radius of the target markers, m.
    pub fn marker_radius(&self) -> f64 {
        self.marker_radius
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn creased_box_has_flat_faces() {
        let c = rapier3d::geometry::Cuboid::new(rapier3d::math::Vector::new(0.5, 0.5, 0.5));
        let (v, t) = c.to_trimesh();
        let m = LocalMesh::from_parry(&v, &t, 30.0);
        // 6 faces x 4 corners.
        assert_eq!(m.positions.len(), 24, "vertices of a creased box");
        for (p, n) in m.positions.iter().zip(&m.normals) {
            // Each normal is an axis and the vertex lies on that face.
            assert!((n.abs().max() - 1.0).abs() < 1e-9, "normal {n}");
            assert!((p.dot(n) - 0.5).abs() < 1e-6, "vertex {p} normal {n}");
        }
    }

    #[test]
    fn sphere_normals_are_radial() {
        let m = LocalMesh::sphere(2.0);
        for (p, n) in m.positions.iter().zip(&m.normals) {
            assert!((p.normalize() - n).norm() < 0.15, "{p} {n}");
        }
    }
}
