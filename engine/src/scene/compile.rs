//! Compilation (validate, mesh, let plugins compile their parameters: [`compile`]) and spawning
//! of scenes, and the scene verbs of [`SimApp`].

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use bevy_ecs::prelude::*;
use nalgebra::{Isometry3, Vector3};
use ron::value::RawValue;

use super::desc::{gravity_of, BodyDesc, MaterialDesc, PhysicsDesc, PoseDesc, SceneDesc};
use super::error::SceneError;
use super::model::{RigidKind, RigidModel, RigidShape};
use super::source::SceneSource;
use crate::components::{Object, Pose};
use crate::contact::ContactSurface;
use crate::registry::{BodyCompileContext, BodyModel, ObjectModel, Registry, TermKind};
use crate::settings::EpisodeLimit;
use crate::shapes::{ShapeContext, ShapeDesc, ShapeError};
use crate::terms::ConfiguredTerm;
use crate::{SimApp, SimSettings};

/// A compiled scene: immutable, shared by all envs through `Arc`.
#[derive(Clone)]
pub struct SceneModel {
    /// Timing and gravity.
    pub settings: SimSettings,
    /// Objects in spawn order.
    pub objects: Vec<ObjectModel>,
    /// Named frames and targets.
    pub frames: BTreeMap<String, Isometry3<f64>>,
    /// Episode length in env steps.
    pub episode_steps: Option<u64>,
    /// Plugin-owned scene sections, raw RON.
    pub extensions: BTreeMap<String, Box<RawValue>>,
    /// The same sections compiled by their handlers, in key order (spawned after the objects).
    pub sections: Vec<CompiledSceneSection>,
    /// One-line description.
    pub description: Option<String>,
    /// Where it came from.
    pub source: SceneSource,
    /// Configured reward, termination and observation terms and passive forces.
    pub terms: crate::terms::SceneTerms,
}

/// One compiled plugin-owned scene section.
#[derive(Clone)]
pub struct CompiledSceneSection {
    /// Its key in `extensions`.
    pub key: String,
    /// The handler that compiled it and spawns it.
    pub handler: Arc<dyn crate::registry::SceneSection>,
    /// Its compiled data.
    pub compiled: crate::registry::CompiledSection,
}

/// Named world frames of the spawned scene (targets, markers).
#[derive(Resource, Debug, Clone, Default)]
pub struct NamedFrames(pub BTreeMap<String, Isometry3<f64>>);

fn finite3(v: &[f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn fmt3(v: &[f64; 3]) -> String {
    format!("({}, {}, {})", v[0], v[1], v[2])
}

fn shape_err(path: &str, e: ShapeError) -> SceneError {
    match e.field() {
        Some(_) => {
            let e = e.prefixed(&format!("{path}."));
            match &e {
                ShapeError::Invalid {
                    field,
                    value,
                    expected,
                } => SceneError::semantic(field.clone(), value.clone(), expected.clone()),
                other => SceneError::semantic(path, "(shape)", other.to_string()),
            }
        }
        None => SceneError::semantic(path, "(shape)", e.to_string()),
    }
}

fn validate_physics(p: &PhysicsDesc) -> Result<(), SceneError> {
    if !(p.dt.is_finite() && p.dt > 0.0 && p.dt <= 1.0) {
        return Err(SceneError::semantic(
            "physics.dt",
            p.dt.to_string(),
            "a finite step in seconds, 0 < dt <= 1",
        ));
    }
    if !(1..=1000).contains(&p.substeps) {
        return Err(SceneError::semantic(
            "physics.substeps",
            p.substeps.to_string(),
            "an integer in 1..=1000",
        ));
    }
    if !(1..=1000).contains(&p.decimation) {
        return Err(SceneError::semantic(
            "physics.decimation",
            p.decimation.to_string(),
            "an integer in 1..=1000",
        ));
    }
    if let Some(d) = p.deformable_substeps {
        let fits = d > 0 && (p.substeps.is_multiple_of(d) || d.is_multiple_of(p.substeps));
        if !fits || d > 1000 {
            return Err(SceneError::semantic(
                "physics.deformable_substeps",
                d.to_string(),
                format!(
                    "a positive divisor or multiple (at most 1000) of physics.substeps ({}), or leave it out for one deformable step per substep",
                    p.substeps
                ),
            ));
        }
    }
    if !(p.max_body_speed.is_finite() && p.max_body_speed > 0.0) {
        return Err(SceneError::semantic(
            "physics.max_body_speed",
            p.max_body_speed.to_string(),
            "a finite speed in m/s above 0 (default 100)",
        ));
    }
    for (field, value) in [
        ("physics.rigid_iterations", p.rigid_iterations),
        ("physics.rigid_pgs_iterations", p.rigid_pgs_iterations),
    ] {
        if !(1..=100).contains(&value) {
            return Err(SceneError::semantic(
                field,
                value.to_string(),
                "an integer in 1..=100",
            ));
        }
    }
    if !finite3(&p.gravity) {
        return Err(SceneError::semantic(
            "physics.gravity",
            fmt3(&p.gravity),
            "three finite numbers, m/s^2",
        ));
    }
    Ok(())
}

fn validate_material(name: &str, m: &MaterialDesc) -> Result<(), SceneError> {
    let path = format!("materials[\"{name}\"]");
    if !(m.friction.is_finite() && m.friction >= 0.0) {
        return Err(SceneError::semantic(
            format!("{path}.friction"),
            m.friction.to_string(),
            "a finite number >= 0",
        ));
    }
    if !(m.restitution.is_finite() && (0.0..=1.0).contains(&m.restitution)) {
        return Err(SceneError::semantic(
            format!("{path}.restitution"),
            m.restitution.to_string(),
            "a number in [0, 1]",
        ));
    }
    crate::contact::validate_material(&path, m)?;
    if !(m.density.is_finite() && m.density > 0.0) {
        return Err(SceneError::semantic(
            format!("{path}.density"),
            m.density.to_string(),
            "a finite density > 0, kg/m^3",
        ));
    }
    Ok(())
}

fn validate_pose(path: &str, p: &PoseDesc) -> Result<(), SceneError> {
    if !finite3(&p.pos) {
        return Err(SceneError::semantic(
            format!("{path}.pos"),
            fmt3(&p.pos),
            "three finite numbers, m",
        ));
    }
    if !finite3(&p.rpy) {
        return Err(SceneError::semantic(
            format!("{path}.rpy"),
            fmt3(&p.rpy),
            "three finite angles, rad",
        ));
    }
    Ok(())
}

/// Collision shape for a rigid object: primitives map to rapier primitives, the rest to meshes.
fn rigid_shape(
    path: &str,
    shape: &ShapeDesc,
    kind: RigidKind,
    ctx: &ShapeContext,
) -> Result<RigidShape, SceneError> {
    Ok(match shape {
        ShapeDesc::Box { size, .. } => {
            RigidShape::Cuboid(Vector3::new(size.0, size.1, size.2) * 0.5)
        }
        ShapeDesc::Sphere { radius, .. } => RigidShape::Ball(*radius),
        ShapeDesc::Cylinder { radius, height, .. } => RigidShape::CylinderZ {
            radius: *radius,
            half_height: height * 0.5,
        },
        ShapeDesc::Capsule { radius, height, .. } => RigidShape::CapsuleZ {
            radius: *radius,
            half_height: height * 0.5,
        },
        ShapeDesc::Plane { .. } => {
            if kind != RigidKind::Static {
                return Err(SceneError::semantic(
                    format!("{path}.body"),
                    format!("{kind:?}"),
                    "a Plane is an infinite half space and can only be Static",
                ));
            }
            RigidShape::HalfSpace
        }
        other => {
            let mesh = other
                .surface(ctx)
                .map_err(|e| shape_err(&format!("{path}.shape"), e))?;
            if mesh.triangles.is_empty() {
                return Err(SceneError::semantic(
                    format!("{path}.shape"),
                    "(mesh)",
                    "a shape with at least one triangle (Polyline is a path, not a body)",
                ));
            }
            let mesh = Arc::new(mesh);
            if kind == RigidKind::Static {
                RigidShape::TriMesh(mesh)
            } else {
                let parts = crate::rigid::convex_decomposition(&mesh).map_err(|why| {
                    SceneError::semantic(
                        format!("{path}.shape"),
                        "(mesh)",
                        format!(
                            "a mesh a moving rigid body can use: its convex decomposition failed ({why}); make the body Static (a triangle mesh) or give it a closed, non-degenerate surface"
                        ),
                    )
                })?;
                RigidShape::ConvexDecomposition { mesh, parts }
            }
        }
    })
}

/// Validates and compiles a scene description with the given registries.
pub fn compile(
    desc: &SceneDesc,
    source: &SceneSource,
    registry: &Registry,
) -> Result<SceneModel, SceneError> {
    let file = source.file.as_ref().map(|f| f.display().to_string());
    compile_inner(desc, source, registry).map_err(|e| e.in_file(file.as_deref()))
}

fn compile_inner(
    desc: &SceneDesc,
    source: &SceneSource,
    registry: &Registry,
) -> Result<SceneModel, SceneError> {
    validate_physics(&desc.physics)?;
    let mut materials = desc.materials.clone();
    materials.entry("default".to_string()).or_default();
    for (name, m) in &materials {
        validate_material(name, m)?;
    }
    let settings = SimSettings {
        dt: desc.physics.dt,
        substeps: desc.physics.substeps,
        decimation: desc.physics.decimation,
        gravity: gravity_of(&desc.physics),
        rigid_iterations: desc.physics.rigid_iterations,
        rigid_pgs_iterations: desc.physics.rigid_pgs_iterations,
        rigid_friction_in_bias_pass: desc.physics.rigid_friction_in_bias_pass,
        deformable_stride: desc
            .physics
            .deformable_substeps
            .map_or(1, |d| (desc.physics.substeps / d).max(1)),
        deformable_inner: desc
            .physics
            .deformable_substeps
            .map_or(1, |d| (d / desc.physics.substeps).max(1)),
        max_body_speed: desc.physics.max_body_speed,
        coupling_substeps: 1,
    };
    if let Some(0) = desc.episode_steps {
        return Err(SceneError::semantic(
            "episode_steps",
            "0",
            "a positive number of env steps, or leave it out for no limit",
        ));
    }
    let mut frames = BTreeMap::new();
    for (name, f) in &desc.frames {
        validate_pose(&format!("frames[\"{name}\"]"), f)?;
        frames.insert(name.clone(), f.isometry());
    }
    let shape_ctx = ShapeContext {
        base_dir: &source.base_dir,
        asset_roots: &source.asset_roots,
        generators: Some(registry),
    };
    let mut names = BTreeSet::new();
    let mut objects = Vec::with_capacity(desc.objects.len());
    for (i, obj) in desc.objects.iter().enumerate() {
        let path = format!("objects[{i}] \"{}\"", obj.name);
        if obj.name.trim().is_empty() {
            return Err(SceneError::semantic(
                format!("objects[{i}].name"),
                format!("{:?}", obj.name),
                "a non-empty unique name",
            ));
        }
        if !names.insert(obj.name.clone()) {
            return Err(SceneError::semantic(
                format!("{path}.name"),
                format!("{:?}", obj.name),
                "names must be unique within a scene",
            ));
        }
        obj.shape
            .validate()
            .map_err(|e| shape_err(&format!("{path}.shape"), e))?;
        validate_pose(&format!("{path}.pose"), &obj.pose)?;
        let material_name = obj
            .material
            .clone()
            .unwrap_or_else(|| "default".to_string());
        let material = *materials.get(&material_name).ok_or_else(|| {
            SceneError::semantic(
                format!("{path}.material"),
                format!("{material_name:?}"),
                format!(
                    "one of the scene's materials: [{}]",
                    materials.keys().cloned().collect::<Vec<_>>().join(", ")
                ),
            )
        })?;
        if let Some(c) = obj.color {
            if !c.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x)) {
                return Err(SceneError::semantic(
                    format!("{path}.color"),
                    format!("{c:?}"),
                    "three numbers in [0, 1]",
                ));
            }
        }
        let body = match &obj.body {
            BodyDesc::Static => BodyModel::Rigid(RigidModel {
                kind: RigidKind::Static,
                shape: rigid_shape(&path, &obj.shape, RigidKind::Static, &shape_ctx)?,
                mass: None,
                linear_velocity: Vector3::zeros(),
                angular_velocity: Vector3::zeros(),
            }),
            BodyDesc::Kinematic => BodyModel::Rigid(RigidModel {
                kind: RigidKind::Kinematic,
                shape: rigid_shape(&path, &obj.shape, RigidKind::Kinematic, &shape_ctx)?,
                mass: None,
                linear_velocity: Vector3::zeros(),
                angular_velocity: Vector3::zeros(),
            }),
            BodyDesc::Dynamic {
                mass,
                linear_velocity,
                angular_velocity,
            } => {
                if let Some(m) = mass {
                    if !(m.is_finite() && *m > 0.0) {
                        return Err(SceneError::semantic(
                            format!("{path}.body.mass"),
                            m.to_string(),
                            "a finite mass > 0, kg (or leave it out to use the material density)",
                        ));
                    }
                }
                if !finite3(linear_velocity) {
                    return Err(SceneError::semantic(
                        format!("{path}.body.linear_velocity"),
                        fmt3(linear_velocity),
                        "three finite numbers, m/s",
                    ));
                }
                if !finite3(angular_velocity) {
                    return Err(SceneError::semantic(
                        format!("{path}.body.angular_velocity"),
                        fmt3(angular_velocity),
                        "three finite numbers, rad/s",
                    ));
                }
                BodyModel::Rigid(RigidModel {
                    kind: RigidKind::Dynamic,
                    shape: rigid_shape(&path, &obj.shape, RigidKind::Dynamic, &shape_ctx)?,
                    mass: *mass,
                    linear_velocity: Vector3::from(*linear_velocity),
                    angular_velocity: Vector3::from(*angular_velocity),
                })
            }
            BodyDesc::Kind { kind, params } => {
                let body_kind = registry.body_kinds.get(kind).ok_or_else(|| {
                    SceneError::semantic(
                        format!("{path}.body.kind"),
                        format!("{kind:?}"),
                        format!(
                            "a registered body kind: [{}] (or Static, Dynamic, Kinematic); a kind from a compiled plugin needs `--plugin PATH`",
                            registry.body_kinds.keys().cloned().collect::<Vec<_>>().join(", ")
                        ),
                    )
                })?;
                let ctx = BodyCompileContext {
                    object: obj,
                    path: path.clone(),
                    params_ron: params.get_ron(),
                    shapes: &shape_ctx,
                    settings: &settings,
                    material: &material,
                    source,
                };
                let compiled = body_kind.compile(&ctx)?;
                BodyModel::Plugin {
                    kind: body_kind.clone(),
                    compiled,
                }
            }
        };
        let deformable = matches!(body, BodyModel::Plugin { .. });
        crate::contact::validate_object(&path, obj, deformable)?;
        objects.push(ObjectModel {
            collide: obj.collide,
            collision_group: obj.collision_group.clone(),
            name: obj.name.clone(),
            pose: obj.pose.isometry(),
            material,
            color: obj.color,
            shape: obj.shape.clone(),
            body,
        });
    }
    let mut sections = Vec::with_capacity(desc.extensions.len());
    let mut mounted_cameras = Vec::new();
    for (key, raw) in &desc.extensions {
        let handler = registry.sections.get(key).ok_or_else(|| {
            SceneError::semantic(
                format!("extensions[\"{key}\"]"),
                "(section)",
                format!(
                    "a registered scene section: [{}]; a section from a compiled plugin needs `--plugin PATH`",
                    registry.sections.keys().cloned().collect::<Vec<_>>().join(", ")
                ),
            )
        })?;
        let ctx = crate::registry::SectionCompileContext {
            key,
            ron: raw.get_ron(),
            settings: &settings,
            objects: &objects,
            frames: &frames,
            source,
            registry,
            extensions: &desc.extensions,
            mounted_cameras: &mounted_cameras,
        };
        let compiled = handler.compile(&ctx)?;
        mounted_cameras.extend(handler.cameras(&compiled));
        sections.push(CompiledSceneSection {
            key: key.clone(),
            handler: handler.clone(),
            compiled,
        });
    }
    let terms = compile_terms(desc, registry, &objects)?;
    Ok(SceneModel {
        settings,
        objects,
        frames,
        episode_steps: desc.episode_steps,
        sections,
        extensions: desc.extensions.clone(),
        description: desc.description.clone(),
        source: source.clone(),
        terms,
    })
}

fn params_text(params: &Option<Box<RawValue>>) -> &str {
    params.as_deref().map_or("()", RawValue::get_ron)
}

/// Looks up and configures one term of a scene section.
fn configure_term(
    registry: &Registry,
    section: &str,
    i: usize,
    name: &str,
    kind: TermKind,
    params: &Option<Box<RawValue>>,
) -> Result<Arc<dyn ConfiguredTerm>, SceneError> {
    let of_kind = || {
        registry
            .terms
            .values()
            .filter(|t| t.kind == kind && t.term().is_some())
            .map(|t| t.name.clone())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let entry = registry.terms.get(name).ok_or_else(|| {
        SceneError::semantic(
            format!("{section}[{i}].term"),
            format!("{name:?}"),
            format!(
                "a registered {kind:?} term: [{}]; a term from a compiled plugin needs `--plugin PATH`",
                of_kind()
            ),
        )
    })?;
    if entry.kind != kind {
        return Err(SceneError::semantic(
            format!("{section}[{i}].term"),
            format!("{name:?} (a {:?} term)", entry.kind),
            format!("a {kind:?} term: [{}]", of_kind()),
        ));
    }
    let term = entry.term().ok_or_else(|| {
        SceneError::semantic(
            format!("{section}[{i}].term"),
            format!("{name:?}"),
            "a term usable in scene sections; this one is evaluated by its plugin's own managers",
        )
    })?;
    let text = params_text(params);
    term.configure(text).map_err(|e| {
        SceneError::semantic(format!("{section}[{i}] \"{name}\".params"), text.trim(), e)
    })
}

/// Configures the scene's term sections and passive forces with the registry.
fn compile_terms(
    desc: &SceneDesc,
    registry: &Registry,
    objects: &[ObjectModel],
) -> Result<crate::terms::SceneTerms, SceneError> {
    use crate::terms::{ForceModel, RewardModel, TermModel};
    let mut out = crate::terms::SceneTerms::default();
    for (i, r) in desc.rewards.iter().enumerate() {
        if !r.weight.is_finite() {
            return Err(SceneError::semantic(
                format!("rewards[{i}].weight"),
                r.weight.to_string(),
                "a finite number",
            ));
        }
        let term = configure_term(registry, "rewards", i, &r.term, TermKind::Reward, &r.params)?;
        out.rewards.push(RewardModel {
            name: r.term.clone(),
            weight: r.weight,
            term,
        });
    }
    for (section, list, kind, dest) in [
        (
            "terminations",
            &desc.terminations,
            TermKind::Termination,
            &mut out.terminations,
        ),
        (
            "observations",
            &desc.observations,
            TermKind::Observation,
            &mut out.observations,
        ),
    ] {
        for (i, t) in list.iter().enumerate() {
            let term = configure_term(registry, section, i, &t.term, kind, &t.params)?;
            if kind != TermKind::Observation && term.dim() != 1 {
                return Err(SceneError::semantic(
                    format!("{section}[{i}].term"),
                    format!("{:?} ({} values)", t.term, term.dim()),
                    "a term with exactly one value",
                ));
            }
            dest.push(TermModel {
                name: t.term.clone(),
                term,
            });
        }
    }
    for (i, f) in desc.passive_forces.iter().enumerate() {
        let force = registry.forces.get(&f.force).ok_or_else(|| {
            SceneError::semantic(
                format!("passive_forces[{i}].force"),
                format!("{:?}", f.force),
                format!(
                    "a registered passive force: [{}]; a force from a compiled plugin needs `--plugin PATH`",
                    registry.forces.keys().cloned().collect::<Vec<_>>().join(", ")
                ),
            )
        })?;
        let mut indices = Vec::with_capacity(f.objects.len());
        for (k, name) in f.objects.iter().enumerate() {
            let idx = objects.iter().position(|o| &o.name == name);
            match idx.map(|j| (j, &objects[j].body)) {
                Some((j, BodyModel::Plugin { .. })) => indices.push(j as u32),
                Some(_) => {
                    return Err(SceneError::semantic(
                        format!("passive_forces[{i}].objects[{k}]"),
                        format!("{name:?}"),
                        "a deformable object (a plugin body kind such as fem.solid); rigid bodies take no passive forces",
                    ))
                }
                None => {
                    return Err(SceneError::semantic(
                        format!("passive_forces[{i}].objects[{k}]"),
                        format!("{name:?}"),
                        "the name of an object of the scene",
                    ))
                }
            }
        }
        let text = params_text(&f.params);
        let configured = force.configure(text).map_err(|e| {
            SceneError::semantic(
                format!("passive_forces[{i}] \"{}\".params", f.force),
                text.trim(),
                e,
            )
        })?;
        out.forces.push(ForceModel {
            name: f.force.clone(),
            objects: indices,
            force: configured,
        });
    }
    Ok(out)
}

/// Spawns a compiled scene into an app (called by [`SimApp::spawn_scene`]).
pub(crate) fn spawn(model: &SceneModel, app: &mut SimApp) -> Result<(), SceneError> {
    app.world.insert_resource(model.settings);
    app.world.insert_resource(NamedFrames(model.frames.clone()));
    app.world.insert_resource(EpisodeLimit(model.episode_steps));
    if !model.terms.is_empty() {
        app.world.insert_resource(model.terms.clone());
    }
    if !model.terms.observations.is_empty() {
        let dim = model.terms.observation_dim();
        let action = app
            .world
            .get_resource::<crate::signals::Spaces>()
            .map_or_else(|| crate::signals::Space::unbounded(0), |s| s.action.clone());
        app.world.insert_resource(crate::signals::Spaces {
            observation: crate::signals::Space::unbounded(dim),
            action,
        });
    }
    let has_rigid = model
        .objects
        .iter()
        .any(|o| matches!(o.body, BodyModel::Rigid(_)));
    if has_rigid && !app.world.contains_resource::<crate::rigid::RigidContext>() {
        return Err(SceneError::semantic(
            "objects",
            "(rigid bodies)",
            "the scene has rigid bodies but the app has no RigidPlugin; add modesuite_engine::RigidPlugin",
        ));
    }
    if let Some(mut rigid) = app.world.get_resource_mut::<crate::rigid::RigidContext>() {
        rigid.set_gravity(model.settings.gravity);
        rigid.params.num_solver_iterations = model.settings.rigid_iterations as usize;
        rigid.params.num_internal_pgs_iterations = model.settings.rigid_pgs_iterations as usize;
        rigid.params.friction_in_bias_pass = model.settings.rigid_friction_in_bias_pass;
    }
    for (i, obj) in model.objects.iter().enumerate() {
        let entity = app
            .world
            .spawn((
                Object {
                    name: obj.name.clone(),
                    index: i as u32,
                    kind: match &obj.body {
                        BodyModel::Rigid(r) => format!("{:?}", r.kind).to_lowercase(),
                        BodyModel::Plugin { kind, .. } => kind.name().to_string(),
                    },
                },
                Pose(obj.pose),
            ))
            .id();
        match &obj.body {
            BodyModel::Rigid(r) => {
                let mut rigid = app.world.resource_mut::<crate::rigid::RigidContext>();
                let handle = rigid.add_body(entity, &obj.pose, r, &obj.material);
                app.world.entity_mut(entity).insert((
                    crate::rigid::RigidRef(handle),
                    crate::components::Velocity {
                        linear: r.linear_velocity,
                        angular: r.angular_velocity,
                    },
                ));
            }
            BodyModel::Plugin { kind, compiled } => {
                kind.spawn(app, entity, compiled)?;
                if let Some(triangles) = kind.surface_triangles(compiled) {
                    let (collide, group) = (obj.collide, obj.collision_group.clone());
                    let surface = ContactSurface::new(triangles, &obj.material, collide, group);
                    crate::contact::attach_surface(&mut app.world, entity, surface);
                }
            }
        }
    }
    // after the scene's bodies, before the sections' (robots' links never resolve contacts
    // with deformables themselves)
    crate::contact::rigid_side::add_surface_colliders(&mut app.world);
    for section in &model.sections {
        section.handler.spawn(app, &section.compiled)?;
    }
    if let Some(mut rigid) = app.world.get_resource_mut::<crate::rigid::RigidContext>() {
        rigid.bodies_moved();
    }
    Ok(())
}

/// The scene an app spawned (one per app).
#[derive(Resource)]
struct SpawnedScene(Arc<SceneModel>);

/// The scene verbs of [`SimApp`] (here, beside the compiler, so that the application layer
/// does not depend on scenes).
impl SimApp {
    /// Compiles a scene description with this app's registries (body kinds, shapes).
    pub fn compile_scene(
        &self,
        desc: &SceneDesc,
        source: &SceneSource,
    ) -> Result<Arc<SceneModel>, SceneError> {
        if !self.setup_errors().is_empty() {
            return Err(SceneError::semantic(
                "plugins",
                self.setup_errors().join("; "),
                "plugins whose names do not clash",
            ));
        }
        compile(desc, source, self.registry()).map(Arc::new)
    }

    /// Spawns a compiled scene into this app's world and sets the simulation settings.
    pub fn spawn_scene(&mut self, model: Arc<SceneModel>) -> Result<(), SceneError> {
        if self.world.contains_resource::<SpawnedScene>() {
            return Err(SceneError::semantic(
                "scene",
                "already spawned",
                "one scene per app; build a new SimApp",
            ));
        }
        spawn(&model, self)?;
        self.world.insert_resource(SpawnedScene(model));
        Ok(())
    }

    /// The compiled scene of this app, if one was spawned.
    pub fn scene(&self) -> Option<&Arc<SceneModel>> {
        self.world.get_resource::<SpawnedScene>().map(|s| &s.0)
    }
}
